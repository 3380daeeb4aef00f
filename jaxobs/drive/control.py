"""Field-oriented control: dq current PI with decoupling, speed PI, I-f start-up.

Current loop (every control period T_s, 10 kHz in 000): PI in the rotor frame with the cross-coupling and PM
terms fed forward from the *assumed* machine (``est_par``):

    u_d* = k_pd e_d + ∫k_id e_d − ω̂e L̂q i_q
    u_q* = k_pq e_q + ∫k_iq e_q + ω̂e (L̂d i_d + ψ̂f)

IMC tuning (the default, :meth:`FOC.imc`): k_p = α_c L̂, k_i = α_c R̂s, which cancels the R–L pole and leaves
i/i* = α_c/(s + α_c) (plus the 1.5-sample delay of computation and PWM, small when α_c T_s ≪ 1).

Speed loop (every ``speed_every`` periods, 1 kHz in 000): two-degree-of-freedom PI from speed to i_q*,
i_q* = k_pω (b ω* − ω) + k_iω ∫(ω* − ω), with the mechanics J s ω = K_t i_q (K_t = 1.5 p ψ̂f).  Pole placement puts
both closed-loop poles at −α_s: k_pω = 2α_s Ĵ/K_t, k_iω = α_s² Ĵ/K_t.  The default setpoint weight b = 0 (I-P, as
motulator's 2DOF PI) gives ω/ω* = α_s²/(s + α_s)² without the PI zero's overshoot; b = 1 is the plain PI.  Load
rejection is the same for both.  Conditional integration keeps the integrators from winding up when the current
limit (speed loop) or the voltage limit (current loop) is reached.

i_d* = 0 by default; ``id_mode="mtpa"`` gives the IPMSM's maximum torque per ampere, i_d = ψf/(2(Lq − Ld)) −
√(ψf²/(4(Lq − Ld)²) + i_q²) (i_d = 0 for Ld = Lq).  ``field_weakening=VoltageFeedbackFW()`` adds a negative i_d
above base speed (:mod:`jaxobs.drive.weakening`); off by default.

Torque to current under MTPA (the speed loop's gain kept at every load): :mod:`jaxobs.drive._policy`.

Current limit: the circle |i*| ≤ i_ref at every sample (standstill, I-f and its blend included), i_ref =
(1 − ``current_margin``) i_max.  i_d has priority: i_d* is kept within ±i_ref and i_q* takes what the circle
leaves, |i_q*| ≤ √(i_ref² − i_d*²).  Under MTPA the speed loop's output is limited to the torque of the MTPA point
on the circle (:meth:`FOC.iq_limit`), so the MTPA current it asks for is on the circle at most.  With field
weakening the weakened reference keeps the speed loop's torque while it can and is cut by the circle, MTPV and
the voltage (:mod:`jaxobs.drive.weakening`).  The current itself within i_max at every sample (the margin below
it and the current PIs' ``error_limit``, a drive file's): :mod:`jaxobs.drive._reflimit`.

The voltage limit: the vector u* beyond u_max is scaled back onto the circle, its direction kept (the default).
``d_priority=True`` (a drive file with field weakening) keeps u_d* (clipped to ±u_max) and gives u_q* what is
left: in field weakening u_d ≈ −ω ψq holds the negative i_d; the scaled vector let it drift up (the PM-SyRM of
``docs/examples/pmsyrm_5p6kw_sat.toml`` at 2136 r/min: i_d* −17.5 A, i_d at −11 A whenever the voltage
saturated).  ``flux_map=True`` (a drive file with a saturation map) runs the current loop on the map
(``est.sat``): k_pd, k_pq = α_c L_dd, α_c L_qq, its incremental inductances at i* (the integral gains α_c R̂s
unchanged), and the decoupling −ω̂e ψq, ω̂e ψd of its flux at the measured current (as motulator's flux-map
controllers): the secant L̂q at the rated MTPA point is 6× the saturated incremental inductance near i_max on
that PM-SyRM (0.102 against 0.017 H); the q loop rang from standstill (1.10 × i_max, ``tests/test_current_limit.py``).

Speed-loop anti-windup: conditional integration on the torque *realised*: the integrator stops while the speed
loop's output is not realised (beyond the circle's torque, or cut by field weakening's limits: the reference's
torque on the assumed machine, in K̂_t units) and the speed error pushes further.  Stopping only at the circle's
torque let the integrator wind up while field weakening cut i_q*: a 1000 → 2000 r/min step at 14 N·m on the lab
IPMSM of ``docs/examples/ipmsm_2p2kw_lab.toml`` overshot by 47.6 r/min; it now does not overshoot
(``tests/test_weakening.py`` holds it within 5 r/min).

Delay compensation: the voltage computed from the samples at τ_k acts ``advance`` periods later on average (1.5
with sampling at the period start and one period of computation: :mod:`jaxobs.drive.latency`), so the controller
rotates its output ahead by ``advance`` × ω̂e T_s; ``advance = 0`` is no compensation (``delay_compensation=False``
is ``advance=0``).

I-f start-up from standstill (:class:`IfStartup`, the design and its reasons): :mod:`jaxobs.drive.startup`.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer

from ..core.numerics import safe_norm2, safe_sqrt, wrap
from ..core.trig import sincos
from ..core.validate import check_nonnegative, check_positive, check_sample_time
from . import _policy
from ._foctypes import ControllerState as ControllerState
from ._foctypes import FOCInput as FOCInput
from ._foctypes import FOCOutput as FOCOutput
from ._foctypes import IfPhase
from ._operating import OperatingPoint as OperatingPoint
from ._operating import steady_point
from ._policy import policy_id, policy_iq_limit, policy_iq_lin, policy_mtpa_iq, policy_torque, rotate_by, torque_dq
from ._reflimit import limit_error
from .component import AbstractComponent
from .machine import PMSMParams
from .startup import IfStartup as IfStartup
from .weakening import VoltageFeedbackFW

__all__ = ["FOC", "FOCInput", "FOCOutput", "IfStartup", "ControllerState", "OperatingPoint", "DEFAULT_U_MAX"]

DEFAULT_U_MAX = 540.0 / math.sqrt(3.0)  # V: the default Inverter's U_dc/√3 (jaxobs.drive.hardware), FOC.imc's default


class FOC(AbstractComponent):
    """FOC gains and settings (gains are leaves: differentiable and tunable).

    Besides its gains the controller needs the machine it assumes (``est``: its
    decoupling terms and MTPA use it), the voltage limit of its inverter
    (``u_max``, for anti-windup and field weakening) and, optionally, an I-f ``startup``:
    it is built whole, with both (:meth:`imc` takes ``u_max``, default the default
    :class:`~jaxobs.drive.Inverter`'s U_dc/√3).  :class:`~jaxobs.drive.ClosedLoop` runs
    :meth:`bind`'s copy of it, whole too, with the scenario's assumed machine, the
    drive's inverter limit and start-up.

    Args:
        kp_d: d current loop's proportional gain, V/A (> 0).
        ki_d: d current loop's integral gain, V/(A·s) (≥ 0).
        kp_q: q current loop's proportional gain, V/A (> 0).
        ki_q: q current loop's integral gain, V/(A·s) (≥ 0).
        kp_w: Speed loop's proportional gain, A/(rad/s), mechanical speed (> 0).
        ki_w: Speed loop's integral gain, A/rad (≥ 0).
        i_max: The current-vector limit, A (> 0): the references' circle at (1 − ``current_margin``) × it.
        ts: The current-loop period, s.
        speed_every: The speed loop runs every this many periods (an integer ≥ 1).
        id_mode: The i_d* policy: ``"zero"`` or ``"mtpa"``.
        delay_compensation: Whether to rotate the output ahead (the default ``advance`` 1.5 periods, else 0).
        advance: The output is rotated ahead by advance·ω̂e·T_s (delay compensation), periods in [0, 3].
        field_weakening: A :class:`VoltageFeedbackFW`, or None: i_d* is the policy's (zero or MTPA).
        outer: ``"speed"``, or ``"current"``: the reference is i_q*, A.
        setpoint_weight: b in k_pω (b ω* − ω), in [0, 1]: 0 = I-P (no overshoot), 1 = PI.
        speed_schedule: N > 0: the speed-loop bandwidth is min(α_s, |ωe*|/N) (:meth:`speed_gains`); 0: fixed.
        d_priority: The voltage limit keeps u_d* and gives u_q* what is left (module doc), else it scales the vector.
        flux_map: Where ``est`` has a saturation map, the current loop runs on it: k_pd and k_pq scale with its
            incremental inductances at i*, the decoupling is its flux at i (module doc); else the constants.
        current_margin: h in [0, 0.5]: the references' circle i_ref = (1 − h) i_max (:mod:`jaxobs.drive._reflimit`).
        error_limit: E in [0, 0.5]: the current PIs see |i* − i| ≤ E i_max (:mod:`jaxobs.drive._reflimit`); 0: off.
        est: The machine the controller assumes (:class:`PMSMParams`; keyword, required).
        u_max: The voltage limit for anti-windup and field weakening, V (> 0; keyword, required).
        startup: An :class:`IfStartup` (None: closed loop from t = 0).

    Raises:
        ValueError: A value out of its range, naming the field.
    """

    kp_d: jax.Array  # V/A
    ki_d: jax.Array  # V/(A·s)
    kp_q: jax.Array
    ki_q: jax.Array
    kp_w: jax.Array  # A/(rad/s), mechanical speed
    ki_w: jax.Array  # A/rad
    i_max: jax.Array  # current-vector limit, A
    ts: float = eqx.field(static=True)  # current-loop period, s
    speed_every: int = eqx.field(static=True)  # speed loop runs every this many periods
    id_mode: Literal["zero", "mtpa"] = eqx.field(static=True)
    delay_compensation: bool = eqx.field(static=True)  # advance != 0
    advance: float = eqx.field(static=True)  # output rotated ahead by advance·ω̂e·T_s (delay compensation), periods
    outer: Literal["speed", "current"] = eqx.field(static=True)  # "current": the reference is i_q*, A
    setpoint_weight: float = eqx.field(static=True)  # b in k_pω (b ω* − ω): 0 = I-P (no overshoot), 1 = PI
    speed_schedule: float = eqx.field(static=True)  # N > 0: speed-loop bandwidth min(α_s, |ωe*|/N); 0: fixed
    d_priority: bool = eqx.field(static=True)  # the voltage limit keeps u_d* first (else scales the vector)
    flux_map: bool = eqx.field(static=True)  # the current loop on est.sat: k_p at L_inc(i*), decoupling ψ(i)
    current_margin: float = eqx.field(static=True)  # h: the references' circle at (1 − h) i_max
    error_limit: float = eqx.field(static=True)  # E: the current PIs see |i* − i| ≤ E i_max (0: off)
    field_weakening: VoltageFeedbackFW | None  # None: i_d* is the policy's (zero or MTPA)
    est: PMSMParams  # the machine the controller assumes
    u_max: jax.Array  # voltage limit for anti-windup and field weakening, V
    startup: IfStartup | None  # I-f start-up (None: closed loop from t = 0)

    def __init__(
        self,
        kp_d,
        ki_d,
        kp_q,
        ki_q,
        kp_w,
        ki_w,
        i_max,
        *,
        ts=1e-4,
        speed_every=10,
        id_mode="zero",
        delay_compensation=True,
        advance=None,
        field_weakening=None,
        outer="speed",
        setpoint_weight=0.0,
        speed_schedule=0.0,
        d_priority=False,
        flux_map=False,
        current_margin=0.0,
        error_limit=0.0,
        est,
        u_max,
        startup=None,
    ):
        own = "FOC"
        if not isinstance(est, PMSMParams):
            raise ValueError(f"{own}.est must be a PMSMParams (the machine the controller assumes), got "
                             f"{type(est).__name__}")  # fmt: skip
        if startup is not None and not isinstance(startup, IfStartup):
            raise ValueError(f"{own}.startup must be an IfStartup or None, got {type(startup).__name__}")
        self.est = est
        if u_max is None:
            raise ValueError(f"{own}.u_max must be the inverter's voltage limit, V (> 0), got None")
        self.u_max = check_positive("u_max", u_max, own)
        self.startup = startup
        self.kp_d = check_positive("kp_d", kp_d, own)
        self.ki_d = check_nonnegative("ki_d", ki_d, own)
        self.kp_q = check_positive("kp_q", kp_q, own)
        self.ki_q = check_nonnegative("ki_q", ki_q, own)
        self.kp_w = check_positive("kp_w", kp_w, own)
        self.ki_w = check_nonnegative("ki_w", ki_w, own)
        self.i_max = check_positive("i_max", i_max, own)
        self.ts = check_sample_time("ts", ts, own)
        if not (isinstance(speed_every, int) and speed_every >= 1):
            raise ValueError(f"{own}.speed_every must be an integer >= 1, got {speed_every!r}")
        self.speed_every = speed_every
        if id_mode not in ("zero", "mtpa"):
            raise ValueError(f"{own}.id_mode must be 'zero' or 'mtpa', got {id_mode!r}")
        self.id_mode = id_mode
        if advance is None:
            advance = 1.5 if delay_compensation else 0.0
        if isinstance(advance, bool) or not (0.0 <= float(advance) <= 3.0):
            raise ValueError(f"{own}.advance must be a number of periods in [0, 3], got {advance!r}")
        self.advance = float(advance)
        self.delay_compensation = self.advance != 0.0
        if field_weakening is not None and not isinstance(field_weakening, VoltageFeedbackFW):
            raise ValueError(
                f"{own}.field_weakening must be a VoltageFeedbackFW or None, got {type(field_weakening).__name__}"
            )
        self.field_weakening = field_weakening
        if outer not in ("speed", "current"):
            raise ValueError(f"{own}.outer must be 'speed' or 'current', got {outer!r}")
        self.outer = outer
        if not (0.0 <= float(setpoint_weight) <= 1.0):
            raise ValueError(f"{own}.setpoint_weight must be in [0, 1], got {setpoint_weight!r}")
        self.setpoint_weight = float(setpoint_weight)
        if not (0.0 <= float(speed_schedule) <= 1e3):
            raise ValueError(f"{own}.speed_schedule must be 0 (off) or a ratio in (0, 1000], got {speed_schedule!r}")
        self.speed_schedule = float(speed_schedule)
        if not isinstance(d_priority, bool):
            raise ValueError(f"{own}.d_priority must be True or False, got {d_priority!r}")
        self.d_priority = d_priority
        if not isinstance(flux_map, bool):
            raise ValueError(f"{own}.flux_map must be True or False, got {flux_map!r}")
        self.flux_map = flux_map
        for key, val in (("current_margin", current_margin), ("error_limit", error_limit)):
            if isinstance(val, bool) or not (0.0 <= float(val) <= 0.5):
                raise ValueError(f"{own}.{key} must be a per-unit number in [0, 0.5], got {val!r}")
        self.current_margin, self.error_limit = float(current_margin), float(error_limit)

    @classmethod
    def imc(
        cls,
        est_par: PMSMParams,
        alpha_c: jax.Array | float,
        alpha_s: jax.Array | float,
        i_max: jax.Array | float | None = None,
        u_max: jax.Array | float | None = None,
        **kw: Any,
    ) -> FOC:
        """IMC current gains (k_p = α_c L̂, k_i = α_c R̂s) and double-pole speed gains at −α_s.

        Args:
            est_par: The machine the controller assumes.
            alpha_c: The current loops' bandwidth α_c, rad/s.
            alpha_s: The speed loop's double pole α_s, rad/s.
            i_max: The current-vector limit, A (default 1.5× the rated current).
            u_max: The voltage limit, V (default the default :class:`~jaxobs.drive.Inverter`'s, 540 V/√3).
            **kw: Other :class:`FOC` keywords.

        Returns:
            The :class:`FOC`.
        """
        alpha_c = check_positive("alpha_c", alpha_c, "FOC.imc")
        alpha_s = check_positive("alpha_s", alpha_s, "FOC.imc")
        vals: tuple[Any, ...] = (alpha_c, alpha_s, est_par.Ld, est_par.Lq, est_par.Rs, est_par.J, est_par.psi_f,
                                 est_par.T_rated)  # fmt: skip
        if not any(isinstance(v, Tracer) for v in vals):
            # concrete values: the same IEEE operations in NumPy, in the same dtype and order, give the same bits
            # without compiling one XLA kernel per operation (a drive file's check builds a FOC and runs nothing)
            vals = tuple(np.asarray(v) for v in vals)
        a_c, a_s, Ld, Lq, Rs, J, psi_f, T_rated = vals
        kt = 1.5 * est_par.p * psi_f  # PMSMParams.kt
        return cls(
            kp_d=a_c * Ld,
            ki_d=a_c * Rs,
            kp_q=a_c * Lq,
            ki_q=a_c * Rs,
            kp_w=2 * a_s * J / kt,
            ki_w=a_s**2 * J / kt,
            i_max=1.5 * (T_rated / kt) if i_max is None else i_max,  # 1.5 × PMSMParams.i_rated by default
            est=kw.pop("est", est_par),
            u_max=DEFAULT_U_MAX if u_max is None else u_max,
            **kw,
        )

    @property
    def i_ref(self) -> jax.Array:
        """The references' circle, A: (1 − ``current_margin``) × i_max (i_max itself without a margin)."""
        return self.i_max if self.current_margin == 0.0 else self.i_max * (1.0 - self.current_margin)

    def speed_gains(self, omega_m_ref: jax.Array | float) -> tuple[jax.Array, jax.Array]:
        """(k_pω, k_iω) of the speed loop at the mechanical speed reference ω_m* (rad/s).

        ``speed_schedule = N > 0`` keeps the speed loop inside the bandwidth of a speed estimate that scales
        with the speed (a flux observer's FLL: docs/stability.md): its double pole moves from the designed
        α_s = 2 k_iω/k_pω to min(α_s, |p ω_m*|/N), so k_pω scales by r = min(1, |p ω_m*|/(N α_s)) and k_iω
        by r².  Scheduled on the reference, an outside signal: scheduled on ω̂ the I-P's proportional term
        k_pω(ω̂) ω̂ would double its own small-signal gain.  At ω_m* = 0 the speed loop holds its output.

        Args:
            omega_m_ref: The mechanical speed reference ω_m*, rad/s.

        Returns:
            ``(k_pω, k_iω)``.
        """
        if self.speed_schedule <= 0:
            return self.kp_w, self.ki_w
        alpha = 2 * self.ki_w / self.kp_w
        w_e = jnp.abs(self.est.p * omega_m_ref)
        r = jnp.where(alpha > 0, jnp.minimum(w_e / (self.speed_schedule * jnp.where(alpha > 0, alpha, 1.0)), 1.0), 1.0)
        return self.kp_w * r, self.ki_w * r * r

    def bind(self, est: PMSMParams, u_max: jax.Array | float, startup: IfStartup | None = None) -> FOC:
        """A copy of this controller with another assumed machine, voltage limit and start-up (a scenario's, a
        drive's), as whole as this one (no value checks: traced-safe; None is refused).

        Args:
            est: The machine the controller assumes.
            u_max: The voltage limit, V.
            startup: The I-f start-up, or None.

        Returns:
            The :class:`FOC`.

        Raises:
            ValueError: ``est`` or ``u_max`` None.
        """
        if est is None or u_max is None:
            raise ValueError("FOC.bind: est and u_max must be given (a FOC is whole), got None")
        return eqx.tree_at(
            lambda f: (f.est, f.u_max, f.startup), self, (est, u_max, startup), is_leaf=lambda x: x is None
        )

    def init(self, op: OperatingPoint | None = None, *, theta_f0: jax.Array | float = 0.0) -> ControllerState:
        """Zero integrators (``op=None``), or the integrators that hold the drive at ``op`` (a steady start).

        At a steady operating point the errors are zero, so the current PIs'
        outputs are their integrators plus the decoupling terms (computed with
        the *assumed* machine), which must equal the voltage the true machine
        needs; the speed PI's output, k_pω (b ω* − ω) + ∫, must equal i_q.  The field
        weakening's integrator starts at the operating point's Δi_d (``op.id_fw``).
        With an I-f start-up the drive starts from standstill: zeros, and the
        I-f angle at ``theta_f0`` (ClosedLoop: θ_e0 − 90°, the parked rotor).

        Args:
            op: The :class:`OperatingPoint`, or None.
            theta_f0: The I-f angle to start from when the FOC has a start-up, rad.

        Returns:
            The :class:`ControllerState`.
        """
        z = jnp.zeros_like(self.kp_d)
        mode = jnp.asarray(1 if self.startup is None else 0, dtype=jnp.int32)
        rest = dict(
            theta_f=z + theta_f0, omega_f=z, t_at_switch=z, mode=mode, d_lp=z, t_agree=z, t_closed=z, id_hand=z, id_fw=z
        )
        rest["kp_w"] = z + self.speed_gains(jnp.zeros_like(z) if op is None else op.omega_m_ref)[0]
        if op is None or self.startup is not None:
            return ControllerState(int_d=z, int_q=z, int_w=z, iq_ref=z, **rest)
        est = self.est
        w_e = est.p * op.omega_m
        # the controller's frame is op.offset ahead of the rotor's: its currents and the voltage it must
        # produce are the rotor frame's rotated back by the offset (zero offset: the rotor frame itself)
        i_d, i_q = rotate_by(op.i_d, op.i_q, -op.offset)
        u_d, u_q = rotate_by(op.u_d, op.u_q, -op.offset)
        emf_d, emf_q = _policy.rotation_emf(est, w_e, i_d, i_q, self.flux_map)  # the current loop's decoupling
        int_d = u_d + emf_d
        int_q = u_q - emf_q
        lin, held = self.iq_lin(est, i_q), i_q
        if self.field_weakening is not None:
            # weakened: the speed loop asks for the torque of the references on the assumed machine, as its policy's
            # current i_q,cmd; Δi_d takes i_d* from the policy's i_d(i_q,cmd) (jaxobs.drive.weakening, points 1-2)
            weak = op.id_fw < 0
            lin_w = torque_dq(est, i_d, i_q) / est.kt
            cmd = self.mtpa_iq(est, lin_w)
            lin, held = jnp.where(weak, lin_w, lin), jnp.where(weak, cmd, held)
            rest["id_fw"] = z + jnp.where(weak, jnp.minimum(i_d - self._id_ref(est, cmd), 0.0), op.id_fw)
        if self.outer == "current":
            int_w = z
        else:
            gain = self.speed_gains(op.omega_m_ref)[0]
            int_w = lin - gain * (self.setpoint_weight * op.omega_m_ref - op.omega_m)
        return ControllerState(int_d=z + int_d, int_q=z + int_q, int_w=z + int_w, iq_ref=z + held, **rest)

    def operating_point(
        self,
        par: PMSMParams,
        omega_m: jax.Array | float,
        omega_m_ref: jax.Array | float,
        theta_e: jax.Array | float,
        t_load: jax.Array | float,
        offset: jax.Array | float = 0.0,
    ) -> OperatingPoint:
        """The steady state of the true machine ``par`` under this controller at speed ω_m and load T_L.

        The torque balanced against the load and friction with the controller's references met in its own frame,
        ``offset`` ahead of the rotor's, field-weakened where the voltage asks for it: the rules are
        ``jaxobs.drive._operating.steady_point``'s, which this calls with the controller's settings.

        Args:
            par: The true machine.
            omega_m: The mechanical speed ω_m, rad/s.
            omega_m_ref: The speed reference, rad/s (i_q* in A with ``outer="current"``).
            theta_e: The electrical angle, rad.
            t_load: The load torque T_L, N·m.
            offset: The controller's angle minus the rotor's, rad.

        Returns:
            The :class:`OperatingPoint`.
        """
        return steady_point(
            est=self.est,
            id_mode=self.id_mode,
            outer=self.outer,
            i_max=self.i_ref,
            u_max=self.u_max,
            field_weakening=self.field_weakening,
            par=par,
            omega_m=omega_m,
            omega_m_ref=omega_m_ref,
            theta_e=theta_e,
            t_load=t_load,
            offset=offset,
        )

    def _id_ref(self, est: PMSMParams, iq: jax.Array | float) -> jax.Array:
        return policy_id(self.id_mode, est, iq)

    def _policy_torque(self, est: PMSMParams, iq: jax.Array | float) -> jax.Array:
        """The mean torque (N·m) of i_q and the policy's i_d(i_q) on ``est``."""
        return policy_torque(self.id_mode, est, iq)

    def mtpa_iq(self, est: PMSMParams, iq_lin: jax.Array) -> jax.Array:
        """The i_q* (A) whose torque under the policy's i_d(i_q*) on ``est`` is K̂_t·``iq_lin`` (module doc): the
        speed loop's output turned into current.  ``iq_lin`` itself with i_d* = 0 or a non-salient ``est``.

        Newton's method from i_q = i_lin, 6 steps: the policy's torque is odd, increasing and convex in i_q
        for i_q > 0 under MTPA (the reluctance term grows as i_q², then i_q), so from i_lin, where it is at or
        above the target, the steps fall monotonically; on a machine with Lq = 4 Ld at 2× its rated torque the
        torque's error is 8e-6 after 3 steps, 2e-11 after 4 and rounding after 5.

        Args:
            est: The machine the controller assumes.
            iq_lin: The speed loop's output, A (K̂_t units).

        Returns:
            i_q*, A.
        """
        return policy_mtpa_iq(self.id_mode, est, iq_lin)

    def iq_lin(self, est: PMSMParams, iq: jax.Array) -> jax.Array:
        """The speed loop's output that asks for the current i_q under the policy: the inverse of :meth:`mtpa_iq`.

        Args:
            est: The machine the controller assumes.
            iq: The q current, A.

        Returns:
            The speed loop's output, A (K̂_t units).
        """
        return policy_iq_lin(self.id_mode, est, iq)

    def iq_limit(self, est: PMSMParams) -> tuple[jax.Array, jax.Array]:
        """The current limits of the speed loop under the policy.

        MTPA on the circle |i| = I: i_d = (ψf − √(ψf² + 8 ΔL² I²))/(4 ΔL), ΔL = Lq − Ld (the torque
        (ψf − ΔL i_d)·√(I² − i_d²) at its maximum over i_d), i_q = √(I² − i_d²).

        Args:
            est: The machine the controller assumes.

        Returns:
            ``(|i_q*| on the policy's curve at |i| = i_max, the speed loop's output limit in K̂_t units)``, A.
        """
        return policy_iq_limit(self.id_mode, est, self.i_ref)

    def step(self, cs: ControllerState, inp: FOCInput) -> tuple[ControllerState, FOCOutput]:
        """One current-loop period: the voltage to apply over the next period.

        The I-f start-up's phase (:meth:`_if_phase`), the speed loop (:meth:`_speed_loop`), the I-f references and
        hand-over (:meth:`_if_references`), the current circle, then the current loop (:meth:`_current_loop`): helper
        methods that the trace inlines, so the compiled period is the one function it always was.

        Args:
            cs: The :class:`ControllerState`.
            inp: The :class:`FOCInput`: ``inp.theta``/``omega_e``/``omega_m`` are the position and speeds the
                controller uses (encoder or observer); ``inp.omega_m_ref`` is the speed reference (rad/s), or
                i_q* (A) when ``outer="current"``.

        Returns:
            ``(the next ControllerState, the FOCOutput)``.
        """
        kp_w, ki_w = self.speed_gains(inp.omega_m_ref)
        ph = self._if_phase(cs, inp, kp_w)
        closed = ph.mode == 1
        th = jnp.where(closed, inp.theta, ph.theta_f)
        w_e = jnp.where(closed, inp.omega_e, ph.omega_f)
        run_speed = (inp.k % self.speed_every) == 0
        id_ref, iq_ref, int_w, held, fw_lo = self._speed_loop(cs, inp, ph, (kp_w, ki_w), closed, run_speed, w_e)
        int_d0, int_q0 = cs.int_d, cs.int_q
        if self.startup is not None:
            id_ref, iq_ref, held, int_w, int_d0, int_q0 = self._if_references(
                cs, inp, ph, closed, (id_ref, iq_ref, held, int_w)
            )
        # the current circle, whatever set the references (the blend after an I-f switch, an I-f current above
        # i_max): |i*| ≤ i_max at every sample, i_d first (an identity where the circle is not reached)
        id_ref = jnp.clip(id_ref, -self.i_ref, self.i_ref)
        iq_ref = VoltageFeedbackFW.limit_iq(iq_ref, id_ref, self.i_ref)
        u_a, u_b, int_d, int_q, id_fw = self._current_loop(cs, inp, th, w_e, (id_ref, iq_ref), (int_d0, int_q0), fw_lo)
        new = ControllerState(
            int_d=int_d,
            int_q=int_q,
            int_w=int_w,
            iq_ref=held,
            theta_f=ph.theta_f,
            omega_f=ph.omega_f,
            t_at_switch=ph.t_at_switch,
            mode=ph.mode,
            d_lp=ph.d_lp,
            t_agree=ph.t_agree,
            t_closed=ph.t_closed,
            id_hand=ph.id_hand,
            id_fw=id_fw,
            kp_w=jnp.where(run_speed, kp_w, cs.kp_w),
        )
        return new, FOCOutput(
            u_a=u_a, u_b=u_b, id_ref=id_ref, iq_ref=iq_ref, theta=jnp.where(ph.mode == 1, inp.theta, ph.theta_f)
        )

    def _if_phase(self, cs: ControllerState, inp: FOCInput, kp_w: jax.Array) -> IfPhase:
        """The I-f start-up's part of a period (module doc): the angle advances every period (used in mode 0), the
        agreement, the switch and the bumpless hand-over's values; without a start-up the state's, unchanged."""
        startup, ts = self.startup, self.ts
        if startup is None:
            return IfPhase(cs.omega_f, cs.theta_f, cs.mode, cs.int_w, cs.iq_ref, cs.t_at_switch, cs.d_lp, cs.t_agree,
                            cs.t_closed, cs.id_hand)  # fmt: skip
        k, theta, omega_e, omega_m, omega_m_ref = inp.k, inp.theta, inp.omega_e, inp.omega_m, inp.omega_m_ref
        omega_f = startup.ramp(k * ts)
        theta_f = wrap(cs.theta_f + 0.5 * (cs.omega_f + omega_f) * ts)  # trapezoidal: exact for the ramp
        at_top = omega_f >= startup.omega_switch
        t_at_switch = jnp.where(at_top, cs.t_at_switch + ts, 0.0)
        # agreement of the given position with the I-f frame: Δ = θ_f − θ̂ steady and ω̂ ≈ ω_f
        delta = wrap(theta_f - theta)
        d_lp = jnp.where(
            cs.t_at_switch > 0, wrap(cs.d_lp + jnp.minimum(ts / startup.dwell, 1.0) * wrap(delta - cs.d_lp)), delta
        )
        agree = (
            at_top
            & (jnp.abs(wrap(delta - d_lp)) <= startup.tol)
            & (jnp.abs(omega_e - omega_f) <= startup.speed_tol * omega_f)
        )
        t_agree = jnp.where(agree, cs.t_agree + ts, 0.0)
        switch = (cs.mode == 0) & (t_at_switch >= startup.hold) & (t_agree >= startup.dwell)
        mode = jnp.where(switch, 1, cs.mode)
        t_closed = jnp.where(cs.mode == 1, cs.t_closed + ts, 0.0)  # 0 at the switch
        # bumpless: the I-f vector (I_f along θ_f + 90°) seen from the given frame
        sd, cd = sincos(delta)  # also rotates the integrators (_if_references)
        iq_hand = startup.i_f * cd
        id_hand = jnp.where(switch, -startup.i_f * sd, cs.id_hand)
        # the speed PI's output k_pω(b ω* − ω̂) + ∫ starts at iq_hand
        lin_hand = self.iq_lin(self.est, iq_hand)
        int_w0 = jnp.where(switch, lin_hand - kp_w * (self.setpoint_weight * omega_m_ref - omega_m), cs.int_w)
        iq_held = jnp.where(switch, iq_hand, cs.iq_ref)
        return IfPhase(omega_f, theta_f, mode, int_w0, iq_held, t_at_switch, d_lp, t_agree, t_closed, id_hand,
                        switch, sd, cd)  # fmt: skip

    def _speed_loop(
        self,
        cs: ControllerState,
        inp: FOCInput,
        ph: IfPhase,
        gains: tuple[jax.Array, jax.Array],
        closed: jax.Array,
        run_speed: jax.Array,
        w_e: jax.Array,
    ) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array, tuple[jax.Array | None, jax.Array | None]]:
        """The speed loop at its own rate (its result held in between) and the current references it gives:
        ``(i_d*, i_q*, the speed integrator, the held i_q*, (field weakening's Δi_d floor, its path slope) or
        None each)``."""
        est, ts, fw = self.est, self.ts, self.field_weakening
        omega_m, omega_m_ref = inp.omega_m, inp.omega_m_ref
        kp_w, ki_w = gains
        int_w0 = ph.int_w0
        tw = ts * self.speed_every
        e_w = omega_m_ref - omega_m
        if self.speed_schedule > 0:
            # Bumpless schedule: the integrator takes up the change of k_pω (b ω* − ω̂).  Without it a +2 % reference
            # step cut the I-P's −k_pω ω̂ + ∫ by 2 % of k_pω ω̂, and at 20 r/min under load that kick lost the drive
            # (docs/stability.md).  Not at the I-f switch, where the integrator is set afresh.
            bump = (cs.kp_w - kp_w) * (self.setpoint_weight * omega_m_ref - omega_m)
            keep = run_speed & closed if ph.switch is None else run_speed & closed & ~ph.switch
            int_w0 = int_w0 + jnp.where(keep, bump, 0.0)
        unsat = kp_w * (self.setpoint_weight * omega_m_ref - omega_m) + int_w0
        iq_max, lin_max = self.iq_limit(est)  # the circle's i_q under the policy, and its torque in K̂_t units
        iq_sat = jnp.clip(unsat, -lin_max, lin_max)
        iq_cmd = jnp.where(run_speed, self.mtpa_iq(est, iq_sat), ph.iq_held)  # the speed loop's current, held
        if self.outer == "current":  # the reference is i_q* itself (current-loop tests, torque control)
            iq_cmd = jnp.clip(omega_m_ref, -iq_max, iq_max)
        id_ref = self._id_ref(est, iq_cmd)
        iq_ref, real, fw_lo, slope = iq_cmd, iq_sat, None, None
        if fw is not None:
            # the weakened reference within the stop, the circle, MTPV and the voltage (jaxobs.drive.weakening)
            id_pol = id_ref
            id_ref, iq_ref, capped, fw_lo = fw.references(est, id_pol, iq_cmd, cs.id_fw, w_e, self.u_max, self.i_ref)
            if fw.bounded:  # the gain on the reference path's slope (jaxobs.drive.weakening, "Bounded")
                slope = fw.path_slope(est, id_pol, iq_cmd, cs.id_fw, w_e, self.u_max, self.i_ref)
            real = jnp.where(capped, torque_dq(est, id_ref, iq_ref) / est.kt, iq_sat)
        # conditional integration on the torque realised (in K̂_t units): freeze while the speed loop's output is
        # not realised (the circle's torque, or field weakening's limits) and the error pushes further.  Without
        # field weakening real = iq_sat, the circle's limit alone.
        windup = (unsat != real) & (jnp.sign(e_w) == jnp.sign(unsat - real))
        int_w = jnp.where(run_speed & ~windup, int_w0 + ki_w * e_w * tw, int_w0)
        if self.outer == "current":
            int_w = cs.int_w
        return id_ref, iq_ref, int_w, iq_cmd, (fw_lo, slope)

    def _if_references(
        self,
        cs: ControllerState,
        inp: FOCInput,
        ph: IfPhase,
        closed: jax.Array,
        refs: tuple[jax.Array, jax.Array, jax.Array, jax.Array],
    ) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array, jax.Array, jax.Array]:
        """I-f: I_f on the I-f frame's q axis; after the switch the d-current blends from the I-f vector's, and at
        the switch the current PIs' integrators move into the given frame.  ``refs`` is ``(i_d*, i_q*, the held
        i_q*, the speed integrator)``; returns them with the current integrators ``(int_d, int_q)``."""
        startup, est, ts = self.startup, self.est, self.ts
        assert startup is not None and ph.switch is not None and ph.sd is not None and ph.cd is not None
        id_ref, iq_ref, held, int_w = refs
        i_a, i_b, theta, omega_e = inp.i_a, inp.i_b, inp.theta, inp.omega_e
        switch, sd, cd, theta_f, omega_f = ph.switch, ph.sd, ph.cd, ph.theta_f, ph.omega_f
        r = jnp.where(startup.blend > 0, jnp.clip(1.0 - ph.t_closed / jnp.maximum(startup.blend, ts), 0.0, 1.0), 0.0)
        id_ref = jnp.where(closed, r * ph.id_hand + (1 - r) * id_ref, 0.0)
        iq_ref = jnp.where(closed, iq_ref, startup.i_f)
        held = jnp.where(closed, held, startup.i_f)
        int_w = jnp.where(closed, int_w, cs.int_w)
        # the current PIs' integrators into the new frame, so that the voltage vector is continuous:
        # u = ∫ + decoupling, rotated by Δ from θ_f to θ̂, minus the decoupling computed in θ̂
        sf, cf = sincos(theta_f)
        idf, iqf = cf * i_a + sf * i_b, -sf * i_a + cf * i_b
        sh, ch = sincos(theta)
        idh, iqh = ch * i_a + sh * i_b, -sh * i_a + ch * i_b
        vd = cs.int_d - omega_f * est.Lq * iqf
        vq = cs.int_q + omega_f * (est.Ld * idf + est.psi_f)
        int_d0 = jnp.where(switch, cd * vd - sd * vq + omega_e * est.Lq * iqh, cs.int_d)
        int_q0 = jnp.where(switch, sd * vd + cd * vq - omega_e * (est.Ld * idh + est.psi_f), cs.int_q)
        return id_ref, iq_ref, held, int_w, int_d0, int_q0

    def _current_loop(
        self,
        cs: ControllerState,
        inp: FOCInput,
        th: jax.Array,
        w_e: jax.Array,
        refs: tuple[jax.Array, jax.Array],
        ints: tuple[jax.Array, jax.Array],
        fw_lo: tuple[jax.Array | None, jax.Array | None],
    ) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array, jax.Array]:
        """The current PIs with decoupling in the frame ``th``, the voltage limit and the delay compensation:
        ``(u_α, u_β, int_d, int_q, field weakening's Δi_d)``."""
        est, u_max, ts, fw = self.est, self.u_max, self.ts, self.field_weakening
        id_ref, iq_ref = refs
        int_d0, int_q0 = ints
        s, c = sincos(th)
        i_d = c * inp.i_a + s * inp.i_b
        i_q = -s * inp.i_a + c * inp.i_b
        e_d, e_q = id_ref - i_d, iq_ref - i_q
        if self.error_limit > 0.0:  # a step becomes a ramp that ends within the margin (jaxobs.drive._reflimit)
            e_d, e_q = limit_error(e_d, e_q, self.error_limit * self.i_max)
        kp_d, kp_q = self.kp_d, self.kp_q
        if self.flux_map and est.sat is not None:
            # IMC on the map's incremental inductance at the reference, where the current settles: k_p = α_c L_inc
            # (module doc); the secant L̂ overstated a saturated q axis 6× on the PM-SyRM, and the loop rang
            ind = est.sat.inductance(id_ref, iq_ref)
            kp_d, kp_q = kp_d * ind[..., 0, 0] / est.Ld, kp_q * ind[..., 1, 1] / est.Lq
        emf_d, emf_q = _policy.rotation_emf(est, w_e, i_d, i_q, self.flux_map)
        u_d = kp_d * e_d + int_d0 - emf_d
        u_q = kp_q * e_q + int_q0 + emf_q
        mag = safe_norm2(u_d, u_q)
        sat = mag > u_max
        scale = jnp.where(sat, u_max / jnp.maximum(mag, 1e-12), 1.0)
        int_d = jnp.where(sat, int_d0, int_d0 + self.ki_d * e_d * ts)
        int_q = jnp.where(sat, int_q0, int_q0 + self.ki_q * e_q * ts)
        if fw is None:
            id_fw = cs.id_fw
        else:
            id_fw = fw.update(cs.id_fw, mag, u_max, w_e, est.Ld, self.i_ref, ts, *fw_lo)
        if self.d_priority:  # u_d* kept (the flux held where field weakening needs it), u_q* takes what is left
            u_d = jnp.clip(u_d, -u_max, u_max)
            room = safe_sqrt(u_max * u_max - u_d * u_d)  # 0 at a clipped u_d*, where a bare √ made gradients NaN
            u_q = jnp.clip(u_q, -room, room)
        else:
            u_d, u_q = u_d * scale, u_q * scale
        # the voltage is applied later (1.5 periods on average by default, jaxobs.drive.latency): rotate ahead
        th_out = th + (self.advance * w_e * ts if self.advance != 0.0 else 0.0)
        so, co = sincos(th_out)
        u_a = co * u_d - so * u_q
        u_b = so * u_d + co * u_q
        return u_a, u_b, int_d, int_q, id_fw
