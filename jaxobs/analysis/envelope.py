"""Where a sensorless design holds: its operating envelope over the speed × load plane.

    ds = envelope({"closed form": cf, "tuned": tuned}, machine=par, drive=drive)
    ds["holds"].sel(design="tuned")            # stable ∧ synchronous ∧ error within the bound
    ds["margin"].sel(design="tuned", load_nm=0)   # 1/s, the slowest mode's decay rate

At every operating point (speed × load, optionally × one mismatch axis) and for every design (an observer that
closes the loop sensorless) it measures two things, each batched over the points in one ``jit(vmap)``:

- **the stability margin** of the simulated, sampled loop (:func:`jaxobs.analysis.stability.floquet`: the
  largest non-neutral Floquet multiplier of ``ClosedLoop.step`` over whole electrical periods of its own
  orbit, as a decay rate; or, with ``stability={"method": "lyapunov"}``, the largest non-neutral Lyapunov
  exponent fitted over a window, :func:`jaxobs.analysis.stability.lyapunov`);
- **a long simulation** through the study runner (:func:`jaxobs.runtime.runner.run_scenarios`), started steady and
  perturbed by a speed-reference pulse: ``perturb`` (relative) × the point's speed from ``t_perturb`` s for one
  time constant 1/α of the point's speed loop, then back.  A pulse, not a step: a step would move the point
  the late window watches (a +2 % step at 405 r/min, 5 N·m on the bench moves 000's second-order SOIFO from
  a point where its loop grows at +0.146 /s, Floquet, onto the stable side of its boundary near 407 r/min),
  and a step in either one direction biases the verdict of a point just beside a boundary.  With the pulse
  the check says not synchronous there (late peak speed deviation 1.40 % against 1.21 % early) and
  synchronous at 410 r/min (−0.32 /s; 0.80 % against 1.07 %): tests/test_envelope.py.  The horizon spans at least
  :data:`HORIZON_TC` time constants 1/α of the slowest speed loop among the points (``horizon`` is its floor)
  and the late window is its second half ``[steady_from, horizon)``.  The rule: the slowest closed-loop mode
  is the speed loop's (α its double-pole bandwidth, :meth:`jaxobs.drive.FOC.speed_gains`; scheduled on the
  speed at low speed, α = |p ω*|/N, where its slowest pair is −0.57 α ± 2.5 α j, docs/stability.md,
  :func:`jaxobs.analysis.stability.linear_speed_loop`), so a response decays by e^-1.7 in 3/α: the early
  window opens 3/α after the pulse ends, the late one at least 3/α after that.  At 20 r/min on 000's SPMSM
  under the scheduled loop (α = 1.05 rad/s) the horizon is 11.5 s, where 2 s marked a holding point "not
  synchronous" (the loop had not finished its step); under the bench's fixed 5 Hz loop (α = 31.4 rad/s) 2 s.
  Nothing is stored per sample (:class:`jaxobs.SaveFinal`): the loop is wrapped in a system that keeps
  running sums in its state — the position error's mean and mean square and its peak over the late window,
  the speed's peak deviation in the early window ``[t_perturb + 4/α, steady_from)`` and in the late one, and
  the mean |ωm − ωm*| and |ωm*| over the late window.

A point is **synchronous** when the run stayed finite, kept lock (late peak position error ≤ 90° electrical,
the drive studies' lost-lock tolerance), kept its speed (:func:`jaxobs.metrics.lost_speed`'s rule on the late
window) and settled: its late peak speed deviation is under ``speed_tol`` and at most 2 % above the early
window's (:data:`SETTLE_GROWTH`: a settled point's windows both see the same steady ripple, equal to within
their sampling; a mode growing at λ shows as about e^(λ (steady_from − early start)), 1.15 at 405 r/min
above).  It **holds** when it is stable (the stability verdict), synchronous and its late peak position
error is within ``bound_deg``.
Where the verdict's linearized run left its operating point (``off_orbit``) the point is unstable and its rate
is a bound (``rate_bound``, :func:`jaxobs.analysis.stability.floquet`), not a margin ± a resolution.

Designs of one class share both compilations (their gains are array leaves).

The dual three-phase drive maps the same way: ``machine`` a :class:`~jaxobs.drive.DualPMSMParams` and ``drive`` a
:class:`~jaxobs.drive.DualDrive` (either current-control mode, closed by the observer from t = 0), each point a
:class:`~jaxobs.drive.DualClosedLoop` whose observer assumes one set (:meth:`DualPMSMParams.per_set`) and whose
load is the whole machine's; the axes' defaults and limits come from the whole machine (``machine.m``).

:func:`worst_case` searches a box of operating points and resistance mismatch for the least stable point: a grid,
then a multi-start projected gradient ascent with a line search, each worst verified by Floquet and simulation.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import AbstractSystem, SaveAll, SaveFinal, kept_jit, simulate
from .. import metrics as M
from ..drive import (
    SETTLE_PERIODS,
    ClosedLoop,
    Drive,
    DualClosedLoop,
    DualDrive,
    DualPMSMParams,
    PMSMParams,
    drive_speed_limit_rpm,
    speed_limit,
)
from ..io.provenance import cf_dataset, provenance
from ..runtime.sharding import batch_mesh
from ..scenarios import Grid
from ..scenarios.families import DRIVE_STUDY_AXES, AbstractFamily, DriveScenarios, bind_observer
from ..studies.study import gain_variables, study
from .stability import Stability, floquet, lyapunov

__all__ = [
    "ENVELOPE_VARIABLES",
    "MISMATCH_AXES",
    "STABILITY_METHODS",
    "WORST_AXES",
    "envelope",
    "default_speeds",
    "speed_limit_rpm",
    "speed_pulse",
    "default_loads",
    "worst_case",
]

# the axes one may add as a third dim (relative errors of the assumed machine, the true inertia)
MISMATCH_AXES = ("dRs", "dLd", "dLq", "dpsi", "dJ")
# variable -> (units, long_name) of the per-point results
ENVELOPE_VARIABLES = {
    "margin": (
        "s-1",
        "stability margin: minus the largest non-neutral exponent of the sampled loop (log|Floquet multiplier|/period)",
    ),
    "stable": (
        "1",
        "stable: margin - resolution > 0 and the orbit held its speed during the linearized run (1: stable)",
    ),
    "marginal": (
        "1",
        "marginal: |margin| within its resolution, the orbit held its speed: neither verdict (1: marginal)",
    ),
    "resolution": (
        "s-1",
        "resolution of the margin: how far the orbit was from periodic (floquet), or the exponent's spread over "
        "the window's thirds (lyapunov); NaN off the orbit (off_orbit: the rate is a bound, rate_bound)",
    ),
    "orbit_speed_dev": ("1", "max |speed - reference| / |reference| during the linearized run after its settle"),
    "off_orbit": (
        "1",
        "off orbit: the linearized run left its operating point (orbit_speed_dev >= 0.1): unstable, its rate a "
        "bound (1: off)",
    ),
    "rate_bound": (
        "s-1",
        "off the orbit: a lower bound on the growth rate, max(exponent - resolution, 0), measured along the "
        "departed trajectory; NaN on the orbit",
    ),
    "synchronous": (
        "1",
        "held synchronism over the long run after a speed-reference pulse: finite, locked, at speed, settled (1: held)",
    ),
    "lost_lock": ("1", "lost lock over the late window: diverged or position error > 90 deg electrical (1: lost)"),
    "lost_speed": ("1", "lost speed over the late window: diverged, or mean |speed - ref| > 20 % of |ref| (1: lost)"),
    "peak_position_late": ("rad", "peak |position error| in the late window (electrical)"),
    "mean_position_late": ("rad", "mean position error in the late window (electrical, signed): the steady bias"),
    "ripple_position_late": ("rad", "rms of the position error about its mean in the late window (electrical)"),
    "peak_speed_deviation_early": ("1", "peak |speed - reference| / |reference| in the early window"),
    "peak_speed_deviation_late": ("1", "peak |speed - reference| / |reference| in the late window"),
    "holds": ("1", "holds: stable, synchronous and peak position error within bound_deg (1: holds)"),
}


def speed_limit_rpm(
    machine: PMSMParams, drive: Drive | DualDrive | None = None, max_speed_rpm: float | None = None
) -> float:
    """The highest speed (r/min) ``drive`` may ask of ``machine``: the drive file's one rule
    (:func:`jaxobs.drive.drivefile.speed_limit`: the no-load voltage bound, ωe ψf = u_max, or with the FOC's
    field weakening ωe (ψf − Ld i_max) = u_max; then the mechanical limit ``max_speed_rpm``, a drive file's
    ``[machine] max_speed_rpm``, or 3 × rated speed where the voltage leaves the speed unbounded).
    ``drive=None``: the default inverter, no weakening (:func:`jaxobs.drive.drive_speed_limit_rpm`)."""
    if drive is None:
        return drive_speed_limit_rpm(machine)
    foc = drive.ctrl.foc if isinstance(drive, DualDrive) else drive.foc  # the dual drive: per phase, the same bound
    return speed_limit(
        machine.p,
        float(machine.psi_f),
        float(machine.Ld),
        float(foc.i_max),
        float(drive.inverter.u_max),
        foc.field_weakening is not None,
        float(machine.n_rated),
        max_speed_rpm,
    )[0]


def default_speeds(
    machine: PMSMParams, n: int = 8, drive: Drive | None = None, max_speed_rpm: float | None = None
) -> np.ndarray:
    """``n`` speeds, r/min, log-spaced from 1 % of the machine's rated speed to the highest allowed speed,
    98 % of :func:`speed_limit_rpm` (the drive's one speed limit, ``max_speed_rpm`` its mechanical one)."""
    top = 0.98 * speed_limit_rpm(machine, drive, max_speed_rpm)
    return np.geomspace(min(0.01 * float(machine.n_rated), 0.5 * top), top, n)


def default_loads(machine: PMSMParams, n: int = 4) -> np.ndarray:
    """``n`` load torques, N·m, evenly from 0 to the machine's rated torque."""
    return np.linspace(0.0, float(machine.T_rated), n)


class _Watch(NamedTuple):
    """Running sums of one long run (no trajectory is stored)."""

    n: jax.Array  # samples in the late window
    sum_e: jax.Array  # Σ position error, rad
    sum_e2: jax.Array  # Σ position error², rad²
    max_e: jax.Array  # max |position error|, rad
    dev_early: jax.Array  # max |ωm − ωm*| / |ωm*| in the early window, 1
    dev_late: jax.Array  # the same in the late window, 1
    sum_dw: jax.Array  # Σ |ωm − ωm*|, rad/s, late window
    sum_ref: jax.Array  # Σ |ωm*|, rad/s, late window


class _Watched(AbstractSystem):
    """A closed loop whose state carries the running sums of :class:`_Watch` (read from ``final_state``)."""

    loop: ClosedLoop
    k_early: jax.Array  # first sample of the early window (per scenario: it follows the point's speed loop)
    k_late: int = eqx.field(static=True)  # first sample of the late window
    unroll: ClassVar[int] = 1

    @property
    def ts(self) -> float:
        return self.loop.ts

    def init(self):
        z = jnp.zeros((), jnp.result_type(float))
        return self.loop.init(), _Watch(z, z, z, z, z, z, z, z)

    def step(self, state, k):
        s, w = state
        new, out = self.loop.step(s, k)
        e = M.wrap(out.obs.theta - out.theta_e)
        dw = jnp.abs(out.omega_m - out.omega_m_ref)
        ref = jnp.abs(out.omega_m_ref)
        dev = dw / jnp.maximum(ref, 1e-9)
        late = k >= self.k_late
        early = (k >= self.k_early) & ~late
        lf = late.astype(e.dtype)
        w = _Watch(
            n=w.n + lf,
            sum_e=w.sum_e + lf * e,
            sum_e2=w.sum_e2 + lf * e * e,
            max_e=jnp.where(late, jnp.maximum(w.max_e, jnp.abs(e)), w.max_e),
            dev_early=jnp.where(early, jnp.maximum(w.dev_early, dev), w.dev_early),
            dev_late=jnp.where(late, jnp.maximum(w.dev_late, dev), w.dev_late),
            sum_dw=w.sum_dw + lf * dw,
            sum_ref=w.sum_ref + lf * ref,
        )
        return (new, w), jnp.zeros((), e.dtype)


# The long run's timing, in time constants 1/α of the speed loop at the point (α: its double-pole bandwidth,
# FOC.speed_gains; scheduled on the speed, |p ω*|/N at low speed, docs/stability.md).  The slowest closed-loop
# mode there is the speed loop's weakly damped pair, −0.57 α ± 2.5 α j (linear_speed_loop at N = 6: −0.60 ±
# 2.67j 1/s at 20 r/min on 000's SPMSM, α = 1.05 rad/s); the fixed loop's double pole −α decays faster.
PULSE_TC = 1.0  # the speed-reference pulse lasts 1/α: the loop follows it by most of its height
EARLY_TC = 3.0  # the early window opens 3/α after the pulse ends: its transient has decayed to e^-1.7 = 0.18
HORIZON_TC = 12.0  # the horizon spans at least 12/α of the slowest point after t_perturb: late window from 6/α
HORIZON_MAX = 30.0  # s: the longest horizon the rule may ask for (1/α ≤ 2.5 s)
SETTLE_GROWTH = 1.02  # a settled point's late peak deviation is at most 2 % above its early one (module doc)


def _pulse_width(drive: Drive, machine: PMSMParams, speeds_rpm) -> np.ndarray:
    """The speed-reference pulse's width at each speed, s: :data:`PULSE_TC` / α (α: :func:`_speed_bandwidth`)."""
    alpha = {float(v): _speed_bandwidth(drive, machine, float(v)) for v in np.unique(np.asarray(speeds_rpm, float))}
    return np.array([PULSE_TC / alpha[float(v)] for v in np.asarray(speeds_rpm, float)])


def speed_pulse(scenarios, t0: float, width, height: float):
    """``scenarios`` (batched, each started steady at its speed reference ω0) with the reference pulsed:
    ω0 (1 + ``height``) from ``t0`` s for ``width`` s (a number or one per scenario), then ω0 again.

    Raises:
        ValueError: ``t0`` or a width not a finite number of seconds > 0.
    """
    w0 = scenarios.speed_ref.values[:, 0]
    width = np.broadcast_to(np.asarray(width, dtype=float), w0.shape)
    if not (math.isfinite(t0) and t0 > 0.0 and np.all(np.isfinite(width)) and np.all(width > 0.0)):
        raise ValueError(f"speed_pulse: t0 and width must be finite numbers of seconds > 0, got {t0!r}, {width!r}")
    times = jnp.stack([jnp.zeros_like(w0), jnp.full_like(w0, t0), t0 + jnp.asarray(width, w0.dtype)], axis=1)
    values = jnp.stack([w0, w0 * (1.0 + height), w0], axis=1)
    return eqx.tree_at(lambda s: (s.speed_ref.times, s.speed_ref.values), scenarios, (times, values))


class _LongRuns(AbstractFamily):
    """The long runs' scenarios: the drive's (``family``), each point's speed reference pulsed by ``perturb`` ×
    its speed from the family's ``t_event`` for :data:`PULSE_TC` / α s and back (so the late window watches the
    operating point itself, not one a step moved it to), the loop wrapped in :class:`_Watched` (its running sums;
    the early window from :data:`EARLY_TC` / α after the pulse)."""

    family: DriveScenarios
    perturb: float = eqx.field(static=True)
    k_late: int = eqx.field(static=True)

    signal: ClassVar[str] = "drive"
    axes: ClassVar[dict] = DRIVE_STUDY_AXES
    closed_loop: ClassVar[bool] = True
    bytes_per_step: ClassVar[int] = DriveScenarios.bytes_per_step
    study_bytes_per_step: ClassVar[int] = DriveScenarios.study_bytes_per_step
    drive_observer: ClassVar[bool] = True
    options: ClassVar[tuple] = ()  # built from the drive's family, not from a TOML table
    # the long run's own metrics (LONG_RUN_METRICS, read from its running sums) and flags (_long_run_flags)
    metrics: ClassVar[tuple[str, ...]] = (
        "peak_position_late",
        "mean_position_late",
        "ripple_position_late",
        "peak_speed_deviation_early",
        "peak_speed_deviation_late",
    )
    flags: ClassVar[tuple[str, ...]] = ("lost_lock", "lost_speed", "synchronous", "diverged")

    def build(self, names, points, first: int = 0):
        fam = self.family
        width = _pulse_width(fam.drive, fam.machine, [p[0] for p in points])
        return speed_pulse(fam.build(names, points, first=first), float(fam.t_event), width, self.perturb)

    def system(self, design, scenario):
        ref = scenario.speed_ref
        t_end, width = ref.times[2], ref.times[2] - ref.times[1]
        k_early = jnp.round((t_end + EARLY_TC / PULSE_TC * width) / self.family.drive.ts)
        return _Watched(self.family.system(design, scenario), k_early, self.k_late)


def _sums(sol):
    """The long run's running sums (:class:`_Watch`), its mean position error and the ripple about it (rad)."""
    w = sol.final_state[1]
    mean = w.sum_e / w.n
    return w, mean, jnp.sqrt(jnp.maximum(w.sum_e2 / w.n - mean * mean, 0.0))


def _var(name: str, form) -> M.Metric:
    return M.Metric(name, *ENVELOPE_VARIABLES[name], exact=form, closed_loop=True)


# the long run's metrics, read from its final state (units and long names: ENVELOPE_VARIABLES)
LONG_RUN_METRICS = (
    _var("peak_position_late", lambda sol, sc, ctx: _sums(sol)[0].max_e),
    _var("mean_position_late", lambda sol, sc, ctx: _sums(sol)[1]),
    _var("ripple_position_late", lambda sol, sc, ctx: _sums(sol)[2]),
    _var("peak_speed_deviation_early", lambda sol, sc, ctx: _sums(sol)[0].dev_early),
    _var("peak_speed_deviation_late", lambda sol, sc, ctx: _sums(sol)[0].dev_late),
)


def _lock_lost(sol, sc, ctx):
    # the lost-lock flag's definition (jaxobs.metrics.lost_lock: |error| > 90 deg electrical somewhere in the window)
    # read from the running maximum: the long run keeps no trajectory
    return _sums(sol)[0].max_e > math.radians(M.LOCK_TOL_DRIVE_DEG)


def _speed_lost(sol, sc, ctx):
    # jaxobs.metrics.lost_speed's definition from the running sums (the window's means are the sums over n)
    w = _sums(sol)[0]
    return w.sum_dw > jnp.maximum(M.SPEED_TOL * w.sum_ref, M.SPEED_FLOOR_RPM * math.pi / 30 * w.n)


def _long_run_flags(speed_tol: float) -> tuple:
    """lost_lock, lost_speed (diverged included) and synchronous: finite, locked, at speed and settled (its late
    peak speed deviation under ``speed_tol`` and at most :data:`SETTLE_GROWTH` × the early window's).  The first two
    are the metric table's flags (:data:`jaxobs.metrics.METRICS`) with the long run's forms, over its late window."""

    def synchronous(sol, sc, ctx):
        w = _sums(sol)[0]
        settled = (w.dev_late < speed_tol) & (w.dev_late <= SETTLE_GROWTH * jnp.maximum(w.dev_early, 1e-6))
        return ~_lock_lost(sol, sc, ctx) & ~_speed_lost(sol, sc, ctx) & settled

    def table(name, form):
        return replace(M.METRICS[name], exact=form, long_name=ENVELOPE_VARIABLES[name][1], count=None)

    sync = M.Metric("synchronous", "1", ENVELOPE_VARIABLES["synchronous"][1], synchronous, kind="flag", diverged=False)
    return table("lost_lock", _lock_lost), table("lost_speed", _speed_lost), sync


class _DualScenarios(DriveScenarios):
    """The dual drive's scenarios: built on the per-set machine ``machine`` (what the observers assume,
    :meth:`DualPMSMParams.per_set`; each scenario's load is the whole machine's, each set carrying half), each
    design closing :class:`~jaxobs.drive.DualClosedLoop` on the dual machine ``dual``."""

    dual: DualPMSMParams | None = None

    def system(self, design, scenario):
        return DualClosedLoop(self.drive, bind_observer(design, scenario), scenario, self.dual)


def _family(machine, drive, **kw) -> DriveScenarios:
    """The scenarios of ``drive`` on ``machine``: the single drive's, or the dual drive's (:class:`_DualScenarios`)."""
    if isinstance(drive, DualDrive):
        return _DualScenarios(None if machine is None else machine.per_set(), drive, dual=machine, **kw)
    return DriveScenarios(machine, drive, **kw)


# the stability verdict's options, by method: its defaults (envelope), and what each accepts
STABILITY_METHODS = {
    "floquet": {"settle": 0.2, "window": 0.2, "max_window": 2.0, "tol": 0.0, "n_report": 3},
    "lyapunov": {"settle": 0.2, "warmup": 0.1, "window": 0.4, "n_dirs": 3, "tol": 0.0},
}


def _stability_fields(drive, obs, scs, method: str, kw: tuple, dual=None):
    """The stability verdict (:func:`floquet` or :func:`lyapunov`) at every scenario of ``scs``, each closed by
    its own row of ``obs`` (observers of one class stacked along a leading axis, as long as the batch: several
    designs in one batch), one program per observer class and batch size (gains are traced); its fields as a
    plain tuple, which a kept program can return.  ``dual``: the dual machine a :class:`DualDrive` runs."""
    fn = floquet if method == "floquet" else lyapunov
    # the system alone: its machine is the scenarios' (the dual one's true machine is ``dual``)
    family = DriveScenarios(None, drive) if dual is None else _DualScenarios(None, drive, dual=dual)
    return tuple(jax.vmap(lambda o, sc: fn(family.system(o, sc), **dict(kw)))(obs, scs))


_stability_jit = kept_jit(_stability_fields)  # kept across processes where a folder is set


def _stability(drive, obs, scs, method: str, kw: tuple, dual=None) -> Stability:
    return Stability(*(_stability_jit(drive, obs, scs, method, kw) if dual is None else
                       _stability_jit(drive, obs, scs, method, kw, dual)))  # fmt: skip


def _speed_bandwidth(drive: Drive, machine: PMSMParams, speed_rpm: float) -> float:
    """The speed loop's double-pole bandwidth α = 2 k_iω / k_pω (rad/s) at ``speed_rpm``: α_s, or less where
    the FOC schedules it on the speed (FOC.speed_gains)."""
    foc = drive.ctrl.foc if isinstance(drive, DualDrive) else drive.foc
    foc = foc.bind(foc.est, drive.inverter.u_max)
    kp, ki = foc.speed_gains(jnp.asarray(speed_rpm * 2.0 * math.pi / 60.0))
    return 2.0 * float(ki) / float(kp)


def _dual_machine(machine, drive, mismatch) -> DualPMSMParams | None:
    """The dual machine when ``drive`` is a :class:`DualDrive` (checked against ``machine`` and ``mismatch``), else
    None.  The dual loop closes by the observer from t = 0 (``handover`` 0: the long run's step and the verdict's
    window see the observer's loop); a mismatch axis moves what the observers assume, so ``dJ`` (the true
    inertia, which the dual loop takes from the dual machine) is refused."""
    if not isinstance(drive, DualDrive):
        if isinstance(machine, DualPMSMParams):
            raise ValueError("envelope: a DualPMSMParams machine needs a DualDrive (jaxobs.drive.dual_bench_drive)")
        return None
    if not isinstance(machine, DualPMSMParams):
        raise ValueError(f"envelope: a DualDrive needs machine to be a DualPMSMParams, got {type(machine).__name__}")
    if drive.handover != 0.0:
        raise ValueError(f"envelope: a DualDrive's handover must be 0 (observer from t = 0), got {drive.handover!r}")
    if mismatch is not None and isinstance(mismatch, tuple) and mismatch and mismatch[0] == "dJ":
        raise ValueError("envelope: mismatch must not be dJ on a DualDrive (its true inertia is the dual machine's)")
    return machine


def _axis(name: str, vals, lo: float, hi: float, unit: str) -> np.ndarray:
    arr = np.asarray(vals, dtype=float)
    if arr.ndim != 1 or arr.size < 1 or not np.all(np.isfinite(arr)) or np.any(arr < lo) or np.any(arr > hi):
        raise ValueError(f"envelope: {name} must be a non-empty list of numbers in [{lo:g}, {hi:g}] {unit}")
    if np.any(np.diff(arr) <= 0):
        raise ValueError(f"envelope: {name} must be strictly increasing")
    return arr


def envelope(
    designs: dict,
    *,
    machine: PMSMParams,
    drive: Drive,
    speeds_rpm=None,
    loads_nm=None,
    mismatch: tuple | None = None,
    horizon: float = 2.0,
    steady_from: float | None = None,
    perturb: float = 0.02,
    t_perturb: float = 0.05,
    bound_deg: float = 30.0,
    speed_tol: float = 0.01,
    stability: dict | None = None,
    seed: int = 0,
    chunk_size: int = 256,
    progress=None,
    max_speed_rpm: float | None = None,
):
    """The operating envelope of every design (name -> drive observer closing ``drive``'s loop sensorless).

    ``speeds_rpm`` (r/min, > 0; default :func:`default_speeds`), ``loads_nm`` (N·m; default
    :func:`default_loads`); ``mismatch``: ``(axis, values)`` with axis one of :data:`MISMATCH_AXES` (relative,
    1), a third dim.  ``horizon`` (s, in [0.5, 20]): the long run's least horizon, stretched to
    :data:`HORIZON_TC` time constants of the slowest speed loop (module doc; at most :data:`HORIZON_MAX`), its
    late window from ``steady_from`` (s; default horizon/2, after the slowest point's early window opens);
    ``perturb`` (relative, in [0, 0.2]): the speed-reference pulse's height, from ``t_perturb`` (s) for
    :data:`PULSE_TC` / α at each point.
    ``bound_deg`` (deg electrical): the late peak position error a holding point may have; ``speed_tol``
    (relative): the late peak speed deviation a synchronous point may have.  ``stability``: ``method``
    ("floquet", the default, or "lyapunov") and that function's keyword arguments
    (:func:`~jaxobs.analysis.stability.floquet`: settle, window, tol, n_report;
    :func:`~jaxobs.analysis.stability.lyapunov`: settle, warmup, window, n_dirs, tol).  ``progress`` as in
    :func:`jaxobs.runtime.runner.run_scenarios`.  ``max_speed_rpm``: the drive file's mechanical limit
    (``[machine] max_speed_rpm``; :func:`speed_limit_rpm`), None: the rule's default.  The long runs' and the
    verdicts' traced programs are kept across
    processes where a folder is set (:func:`jaxobs.kept_jit`).  Returns an ``xarray.Dataset`` with dims
    ``("design", "speed_rpm", "load_nm"[, axis])`` and the variables of :data:`ENVELOPE_VARIABLES` (booleans stored
    as int8 0/1); its ``horizon`` and ``steady_from`` attributes are those that ran.

    Raises:
        ValueError: no design, a drive that is not sensorless or not started steady, or an argument out of its
            range (the message names it and the range).
    """
    import xarray as xr

    if not designs:
        raise ValueError("envelope: at least one design is required")
    if not drive.sensorless or drive.startup is not None:
        raise ValueError("envelope: drive must be sensorless and start steady (Drive(sensorless=True, startup=None))")
    dual = _dual_machine(machine, drive, mismatch)
    machine = machine if dual is None else dual.m  # the whole machine's ratings, ψf and p set the axes
    # the drive's limit with its inverter and field weakening (the dual drive's per phase: the same bound)
    n_max = speed_limit_rpm(machine, drive, max_speed_rpm)
    # the lowest speed whose steady start (Drive.settled_for) fits the 60 s settle limit: SETTLE_PERIODS / p r/min
    n_min = max(1.0, SETTLE_PERIODS / machine.p)
    speeds = default_speeds(machine, drive=drive, max_speed_rpm=max_speed_rpm) if speeds_rpm is None else speeds_rpm
    speeds = _axis("speeds_rpm", speeds, n_min, n_max, "r/min")
    lo_l, hi_l = DRIVE_STUDY_AXES["load_nm"].range
    loads = _axis("loads_nm", default_loads(machine) if loads_nm is None else loads_nm, lo_l, hi_l, "N·m")
    if not (math.isfinite(horizon) and 0.5 <= horizon <= 20.0):
        raise ValueError(f"envelope: horizon must be in [0.5, 20] s, got {horizon!r}")
    if not (math.isfinite(t_perturb) and t_perturb > 0.0):
        raise ValueError(f"envelope: t_perturb must be a number of seconds > 0, got {t_perturb!r}")
    # the horizon spans HORIZON_TC time constants of the slowest speed loop among the points (its floor: horizon)
    tc_max = max(_pulse_width(drive, machine, speeds)) / PULSE_TC
    horizon = min(max(float(horizon), t_perturb + HORIZON_TC * tc_max), max(float(horizon), HORIZON_MAX))
    steady_from = 0.5 * horizon if steady_from is None else float(steady_from)
    early_min = t_perturb + (PULSE_TC + EARLY_TC) * tc_max
    if not (early_min < steady_from < horizon):
        raise ValueError(
            f"envelope: steady_from must be in ({early_min:.4g}, {horizon:.4g}) s (after the slowest point's pulse "
            f"and early window, before the horizon), got {steady_from!r}"
        )
    for name, v, lo, hi in (("perturb", perturb, 0.0, 0.2), ("bound_deg", bound_deg, 0.1, 90.0),
                            ("speed_tol", speed_tol, 1e-4, 1.0)):  # fmt: skip
        if not (lo <= float(v) <= hi):
            raise ValueError(f"envelope: {name} must be in [{lo:g}, {hi:g}], got {v!r}")
    axes = {"speed_rpm": speeds, "load_nm": loads}
    if mismatch is not None:
        if not (isinstance(mismatch, tuple) and len(mismatch) == 2 and mismatch[0] in MISMATCH_AXES):
            raise ValueError(f"envelope: mismatch must be (axis, values) with axis one of {', '.join(MISMATCH_AXES)}")
        m_lo, m_hi = DRIVE_STUDY_AXES[mismatch[0]].range
        axes[mismatch[0]] = _axis(f"mismatch {mismatch[0]}", mismatch[1], m_lo, m_hi, "(relative)")
    stability = dict(stability or {})
    method = stability.pop("method", "floquet")
    if method not in STABILITY_METHODS:
        raise ValueError(f"envelope: stability method must be one of {', '.join(STABILITY_METHODS)}, got {method!r}")
    kw = {**STABILITY_METHODS[method], **stability}
    unknown = set(kw) - set(STABILITY_METHODS[method])
    if unknown:
        raise ValueError(
            f"envelope: stability has unknown keys {sorted(unknown)} for method {method!r}; allowed: "
            f"method, {', '.join(STABILITY_METHODS[method])}"
        )

    # A steady start at every point the loop can hold: the observer settles over SETTLE_PERIODS electrical periods
    # (Drive.settled_for) of the lowest speed whose speed loop is slow enough for a speed estimate scaling with
    # ω_e (a flux observer's FLL) to close it stably, ω_e ≥ 4 α (the linear boundary is 4.2-5.4 α,
    # docs/stability.md).  With 0.2 s the flux observers started 14-41° off below 150 r/min under the scheduled
    # loop.  Below that speed the loop cannot hold with such an observer whatever its start, and settling there
    # for 10 periods would cost 3x the whole envelope (the settle is 2 passes, and the Lyapunov run's jvp).
    w_es = [machine.p * float(s) * 2.0 * math.pi / 60.0 for s in speeds]
    holdable = [w for s, w in zip(speeds, w_es) if w >= 4.0 * _speed_bandwidth(drive, machine, float(s))]
    drive = drive.settled_for(holdable[0] if holdable else w_es[-1])
    # The Lyapunov run spans the slowest speed loop.  With the loop scheduled on the speed (FOC.speed_schedule)
    # its bandwidth α is |p ω*|/N at the lowest speed, 1.05 rad/s at 20 r/min on 000's SPMSM, and its slowest
    # mode there a weakly damped pair −0.60 ± 2.67j 1/s (linear_speed_loop; period 2.5/α at N = 6).  A window
    # whose thirds are shorter than that period sees the pair's wobble, not its decay (the resolution,
    # jaxobs.analysis.stability).  Measured with 000's second-order SOIFO at 20 r/min, no load: over 3 s (π/α)
    # −0.29 ± 1.8 1/s (marginal), over 7.6 s (8/α) −0.58 ± 0.57, over 12 s −0.600 ± 0.13 (the linear model:
    # −0.601).  So the window is at least 12/α and the warm-up 1/α (11.5 s and 1 s there; 0.38 s and 0.03 s
    # for the bench's fixed 5 Hz loop, below the defaults: no change).
    #
    # The Floquet verdict needs none of that: each point's window is its own whole electrical periods (floquet:
    # they make the transition matrix a monodromy matrix), so the longest must hold one period of the lowest
    # speed (2 % more: the speed's move to whole speed-loop periods), and the answer is exact however slow the
    # mode.  Its cost follows each point's period: the points are batched by speed (below).
    if method == "lyapunov":
        alpha = _speed_bandwidth(drive, machine, float(speeds[0]))
        kw["window"] = max(float(kw["window"]), 12.0 / alpha)
        kw["warmup"] = max(float(kw["warmup"]), 1.0 / alpha)
    else:
        kw["max_window"] = max(float(kw["max_window"]), float(kw["window"]), 1.02 * 2.0 * math.pi / w_es[0])
    sampler = Grid(axes)
    names, points = sampler.names, sampler.points()

    # the long runs, a study: each point's speed reference pulses by perturb × its speed at t_perturb; nothing
    # stored per sample (SaveFinal), the wrapped loop's running sums read from its final state
    ts = drive.ts
    family = _family(machine if dual is None else dual, drive, t_event=t_perturb, seed=seed)
    long = _LongRuns(family, float(perturb), int(round(steady_from / ts)))
    runs = study(
        designs,
        long,
        sampler,
        LONG_RUN_METRICS,
        horizon=float(horizon),
        flags=_long_run_flags(float(speed_tol)),
        mask=None,  # a lost point's errors are masked below, its speed deviations kept
        save=SaveFinal(),
        chunk_size=chunk_size,
        mesh=batch_mesh(jax.devices()[:1]),
        progress=progress,
        label="envelope",
    )
    # the stability margins: constant profiles (no step), one jit(vmap) per observer class
    scs = _family(machine if dual is None else dual, drive, seed=seed).build(names, points)
    kwt = tuple(sorted(kw.items()))
    # one batch per speed (every load and mismatch at it, the same shape: one program), so that a batch runs
    # as long as its own points' windows (floquet's while_loop), not the lowest speed's
    spd = np.asarray(points)[:, 0]
    groups = [np.flatnonzero(spd == v) for v in np.unique(spd)]
    if method != "floquet" or len({len(g) for g in groups}) != 1:
        groups = [np.arange(len(spd))]

    # the designs of one observer class (the same tree structure: only the gains differ) share each batch, stacked:
    # one call per speed for all of them instead of one per design.  Measured on the ipmsm002 bench, C-LESO,
    # 10 loads × 3 designs per call: 4.25 s against 5.56 s for three calls at 100 r/min (docs/performance.md)
    classes: dict = {}
    for d, obs in designs.items():
        classes.setdefault(jax.tree.structure(obs), []).append(d)

    def verdicts(names_):
        obs = [designs[d] for d in names_]
        k = len(obs)
        # every group has the same size (one speed's points, or all of them): one stacked copy of the gains
        stacked = jax.tree.map(lambda *x: jnp.repeat(jnp.stack([jnp.asarray(v) for v in x]), len(groups[0]), 0), *obs)
        parts = []
        for g in groups:
            rows = jax.tree.map(lambda x: jnp.concatenate([x[g]] * k), scs)
            parts.append(jax.device_get(_stability(drive, stacked, rows, method, kwt, dual)))
        order = np.argsort(np.concatenate(groups))
        out = {}
        for j, d in enumerate(names_):
            cols = [jax.tree.map(lambda x, j=j, n=len(g): np.asarray(x)[j * n : (j + 1) * n], p)
                    for p, g in zip(parts, groups)]  # fmt: skip
            out[d] = jax.tree.map(lambda *xs: np.concatenate(xs)[order], *cols)
        return out

    stab = {}
    for names_ in classes.values():
        stab.update(verdicts(names_))

    dnames = list(designs)
    shape = (len(dnames), *(len(axes[n]) for n in names))

    def grid(get):
        return np.stack([np.asarray(get(d)) for d in dnames]).reshape(shape)

    res = {
        "margin": grid(lambda d: stab[d].margin),
        "stable": grid(lambda d: stab[d].stable),
        "marginal": grid(lambda d: stab[d].marginal),
        "resolution": grid(lambda d: stab[d].resolution),
        "orbit_speed_dev": grid(lambda d: stab[d].speed_dev),
        "off_orbit": grid(lambda d: stab[d].off_orbit),
        "rate_bound": grid(lambda d: stab[d].rate_bound),
    }
    for k in ("synchronous", "lost_lock", "lost_speed"):  # flags: int8 in the study, booleans here
        res[k] = runs[k].values.astype(bool)
    for m in LONG_RUN_METRICS:
        res[m.name] = runs[m.name].values
    lost = res["lost_lock"].astype(bool)
    for k in ("peak_position_late", "mean_position_late", "ripple_position_late"):
        res[k] = np.where(lost, np.nan, res[k])  # a lost point has no steady error to speak of
    err_ok = np.nan_to_num(np.degrees(res["peak_position_late"]), nan=np.inf) <= bound_deg
    res["holds"] = res["stable"].astype(bool) & res["synchronous"].astype(bool) & err_ok

    dims = ("design", "speed_rpm", "load_nm", *names[2:])
    coords = {
        "design": ("design", dnames, {"long_name": "observer design (closing the loop sensorless)"}),
        "speed_rpm": ("speed_rpm", speeds, DRIVE_STUDY_AXES["speed_rpm"].attrs),
        "load_nm": ("load_nm", loads, DRIVE_STUDY_AXES["load_nm"].attrs),
    }
    if mismatch is not None:
        coords[mismatch[0]] = (mismatch[0], axes[mismatch[0]], DRIVE_STUDY_AXES[mismatch[0]].attrs)
    data = {}
    for k, (unit, long_name) in ENVELOPE_VARIABLES.items():
        v = res[k]
        v = v.astype(np.int8) if v.dtype == bool else v.astype(float)
        data[k] = (dims, v, {"units": unit, "long_name": long_name})
    data.update(gain_variables({d: designs[d] for d in dnames}))  # as the drive studies write them
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update(
        horizon=float(horizon),
        steady_from=steady_from,
        perturb=float(perturb),
        t_perturb=float(t_perturb),
        pulse_time_constants=PULSE_TC,
        bound_deg=float(bound_deg),
        speed_tol=float(speed_tol),
        seed=seed,
        **{f"stability_{k}": float(v) for k, v in kw.items()},
        stability_method=method,
    )
    for f in ("Rs", "Ld", "Lq", "psi_f", "p", "J", "T_rated", "n_rated"):
        ds.attrs[f"machine_{f}"] = float(getattr(machine, f))
    ds.attrs.update(drive_ts=float(drive.ts), drive_settle=float(drive.settle))
    if dual is not None:  # the machine_ attributes are then the αβ subspace's, with the whole machine's J and ratings
        ds.attrs.update(machine_Lls=float(dual.Lls), drive_mode=drive.mode, drive_fw_voltage=drive.ctrl.fw_voltage)
    ds.attrs.update(provenance("jaxobs.analysis.envelope.envelope"))
    return cf_dataset(ds, "jaxobs operating envelope: where each design holds over speed x load")


# --------------------------------------------------------------------------
# the worst case by gradients
# --------------------------------------------------------------------------

# the box's axes a gradient search moves: the operating point and the assumed resistance
WORST_AXES = ("speed_rpm", "load_nm", "dRs")
# the step sizes one line-search round tries per start, as fractions of the start's trust length (in one batch)
_TRIALS = (1.0, 1.0 / 3.0, 1.0 / 9.0)
_ARMIJO = 1e-4  # sufficient increase: f(u') ≥ f(u) + c ∇f·(u' − u), c of Armijo's rule


def _point(base, par: PMSMParams, x):
    """``base`` (one scenario, its speed reference a step at its ``t_event``) moved to x = (speed r/min, load
    N·m, dRs), traceably: the reference held at the speed (both values of the step), the load constant."""
    w = x[0] * jnp.pi / 30
    return eqx.tree_at(
        lambda s: (s.speed_ref.values, s.load.values, s.omega_m0, s.est_par.Rs),
        base,
        (jnp.full_like(base.speed_ref.values, w), jnp.full_like(base.load.values, x[1]), w, par.Rs * (1 + x[2])),
    )


@eqx.filter_jit
def _exponent_and_grad(drive, obs, base, par, xs, kw: tuple):
    """The Lyapunov exponent (1/s) at each point of ``xs`` (B × 3) and its gradient in the point, by forward mode
    (one tangent per axis; no reverse pass through the linearized run, whose compilation took minutes).  One
    program per design class and batch size: the points are its argument."""

    def expo(x):
        sc = _point(base, par, x)
        return lyapunov(DriveScenarios(par, drive).system(obs, sc), **dict(kw)).exponent

    def value_and_jac(x):
        eye = jnp.eye(x.shape[0], dtype=x.dtype)
        return jax.vmap(lambda t: jax.jvp(expo, (x,), (t,)), out_axes=(None, 0))(eye)

    return jax.vmap(value_and_jac)(xs)


@eqx.filter_jit
def _verify_points(drive, obs, base, par, xs, signs, fkw: tuple, horizon: float, block: int):
    """At each point of ``xs``: :func:`floquet`'s verdict, and per sign of ``signs`` a ``horizon`` s simulation whose
    speed reference steps by ``sign`` (relative) at the base's ``t_event``: its peak |ωm − ωm*|/|ωm*| (against the
    reference of the moment) per block of ``block`` samples (points × signs × blocks)."""
    family = DriveScenarios(par, drive)

    def one(x):
        sc = _point(base, par, x)
        fv = floquet(family.system(obs, sc), **dict(fkw))

        def run(sign):
            vals = sc.speed_ref.values.at[1:].multiply(1.0 + sign)
            moved = eqx.tree_at(lambda s: s.speed_ref.values, sc, vals)
            o = simulate(family.system(obs, moved), horizon, save=SaveAll()).outputs
            dev = jnp.abs(o.omega_m - o.omega_m_ref) / jnp.abs(o.omega_m_ref)
            dev = jnp.where(jnp.isfinite(dev), dev, jnp.inf)
            n = (dev.shape[0] // block) * block
            return dev[:n].reshape(-1, block).max(axis=1)

        return tuple(fv), jax.vmap(run)(signs)

    return jax.vmap(one)(xs)


def _simulated_rate(peaks, block_s: float, t_from: float, floor: float = 1e-5, ceil: float = 0.3) -> float:
    """The growth rate (1/s) of a simulated deviation: the least-squares slope of log(peak per block) over the
    blocks from ``t_from`` s until the first that passes ``ceil`` (saturation), those above ``floor`` (the noise)."""
    p = np.asarray(peaks, float)
    t = (np.arange(p.size) + 0.5) * block_s
    over = np.flatnonzero(~(p < ceil))
    end = over[0] if over.size else p.size
    keep = (t >= t_from) & (np.arange(p.size) < end) & (p > floor)
    if keep.sum() < 3:
        return float("inf") if over.size and over[0] * block_s < t_from + 3 * block_s else float("nan")
    return float(np.polyfit(t[keep], np.log(p[keep]), 1)[0])


def _ascend(evaluate, u, v, g, iters: int):
    """Multi-start projected gradient ascent in the unit cube with a parallel backtracking (Armijo) line search
    (:func:`worst_case` has the rule).  ``evaluate(points)`` gives the values and gradients at the rows of
    ``points``; ``u``, ``v``, ``g``: the starts, their values and gradients (each start a row).  Returns the best
    point evaluated, its value, and each start's value per round (iters + 1, starts)."""
    u, v, g = u.copy(), v.copy(), g.copy()
    n_starts, dim = u.shape
    trust = np.full(n_starts, 0.25)
    active = np.ones(n_starts, bool)
    best_u, best_v = u[np.argmax(v)].copy(), float(np.max(v))
    path = [v.copy()]
    fr = np.asarray(_TRIALS)
    for _ in range(iters):
        if not active.any():
            path.append(v.copy())
            continue
        # the projected gradient: a component pushing out of the box at a face the start lies on is dropped
        # before the direction is normalized (else it takes the step's length and the clip then wastes it)
        gp = np.where(((u <= 0.0) & (g < 0)) | ((u >= 1.0) & (g > 0)), 0.0, g)
        d = gp / np.maximum(np.linalg.norm(gp, axis=1, keepdims=True), 1e-300)
        trial = np.clip(u[:, None, :] + (trust[:, None] * fr)[:, :, None] * d[:, None, :], 0.0, 1.0)
        tv, tg = evaluate(trial.reshape(-1, dim))
        tv, tg = tv.reshape(n_starts, len(fr)), tg.reshape(n_starts, len(fr), -1)
        gain = np.einsum("sj,stj->st", g, trial - u[:, None, :])
        ok = (tv >= v[:, None] + _ARMIJO * gain) & (gain > 0)
        for s in np.flatnonzero(active):
            if tv[s].max() > best_v:
                best_u, best_v = trial[s, int(np.argmax(tv[s]))].copy(), float(tv[s].max())
            if ok[s].any():
                j = int(np.argmax(np.where(ok[s], tv[s], -np.inf)))
                step = np.linalg.norm(trial[s, j] - u[s])
                u[s], v[s], g[s] = trial[s, j], tv[s, j], tg[s, j]
                trust[s] = min(1.0, 2.0 * trust[s] * fr[j]) if j == 0 else trust[s] * fr[j]
                active[s] = step >= 1e-3
            else:
                trust[s] /= 27.0
                active[s] = trust[s] >= 1e-3 and np.linalg.norm(trial[s, 0] - u[s]) >= 1e-3
        path.append(v.copy())
    return best_u, best_v, np.stack(path)


def worst_case(
    obs,
    *,
    machine: PMSMParams,
    drive: Drive,
    box: dict,
    grid: int = 3,
    k_grid: int = 2,
    n_random: int = 2,
    iters: int = 6,
    stability: dict | None = None,
    verify: dict | None = None,
    seed: int = 0,
) -> dict:
    """The operating point in ``box`` where ``obs`` is least stable: a grid, then a multi-start projected gradient
    ascent with a backtracking (Armijo) line search of the largest non-neutral Lyapunov exponent (1/s).

    The search runs in the box scaled to the unit cube.  ``grid`` points per free axis (ends included) are
    evaluated first; the ``k_grid`` worst of them and ``n_random`` uniform interior points (``seed``) start the
    search.  Each round every start tries the projected steps u' = clip(u + s t d) along its projected gradient's
    direction d (unit length in the cube; a component pushing out through a face the start lies on dropped) for
    s in 1, 1/3, 1/9 of its trust length t (first 0.25), all starts' trials in one batch; it moves to the best
    trial that meets Armijo's rule f(u') ≥ f(u) + 10⁻⁴ ∇f·(u' − u), its t doubled after a full step and cut to
    the step taken after a shorter one, and cuts t by 27 where none does; a start stops when its projected step is
    under 10⁻³ (a corner whose gradient points out, or a local maximum).  Every evaluation (grid, starts and
    trials) is one program compiled once per design class: the points are its argument, a fixed batch (starts ×
    trials, the grid padded to it); the gradient is forward mode through the linearized run.

    The grid's worst and the search's worst are then each verified (one more program): :func:`floquet`'s exponent
    and resolution, and simulations whose speed reference steps by ±``perturb`` (relative) at 0.05 s, whose
    growth rate is the slope of the log peak speed deviation per 0.05 s block from 0.15 s on
    (:func:`_simulated_rate`: until the deviation passes 30 %, above 10⁻⁵).

    Args:
        obs: a drive observer closing ``drive``'s loop sensorless.
        machine: the true and nominal machine.
        drive: a sensorless drive started steady (``startup`` None); its settle lengthened to the box's lowest
            speed (:meth:`~jaxobs.drive.Drive.settled_for`).
        box: ``{axis: (low, high)}`` over :data:`WORST_AXES` (speed r/min ≥ 1, load N·m, dRs relative); an axis
            left out is held at 0 (speed: required).
        grid: grid points per free axis (≥ 2).
        k_grid: the grid's worst points that start the search (≥ 0).
        n_random: random interior starts (≥ 0; k_grid + n_random ≥ 1).
        iters: line-search rounds (≥ 0).
        stability: :func:`~jaxobs.analysis.stability.lyapunov`'s options (default warmup 0.05, n_dirs 2, settle and
            window 0.1 and 0.2 s or one electrical period of the box's lowest speed where that is longer).
        verify: None for the defaults ``{"horizon": 1.0, "perturb": 0.02, "settle": 0.05, "window": 0.2}`` (the
            simulations' s and relative step, :func:`floquet`'s settle and window: short, since at a point that
            grows at +7 /s a 0.2 s settle and 0.5 s window let the orbit leave the operating point, and the rate
            came out 2.69 ± 0.25 /s where the simulations grow at 5.7–6.7), or False to skip it.
        seed: the random starts.

    Returns:
        A dict of NumPy and plain values: ``grid_x`` (points × 3), ``grid_exponent``; ``grid_worst`` and
        ``search_worst``, each ``{"x": {axis: value}, "exponent", and where verified "floquet", "floquet_resolution",
        "sim_rate_up", "sim_rate_down"}``; ``path`` (iters + 1, starts: each start's exponent per round),
        ``starts_x``, ``evaluations`` (points evaluated) and ``seconds`` (wall, compilation included).

    Raises:
        ValueError: a box axis unknown or not a finite (low, high) with low ≤ high, speed missing or below
            1 r/min, or a count out of range.
    """
    import time

    t_start = time.perf_counter()
    if not isinstance(box, dict):
        raise ValueError(f"worst_case: box must be a dict {{axis: (low, high)}}, got {type(box).__name__}")
    if "speed_rpm" not in box:
        raise ValueError("worst_case: box must give speed_rpm = (low, high), r/min")
    unknown = set(box) - set(WORST_AXES)
    if unknown:
        raise ValueError(f"worst_case: box has unknown axes {sorted(unknown)}; allowed: {', '.join(WORST_AXES)}")
    # each axis within what a drive study allows (the speed up to the drive's limit, a positive resistance)
    allowed = {"speed_rpm": (1.0, speed_limit_rpm(machine, drive)), "load_nm": DRIVE_STUDY_AXES["load_nm"].range,
               "dRs": DRIVE_STUDY_AXES["dRs"].range}  # fmt: skip
    lo, hi = np.zeros(len(WORST_AXES)), np.zeros(len(WORST_AXES))
    for i, a in enumerate(WORST_AXES):
        if a not in box:
            continue
        v = box[a]
        if not isinstance(v, (tuple, list)) or len(v) != 2:
            raise ValueError(f"worst_case: box[{a!r}] must be a (low, high) pair, got {v!r}"[:200])
        try:
            lo[i], hi[i] = float(v[0]), float(v[1])
        except (TypeError, ValueError):
            raise ValueError(f"worst_case: box[{a!r}] must be two numbers, got {v!r}"[:200]) from None
        a_lo, a_hi = allowed[a]
        if not (math.isfinite(lo[i]) and math.isfinite(hi[i]) and a_lo <= lo[i] <= hi[i] <= a_hi):
            raise ValueError(
                f"worst_case: box[{a!r}] must be finite with {a_lo:.4g} <= low <= high <= {a_hi:.4g}, got "
                f"({lo[i]:g}, {hi[i]:g})"
            )
    for name, v, least in (("grid", grid, 2), ("k_grid", k_grid, 0), ("n_random", n_random, 0), ("iters", iters, 0)):
        if isinstance(v, bool) or not isinstance(v, int) or v < least:
            raise ValueError(f"worst_case: {name} must be an integer >= {least}, got {v!r}")
    n_starts = k_grid + n_random
    if n_starts < 1:
        raise ValueError("worst_case: k_grid + n_random must be >= 1")
    ver = {"horizon": 1.0, "perturb": 0.02, "settle": 0.05, "window": 0.2}
    if verify not in (None, False):
        unknown = set(verify) - set(ver)
        if unknown:
            raise ValueError(f"worst_case: verify has unknown keys {sorted(unknown)}; allowed: {', '.join(ver)}")
        ver.update(verify)
    if verify is not False and not (0.5 <= float(ver["horizon"]) <= 10.0 and 0.0 < float(ver["perturb"]) <= 0.2):
        raise ValueError("worst_case: verify horizon must be in [0.5, 10] s and perturb in (0, 0.2]")
    # the objective's settle and window cover at least one electrical period of the box's lowest speed.  A window
    # shorter than the period fits the exponent to part of the orbit's own oscillation: 000's SOIFO closed form at
    # 40 r/min (a 0.5 s period on spmsm000) read +14.3 ± 11.4 /s over 0.1 s + 0.2 s against Floquet's +6.83, which
    # made the box's lowest speed look worst and hid the interior maximum near 126 r/min (+8.50); over one period
    # (0.5 s + 0.5 s) it reads +7.44, and +8.56 at 126 r/min (tests/test_envelope.py)
    t_e = 60.0 / (machine.p * float(lo[0]))
    defaults = {"settle": max(0.1, t_e), "warmup": 0.05, "window": max(0.2, t_e), "n_dirs": 2}
    kw = tuple(sorted({**defaults, **(stability or {})}.items()))
    # a steady start at every point of the box: the observer settled over SETTLE_PERIODS electrical periods of its
    # lowest speed (Drive.settled_for, as envelope's).  With the drive's 0.2 s at 250 r/min (6.7 periods) the
    # second-order SOIFO's run left its operating point within 0.3 s, and the short-window exponent there read
    # 6.46 /s against Floquet's 7.86
    drive = drive.settled_for(machine.p * float(lo[0]) * math.pi / 30)
    t_step = 0.05  # the verifying runs' reference step, s
    base = jax.tree.map(
        lambda v: v[0],
        DriveScenarios(machine, drive, t_event=t_step).build(["speed_rpm", "speed_step_rpm"], [(float(lo[0]), 0.0)]),
    )
    span = hi - lo
    free = span > 0
    batch = n_starts * len(_TRIALS)
    n_eval = 0

    def evaluate(u):
        """Exponent and its gradient in the unit cube at the rows of ``u``, in batches of ``batch`` (padded)."""
        nonlocal n_eval
        n_eval += len(u)
        vals, grads = [], []
        for i in range(0, len(u), batch):
            part = u[i : i + batch]
            pad = np.concatenate([part, np.repeat(part[-1:], batch - len(part), axis=0)])
            v, g = jax.device_get(_exponent_and_grad(drive, obs, base, machine, jnp.asarray(lo + span * pad), kw))
            vals.append(np.asarray(v)[: len(part)])
            grads.append(np.asarray(g)[: len(part)] * span)
        v, g = np.concatenate(vals), np.concatenate(grads)
        v = np.where(np.isnan(v), -np.inf, v)  # a failed evaluation is never the worst
        return v, np.where(np.isfinite(g), g, 0.0) * free

    # the grid, and the starts: its k worst points and random interior ones
    axes_u = [np.linspace(0.0, 1.0, grid) if f else np.zeros(1) for f in free]
    grid_u = np.stack(np.meshgrid(*axes_u, indexing="ij"), axis=-1).reshape(-1, len(WORST_AXES))
    grid_v, grid_g = evaluate(grid_u)
    order = np.argsort(-grid_v, kind="stable")[:k_grid]
    rng = np.random.default_rng(seed)
    rand_u = rng.uniform(0.05, 0.95, size=(n_random, len(WORST_AXES))) * free
    u, v, g = grid_u[order], grid_v[order], grid_g[order]
    if n_random:
        rv, rg = evaluate(rand_u)
        u, v, g = np.concatenate([u, rand_u]), np.concatenate([v, rv]), np.concatenate([g, rg])
    starts_u = u.copy()
    best_u, best_v, path = _ascend(evaluate, u, v, g, iters)
    grid_i = int(np.argmax(grid_v))
    found = {
        "grid_worst": {"u": grid_u[grid_i], "exponent": float(grid_v[grid_i])},
        "search_worst": {"u": best_u, "exponent": best_v},
    }
    if verify is not False:
        t_blk = 0.05
        blk = max(int(round(t_blk / drive.ts)), 1)
        xs = jnp.asarray(lo + span * np.stack([f["u"] for f in found.values()]))
        signs = jnp.asarray([float(ver["perturb"]), -float(ver["perturb"])])
        fkw = tuple(sorted({"settle": float(ver["settle"]), "window": float(ver["window"])}.items()))
        fv, peaks = jax.device_get(
            _verify_points(drive, obs, base, machine, xs, signs, fkw, float(ver["horizon"]), blk)
        )
        fv = Stability(*fv)
        for i, f in enumerate(found.values()):
            f["floquet"] = float(fv.exponent[i])
            f["floquet_resolution"] = float(fv.resolution[i])
            f["sim_rate_up"], f["sim_rate_down"] = (
                _simulated_rate(peaks[i, j], blk * drive.ts, t_step + 0.1) for j in range(2)
            )
    for f in found.values():
        f["x"] = dict(zip(WORST_AXES, (lo + span * f.pop("u")).tolist()))
    return {
        "grid_x": lo + span * grid_u,
        "grid_exponent": grid_v,
        **found,
        "path": path,
        "starts_x": lo + span * starts_u,
        "evaluations": n_eval,
        "seconds": time.perf_counter() - t_start,
    }
