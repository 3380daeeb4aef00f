"""Rotor-flux observers of paper 000 (Xu et al., TPEL 2018): pure integrator, LPF,
SOIFO and second-order SOIFO, with position from atan2 (eq 4) and speed from an
FLL (SOIFO types) or a PLL (integrator and LPF).

Back EMF (000 eq 6), computed on the DSP's samples.  At t_k the observer knows
the currents i_k, i_{k−1} and the voltage u_{k−1} that was applied over
[t_{k−1}, t_k] (it remembers the voltage it was told one period earlier).  The
period's average back EMF is then, to O(T_s²),

    e_{k−½} = u_{k−1} − R̂s (i_k + i_{k−1})/2 − L̂ (i_k − i_{k−1})/T_s,

and the observer integrates its filter over [t_{k−1}, t_k] with that value held
(by RK4 by default; ``rule=jaxobs.Tustin()`` gives the paper's trapezoidal
method on the continuous model, and ``SecondOrderSOIFO(discretization="paper")``
its printed difference equations).
So the estimate it returns at t_k is the estimate *at* t_k from data up to t_k:
no extra sampling delay is built in.  (Using the voltage about to be applied,
u_k, with the backward current difference would mix two periods and, at
2000 r/min, misplace e by ω_e T_s ≈ 0.06 rad.)

Two axes, one FLL.  For the SOIFO types the α and β back EMFs each go through
their own (real-coefficient) SOGI or second-order SOGI, and one FLL adapts
both centre frequencies, its error summed over the axes and normalized by
V̂α² + V̂β² (floored at |ê|², see ``_fll_norm``).  We chose this over a complex (αβ) SOGI because it keeps paper 000's
per-axis transfer functions (Table III, eqs 15–21, 29, 36), which are what the
paper analyses and what we test; and because for a balanced input the summed
FLL error has no double-frequency term, so ω̂ is ripple-free in steady state.
The linearized FLL is the same as the single-phase one (λ/2 per rad of phase
error).  A SOGI cannot tell the direction of rotation: ω̂ from the FLL is |ωe|
and its sign is taken from the rotation of the estimated flux,
sign(ψ̂α ê′β − ψ̂β ê′α) with ê′ the filtered back EMF (≈ dψ/dt).

Flux outputs: SOIFO ψ̂ = qv′/ω̂ (eq 15), second-order SOIFO ψ̂ = qv′/ω̂ (eq 20),
with qv′ the quadrature output of the (second-order) SOGI on ê.

Frequency-normalized FLL gain.  000 draws an FLL with a gain Γ (Figs. 3–4) but
gives no equation for it.  A drive sweeps ωe over 100:1 (20 → 2000 r/min); with
a fixed λ the FLL's characteristic polynomial s² + (kω̂/2)s + λ/2 (001 eq 21)
loses its damping at low speed, and in simulation the FLL ran away after a
start-up transient (ω̂ fell to 57 rad/s, then climbed past 3000 rad/s).  So the
flux observers' ``lam`` is *dimensionless*: the FLL gain is λ(ω̂) = lam·ω̂², the
frequency normalization of Rodriguez et al., which keeps every root of the
FLL's small-signal polynomial proportional to ω̂ and the damping independent
of speed.  001's damping rule λ = k²ωn²/4 becomes lam = k²/4 (ζ = 1/√2 at every
speed); the WIF's symmetric optimum λ = 2ωc²/b becomes lam = 2(ωc/ω̂)²/b.

Salient machines: the active flux (Boldea, Paicu, Andreescu, "Active flux concept for motion-sensorless
unified AC drives", IEEE Trans. Power Electron. 23(5), 2008).  In the rotor frame ψs = (Ld i_d + ψf) + j Lq i_q,
so ψs − Lq i = (ψf + (Ld − Lq) i_d) e^{jθe}: the "active flux" ψa, aligned with the rotor's d axis on any PMSM.
Bound to a machine, an observer takes L̂ = L̂q (:meth:`AbstractFluxObserver.bind`), so the back EMF it filters,
u − R̂s i − L̂q di/dt = dψa/dt, is the active flux's, and θ̂ = atan2(ψ̂β, ψ̂α) is θe on a salient machine as on
000's non-salient one (where Lq = Ld, ψa = ψf and nothing changes).  What that changes for 000's closed forms:

- the filters (SOGI, second-order SOGI, LPF, integrator) are linear in e: their transfer functions (000 Table
  III, eqs 15–21) and the angle they give at a steady point are unchanged;
- the FLL is normalized by V̂² (``_fll_norm``) and its gain by ω̂² (above), the PLLs by |ψ̂|: none depends on the
  flux amplitude, so the closed forms (001's damping rule, the WIF's symmetric optimum, the PLL's placement)
  hold at every steady operating point as derived;
- but the amplitude |ψa| = |ψf + (Ld − Lq) i_d| moves with i_d: under i_d* = 0 it is ψf (000's analysis holds
  as is), under MTPA (Lq > Ld, i_d < 0) it falls with the load, and a step of i_d steps it.  The flux outputs
  are then ψa, not ψf; a load step is an amplitude step (Ld − Lq)Δi_d of the filtered signal, which the
  filters pass with their own step response — a transient angle error that 000's analysis (a constant
  amplitude) does not cover, and the stability maps of docs/stability.md, drawn at constant amplitude,
  do not either.  A machine whose ψa nears zero (strong saliency at high −i_d) leaves only the floors.

Names.  ``lam`` keeps the name of the FLL gain it normalizes (001's λ, which 000's Γ draws): it is the same
gain of the same loop, divided by ω̂², so it keeps the name and carries its own unit ("1", against the
FLLs' rad²/s²) in its field's metadata (:func:`jaxobs.observers.gain_fields`); a gain is (class, name).  The
speed the FLL or PLL starts from is ``omega_init``: 002's ω0 names a LESO's bandwidth, a gain, while this is
a bound field (``bind`` sets it per scenario), so it takes a name no gain has.  The constructors accept
``omega0=`` for it, as job files and result.json files written with that key give it.
"""

from __future__ import annotations

import abc
import math
from typing import ClassVar, Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .. import papers
from ..core.discretize import RK4, AbstractRule, check_rule
from ..core.numerics import safe_atan2
from ..core.validate import as_float, check_nonnegative, check_positive, check_sample_time
from ._cores import quadrature_error, safe_sq_amplitude, sogi2_tustin_coefficients, sogi2_vf, sogi_vf
from ._gains import ClosedForm, gain, gain_row
from ._rules import pll_gains, second_order_soifo_lambda, soifo_lambda
from .base import AbstractDriveObserver, BoundFields, DriveObserverState, replace_leaves
from .speed import AbstractSpeedEstimator, speed_from_spec

__all__ = ["FluxOutput", "AbstractFluxObserver", "PureIntegratorFlux", "LPFFlux", "SOIFO", "SecondOrderSOIFO"]


class FluxOutput(NamedTuple):
    """A flux observer's outputs at a sample.

    Attributes:
        psi_a: The estimated rotor flux, α, Wb.
        psi_b: The estimated rotor flux, β, Wb.
        theta: θ̂e = atan2(ψ̂β, ψ̂α), rad (000 eq 4).
        omega: ω̂e, rad/s (signed).
        e_a: The α back EMF fed to the filter over the last period, V.
        e_b: The β back EMF, V.
    """

    psi_a: jax.Array  # estimated rotor flux, α, Wb
    psi_b: jax.Array  # estimated rotor flux, β, Wb
    theta: jax.Array  # θ̂e = atan2(ψ̂β, ψ̂α), rad (000 eq 4)
    omega: jax.Array  # ω̂e, rad/s (signed)
    e_a: jax.Array  # back EMF fed to the filter over the last period, V
    e_b: jax.Array


class AbstractFluxObserver(AbstractDriveObserver):
    """A flux observer of 000: the back EMF (module doc) fed to a filter, with an FLL or a PLL for the speed.

    Subclasses give the filter (``f``, ``output``, ``initial_state``), where their speed estimate sits in
    the state (``_speed_index``) and the speed they start from (:meth:`start_speed`).  The model has one
    inductance ``L``: bound to a machine it takes the q-axis one, L̂q, so that on a salient machine the flux it
    integrates is the active flux ψa = ψf + (Ld − Lq) i_d along the rotor's d axis (module doc, "Salient
    machines"); on 000's non-salient machine Lq = Ld and nothing changes.

    Attributes:
        Rs: Assumed stator resistance, ohm (:meth:`bind` sets it).
        L: Assumed inductance, H (:meth:`bind` sets it to the machine's Lq: the active flux).
        omega_init: The speed estimate's start, rad/s (:meth:`bind` sets it).
        ts: Sample time, s.
        rule: Discretization rule.
    """

    Rs: eqx.AbstractVar[jax.Array]
    L: eqx.AbstractVar[jax.Array]
    omega_init: eqx.AbstractVar[jax.Array]
    ts: eqx.AbstractVar[float]
    rule: eqx.AbstractVar[AbstractRule]

    bound_fields: ClassVar[BoundFields] = BoundFields(resistance="Rs", inductance="L", speed="omega_init")
    _speed_index: ClassVar[int]  # the speed estimate's place in the state

    @abc.abstractmethod
    def start_speed(self, omega_e) -> jax.Array:
        """The speed estimate the observer starts from, or is held at, when the rotor turns at ω_e.

        Args:
            omega_e: The rotor's electrical speed ω_e, rad/s.

        Returns:
            The speed estimate, rad/s.
        """

    def bind(self, est_par, omega_e) -> AbstractFluxObserver:
        w = self.start_speed(omega_e)
        if est_par is None:
            return replace_leaves(self, omega_init=w)
        # L̂q, not L̂d: the active flux (module doc, "Salient machines"); Lq = Ld on a non-salient machine
        new = replace_leaves(self, Rs=est_par.Rs, L=est_par.Lq, omega_init=w)
        speed = self.speed_estimator()  # the PLL-type observers' speed estimator (jaxobs.observers.speed)
        bound = None if speed is None else speed.bind(est_par)
        return new if bound is speed else eqx.tree_at(lambda o: o.speed, new, bound)

    def init(self, u0=None) -> DriveObserverState:
        return self._init_from(self.initial_state())

    def init_at(self, omega_e) -> DriveObserverState:
        """The initial state with the speed estimate at ω_e: the start of a drive's settling phase.

        Args:
            omega_e: ω_e, rad/s.

        Returns:
            The :class:`DriveObserverState`.
        """
        return self._init_from(self.initial_state().at[self._speed_index].set(self.start_speed(omega_e)))

    def seed_speed(self, state: DriveObserverState, omega_e) -> DriveObserverState:
        """``state`` with its speed estimate (FLL centre frequency or PLL speed) set to ω_e: an I-f start-up
        holds it at the I-f frequency until the hand-over (jaxobs.drive.ClosedLoop).

        Args:
            state: The :class:`DriveObserverState`.
            omega_e: ω_e, rad/s.

        Returns:
            The state with its speed estimate set.
        """
        w = self.start_speed(omega_e)
        return eqx.tree_at(lambda s: s.x, state, state.x.at[self._speed_index].set(w))

    def _init_from(self, x0) -> DriveObserverState:
        z2 = jnp.zeros((2,), x0.dtype)
        return DriveObserverState(
            x=x0, rule=self.rule.init(self.f, x0, z2), i_prev=z2, u_prev=z2, started=jnp.asarray(False)
        )

    def back_emf(self, state: DriveObserverState, u):
        i = jnp.stack([u.i_a, u.i_b])
        e = state.u_prev - self.Rs * 0.5 * (i + state.i_prev) - self.L * (i - state.i_prev) / self.ts
        return jnp.where(state.started, e, 0.0), i

    def step(self, state: DriveObserverState, u):
        e, i = self.back_emf(state, u)
        f = self.f
        if self.reads_torque:
            # a mechanical-model speed estimator reads the torque reference held over the period (0: none given)
            tq = u.T_ref
            tq = jnp.zeros((), state.x.dtype) if tq is None else jnp.asarray(tq, state.x.dtype)

            def f(x, e):
                return self.f(x, e, tq)

        x1, rs = self.rule.step(f, state.x, e, self.ts, state.rule)
        x1 = jnp.where(state.started, x1, state.x)
        new = DriveObserverState(x=x1, rule=rs, i_prev=i, u_prev=jnp.stack([u.u_a, u.u_b]), started=jnp.asarray(True))
        return new, self.output(x1, e)

    def vector_field(self, t, x, e_of_t):
        """``f(t, x, args)`` for diffrax.

        Args:
            t: The time, s.
            x: The flat state.
            e_of_t: A function of t returning (e_α, e_β).

        Returns:
            dx/dt.
        """
        return self.f(x, e_of_t(t))


def _check_common(obj, Rs, L, ts, rule, name):
    obj.Rs = check_nonnegative("Rs", Rs, name)
    obj.L = check_positive("L", L, name)
    obj.ts = check_sample_time("ts", ts, name)
    obj.rule = check_rule(RK4() if rule is None else rule, name)


def _omega_init(omega_init, omega0, name):
    """The initial speed given as ``omega_init`` or as ``omega0`` (job files' and result.json's key)."""
    if omega0 is None:
        return omega_init
    if omega_init is not None:
        raise ValueError(f"{name}: give the initial speed once, as omega_init (omega0 is the same field)")
    return omega0


def _check_pll(obj, kp_pll, ki_pll, omega_init, psi_floor, name):
    del name  # the gains' bounds: check_gains (AbstractObserver)
    obj.kp_pll, obj.ki_pll = as_float(kp_pll), as_float(ki_pll)
    obj.omega_init = jnp.asarray(omega_init, dtype=obj.kp_pll.dtype)
    obj.psi_floor = float(psi_floor)


def _kp():
    return gain(units="s-1", role="pll", long_name="PLL proportional gain", symbol="k_p (ours: 2ζω_b)")


def _ki():
    return gain(units="s-2", role="pll", long_name="PLL integral gain", symbol="k_i (ours: ω_b²)")


def _lam_normalized():
    # lam·ω̂² is 001's λ (module doc, "Names"): dimensionless, where the FLLs' λ is in rad²/s²
    return gain(units="1", role="fll", long_name="frequency-normalized FLL gain, λ/ω̂²", symbol="000: Γ, λ/ω̂²")


def _pll_design(cls, pll_hz):
    """The flux observers' PLL placed at ω_b = 2π·``pll_hz`` (ζ = 1/√2; ASSUMED: 000 gives no PLL): its gains and
    rows."""
    check_positive("pll_hz", pll_hz, f"{cls.__name__}.closed_form")
    kp, ki = pll_gains(2 * math.pi * pll_hz)
    src = "ours (ASSUMED: 000 gives no PLL)"
    rows = (
        gain_row(cls, "kp_pll", float(kp), "k_p = 2ζω_b, ω_b = 2π·pll_hz, ζ = 1/√2", src),
        gain_row(cls, "ki_pll", float(ki), "k_i = ω_b²", src),
    )
    return float(kp), float(ki), rows


class _PLLFluxBase(AbstractFluxObserver):
    """Flux filters with state [ψα, ψβ, θ̂, ω̂, ...]: a speed estimator (``speed``, jaxobs.observers.speed) on the
    estimated flux's phase error gives θ̂ and ω̂: the type-2 PLL on ``kp_pll``, ``ki_pll`` by default, or a
    mechanical model (its load-torque state follows ω̂).  The flux does not vanish at standstill, so the
    detector needs no fade: quadrature_error normalizes by |ψ̂| (floored at ``psi_floor``)."""

    kp_pll: eqx.AbstractVar[jax.Array]
    ki_pll: eqx.AbstractVar[jax.Array]
    psi_floor: eqx.AbstractVar[float]
    speed: eqx.AbstractVar[AbstractSpeedEstimator]

    _speed_index: ClassVar[int] = 3  # the PLL's ω in the state
    takes_speed_estimator: ClassVar[bool] = True

    def speed_estimator(self) -> AbstractSpeedEstimator:
        return self.speed

    def start_speed(self, omega_e):
        """ω_e itself: a PLL's speed is signed and may be zero.

        Args:
            omega_e: ω_e, rad/s.

        Returns:
            ω_e, rad/s.
        """
        return jnp.asarray(omega_e)

    def initial_state(self):
        z = jnp.zeros_like(self.kp_pll)
        return jnp.concatenate([jnp.stack([z, z]), self.speed.initial_state(z, self.omega_init)])

    def _pll_rates(self, x, torque=0.0):
        err = quadrature_error(x[0], x[1], x[2], self.psi_floor)
        return self.speed.vf(self, x[2:], err, torque)


class PureIntegratorFlux(_PLLFluxBase):
    """ψ̂ = ∫ê dt (000 eq 6) with a type-2 PLL on ψ̂ for the speed.  State [ψα, ψβ, θ_pll, ω_pll].

    Args:
        Rs: Assumed stator resistance, ohm (≥ 0; :meth:`bind` sets it per scenario).
        L: Assumed inductance, H (> 0; :meth:`bind` sets it to the machine's Lq: the active flux).
        kp_pll: The PLL's proportional gain, 1/s (> 0).
        ki_pll: The PLL's integral gain, 1/s² (> 0).
        omega_init: The PLL's initial speed, rad/s (default 0; :meth:`bind` sets it).
        ts: Sample time, s.
        rule: Discretization rule (default :class:`~jaxobs.RK4`).
        psi_floor: Floor of |ψ̂| in the PLL's normalized phase detector, Wb.
        omega0: Another name of ``omega_init`` (the job files' key); give one of the two.
        speed: The speed extraction: an estimator or a record (:func:`~jaxobs.observers.speed.speed_from_spec`);
            default :class:`~jaxobs.observers.speed.PLLSpeed` on ``kp_pll``, ``ki_pll``.

    Raises:
        ValueError: A value out of its range, or both ``omega_init`` and ``omega0`` given.
    """

    Rs: jax.Array
    L: jax.Array
    kp_pll: jax.Array = _kp()
    ki_pll: jax.Array = _ki()
    omega_init: jax.Array  # initial PLL speed, rad/s
    speed: AbstractSpeedEstimator  # speed and position extraction (its states follow the flux's)
    ts: float = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)
    psi_floor: float = eqx.field(static=True)

    # its flux starts from zero, so its circle is offset by the flux at its start (000's "unknown integral
    # initial value") and θ̂ is wrong by up to 90° whatever its PLL gains: in a sensorless drive it loses
    # synchronism
    why_not_tunable: ClassVar[str] = (
        "its flux keeps the integration constant of its start, so it cannot hold a sensorless drive; "
        "use LPFFlux, SOIFO or SecondOrderSOIFO"
    )

    def __init__(
        self, Rs, L, kp_pll, ki_pll, omega_init=None, *, ts=1e-4, rule=None, psi_floor=1e-4, omega0=None, speed=None
    ):
        omega_init = _omega_init(omega_init, omega0, "PureIntegratorFlux")
        _check_common(self, Rs, L, ts, rule, "PureIntegratorFlux")
        _check_pll(self, kp_pll, ki_pll, 0.0 if omega_init is None else omega_init, psi_floor, "PureIntegratorFlux")
        self.speed = speed_from_spec(speed, "PureIntegratorFlux.speed")

    @classmethod
    def closed_form_design(
        cls,
        pll_hz=papers.FLUX_PLL_HZ,
        Rs=papers.SPMSM_000["Rs"],
        L=papers.SPMSM_000["Ld"],
        omega_init=0.0,
        **kw,
    ) -> ClosedForm:
        """000's pure integrator (eq 6: it has no gain of its own) with its type-2 PLL placed at
        ω_b = 2π·``pll_hz`` (k_p = 2ζω_b, k_i = ω_b², ζ = 1/√2; ASSUMED: 000 gives no PLL).

        Args:
            pll_hz: the PLL's bandwidth, Hz (> 0).
            Rs: assumed stator resistance, ohm (>= 0; ``bind`` sets it per scenario).
            L: assumed inductance, H (> 0; ``bind`` sets it).
            omega_init: the PLL's initial speed, rad/s (``bind`` sets it).
            **kw: the constructor's keywords.

        Returns:
            The :class:`~jaxobs.observers.ClosedForm`: the :class:`PureIntegratorFlux` and the PLL's rows.

        Raises:
            ValueError: a value out of its range.
        """
        kp, ki, rows = _pll_design(cls, pll_hz)
        obs = cls(Rs, L, kp, ki, omega_init, **kw)
        inputs = dict(pll_hz=pll_hz, Rs=Rs, L=L, omega_init=omega_init)
        return ClosedForm(obs, inputs, rows, "000 eq (6), PLL pole placement ω_b = 2π·20 (ASSUMED)")

    @classmethod
    def closed_form(cls, **kw) -> PureIntegratorFlux:
        """The observer of :meth:`closed_form_design` (same arguments).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`PureIntegratorFlux`.
        """
        return cls.closed_form_design(**kw).observer

    def f(self, x, e, torque=0.0):
        return jnp.concatenate([jnp.stack([e[0], e[1]]), self._pll_rates(x, torque)])

    def output(self, x, e):
        return FluxOutput(psi_a=x[0], psi_b=x[1], theta=safe_atan2(x[1], x[0]), omega=x[3], e_a=e[0], e_b=e[1])


class LPFFlux(_PLLFluxBase):
    """ψ̂ = ê/(s + ωc) (000 Sec. II) with a type-2 PLL for the speed and optional compensation.

    With ``compensate=True`` the estimate is scaled by √(ω̂² + ωc²)/|ω̂| and rotated by
    −atan(ωc/ω̂) (000 eq 11), using the PLL's ω̂ — the phase compensation that
    000 says the LPF "relies on rigidly".  State [ψα, ψβ, θ_pll, ω_pll]; the PLL
    tracks the uncompensated flux (a constant lead does not change its speed).

    Args:
        Rs: Assumed stator resistance, ohm (≥ 0; :meth:`bind` sets it per scenario).
        L: Assumed inductance, H (> 0; :meth:`bind` sets it to the machine's Lq: the active flux).
        omega_c: The low-pass cut-off ωc, rad/s (> 0).
        kp_pll: The PLL's proportional gain, 1/s (> 0).
        ki_pll: The PLL's integral gain, 1/s² (> 0).
        omega_init: The PLL's initial speed, rad/s (default 0; :meth:`bind` sets it).
        compensate: Whether to apply 000 eq 11's magnitude and phase compensation.
        ts: Sample time, s.
        rule: Discretization rule (default :class:`~jaxobs.RK4`).
        psi_floor: Floor of |ψ̂| in the PLL's normalized phase detector, Wb.
        omega0: Another name of ``omega_init`` (the job files' key); give one of the two.
        speed: The speed extraction: an estimator or a record (:func:`~jaxobs.observers.speed.speed_from_spec`);
            default :class:`~jaxobs.observers.speed.PLLSpeed` on ``kp_pll``, ``ki_pll``.

    Raises:
        ValueError: A value out of its range, or both ``omega_init`` and ``omega0`` given.
    """

    Rs: jax.Array
    L: jax.Array
    omega_c: jax.Array = gain(units="rad s-1", role="filter", long_name="low-pass cut-off", symbol="000: ωc")
    kp_pll: jax.Array = _kp()
    ki_pll: jax.Array = _ki()
    omega_init: jax.Array  # initial PLL speed, rad/s
    speed: AbstractSpeedEstimator  # speed and position extraction (its states follow the flux's)
    ts: float = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)
    compensate: bool = eqx.field(static=True)
    psi_floor: float = eqx.field(static=True)

    def __init__(
        self,
        Rs,
        L,
        omega_c,
        kp_pll,
        ki_pll,
        omega_init=None,
        *,
        compensate=False,
        ts=1e-4,
        rule=None,
        psi_floor=1e-4,
        omega0=None,
        speed=None,
    ):
        omega_init = _omega_init(omega_init, omega0, "LPFFlux")
        _check_common(self, Rs, L, ts, rule, "LPFFlux")
        self.omega_c = as_float(omega_c)  # bounds: check_gains (AbstractObserver)
        _check_pll(self, kp_pll, ki_pll, 0.0 if omega_init is None else omega_init, psi_floor, "LPFFlux")
        self.compensate = bool(compensate)
        self.speed = speed_from_spec(speed, "LPFFlux.speed")

    @classmethod
    def closed_form_design(
        cls,
        omega_c=papers.LPF_OMEGA_C,
        pll_hz=papers.FLUX_PLL_HZ,
        Rs=papers.SPMSM_000["Rs"],
        L=papers.SPMSM_000["Ld"],
        omega_init=0.0,
        **kw,
    ) -> ClosedForm:
        """000's LPF estimator, uncompensated as in 000 Fig. 5 (ωc = 100 rad/s), with its type-2 PLL placed at
        ω_b = 2π·``pll_hz`` (k_p = 2ζω_b, k_i = ω_b², ζ = 1/√2; ASSUMED: 000 gives no PLL).

        Args:
            omega_c: the low-pass cut-off, rad/s (> 0).
            pll_hz: the PLL's bandwidth, Hz (> 0).
            Rs: assumed stator resistance, ohm (>= 0; ``bind`` sets it per scenario).
            L: assumed inductance, H (> 0; ``bind`` sets it).
            omega_init: the PLL's initial speed, rad/s (``bind`` sets it).
            **kw: the constructor's keywords.

        Returns:
            The :class:`~jaxobs.observers.ClosedForm`: the :class:`LPFFlux` and the rows omega_c and the PLL's.

        Raises:
            ValueError: a value out of its range.
        """
        kp, ki, pll_rows = _pll_design(cls, pll_hz)
        obs = cls(Rs, L, omega_c, kp, ki, omega_init, **kw)
        rows = (gain_row(cls, "omega_c", obs.omega_c, "chosen: ωc = 100 rad/s", "000 Fig. 5"), *pll_rows)
        inputs = dict(omega_c=omega_c, pll_hz=pll_hz, Rs=Rs, L=L, omega_init=omega_init)
        return ClosedForm(obs, inputs, rows, "000 Fig. 5 (ωc = 100 rad/s), PLL pole placement ω_b = 2π·20 (ASSUMED)")

    @classmethod
    def closed_form(cls, **kw) -> LPFFlux:
        """The observer of :meth:`closed_form_design` (same arguments).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`LPFFlux`.
        """
        return cls.closed_form_design(**kw).observer

    def f(self, x, e, torque=0.0):
        filt = jnp.stack([e[0] - self.omega_c * x[0], e[1] - self.omega_c * x[1]])
        return jnp.concatenate([filt, self._pll_rates(x, torque)])

    def output(self, x, e):
        pa, pb, w = x[0], x[1], x[3]
        if self.compensate:
            w_safe = jnp.where(jnp.abs(w) > 1.0, w, 1.0)
            gain = jnp.sqrt(w_safe * w_safe + self.omega_c**2) / jnp.abs(w_safe)
            rot = -jnp.arctan(self.omega_c / w_safe)
            c, s = jnp.cos(rot), jnp.sin(rot)
            pa, pb = gain * (c * pa - s * pb), gain * (s * pa + c * pb)
        return FluxOutput(psi_a=pa, psi_b=pb, theta=safe_atan2(pb, pa), omega=w, e_a=e[0], e_b=e[1])


def _fll_norm(ya, qa, yb, qb, e, v_floor):
    """FLL normalization max(V̂α² + V̂β², |ê|², v_floor²).

    In steady state V̂α² + V̂β² = 2|ê|² for a balanced input, so the floor |ê|² is
    inactive and the small-signal model is unchanged.  At start-up the SOGI
    outputs are still near zero while ê already has its full amplitude; without
    the floor the normalized error (ê − y)q/V̂² ~ |ê|/|q| grows without bound
    and the FLL runs away (seen with a current-sensor offset: ω̂ reached
    3000 rad/s and the states overflowed).  |ê|² is the instantaneous amplitude
    of the two-axis input, available without filtering.
    """
    v2 = safe_sq_amplitude(ya, qa, 0.0) + safe_sq_amplitude(yb, qb, 0.0)
    return jnp.maximum(jnp.maximum(v2, e[0] * e[0] + e[1] * e[1]), v_floor * v_floor)


class _FLLFluxBase(AbstractFluxObserver):
    """Flux filters whose speed is an FLL's: a SOGI's centre frequency, > 0 (``omega_min`` its floor)."""

    omega_min: eqx.AbstractVar[float]

    def start_speed(self, omega_e):
        """max(|ω_e|, omega_min): a SOGI cannot tell the direction (the sign comes from the flux's rotation,
        module doc) and its centre frequency must stay positive.  The floor is the observer's own
        ``omega_min`` (1 rad/s by default), the one its outputs divide by, not a separate constant.

        Args:
            omega_e: ω_e, rad/s.

        Returns:
            The FLL's start frequency, rad/s.
        """
        return jnp.maximum(jnp.abs(omega_e), self.omega_min)


def _signed(omega_abs, psi_a, psi_b, y_a, y_b):
    cross = psi_a * y_b - psi_b * y_a
    return jnp.where(cross < 0, -omega_abs, omega_abs)


class SOIFO(_FLLFluxBase):
    """SOGI flux observer with FLL (000 Sec. III-A, eq 15, Fig. 3): ψ̂ = kω'/(s² + kω's + ω'²)·ê.

    State [yα, qα, yβ, qβ, ω̂].  FLL: ω̂̇ = −lam·ω̂² Σₓ (êₓ − yₓ) qₓ / Σₓ (yₓ² + qₓ²) (two SOGIs, one FLL;
    ``lam`` dimensionless, k²/4 for ζ = 1/√2).

    Args:
        Rs: Assumed stator resistance, ohm (≥ 0; :meth:`bind` sets it per scenario).
        L: Assumed inductance, H (> 0; :meth:`bind` sets it to the machine's Lq: the active flux).
        k: SOGI gain (> 0).
        lam: Frequency-normalized FLL gain λ/ω̂² (dimensionless, > 0).
        omega_init: The FLL's initial frequency, rad/s (> 0; :meth:`bind` sets it).
        ts: Sample time, s.
        rule: Discretization rule (default :class:`~jaxobs.RK4`).
        v_floor: Floor of the FLL normalization (V, > 0).
        omega_min: Floor of |ω̂| in the outputs, which divide by it, rad/s.
        omega0: Another name of ``omega_init`` (the job files' key); give one of the two.

    Raises:
        ValueError: A value out of its range, or both ``omega_init`` and ``omega0`` given.
    """

    Rs: jax.Array
    L: jax.Array
    k: jax.Array = gain(units="1", role="sogi", long_name="SOGI gain", symbol="000: k")
    lam: jax.Array = _lam_normalized()
    omega_init: jax.Array  # initial FLL frequency, rad/s (> 0)
    ts: float = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)
    v_floor: float = eqx.field(static=True)
    omega_min: float = eqx.field(static=True)

    small_signal_model: ClassVar = ("soifo_tf", ("k", "omega_init"))  # 000 eq (15), ψ̂/e at ω' = omega_init

    def __init__(self, Rs, L, k, lam, omega_init=None, *, ts=1e-4, rule=None, v_floor=1e-2, omega_min=1.0, omega0=None):
        omega_init = _omega_init(omega_init, omega0, "SOIFO")
        _check_common(self, Rs, L, ts, rule, "SOIFO")
        self.k, self.lam = as_float(k), as_float(lam)  # bounds: check_gains (AbstractObserver)
        self.omega_init = check_positive("omega_init", omega_init, "SOIFO")
        self.v_floor = float(v_floor)
        self.omega_min = float(omega_min)

    @classmethod
    def closed_form_design(cls, k=papers.SOIFO_K, Rs=0.0, L=1.0, omega_init=papers.FLL_OMEGA_N, **kw) -> ClosedForm:
        """The SOIFO at 000's k = 1.414 with the FLL damped by 001 eq (22) frequency-normalized: lam = k²/4
        (ζ = 1/√2 at every speed, module doc).

        Args:
            k: SOGI gain (> 0).
            Rs: assumed stator resistance, ohm (>= 0; ``bind`` sets it per scenario).
            L: assumed inductance, H (> 0; ``bind`` sets it).
            omega_init: the FLL's initial frequency, rad/s (> 0; ``bind`` sets it).
            **kw: the constructor's keywords.

        Returns:
            The :class:`~jaxobs.observers.ClosedForm`: the :class:`SOIFO` and the rows k, lam.

        Raises:
            ValueError: a value out of its range.
        """
        obs = cls(Rs, L, k, soifo_lambda(k), omega_init, **kw)
        rows = (
            gain_row(cls, "k", obs.k, "chosen: k = 1.414 (settling time 0.018 s)", "000 Sec. III-B"),
            gain_row(cls, "lam", obs.lam, "lam = k²/4 (λ = k²ωn²/4 at ζ = 1/√2, ωn → 1)", "001 eq (22), normalized"),
        )
        inputs = dict(k=k, Rs=Rs, L=L, omega_init=omega_init)
        return ClosedForm(obs, inputs, rows, "000 (k = 1.414), lam = k²/4")

    @classmethod
    def closed_form(cls, **kw) -> SOIFO:
        """The observer of :meth:`closed_form_design` (same arguments).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`SOIFO`.
        """
        return cls.closed_form_design(**kw).observer

    _speed_index: ClassVar[int] = 4  # the FLL's ω̂ (a SOGI's centre frequency: > 0)

    def initial_state(self):
        z = jnp.zeros_like(self.k)
        return jnp.stack([z, z, z, z, self.omega_init])

    def f(self, x, e):
        ya, qa, yb, qb, w = x[0], x[1], x[2], x[3], x[4]
        dya, dqa = sogi_vf(ya, qa, e[0], w, self.k)
        dyb, dqb = sogi_vf(yb, qb, e[1], w, self.k)
        num = (e[0] - ya) * qa + (e[1] - yb) * qb
        lam = self.lam * w * w  # frequency-normalized FLL gain (module doc)
        return jnp.stack([dya, dqa, dyb, dqb, -lam * num / _fll_norm(ya, qa, yb, qb, e, self.v_floor)])

    def output(self, x, e):
        w = jnp.maximum(x[4], self.omega_min)
        pa, pb = x[1] / w, x[3] / w
        return FluxOutput(
            psi_a=pa, psi_b=pb, theta=safe_atan2(pb, pa), omega=_signed(x[4], pa, pb, x[0], x[2]), e_a=e[0], e_b=e[1]
        )


class SecondOrderSOIFO(_FLLFluxBase):
    """Second-order SOIFO with FLL (000 Sec. III-B, eq 20, Fig. 4).

    ψ̂ = K1K2ω'²s/(s⁴ + K2ω's³ + (2+K1K2)ω'²s² + K2ω'³s + ω'⁴)·ê: the second-order SOGI of
    :mod:`jaxobs.observers._cores` on each axis, sharing one FLL.

    ``discretization``:

    - ``"rule"`` (default): the continuous vector field through ``rule``
      (RK4 by default; ``Tustin()`` is the paper's trapezoidal method).  State
      [zaα, zbα, yα, qα, zaβ, zbβ, yβ, qβ, ω̂].  FLL: the detector derived for
      the SOGI-FLL-WIF (Golestan's k1 = K2, k2 = K1), ω̂̇ = −(lam·ω̂²/K1) Σₓ zaₓ qₓ / Σₓ V̂ₓ²,
      whose small-signal model is 001 eqs (31)–(32).
    - ``"paper"``: the difference equations of 000 eqs (22)–(25), coefficients
      recomputed every sample from ω̂ (direct form II, four delays per axis,
      shared by D1 and Q1).  The direct form hides the first GI's output z_a, so
      this variant's FLL uses the SOGI-FLL error (ê − v′)qv′ on the outputs, and
      ω̂ is updated by forward Euler.  State [w_α(k−1..k−4), w_β(k−1..k−4), ω̂].

    Args:
        Rs: Assumed stator resistance, ohm (≥ 0; :meth:`bind` sets it per scenario).
        L: Assumed inductance, H (> 0; :meth:`bind` sets it to the machine's Lq: the active flux).
        K1: Second-order SOGI error gain (000's K1, > 0).
        K2: Second-order SOGI damping gain (000's K2, > 0).
        lam: Frequency-normalized FLL gain λ/ω̂² (dimensionless, > 0).
        omega_init: The FLL's initial frequency, rad/s (> 0; :meth:`bind` sets it).
        ts: Sample time, s.
        rule: Discretization rule (default :class:`~jaxobs.RK4`).
        discretization: ``"rule"`` or ``"paper"``, as above.
        v_floor: Floor of the FLL normalization (V, > 0).
        omega_min: Floor of |ω̂| in the outputs, which divide by it, rad/s.
        omega0: Another name of ``omega_init`` (the job files' key); give one of the two.

    Raises:
        ValueError: A value out of its range, or both ``omega_init`` and ``omega0`` given.
    """

    Rs: jax.Array
    L: jax.Array
    K1: jax.Array = gain(units="1", role="sogi", long_name="second-order SOGI error gain", symbol="000: K1")
    K2: jax.Array = gain(units="1", role="sogi", long_name="second-order SOGI damping gain", symbol="000: K2")
    lam: jax.Array = _lam_normalized()
    omega_init: jax.Array  # initial FLL frequency, rad/s (> 0)
    ts: float = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)
    discretization: Literal["rule", "paper"] = eqx.field(static=True)
    v_floor: float = eqx.field(static=True)
    omega_min: float = eqx.field(static=True)

    small_signal_model: ClassVar = ("sosoifo_tf", ("K1", "K2", "omega_init"))  # 000 eq (20) at ω' = omega_init

    def __init__(
        self,
        Rs,
        L,
        K1,
        K2,
        lam,
        omega_init=None,
        *,
        ts=1e-4,
        rule=None,
        discretization="rule",
        v_floor=1e-2,
        omega_min=1.0,
        omega0=None,
    ):
        omega_init = _omega_init(omega_init, omega0, "SecondOrderSOIFO")
        _check_common(self, Rs, L, ts, rule, "SecondOrderSOIFO")
        self.K1, self.K2, self.lam = as_float(K1), as_float(K2), as_float(lam)  # bounds: check_gains
        self.omega_init = check_positive("omega_init", omega_init, "SecondOrderSOIFO")
        if discretization not in ("rule", "paper"):
            raise ValueError(f"SecondOrderSOIFO.discretization must be 'rule' or 'paper', got {discretization!r}")
        self.discretization = discretization
        self.v_floor = float(v_floor)
        self.omega_min = float(omega_min)

    _speed_index: ClassVar[int] = 8  # the FLL's ω̂

    @classmethod
    def closed_form_design(
        cls,
        K1=papers.SECOND_ORDER_SOIFO_K1,
        K2=papers.SECOND_ORDER_SOIFO_K2,
        Rs=0.0,
        L=1.0,
        omega_init=papers.FLL_OMEGA_N,
        **kw,
    ) -> ClosedForm:
        """The second-order SOIFO at 000's K1 = 1.56, K2 = 3.11 with the FLL of 001's symmetric optimum (eq 34)
        frequency-normalized, in 000's names (b = K2/K1): lam = K1³/(2 K2).

        Args:
            K1: error gain (> 0).
            K2: damping gain (> 0).
            Rs: assumed stator resistance, ohm (>= 0; ``bind`` sets it per scenario).
            L: assumed inductance, H (> 0; ``bind`` sets it).
            omega_init: the FLL's initial frequency, rad/s (> 0; ``bind`` sets it).
            **kw: the constructor's keywords (``discretization``, ...).

        Returns:
            The :class:`~jaxobs.observers.ClosedForm`: the :class:`SecondOrderSOIFO` and the rows K1, K2, lam.

        Raises:
            ValueError: a value out of its range.
        """
        obs = cls(Rs, L, K1, K2, second_order_soifo_lambda(K1, K2), omega_init, **kw)
        chosen = "000 Sec. III-B"
        rows = (
            gain_row(cls, "K1", obs.K1, "chosen: K1 = 1.56 (settling time 0.018 s)", chosen),
            gain_row(cls, "K2", obs.K2, "chosen: K2 = 3.11 (settling time 0.018 s)", chosen),
            gain_row(cls, "lam", obs.lam, "lam = K1³/(2K2) (λ = 2ωc²/b, b = K2/K1, ωn → 1)", "001 eq (34), normalized"),
        )
        inputs = dict(K1=K1, K2=K2, Rs=Rs, L=L, omega_init=omega_init)
        return ClosedForm(obs, inputs, rows, "000 (K1 = 1.56, K2 = 3.11), lam = K1³/(2K2)")

    @classmethod
    def closed_form(cls, **kw) -> SecondOrderSOIFO:
        """The observer of :meth:`closed_form_design` (same arguments).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`SecondOrderSOIFO`.
        """
        return cls.closed_form_design(**kw).observer

    def initial_state(self):
        z = jnp.zeros_like(self.K1)
        n = 8
        return jnp.concatenate([jnp.zeros((n,), z.dtype), self.omega_init[None]])

    # --- continuous form -----------------------------------------------------
    def f(self, x, e):
        w = x[8]
        ax = sogi2_vf(x[0], x[1], x[2], x[3], e[0], w, k_err=self.K1, k_damp=self.K2)
        bx = sogi2_vf(x[4], x[5], x[6], x[7], e[1], w, k_err=self.K1, k_damp=self.K2)
        num = x[0] * x[3] + x[4] * x[7]
        lam = self.lam * w * w  # frequency-normalized FLL gain (module doc)
        return jnp.stack([*ax, *bx, -(lam / self.K1) * num / _fll_norm(x[2], x[3], x[6], x[7], e, self.v_floor)])

    # --- paper 000 eqs (22)-(25) ---------------------------------------------
    def _paper_step(self, x, e):
        w = x[8]
        a, bd, bq = sogi2_tustin_coefficients(self.K1, self.K2, jnp.maximum(w, self.omega_min), self.ts)
        outs = []
        new_hist = []
        for ax, ex in ((0, e[0]), (1, e[1])):
            hist = x[4 * ax : 4 * ax + 4]  # w[k-1], w[k-2], w[k-3], w[k-4]
            wk = ex - jnp.dot(a, hist)
            taps = jnp.concatenate([wk[None], hist])
            outs.append((jnp.dot(bd, taps), jnp.dot(bq, taps)))
            new_hist.append(jnp.concatenate([wk[None], hist[:3]]))
        (ya, qa), (yb, qb) = outs
        num = (e[0] - ya) * qa + (e[1] - yb) * qb
        w_new = w - self.ts * self.lam * w * w * num / _fll_norm(ya, qa, yb, qb, e, self.v_floor)
        return jnp.concatenate([new_hist[0], new_hist[1], w_new[None]]), (ya, qa, yb, qb)

    def step(self, state: DriveObserverState, u):
        if self.discretization == "rule":
            return super().step(state, u)
        e, i = self.back_emf(state, u)
        x1, (ya, qa, yb, qb) = self._paper_step(state.x, e)
        x1 = jnp.where(state.started, x1, state.x)
        new = DriveObserverState(
            x=x1, rule=state.rule, i_prev=i, u_prev=jnp.stack([u.u_a, u.u_b]), started=jnp.asarray(True)
        )
        w = jnp.maximum(x1[8], self.omega_min)
        pa, pb = qa / w, qb / w
        out = FluxOutput(
            psi_a=pa, psi_b=pb, theta=safe_atan2(pb, pa), omega=_signed(x1[8], pa, pb, ya, yb), e_a=e[0], e_b=e[1]
        )
        return new, out

    def output(self, x, e):
        w = jnp.maximum(x[8], self.omega_min)
        pa, pb = x[3] / w, x[7] / w
        return FluxOutput(
            psi_a=pa, psi_b=pb, theta=safe_atan2(pb, pa), omega=_signed(x[8], pa, pb, x[2], x[6]), e_a=e[0], e_b=e[1]
        )
