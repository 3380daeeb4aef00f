"""Fixed-frequency quadrature signal generators: the SOGI-QSG and the second-order SOGI.

Linear time-invariant at a given centre frequency ω' (no FLL): the building
blocks on their own, used to check discretization rules against exact
solutions and as filters in flux observers when the frequency is supplied
from outside.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from .. import papers
from ..core.discretize import AbstractRule, Tustin, check_rule
from ..core.validate import as_float, check_positive, check_sample_time
from ._cores import sogi2_vf, sogi_vf
from ._gains import gain_metadata
from .base import AbstractVectorFieldObserver

__all__ = ["QSGOutput", "SOGI", "SOGI2"]


class QSGOutput(NamedTuple):
    """A quadrature signal generator's outputs at a sample.

    Attributes:
        v_alpha: The in-phase output v' = D(s) v.
        v_beta: The quadrature output qv' = Q(s) v.
    """

    v_alpha: jax.Array  # in-phase output v' = D(s) v
    v_beta: jax.Array  # quadrature output qv' = Q(s) v


class SOGI(AbstractVectorFieldObserver):
    """SOGI-QSG at fixed ω' (000 eqs 12–13; 001 eqs 1–2): D = kω's/(s²+kω's+ω'²).

    Args:
        k: SOGI gain (> 0).
        omega: The fixed centre frequency ω', rad/s (> 0).
        ts: Sample time (s).
        rule: Discretization rule (default :class:`~jaxobs.Tustin`).

    Raises:
        ValueError: A value out of its range.
    """

    k: jax.Array = eqx.field(metadata=gain_metadata(units="1", role="sogi", long_name="SOGI gain", symbol="001: k"))
    omega: jax.Array
    ts: float = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)

    def __init__(
        self, k: ArrayLike, omega: ArrayLike = papers.FLL_OMEGA_N, *, ts: float = 1e-4, rule: AbstractRule | None = None
    ) -> None:
        self.k = as_float(k)  # bounds: check_gains (AbstractObserver)
        self.omega = check_positive("omega", omega, "SOGI")
        self.ts = check_sample_time("ts", ts, "SOGI")
        self.rule = check_rule(Tustin() if rule is None else rule, "SOGI")

    def f(self, x: jax.Array, u: ArrayLike) -> jax.Array:
        """The SOGI (001 eqs 6–7) at ω' = ``omega``.

        Args:
            x: [v', qv'].
            u: The input sample v.

        Returns:
            dx/dt.
        """
        dy, dq = sogi_vf(x[0], x[1], u, self.omega, self.k)
        return jnp.stack([dy, dq])

    def output(self, x: jax.Array) -> QSGOutput:
        """v' and qv' of a state.

        Args:
            x: The flat state.

        Returns:
            The :class:`QSGOutput`.
        """
        return QSGOutput(v_alpha=x[0], v_beta=x[1])

    def initial_state(self) -> jax.Array:
        """Every integrator at 0.

        Returns:
            The flat state.
        """
        return jnp.zeros((2,), dtype=self.omega.dtype)


class SOGI2(AbstractVectorFieldObserver):
    """Second-order SOGI at fixed ω' (000 eqs 17–18), gains K1, K2 in paper 000's naming.

    Args:
        K1: Second-order SOGI error gain (> 0).
        K2: Second-order SOGI damping gain (> 0).
        omega: The fixed centre frequency ω', rad/s (> 0).
        ts: Sample time (s).
        rule: Discretization rule (default :class:`~jaxobs.Tustin`).

    Raises:
        ValueError: A value out of its range.
    """

    K1: jax.Array = eqx.field(
        metadata=gain_metadata(units="1", role="sogi", long_name="second-order SOGI error gain", symbol="000: K1")
    )
    K2: jax.Array = eqx.field(
        metadata=gain_metadata(units="1", role="sogi", long_name="second-order SOGI damping gain", symbol="000: K2")
    )
    omega: jax.Array
    ts: float = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)

    def __init__(
        self,
        K1: ArrayLike,
        K2: ArrayLike,
        omega: ArrayLike = papers.FLL_OMEGA_N,
        *,
        ts: float = 1e-4,
        rule: AbstractRule | None = None,
    ) -> None:
        self.K1, self.K2 = as_float(K1), as_float(K2)  # bounds: check_gains (AbstractObserver)
        self.omega = check_positive("omega", omega, "SOGI2")
        self.ts = check_sample_time("ts", ts, "SOGI2")
        self.rule = check_rule(Tustin() if rule is None else rule, "SOGI2")

    def f(self, x: jax.Array, u: ArrayLike) -> jax.Array:
        """The second-order SOGI (000 eqs 17–18) at ω' = ``omega``.

        Args:
            x: [z_a, z_b, v', qv'].
            u: The input sample v.

        Returns:
            dx/dt.
        """
        return jnp.stack(sogi2_vf(x[0], x[1], x[2], x[3], u, self.omega, k_err=self.K1, k_damp=self.K2))

    def output(self, x: jax.Array) -> QSGOutput:
        """v' and qv' of a state.

        Args:
            x: The flat state.

        Returns:
            The :class:`QSGOutput`.
        """
        return QSGOutput(v_alpha=x[2], v_beta=x[3])

    def initial_state(self) -> jax.Array:
        """Every integrator at 0.

        Returns:
            The flat state.
        """
        return jnp.zeros((4,), dtype=self.omega.dtype)
