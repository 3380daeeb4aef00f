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
  synchronous at 410 r/min (−0.32 /s; 0.80 % against 1.07 %): tests/test_envelope.py.  **Both ways**: each point
  runs twice, pulsed up and pulsed down, and reads the worse run (``pulse`` says which): a point holds only if it
  holds either way.  Near the voltage limit a pulse up asks for voltage the inverter lacks (the traction IPMSM at
  3000 r/min, no load: up loses lock, down holds; docs/envelope.md), near zero a pulse down moves the point
  towards where a back-EMF observer sees nothing.  Two runs batched in the one ``vmap`` (the pulse's direction is
  the long runs' last axis, :data:`~jaxobs.analysis.envelope_runs.PULSES`), not one run pulsed up then down:
  each is then exactly the independent one-direction run a simulation pulsed that way is, with the same noise
  draw; a second pulse in the same run would start from the first one's remainder and, to let that decay
  (3/α) and still leave its early window, lengthen the horizon rule from 12/α to at least 16/α at the slow
  points, where the runs cost most; the two runs cost one more long run per point, the Floquet verdict (most
  of a map's time) unchanged, and one compiled program still.  The horizon spans at least
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
window's (:data:`~jaxobs.analysis.envelope_runs.SETTLE_GROWTH`: a settled point's windows both see the same
steady ripple, equal to within their sampling; a mode growing at λ shows as about e^(λ (steady_from − early
start)), 1.15 at 405 r/min above).
Where the verdict's linearized run left its operating point (``off_orbit``) the point is unstable and its rate
is a bound (``rate_bound``, :func:`jaxobs.analysis.stability.floquet`), not a margin ± a resolution.

Each point has **one verdict**, ``state`` (:data:`jaxobs.analysis.verdict.VERDICTS`): the long run judged by the
rule of :func:`jaxobs.analysis.verdict.verdict` (``run_state``, :func:`~jaxobs.analysis.verdict.verdict_from` on
the quantities the running sums keep: lock from the pulse on, the speed over the late window and the swing in its
two halves), except that a run that holds where the small-signal verdict (``linear_stable``) is resolved unstable
is unstable.  A point is **stable** when it is stable in the small and its run neither lost speed nor lock nor
diverged (never where the run loses speed), and it **holds** when it is stable, synchronous and its late peak
position error is within ``bound_deg``.

The speed axis may hold negative speeds (a drive runs both ways: :func:`~jaxobs.analysis.envelope_runs.build_signed`;
every window, settle and schedule follows |speed|); the runs measure through ``sensors`` (a drive file's
``[sensors]``; None: ideal); and ``reversal=`` adds each design's slowest held reversal (:func:`reversals`).

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
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from .. import SaveFinal
from ..drive import RPM, SETTLE_PERIODS, Drive, DualDrive, DualPMSMParams, PMSMParams, Scenario, Sensors
from ..observers import AbstractObserver
from ..observers.base import AbstractDriveObserver
from ..runtime.sharding import batch_mesh
from ..scenarios import Grid
from ..scenarios.families import DRIVE_STUDY_AXES, DriveScenarios
from ..studies.study import study
from .envelope_layout import ENVELOPE_VARIABLES, REVERSAL_VARIABLES, envelope_dataset, reversal_variables
from .envelope_runs import (
    EARLY_TC,
    HORIZON_MAX,
    HORIZON_TC,
    LONG_RUN_METRICS,
    MISMATCH_AXES,
    PULSE_TC,
    PULSES,
    STABILITY_METHODS,
    _axis,
    _dual_machine,
    _family,
    _long_run_flags,
    _LongRuns,
    _pulse_width,
    _speed_bandwidth,
    _stability,
    build_signed,
    default_loads,
    default_speeds,
    speed_limit_rpm,
    speed_pulse,
    worse_pulse,
)
from .stability import Stability
from .verdict import HOLDS, LIMIT_CYCLE, UNSTABLE, VERDICTS, held_rate, reversal_holds, verdict_from
from .worst import WORST_AXES, worst_case

if TYPE_CHECKING:
    import xarray as xr

__all__ = [
    "ENVELOPE_VARIABLES",
    "MISMATCH_AXES",
    "REVERSAL_OPTIONS",
    "REVERSAL_VARIABLES",
    "REVERSAL_T_START",
    "STABILITY_METHODS",
    "WORST_AXES",
    "envelope",
    "reversal_options",
    "reversals",
    "default_speeds",
    "speed_limit_rpm",
    "speed_pulse",
    "default_loads",
    "worst_case",
]


# ---- the reversal verdict: each design's slowest held ±speed reversal, with and without load ----------------------
# (verdict.held_rate over verdict.reversal_holds on the envelope's drive and sensors).  A map says where a design
# holds at constant speed; a drive also runs both ways, and the way through zero is where a back-EMF observer has
# nothing to see (docs/through-zero.md).  It costs simulations (each probe one batched run as long as the slowest
# ramp), so envelope() runs it only when asked (reversal=; jaxobs envelope --reversal).

# the options of the reversal verdict (envelope's ``reversal=``), each with what it is
REVERSAL_OPTIONS = {
    "speed_rpm": "the reversal's speed, r/min: +n to -n (default half the rated speed)",
    "loads_nm": "the constant loads, N·m, one search each (default 0 and half the rated torque)",
    "rates": "(slow, fast) ramp rates, r/min per second (default 2n/10 and 2n/0.1: a reversal in 10 s to 0.1 s)",
    "resolution": "the search's relative resolution (default 0.1)",
    "probes": "rates per batched probe inside the bracket (default 3)",
    "settle": "s after the slowest ramp's end (default max(1 s, 12/α), α the speed loop's at speed_rpm)",
}
REVERSAL_T_START = 0.2  # s: the ramp's start (the observer settled before t = 0, Drive.settled_for)


def _positive(name: str, v: Any, hi: float = math.inf) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"envelope: reversal.{name} must be a number, got {v!r}") from None
    if not (math.isfinite(x) and 0.0 < x <= hi):
        raise ValueError(f"envelope: reversal.{name} must be in (0, {hi:.6g}], got {v!r}")
    return x


def reversal_options(
    reversal: Mapping[str, Any], machine: PMSMParams, drive: Drive | DualDrive, max_speed_rpm: float | None = None
) -> dict[str, Any]:
    """The reversal verdict's options (:data:`REVERSAL_OPTIONS`) with their defaults filled in, checked.

    Args:
        reversal: The options given (any subset of :data:`REVERSAL_OPTIONS`).
        machine: The machine (its rated speed and torque set the defaults).
        drive: The envelope's drive (its speed limit bounds ``speed_rpm``; a dual drive is refused).
        max_speed_rpm: The drive file's mechanical limit (None: the rule's default).

    Returns:
        ``{speed_rpm, loads_nm (a tuple), rates (lo, hi), resolution, probes, settle}``.

    Raises:
        ValueError: An unknown option, a value out of its range (naming ``reversal.<option>`` and the range), or
            a dual drive.
    """
    if isinstance(drive, DualDrive):
        raise ValueError("envelope: reversal runs a single three-phase drive (reversal_holds), not a DualDrive")
    if not isinstance(reversal, Mapping):
        raise ValueError(f"envelope: reversal must be a mapping of options or None, got {type(reversal).__name__}")
    unknown = sorted(set(reversal) - set(REVERSAL_OPTIONS))
    if unknown:
        raise ValueError(f"envelope: reversal has unknown keys {unknown}; allowed: {', '.join(REVERSAL_OPTIONS)}")
    top = speed_limit_rpm(machine, drive, max_speed_rpm)
    n = _positive("speed_rpm", reversal.get("speed_rpm", 0.5 * float(machine.n_rated)), top)
    lo_l, hi_l = DRIVE_STUDY_AXES["load_nm"].range
    loads = np.atleast_1d(np.asarray(reversal.get("loads_nm", (0.0, 0.5 * float(machine.T_rated))), dtype=float))
    if loads.ndim != 1 or loads.size < 1 or not np.all(np.isfinite(loads) & (loads >= lo_l) & (loads <= hi_l)):
        raise ValueError(f"envelope: reversal.loads_nm must be a non-empty list of numbers in [{lo_l:g}, {hi_l:g}]")
    rates = reversal.get("rates", (2.0 * n / 10.0, 2.0 * n / 0.1))
    if not (isinstance(rates, (tuple, list)) and len(rates) == 2):
        raise ValueError(f"envelope: reversal.rates must be (slow, fast) r/min per second, got {rates!r}")
    lo, hi = _positive("rates", rates[0]), _positive("rates", rates[1])
    if not lo < hi:
        raise ValueError(f"envelope: reversal.rates must be (slow, fast) with slow < fast, got {rates!r}")
    alpha = _speed_bandwidth(drive, machine, n)
    settle = _positive("settle", reversal.get("settle", max(1.0, 12.0 / alpha)), 60.0)
    if REVERSAL_T_START + 2.0 * n / lo + settle > 120.0:
        raise ValueError(
            f"envelope: reversal.rates' slow end must leave the runs within 120 s: a reversal of ±{n:g} r/min at "
            f"{lo:g} r/min per second lasts {2.0 * n / lo:.4g} s"
        )
    probes = reversal.get("probes", 3)
    if isinstance(probes, bool) or not isinstance(probes, int) or not 1 <= probes <= 64:
        raise ValueError(f"envelope: reversal.probes must be an integer in [1, 64], got {probes!r}")
    return {
        "speed_rpm": n,
        "loads_nm": tuple(float(x) for x in loads),
        "rates": (lo, hi),
        "resolution": _positive("resolution", reversal.get("resolution", 0.1), 10.0),
        "probes": probes,
        "settle": settle,
    }


def reversals(
    designs: Mapping[str, AbstractObserver],
    machine: PMSMParams,
    drive: Drive,
    sensors: Sensors | None,
    opts: Mapping[str, Any],
) -> dict[str, np.ndarray]:
    """Each design's slowest held reversal at each load (:func:`jaxobs.analysis.verdict.held_rate`).

    Every run is :func:`jaxobs.drive.reversal` from +``speed_rpm`` to −``speed_rpm`` at the probed rate from
    :data:`REVERSAL_T_START`, on ``drive`` settled for ``speed_rpm`` (:meth:`Drive.settled_for`) and measured through
    ``sensors``; one horizon for every probe (the slowest ramp's end plus ``settle``), so a design class compiles
    one program per batch size.

    Args:
        designs: name -> drive observer (unbound).
        machine: The machine (true and assumed alike).
        drive: The envelope's sensorless drive, before its settle was lengthened for the map.
        sensors: The sensors (None: ideal).
        opts: :func:`reversal_options`'s output.

    Returns:
        Arrays shaped (design, load): ``rate`` (the slowest held, r/min per second; NaN where none held),
        ``other`` (the nearest probed rate that fails; NaN where every probed rate held: ``rate`` is then the
        range's slow end, a bound), ``resolution``, ``monotone`` (bool), ``probes`` and ``states`` (the probed
        verdicts, "rate:state" joined by spaces, one string per search).
    """
    n, (lo, hi), settle = float(opts["speed_rpm"]), opts["rates"], float(opts["settle"])
    rev_drive = drive.settled_for(float(machine.p) * n * RPM)
    base = Scenario(machine, sensors=sensors)
    horizon = REVERSAL_T_START + 2.0 * n / lo + settle
    loads = opts["loads_nm"]
    shape = (len(designs), len(loads))
    out = {k: np.full(shape, np.nan) for k in ("rate", "other", "resolution")}
    out["monotone"], out["probes"] = np.zeros(shape, bool), np.zeros(shape, np.int32)
    out["states"] = np.empty(shape, dtype=object)
    for i, (name, obs) in enumerate(designs.items()):
        if not isinstance(obs, AbstractDriveObserver):  # the map's own check has run: a drive observer each
            raise ValueError(f"envelope reversal: design {name!r} is not a drive observer ({type(obs).__name__})")
        for j, load in enumerate(loads):
            states_at = reversal_holds(
                rev_drive, obs, base, n, load_nm=load, t_start=REVERSAL_T_START, settle=settle, horizon=horizon
            )
            r = held_rate(lo, hi, states_at=states_at, resolution=opts["resolution"], probes=opts["probes"])
            out["rate"][i, j], out["other"][i, j], out["resolution"][i, j] = r.rate, r.other, r.resolution
            out["monotone"][i, j], out["probes"][i, j] = r.monotone, r.probes
            probed = zip(r.rates, r.states)
            out["states"][i, j] = " ".join(f"{x:.6g}:{VERDICTS[s].replace(' ', '_')}" for x, s in probed)
    return out


def _check_designs_and_drive(designs: Mapping[str, Any], drive: Drive | DualDrive) -> None:
    """Refuse no design, or a drive that is not sensorless or not started steady."""
    if not designs:
        raise ValueError("envelope: at least one design is required")
    if not drive.sensorless or drive.startup is not None:
        raise ValueError("envelope: drive must be sensorless and start steady (Drive(sensorless=True, startup=None))")


def _plane(
    machine: PMSMParams,
    drive: Drive | DualDrive,
    speeds_rpm: ArrayLike | Sequence[float] | None,
    loads_nm: ArrayLike | Sequence[float] | None,
    mismatch: tuple | None,
    max_speed_rpm: float | None,
) -> dict[str, np.ndarray]:
    """The envelope's axes, checked: speed (within the drive's limits), load and the optional mismatch axis."""
    # the drive's limit with its inverter and field weakening (the dual drive's per phase: the same bound)
    n_max = speed_limit_rpm(machine, drive, max_speed_rpm)
    # the lowest speed whose steady start (Drive.settled_for) fits the 60 s settle limit: SETTLE_PERIODS / p r/min
    n_min = max(1.0, SETTLE_PERIODS / machine.p)
    speeds = default_speeds(machine, drive=drive, max_speed_rpm=max_speed_rpm) if speeds_rpm is None else speeds_rpm
    speeds = _axis("speeds_rpm", speeds, n_min, n_max, "r/min", signed=True)  # either direction, |speed| bounded
    lo_l, hi_l = DRIVE_STUDY_AXES["load_nm"].range
    loads = _axis("loads_nm", default_loads(machine) if loads_nm is None else loads_nm, lo_l, hi_l, "N·m")
    return {"speed_rpm": speeds, "load_nm": loads}


def _timing(
    drive: Drive | DualDrive,
    machine: PMSMParams,
    speeds: np.ndarray,
    horizon: float,
    steady_from: float | None,
    t_perturb: float,
) -> tuple[float, float]:
    """The long run's horizon (stretched to :data:`HORIZON_TC` time constants of the slowest speed loop, at most
    :data:`HORIZON_MAX`) and the late window's start, checked."""
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
    return horizon, steady_from


def _mismatch_axis(axes: dict[str, np.ndarray], mismatch: tuple | None) -> None:
    """Add the mismatch axis ``(axis, values)`` to ``axes``, checked."""
    if mismatch is None:
        return
    if not (isinstance(mismatch, tuple) and len(mismatch) == 2 and mismatch[0] in MISMATCH_AXES):
        raise ValueError(f"envelope: mismatch must be (axis, values) with axis one of {', '.join(MISMATCH_AXES)}")
    m_lo, m_hi = DRIVE_STUDY_AXES[mismatch[0]].range
    axes[mismatch[0]] = _axis(f"mismatch {mismatch[0]}", mismatch[1], m_lo, m_hi, "(relative)")


def _stability_options(stability: Mapping[str, Any] | None) -> tuple[str, dict[str, Any]]:
    """The stability verdict's method and its options (the method's defaults updated), checked."""
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
    return method, kw


def _settle_and_windows(
    drive: Drive | DualDrive, machine: PMSMParams, speeds: np.ndarray, method: str, kw: dict[str, Any]
) -> Drive | DualDrive:
    """The drive settled for the lowest holdable speed, and ``kw``'s windows (in place) spanning the slowest
    speed loop (Lyapunov) or one electrical period of the lowest speed (Floquet)."""
    # A steady start at every point the loop can hold: the observer settles over SETTLE_PERIODS electrical periods
    # (Drive.settled_for) of the lowest speed whose speed loop is slow enough for a speed estimate scaling with
    # ω_e (a flux observer's FLL) to close it stably, ω_e ≥ 4 α (the linear boundary is 4.2-5.4 α,
    # docs/stability.md).  Below that speed the loop cannot hold with such an observer whatever its start, and
    # settling there would cost more than the whole envelope (docs/performance.md).
    # (by |speed|: the axis may hold negative speeds, each direction's periods and speed loop as the other's)
    mags = sorted({abs(float(s)) for s in speeds})
    w_es = [machine.p * s * 2.0 * math.pi / 60.0 for s in mags]
    holdable = [w for s, w in zip(mags, w_es) if w >= 4.0 * _speed_bandwidth(drive, machine, s)]
    drive = drive.settled_for(holdable[0] if holdable else w_es[-1])
    # The Lyapunov run spans the slowest speed loop: its window at least 12/α and its warm-up 1/α (α at the lowest
    # speed; a window whose thirds are shorter than the slowest pair's period sees its wobble, not its decay:
    # docs/stability.md, docs/performance.md).
    #
    # The Floquet verdict needs none of that: each point's window is its own whole electrical periods (floquet:
    # they make the transition matrix a monodromy matrix), so the longest must hold one period of the lowest
    # speed (2 % more: the speed's move to whole speed-loop periods), and the answer is exact however slow the
    # mode.  Its cost follows each point's period: the points are batched by speed (_verdicts).
    if method == "lyapunov":
        alpha = _speed_bandwidth(drive, machine, mags[0])
        kw["window"] = max(float(kw["window"]), 12.0 / alpha)
        kw["warmup"] = max(float(kw["warmup"]), 1.0 / alpha)
    else:
        kw["max_window"] = max(float(kw["max_window"]), float(kw["window"]), 1.02 * 2.0 * math.pi / w_es[0])
    return drive


def _verdicts(
    designs: Mapping[str, Any],
    drive: Drive | DualDrive,
    scs: Any,
    points: Sequence[Sequence[float]],
    method: str,
    kwt: tuple,
    dual: DualPMSMParams | None,
) -> dict[str, Stability]:
    """The stability verdict of every design at every point of ``scs``, per design (host arrays)."""
    # one batch per speed (every load and mismatch at it, the same shape: one program), so that a batch runs
    # as long as its own points' windows (floquet's while_loop), not the lowest speed's
    spd = np.asarray(points)[:, 0]
    groups = [np.flatnonzero(spd == v) for v in np.unique(spd)]
    if method != "floquet" or len({len(g) for g in groups}) != 1:
        groups = [np.arange(len(spd))]

    # the designs of one observer class (the same tree structure: only the gains differ) share each batch,
    # stacked: one call per speed for all of them instead of one per design (docs/performance.md)
    classes: dict = {}
    for d, obs in designs.items():
        classes.setdefault(jax.tree.structure(obs), []).append(d)

    def of_class(names_: list[str]) -> dict[str, Stability]:
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
        stab.update(of_class(names_))
    return stab


def _results(
    stab: Mapping[str, Stability], runs: xr.Dataset, dnames: list[str], shape: tuple[int, ...], bound_deg: float
) -> dict[str, np.ndarray]:
    """The per-point variables of :data:`ENVELOPE_VARIABLES` from the verdicts and the long runs."""

    def grid(get: Callable[[str], ArrayLike]) -> np.ndarray:
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
    res["pulse"] = runs["pulse"].values
    for m in LONG_RUN_METRICS:
        res[m.name] = runs[m.name].values
    lost = res["lost_lock"].astype(bool)
    for k in ("peak_position_late", "mean_position_late", "ripple_position_late"):
        res[k] = np.where(lost, np.nan, res[k])  # a lost point has no steady error to speak of
    _states(res)
    err_ok = np.nan_to_num(np.degrees(res["peak_position_late"]), nan=np.inf) <= bound_deg
    res["holds"] = res["stable"].astype(bool) & res["synchronous"].astype(bool) & err_ok
    return res


def _states(res: dict[str, np.ndarray]) -> None:
    """``run_state``, ``state``, ``linear_stable`` and ``stable`` (in place) from the long runs' window quantities and
    the small-signal verdict.

    The long run is judged by :func:`~jaxobs.analysis.verdict.verdict_from`, the rule of
    :func:`~jaxobs.analysis.verdict.verdict` (lock from the pulse on, the speed over the late window and its two
    halves).  The point's ``state`` is that verdict, except that a run that holds where the small-signal verdict
    is resolved unstable (or left its orbit) is ``unstable``: a growth slower than the window resolves
    (verdict.py's module doc says the Floquet margin is the tool for it).  ``stable`` is the small-signal verdict
    and a run that neither lost speed nor lock nor diverged: never 1 where the run loses speed.
    """
    run = verdict_from(
        res["run_finite"] > 0.5,
        np.degrees(res["peak_position_event"]),
        res["mean_speed_error_late"],
        res["mean_speed_reference_late"],
        res["speed_swing_first"],
        res["speed_swing_second"],
    )
    run_state = np.asarray(run.state, dtype=np.int8)
    linear = res["stable"].astype(bool)
    lin_unstable = ~linear & ~res["marginal"].astype(bool)  # resolved unstable, or off its orbit
    res["run_state"] = run_state
    res["state"] = np.where((run_state == HOLDS) & lin_unstable, UNSTABLE, run_state).astype(np.int8)
    res["linear_stable"] = linear
    res["stable"] = linear & ((run_state == HOLDS) | (run_state == LIMIT_CYCLE))


def _from_family(
    family: DriveScenarios | None,
    machine: PMSMParams | DualPMSMParams | None,
    drive: Drive | DualDrive | None,
    sensors: Sensors | None,
    seed: int,
) -> tuple[PMSMParams | DualPMSMParams, Drive | DualDrive, Sensors | None, int]:
    """The machine, drive, sensors and seed a map runs: its family's, or those given (:func:`envelope`)."""
    if family is None:
        if machine is None or drive is None:
            raise ValueError("envelope: give family (a DriveScenarios), or machine and drive")
        return machine, drive, sensors, seed
    if not isinstance(family, DriveScenarios):
        raise ValueError(f"envelope: family must be DriveScenarios, got {type(family).__name__}")
    if machine is not None or drive is not None or sensors is not None:
        raise ValueError("envelope: give family, or machine, drive and sensors, not both (the family holds its own)")
    return family.machine, family.drive, family.sensors, family.seed


def envelope(
    designs: Mapping[str, AbstractObserver],
    *,
    machine: PMSMParams | DualPMSMParams | None = None,
    drive: Drive | DualDrive | None = None,
    family: DriveScenarios | None = None,
    speeds_rpm: ArrayLike | Sequence[float] | None = None,
    loads_nm: ArrayLike | Sequence[float] | None = None,
    mismatch: tuple[str, ArrayLike] | None = None,
    horizon: float = 2.0,
    steady_from: float | None = None,
    perturb: float = 0.02,
    t_perturb: float = 0.05,
    bound_deg: float = 30.0,
    speed_tol: float = 0.01,
    stability: Mapping[str, Any] | None = None,
    seed: int = 0,
    chunk_size: int = 256,
    progress: Any = None,
    max_speed_rpm: float | None = None,
    sensors: Sensors | None = None,
    reversal: Mapping[str, Any] | None = None,
) -> xr.Dataset:
    """The operating envelope of every design (name -> drive observer closing ``drive``'s loop sensorless).

    The long runs' and the verdicts' traced programs are kept across processes where a folder is set
    (:func:`jaxobs.kept_jit`).

    Args:
        designs: name -> drive observer closing ``drive``'s loop sensorless.
        machine: the machine (a :class:`~jaxobs.drive.DualPMSMParams` for a :class:`~jaxobs.drive.DualDrive`);
            with ``drive``, or ``family``.
        drive: a sensorless drive started steady.
        family: the drive's scenarios (:class:`~jaxobs.scenarios.families.DriveScenarios`, as a drive study takes
            them): its machine, drive, sensors and seed, in place of ``machine``, ``drive``, ``sensors`` and
            ``seed``.
        speeds_rpm: speeds, r/min, increasing, either sign (|speed| within the drive's limits; default
            :func:`default_speeds`, positive).
        loads_nm: load torques, N·m (default :func:`default_loads`).
        mismatch: ``(axis, values)`` with axis one of :data:`MISMATCH_AXES` (relative, 1), a third dim.
        horizon: s, in [0.5, 20]: the long run's least horizon, stretched to :data:`HORIZON_TC` time constants of
            the slowest speed loop (module doc; at most :data:`HORIZON_MAX`).
        steady_from: s, the late window's start (default horizon/2, after the slowest point's early window opens).
        perturb: relative, in [0, 0.2]: the speed-reference pulse's height; each point runs pulsed up and down by
            it and reads the worse run (module doc; one run where it is 0).
        t_perturb: s, the pulse's start; it lasts :data:`PULSE_TC` / α at each point.
        bound_deg: deg electrical: the late peak position error a holding point may have.
        speed_tol: relative: the late peak speed deviation a synchronous point may have.
        stability: ``method`` ("floquet", the default, or "lyapunov") and that function's keyword arguments
            (:func:`~jaxobs.analysis.stability.floquet`: settle, window, max_window, tol, n_report,
            matrix, block, iters, rtol;
            :func:`~jaxobs.analysis.stability.lyapunov`: settle, warmup, window, n_dirs, tol).
        seed: the scenarios' seed.
        chunk_size: the long runs' batch size.
        progress: as in :func:`jaxobs.runtime.runner.run_scenarios`.
        max_speed_rpm: the drive file's mechanical limit (``[machine] max_speed_rpm``; :func:`speed_limit_rpm`),
            None: the rule's default.
        sensors: the drive's sensors (a drive file's ``[sensors]``: :attr:`jaxobs.drive.DriveFile.sensors`, its
            ADC's quantization as noise), which every run measures through (the long runs, the stability
            verdict's linearized run and the reversals); None: ideal.
        reversal: None (the default: not run), or the options of each design's slowest held reversal
            (:data:`REVERSAL_OPTIONS`; ``{}`` takes every default): ``speed_rpm`` (the reversal's ±speed, default
            half the rated speed), ``loads_nm`` (default 0 and half the rated torque), ``rates`` ((slow, fast)
            ramp rates, r/min per second; default a reversal in 10 s to one in 0.1 s), ``resolution`` (relative,
            default 0.1), ``probes`` (default 3) and ``settle`` (s after the slowest ramp; default the larger of
            1 s and 12/α of the speed loop at ``speed_rpm``).  Each is
            :func:`jaxobs.analysis.verdict.held_rate` over :func:`~jaxobs.analysis.verdict.reversal_holds` on
            the same drive and sensors (a :class:`~jaxobs.drive.DualDrive` has none).

    Returns:
        An ``xarray.Dataset`` with dims ``("design", "speed_rpm", "load_nm"[, axis])`` and the variables of
        :data:`ENVELOPE_VARIABLES` (booleans stored as int8 0/1; ``state`` and ``run_state`` codes of
        :data:`jaxobs.analysis.verdict.VERDICTS`); its ``horizon`` and ``steady_from`` attributes are those that
        ran.  With ``reversal``, the variables of :data:`REVERSAL_VARIABLES` over ``("design",
        "reversal_load_nm")``.

    Raises:
        ValueError: no design, a drive that is not sensorless or not started steady, or an argument out of its
            range (the message names it and the range); ``reversal`` on a dual drive; ``family`` with
            ``machine``, ``drive`` or ``sensors``, or neither.
    """
    machine, drive, sensors, seed = _from_family(family, machine, drive, sensors, seed)
    _check_designs_and_drive(designs, drive)
    dual = _dual_machine(machine, drive, mismatch)
    if dual is not None:
        machine = dual.m  # the whole machine's ratings, ψf and p set the axes
    assert isinstance(machine, PMSMParams)  # a DualPMSMParams needs a DualDrive (_dual_machine)
    axes = _plane(machine, drive, speeds_rpm, loads_nm, mismatch, max_speed_rpm)
    speeds = axes["speed_rpm"]
    horizon, steady_from = _timing(drive, machine, speeds, horizon, steady_from, t_perturb)
    for name, v, lo, hi in (("perturb", perturb, 0.0, 0.2), ("bound_deg", bound_deg, 0.1, 90.0),
                            ("speed_tol", speed_tol, 1e-4, 1.0)):  # fmt: skip
        if not (lo <= float(v) <= hi):
            raise ValueError(f"envelope: {name} must be in [{lo:g}, {hi:g}], got {v!r}")
    _mismatch_axis(axes, mismatch)
    method, kw = _stability_options(stability)
    rev = None if reversal is None else reversal_options(reversal, machine, drive, max_speed_rpm)
    unsettled = drive
    drive = _settle_and_windows(drive, machine, speeds, method, kw)
    sampler = Grid(axes)
    names, points = sampler.names, sampler.points()

    # the long runs, a study: each point's speed reference pulses by ±perturb × its speed at t_perturb; nothing
    # stored per sample (SaveFinal), the wrapped loop's running sums read from its final state
    ts = drive.ts
    family = _family(machine if dual is None else dual, drive, t_event=t_perturb, seed=seed, sensors=sensors)
    k_late, n_steps = int(round(steady_from / ts)), int(round(float(horizon) / ts))
    long = _LongRuns(family, float(perturb), k_late, (k_late + n_steps) // 2)
    # each point pulsed up and down in the one batch (the pulse the grid's last axis), the worse run its verdict
    runs = study(
        dict(designs),
        long,
        Grid({**axes, "pulse": list(PULSES if perturb > 0.0 else PULSES[:1])}),
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
    runs = worse_pulse(runs)
    # the stability margins: constant profiles (no step), one jit(vmap) per observer class
    scs = build_signed(_family(machine if dual is None else dual, drive, seed=seed, sensors=sensors), names, points)
    stab = _verdicts(designs, drive, scs, points, method, tuple(sorted(kw.items())), dual)
    dnames = list(designs)
    res = _results(stab, runs, dnames, (len(dnames), *(len(axes[n]) for n in names)), bound_deg)
    attrs = dict(
        horizon=float(horizon),
        steady_from=steady_from,
        perturb=float(perturb),
        t_perturb=float(t_perturb),
        pulse_time_constants=PULSE_TC,
        bound_deg=float(bound_deg),
        speed_tol=float(speed_tol),
        seed=seed,
        **{f"stability_{k}": v if isinstance(v, str) else float(v) for k, v in kw.items()},
        stability_method=method,
        sensors="ideal" if sensors is None else "given",
    )
    if sensors is not None:  # what the runs measured through (Sensors' fields; the noise levels, A and V)
        attrs: dict[str, object] = dict(attrs)
        attrs.update(
            sensors_i_noise=float(sensors.i_noise),
            sensors_u_noise=float(sensors.u_noise),
            sensors_i_offset=np.asarray(sensors.i_offset, dtype=float),
            sensors_u_offset=np.asarray(sensors.u_offset, dtype=float),
            sensors_i_gain_error=np.asarray(sensors.i_gain, dtype=float) - 1.0,
        )
    ds = envelope_dataset(res, {d: designs[d] for d in dnames}, axes, names, attrs, machine, drive, dual)
    if rev is not None:
        assert isinstance(unsettled, Drive)  # reversal_options refuses a dual drive
        ds = ds.assign(reversal_variables(reversals(designs, machine, unsettled, sensors, rev), dnames, rev))
        ds.attrs.update({f"reversal_{k}": v for k, v in rev.items() if k != "loads_nm"})
    return ds
