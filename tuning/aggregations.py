"""Aggregations: how an objective combines its per-scenario values into one number.

Each is a small object with the method that aggregates (``aggregation(values)``), as optax's
transformations carry their update: :class:`Mean`, :class:`SmoothMax` (a smooth worst case) and
:class:`CVaR` (the mean of the worst fraction).  A TOML job names one (``objective.aggregate``) and
:mod:`jaxobs_tuning.strategies` maps the name to the object.
"""

from __future__ import annotations

import abc
import math

import equinox as eqx
import jax
import jax.numpy as jnp

from jaxobs import metrics as M

__all__ = ["AbstractAggregation", "Mean", "SmoothMax", "CVaR"]


class AbstractAggregation(eqx.Module):
    """Per-scenario values (shape (B,), the objective's units) → one scalar to minimise."""

    @abc.abstractmethod
    def __call__(self, values: jax.Array) -> jax.Array:
        """The aggregate of ``values`` (leading axis the scenarios), differentiable in them."""


class Mean(AbstractAggregation):
    """The mean over the scenarios."""

    def __call__(self, values):
        return jnp.mean(values)


class SmoothMax(AbstractAggregation):
    """A smooth worst case: T·log Σ exp(v/T) at T = ``temperature``,
    between the largest value and it plus T·log B (an upper bound of the worst case, tight as T → 0).

    Attributes:
        temperature: T, in the units of the values; None: 1 % of the values' mean magnitude (a constant
            under differentiation).
    """

    temperature: float | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        t = self.temperature
        if t is not None and (isinstance(t, bool) or not isinstance(t, (int, float)) or not 0 < t < math.inf):
            raise ValueError(f"SmoothMax.temperature must be a finite number > 0 or None, got {t!r}")

    def __call__(self, values):
        t = self.temperature
        if t is None:
            t = 0.01 * jax.lax.stop_gradient(jnp.mean(jnp.abs(values)) + 1e-30)
        return M.smooth_max(values, t) + t * jnp.log(values.shape[0])


class CVaR(AbstractAggregation):
    """Conditional value at risk: the mean of the largest ⌈(1 − α)·B⌉ values (at least one).

    Attributes:
        alpha: α, in [0, 1).
    """

    alpha: float = eqx.field(static=True, default=0.9)

    def __check_init__(self):
        a = self.alpha
        if isinstance(a, bool) or not isinstance(a, (int, float)) or not 0 <= a < 1:
            raise ValueError(f"CVaR.alpha must be a number in [0, 1), got {a!r}")

    def __call__(self, values):
        k = max(1, math.ceil((1 - self.alpha) * values.shape[0]))
        return jnp.mean(jnp.sort(values)[-k:])
