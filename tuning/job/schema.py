"""A job file checked in full (every error names its field) and parsed into a :class:`~jaxobs_tuning.job.spec.Job`."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path

from jaxobs.io.provenance import sha256
from jaxobs.metrics import canonical
from jaxobs.observers import AbstractDriveObserver, AbstractLESO, gain_fields
from jaxobs.observers.speed import MECHANICAL_GAINS, SPEED_KINDS, alpha_o_out_of_range, mechanical_gains
from jaxobs.scenarios.families import FAMILIES, GridSignals
from jaxobs.studies.registry import REGISTRY, canonical_key

from .. import strategies
from ..aggregations import AbstractAggregation
from ..objective import DRIVE_METRICS, TERM_METRICS, Term
from ..params import GainSpec
from ..solvers import AbstractSolver
from .components import COMPONENTS, W_N, ComponentInfo
from .drive import check_drive_speeds, check_standstill, inline_drive, parse_drive
from .fields import (
    MAX_SCENARIOS,
    MAX_SOLVER_STEPS,
    MAX_STEPS,
    JobError,
    axes_field,
    cap,
    get_field,
    no_unknown,
    show,
)
from .recordings import check_recording_job, parse_recording_scenarios
from .spec import DriveSpec, Job, ScenarioSpec
from .toml import read_toml
from .verify import parse_envelope

# the scenario axes and their ranges: each family's (jaxobs.scenarios.families); a job's signal names its family
AXIS_RANGES = {name: family.axes for name, family in FAMILIES.items()}


def freq_step_range(freq_n: float, ts: float) -> tuple[float, float]:
    """The allowed ``freq_step`` on a grid (:meth:`jaxobs.scenarios.families.GridSignals.limits`).

    Args:
        freq_n: The grid's nominal frequency, Hz.
        ts: The sample time, s.

    Returns:
        ``(low, high)``, Hz.
    """
    return GridSignals.limits(freq_n, ts)["freq_step"]


def available_memory() -> int:
    """Bytes of memory available now (MemAvailable on Linux, else the physical memory; 16 GiB if unknown)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return 16 * 2**30


def check_size(spec: ScenarioSpec, where: str, ts: float, extra_s: float = 0.0) -> None:
    """Time steps, scenario count and the memory a simulation of the batch needs, at --check time.

    Args:
        spec: The scenario set.
        where: The table's name in errors.
        ts: The component's sample time, s.
        extra_s: Simulated time beyond the horizon, s (a drive's settling phase).

    Raises:
        JobError: Too many scenarios or steps, a steady window of fewer than 10 samples, or more memory than
            is available, naming the field.
    """
    n_scen = spec.sample or math.prod(len(v) for v in spec.axes.values())  # a recording: one per file
    if n_scen > MAX_SCENARIOS:
        raise JobError(f"{where}.grid", f"{n_scen} scenarios (the product of the axes' lengths) > {MAX_SCENARIOS}")
    steps = (spec.horizon + extra_s) / ts
    if spec.horizon < ts:
        raise JobError(f"{where}.horizon", f"shorter than one sample (ts = {ts:g} s), got {spec.horizon:g} s")
    if steps > MAX_STEPS:
        raise JobError(f"{where}.horizon", f"{steps:.3g} time steps of {ts:g} s > {MAX_STEPS:g}: too long")
    if (spec.horizon - spec.steady_from) / ts < 10:
        raise JobError(
            f"{where}.steady_from",
            f"the steady window [{spec.steady_from:g}, {spec.horizon:g}) s holds fewer than 10 samples of {ts:g} s",
        )
    need = steps * n_scen * spec.family.bytes_per_step
    have = available_memory()
    if need > have:
        raise JobError(
            f"{where}.horizon",
            f"{n_scen} scenarios x {steps:.3g} steps need about {need / 2**30:.3g} GiB, "
            f"{have / 2**30:.3g} GiB available: shorten the horizon or use fewer scenarios",
        )


def parse_scenarios(
    tab: dict, where: str, signals: tuple, seed: int, freq_n: float, ts: float, base: Path | None = None
) -> ScenarioSpec:
    """A job's ``[scenarios]`` or ``[holdout]`` table.

    Args:
        tab: The table.
        where: Its name in errors.
        signals: The component's scenario signals (its default first).
        seed: The job's seed (the default of the table's).
        freq_n: The component's nominal frequency, Hz.
        ts: The component's sample time, s.
        base: The job file's folder (recordings).

    Returns:
        The :class:`ScenarioSpec`.

    Raises:
        JobError: A field out of its range, naming it.
    """
    tab = get_field({"s": tab}, "s", where, dict, required=True)
    no_unknown(tab, ("signal", "t_event", "horizon", "steady_from", "grid", "sample", "seed", "recording"), where)
    signal = get_field(tab, "signal", f"{where}.signal", str, signals[0])
    if signal not in FAMILIES:
        raise JobError(f"{where}.signal", f"must be 'grid', 'emf' or 'drive', got {show(signal)}")
    if signal not in signals:
        need = " or ".join(f"'{x}'" for x in signals)
        raise JobError(f"{where}.signal", f"the component needs {need} signals, got {show(signal)}")
    family = FAMILIES[signal]  # the one place a job's signal name becomes its family
    t_event = get_field(tab, "t_event", f"{where}.t_event", float, 0.1)
    horizon = get_field(tab, "horizon", f"{where}.horizon", float, 0.4)
    if t_event < 0:
        raise JobError(f"{where}.t_event", f"must be >= 0 s, got {t_event}")
    if horizon <= t_event and "horizon" not in tab:  # the user moved the event, not the default horizon: name it
        raise JobError(
            f"{where}.t_event",
            f"must be in [0, horizon) = [0, {horizon:g}) s (the default horizon; set {where}.horizon to run "
            f"longer), got {t_event:g}",
        )
    if horizon <= t_event:
        raise JobError(f"{where}.horizon", f"must exceed t_event ({t_event:g} s), got {horizon:g}")
    if horizon > MAX_STEPS * ts:
        raise JobError(f"{where}.horizon", f"{horizon:g} s is more than {MAX_STEPS:g} time steps of {ts:g} s")
    steady = get_field(tab, "steady_from", f"{where}.steady_from", float, t_event + 0.75 * (horizon - t_event))
    if not (0 <= steady < horizon):
        raise JobError(f"{where}.steady_from", f"must be in [0, horizon), got {steady:g}")
    if "recording" in tab:
        return parse_recording_scenarios(tab, where, family, t_event, horizon, steady, seed, ts, base)
    grid = get_field(tab, "grid", f"{where}.grid", dict, required=True)
    # freq_step is tied to the nominal frequency and the sample rate, speed_hz to the sample rate
    axes = axes_field(grid, family, f"{where}.grid", family.limits(freq_n, ts))
    sample = get_field(tab, "sample", f"{where}.sample", int, 0)
    if not 0 <= sample <= MAX_SCENARIOS:
        raise JobError(f"{where}.sample", f"must be in [0, {MAX_SCENARIOS}] (0: the full grid), got {show(sample)}")
    sseed = get_field(tab, "seed", f"{where}.seed", int, seed)
    if not 0 <= sseed < 2**32:
        raise JobError(f"{where}.seed", f"must be in [0, 2^32), got {show(sseed)}")
    return ScenarioSpec(signal, t_event, horizon, steady, axes, sample, sseed)


def parse_observer_speed(raw: dict, info: ComponentInfo) -> dict:
    """A job's ``[observer.speed]``: how a LESO, a PLL-type flux observer or the reduced-order flux observer
    extracts speed and position (jaxobs.observers.speed).

    ``kind = "pll"`` (the default: the observer's PLL on its ``kp_pll``, ``ki_pll``) or ``"mechanical"`` (a
    mechanical-model speed observer with its three poles at −``alpha_o`` rad/s, its Ĵ, B̂ and p those of the
    drive's assumed machine); ``zero_fade`` (rad/s, ≥ 0) selects the phase detector's fade through zero speed
    (a LESO's; 0, the default: the sign detector).  The values are a record and a number, so a result file keeps them.

    Args:
        raw: The parsed job file.
        info: The component's :class:`~jaxobs_tuning.job.components.ComponentInfo`.

    Returns:
        The constructor keywords to add (``speed``, ``zero_fade``); empty without the table.

    Raises:
        JobError: An unknown key or kind, a value out of its range, or a component without a speed estimator.
    """
    obs_t = get_field(raw, "observer", "observer", dict, {})
    no_unknown(obs_t, ("speed",), "observer")
    if "speed" not in obs_t:
        return {}
    sp = get_field(obs_t, "speed", "observer.speed", dict, required=True)
    no_unknown(sp, ("kind", "alpha_o", "zero_fade"), "observer.speed")
    if not (issubclass(info.ctor, AbstractDriveObserver) and info.ctor.takes_speed_estimator):
        raise JobError(
            "observer.speed",
            "only the LESOs, the PLL-type flux observers (LPFFlux) and the reduced-order flux observer take a "
            f"speed estimator, not {info.entry.name}",
        )
    kind = get_field(sp, "kind", "observer.speed.kind", str, "pll")
    if kind not in SPEED_KINDS:
        raise JobError("observer.speed.kind", f"must be one of {', '.join(SPEED_KINDS)}, got {show(kind)}")
    out = {}
    if kind == "mechanical":
        alpha = get_field(sp, "alpha_o", "observer.speed.alpha_o", float, required=True)
        if alpha <= 0:
            raise JobError("observer.speed.alpha_o", f"must be > 0 rad/s, got {show(alpha)}")
        out["speed"] = {"kind": kind, "alpha_o": alpha}
    elif "alpha_o" in sp:
        raise JobError("observer.speed.alpha_o", 'applies to kind = "mechanical" only')
    else:
        out["speed"] = {"kind": kind}
    zf = get_field(sp, "zero_fade", "observer.speed.zero_fade", float, None)
    if zf is not None:
        if not issubclass(info.ctor, AbstractLESO):
            raise JobError("observer.speed.zero_fade", "applies to the LESOs only (a flux does not vanish at zero)")
        if zf < 0:
            raise JobError("observer.speed.zero_fade", f"must be >= 0 rad/s (0: the sign detector), got {show(zf)}")
        out["zero_fade"] = zf
    return out


# the tables of a job file
JOB_TABLES = ("job", "component", "observer", "gains", "scenarios", "holdout", "objective", "solver", "drive")
JOB_TABLES += ("envelope",)
SOLVER_KEYS = ("kind", "learning_rate", "steps", "patience", "tol", "schedule", "checkpoint_every", "progress_every")


# a registered class's short names (its closed form's aliases) -> the class's name
_ALIAS_CLASS = {alias: name for name, entry in REGISTRY.items() for alias in entry.aliases}


def _parse_job_table(raw: dict) -> tuple[str, str, int]:
    """``[job]``: the job's name, its component's registered name (tunable) and its seed."""
    job_t = get_field(raw, "job", "job", dict, required=True)
    no_unknown(job_t, ("name", "component", "seed"), "job")
    name = get_field(job_t, "name", "job.name", str, "job")
    comp = get_field(job_t, "component", "job.component", str, required=True)
    comp = _ALIAS_CLASS.get(comp, comp)  # a closed form's short name ("soifo", as `jaxobs closed-form` takes it)
    if comp in REGISTRY and not REGISTRY[comp].tunable:  # the class declares why (why_not_tunable)
        raise JobError("job.component", f"{comp} is not tunable: {REGISTRY[comp].cls.why_not_tunable}")
    if comp not in COMPONENTS:
        known = ", ".join([*COMPONENTS, *(a for a, c in _ALIAS_CLASS.items() if c in COMPONENTS)])
        raise JobError("job.component", f"unknown component {show(comp)}; known: {known}")
    seed = get_field(job_t, "seed", "job.seed", int, 0)
    if not 0 <= seed < 2**32 - 1:
        raise JobError("job.seed", f"must be in [0, 2^32 - 1), got {show(seed)}")
    return name, comp, seed


def _parse_component(comp_t: dict, comp: str, info: ComponentInfo, ts: float | None = None) -> dict:
    """``[component]``: the component's defaults at the period ``ts`` (None: its class's; ``values["ts"]`` set
    otherwise) with the table's values (each a number of its defaults)."""
    values = info.defaults_at(ts)
    for k in comp_t:
        key = canonical_key(info.ctor, k)  # a flux observer's omega_init may be written omega0
        if key not in info.defaults:
            raise JobError(f"component.{k}", f"unknown for {comp}; allowed: {', '.join(info.defaults)}")
        values[key] = get_field(comp_t, k, f"component.{k}", float)
    return values


def _component_ts(info: ComponentInfo, values: dict) -> float:
    """The sample time of the component built from ``values`` (its constructor's refusal, one line)."""
    try:  # without its speed estimator: a record's α_o is checked at the job's own period (parse_job)
        return float(info.ctor(**{k: v for k, v in values.items() if k != "speed"}).ts)
    except (ValueError, ArithmeticError, TypeError) as e:
        raise JobError("component", str(e)) from None


def _parse_gain(gname: str, gains_t: dict, values: Mapping[str, float], prefix: str = "") -> GainSpec:
    """``[gains.<prefix><gname>]``: the free gain's initial value, bounds and scale, checked together (``prefix``
    ``"speed."``: a gain of the speed estimator, the GainSpec named ``speed.<gname>``)."""
    where = f"gains.{prefix}{gname}"
    spec = get_field(gains_t, gname, where, dict, required=True)
    no_unknown(spec, ("init", "lower", "upper", "log"), where)
    init = get_field(spec, "init", f"{where}.init", float, values[gname])
    lower = get_field(spec, "lower", f"{where}.lower", float)
    upper = get_field(spec, "upper", f"{where}.upper", float)
    log = get_field(spec, "log", f"{where}.log", bool, True)
    if lower is not None and lower < 0:
        raise JobError(f"{where}.lower", f"must be >= 0 (gains are positive), got {lower}")
    if log and lower is not None and lower <= 0:
        raise JobError(f"{where}.lower", f"must be > 0 with log = true, got {lower}")
    if upper is not None and upper <= 0:
        raise JobError(f"{where}.upper", f"must be > 0, got {upper}")
    if lower is not None and upper is not None and not lower < upper:
        raise JobError(f"{where}.upper", f"must exceed lower ({lower}), got {upper}")
    if init <= 0:
        raise JobError(f"{where}.init", f"must be > 0, got {init}")
    if (lower is not None and init <= lower) or (upper is not None and init >= upper):
        raise JobError(f"{where}.init", f"must lie strictly inside [{lower}, {upper}], got {init}")
    if lower is not None and upper is not None and (upper - lower) < 1e-6 * upper:
        raise JobError(f"{where}.upper", f"bounds [{lower:g}, {upper:g}] are too narrow (relative width < 1e-6)")
    g = GainSpec(prefix + gname, init, lower, upper, log)
    try:  # the parametrization must map init (and the closed form, nudged inside) to a finite θ
        th = g.to_theta(init)
    except (ValueError, ArithmeticError):
        th = math.nan
    if not math.isfinite(th):
        raise JobError(f"{where}.init", f"{init:g} cannot be parametrized inside its bounds [{lower}, {upper}]")
    return g


def _parse_gains(raw: dict, comp: str, info: ComponentInfo, values: dict) -> list[GainSpec]:
    """``[gains]``: one table per free gain (``values`` takes each one's initial value); a mechanical speed
    observer leaves the PLL's gains nothing to do."""
    gains_t = get_field(raw, "gains", "gains", dict, required=True)
    if not gains_t:
        raise JobError("gains", "at least one free gain is required")
    gains = []
    for gname in gains_t:
        if gname == "speed" and "speed" not in info.gains:
            gains += _parse_speed_gains(gains_t, values)
            continue
        if gname not in info.gains:
            raise JobError(cap(f"gains.{gname}", 60), f"unknown gain for {comp}; tunable: {', '.join(info.gains)}")
        g = _parse_gain(gname, gains_t, values)
        gains.append(g)
        values[gname] = g.init
    speed_spec = values.get("speed")
    if isinstance(speed_spec, dict) and speed_spec.get("kind") == "mechanical":
        roles = gain_fields(info.ctor)
        unused = [g.name for g in gains if g.name in roles and roles[g.name].role == "pll"]
        if unused:
            raise JobError(
                f"gains.{unused[0]}",
                'the PLL\'s gains do nothing under [observer.speed] kind = "mechanical"; free another gain',
            )
    return gains


def _parse_speed_gains(gains_t: dict, values: dict) -> list[GainSpec]:
    """``[gains.speed.<k>]``: the mechanical speed observer's gains k1, k2, k3 (jaxobs.observers.speed), free as
    any gain; their closed form (each one's default initial value) is the triple pole at ``[observer.speed]``'s
    ``alpha_o``, and ``values["speed"]``'s record takes their initial values."""
    rec = values.get("speed")
    if not (isinstance(rec, dict) and rec.get("kind") == "mechanical"):
        raise JobError(
            "gains.speed", 'the speed estimator\'s gains are free only with [observer.speed] kind = "mechanical"'
        )
    sub = get_field(gains_t, "speed", "gains.speed", dict, required=True)
    if not sub:
        raise JobError("gains.speed", f"name a gain of the mechanical model: {', '.join(MECHANICAL_GAINS)}")
    closed: dict[str, float] = dict(zip(MECHANICAL_GAINS, mechanical_gains(float(rec["alpha_o"]))))
    out, rec = [], dict(rec)
    for k in sub:
        if k not in closed:
            raise JobError(
                cap(f"gains.speed.{k}", 60), f"unknown gain of the mechanical model; tunable: {', '.join(closed)}"
            )
        g = _parse_gain(k, sub, closed, prefix="speed.")
        rec[k] = g.init
        out.append(g)
    values["speed"] = rec
    return out


def _parse_scenarios_and_drive(
    raw: dict, comp: str, info: ComponentInfo, values: dict, seed: int, freq_n: float, ts: float, base: Path | None
) -> tuple[ScenarioSpec, DriveSpec | None, float]:
    """``[scenarios]`` and, for a drive job, ``[drive]``: the observer runs at the drive's period, so the
    scenarios are read again at it (``values["ts"]`` set) where it differs.

    Returns:
        ``(scenarios, drive or None, ts)``.
    """
    scen = parse_scenarios(
        get_field(raw, "scenarios", "scenarios", dict, required=True), "scenarios", info.signals, seed, freq_n, ts, base
    )
    drive = None
    if scen.family.closed_loop:
        drive = parse_drive(get_field(raw, "drive", "drive", dict, {}), comp, scen, base)
        d_ts = drive.drive_file.ts
        if abs(d_ts - ts) > 1e-12 * ts:  # the observer runs at the drive's period (its file's f_sample_hz)
            values["ts"] = d_ts
            ts = _component_ts(info, values)
            scen = parse_scenarios(raw["scenarios"], "scenarios", info.signals, seed, freq_n, ts, base)
    elif "drive" in raw:
        raise JobError("drive", f"applies to drive jobs (scenarios.signal = 'drive'), not {scen.signal!r} signals")
    return scen, drive, ts


def _parse_holdout(
    raw: dict, scen: ScenarioSpec, seed: int, freq_n: float, ts: float, base: Path | None
) -> ScenarioSpec | None:
    """``[holdout]`` (None without it): the tuning set's signal, event and windows unless it gives its own."""
    tab = get_field(raw, "holdout", "holdout", dict)
    if tab is None:
        return None
    h = dict(tab)
    for key in ("t_event", "horizon", "steady_from"):
        h.setdefault(key, getattr(scen, key))
    h.setdefault("signal", scen.signal)
    return parse_scenarios(h, "holdout", (scen.signal,), seed + 1, freq_n, ts, base)


def _check_sets(scen: ScenarioSpec, holdout: ScenarioSpec | None, drive: DriveSpec | None, ts: float) -> None:
    """The held-out set's start-up, then each set's size and drive speeds, at --check time."""
    if holdout is not None and holdout.recording is None and drive is not None and drive.start == "standstill":
        check_standstill(drive, holdout, "holdout")
    settle = drive.settle if drive is not None else 0.0
    for spec, where in ((scen, "scenarios"), (holdout, "holdout")):
        if spec is not None:
            check_size(spec, where, ts, settle)
            if drive is not None:
                check_drive_speeds(spec, where, drive)


def _parse_term(t: object, where: str, comp: str, scen: ScenarioSpec, drive: DriveSpec | None) -> Term:
    """One ``{ metric = ..., weight = ... }`` of ``objective.terms``: a metric that applies to the job's signals."""
    if not isinstance(t, dict):
        raise JobError(where, f"must be a table {{ metric = ..., weight = ... }}, got {show(t)}")
    no_unknown(t, ("metric", "weight"), where)
    metric = get_field(t, "metric", f"{where}.metric", str, required=True)
    # an old name is read as its new one (one line of warning), its weight converted to the new units
    metric, scale = canonical(metric, f"{where}.metric")
    if metric not in TERM_METRICS:
        raise JobError(f"{where}.metric", f"unknown metric {show(metric)}; known: {', '.join(TERM_METRICS)}")
    grid_only = metric.endswith(("_freq", "_phase", "freq_steady", "phase_steady"))
    if TERM_METRICS[metric].needs_truth and scen.recording is None:
        raise JobError(
            f"{where}.metric",
            f"{show(metric)} compares the estimate with a recording's truth: it needs [scenarios.recording]",
        )
    if metric in DRIVE_METRICS and not scen.family.closed_loop:
        raise JobError(f"{where}.metric", f"{show(metric)} needs the closed-loop drive, not {comp} ({scen.signal})")
    if scen.family.drive_observer == grid_only:
        raise JobError(f"{where}.metric", f"{show(metric)} does not apply to {comp} ({scen.signal} signals)")
    if TERM_METRICS[metric].kind == "system" and drive is not None and drive.start != "steady":
        raise JobError(f"{where}.metric", f"{metric} needs drive.start = 'steady' (an operating point)")
    weight = get_field(t, "weight", f"{where}.weight", float, 1.0)
    if weight <= 0:
        raise JobError(f"{where}.weight", f"must be > 0, got {weight}")
    return Term(metric, weight / scale)


def _parse_terms(obj_t: dict, comp: str, scen: ScenarioSpec, drive: DriveSpec | None) -> tuple[list, list[Term]]:
    """``objective.terms``: the terms as written and as read (old metric names as their new ones)."""
    terms_raw = obj_t.get("terms")
    if not isinstance(terms_raw, list) or not terms_raw:
        raise JobError("objective.terms", "missing (required): a list of { metric = ..., weight = ... }")
    terms = [_parse_term(t, f"objective.terms[{i}]", comp, scen, drive) for i, t in enumerate(terms_raw)]
    return terms_raw, terms


def _parse_aggregation(obj_t: dict) -> tuple[AbstractAggregation, float]:
    """``[objective]``'s aggregation (with its alpha and temperature) and penalty."""
    agg = get_field(obj_t, "aggregate", "objective.aggregate", str, "mean")
    if agg not in strategies.AGGREGATIONS:
        raise JobError("objective.aggregate", f"must be {strategies.one_of(strategies.AGGREGATIONS)}, got {show(agg)}")
    alpha = get_field(obj_t, "alpha", "objective.alpha", float, 0.9)
    if not 0 <= alpha < 1:
        raise JobError("objective.alpha", f"must be in [0, 1), got {alpha}")
    temperature = get_field(obj_t, "temperature", "objective.temperature", float)
    if temperature is not None and temperature <= 0:
        raise JobError("objective.temperature", f"must be > 0, got {temperature}")
    penalty = get_field(obj_t, "penalty", "objective.penalty", float, 1e3)
    if penalty <= 0:
        raise JobError("objective.penalty", f"must be > 0, got {penalty}")
    return strategies.aggregation(agg, alpha=alpha, temperature=temperature), penalty


def _parse_solver(raw: dict) -> AbstractSolver:
    """``[solver]``: its kind and options (the optax solvers' own refused for a minimiser)."""
    sol_t = get_field(raw, "solver", "solver", dict, {})
    no_unknown(sol_t, SOLVER_KEYS, "solver")
    kind = get_field(sol_t, "kind", "solver.kind", str, "adam")
    if kind not in strategies.SOLVER_KINDS:
        raise JobError("solver.kind", f"must be {strategies.one_of(strategies.SOLVER_KINDS)}, got {show(kind)}")
    if kind in strategies.MINIMISERS:  # optimistix: no learning rate, schedule, patience or checkpoints
        for key in strategies.OPTAX_ONLY:
            if key in sol_t:
                raise JobError(
                    f"solver.{key}", f"does not apply to kind = '{kind}' (it applies to {', '.join(strategies.OPTAX)})"
                )
    learning_rate = get_field(sol_t, "learning_rate", "solver.learning_rate", float, 0.05)
    steps = get_field(sol_t, "steps", "solver.steps", int, 100)
    patience = get_field(sol_t, "patience", "solver.patience", int, 25)
    tol = get_field(sol_t, "tol", "solver.tol", float, 1e-6)
    schedule = get_field(sol_t, "schedule", "solver.schedule", str, "constant")
    checkpoint_every = get_field(sol_t, "checkpoint_every", "solver.checkpoint_every", int, 5)
    progress_every = get_field(sol_t, "progress_every", "solver.progress_every", int, 1)
    if not 0 < learning_rate <= 1e6:
        raise JobError("solver.learning_rate", f"must be in (0, 1e6], got {learning_rate:g}")
    if tol < 0:
        raise JobError("solver.tol", f"must be >= 0, got {tol:g}")
    if steps > MAX_SOLVER_STEPS:
        raise JobError("solver.steps", f"must be <= {MAX_SOLVER_STEPS}, got {show(steps)}")
    counts = (("steps", steps), ("patience", patience), ("checkpoint_every", checkpoint_every))
    for fld, n in (*counts, ("progress_every", progress_every)):
        if n < 1:
            raise JobError(f"solver.{fld}", f"must be >= 1, got {n}")
    if schedule not in strategies.SCHEDULES:
        raise JobError("solver.schedule", f"must be {strategies.one_of(strategies.SCHEDULES)}, got {show(schedule)}")
    return strategies.solver(
        kind,
        learning_rate=learning_rate,
        steps=steps,
        patience=patience,
        tol=tol,
        schedule=schedule,
        checkpoint_every=checkpoint_every,
        progress_every=progress_every,
    )


def _raw_to_keep(raw: dict, drive: DriveSpec | None, terms_raw: list, terms: list[Term]) -> dict:
    """The job's tables as a result keeps them: a drive file inline, old metric names as their new ones."""
    if drive is not None and drive.file is not None and "file" in raw["drive"]:
        raw = {**raw, "drive": inline_drive(raw["drive"], drive.file)}  # a result reads it wherever it moves
    if any(t.get("metric") != term.metric for t, term in zip(terms_raw, terms)):  # old names: never written back
        new = [{**t, "metric": term.metric, "weight": term.weight} for t, term in zip(terms_raw, terms)]
        raw = {**raw, "objective": {**raw["objective"], "terms": new}}
    return raw


def parse_job(raw: dict, base: Path | None = None) -> Job:
    """Validate a job dict (the parsed TOML).

    The tables are read in order, each error naming its field: ``[job]``, ``[component]`` and
    ``[observer.speed]``, ``[gains]``, ``[scenarios]`` and ``[drive]``, ``[envelope]``, ``[holdout]``, the sets'
    sizes, ``[objective]``, ``[solver]``.

    Args:
        raw: The parsed job file.
        base: The job file's folder, against which a recording's relative ``file`` is read (and then
            checked now: it exists, its columns, its rate); without it the files are read when the job runs.

    Returns:
        The :class:`Job`.

    Raises:
        JobError: A field out of its range, naming the field.
    """
    no_unknown(raw, JOB_TABLES, "job file")
    name, comp, seed = _parse_job_table(raw)
    info = COMPONENTS[comp]
    comp_t = get_field(raw, "component", "component", dict, {})
    values = _parse_component(comp_t, comp, info)
    values.update(parse_observer_speed(raw, info))
    ts = _component_ts(info, values)
    freq_n = float(values.get("omega_n", W_N)) / (2 * math.pi)
    gains = _parse_gains(raw, comp, info, values)
    scen, drive, ts = _parse_scenarios_and_drive(raw, comp, info, values, seed, freq_n, ts, base)
    if "ts" in values:  # a drive job at its drive file's period: the defaults designed at that period, read again
        values = _parse_component(comp_t, comp, info, ts)
        values.update(parse_observer_speed(raw, info))
        gains = _parse_gains(raw, comp, info, values)
    alpha = values.get("speed", {}).get("alpha_o")
    bad = None if alpha is None else alpha_o_out_of_range(alpha, ts)
    if bad:
        raise JobError("observer.speed.alpha_o", bad)
    envelope = parse_envelope(raw, scen, drive)
    holdout = _parse_holdout(raw, scen, seed, freq_n, ts, base)
    _check_sets(scen, holdout, drive, ts)
    obj_t = get_field(raw, "objective", "objective", dict, required=True)
    no_unknown(obj_t, ("terms", "aggregate", "alpha", "temperature", "penalty"), "objective")
    terms_raw, terms = _parse_terms(obj_t, comp, scen, drive)
    aggregation, penalty = _parse_aggregation(obj_t)
    solver = _parse_solver(raw)
    job = Job(
        raw=_raw_to_keep(raw, drive, terms_raw, terms),
        name=name,
        component=comp,
        seed=seed,
        values=values,
        gains=gains,
        scenarios=scen,
        holdout=holdout,
        terms=terms,
        aggregation=aggregation,
        penalty=penalty,
        solver=solver,
        drive=drive,
        envelope=envelope,
    )
    check_recording_job(job, comp_t)
    return job


def load_job(path: str | os.PathLike) -> Job:
    """Read, check and parse a job file (:func:`read_toml`, then :func:`parse_job`).

    Args:
        path: The job file.

    Returns:
        The :class:`Job`, with its ``sha256``.

    Raises:
        JobError: An unreadable file, or a field out of its range, naming the field.
    """
    raw, data = read_toml(path)
    job = parse_job(raw, Path(path).parent)
    job.sha256 = sha256(data)
    return job
