"""The frequency-adaptive complex-coefficient LESO of paper 002 (Li et al., eqs 21–28), with the normalized
quadrature PLL of every LESO (:mod:`jaxobs.observers.leso`: the model, the PLL, the sampling).

FA-LESO (eqs 25–28): L1 = −jω̂e − μ, L2 = k1 + k2 s on the complex vector x = xα + j xβ:
x̂2 = −k2 ε1 − k1 z with ż = ε1, and

    ẋ̂1α = x̂2α + b0 uα − μ x̂1α + μ ε1α − ω̂e ε1β,   ẋ̂1β = x̂2β + b0 uβ − μ x̂1β + μ ε1β + ω̂e ε1α

(the −μx̂1 + με1 = −μ i of eq 27 is the known term F).  ê/e = (k2 s + k1)/(s² + (k2 − jω̂e)s + k1).
States [x̂1α, x̂1β, zα, zβ].  ω̂e is the PLL's: the rotation term closes a frequency-adaptation loop
(:mod:`jaxobs.observers.leso`, "PLL").
"""

from __future__ import annotations

from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from .. import papers
from ..core.discretize import AbstractRule
from ..core.validate import as_float
from ._gains import ClosedForm, gain_metadata, gain_row, ki_pll_metadata, kp_pll_metadata
from .leso import _DEFAULT_PLL, _LQ, _RS, AbstractLESO, _common, _pll_design
from .speed import AbstractSpeedEstimator

__all__ = ["FALESO"]


class FALESO(AbstractLESO):
    """Frequency-adaptive complex-coefficient LESO (002 eqs 25–28).

    ê/e = (k2 s + k1)/(s² + (k2 − jω̂e)s + k1); stable iff k1 > 0 and k2 > 0 (002 eq 24).

    Args:
        Rs: Assumed stator resistance, ohm (≥ 0; :meth:`bind` sets it per scenario).
        Lq: Assumed q-axis inductance, H (> 0; :meth:`bind` sets it).
        k1: FA-LESO integral gain, 1/s² (> 0).
        k2: FA-LESO proportional gain, 1/s (> 0).
        kp_pll: The PLL's proportional gain, 1/s (> 0; default: placed at 2π·``papers.LESO_PLL_HZ``, ζ = 1/√2).
        ki_pll: The PLL's integral gain, 1/s² (> 0; default as ``kp_pll``).
        omega0_pll: The PLL's initial speed, rad/s (:meth:`bind` sets it).
        ts: Sample time, s.
        rule: Discretization rule (default :class:`~jaxobs.RK4`).
        e_floor: Floor of |ê| in the PLL's normalized error, V.
        speed: The speed extraction: an estimator, or a record (:func:`~jaxobs.observers.speed.speed_from_spec`);
            default :class:`~jaxobs.observers.speed.PLLSpeed` on ``kp_pll``, ``ki_pll``.
        zero_fade: ω_f, rad/s (≥ 0; 0: the sign detector; module doc, "Through zero speed").

    Raises:
        ValueError: A value out of its range.
    """

    # 002's names: ê/e = (k2 s + k1)/(s² + (k2 − jω̂e)s + k1), so k1 is in s⁻² and k2 in s⁻¹ (001's WIF k1,
    # k2, dimensionless, are other gains: a gain is (class, name), jaxobs.observers.gain_fields)
    Rs: jax.Array
    Lq: jax.Array
    k1: jax.Array = eqx.field(
        metadata=gain_metadata(units="s-2", role="leso", long_name="FA-LESO integral gain", symbol="002: k1")
    )
    k2: jax.Array = eqx.field(
        metadata=gain_metadata(units="s-1", role="leso", long_name="FA-LESO proportional gain", symbol="002: k2")
    )
    kp_pll: jax.Array = eqx.field(metadata=kp_pll_metadata())
    ki_pll: jax.Array = eqx.field(metadata=ki_pll_metadata())
    omega0_pll: jax.Array  # initial PLL speed, rad/s
    speed: AbstractSpeedEstimator  # speed and position extraction (its states follow the LESO's)
    ts: float = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)
    e_floor: float = eqx.field(static=True)
    zero_fade: float = eqx.field(static=True)  # ω_f of the detector's fade through zero, rad/s (0: sign)
    n_leso: ClassVar[int] = 4

    def __init__(
        self,
        Rs: ArrayLike,
        Lq: ArrayLike,
        k1: ArrayLike = papers.FALESO_K1,
        k2: ArrayLike = papers.FALESO_K2,
        kp_pll: ArrayLike = _DEFAULT_PLL[0],
        ki_pll: ArrayLike = _DEFAULT_PLL[1],
        omega0_pll: ArrayLike = 0.0,
        *,
        ts: float = 1e-4,
        rule: AbstractRule | None = None,
        e_floor: float = 1.0,
        speed: AbstractSpeedEstimator | dict[str, Any] | None = None,
        zero_fade: float = 0.0,
    ) -> None:
        _common(self, Rs, Lq, kp_pll, ki_pll, omega0_pll, ts, rule, e_floor, "FALESO", speed, zero_fade)
        # 002 eq (24): stable iff k1 > 0 and k2 > 0 (generalized Routh test): their declared bounds, which
        # check_gains enforces (AbstractObserver)
        self.k1, self.k2 = as_float(k1), as_float(k2)

    @classmethod
    def closed_form_design(
        cls,
        k1: ArrayLike = papers.FALESO_K1,
        k2: ArrayLike = papers.FALESO_K2,
        pll_hz: float = papers.LESO_PLL_HZ,
        Rs: ArrayLike = _RS,
        Lq: ArrayLike = _LQ,
        omega0_pll: ArrayLike = 0.0,
        **kw: Any,
    ) -> ClosedForm:
        """The FA-LESO of 002 Table II (k1 = 10π, k2 = 100π; stable iff k1, k2 > 0, eq 24) with its PLL placed
        at ω_b = 2π·``pll_hz`` (k_p = 2ζω_b, k_i = ω_b², ζ = 1/√2).

        Args:
            k1: integral gain, s⁻² (> 0).
            k2: proportional gain, s⁻¹ (> 0).
            pll_hz: the PLL's bandwidth, Hz (> 0).
            Rs: assumed stator resistance, ohm (>= 0; ``bind`` sets it per scenario).
            Lq: assumed q-axis inductance, H (> 0; ``bind`` sets it).
            omega0_pll: the PLL's initial speed, rad/s (``bind`` sets it).
            **kw: the constructor's keywords.

        Returns:
            The :class:`~jaxobs.observers.ClosedForm`: the :class:`FALESO` and the rows k1, k2 and the PLL's.

        Raises:
            ValueError: a value out of its range.
        """
        kp, ki, pll_rows = _pll_design(cls, pll_hz)
        obs = cls(Rs, Lq, k1, k2, kp, ki, omega0_pll, **kw)
        rows = (
            gain_row(cls, "k1", obs.k1, "chosen: k1 = 10π (stable iff k1 > 0, eq 24)", "002 Table II"),
            gain_row(cls, "k2", obs.k2, "chosen: k2 = 100π (stable iff k2 > 0, eq 24)", "002 Table II"),
            *pll_rows,
        )
        inputs = dict(k1=k1, k2=k2, pll_hz=pll_hz, Rs=Rs, Lq=Lq, omega0_pll=omega0_pll)
        return ClosedForm(obs, inputs, rows, "002 Table II (k1 = 10π, k2 = 100π), PLL pole placement ω_b = 2π·15")

    @classmethod
    def closed_form(cls, **kw: Any) -> FALESO:
        """The observer of :meth:`closed_form_design` (same arguments).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`FALESO`.
        """
        return cls.closed_form_design(**kw).observer

    def leso(self, xl: jax.Array, u: jax.Array, i: jax.Array, w: jax.Array) -> tuple[jax.Array, jax.Array]:
        """The FA-LESO (002 eqs 25–28; module doc) on the complex vector.

        Args:
            xl: [x̂1α, x̂1β, zα, zβ].
            u: The voltage (αβ), V.
            i: The current (αβ), A.
            w: The PLL's speed ω̂, rad/s (the rotation term jω̂ε1).

        Returns:
            ``(dx_leso/dt, ê)``.
        """
        mu, b0 = self.mu, 1.0 / self.Lq
        x1, z = xl[0:2], xl[2:4]
        eps = x1 - i
        x2 = -self.k2 * eps - self.k1 * z
        rot = jnp.stack([-w * eps[1], w * eps[0]])  # j ω̂ ε1
        dx1 = x2 + b0 * u - mu * x1 + mu * eps + rot
        return jnp.concatenate([dx1, eps]), -self.Lq * x2
