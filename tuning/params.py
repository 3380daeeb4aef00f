"""Free gains by name, with bounds and an unconstrained parametrization.

A gain g is optimized through an unconstrained θ:

- ``log = true`` (positive gains): work in z = log g, so multiplicative steps;
- bounds [lo, hi] (in z): z = lo + (hi − lo)·σ(θ); one bound only: z = lo + softplus(θ)
  or z = hi − softplus(θ); no bound: z = θ.

Frozen gains are the component's own values and are never touched: the
parametrization only writes the free ones, with ``eqx.tree_at``.  A name with a
dot is a path into a part the component holds: ``speed.k1`` is the ``k1`` of its
speed estimator (a mechanical model's gain, jaxobs.observers.speed).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TypeVar, cast

import equinox as eqx
import jax
import jax.numpy as jnp

_M = TypeVar("_M", bound=eqx.Module)  # the component a parametrization applies to

__all__ = ["GainSpec", "Parametrization"]


@dataclass(frozen=True)
class GainSpec:
    """One free gain: its name, initial value, bounds and scale (module doc).

    Attributes:
        name: The gain's field name.
        init: Its initial value.
        lower: Its lower bound (in the gain's units), or None.
        upper: Its upper bound (in the gain's units), or None.
        log: Whether to optimize log g (positive gains: multiplicative steps).
    """

    name: str
    init: float
    lower: float | None = None
    upper: float | None = None
    log: bool = True

    def _z_bounds(self):
        f = math.log if self.log else (lambda v: v)
        lo = None if self.lower is None else f(self.lower)
        hi = None if self.upper is None else f(self.upper)
        return lo, hi

    def to_theta(self, g: float) -> float:
        """The unconstrained coordinate of a gain value (the inverse of :meth:`from_theta`).

        Args:
            g: The gain's value, within its bounds.

        Returns:
            Its θ coordinate.
        """
        z = math.log(g) if self.log else g
        lo, hi = self._z_bounds()
        # A gain on its bound (a solver's θ run far out: from about |θ| = 37 the sigmoid rounds to the bound in
        # float64, as a Nelder–Mead expansion reaches) maps to the finite θ of a point _EDGE inside it, not to
        # log 0: the run's result is read back to θ after tuning, which failed there with "math domain error".
        if lo is not None and hi is not None:
            u = min(max((z - lo) / (hi - lo), _EDGE), 1.0 - _EDGE)
            return math.log(u / (1 - u))
        if lo is not None:
            return _softplus_inv(max(z - lo, _EDGE))
        if hi is not None:
            return _softplus_inv(max(hi - z, _EDGE))
        return z

    def from_theta(self, th: jax.Array) -> jax.Array:
        """The gain's value at a θ coordinate: within its bounds, whatever ``th``.

        Args:
            th: The θ coordinate.

        Returns:
            The gain's value.
        """
        lo, hi = self._z_bounds()
        if lo is not None and hi is not None:
            z = lo + (hi - lo) * jax.nn.sigmoid(th)
        elif lo is not None:
            z = lo + jax.nn.softplus(th)
        elif hi is not None:
            z = hi - jax.nn.softplus(th)
        else:
            z = th
        return jnp.exp(z) if self.log else z


def _leaf(component: eqx.Module, name: str) -> jax.Array:
    """The field a gain's name points at: ``name`` itself, or a dotted path into a part (module doc)."""
    node = component
    for part in name.split("."):
        node = getattr(node, part)
    return cast(jax.Array, node)  # a gain's leaf: the parser names only array fields


_EDGE = 1e-15  # how far inside its bounds a gain on a bound is read back (to_theta)


def _softplus_inv(y: float) -> float:
    return y + math.log(-math.expm1(-y))


class Parametrization:
    """Maps an unconstrained vector θ to the free gains of a component.

    Args:
        specs: The free gains (:class:`GainSpec`), in θ's order.
    """

    kept_fields = ("specs",)  # what a kept program that applies it bakes in (jaxobs.kept_jit)

    def __init__(self, specs: list[GainSpec]):
        self.specs = list(specs)
        self.names = [s.name for s in self.specs]

    def theta0(self) -> jax.Array:
        """θ at the gains' initial values."""
        return jnp.asarray([s.to_theta(s.init) for s in self.specs], dtype=jnp.result_type(float))

    def to_theta(self, values: Mapping[str, float]) -> jax.Array:
        """θ at given gain values.

        Args:
            values: Every free gain's value, by name.

        Returns:
            The vector θ.
        """
        return jnp.asarray([s.to_theta(float(values[s.name])) for s in self.specs], dtype=jnp.result_type(float))

    def gains(self, theta: jax.Array) -> dict[str, jax.Array]:
        """The free gains at θ.

        Args:
            theta: The vector θ.

        Returns:
            Each gain's value, by name.
        """
        return {s.name: s.from_theta(theta[i]) for i, s in enumerate(self.specs)}

    def apply(self, component: _M, theta: jax.Array) -> _M:
        """``component`` with its free gains set from θ (each in its field's dtype).

        Args:
            component: The module whose gains are free.
            theta: The vector θ.

        Returns:
            The module with the gains at θ.
        """
        g = self.gains(theta)
        return eqx.tree_at(
            lambda c: tuple(_leaf(c, n) for n in self.names),
            component,
            tuple(jnp.asarray(g[n], dtype=_leaf(component, n).dtype) for n in self.names),
        )

    def values(self, theta: jax.Array) -> dict[str, float]:
        """The free gains at θ as Python floats.

        Args:
            theta: The vector θ.

        Returns:
            Each gain's value, by name.
        """
        return {k: float(v) for k, v in self.gains(theta).items()}
