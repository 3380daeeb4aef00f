"""The dual three-phase drive: its two current-control modes and the closed loop (paper 002, Sec. V-B).

Current control, :class:`DualFOC` with ``mode`` (both reuse :class:`~jaxobs.drive.FOC` unchanged: its
speed loop, dq current PIs with decoupling, delay compensation, anti-windup):

- ``"vsd"``: VSD control (002 Fig. 15; its refs [5], [6]).  The FOC runs on the αβ subspace (i_αβ =
  the mean of the two sets' Clarke currents) in the rotor frame, tuned on :meth:`DualPMSMParams.per_set`
  (the αβ inductances, half the rotor); a PI per xy axis drives i_x, i_y to zero,
  u_xy = k_p,xy e + k_i,xy ∫e with IMC gains k_p,xy = α_c L̂ls, k_i,xy = α_c R̂s.  The xy disturbance is
  the BEMF's 5th/7th harmonics, at 5ωe and 7ωe in the stationary xy frame: a PI there attenuates it by
  its loop gain, it does not cancel it (resonant or rotating-frame xy controllers would; 002 does not
  say which it used).  Each set's voltage is then z_αβ ± conj(z_xy).  Field weakening (the FOC's
  ``field_weakening``) holds the αβ voltage, the FOC's own |u*|, at its margin by default (``fw_voltage="ab"``);
  ``fw_voltage="set"`` holds the larger set voltage |z_αβ ± conj(z_xy)| there instead, on a deeper i_d: the xy
  voltage rides on top of the αβ one.  Sensorless that deeper i_d costs the speed loop its damping (the
  :class:`DualFOC` field's comment has the numbers; docs/papers.md, 330 V).
- ``"individual"``: two individual sets (002 Figs 13-14; ref [6]).  Each set has its own dq frame, set 2's
  30° behind set 1's in its own Clarke coordinates (θ_e − π/6: its a-axis is 30° ahead), and its own
  FOC PI state; the gains are the IMC design on one set's self inductances (:meth:`DualPMSMParams.set_self`)
  and the mutual coupling through the other set is left to the PIs, as in ref. [6].  Both FOCs run the
  same speed loop on the same inputs, so they hold the same i_q* (each set carries half the torque).
  The common mode (xy = 0) then has the bandwidth α_c (L + Lls)/(2L) and the differential mode (the
  xy currents) α_c (L + Lls)/(2 Lls): 1.83 α_c on q with the assumed machine (Lls = 4.5 mH).  At the
  single bench's α_c = 2π·300 rad/s that crossover, 3460 rad/s, leaves 60° of phase margin to the
  1.5-sample delay; both modes use that α_c (:func:`dual_bench_drive`).
  Nothing here acts on the 5th/7th: 002 adds no harmonic control to the individual sets (ref. [6]'s
  two-individual control is dq PIs per set, which pass the 6ωe ripple the 5th/7th make in each set's dq
  frame), and its point in Figs 13-14 is to show the LESOs facing them.  The PIs' gain at 6ωe still
  shrinks the xy currents (0.44 A rms at 300 r/min half load, 0.90 A at 600 r/min 40 %); what remains is in
  set 1's equivalent BEMF as (L̂q − Lls) di_xy/dt (jaxobs.papers, DUAL_LLS_002).

The observer (``DriveInput``) is chosen by the mode: set 1's measured voltage and current under
``"individual"`` (002: "the LESOs are only applied to the first set"), the VSD αβ ones under ``"vsd"``.

:class:`DualClosedLoop` is :class:`~jaxobs.drive.ClosedLoop`'s wiring for this machine (same step
order: plant at t_k, sensors, observer, controller, inverter), sharing its machinery through
:class:`~jaxobs.drive.loop.AbstractDriveLoop`: the observer rebound each period under ``scenario.est_drift``,
the encoder/observer hand-over, and the steady start: the machine at the scenario's speed and load (each set
carrying half), the FOC integrators holding it, the observer settled on it for ``drive.settle`` s (0.2 by
default, as :class:`~jaxobs.drive.Drive`'s; with 0 it starts from ``init_at(ω_e)`` and converges on the
encoder-run drive until ``drive.handover``) and, closing the loop from t = 0, started where it settles; or,
with ``DualDrive(startup=IfStartup(...))``, from standstill through the I-f ramp (both sets' FOCs run it; the
observer held at the I-f frequency).  The timing is the default one (no Latency).
The scenario gives the profiles, sensors (applied to each set; set 2's noise from another key), dead
time and ``est_par`` (what the observers assume: the per-set machine); the true machine is ``machine``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, ClassVar, Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .. import papers
from ..core.discretize import RK4, AbstractRule, check_rule
from ..core.measurements import DriveInput
from ..core.numerics import safe_norm2, wrap
from ..core.validate import check_nonnegative, check_positive
from .component import AbstractComponent
from .control import FOC, ControllerState, FOCInput, IfStartup, OperatingPoint
from .dual import DualPlantInput, DualPlantState, DualPMSM, DualPMSMParams, sets_to_vsd, vsd_to_sets
from .hardware import Inverter
from .latency import Latency
from .loop import AbstractDriveLoop, settled_for
from .machine import dq_to_ab
from .scenario import Scenario

__all__ = [
    "DualFOC",
    "DualFOCInput",
    "DualFOCOutput",
    "DualFOCState",
    "DualDrive",
    "DualClosedLoop",
    "DualOutput",
    "dual_bench_drive",
]

_C30, _S30 = math.cos(math.pi / 6), math.sin(math.pi / 6)


def _rot(a, b, c, s):
    return c * a - s * b, s * a + c * b


class DualFOCInput(NamedTuple):
    """What the dual FOC is given at sample ``k`` (each set's currents, the angle and speeds it uses)."""

    k: jax.Array
    i_a1: jax.Array  # measured Clarke currents of each set (set 1's stationary frame), A
    i_b1: jax.Array
    i_a2: jax.Array
    i_b2: jax.Array
    theta: jax.Array  # electrical angle the controller uses, rad
    omega_e: jax.Array  # rad/s
    omega_m: jax.Array  # rad/s
    omega_m_ref: jax.Array  # rad/s


class DualFOCOutput(NamedTuple):
    """What the dual FOC gives each period: each set's voltage, the references and the angle used."""

    u_a1: jax.Array  # each set's voltage for the next period (set 1's frame, before the inverters' limit), V
    u_b1: jax.Array
    u_a2: jax.Array
    u_b2: jax.Array
    id_ref: jax.Array  # A
    iq_ref: jax.Array
    theta: jax.Array  # rad


class DualFOCState(NamedTuple):
    """The dual FOC's state: the αβ (or each set's) FOC state and the xy PI integrators."""

    main: ControllerState  # the αβ FOC ("vsd") or set 1's ("individual")
    second: ControllerState  # set 2's ("individual"; carried unused under "vsd")
    int_x: jax.Array  # xy PI integrators, V
    int_y: jax.Array


class DualFOC(AbstractComponent):
    """Current control of the dual machine, ``mode`` "vsd" or "individual" (module doc)."""

    foc: FOC
    kp_xy: jax.Array  # V/A
    ki_xy: jax.Array  # V/(A·s)
    mode: Literal["vsd", "individual"] = eqx.field(static=True)
    # the voltage the field weakening holds at its margin under "vsd": "ab", the αβ voltage (the FOC's own
    # |u*|), or "set", each set's |z_αβ ± conj(z_xy)| (the larger).  Both loops have the same gain (the xy
    # voltage does not depend on i_d: ∂|u|/∂i_d ≈ ω̂e L̂d either way, a first-order loop at α_fw, 20 Hz) and
    # neither sees the observer's angle error (|u| is a magnitude); they differ in the i_d they settle on.
    # "set" fits the xy PIs' voltage under the margin too, which takes a deeper i_d, and a lagging estimate
    # turns i_d into accelerating torque (K_δ = 1.5 p ψf i_d): the deeper i_d destabilizes the sensorless speed
    # loop (tests/test_dual.py; docs/performance.md).  So "ab" is the default; it leaves a set at its inverter's
    # limit part of the time (that set's current loop then has no voltage in reserve).  002
    # does not say which voltage its field weakening (its ref. [32]) budgets.  "individual" is per set either
    # way (each set's FOC limits its own).
    fw_voltage: Literal["ab", "set"] = eqx.field(static=True)

    def __init__(
        self,
        foc: FOC,
        kp_xy: jax.Array | float = 1.0,
        ki_xy: jax.Array | float = 0.0,
        *,
        mode: Literal["vsd", "individual"] = "vsd",
        fw_voltage: Literal["ab", "set"] = "ab",
    ) -> None:
        if not isinstance(foc, FOC):
            raise ValueError(f"DualFOC.foc must be a FOC, got {type(foc).__name__}")
        if mode not in ("vsd", "individual"):
            raise ValueError(f"DualFOC.mode must be 'vsd' or 'individual', got {mode!r}")
        if fw_voltage not in ("ab", "set"):
            raise ValueError(f"DualFOC.fw_voltage must be 'ab' or 'set', got {fw_voltage!r}")
        self.foc = foc
        self.kp_xy = check_positive("kp_xy", kp_xy, "DualFOC")
        self.ki_xy = check_nonnegative("ki_xy", ki_xy, "DualFOC")
        self.mode = mode
        self.fw_voltage = fw_voltage

    @classmethod
    def imc(
        cls,
        est: DualPMSMParams,
        alpha_c: jax.Array | float,
        alpha_s: jax.Array | float,
        *,
        mode: Literal["vsd", "individual"] = "vsd",
        fw_voltage: Literal["ab", "set"] = "ab",
        **kw: Any,
    ) -> DualFOC:
        """IMC current loops at ``alpha_c`` rad/s and the double-pole speed loop at ``alpha_s`` on ``est``.

        "vsd": :meth:`FOC.imc` on ``est.per_set()``, xy PIs k_p = α_c L̂ls, k_i = α_c R̂s.  "individual":
        :meth:`FOC.imc` on ``est.set_self()``; its differential mode runs (L̂q + L̂ls)/(2 L̂ls) times faster
        than ``alpha_c`` (module doc): lower ``alpha_c`` on a machine of small L̂ls.

        Args:
            est: The dual machine the controller assumes.
            alpha_c: The current loops' bandwidth, rad/s.
            alpha_s: The speed loop's double pole, rad/s.
            mode: ``"vsd"`` or ``"individual"``.
            fw_voltage: The voltage the field weakening budgets, ``"ab"`` or ``"set"``.
            **kw: Other :class:`FOC` keywords.

        Returns:
            The :class:`DualFOC`.
        """
        if not isinstance(est, DualPMSMParams):
            raise ValueError(f"DualFOC.imc: est must be a DualPMSMParams, got {type(est).__name__}")
        if mode not in ("vsd", "individual"):
            raise ValueError(f"DualFOC.mode must be 'vsd' or 'individual', got {mode!r}")
        machine = est.per_set() if mode == "vsd" else est.set_self()
        foc = FOC.imc(machine, alpha_c, alpha_s, **kw)
        return cls(foc, alpha_c * est.Lls, alpha_c * est.m.Rs, mode=mode, fw_voltage=fw_voltage)

    def init(self, op: OperatingPoint | None = None, *, theta_f0: jax.Array | float = 0.0) -> DualFOCState:
        """The integrators that hold the drive at ``op`` (per set; zero xy), zeros for None; with the FOC's
        I-f start-up its angle at ``theta_f0`` (rad; set 2's FOC, in its own frame, 30° behind).

        Args:
            op: The :class:`OperatingPoint` (per set), or None.
            theta_f0: The I-f angle to start from, rad.

        Returns:
            The :class:`DualFOCState`.
        """
        cs = self.foc.init(op, theta_f0=theta_f0)
        second = cs if self.foc.startup is None else self.foc.init(op, theta_f0=theta_f0 - math.pi / 6)
        z = jnp.zeros_like(cs.int_d)
        return DualFOCState(main=cs, second=second, int_x=z, int_y=z)

    def _xy_pi(self, int_, i, ts, u_max):
        e = -i
        int_new = jnp.clip(int_ + self.ki_xy * e * ts, -u_max, u_max)
        return int_new, self.kp_xy * e + int_

    def step(self, cs: DualFOCState, inp: DualFOCInput) -> tuple[DualFOCState, DualFOCOutput]:
        """One current-loop period of the dual FOC: each set's voltage for the next period.

        Args:
            cs: The :class:`DualFOCState`.
            inp: The :class:`DualFOCInput`.

        Returns:
            ``(the next DualFOCState, the DualFOCOutput)``.
        """
        foc, ts = self.foc, self.foc.ts
        k, th, w_e, w_m, ref = inp.k, inp.theta, inp.omega_e, inp.omega_m, inp.omega_m_ref
        if self.mode == "vsd":
            i_a, i_b, i_x, i_y = sets_to_vsd(inp.i_a1, inp.i_b1, inp.i_a2, inp.i_b2)
            main, o = foc.step(cs.main, FOCInput(k, i_a, i_b, th, w_e, w_m, ref))
            int_x, u_x = self._xy_pi(cs.int_x, i_x, ts, foc.u_max)
            int_y, u_y = self._xy_pi(cs.int_y, i_y, ts, foc.u_max)
            u = vsd_to_sets(o.u_a, o.u_b, u_x, u_y)
            fw = foc.field_weakening
            if self.fw_voltage == "set" and fw is not None:
                # the FOC's Δi_d update redone on the sets' voltage: the αβ one after the FOC's limit (a
                # saturated αβ voltage already puts a set at or above u_max, so Δi_d still grows), plus xy
                mag = jnp.maximum(safe_norm2(u[0], u[1]), safe_norm2(u[2], u[3]))
                id_fw = fw.update(cs.main.id_fw, mag, foc.u_max, w_e, foc.est.Ld, foc.i_max, ts)
                main = dataclasses.replace(main, id_fw=id_fw)
            new = DualFOCState(main=main, second=cs.second, int_x=int_x, int_y=int_y)
            return new, DualFOCOutput(*u, o.id_ref, o.iq_ref, o.theta)
        main, o1 = foc.step(cs.main, FOCInput(k, inp.i_a1, inp.i_b1, th, w_e, w_m, ref))
        # set 2 in its own Clarke frame (a2 axis 30° ahead of a1): currents rotated back 30°, angle θ − 30°,
        # its voltage rotated forward again into set 1's frame
        j_a, j_b = _rot(inp.i_a2, inp.i_b2, _C30, -_S30)
        second, o2 = foc.step(cs.second, FOCInput(k, j_a, j_b, th - math.pi / 6, w_e, w_m, ref))
        u_a2, u_b2 = _rot(o2.u_a, o2.u_b, _C30, _S30)
        new = DualFOCState(main=main, second=second, int_x=cs.int_x, int_y=cs.int_y)
        return new, DualFOCOutput(o1.u_a, o1.u_b, u_a2, u_b2, o1.id_ref, o1.iq_ref, o1.theta)


class DualDrive(eqx.Module):
    """The dual drive's hardware and controller: :class:`DualFOC`, one inverter per set (alike)."""

    ctrl: DualFOC
    inverter: Inverter
    startup: IfStartup | None
    n_sub: int = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)
    sensorless: bool = eqx.field(static=True)
    handover: float = eqx.field(static=True)  # sensorless: encoder until this time (s), observer after
    # steady start: the observer's unscored settling phase before t = 0, s (Drive.settle, and its default 0.2:
    # with 0 the observer starts from init_at(ω_e) and its own start-up transient runs into the scored horizon
    # while the encoder runs the drive until the hand-over, a transient the single loop does not have)
    settle: float = eqx.field(static=True)

    def __init__(
        self, ctrl, inverter=None, *, startup=None, n_sub=2, rule=None, sensorless=False, handover=0.2, settle=0.2
    ):
        if not isinstance(ctrl, DualFOC):
            raise ValueError(f"DualDrive.ctrl must be a DualFOC, got {type(ctrl).__name__}")
        self.ctrl = ctrl
        self.inverter = Inverter() if inverter is None else inverter
        if startup is not None and not isinstance(startup, IfStartup):
            raise ValueError(f"DualDrive.startup must be an IfStartup or None, got {type(startup).__name__}")
        self.startup = startup
        if isinstance(n_sub, bool) or not isinstance(n_sub, int) or n_sub < 1:
            raise ValueError(f"DualDrive.n_sub must be an integer >= 1, got {n_sub!r}")
        self.n_sub = n_sub
        self.rule = check_rule(RK4() if rule is None else rule, "DualDrive")
        self.sensorless = bool(sensorless)
        if not (0.0 <= handover <= 100.0):
            raise ValueError(f"DualDrive.handover must be in [0, 100] s, got {handover!r}")
        self.handover = float(handover)
        if not (0.0 <= settle <= 60.0):
            raise ValueError(f"DualDrive.settle must be in [0, 60] s, got {settle!r}")
        self.settle = float(settle)

    @property
    def ts(self) -> float:
        """The control period, s."""
        return self.ctrl.foc.ts

    @property
    def latency(self) -> Latency:
        """The dual loop's timing, always the default one (:class:`~jaxobs.drive.Latency`): the sample at t_k,
        the voltage computed from it applied one period later."""
        return Latency()

    def settled_for(self, omega_e_min: float) -> DualDrive:
        """This drive with its settling phase at least :data:`~jaxobs.drive.loop.SETTLE_PERIODS` electrical
        periods at ``omega_e_min`` rad/s (:meth:`jaxobs.drive.Drive.settled_for`).

        Args:
            omega_e_min: The lowest electrical speed it will start at, rad/s (> 0).

        Returns:
            The :class:`DualDrive`.
        """
        return settled_for(self, omega_e_min)

    @property
    def mode(self) -> str:
        """The current control's mode, ``"vsd"`` or ``"individual"``."""
        return self.ctrl.mode


class DualOutput(NamedTuple):
    """One control period's signals at t_k."""

    t: jax.Array  # s
    theta_e: jax.Array  # true electrical angle, rad, wrapped
    theta_e_hat: jax.Array  # the angle the controller used, rad, wrapped
    omega_m: jax.Array  # rad/s
    omega_m_hat: jax.Array
    omega_m_ref: jax.Array
    i_d: jax.Array  # αβ subspace, rotor frame, A
    i_q: jax.Array
    i_x: jax.Array  # xy subspace, A
    i_y: jax.Array
    i_a1: jax.Array  # each set's Clarke currents (set 1's frame), A
    i_b1: jax.Array
    i_a2: jax.Array
    i_b2: jax.Array
    torque: jax.Array  # N·m
    load: jax.Array  # N·m
    id_ref: jax.Array  # A (per set / αβ; field weakening's Δi_d included)
    iq_ref: jax.Array
    obs: Any  # the observer's outputs (None with the encoder)
    u_a1: jax.Array  # each set's voltage applied over [t_k, t_{k+1}] (set 1's frame, limited), V
    u_b1: jax.Array
    u_a2: jax.Array
    u_b2: jax.Array
    mode: jax.Array  # 0: I-f start-up, 1: closed loop

    @property
    def speed_rpm(self) -> jax.Array:
        """The mechanical speed, r/min."""
        return self.omega_m * 60 / (2 * jnp.pi)


class DualLoopState(NamedTuple):
    """The dual closed loop's state between two periods: plant, controller, observer, sensors' key, voltage."""

    plant: DualPlantState
    ctrl: DualFOCState
    obs: Any
    sensors: jax.Array
    u: tuple[jax.Array, jax.Array, jax.Array, jax.Array]  # (u_a1, u_b1, u_a2, u_b2) to apply over the coming period, V


class DualClosedLoop(AbstractDriveLoop):
    """The dual drive ``drive`` on the dual machine ``machine`` running ``scenario`` with ``observer``
    (None: the encoder).  ``scenario.par`` is not used (the true machine is ``machine``)."""

    drive: DualDrive
    observer: Any
    scenario: Scenario
    machine: DualPMSMParams

    unroll: ClassVar[int] = 1

    def __init__(self, drive: DualDrive, observer, scenario: Scenario, machine: DualPMSMParams):
        if not isinstance(drive, DualDrive):
            raise ValueError(f"DualClosedLoop.drive must be a DualDrive, got {type(drive).__name__}")
        if not isinstance(scenario, Scenario):
            raise ValueError(f"DualClosedLoop.scenario must be a Scenario, got {type(scenario).__name__}")
        if not isinstance(machine, DualPMSMParams):
            raise ValueError(f"DualClosedLoop.machine must be a DualPMSMParams, got {type(machine).__name__}")
        if drive.sensorless and observer is None:
            raise ValueError("DualClosedLoop: a sensorless drive needs an observer (observer=None is the encoder)")
        if scenario.est_par.p != machine.p:
            raise ValueError(f"DualClosedLoop.scenario.est_par.p must equal the machine's p ({machine.p})")
        self.drive, self.observer, self.scenario, self.machine = drive, observer, scenario, machine

    @property
    def ts(self) -> float:
        """The control period, s."""
        return self.drive.ts

    @property
    def pole_pairs(self) -> int:
        """The machine's pole pairs."""
        return self.machine.p

    @property
    def plant(self) -> DualPMSM:
        """The true dual machine behind the drive's inverter, with the scenario's dead time."""
        d = self.drive
        return DualPMSM(self.machine, d.inverter, self.scenario.dead_time, ts=d.ts, n_sub=d.n_sub, rule=d.rule)

    @property
    def controller(self) -> DualFOC:
        """The DualFOC with its FOC bound to the machine it was tuned on, the inverters' voltage limit and the
        drive's I-f start-up."""
        c = self.drive.ctrl
        foc = c.foc.bind(c.foc.est, self.drive.inverter.u_max, self.drive.startup)
        return eqx.tree_at(lambda q: q.foc, c, foc)

    def operating_point(self, offset: jax.Array | float = 0.0) -> OperatingPoint:
        """The steady state at the scenario's initial speed and load: each set carries half the load
        (the FOC's operating point on the per-set machine, its frame ``offset`` rad ahead of the rotor's),
        zero xy current.  Above base speed with field weakening it is the field-weakened one (the αβ voltage at
        the margin, :meth:`FOC.operating_point`): exact for ``fw_voltage="ab"`` until the xy currents build up
        from zero (the 5th/7th BEMF drive them; where a set then reaches its inverter's limit the αβ voltage it
        delivers falls short, and i_d settles deeper: −7.29 A against the start's −6.43 A at 840 r/min, no load,
        330 V); ``fw_voltage="set"`` settles deeper still (the xy voltage under the margin too).

        Args:
            offset: The controller's angle minus the rotor's, rad.

        Returns:
            The :class:`OperatingPoint` (per set).
        """
        sc = self.scenario
        return self.controller.foc.operating_point(
            self.machine.per_set(), sc.omega_m0, sc.speed_ref(0.0), sc.theta_e0, sc.load(0.0) / 2, offset
        )

    def _steady_voltage(self, op: OperatingPoint, theta):
        """Each set's (u_α, u_β) at steady state (zero xy: the αβ voltage) over the period that starts where the
        rotor is at ``theta``, computed a period before with the delay compensation: centred half a period on."""
        w_e = self.machine.p * op.omega_m
        lead = (0.5 if self.drive.ctrl.foc.delay_compensation else -1.0) * w_e * self.ts
        return dq_to_ab(op.u_d, op.u_q, theta + lead)

    def init(self) -> DualLoopState:
        """The steady start (:meth:`AbstractDriveLoop._steady_start`): the machine at the scenario's speed and
        load, the observer settled on it for ``drive.settle`` s (from ``init_at(ω_e)`` when 0) on one set's
        steady measurements, which are the αβ ones (xy = 0; under "vsd" the sensor noise of the mean of two
        sets is √2 lower than what it settles on), and, sensorless without a hand-over, where it settles."""
        sc, foc = self.scenario, self.controller
        if self.drive.startup is not None:
            # from standstill, as ClosedLoop.init: all zeros, the I-f angle at θ_e0 − 90° (the parked rotor)
            _, plant, obs, ctrl, sensors = self._rest_start()
            z = jnp.zeros((), plant.x.dtype)
            return DualLoopState(plant=plant, ctrl=ctrl, obs=obs, sensors=sensors, u=(z, z, z, z))
        op, obs = self._steady_start(self.operating_point())
        plant = self.plant.init(op)
        u_a, u_b = self.drive.inverter.limit(*self._steady_voltage(op, op.theta_e))
        key = sc.sensors.init(op, key=sc.key)
        return DualLoopState(plant=plant, ctrl=foc.init(op), obs=obs, sensors=key, u=(u_a, u_b, u_a, u_b))

    def step(self, state: DualLoopState, k: jax.Array) -> tuple[DualLoopState, DualOutput]:
        """One control period of the dual closed loop.

        Args:
            state: The :class:`DualLoopState`.
            k: The sample index.

        Returns:
            ``(the next state, the DualOutput)``.
        """
        drive, sc, inv = self.drive, self.scenario, self.drive.inverter
        t = k * self.ts
        w_ref, load = sc.speed_ref(t), sc.load(t)
        plant_state, y = self.plant.step(state.plant, DualPlantInput(*state.u, load))
        u = state.u
        key = state.sensors
        m1 = sc.sensors.measure(key, k, u[0], u[1], y.i_a1, y.i_b1)
        m2 = sc.sensors.measure(jax.random.fold_in(key, 1), k, u[2], u[3], y.i_a2, y.i_b2)
        if drive.mode == "individual":
            obs_in = DriveInput(*m1)
        else:
            ua, ub, _, _ = sets_to_vsd(m1[0], m1[1], m2[0], m2[1])
            ia, ib, _, _ = sets_to_vsd(m1[2], m1[3], m2[2], m2[3])
            obs_in = DriveInput(ua, ub, ia, ib)
        obs_state, obs_out = self._observe(state.obs, obs_in, t)
        th_c, w_e_c, w_m_c = self._feedback(t, obs_out, y.theta_e, self.machine.p * y.omega_m, y.omega_m)
        ctrl, c = self.controller.step(
            state.ctrl, DualFOCInput(k, m1[2], m1[3], m2[2], m2[3], th_c, w_e_c, w_m_c, w_ref)
        )
        obs_state = self._seed_observer(obs_state, ctrl.main)
        u_next = (*inv.limit(c.u_a1, c.u_b1), *inv.limit(c.u_a2, c.u_b2))
        out = DualOutput(
            t=t,
            theta_e=wrap(y.theta_e),
            theta_e_hat=wrap(c.theta),
            omega_m=y.omega_m,
            omega_m_hat=w_m_c,
            omega_m_ref=w_ref,
            i_d=y.i_d,
            i_q=y.i_q,
            i_x=y.i_x,
            i_y=y.i_y,
            i_a1=y.i_a1,
            i_b1=y.i_b1,
            i_a2=y.i_a2,
            i_b2=y.i_b2,
            torque=y.torque,
            load=load,
            id_ref=c.id_ref,
            iq_ref=c.iq_ref,
            obs=obs_out,
            u_a1=u[0],
            u_b1=u[1],
            u_a2=u[2],
            u_b2=u[3],
            mode=ctrl.main.mode,
        )
        return DualLoopState(plant=plant_state, ctrl=ctrl, obs=obs_state, sensors=key, u=u_next), out


def dual_bench_drive(
    machine: DualPMSMParams,
    *,
    mode: Literal["vsd", "individual"] = "vsd",
    fw_voltage: Literal["ab", "set"] = "ab",
    sensorless: bool = True,
    handover: float = 0.2,
    startup: IfStartup | None = None,
    settle: float = 0.2,
    alpha_s: float | None = None,
    alpha_c: float | None = None,
    n_sub: int = 2,
    inverter: Inverter | None = None,
    **foc_kw: Any,
) -> DualDrive:
    """The single IPMSM bench's drive (:func:`jaxobs.drive.bench_drive`) on the dual machine ``machine`` (what
    the controller assumes): the speed loop at ``alpha_s`` (default 2π·papers.BENCH_SPEED_HZ rad/s), IMC
    current loops at ``alpha_c`` (default 2π·papers.BENCH_CURRENT_HZ rad/s) in either mode, ``inverter``
    (default 540 V) for both sets, ``settle`` the observer's settling phase before t = 0 (s, :class:`DualDrive`),
    ``startup`` an I-f start-up from standstill (:class:`~jaxobs.drive.IfStartup`, per set) or None, ``fw_voltage``
    the voltage the field weakening budgets (:class:`DualFOC`), ``foc_kw`` :class:`FOC`'s options
    (``field_weakening``, ...).

    Args:
        machine: The dual machine the controller assumes.
        mode: ``"vsd"`` or ``"individual"``.
        fw_voltage: ``"ab"`` or ``"set"``.
        sensorless: Whether the observer closes the loop.
        handover: The time from which the observer closes the loop, s.
        startup: An I-f start-up, or None.
        settle: The observer's settling phase before t = 0, s.
        alpha_s: The speed loop's bandwidth, rad/s (None: the default).
        alpha_c: The current loops' bandwidth, rad/s (None: the default).
        n_sub: Plant substeps per period.
        inverter: Both sets' inverter (None: 540 V).
        **foc_kw: :class:`FOC`'s options.

    Returns:
        The :class:`DualDrive`.
    """
    alpha_c = 2 * math.pi * papers.BENCH_CURRENT_HZ if alpha_c is None else alpha_c
    alpha_s = 2 * math.pi * papers.BENCH_SPEED_HZ if alpha_s is None else alpha_s
    ctrl = DualFOC.imc(machine, alpha_c, alpha_s, mode=mode, fw_voltage=fw_voltage, **foc_kw)
    return DualDrive(
        ctrl, inverter, startup=startup, sensorless=sensorless, handover=handover, settle=settle, n_sub=n_sub
    )
