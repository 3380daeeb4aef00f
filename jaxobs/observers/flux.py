"""Rotor-flux observers of paper 000 (Xu et al., TPEL 2018): the back EMF they filter, their contract
(:class:`AbstractFluxObserver`) and the PLL types, pure integrator and LPF, with position from atan2 (eq 4)
and speed from a PLL.  The SOGI types, SOIFO and second-order SOIFO, whose speed is an FLL's (and their
frequency-normalized FLL gain ``lam``, λ(ω̂) = lam·ω̂²), are in :mod:`jaxobs.observers.soifo`.

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

Salient machines: the active flux (Boldea, Paicu, Andreescu, "Active flux concept for motion-sensorless
unified AC drives", IEEE Trans. Power Electron. 23(5), 2008).  In the rotor frame ψs = (Ld i_d + ψf) + j Lq i_q,
so ψs − Lq i = (ψf + (Ld − Lq) i_d) e^{jθe}: the "active flux" ψa, aligned with the rotor's d axis on any PMSM.
Bound to a machine, an observer takes L̂ = L̂q (:meth:`AbstractFluxObserver.bind`), so the back EMF it filters,
u − R̂s i − L̂q di/dt = dψa/dt, is the active flux's, and θ̂ = atan2(ψ̂β, ψ̂α) is θe on a salient machine as on
000's non-salient one (where Lq = Ld, ψa = ψf and nothing changes).  What that changes for 000's closed forms:

- the filters (SOGI, second-order SOGI, LPF, integrator) are linear in e: their transfer functions (000 Table
  III, eqs 15–21) and the angle they give at a steady point are unchanged;
- the FLL is normalized by V̂² and its gain by ω̂² (:mod:`jaxobs.observers.soifo`), the PLLs by |ψ̂|: none
  depends on the flux amplitude, so the closed forms (001's damping rule, the WIF's symmetric optimum, the PLL's
  placement) hold at every steady operating point as derived;
- but the amplitude |ψa| = |ψf + (Ld − Lq) i_d| moves with i_d: under i_d* = 0 it is ψf (000's analysis holds
  as is), under MTPA (Lq > Ld, i_d < 0) it falls with the load, and a step of i_d steps it.  The flux outputs
  are then ψa, not ψf; a load step is an amplitude step (Ld − Lq)Δi_d of the filtered signal, which the
  filters pass with their own step response — a transient angle error that 000's analysis (a constant
  amplitude) does not cover, and the stability maps of docs/stability.md, drawn at constant amplitude,
  do not either.  A machine whose ψa nears zero (strong saliency at high −i_d) leaves only the floors.

Names.  The speed the FLL or PLL starts from is ``omega_init``: 002's ω0 names a LESO's bandwidth, a gain,
while this is a bound field (``bind`` sets it per scenario), so it takes a name no gain has.  The constructors
accept ``omega0=`` for it, as job files and result.json files written with that key give it.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple, Self

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike, DTypeLike

from .. import papers
from ..core.discretize import RK4, AbstractRule, check_rule
from ..core.measurements import DriveInput
from ..core.numerics import safe_atan2
from ..core.validate import as_float, check_nonnegative, check_positive, check_sample_time
from ._cores import quadrature_error
from ._gains import ClosedForm, DesignRow, gain_metadata, gain_row, ki_pll_metadata, kp_pll_metadata
from ._rules import pll_gains
from .base import AbstractDriveObserver, AssumedMachine, BoundFields, DriveObserverState, replace_leaves
from .speed import AbstractSpeedEstimator, speed_from_spec

__all__ = ["FluxOutput", "AbstractFluxObserver", "PureIntegratorFlux", "LPFFlux"]

# the vector field a rule integrates over one period: f(x, e) -> dx/dt
PeriodField = Callable[[jax.Array, jax.Array], jax.Array]


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
    def start_speed(self, omega_e: ArrayLike) -> jax.Array:
        """The speed estimate the observer starts from, or is held at, when the rotor turns at ω_e.

        Args:
            omega_e: The rotor's electrical speed ω_e, rad/s.

        Returns:
            The speed estimate, rad/s.
        """

    @abc.abstractmethod
    def initial_state(self) -> jax.Array:
        """The flat state at t = 0 (filter states zero, the speed estimate at ``omega_init``)."""

    @abc.abstractmethod
    def f(self, x: jax.Array, e: jax.Array) -> jax.Array:
        """The filter's and speed estimate's vector field.

        Args:
            x: The flat state.
            e: The back EMF (e_α, e_β) held over the period, V.

        Returns:
            dx/dt.
        """

    @abc.abstractmethod
    def output(self, x: jax.Array, e: jax.Array) -> FluxOutput:
        """The outputs of a state.

        Args:
            x: The flat state.
            e: The back EMF fed to the filter over the last period, V.

        Returns:
            The :class:`FluxOutput`.
        """

    def bind(self, est_par: AssumedMachine | None, omega_e: ArrayLike) -> Self:
        """This observer assuming ``est_par``'s Rs and Lq (the active flux, module doc) and starting at ω_e
        (:meth:`AbstractDriveObserver.bind`).

        Args:
            est_par: The machine assumed, or None (the speed only).
            omega_e: The electrical speed, rad/s, signed.

        Returns:
            The bound observer.
        """
        w = self.start_speed(omega_e)
        if est_par is None:
            return replace_leaves(self, omega_init=w)
        # L̂q, not L̂d: the active flux (module doc, "Salient machines"); Lq = Ld on a non-salient machine
        new = replace_leaves(self, Rs=est_par.Rs, L=est_par.Lq, omega_init=w)
        speed = self.speed_estimator()  # the PLL-type observers' speed estimator (jaxobs.observers.speed)
        bound = None if speed is None else speed.bind(est_par)
        return new if bound is speed else eqx.tree_at(lambda o: o.speed, new, bound)

    def init(self, u0: Any = None) -> DriveObserverState:
        """The state at sample 0: :meth:`initial_state`, nothing seen yet.

        Args:
            u0: Unused (the first period starts at the first sample).

        Returns:
            The :class:`DriveObserverState`.
        """
        return self._init_from(self.initial_state())

    def init_at(self, omega_e: ArrayLike) -> DriveObserverState:
        """The initial state with the speed estimate at ω_e: the start of a drive's settling phase.

        Args:
            omega_e: ω_e, rad/s.

        Returns:
            The :class:`DriveObserverState`.
        """
        return self._init_from(self.initial_state().at[self._speed_index].set(self.start_speed(omega_e)))

    def seed_speed(self, state: DriveObserverState, omega_e: ArrayLike) -> DriveObserverState:
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

    def _init_from(self, x0: jax.Array) -> DriveObserverState:
        z2 = jnp.zeros((2,), x0.dtype)
        return DriveObserverState(
            x=x0, rule=self.rule.init(self.f, x0, z2), i_prev=z2, u_prev=z2, started=jnp.asarray(False)
        )

    def back_emf(self, state: DriveObserverState, u: DriveInput) -> tuple[jax.Array, jax.Array]:
        """The period's average back EMF (module doc), and the current at the sample.

        Args:
            state: The state at the previous sample (its current and the voltage applied since).
            u: The measurements at this sample.

        Returns:
            ``(e, i)``: (e_α, e_β), V (0 before a period has been seen), and (i_α, i_β), A.
        """
        i = jnp.stack([u.i_a, u.i_b])
        e = state.u_prev - self.Rs * 0.5 * (i + state.i_prev) - self.L * (i - state.i_prev) / self.ts
        return jnp.where(state.started, e, 0.0), i

    def _period_field(self, u: DriveInput, dtype: DTypeLike) -> PeriodField:
        """The vector field integrated over the period that ends at ``u``'s sample: :meth:`f`."""
        del u, dtype
        return self.f

    def step(self, state: DriveObserverState, u: DriveInput) -> tuple[DriveObserverState, FluxOutput]:
        """One sample: the period that ends now integrated with its back EMF held, and the outputs at t_k.

        Args:
            state: The state at the previous sample.
            u: The measurements at this sample.

        Returns:
            ``(the state at this sample, the outputs at t_k)``.
        """
        e, i = self.back_emf(state, u)
        f = self._period_field(u, state.x.dtype)
        x1, rs = self.rule.step(f, state.x, e, self.ts, state.rule)
        x1 = jnp.where(state.started, x1, state.x)
        new = DriveObserverState(x=x1, rule=rs, i_prev=i, u_prev=jnp.stack([u.u_a, u.u_b]), started=jnp.asarray(True))
        return new, self.output(x1, e)

    def vector_field(self, t: ArrayLike, x: jax.Array, e_of_t: Callable[[ArrayLike], jax.Array]) -> jax.Array:
        """``f(t, x, args)`` for diffrax.

        Args:
            t: The time, s.
            x: The flat state.
            e_of_t: A function of t returning (e_α, e_β).

        Returns:
            dx/dt.
        """
        return self.f(x, e_of_t(t))

    def _check_common(self, Rs: ArrayLike, L: ArrayLike, ts: float, rule: AbstractRule | None, name: str) -> None:
        """Set and check the fields every flux observer has (a constructor's first step)."""
        self.Rs = check_nonnegative("Rs", Rs, name)
        self.L = check_positive("L", L, name)
        self.ts = check_sample_time("ts", ts, name)
        self.rule = check_rule(RK4() if rule is None else rule, name)

    @staticmethod
    def _initial_speed(omega_init: ArrayLike | None, omega0: ArrayLike | None, name: str) -> ArrayLike | None:
        """The initial speed given as ``omega_init`` or as ``omega0`` (job files' and result.json's key)."""
        if omega0 is None:
            return omega_init
        if omega_init is not None:
            raise ValueError(f"{name}: give the initial speed once, as omega_init (omega0 is the same field)")
        return omega0


def _pll_design(cls: type, pll_hz: float) -> tuple[float, float, tuple[DesignRow, ...]]:
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
        """The speed extraction this observer holds (``speed``).

        Returns:
            The :class:`~jaxobs.observers.speed.AbstractSpeedEstimator`.
        """
        return self.speed

    def start_speed(self, omega_e: ArrayLike) -> jax.Array:
        """ω_e itself: a PLL's speed is signed and may be zero.

        Args:
            omega_e: ω_e, rad/s.

        Returns:
            ω_e, rad/s.
        """
        return jnp.asarray(omega_e)

    def initial_state(self) -> jax.Array:
        """[0, 0, the speed estimator's start at ``omega_init``].

        Returns:
            The flat state.
        """
        z = jnp.zeros_like(self.kp_pll)
        return jnp.concatenate([jnp.stack([z, z]), self.speed.initial_state(z, self.omega_init)])

    @abc.abstractmethod
    def f(self, x: jax.Array, e: jax.Array, torque: ArrayLike = 0.0) -> jax.Array:
        """The filter's and speed estimator's vector field.

        Args:
            x: The flat state.
            e: The back EMF (e_α, e_β) held over the period, V.
            torque: The torque reference, N·m (a mechanical-model speed estimator reads it).

        Returns:
            dx/dt.
        """

    def _period_field(self, u: DriveInput, dtype: DTypeLike) -> PeriodField:
        """:meth:`f`, with the torque reference held over the period where the speed estimator reads it."""
        if not self.reads_torque:
            return self.f
        # a mechanical-model speed estimator reads the torque reference held over the period (0: none given)
        tq = u.T_ref
        tq = jnp.zeros((), dtype) if tq is None else jnp.asarray(tq, dtype)

        def f(x: jax.Array, e: jax.Array) -> jax.Array:
            return self.f(x, e, tq)

        return f

    def _set_pll(
        self,
        kp_pll: ArrayLike,
        ki_pll: ArrayLike,
        omega_init: ArrayLike | None,
        psi_floor: float,
        speed: Any,
        name: str,
    ) -> None:
        """Set the PLL types' own fields (the gains' bounds: check_gains, AbstractObserver)."""
        self.kp_pll, self.ki_pll = as_float(kp_pll), as_float(ki_pll)
        self.omega_init = jnp.asarray(0.0 if omega_init is None else omega_init, dtype=self.kp_pll.dtype)
        self.psi_floor = float(psi_floor)
        self.speed = speed_from_spec(speed, f"{name}.speed", self.ts)

    def _pll_rates(self, x: jax.Array, torque: ArrayLike = 0.0) -> jax.Array:
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
    kp_pll: jax.Array = eqx.field(metadata=kp_pll_metadata())
    ki_pll: jax.Array = eqx.field(metadata=ki_pll_metadata())
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
        self,
        Rs: ArrayLike,
        L: ArrayLike,
        kp_pll: ArrayLike,
        ki_pll: ArrayLike,
        omega_init: ArrayLike | None = None,
        *,
        ts: float = 1e-4,
        rule: AbstractRule | None = None,
        psi_floor: float = 1e-4,
        omega0: ArrayLike | None = None,
        speed: AbstractSpeedEstimator | dict[str, Any] | None = None,
    ) -> None:
        omega_init = self._initial_speed(omega_init, omega0, "PureIntegratorFlux")
        self._check_common(Rs, L, ts, rule, "PureIntegratorFlux")
        self._set_pll(kp_pll, ki_pll, omega_init, psi_floor, speed, "PureIntegratorFlux")

    @classmethod
    def closed_form_design(
        cls,
        pll_hz: float = papers.FLUX_PLL_HZ,
        Rs: ArrayLike = papers.SPMSM_000["Rs"],
        L: ArrayLike = papers.SPMSM_000["Ld"],
        omega_init: ArrayLike = 0.0,
        **kw: Any,
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
    def closed_form(cls, **kw: Any) -> PureIntegratorFlux:
        """The observer of :meth:`closed_form_design` (same arguments).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`PureIntegratorFlux`.
        """
        return cls.closed_form_design(**kw).observer

    def f(self, x: jax.Array, e: jax.Array, torque: ArrayLike = 0.0) -> jax.Array:
        """ψ̇ = ê, and the speed estimator's rates.

        Args:
            x: [ψα, ψβ, θ̂, ω̂, ...].
            e: The back EMF (e_α, e_β), V.
            torque: The torque reference, N·m (a mechanical-model speed estimator reads it).

        Returns:
            dx/dt.
        """
        return jnp.concatenate([jnp.stack([e[0], e[1]]), self._pll_rates(x, torque)])

    def output(self, x: jax.Array, e: jax.Array) -> FluxOutput:
        """ψ̂ = [ψα, ψβ], θ̂ = atan2(ψ̂β, ψ̂α) and the speed estimator's ω̂.

        Args:
            x: The flat state.
            e: The back EMF fed over the last period, V.

        Returns:
            The :class:`FluxOutput`.
        """
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
    omega_c: jax.Array = eqx.field(
        metadata=gain_metadata(units="rad s-1", role="filter", long_name="low-pass cut-off", symbol="000: ωc")
    )
    kp_pll: jax.Array = eqx.field(metadata=kp_pll_metadata())
    ki_pll: jax.Array = eqx.field(metadata=ki_pll_metadata())
    omega_init: jax.Array  # initial PLL speed, rad/s
    speed: AbstractSpeedEstimator  # speed and position extraction (its states follow the flux's)
    ts: float = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)
    compensate: bool = eqx.field(static=True)
    psi_floor: float = eqx.field(static=True)

    def __init__(
        self,
        Rs: ArrayLike,
        L: ArrayLike,
        omega_c: ArrayLike,
        kp_pll: ArrayLike,
        ki_pll: ArrayLike,
        omega_init: ArrayLike | None = None,
        *,
        compensate: bool = False,
        ts: float = 1e-4,
        rule: AbstractRule | None = None,
        psi_floor: float = 1e-4,
        omega0: ArrayLike | None = None,
        speed: AbstractSpeedEstimator | dict[str, Any] | None = None,
    ) -> None:
        omega_init = self._initial_speed(omega_init, omega0, "LPFFlux")
        self._check_common(Rs, L, ts, rule, "LPFFlux")
        self.omega_c = as_float(omega_c)  # bounds: check_gains (AbstractObserver)
        self.compensate = bool(compensate)
        self._set_pll(kp_pll, ki_pll, omega_init, psi_floor, speed, "LPFFlux")

    @classmethod
    def closed_form_design(
        cls,
        omega_c: ArrayLike = papers.LPF_OMEGA_C,
        pll_hz: float = papers.FLUX_PLL_HZ,
        Rs: ArrayLike = papers.SPMSM_000["Rs"],
        L: ArrayLike = papers.SPMSM_000["Ld"],
        omega_init: ArrayLike = 0.0,
        **kw: Any,
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
    def closed_form(cls, **kw: Any) -> LPFFlux:
        """The observer of :meth:`closed_form_design` (same arguments).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`LPFFlux`.
        """
        return cls.closed_form_design(**kw).observer

    def f(self, x: jax.Array, e: jax.Array, torque: ArrayLike = 0.0) -> jax.Array:
        """ψ̇ = ê − ωc ψ, and the speed estimator's rates.

        Args:
            x: [ψα, ψβ, θ̂, ω̂, ...].
            e: The back EMF (e_α, e_β), V.
            torque: The torque reference, N·m (a mechanical-model speed estimator reads it).

        Returns:
            dx/dt.
        """
        filt = jnp.stack([e[0] - self.omega_c * x[0], e[1] - self.omega_c * x[1]])
        return jnp.concatenate([filt, self._pll_rates(x, torque)])

    def output(self, x: jax.Array, e: jax.Array) -> FluxOutput:
        """ψ̂ (compensated by 000 eq 11 where ``compensate``), θ̂ = atan2(ψ̂β, ψ̂α) and the speed estimator's ω̂.

        Args:
            x: The flat state.
            e: The back EMF fed over the last period, V.

        Returns:
            The :class:`FluxOutput`.
        """
        pa, pb, w = x[0], x[1], x[3]
        if self.compensate:
            w_safe = jnp.where(jnp.abs(w) > 1.0, w, 1.0)
            gain = jnp.sqrt(w_safe * w_safe + self.omega_c**2) / jnp.abs(w_safe)
            rot = -jnp.arctan(self.omega_c / w_safe)
            c, s = jnp.cos(rot), jnp.sin(rot)
            pa, pb = gain * (c * pa - s * pb), gain * (s * pa + c * pb)
        return FluxOutput(psi_a=pa, psi_b=pb, theta=safe_atan2(pb, pa), omega=w, e_a=e[0], e_b=e[1])
