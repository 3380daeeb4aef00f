"""The envelope's grid and its runs: the speed and load axes a drive allows, the long runs' scenarios (a
speed-reference pulse, the loop wrapped in a system that keeps running sums), their metrics and flags, and the
stability verdict batched over the points (:func:`jaxobs.analysis.envelope.envelope` assembles them).

The long run's timing is in time constants 1/α of the speed loop at the point (:data:`PULSE_TC`,
:data:`EARLY_TC`, :data:`HORIZON_TC`; the module doc of :mod:`jaxobs.analysis.envelope` has the rule)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any, ClassVar, NamedTuple, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from .. import AbstractSystem, kept_jit
from .. import metrics as M
from ..core.quantities import Axis
from ..drive import (
    ClosedLoop,
    Drive,
    DualClosedLoop,
    DualDrive,
    DualPMSMParams,
    PMSMParams,
    Scenario,
    drive_speed_limit_rpm,
    speed_limit,
)
from ..drive.weakening import map_speed_flux
from ..observers import AbstractObserver
from ..scenarios.families import DRIVE_STUDY_AXES, AbstractFamily, DriveScenarios, bind_observer
from .envelope_layout import ENVELOPE_VARIABLES
from .stability import Stability, floquet, lyapunov
from .verdict import verdict_from

__all__ = [
    "EARLY_TC",
    "HORIZON_MAX",
    "HORIZON_TC",
    "LONG_RUN_METRICS",
    "MISMATCH_AXES",
    "PULSE_TC",
    "SETTLE_GROWTH",
    "STABILITY_METHODS",
    "build_signed",
    "default_loads",
    "default_speeds",
    "speed_limit_rpm",
    "speed_pulse",
    "worse_pulse",
    "PULSE_AXIS",
    "PULSES",
]

# the axes one may add as a third dim (relative errors of the assumed machine, the true inertia)
MISMATCH_AXES = ("dRs", "dLd", "dLq", "dpsi", "dJ")
_S = TypeVar("_S", bound=Scenario)


def speed_limit_rpm(
    machine: PMSMParams, drive: Drive | DualDrive | None = None, max_speed_rpm: float | None = None
) -> float:
    """The highest speed (r/min) ``drive`` may ask of ``machine``: the drive file's one rule.

    The rule (:func:`jaxobs.drive.drivefile.speed_limit`): the no-load voltage bound, ωe ψf = u_max, or with the
    FOC's field weakening ωe (ψf − Ld i_max) = u_max (a saturation map's flux there where the machine has one);
    then the mechanical limit.

    Args:
        machine: the machine.
        drive: the drive (its inverter and FOC); None: the default inverter, no weakening
            (:func:`jaxobs.drive.drive_speed_limit_rpm`).
        max_speed_rpm: the mechanical limit, a drive file's ``[machine] max_speed_rpm``; None: 3 × rated speed
            where the voltage leaves the speed unbounded.

    Returns:
        The speed limit, r/min.
    """
    if drive is None:
        return drive_speed_limit_rpm(machine)
    foc = drive.ctrl.foc if isinstance(drive, DualDrive) else drive.foc  # the dual drive: per phase, the same bound
    weak = foc.field_weakening is not None
    return speed_limit(
        machine.p,
        float(machine.psi_f),
        float(machine.Ld),
        float(foc.i_max),
        float(drive.inverter.u_max),
        weak,
        float(machine.n_rated),
        max_speed_rpm,
        map_speed_flux(machine, float(foc.i_max), weak),  # a saturation map's flux (None: the constants)
    )[0]


def default_speeds(
    machine: PMSMParams, n: int = 8, drive: Drive | DualDrive | None = None, max_speed_rpm: float | None = None
) -> np.ndarray:
    """``n`` speeds, r/min, log-spaced from 1 % of the machine's rated speed to the highest allowed speed.

    Args:
        machine: the machine (its rated speed).
        n: how many speeds.
        drive: the drive (its inverter and field weakening set the limit); None: the default inverter.
        max_speed_rpm: the mechanical limit, r/min (None: the rule's default).

    Returns:
        The speeds, up to 98 % of :func:`speed_limit_rpm` (the drive's one speed limit).
    """
    top = 0.98 * speed_limit_rpm(machine, drive, max_speed_rpm)
    return np.geomspace(min(0.01 * float(machine.n_rated), 0.5 * top), top, n)


def default_loads(machine: PMSMParams, n: int = 4) -> np.ndarray:
    """``n`` load torques, N·m, evenly from 0 to the machine's rated torque.

    Args:
        machine: the machine (its rated torque).
        n: how many loads.

    Returns:
        The load torques, N·m.
    """
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
    # the verdict's quantities (jaxobs.analysis.verdict.verdict_from): lock from the pulse on, the swing of
    # ωm − ωm* in each half of the late window, and whether every value stayed finite
    max_e_event: jax.Array  # max |position error| from the pulse on, rad
    hi1: jax.Array  # max (ωm − ωm*), rad/s, the late window's first half
    lo1: jax.Array  # min (ωm − ωm*), the same
    hi2: jax.Array  # max (ωm − ωm*), its second half
    lo2: jax.Array  # min (ωm − ωm*), the same
    finite: jax.Array  # 1 while every position error and speed so far is finite, else 0


class _Watched(AbstractSystem):
    """A closed loop whose state carries the running sums of :class:`_Watch` (read from ``final_state``)."""

    loop: ClosedLoop
    k_early: jax.Array  # first sample of the early window (per scenario: it follows the point's speed loop)
    k_late: int = eqx.field(static=True)  # first sample of the late window
    k_event: int = eqx.field(static=True, default=0)  # first sample of the verdict's event window (the pulse)
    k_mid: int = eqx.field(static=True, default=0)  # first sample of the late window's second half
    unroll: ClassVar[int] = 1

    @property
    def ts(self) -> float:
        return self.loop.ts

    def init(self):
        z = jnp.zeros((), jnp.result_type(float))
        inf = jnp.full((), jnp.inf, z.dtype)
        return self.loop.init(), _Watch(z, z, z, z, z, z, z, z, z, -inf, inf, -inf, inf, z + 1.0)

    def step(self, state, k):
        s, w = state
        new, out = self.loop.step(s, k)
        e = M.wrap(out.obs.theta - out.theta_e)
        sdw = out.omega_m - out.omega_m_ref
        dw = jnp.abs(sdw)
        ref = jnp.abs(out.omega_m_ref)
        dev = dw / jnp.maximum(ref, 1e-9)
        late = k >= self.k_late
        early = (k >= self.k_early) & ~late
        lf = late.astype(e.dtype)
        first, second = late & (k < self.k_mid), k >= self.k_mid
        ok = jnp.isfinite(e) & jnp.isfinite(out.omega_m)
        w = _Watch(
            n=w.n + lf,
            sum_e=w.sum_e + lf * e,
            sum_e2=w.sum_e2 + lf * e * e,
            max_e=jnp.where(late, jnp.maximum(w.max_e, jnp.abs(e)), w.max_e),
            dev_early=jnp.where(early, jnp.maximum(w.dev_early, dev), w.dev_early),
            dev_late=jnp.where(late, jnp.maximum(w.dev_late, dev), w.dev_late),
            sum_dw=w.sum_dw + lf * dw,
            sum_ref=w.sum_ref + lf * ref,
            max_e_event=jnp.where(k >= self.k_event, jnp.maximum(w.max_e_event, jnp.abs(e)), w.max_e_event),
            hi1=jnp.where(first, jnp.maximum(w.hi1, sdw), w.hi1),
            lo1=jnp.where(first, jnp.minimum(w.lo1, sdw), w.lo1),
            hi2=jnp.where(second, jnp.maximum(w.hi2, sdw), w.hi2),
            lo2=jnp.where(second, jnp.minimum(w.lo2, sdw), w.lo2),
            finite=jnp.where(ok, w.finite, 0.0),
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


def build_signed(
    family: AbstractFamily, names: Sequence[str], points: Sequence[Sequence[float]], first: int = 0
) -> Any:
    """``family``'s scenarios at ``points`` whose ``speed_rpm`` may be negative (a drive runs both ways).

    The scenarios are built at |speed| (the drive axes' range is positive) and turned to the signed speed: the
    speed reference and the start speed ω_m0 negated where the speed is negative, which is what a scenario
    built at that speed holds (:func:`jaxobs.drive.scenario_batch` sets exactly these two from ``speed_rpm``;
    the observer is bound at p̂ ω_m0, the sign included).  Where every speed is positive the scenarios are the
    family's own.

    Args:
        family: A drive family (:class:`~jaxobs.scenarios.families.DriveScenarios` or the dual one).
        names: The axes, ``speed_rpm`` first.
        points: Tuples of values for ``names``.
        first: The index of ``points[0]`` among all the scenarios (the noise keys).

    Returns:
        The batched :class:`~jaxobs.drive.Scenario`.
    """
    pts = np.asarray(points, dtype=float).reshape(len(points), len(names))
    i = list(names).index("speed_rpm")
    sign = np.where(pts[:, i] < 0.0, -1.0, 1.0)
    if np.all(sign > 0.0):
        return family.build(names, points, first=first)
    pts[:, i] = np.abs(pts[:, i])
    scs = family.build(names, [tuple(p) for p in pts], first=first)
    sg = jnp.asarray(sign, scs.omega_m0.dtype)
    return eqx.tree_at(
        lambda sc: (sc.speed_ref.values, sc.omega_m0), scs, (scs.speed_ref.values * sg[:, None], scs.omega_m0 * sg)
    )


def _pulse_width(drive: Drive | DualDrive, machine: PMSMParams, speeds_rpm) -> np.ndarray:
    """The speed-reference pulse's width at each speed, s: :data:`PULSE_TC` / α (α: :func:`_speed_bandwidth`)."""
    alpha = {float(v): _speed_bandwidth(drive, machine, float(v)) for v in np.unique(np.asarray(speeds_rpm, float))}
    return np.array([PULSE_TC / alpha[float(v)] for v in np.asarray(speeds_rpm, float)])


def speed_pulse(scenarios: _S, t0: float, width: ArrayLike, height: ArrayLike) -> _S:
    """``scenarios`` (batched, each started steady at its speed reference ω0) with the reference pulsed.

    Args:
        scenarios: a batch of drive scenarios (:class:`~jaxobs.drive.Scenario`, leading axis the batch).
        t0: the pulse's start, s.
        width: its width, s: a number or one per scenario.
        height: its height, relative: the reference is ω0 (1 + ``height``) from ``t0`` for ``width``, then ω0; a
            number or one per scenario (negative: a pulse down).

    Returns:
        The scenarios with the pulsed speed reference.

    Raises:
        ValueError: ``t0`` or a width not a finite number of seconds > 0.
    """
    w0 = scenarios.speed_ref.values[:, 0]
    width = np.broadcast_to(np.asarray(width, dtype=float), w0.shape)
    if not (math.isfinite(t0) and t0 > 0.0 and np.all(np.isfinite(width)) and np.all(width > 0.0)):
        raise ValueError(f"speed_pulse: t0 and width must be finite numbers of seconds > 0, got {t0!r}, {width!r}")
    times = jnp.stack([jnp.zeros_like(w0), jnp.full_like(w0, t0), t0 + jnp.asarray(width, w0.dtype)], axis=1)
    values = jnp.stack([w0, w0 * (1.0 + jnp.asarray(height, w0.dtype)), w0], axis=1)
    return eqx.tree_at(lambda s: (s.speed_ref.times, s.speed_ref.values), scenarios, (times, values))


# the long runs' last axis: the pulse's direction, each point run twice (PULSES; envelope_runs.worse_pulse)
PULSE_AXIS = Axis("pulse", "1", (-1.0, 1.0), "direction of the speed-reference pulse: +1 up, -1 down")
PULSES = (1.0, -1.0)  # up first: where both directions' runs are alike the point reads the up pulse's run


class _LongRuns(AbstractFamily):
    """The long runs' scenarios: the drive's (``family``), each point's speed reference pulsed by ``perturb`` ×
    its speed from the family's ``t_event`` for :data:`PULSE_TC` / α s and back (so the late window watches the
    operating point itself, not one a step moved it to), the loop wrapped in :class:`_Watched` (its running sums;
    the early window from :data:`EARLY_TC` / α after the pulse).

    The last axis of the points is ``pulse`` (:data:`PULSE_AXIS`: +1 up, −1 down), so each operating point runs
    both ways in the one batch; both runs of a point draw the same noise (the key of the point's index among the
    points without the pulse axis: the up run's is the one-direction map's), so they differ by the pulse alone.
    """

    family: DriveScenarios
    perturb: float = eqx.field(static=True)
    k_late: int = eqx.field(static=True)
    k_mid: int = eqx.field(static=True, default=0)  # the late window's second half (the verdict's swing test)

    signal: ClassVar[str] = "drive"
    axes: ClassVar[dict] = {**DRIVE_STUDY_AXES, "pulse": PULSE_AXIS}
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
        "peak_position_event",
        "mean_speed_error_late",
        "mean_speed_reference_late",
        "speed_swing_first",
        "speed_swing_second",
        "run_finite",
    )
    flags: ClassVar[tuple[str, ...]] = ("lost_lock", "lost_speed", "synchronous", "diverged")

    def build(self, names, points, first: int = 0):
        fam = self.family
        pts = np.asarray(points, dtype=float).reshape(len(points), len(names))
        assert list(names)[-1] == "pulse", "the long runs' last axis is the pulse's direction"
        # scenario first + i is point (first + i) // n_pulse of the points without the pulse axis (the grid's
        # last axis runs fastest): build each point once, with its own index's key, and repeat it per direction
        n_pulse = len(PULSES) if self.perturb > 0.0 else 1
        idx = (first + np.arange(len(pts))) // n_pulse
        rows = {int(j): tuple(pts[i, :-1]) for i, j in enumerate(idx)}
        base = build_signed(fam, list(names)[:-1], list(rows.values()), int(idx[0]))
        scs = jax.tree.map(lambda x: x[jnp.asarray(idx - idx[0])], base)
        width = _pulse_width(fam.drive, fam.machine, pts[:, 0])
        return speed_pulse(scs, float(fam.t_event), width, self.perturb * pts[:, -1])

    def system(self, design, scenario):
        ref = scenario.speed_ref
        t_end, width = ref.times[2], ref.times[2] - ref.times[1]
        k_early = jnp.round((t_end + EARLY_TC / PULSE_TC * width) / self.family.drive.ts)
        k_event = int(round(float(self.family.t_event) / self.family.drive.ts))
        return _Watched(self.family.system(design, scenario), k_early, self.k_late, k_event, self.k_mid)


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
    # the verdict's quantities (jaxobs.analysis.verdict.verdict_from), read from the same sums
    _var("peak_position_event", lambda sol, sc, ctx: _sums(sol)[0].max_e_event),
    _var("mean_speed_error_late", lambda sol, sc, ctx: _sums(sol)[0].sum_dw / _sums(sol)[0].n),
    _var("mean_speed_reference_late", lambda sol, sc, ctx: _sums(sol)[0].sum_ref / _sums(sol)[0].n),
    _var("speed_swing_first", lambda sol, sc, ctx: 0.5 * (_sums(sol)[0].hi1 - _sums(sol)[0].lo1)),
    _var("speed_swing_second", lambda sol, sc, ctx: 0.5 * (_sums(sol)[0].hi2 - _sums(sol)[0].lo2)),
    _var("run_finite", lambda sol, sc, ctx: _sums(sol)[0].finite),
)


def worse_pulse(runs: Any) -> Any:
    """Each point's worse long run of its two pulse directions (the study's last dim ``pulse``, :data:`PULSES`).

    A point holds only if it holds pulsed either way: near the voltage limit a pulse up can lose lock where one
    down holds, near zero speed a pulse down (towards zero) can run the machine away where one up holds.  The
    worse run is the one with the higher verdict code (:func:`jaxobs.analysis.verdict.verdict_from` on its running
    sums: the codes rise with severity), then the one not synchronous; on a tie the up pulse's (the first).  Its
    metrics are the point's; the flags are both runs': ``synchronous`` where both are, ``lost_lock`` and
    ``lost_speed`` where either is.

    Args:
        runs: The long runs' study (an ``xarray.Dataset`` with dims ``(design, ..., pulse)``).

    Returns:
        The same variables without the ``pulse`` dim, and ``pulse`` (±1: which direction's run each point reads).
    """
    import xarray as xr

    if "pulse" not in runs.dims:
        raise ValueError("worse_pulse: the long runs have no 'pulse' dim")
    state = verdict_from(
        runs["run_finite"].values > 0.5,
        np.degrees(runs["peak_position_event"].values),
        runs["mean_speed_error_late"].values,
        runs["mean_speed_reference_late"].values,
        runs["speed_swing_first"].values,
        runs["speed_swing_second"].values,
    ).state
    worse = 2 * np.asarray(state, dtype=int) + (runs["synchronous"].values == 0)
    rank = xr.DataArray(worse, dims=runs["run_finite"].dims)
    pick = rank.argmax("pulse")  # the first maximum: the up pulse on a tie
    out = runs.isel(pulse=pick)
    out["synchronous"] = runs["synchronous"].min("pulse")
    for k in ("lost_lock", "lost_speed"):
        out[k] = runs[k].max("pulse")
    sign = runs["pulse"].values[pick.values]
    return out.drop_vars("pulse").assign(pulse=(pick.dims, sign.astype(float)))


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

    drive: DualDrive  # the dual family runs the dual drive
    dual: DualPMSMParams | None = None

    def system(self, design: AbstractObserver, scenario: Scenario) -> DualClosedLoop:
        """The dual loop ``design`` closes on ``scenario``.

        Args:
            design: The drive observer (bound to the scenario's assumed machine).
            scenario: One scenario.

        Returns:
            The :class:`~jaxobs.drive.DualClosedLoop` on the dual machine ``dual``.
        """
        assert self.dual is not None, "_DualScenarios needs the dual machine"
        return DualClosedLoop(self.drive, bind_observer(design, scenario), scenario, self.dual)


def _family(machine: PMSMParams | DualPMSMParams, drive: Drive | DualDrive, **kw: Any) -> DriveScenarios:
    """The scenarios of ``drive`` on ``machine``: the single drive's, or the dual drive's (:class:`_DualScenarios`)."""
    if isinstance(drive, DualDrive):
        assert isinstance(machine, DualPMSMParams)
        return _DualScenarios(machine.per_set(), drive, dual=machine, **kw)
    assert isinstance(machine, PMSMParams)
    return DriveScenarios(machine, drive, **kw)


# the stability verdict's options, by method: its defaults (envelope), and what each accepts
STABILITY_METHODS = {
    "floquet": {
        **{"settle": 0.2, "window": 0.2, "max_window": 2.0, "tol": 0.0, "n_report": 3},
        **{"matrix": "auto", "block": 6, "iters": 5, "rtol": 1e-6},
    },
    "lyapunov": {"settle": 0.2, "warmup": 0.1, "window": 0.4, "n_dirs": 3, "tol": 0.0},
}


def _loop(
    drive: Drive | DualDrive, obs: AbstractObserver, scenario: Scenario, dual: DualPMSMParams | None
) -> ClosedLoop | DualClosedLoop:
    """The loop ``obs`` closes on ``scenario``: the family's system alone (the single drive's, or the dual one's
    on the true machine ``dual``)."""
    if dual is None:
        assert isinstance(drive, Drive)
        return ClosedLoop(drive, bind_observer(obs, scenario), scenario)
    assert isinstance(drive, DualDrive)
    return DualClosedLoop(drive, bind_observer(obs, scenario), scenario, dual)


def _stability_fields(
    drive: Drive | DualDrive, obs: AbstractObserver, scs: Scenario, method: str, kw: tuple,
    dual: DualPMSMParams | None = None,
) -> tuple[jax.Array, ...]:  # fmt: skip
    """The stability verdict (:func:`floquet` or :func:`lyapunov`) at every scenario of ``scs``, each closed by
    its own row of ``obs`` (observers of one class stacked along a leading axis, as long as the batch: several
    designs in one batch), one program per observer class and batch size (gains are traced); its fields as a
    plain tuple, which a kept program can return.  ``dual``: the dual machine a :class:`DualDrive` runs."""
    fn = floquet if method == "floquet" else lyapunov
    return tuple(jax.vmap(lambda o, sc: fn(_loop(drive, o, sc, dual), **dict(kw)))(obs, scs))


_stability_jit = kept_jit(_stability_fields)  # kept across processes where a folder is set


def _stability(
    drive: Drive | DualDrive, obs: AbstractObserver, scs: Scenario, method: str, kw: tuple,
    dual: DualPMSMParams | None = None,
) -> Stability:  # fmt: skip
    """:func:`_stability_fields` kept across processes, as a :class:`Stability`."""
    return Stability(*(_stability_jit(drive, obs, scs, method, kw) if dual is None else
                       _stability_jit(drive, obs, scs, method, kw, dual)))  # fmt: skip


def _speed_bandwidth(drive: Drive | DualDrive, machine: PMSMParams, speed_rpm: float) -> float:
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


def _axis(name: str, vals, lo: float, hi: float, unit: str, signed: bool = False) -> np.ndarray:
    arr = np.asarray(vals, dtype=float)
    mag = np.abs(arr) if signed else arr
    if arr.ndim != 1 or arr.size < 1 or not np.all(np.isfinite(arr)) or np.any(mag < lo) or np.any(mag > hi):
        within = f"[{lo:g}, {hi:g}] or [{-hi:g}, {-lo:g}]" if signed else f"[{lo:g}, {hi:g}]"
        raise ValueError(f"envelope: {name} must be a non-empty list of numbers in {within} {unit}")
    if np.any(np.diff(arr) <= 0):
        raise ValueError(f"envelope: {name} must be strictly increasing")
    return arr
