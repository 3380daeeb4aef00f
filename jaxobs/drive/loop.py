"""The closed-loop drive as a system: PMSM + inverter + sensors + FOC (+ observer), one step per control period.

``ClosedLoop(drive, observer, scenario)`` has the contract of every dynamic
piece (docs/architecture.md, section 2): ``init()`` and ``step(state, k)`` with ``k`` the sample
index, so a user can scan it themselves::

    system = jaxobs.drive.ClosedLoop(drive, None, scenario)      # None: the encoder
    _, out = jax.lax.scan(system.step, system.init(), jnp.arange(n))
    # out == jaxobs.simulate(system, n * drive.ts).outputs

One step is one control period T_s (10 kHz by default), as on a DSP:

1. the plant reports the machine at t_k and integrates over [t_k, t_{k+1}]
   under the voltage computed at t_{k−1} (the one-sample computation delay)
   and the load at t_k (:class:`~jaxobs.drive.PMSM`: ``n_sub`` substeps of its
   rule, the inverter's dead-time error inside its vector field);
2. the sensors measure the current at t_k and the voltage applied over
   [t_k, t_{k+1}], with their offsets, gain errors and noise
   (:class:`~jaxobs.drive.Sensors`);
3. the observer steps on those measurements (a :class:`~jaxobs.core.measurements.DriveInput`)
   and reports θ̂e, ω̂e at t_k;
4. the FOC uses the encoder (``drive.sensorless=False``) or the observer's θ̂e,
   ω̂e (from ``drive.handover`` on; the encoder before, while the observer
   converges — or an I-f start-up) and computes the voltage to apply over
   [t_{k+1}, t_{k+2}], which the inverter limits.

That is the default timing, ``Drive(latency=Latency())``.  :class:`~jaxobs.drive.Latency` moves the
sample to the PWM centre (the plant is then integrated in two half periods and sampled between them), makes
the computation instantaneous or one period long, and compares the estimates with the rotor at their own
time stamp or while the voltage computed from them acts (:mod:`jaxobs.drive.latency`).

Each piece is a step component of its own (plant, sensors, FOC, inverter,
observer); this module only wires them.  The speed-reference and load
profiles are the system's ``input(k)``, which ``jaxobs.simulate`` evaluates a
block of steps at a time.
"""

from __future__ import annotations

import abc
import dataclasses
import math
from typing import Any, ClassVar, NamedTuple, Protocol, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp

from ..core.discretize import RK4, AbstractRule, check_rule
from ..core.numerics import wrap
from ..core.sampletime import TS_REL_TOL
from ..core.system import AbstractSystem
from ..core.validate import check_sample_time
from ..observers import AbstractDriveObserver, AbstractObserver
from .control import FOC, ControllerState, FOCInput, IfStartup, OperatingPoint
from .hardware import Inverter, InverterInput, SensorInput
from .latency import Latency
from .machine import dq_to_ab
from .plant import PMSM, PlantInput, PlantState
from .scenario import Scenario

__all__ = ["Drive", "AbstractDriveLoop", "ClosedLoop", "LoopState", "DriveOutput", "LoopInput", "SETTLE_PERIODS"]

# Electrical periods of steady measurements a sensorless steady start gives an observer whose settling scales
# with the speed (Drive.settled_for).  The flux observers' filters and FLL have every time constant ∝ 1/ω_e
# (jaxobs.observers.flux): the slowest pole of 000's second-order SOGI is −0.243 ω_e, so 10 periods (62.8 rad)
# leave e^(−0.243·62.8) ≈ 2e-7 of its start-up transient (measured settling: docs/performance.md).
SETTLE_PERIODS = 10.0


class Drive(eqx.Module):
    """The drive hardware and controller: FOC, inverter, plant integration, optional I-f start-up.

    Args:
        foc: The :class:`FOC`.
        inverter: The :class:`Inverter` (default ``Inverter()``).
        startup: An :class:`IfStartup`, or None (a steady start).
        n_sub: Plant substeps per control period (an integer ≥ 1; even to sample at the PWM centre).
        rule: The plant integration rule (default :class:`~jaxobs.RK4`).
        sensorless: Whether the observer closes the loop.
        handover: Sensorless: the encoder closes the loop until this time (s, ≥ 0), the observer after.
        settle: A steady start's unscored settling phase of the observer before t = 0, s (in [0, 60]).
        latency: Sampling, computation delay, comparison instant (:class:`Latency`; default ``Latency()``).

    Raises:
        ValueError: A value out of its range, naming the field.
    """

    foc: FOC
    inverter: Inverter
    startup: IfStartup | None
    n_sub: int = eqx.field(static=True)  # plant substeps per control period
    rule: AbstractRule = eqx.field(static=True)  # plant integration rule
    sensorless: bool = eqx.field(static=True)
    handover: float = eqx.field(static=True)  # sensorless: encoder until this time (s), observer after
    settle: float = eqx.field(static=True)  # steady start: the observer's unscored settling phase before t = 0, s
    latency: Latency = eqx.field(static=True)  # sampling, computation delay, comparison instant (jaxobs.drive.latency)

    def __init__(
        self,
        foc,
        inverter=None,
        *,
        startup=None,
        n_sub=2,
        rule=None,
        sensorless=False,
        handover=0.0,
        settle=0.2,
        latency=None,
    ):
        if not isinstance(foc, FOC):
            raise ValueError(f"Drive.foc must be a FOC, got {type(foc).__name__}")
        self.foc = foc
        self.inverter = Inverter() if inverter is None else inverter
        if startup is not None and not isinstance(startup, IfStartup):
            raise ValueError(f"Drive.startup must be an IfStartup or None, got {type(startup).__name__}")
        self.startup = startup
        if isinstance(n_sub, bool) or not isinstance(n_sub, int) or n_sub < 1:
            raise ValueError(f"Drive.n_sub must be an integer >= 1, got {n_sub!r}")
        self.n_sub = n_sub
        self.rule = check_rule(RK4() if rule is None else rule, "Drive")
        self.sensorless = bool(sensorless)
        if not (handover >= 0.0):
            raise ValueError(f"Drive.handover must be >= 0 s, got {handover!r}")
        self.handover = float(handover)
        if not (0.0 <= settle <= 60.0):
            raise ValueError(f"Drive.settle must be in [0, 60] s, got {settle!r}")
        self.settle = float(settle)
        latency = Latency() if latency is None else latency
        if not isinstance(latency, Latency):
            raise ValueError(f"Drive.latency must be a jaxobs.drive.Latency or None, got {type(latency).__name__}")
        if latency.sample_offset and n_sub % 2:
            raise ValueError(f"Drive.n_sub must be even to sample at the PWM centre, got {n_sub!r}")
        self.latency = latency

    @property
    def ts(self) -> float:
        """The control period, s."""
        return self.foc.ts

    def settled_for(self, omega_e_min: float) -> Drive:
        """This drive with its settling phase (``settle``) at least :data:`SETTLE_PERIODS` electrical periods
        long at the lowest electrical speed it will start at, ``omega_e_min`` (rad/s, > 0; a Python number:
        the phase's length is static).

        A steady start is only steady when the observer has settled.  The flux observers' time constants scale
        with 1/ω_e, so the default 0.2 s is 0.2 electrical periods at 20 r/min on 000's SPMSM: the observer
        starts 41° off and the drive rings for seconds (docs/stability.md, "20 r/min").  The phase is only
        observer steps on synthetic measurements (cheap: 10 s of it costs about what 0.1 s of the loop does).

        Args:
            omega_e_min: The lowest electrical speed the drive will start at, rad/s (> 0; a Python number: the
                phase's length is static).

        Returns:
            The :class:`Drive` with its ``settle`` lengthened where needed.
        """
        return settled_for(self, omega_e_min)


class _Settles(Protocol):
    """A drive with a settling phase (:class:`Drive`, :class:`~jaxobs.drive.dual_loop.DualDrive`)."""

    settle: float
    __dataclass_fields__: ClassVar[dict[str, Any]]  # a dataclass (an equinox module): dataclasses.replace takes it


_D = TypeVar("_D", bound=_Settles)


def settled_for(drive: _D, omega_e_min: float) -> _D:
    """A drive with its settling phase at least :data:`SETTLE_PERIODS` electrical periods long.

    As :meth:`Drive.settled_for`, for any drive.

    Args:
        drive: A :class:`Drive` or a :class:`~jaxobs.drive.dual_loop.DualDrive`: anything with a ``settle``
            field, s.
        omega_e_min: The lowest electrical speed it will start at, rad/s (> 0).

    Returns:
        ``drive`` with its ``settle`` lengthened where needed.
    """
    name = type(drive).__name__
    w = float(omega_e_min)
    if not (math.isfinite(w) and w > 0.0):
        raise ValueError(f"{name}.settled_for: omega_e_min must be a speed > 0 rad/s, got {omega_e_min!r}")
    need = SETTLE_PERIODS * 2.0 * math.pi / w
    if need <= drive.settle:
        return drive
    if need > 60.0:
        raise ValueError(
            f"{name}.settled_for: omega_e_min must be >= {SETTLE_PERIODS * 2 * math.pi / 60.0:.3g} rad/s "
            f"({SETTLE_PERIODS:g} periods within the 60 s settle limit), got {w!r}"
        )
    return dataclasses.replace(drive, settle=need)


class LoopState(NamedTuple):
    """The closed loop's state between two periods.

    Attributes:
        plant: The machine (and its rule's state).
        ctrl: The FOC's integrators, held references, start-up.
        obs: The observer's state (None with the encoder).
        sensors: The sensors' noise key.
        u_a: The α voltage to apply over the coming period (computed last period), V.
        u_b: The β voltage, V.
        pending: (u_α, u_β) computed but due one period after the coming one (a two-period pipeline:
            :class:`Latency` with PWM-centre sampling and a one-period computation), V; None otherwise.
    """

    plant: PlantState  # the machine (and its rule's state)
    ctrl: ControllerState  # the FOC's integrators, held references, start-up
    obs: Any  # the observer's state (None with the encoder)
    sensors: jax.Array  # the sensors' noise key
    u_a: jax.Array  # the voltage to apply over the coming period (computed last period), V
    u_b: jax.Array
    # (u_α, u_β) computed but due one period after the coming one (a two-period pipeline: Latency with
    # PWM-centre sampling and a one-period computation), V; None otherwise
    pending: Any = None


class LoopInput(NamedTuple):
    """The outside world at sample k: the speed reference and the load torque.

    Attributes:
        k: The sample index.
        omega_m_ref: The mechanical speed reference, rad/s (i_q* in A when the FOC's outer loop is ``"current"``).
        load: The load torque, N·m.
    """

    k: jax.Array  # sample index
    omega_m_ref: jax.Array  # mechanical speed reference, rad/s (i_q* in A when the FOC's outer loop is 'current')
    load: jax.Array  # load torque, N·m


class DriveOutput(NamedTuple):
    """One control period's signals at t_k (under ``simulate``: each with the samples as leading axis).

    Attributes:
        t: The sample time t_k, s.
        theta_e: The true electrical angle the estimates are compared with, rad, wrapped to (−π, π]: at t_k by
            default; at the sample instant, or while the voltage computed from it acts (``drive.latency.compare``).
        theta_e_hat: The angle the controller used (encoder, observer or I-f), rad, wrapped.
        omega_m: The true mechanical speed, rad/s.
        omega_m_hat: The speed the speed loop used, rad/s.
        omega_m_ref: The speed reference, rad/s.
        i_d: The true rotor-frame d current, A.
        i_q: The true rotor-frame q current, A.
        i_a: The true stationary-frame α current, A.
        i_b: The true stationary-frame β current, A.
        u_a: The applied stationary-frame α voltage (before the dead-time error), V.
        u_b: The applied β voltage, V.
        torque: The electromagnetic torque, N·m.
        load: The load torque, N·m.
        id_ref: The d current reference, A.
        iq_ref: The q current reference, A.
        mode: 0: I-f start-up, 1: closed loop.
        obs: The observer's outputs (None with the encoder).
    """

    t: jax.Array  # sample time t_k, s
    theta_e: jax.Array  # true electrical angle the estimates are compared with, rad, wrapped to (−π, π]: at t_k by
    # default; at the sample instant, or while the voltage computed from it acts (drive.latency.compare)
    theta_e_hat: jax.Array  # angle the controller used (encoder, observer or I-f), rad, wrapped
    omega_m: jax.Array  # true mechanical speed, rad/s
    omega_m_hat: jax.Array  # speed the speed loop used, rad/s
    omega_m_ref: jax.Array  # speed reference, rad/s
    i_d: jax.Array  # true rotor-frame currents, A
    i_q: jax.Array
    i_a: jax.Array  # true stationary-frame currents, A
    i_b: jax.Array
    u_a: jax.Array  # applied stationary-frame voltage (before the dead-time error), V
    u_b: jax.Array
    torque: jax.Array  # electromagnetic torque, N·m
    load: jax.Array  # load torque, N·m
    id_ref: jax.Array  # current references, A
    iq_ref: jax.Array
    mode: jax.Array  # 0: I-f start-up, 1: closed loop
    obs: Any  # the observer's outputs (None with the encoder)

    @property
    def speed_rpm(self) -> jax.Array:
        """True mechanical speed, r/min."""
        return self.omega_m * 60 / (2 * jnp.pi)


class AbstractDriveLoop(AbstractSystem):
    """What every closed drive loop shares (:class:`ClosedLoop`, the dual three-phase
    :class:`~jaxobs.drive.dual_loop.DualClosedLoop`), each done once here: the observer rebound under the
    scenario's ``est_drift`` each period, its settling phase before t = 0 and the steady start where a
    biased observer settles, and the angle and speed the controller is given (encoder, or the observer from
    ``drive.handover``), the observer held at the I-f frequency during an I-f start-up.  A subclass has
    ``drive`` (with ``settle``, ``sensorless``, ``handover``, ``latency``, ``startup``), ``observer`` and
    ``scenario``, and gives :attr:`pole_pairs`, :meth:`operating_point` and :meth:`_steady_voltage`."""

    # passes of the observer's settling phase before t = 0 in a sensorless steady start: the first measures
    # the observer's steady angle error, the next settle it on the operating point under that error (init)
    settle_passes: ClassVar[int] = 2
    drive: eqx.AbstractVar[Any]  # a Drive or a DualDrive (settle, sensorless, handover, latency, startup)
    observer: eqx.AbstractVar[AbstractObserver | None]
    scenario: eqx.AbstractVar[Scenario]

    @property
    @abc.abstractmethod
    def plant(self) -> Any:
        """The true machine behind the drive's inverter (a :class:`PMSM` or a dual one)."""

    @property
    @abc.abstractmethod
    def controller(self) -> Any:
        """The controller bound to the scenario's assumed machine (a :class:`FOC` or a dual one)."""

    @property
    @abc.abstractmethod
    def pole_pairs(self) -> int:
        """The true machine's pole pairs."""

    @abc.abstractmethod
    def operating_point(self, offset: jax.Array | float = 0.0) -> OperatingPoint:
        """The steady state the scenario starts in.

        Args:
            offset: The controller's frame's lead over the rotor's, rad.

        Returns:
            The :class:`OperatingPoint`.
        """

    @abc.abstractmethod
    def _steady_voltage(self, op: OperatingPoint, theta: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(u_α, u_β) applied at steady state over the period that starts where the rotor is at ``theta``, V."""

    def _steady_start(self, op: OperatingPoint):
        """The operating point a steady start begins at and the observer's state there (None with the encoder):
        the observer settled on ``op`` (:meth:`_settled_observer`), and, when it closes the loop from t = 0,
        on the operating point under its own steady angle error."""
        obs = None
        if self.observer is not None:
            obs, offset = self._settled_observer(op)
            if self.drive.sensorless and self.drive.handover <= 0.0:
                # A biased observer (the LPF's steady lead, a LESO's lag) closes the loop from t = 0, so the drive
                # settles with the FOC's frame at the observer's steady angle error, not at the rotor's: the
                # currents that carry the load are its references rotated by that error (FOC.operating_point).
                # The error on the first settling gives the operating point, and the observer settles again on
                # it (each pass from its own start, init_at: a settled observer fed a step of the currents' phase
                # sees an L·di/dt spike).  The error of a LESO or an LPF with the machine it assumes is the phase
                # of its filter at ω_e, whatever the currents: two passes are its fixed point.  With an L̂q error
                # each pass brings the start closer (settle_passes: docs/performance.md).
                for _ in range(self.settle_passes - 1):
                    # beyond 90° no current in the observer's frame carries the load (it brakes): no steady
                    # state to start in, so such an observer (not locked in its settling) starts as before
                    op = self.operating_point(jnp.where(jnp.abs(offset) < jnp.pi / 2, offset, 0.0))
                    obs, offset = self._settled_observer(op)
        return op, obs

    def _observe(self, obs_state, meas, t, iq_ref=None):
        """The observer's step at time ``t`` (s) on ``meas`` (a DriveInput): (state, outputs); Nones for the
        encoder.  ``iq_ref`` (A), the q-current reference held over the period just ended, gives the observer
        the torque reference ``T_ref`` where its speed estimator reads one (:meth:`_with_torque`)."""
        if self.observer is None:
            return None, None
        return self._observer_at(t).step(obs_state, self._with_torque(meas, iq_ref))

    def _with_torque(self, meas, iq_ref):
        """``meas`` with ``T_ref``, the torque the controller's policy gives ``iq_ref`` on the machine it assumes
        (1.5 p (ψ̂f i_q* + (L̂d − L̂q) i_d*(i_q*) i_q*), field weakening's Δi_d left out), where the observer's
        speed estimator reads it (a mechanical model, jaxobs.observers.speed) and the controller is a
        :class:`FOC`; ``meas`` itself otherwise."""
        observer = self.observer  # a drive observer, or an ObserverBank (any of its observers); a bare observer
        # (a wrapper of the export's golden vectors) reads no torque
        if iq_ref is None or not (isinstance(observer, AbstractDriveObserver) and observer.reads_torque):
            return meas
        foc = self.controller
        if not isinstance(foc, FOC):  # the dual three-phase loop's controller: no torque reference (T* = 0)
            return meas
        return meas._replace(T_ref=foc._policy_torque(foc.est, iq_ref))

    def _feedback(self, t, obs_out, theta_e, omega_e, omega_m):
        """The angle (rad), electrical and mechanical speeds (rad/s) the controller uses at time ``t``: the
        encoder's ``theta_e``, ``omega_e``, ``omega_m``, or, sensorless from ``drive.handover`` on, the observer's."""
        drive = self.drive
        if not drive.sensorless:
            return theta_e, omega_e, omega_m
        # before the hand-over time the encoder runs the drive while the observer converges
        use_obs = t >= drive.handover
        th_c = jnp.where(use_obs, obs_out.theta, theta_e)
        w_e_c = jnp.where(use_obs, obs_out.omega, omega_e)
        return th_c, w_e_c, w_e_c / self.pole_pairs

    def _rest_start(self):
        """The parts of an I-f start-up from standstill, for both loops' ``init``: the operating point at rest,
        the plant, the observer's own initial state, the controller with the I-f angle at θ_e0 − 90° (the
        rotor parked on the current vector, where an alignment phase leaves it) and the sensors."""
        sc = self.scenario
        op = OperatingPoint.at_rest(sc.theta_e0)
        obs = None if self.observer is None else self.observer.init()
        ctrl = self.controller.init(op, theta_f0=sc.theta_e0 - jnp.pi / 2)
        return op, self.plant.init(op), obs, ctrl, sc.sensors.init(op, key=sc.key)

    def _seed_observer(self, obs_state, ctrl: ControllerState):
        """The observer's state held at the I-f frequency while the drive's I-f start-up runs (``ctrl.mode``
        0), released at the switch; ``obs_state`` itself without a start-up or a drive observer."""
        if self.drive.startup is None or not isinstance(self.observer, AbstractDriveObserver):
            return obs_state
        # While the I-f runs, the observer's speed estimate (FLL centre frequency, PLL integrator) is held
        # at the I-f frequency, the rotor's mean speed; released at the switch.  Without it the flux
        # observers' FLLs never left their initial 1 rad/s: their gain is lam·ω̂² (frequency-normalized,
        # jaxobs.observers.flux), so at ω̂ = 1 rad/s they adapt in ~1 s, while the I-f ramp takes 0.1 s —
        # the SOGIs, centred at 1 rad/s, then gave a flux of the wrong phase and amplitude and the drive
        # ran away at the hand-over.  A DSP knows ω_f too: it is the FLL's feed-forward, not a cheat.
        seeded = self.observer.seed_speed(obs_state, ctrl.omega_f)
        return jax.tree.map(lambda a, b: jnp.where(ctrl.mode == 0, a, b), seeded, obs_state)

    def _observer_at(self, t: jax.Array | float) -> AbstractObserver:
        """The observer assuming the scenario's machine at time ``t`` (s): itself, or rebound by its one binding
        to ``est_par`` under the scenario's drift (:class:`~jaxobs.drive.ParameterDrift`; 002 Fig. 18).  The
        speed given to bind() only sets the initial-speed field, which no step reads."""
        obs = self.observer
        assert obs is not None  # called only where an observer runs
        drift = self.scenario.est_drift
        if drift is None or not isinstance(obs, AbstractDriveObserver):
            return obs
        sc = self.scenario
        return obs.bind(drift.at(sc.est_par, t), self.pole_pairs * sc.omega_m0)

    def _settled_observer(self, op: OperatingPoint):
        """The observer after ``drive.settle`` seconds on the steady operating point (a phase before t = 0,
        unscored), and its steady angle error θ̂e − θe, rad.

        A drive observer (:class:`~jaxobs.observers.AbstractDriveObserver`) starts from
        ``observer.init_aligned(ω_e, θ_e)`` (its speed estimate at the true speed, a PLL's angle at the rotor's)
        and steps on the measurements the sensors give
        of the steady machine over k = −n … −1 (offsets, gain errors and noise
        included; θ_k = θ_e0 + ω_e k T_s, the voltage of each period centred at
        θ_k + ω_e T_s/2 as the delay compensation applies it).  So its filters,
        FLL and PLL are locked when the scored horizon starts, by the observer's
        own dynamics rather than by a formula per observer.  The angle error is
        the circular mean over the last quarter of the phase (sensor noise and
        ripple averaged out), 0 without a settling phase.
        """
        sc, obs, ts = self.scenario, self._observer_at(0.0), self.ts
        w_e = self.pole_pairs * op.omega_m
        # a drive observer starts at the true speed (its contract); any other observer (a probe) from its init()
        state = obs.init_at(w_e) if isinstance(obs, AbstractDriveObserver) else obs.init()
        n = int(round(self.drive.settle / ts))
        if n == 0:
            return state, jnp.zeros_like(w_e)
        if isinstance(obs, AbstractDriveObserver):
            # and, settling, with its angle state (a PLL's) at the rotor's angle where the phase starts (the
            # state before the step to t_−n): from 0 instead, the PLL's first error was θ_e0 − ω_e·settle, any
            # angle, and the settled observer depended erratically on the settle's length (init_aligned)
            state = obs.init_aligned(w_e, wrap(op.theta_e - w_e * ((n + 1) * ts)))
        tail = max(1, n // 4)
        lat = self.drive.latency

        def settle_step(carry, k):
            s, acc = carry
            th = op.theta_e + w_e * (k * ts)
            u_a, u_b = self._steady_voltage(op, th + min(lat.pipeline - 1, 0) * w_e * ts)
            if lat.sample_offset:  # the currents (and the angle compared) at the sample instant
                th = th + lat.sample_offset * w_e * ts
            i_a, i_b = dq_to_ab(op.i_d, op.i_q, th)
            _, meas = sc.sensors.step(sc.key, SensorInput(k, u_a, u_b, i_a, i_b))
            s, out = obs.step(s, self._with_torque(meas, op.i_q))
            err = out.theta - th
            counted = k >= -tail
            acc = acc + jnp.where(counted, jnp.stack([jnp.cos(err), jnp.sin(err)]), 0.0)
            return (s, acc), None

        acc0 = jnp.zeros((2,), jnp.result_type(w_e, float))
        (state, acc), _ = jax.lax.scan(settle_step, (state, acc0), jnp.arange(-n, 0, dtype=jnp.int32))
        return state, jnp.arctan2(acc[1], acc[0])


class ClosedLoop(AbstractDriveLoop):
    """The drive ``drive`` running ``scenario``, with ``observer`` (or the encoder when None): a system.

    Args:
        drive: The :class:`Drive`.
        observer: An observer (a :class:`~jaxobs.observers.AbstractObserver`, usually a drive observer), or
            None: the encoder.
        scenario: The :class:`Scenario`.

    Raises:
        ValueError: An argument of the wrong type, or a sensorless drive without an observer.
    """

    drive: Drive
    observer: AbstractObserver | None
    scenario: Scenario

    # loop unrolling (jaxobs.runtime._loop point 3): 1, the drive step is large, and
    # unrolling it made XLA's CPU fusion duplicate work (forward 3.1 → 1.3 M
    # scenario-steps/s at 2) and its reverse-mode compile blow up (> 200 s).
    unroll: ClassVar[int] = 1

    def __init__(self, drive: Drive, observer, scenario: Scenario):
        if not isinstance(drive, Drive):
            raise ValueError(f"ClosedLoop.drive must be a jaxobs.drive.Drive, got {type(drive).__name__}")
        if not isinstance(scenario, Scenario):
            raise ValueError(f"ClosedLoop.scenario must be a jaxobs.drive.Scenario, got {type(scenario).__name__}")
        if observer is not None and not isinstance(observer, AbstractObserver):
            raise ValueError(
                f"ClosedLoop.observer must be an observer (a jaxobs.observers.AbstractObserver: init and step) or "
                f"None, got {type(observer).__name__}"
            )
        if drive.sensorless and observer is None:
            raise ValueError("ClosedLoop: a sensorless drive needs an observer (observer=None is the encoder)")
        check_sample_time("ts", drive.ts, "Drive")
        # one observer step per control period: one built at another ts would integrate the wrong interval each step
        if observer is not None and abs(float(observer.ts) - float(drive.ts)) > TS_REL_TOL * float(drive.ts):
            raise ValueError(
                f"ClosedLoop: the observer runs at ts = {float(observer.ts):g} s, the drive at {float(drive.ts):g} s: "
                "they must agree (build the observer with ts=drive.ts)"
            )
        self.drive = drive
        self.observer = observer
        self.scenario = scenario

    @property
    def ts(self) -> float:
        """The control period, s."""
        return self.drive.ts

    @property
    def pole_pairs(self) -> int:
        return self.scenario.par.p

    # --- the parts, bound to this scenario
    @property
    def plant(self) -> PMSM:
        """The true machine behind the drive's inverter, with the scenario's dead time."""
        d, sc = self.drive, self.scenario
        # the constructor's checks pass traced leaves through (jaxobs.core.validate)
        return PMSM(sc.par, d.inverter, sc.dead_time, ts=d.ts, n_sub=d.n_sub, rule=d.rule)

    @property
    def _half_plant(self) -> PMSM:
        """The plant over half a period (sampling at the PWM centre: two halves per period, the same substeps)."""
        d, sc = self.drive, self.scenario
        return PMSM(sc.par, d.inverter, sc.dead_time, ts=d.ts / 2, n_sub=d.n_sub // 2, rule=d.rule)

    @property
    def _lag(self) -> float:
        """Periods by which the voltage acts behind the angle the FOC rotated it to: the use delay less the
        FOC's advance (0 by default: 1.5 − 1.5).  A steady start's current-PI integrators absorb it."""
        return self.drive.latency.use_delay - self.drive.foc.advance

    @property
    def controller(self) -> FOC:
        """The FOC with the scenario's assumed machine, the inverter's voltage limit and the drive's start-up."""
        return self.drive.foc.bind(self.scenario.est_par, self.drive.inverter.u_max, self.drive.startup)

    def operating_point(self, offset: jax.Array | float = 0.0) -> OperatingPoint:
        """The steady state the scenario starts in: its initial speed, the load at t = 0, currents that carry it.

        Args:
            offset: The controller's frame's lead over the rotor's, rad (:meth:`FOC.operating_point`).

        Returns:
            The :class:`OperatingPoint`.
        """
        sc = self.scenario
        return self.controller.operating_point(
            sc.par, sc.omega_m0, sc.speed_ref(0.0), sc.theta_e0, sc.load(0.0), offset
        )

    def init(self) -> LoopState:
        """The loop at t = 0: a steady start, or standstill with an I-f start-up.

        Without a start-up the scenario starts in the steady state of its
        initial speed and the load at t = 0 (a scenario tests what it claims: no
        transient nobody asked for): the machine carries the currents that balance the load,
        the FOC's integrators hold them (:meth:`FOC.init`), the voltage of the
        period that starts at t = 0 is the steady one (computed at t_{−1}, so
        rotated to θ_e0 + ω_e T_s/2 by the delay compensation), and the
        observer starts settled on that operating point (:meth:`_settled_observer`).
        An observer that closes the loop from t = 0 (sensorless, no hand-over)
        starts at the operating point under its own steady angle error, the FOC's
        references met in the observer's frame (``OperatingPoint.offset``; the
        reasons and measurements in the code below).
        With the drive's I-f start-up the scenario starts from standstill (whatever
        its ``omega_m0``: an I-f start-up from a spinning rotor would be a different
        problem, and a job's scenarios keep their speed for the observer's binding), all zeros, with the I-f angle at
        θ_e0 − 90°: the rotor parked on the current vector, where an alignment
        phase leaves it (:mod:`jaxobs.drive.control`, step 1).
        """
        sc = self.scenario
        foc = self.controller
        # every component starts from one operating point, by the one convention (jaxobs.drive.component)
        if self.drive.startup is not None:
            _, plant, obs, ctrl, sensors = self._rest_start()
            z = jnp.zeros((), plant.x.dtype)
            # at rest no voltage is pending either: a pipeline of 2 holds a zero one (it was None, and the
            # step indexed it: an I-f start on the PWM-centre timing failed)
            pending = jnp.zeros((2,), z.dtype) if self.drive.latency.pipeline == 2 else None
            return LoopState(plant=plant, ctrl=ctrl, obs=obs, sensors=sensors, u_a=z, u_b=z, pending=pending)
        op, obs = self._steady_start(self.operating_point())
        plant = self.plant.init(op)
        inverter = self.drive.inverter
        lat, w_e = self.drive.latency, sc.par.p * op.omega_m
        ctrl_op = op
        if self._lag != 0.0:
            # the voltage acts _lag periods behind the FOC's angle: its integrators hold the needed voltage
            # rotated ahead by that much, so that the voltage applied is centred on the rotor's period
            u_d, u_q = dq_to_ab(op.u_d, op.u_q, self._lag * w_e * self.ts)
            ctrl_op = op._replace(u_d=u_d, u_q=u_q)
        # the voltage of the coming period (for a pipeline of 0: of the period just ended, what the observer
        # is told at the first sample) and, for a pipeline of 2, the one after it
        u_a, u_b = self._steady_voltage(op, op.theta_e + min(lat.pipeline - 1, 0) * w_e * self.ts)
        _, u = inverter.step(inverter.init(op), InverterInput(u_a, u_b))
        pending = None
        if lat.pipeline == 2:
            u_a, u_b = self._steady_voltage(op, op.theta_e + w_e * self.ts)
            _, pending = inverter.step(inverter.init(op), InverterInput(u_a, u_b))
            pending = jnp.stack([pending.u_a, pending.u_b])
        sensors = sc.sensors.init(op, key=sc.key)
        return LoopState(
            plant=plant, ctrl=foc.init(ctrl_op), obs=obs, sensors=sensors, u_a=u.u_a, u_b=u.u_b, pending=pending
        )

    def _steady_voltage(self, op: OperatingPoint, theta):
        """(u_α, u_β) applied over the period that starts where the rotor is at ``theta``, at steady state:
        centred at θ + ω_e T_s/2 (the FOC's integrators absorb what its delay compensation leaves, init)."""
        w_e = self.scenario.par.p * op.omega_m
        lead = 0.5 * w_e * self.ts
        return dq_to_ab(op.u_d, op.u_q, theta + lead)

    def step(self, state: LoopState, k: jax.Array) -> tuple[LoopState, DriveOutput]:
        """One control period of the closed loop: sample, observe, control, then the plant over the period.

        Args:
            state: The :class:`LoopState`.
            k: The sample index.

        Returns:
            ``(the next LoopState, the DriveOutput)``.
        """
        drive, sc = self.drive, self.scenario
        t = k * self.ts
        # The profiles are evaluated here, inside the step, not a block of steps at a
        # time (as OnSignal's signal is): evaluated apart, XLA fused their arithmetic
        # differently (last-bit differences), and a user's own scan of this step must
        # give exactly what simulate gives.  They are a handful of compares per step.
        x = LoopInput(k=k, omega_m_ref=sc.speed_ref(t), load=sc.load(t))
        lat = drive.latency
        # ys: the machine at the sample instant; y: at t_k (the outputs).  The sensors are told the voltage
        # in state.u: that of this period (pipeline ≥ 1), or of the one just ended (pipeline 0).
        if lat.sample_offset:
            held = PlantInput(state.u_a, state.u_b, x.load)
            mid, y = self._half_plant.step(state.plant, held)
            plant_state, ys = self._half_plant.step(mid, held)
        elif lat.pipeline == 0:
            y = ys = self.plant.output(state.plant.x)  # integrated below, under the voltage computed now
        else:
            plant_state, y = self.plant.step(state.plant, PlantInput(state.u_a, state.u_b, x.load))
            ys = y
        key, meas = sc.sensors.step(state.sensors, SensorInput(k, state.u_a, state.u_b, ys.i_a, ys.i_b))
        obs_state, obs_out = self._observe(state.obs, meas, t, state.ctrl.iq_ref)
        w_e = sc.par.p * ys.omega_m
        th_c, w_e_c, w_m_c = self._feedback(t, obs_out, ys.theta_e, w_e, ys.omega_m)
        ctrl, c = self.controller.step(state.ctrl, FOCInput(k, meas.i_a, meas.i_b, th_c, w_e_c, w_m_c, x.omega_m_ref))
        obs_state = self._seed_observer(obs_state, ctrl)
        _, u_next = drive.inverter.step(drive.inverter.init(), InverterInput(c.u_a, c.u_b))  # stateless
        applied, pending = state, None  # the voltage over [t_k, t_{k+1}] (as u_a, u_b) and the one after it
        if lat.pipeline == 0:  # computed from this period's sample, applied at once (an ideal controller)
            plant_state, _ = self.plant.step(state.plant, PlantInput(u_next.u_a, u_next.u_b, x.load))
            applied = u_next
        elif lat.pipeline == 2:
            u_next, pending = InverterInput(state.pending[0], state.pending[1]), jnp.stack([u_next.u_a, u_next.u_b])
        lead = lat.compare_lead
        # the rotor at the comparison instant, extrapolated from the sample at its speed (latency module doc)
        theta_cmp = ys.theta_e if lead == 0.0 else ys.theta_e + w_e * (lead * self.ts)
        out = DriveOutput(
            t=t,
            theta_e=wrap(theta_cmp),
            theta_e_hat=wrap(c.theta),
            omega_m=y.omega_m,
            omega_m_hat=w_m_c,
            omega_m_ref=x.omega_m_ref,
            i_d=y.i_d,
            i_q=y.i_q,
            i_a=y.i_a,
            i_b=y.i_b,
            u_a=applied.u_a,
            u_b=applied.u_b,
            torque=y.torque,
            load=x.load,
            id_ref=c.id_ref,
            iq_ref=c.iq_ref,
            mode=ctrl.mode,
            obs=obs_out,
        )
        new = LoopState(
            plant=plant_state, ctrl=ctrl, obs=obs_state, sensors=key, u_a=u_next.u_a, u_b=u_next.u_b, pending=pending
        )
        return new, out
