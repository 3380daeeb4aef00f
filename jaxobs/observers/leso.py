"""Back-EMF extended state observers of paper 002 (Li et al.): C-LESO, GI-LESO, FA-LESO, each
followed by a normalized quadrature PLL whose ω̂e the GI- and FA-LESO use.  Their contract
(:class:`AbstractLESO`: the PLL, the sampling), the C-LESO and the GI-LESO are here; the complex-coefficient
FA-LESO is :mod:`jaxobs.observers.faleso`'s.

Model (002 eqs 4–8): p i_ab = b0 u_ab − μ i_ab + x2, b0 = 1/L̂q, μ = R̂s/L̂q, x2 = −e_ab/L̂q.
Observer (eq 9), per axis, with ε1 = x̂1 − i:

    p x̂1 = x̂2 + b0 u − μ x̂1 − l1(t) * ε1,      p x̂2 = −l2(t) * ε1,      ê = −L̂q x̂2   (eq 10)

so that ê/e = L2(s)/(s² + (μ + L1(s)) s + L2(s))  (eq 14).

- C-LESO (eqs 15–17): l1 = 2ω0 − μ, l2 = ω0²  →  ω0²/(s + ω0)².  States [x̂1, x̂2] per axis.
- GI-LESO (eqs 29–30): L1 = 2ω0 − μ, L2(s) = ω0² + G(s), G = 2K_r ωc s/(s² + 2ωc s + ω̂e²):
  x̂2 = x̂2a − r with ẋ̂2a = −ω0² ε1 and r = (G/s) ε1, i.e. r̈ = 2K_r ωc ε1 − 2ωc ṙ − ω̂e² r.
  States [x̂1, x̂2a, r, ṙ] per axis (order 4, as 002 says).
- FA-LESO (eqs 25–28): L1 = −jω̂e − μ, L2 = k1 + k2 s on the complex vector x = xα + j xβ:
  x̂2 = −k2 ε1 − k1 z with ż = ε1, and
  ẋ̂1α = x̂2α + b0 uα − μ x̂1α + μ ε1α − ω̂e ε1β,  ẋ̂1β = x̂2β + b0 uβ − μ x̂1β + μ ε1β + ω̂e ε1α
  (the −μx̂1 + με1 = −μ i of eq 27 is the known term F).  ê/e = (k2 s + k1)/(s² + (k2 − jω̂e)s + k1).
  States [x̂1α, x̂1β, zα, zβ].

PLL (our design; 002's PLL section is missing from our copy; the default :class:`~jaxobs.observers.speed.PLLSpeed`
of the speed-estimator strategy the observer holds in ``speed``).  ê = ωe ψ (−sin θe, cos θe)
(002 eq 5), so the normalized quadrature detector

    err = sgn(ω̂e)·(−êα cos θ̂ − êβ sin θ̂)/|ê| = sin(θe − θ̂)

drives a type-2 loop θ̂̇ = ω̂ + k_p err, ω̂̇ = k_i err, tuned by pole placement
(k_p = 2ζω_b, k_i = ω_b², :func:`jaxobs.linear.pll_gains`).  With the FA-LESO in
the loop the phase seen by the PLL is filtered by the FA-LESO's envelope response;
:func:`jaxobs.linear.faleso_pll_loop` builds that loop and the tests check its
stability with the complex Routh test and its phase margin.  ω̂ is fed back to
the GI-LESO's resonance and to the FA-LESO's rotation term: a frequency-adaptation
loop, stable here because the PLL is slower (ω_b = 2π·15 rad/s by default) than
the LESO (k2 = 100π).  Why 15 Hz: 002's speed ramp (4.5°, 13 r/min) pins it — a type-2 PLL's
speed-to-angle error ratio grows with ω_b — and it keeps a wider phase margin through the FA-LESO than 30 Hz
(the ramp's errors and the margins at 15 and 30 Hz: docs/performance.md).  Its price: a
5 Hz speed loop closed through it is barely damped (ζ ≈ 0.07 at 10 Hz), and unstable under field
weakening (:func:`jaxobs.linear.faleso_speed_loop_poles`; docs/papers.md, paper 002's load step).

Through zero speed.  The sign detector's gain is sin(θe − θ̂)·sgn(ωe)·sgn(ω̂): at ω̂ = 0 it jumps from +1 to −1
(the loop flips while the rotor has not yet reversed), and near zero X/|ê| is a full-gain error of an ê that
the LESO's own estimation error dominates.  ``zero_fade = ω_f > 0`` selects instead

    err = X · ω̂|ω̂| / (|ê| (ω̂² + ω_f²)),      X = −êα cos θ̂ − êβ sin θ̂ = ωe ψ sin(θe − θ̂),

i.e. the sign detector times ω̂²/(ω̂² + ω_f²) (sgn(ω̂)·ω̂² = ω̂|ω̂|, continuous and differentiable).
Small-signal gain of the detector, ∂err/∂θe at θ̂ = θe: at speed (|ω̂| ≫ ω_f, ω̂ and ωe of one sign)
1/(1 + ω_f²/ω̂²) → 1, the loop as designed (k_p, k_i placed on a unit gain); near standstill ω̂²/ω_f² → 0: the
loop opens smoothly instead of flipping, and the speed estimator runs on what it holds.  At ω̂ = 0 exactly
the error is 0.  What that means for the speed estimator (:mod:`jaxobs.observers.speed`):

- a PLL's ω̂̇ = k_i err is then ∝ ω̂|ω̂| near zero, so ω̂ = 0 is invariant: the PLL alone cannot carry ω̂ through
  zero.  Under a speed ramp of rate a (rad/s², electrical) its type-2 loop needs err = −a/k_i, which the fade
  can give only while |ω̂| > ω_f √(a/k_i) (for a/k_i ≪ 1); below that ω̂ lags, decays towards 0 without crossing
  it (ω̂̇ ∝ −ω̂²), the rotor crosses zero alone and the detector's sgn(ωe ω̂) = −1 drives the angle away
  (tests/test_zero_speed.py: ω̂ never below 0 while the rotor reaches −300 r/min).  The sign detector slips
  by π at the flip instead.  A back-EMF observer holds no information at ωe = 0 (ê = 0), and a PLL has no
  model to bridge the gap;
- a mechanical-model speed observer (:class:`~jaxobs.observers.speed.MechanicalSpeed`) carries ω̂ and θ̂
  through on the torque reference and the assumed inertia (and, without a torque reference, on its
  acceleration state), and the faded detector re-engages it on the other side (tests/test_zero_speed.py
  measures the reversal).

``zero_fade`` is 0 by default: the fade moves every result at speed by ω_f²/ω̂² relative (2 % of the PLL's gain
at ω̂ = 7 ω_f), so 002's reproductions and the presets keep the sign detector, which 002's operating points
(300–840 r/min, one direction) never take through zero; ``zero_fade`` is static (it picks the detector's
form), so with 0 the step is the old one bit for bit.

Sampling.  Like the flux observers, at t_k the observer integrates the period
[t_{k−1}, t_k] with the voltage applied over it (held) and the current
interpolated linearly between its samples, and returns the estimate at t_k.
"""

from __future__ import annotations

import abc
import math
from typing import Any, ClassVar, NamedTuple, Self

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from .. import papers
from ..core.discretize import RK4, AbstractRule, Knots, check_rule
from ..core.measurements import DriveInput
from ..core.numerics import safe_atan2, wrap
from ..core.validate import as_float, check_nonnegative, check_positive, check_sample_time
from ._gains import ClosedForm, DesignRow, gain_metadata, gain_row, ki_pll_metadata, kp_pll_metadata
from ._rules import cleso_gains, pll_gains
from .base import AbstractDriveObserver, AssumedMachine, BoundFields, DriveObserverState, replace_leaves
from .speed import AbstractSpeedEstimator, speed_from_spec

__all__ = ["LESOOutput", "AbstractLESO", "CLESO", "GILESO"]


class LESOOutput(NamedTuple):
    """A LESO's outputs at a sample.

    Attributes:
        e_a: The estimated equivalent BEMF, α, V.
        e_b: The estimated equivalent BEMF, β, V.
        theta: θ̂e from the PLL, rad (wrapped).
        omega: ω̂e from the PLL, rad/s.
        theta_emf: The BEMF's own angle, atan2(−êα, êβ) (positive rotation), rad.
    """

    e_a: jax.Array  # estimated equivalent BEMF, V
    e_b: jax.Array
    theta: jax.Array  # θ̂e from the PLL, rad (wrapped)
    omega: jax.Array  # ω̂e from the PLL, rad/s
    theta_emf: jax.Array  # the BEMF's own angle, atan2(−êα, êβ) (positive rotation), rad


class AbstractLESO(AbstractDriveObserver):
    """A LESO of 002 followed by the normalized quadrature PLL (module doc).

    Subclasses give the LESO part (:meth:`leso`) and its number of states ``n_leso``; the PLL's θ̂ and ω̂
    follow them in the state.  The model (002 eqs 4–8) is written in the q-axis inductance: bound to a
    machine a LESO takes Lq (the extended EMF absorbs the saliency), and its PLL starts at the signed ω_e.

    Attributes:
        Rs: Assumed stator resistance, ohm (:meth:`bind` sets it).
        Lq: Assumed q-axis inductance, H (:meth:`bind` sets it).
        kp_pll: The PLL's proportional gain, 1/s.
        ki_pll: The PLL's integral gain, 1/s².
        omega0_pll: The PLL's initial speed, rad/s (:meth:`bind` sets it).
        ts: Sample time, s.
        rule: Discretization rule.
        e_floor: Floor of |ê| in the PLL's normalized error, V.
        speed: The speed and position extraction (:class:`~jaxobs.observers.speed.PLLSpeed`, the default, or
            :class:`~jaxobs.observers.speed.MechanicalSpeed`); its states follow the LESO's.
        zero_fade: ω_f of the phase detector's fade through zero speed, rad/s (0: the sign detector; module doc).
        n_leso: The LESO's states (the speed estimator's follow; a class attribute).
    """

    Rs: eqx.AbstractVar[jax.Array]
    Lq: eqx.AbstractVar[jax.Array]
    kp_pll: eqx.AbstractVar[jax.Array]
    ki_pll: eqx.AbstractVar[jax.Array]
    omega0_pll: eqx.AbstractVar[jax.Array]
    ts: eqx.AbstractVar[float]
    rule: eqx.AbstractVar[AbstractRule]
    e_floor: eqx.AbstractVar[float]
    speed: eqx.AbstractVar[AbstractSpeedEstimator]
    zero_fade: eqx.AbstractVar[float]
    n_leso: eqx.AbstractClassVar[int]  # LESO states (the speed estimator's follow)

    bound_fields: ClassVar[BoundFields] = BoundFields(resistance="Rs", inductance="Lq", speed="omega0_pll")
    takes_speed_estimator: ClassVar[bool] = True

    def speed_estimator(self) -> AbstractSpeedEstimator:
        """The speed extraction this observer holds (``speed``).

        Returns:
            The :class:`~jaxobs.observers.speed.AbstractSpeedEstimator`.
        """
        return self.speed

    def bind(self, est_par: AssumedMachine | None, omega_e: ArrayLike) -> Self:
        """This LESO assuming ``est_par``'s Rs and Lq (and its speed estimator the machine's mechanics), its PLL
        starting at the signed ω_e (:meth:`AbstractDriveObserver.bind`).

        Args:
            est_par: The machine assumed, or None (the speed only).
            omega_e: The electrical speed, rad/s, signed.

        Returns:
            The bound observer.
        """
        if est_par is None:
            return replace_leaves(self, omega0_pll=omega_e)
        new = replace_leaves(self, Rs=est_par.Rs, Lq=est_par.Lq, omega0_pll=omega_e)
        speed = self.speed.bind(est_par)  # a mechanical model takes the assumed Ĵ, B̂, p; a PLL has none
        return new if speed is self.speed else eqx.tree_at(lambda o: o.speed, new, speed)

    def initial_state(self) -> jax.Array:
        """The LESO's states at 0, then the speed estimator's (θ̂ = 0, ω̂ = ``omega0_pll``).

        Returns:
            The flat state.
        """
        z = jnp.zeros((self.n_leso,), self.Rs.dtype)
        return jnp.concatenate([z, self.speed.initial_state(jnp.zeros_like(self.Rs), self.omega0_pll)])

    def init(self, u0: Any = None) -> DriveObserverState:
        """The state at sample 0: :meth:`initial_state`, nothing seen yet.

        Args:
            u0: Unused (the first period starts at the first sample).

        Returns:
            The :class:`DriveObserverState`.
        """
        return self._init_from(self.initial_state())

    def init_at(self, omega_e: ArrayLike) -> DriveObserverState:
        """The initial state with the PLL's speed at ω_e: the start of a drive's settling phase.

        Args:
            omega_e: ω_e, rad/s.

        Returns:
            The :class:`DriveObserverState`.
        """
        return self._init_from(self.initial_state().at[self.n_leso + 1].set(omega_e))

    def init_aligned(self, omega_e: ArrayLike, theta_e: ArrayLike) -> DriveObserverState:
        """:meth:`init_at` with the PLL's angle at the rotor's θ_e (rad) too: a steady start's settling phase.

        From θ̂ = 0 the PLL's first error would be wherever the rotor happened to be when the phase began
        (θ_e0 − ω_e·settle, any angle), and near 180° (the sine detector's unstable point) it pulls in slowly
        and erratically, so the observer a steady start hands over would depend on the settle's length
        (docs/performance.md).

        Args:
            omega_e: ω_e, rad/s.
            theta_e: θ_e, rad.

        Returns:
            The :class:`DriveObserverState`.
        """
        x0 = self.initial_state().at[self.n_leso].set(wrap(theta_e))
        return self._init_from(x0.at[self.n_leso + 1].set(omega_e))

    def seed_speed(self, state: DriveObserverState, omega_e: ArrayLike) -> DriveObserverState:
        """``state`` with the PLL's speed set to ω_e: an I-f start-up holds it at the I-f frequency until the
        hand-over (jaxobs.drive.ClosedLoop).

        Args:
            state: The :class:`DriveObserverState`.
            omega_e: ω_e, rad/s.

        Returns:
            The state with the PLL's speed set.
        """
        return eqx.tree_at(lambda s: s.x, state, state.x.at[self.n_leso + 1].set(omega_e))

    def _init_from(self, x0: jax.Array) -> DriveObserverState:
        z2 = jnp.zeros((2,), x0.dtype)
        inp0 = (z2, z2, jnp.zeros((), x0.dtype))
        return DriveObserverState(
            x=x0, rule=self.rule.init(self.f, x0, inp0), i_prev=z2, u_prev=z2, started=jnp.asarray(False)
        )

    @abc.abstractmethod
    def leso(self, xl: jax.Array, u: jax.Array, i: jax.Array, w: jax.Array) -> tuple[jax.Array, jax.Array]:
        """The LESO part.

        Args:
            xl: The LESO's states.
            u: The voltage (αβ), V.
            i: The current (αβ), A.
            w: The PLL's speed ω̂, rad/s.

        Returns:
            ``(dx_leso/dt, ê)``.
        """

    def phase_error(self, e: jax.Array, th: jax.Array, w: jax.Array) -> jax.Array:
        """The phase detector (module doc, "Through zero speed"): ≈ sin(θe − θ̂) at speed.

        Args:
            e: ê (αβ), V.
            th: θ̂, rad.
            w: ω̂, rad/s.

        Returns:
            ε: sgn(ω̂)·X/|ê| (``zero_fade`` 0), or X·ω̂|ω̂|/(|ê|(ω̂² + ω_f²)), X = −êα cos θ̂ − êβ sin θ̂.
        """
        mag = jnp.sqrt(jnp.maximum(e[0] * e[0] + e[1] * e[1], self.e_floor**2))
        if self.zero_fade == 0.0:
            return jnp.where(w < 0, -1.0, 1.0) * (-e[0] * jnp.cos(th) - e[1] * jnp.sin(th)) / mag
        fade = w * jnp.abs(w) / (w * w + self.zero_fade**2)
        return fade * (-e[0] * jnp.cos(th) - e[1] * jnp.sin(th)) / mag

    def f(self, x: jax.Array, inp: tuple[jax.Array, jax.Array, jax.Array]) -> jax.Array:
        """The LESO's and the speed estimator's vector field.

        Args:
            x: The flat state: the LESO's ``n_leso`` states, then the speed estimator's.
            inp: ``(u, i, torque)``: the voltage (αβ), V, the current (αβ), A, and the torque reference, N·m.

        Returns:
            dx/dt.
        """
        u, i, torque = inp
        xl, xs = x[: self.n_leso], x[self.n_leso :]
        dxl, e = self.leso(xl, u, i, xs[1])
        err = self.phase_error(e, xs[0], xs[1])
        return jnp.concatenate([dxl, self.speed.vf(self, xs, err, torque)])

    def step(self, state: DriveObserverState, meas: DriveInput) -> tuple[DriveObserverState, LESOOutput]:
        """One sample: the period that ends now integrated (module doc, "Sampling"), and the outputs at t_k.

        Args:
            state: The state at the previous sample.
            meas: The measurements at this sample.

        Returns:
            ``(the state at this sample, the outputs at t_k)``.
        """
        i = jnp.stack([meas.i_a, meas.i_b])
        tq = meas.T_ref  # the torque reference over the period; none given: 0
        tq = jnp.zeros((), state.x.dtype) if tq is None else jnp.asarray(tq, state.x.dtype)
        path = Knots(
            u0=(state.u_prev, state.i_prev, tq),
            um=(state.u_prev, 0.5 * (i + state.i_prev), tq),
            u1=(state.u_prev, i, tq),
        )
        x1, rs = self.rule.step(self.f, state.x, path, self.ts, state.rule)
        x1 = jnp.where(state.started, x1, state.x)
        x1 = x1.at[self.n_leso].set(wrap(x1[self.n_leso]))
        new = DriveObserverState(
            x=x1, rule=rs, i_prev=i, u_prev=jnp.stack([meas.u_a, meas.u_b]), started=jnp.asarray(True)
        )
        _, e = self.leso(x1[: self.n_leso], new.u_prev, i, x1[self.n_leso + 1])
        out = LESOOutput(
            e_a=e[0], e_b=e[1], theta=x1[self.n_leso], omega=x1[self.n_leso + 1], theta_emf=safe_atan2(-e[0], e[1])
        )
        return new, out

    @property
    def mu(self) -> jax.Array:
        """μ = R̂s/L̂q, 1/s (002 eq 8)."""
        return self.Rs / self.Lq


def _common(
    obj: AbstractLESO,
    Rs: ArrayLike,
    Lq: ArrayLike,
    kp_pll: ArrayLike,
    ki_pll: ArrayLike,
    omega0_pll: ArrayLike,
    ts: float,
    rule: AbstractRule | None,
    e_floor: float,
    name: str,
    speed: AbstractSpeedEstimator | dict[str, Any] | None,
    zero_fade: float,
) -> None:
    obj.Rs = check_nonnegative("Rs", Rs, name)
    obj.Lq = check_positive("Lq", Lq, name)
    obj.kp_pll, obj.ki_pll = as_float(kp_pll), as_float(ki_pll)  # bounds: check_gains (AbstractObserver)
    obj.omega0_pll = jnp.asarray(omega0_pll, dtype=obj.Rs.dtype)
    obj.ts = check_sample_time("ts", ts, name)
    obj.rule = check_rule(RK4() if rule is None else rule, name)
    obj.e_floor = float(e_floor)
    obj.speed = speed_from_spec(speed, f"{name}.speed", obj.ts)
    # static (it picks the detector's form): a Python number, checked here as the sample time is
    zf = float(zero_fade)
    if not math.isfinite(zf) or zf < 0:
        raise ValueError(
            f"{name}.zero_fade must be a finite number of rad/s >= 0 (0: the sign detector), got {zero_fade!r}"
        )
    obj.zero_fade = zf


# The PLL defaults: pole placement at ω_b = 2π·papers.LESO_PLL_HZ with ζ = papers.PLL_ZETA = 1/√2, so a LESO's
# defaults are its closed form exactly.
_DEFAULT_PLL = pll_gains(2 * math.pi * papers.LESO_PLL_HZ)
_RS, _LQ = papers.IPMSM_002["Rs"], papers.IPMSM_002["Lq"]


def _omega0() -> dict[str, Any]:
    return gain_metadata(units="rad s-1", role="leso", long_name="LESO bandwidth", symbol="002: ω0")


def _pll_design(cls: type, pll_hz: float) -> tuple[float, float, tuple[DesignRow, ...]]:
    """The LESOs' PLL placed at ω_b = 2π·``pll_hz`` (ζ = 1/√2, ours: 002's PLL section is missing from our copy):
    its gains and rows."""
    check_positive("pll_hz", pll_hz, f"{cls.__name__}.closed_form")
    kp, ki = (float(g) for g in pll_gains(2 * math.pi * pll_hz))
    src = "ours (module doc: 002's ramp pins 15 Hz)"
    rows = (
        gain_row(cls, "kp_pll", kp, "k_p = 2ζω_b, ω_b = 2π·pll_hz, ζ = 1/√2", src),
        gain_row(cls, "ki_pll", ki, "k_i = ω_b²", src),
    )
    return kp, ki, rows


def _eq16_rows(omega0: ArrayLike, Rs: ArrayLike, Lq: ArrayLike) -> tuple[DesignRow, DesignRow]:
    """002 eq (16)'s l1, l2 at the assumed machine (μ = Rs/Lq): rows of the C- and GI-LESO's designs."""
    l1, l2 = cleso_gains(as_float(omega0), as_float(Rs) / as_float(Lq))
    return (
        DesignRow("l1", l1, "s-1", "l1 = 2ω0 − μ, μ = Rs/Lq", "002 eq (16)"),
        DesignRow("l2", l2, "s-2", "l2 = ω0²", "002 eq (16)"),
    )


class CLESO(AbstractLESO):
    """Conventional LESO (002 eqs 15–17), gains from the bandwidth ω0: l1 = 2ω0 − μ, l2 = ω0².

    Args:
        Rs: Assumed stator resistance, ohm (≥ 0; :meth:`bind` sets it per scenario).
        Lq: Assumed q-axis inductance, H (> 0; :meth:`bind` sets it).
        omega0: LESO bandwidth ω0, rad/s (> 0).
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

    Rs: jax.Array
    Lq: jax.Array
    omega0: jax.Array = eqx.field(metadata=_omega0())
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
        omega0: ArrayLike = papers.LESO_OMEGA0,
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
        _common(self, Rs, Lq, kp_pll, ki_pll, omega0_pll, ts, rule, e_floor, "CLESO", speed, zero_fade)
        self.omega0 = as_float(omega0)

    @classmethod
    def closed_form_design(
        cls,
        omega0: ArrayLike = papers.LESO_OMEGA0,
        pll_hz: float = papers.LESO_PLL_HZ,
        Rs: ArrayLike = _RS,
        Lq: ArrayLike = _LQ,
        omega0_pll: ArrayLike = 0.0,
        **kw: Any,
    ) -> ClosedForm:
        """The C-LESO of 002 Table II (ω0 = 500π; l1 = 2ω0 − μ, l2 = ω0², eq 16) with its PLL placed at
        ω_b = 2π·``pll_hz`` (k_p = 2ζω_b, k_i = ω_b², ζ = 1/√2).

        Args:
            omega0: LESO bandwidth, rad/s (> 0).
            pll_hz: the PLL's bandwidth, Hz (> 0).
            Rs: assumed stator resistance, ohm (>= 0; ``bind`` sets it per scenario; the rows' μ = Rs/Lq).
            Lq: assumed q-axis inductance, H (> 0; ``bind`` sets it).
            omega0_pll: the PLL's initial speed, rad/s (``bind`` sets it).
            **kw: the constructor's keywords.

        Returns:
            The :class:`~jaxobs.observers.ClosedForm`: the :class:`CLESO` and the rows ω0, eq (16)'s l1 and l2
            at Rs/Lq, and the PLL's.

        Raises:
            ValueError: a value out of its range.
        """
        kp, ki, pll_rows = _pll_design(cls, pll_hz)
        obs = cls(Rs, Lq, omega0, kp, ki, omega0_pll, **kw)
        rows = (
            gain_row(cls, "omega0", obs.omega0, "chosen: ω0 = 500π", "002 Table II"),
            *_eq16_rows(obs.omega0, obs.Rs, obs.Lq),
            *pll_rows,
        )
        inputs = dict(omega0=omega0, pll_hz=pll_hz, Rs=Rs, Lq=Lq, omega0_pll=omega0_pll)
        return ClosedForm(obs, inputs, rows, "002 Table II (ω0 = 500π), PLL pole placement ω_b = 2π·15")

    @classmethod
    def closed_form(cls, **kw: Any) -> CLESO:
        """The observer of :meth:`closed_form_design` (same arguments).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`CLESO`.
        """
        return cls.closed_form_design(**kw).observer

    def leso(self, xl: jax.Array, u: jax.Array, i: jax.Array, w: jax.Array) -> tuple[jax.Array, jax.Array]:
        """The C-LESO (002 eqs 9, 15–16), per axis.

        Args:
            xl: [x̂1α, x̂1β, x̂2α, x̂2β].
            u: The voltage (αβ), V.
            i: The current (αβ), A.
            w: The PLL's speed ω̂, rad/s (unused: the C-LESO has no internal model of ω̂).

        Returns:
            ``(dx_leso/dt, ê)``.
        """
        mu, b0 = self.mu, 1.0 / self.Lq
        l1, l2 = cleso_gains(self.omega0, mu)  # 002 eq (16)
        x1, x2 = xl[0:2], xl[2:4]
        eps = x1 - i
        dx1 = x2 + b0 * u - mu * x1 - l1 * eps
        dx2 = -l2 * eps
        return jnp.concatenate([dx1, dx2]), -self.Lq * x2


class GILESO(AbstractLESO):
    """LESO with a generalized integrator at ω̂e in its internal model (002 eqs 29–30).

    Args:
        Rs: Assumed stator resistance, ohm (≥ 0; :meth:`bind` sets it per scenario).
        Lq: Assumed q-axis inductance, H (> 0; :meth:`bind` sets it).
        omega0: LESO bandwidth ω0, rad/s (> 0).
        K_r: Generalized integrator gain, 1/s² (> 0; default 2ω0²).
        omega_c: Generalized integrator damping ωc, rad/s (> 0).
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

    Rs: jax.Array
    Lq: jax.Array
    omega0: jax.Array = eqx.field(metadata=_omega0())
    K_r: jax.Array = eqx.field(
        metadata=gain_metadata(units="s-2", role="leso", long_name="generalized integrator gain", symbol="002: K_r")
    )
    omega_c: jax.Array = eqx.field(
        metadata=gain_metadata(
            units="rad s-1", role="leso", long_name="generalized integrator damping", symbol="002: ωc"
        )
    )
    kp_pll: jax.Array = eqx.field(metadata=kp_pll_metadata())
    ki_pll: jax.Array = eqx.field(metadata=ki_pll_metadata())
    omega0_pll: jax.Array  # initial PLL speed, rad/s
    speed: AbstractSpeedEstimator  # speed and position extraction (its states follow the LESO's)
    ts: float = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)
    e_floor: float = eqx.field(static=True)
    zero_fade: float = eqx.field(static=True)  # ω_f of the detector's fade through zero, rad/s (0: sign)
    n_leso: ClassVar[int] = 8

    def __init__(
        self,
        Rs: ArrayLike,
        Lq: ArrayLike,
        omega0: float | jax.Array = papers.LESO_OMEGA0,
        K_r: ArrayLike | None = None,
        omega_c: ArrayLike = papers.GILESO_OMEGA_C,
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
        _common(self, Rs, Lq, kp_pll, ki_pll, omega0_pll, ts, rule, e_floor, "GILESO", speed, zero_fade)
        self.omega0 = as_float(omega0)
        self.K_r = as_float(2 * float(omega0) ** 2 if K_r is None else K_r)
        self.omega_c = as_float(omega_c)

    @classmethod
    def closed_form_design(
        cls,
        omega0: float | jax.Array = papers.LESO_OMEGA0,
        K_r: ArrayLike = papers.GILESO_K_R,
        omega_c: ArrayLike = papers.GILESO_OMEGA_C,
        pll_hz: float = papers.LESO_PLL_HZ,
        Rs: ArrayLike = _RS,
        Lq: ArrayLike = _LQ,
        omega0_pll: ArrayLike = 0.0,
        **kw: Any,
    ) -> ClosedForm:
        """The GI-LESO of 002 Table II (ω0 = 500π, K_r = 2ω0², ωc = π; eqs 29–30) with its PLL placed at
        ω_b = 2π·``pll_hz`` (k_p = 2ζω_b, k_i = ω_b², ζ = 1/√2).

        Args:
            omega0: LESO bandwidth, rad/s (> 0).
            K_r: generalized integrator gain, s⁻² (> 0).
            omega_c: generalized integrator damping, rad/s (> 0).
            pll_hz: the PLL's bandwidth, Hz (> 0).
            Rs: assumed stator resistance, ohm (>= 0; ``bind`` sets it per scenario; the rows' μ = Rs/Lq).
            Lq: assumed q-axis inductance, H (> 0; ``bind`` sets it).
            omega0_pll: the PLL's initial speed, rad/s (``bind`` sets it).
            **kw: the constructor's keywords.

        Returns:
            The :class:`~jaxobs.observers.ClosedForm`: the :class:`GILESO` and the rows ω0, K_r, ωc, eq (16)'s
            l1 and l2 (its L1 and L2's constant part, eq 29) and the PLL's.

        Raises:
            ValueError: a value out of its range.
        """
        kp, ki, pll_rows = _pll_design(cls, pll_hz)
        obs = cls(Rs, Lq, omega0, K_r, omega_c, kp, ki, omega0_pll, **kw)
        table = "002 Table II"
        rows = (
            gain_row(cls, "omega0", obs.omega0, "chosen: ω0 = 500π", table),
            gain_row(cls, "K_r", obs.K_r, "chosen: K_r = 2ω0²", table),
            gain_row(cls, "omega_c", obs.omega_c, "chosen: ωc = π", table),
            *_eq16_rows(obs.omega0, obs.Rs, obs.Lq),
            *pll_rows,
        )
        inputs = dict(omega0=omega0, K_r=K_r, omega_c=omega_c, pll_hz=pll_hz, Rs=Rs, Lq=Lq, omega0_pll=omega0_pll)
        return ClosedForm(
            obs, inputs, rows, "002 Table II (ω0 = 500π, K_r = 2ω0², ωc = π), PLL pole placement ω_b = 2π·15"
        )

    @classmethod
    def closed_form(cls, **kw: Any) -> GILESO:
        """The observer of :meth:`closed_form_design` (same arguments).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`GILESO`.
        """
        return cls.closed_form_design(**kw).observer

    def leso(self, xl: jax.Array, u: jax.Array, i: jax.Array, w: jax.Array) -> tuple[jax.Array, jax.Array]:
        """The GI-LESO (002 eqs 29–30; module doc), per axis.

        Args:
            xl: [x̂1α, x̂1β, x̂2aα, x̂2aβ, rα, rβ, ṙα, ṙβ].
            u: The voltage (αβ), V.
            i: The current (αβ), A.
            w: The PLL's speed ω̂, rad/s (the generalized integrator's resonance).

        Returns:
            ``(dx_leso/dt, ê)``.
        """
        mu, b0 = self.mu, 1.0 / self.Lq
        l1, l2 = cleso_gains(self.omega0, mu)  # 002 eq (29): L1 and the constant part of L2 are eq (16)'s
        x1, x2a, r, rd = xl[0:2], xl[2:4], xl[4:6], xl[6:8]
        eps = x1 - i
        x2 = x2a - r
        dx1 = x2 + b0 * u - mu * x1 - l1 * eps
        dx2a = -l2 * eps
        drd = 2 * self.K_r * self.omega_c * eps - 2 * self.omega_c * rd - w * w * r
        return jnp.concatenate([dx1, dx2a, rd, drd]), -self.Lq * x2
