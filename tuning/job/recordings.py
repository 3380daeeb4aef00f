"""``[scenarios.recording]``: recorded signals as a job's scenarios (parsed, checked, loaded, bound)."""

from __future__ import annotations

import dataclasses
import math
import re
import warnings
from pathlib import Path
from typing import cast

import equinox as eqx
import jax
import numpy as np

from jaxobs.drive import PMSMParams, bench_machine, load_drive
from jaxobs.io.provenance import sha256
from jaxobs.observers import AbstractFluxObserver
from jaxobs.scenarios.families import FAMILIES, AbstractFamily, RecordedSignals
from jaxobs.signals import (
    DriveRecording,
    RecordingColumnError,
    RecordingLayout,
    RecordingWarning,
    SampledSignal,
    read_recorded,
    stack,
)

from ..objective import DRIVE_METRICS
from .components import COMPONENTS
from .fields import JobError, cap, get_field, no_unknown, show
from .spec import Job, RecordingSpec, ScenarioSpec

# a recording file of a job or study larger than this is refused: a grid voltage read whole (SampledSignal.from_csv,
# in memory), a drive log read in chunks into columns on disk (jaxobs.signals.read_drive_log: its memory does not
# grow with the file; 10^7 rows of 7 columns are about 600 MiB of CSV)
MAX_RECORDING_BYTES = 64 * 2**20
MAX_LOG_BYTES = 4 * 2**30
MAX_WINDOWS = 256  # windows of one drive log (scenarios.recording.windows)
RECORDING_KEYS = (
    "file", "time_column", "sample_rate", "columns", "voltages", "currents", "truth", "layout", "trim", "windows",
    "machine", "startup_periods",
)  # fmt: skip

# The observer's start-up skipped by a drive log's scores (scenarios.recording.startup_periods), in electrical periods
# at the recording's own speed.  A recorded run starts the observer from rest (its filters at zero, its speed bound
# to the encoder's) in the middle of a drive that has been running, a start the drive itself never makes: the first
# samples score that start, not the observer.  The SOIFOs sign ω̂ by the cross product of flux and EMF estimates
# that are still near zero at the first step, so a rounding of 3e-14 V there turns a peak speed error of 28 rad/s
# into 627 (benchmarks/log_layouts.py).  Periods, not "until the estimate settles": a window that moved with the
# gains would let a tuner shorten its own scoring by starting slowly, and its edge would not be differentiable.
# The default, two periods (_startup_periods): at paper 000's gains the SOGI filters' transient (time constant about
# 2/(K1 ω), 0.2 period) and the speed estimate's sign are settled by then (noise on the first samples then moves a
# score by < 0.1 %, tests/test_recording_startup.py); a start far off the speed decays with the FLL, slower (a 20 %
# error: 18 % of the IAE after 2 periods, 2 % after 5, docs/recordings.md), and asks for more.
MAX_STARTUP_PERIODS = 1000.0


MAX_RECORDINGS = 64  # files of one [scenarios.recording]


# what each kind of job reads from a recording: its signal columns and its truth columns (defaults), the family's
RECORDING_COLUMNS = {name: family.recording_columns for name, family in FAMILIES.items()}


def _col_spec(v: object, field: str) -> str | int:
    if isinstance(v, bool) or not isinstance(v, (str, int)) or (isinstance(v, int) and not 0 <= v < 10_000):
        raise JobError(field, f"must be a column name or a 0-based index, got {show(v)}")
    return v


def parse_recording_scenarios(
    tab: dict,
    where: str,
    family: type[AbstractFamily],
    t_event: float,
    horizon: float,
    steady: float,
    seed: int,
    ts: float,
    base: Path | None,
) -> ScenarioSpec:
    """``[<where>.recording]``: the file(s), the time base, the columns.

    Read and checked now when the job file's folder is known (``base``): exists, at most
    :data:`MAX_RECORDING_BYTES`, the columns present, finite, time strictly increasing, sampled at least at
    1/ts, long enough for the horizon.

    Args:
        tab: The scenario table holding ``recording``.
        where: The scenario table's name in errors.
        family: The family the recordings stand for (a class of :mod:`jaxobs.scenarios.families`).
        t_event: The event's time, s.
        horizon: The simulated time, s.
        steady: The steady window's start, s.
        seed: The seed.
        ts: The component's sample time, s.
        base: The job file's folder, or None (the files are read when the job runs).

    Returns:
        The :class:`ScenarioSpec` with its :class:`RecordingSpec`.

    Raises:
        JobError: A field or file refused, naming the field.
    """
    w = f"{where}.recording"
    if "grid" in tab or "sample" in tab:
        key = "grid" if "grid" in tab else "sample"
        raise JobError(f"{where}.{key}", "does not apply with a recording: the recordings are the scenarios")
    rec = get_field(tab, "recording", w, dict, required=True)
    no_unknown(rec, RECORDING_KEYS, w)
    files = rec.get("file")
    if isinstance(files, str):
        files = [files]
    if not isinstance(files, list) or not files or not all(isinstance(f, str) and f for f in files):
        raise JobError(f"{w}.file", f"missing (required): a CSV file name or a list of them, got {show(files)}")
    if len(files) > MAX_RECORDINGS:
        raise JobError(f"{w}.file", f"{len(files)} files, more than {MAX_RECORDINGS}")
    if ("time_column" in rec) == ("sample_rate" in rec):
        raise JobError(w, "give exactly one of time_column (a column of seconds) and sample_rate (Hz)")
    tcol = _col_spec(rec["time_column"], f"{w}.time_column") if "time_column" in rec else None
    rate = get_field(rec, "sample_rate", f"{w}.sample_rate", float)
    if rate is not None and not 0 < rate <= 1e9:
        raise JobError(f"{w}.sample_rate", f"must be in (0, 1e9] Hz, got {rate:g}")
    recorded = family.recorded()
    cols, n_volt, lists = _signal_columns(rec, w, recorded)
    truth = rec.get("truth", list(recorded.truth))
    n_truth = recorded.truth_counts  # grid: theta, omega, amplitude; u/i: theta_e [, omega_e]
    for key, v, n_ok in (*lists, ("truth", truth, n_truth)):
        if not isinstance(v, list) or len(v) not in n_ok:
            raise JobError(f"{w}.{key}", f"must be a list of {' or '.join(map(str, n_ok))} column(s), got {show(v)}")
        for i, c in enumerate(v):
            _col_spec(c, f"{w}.{key}[{i}]")
    root = Path.cwd() if base is None else Path(base)
    paths = tuple(str(Path(f) if Path(f).is_absolute() else root / f) for f in files)
    layout, windows, machine, mname = _log_options(rec, w, recorded, cols, n_volt, root, base is not None)
    trim = get_field(rec, "trim", f"{w}.trim", bool, False)
    startup = _startup_periods(rec, w, recorded)
    spec = RecordingSpec(
        tuple(files), paths, tcol, rate, tuple(cols), tuple(truth), ts, layout=layout, trim=trim, windows=windows,
        machine=machine, machine_name=mname, voltages=n_volt, startup_periods=startup,
    )  # fmt: skip
    lengths, starts = [], []
    if base is not None:
        digests = []
        for i, path in enumerate(paths):
            field = f"{w}.file" if len(files) == 1 else f"{w}.file[{i}]"
            try:
                size = Path(path).stat().st_size
            except OSError as e:
                msg = f"cannot read {cap(files[i], 80)!r} (relative to the job file): {e.strerror}"
                raise JobError(field, msg) from None
            cap_bytes = MAX_LOG_BYTES if recorded.binds else MAX_RECORDING_BYTES
            if size > cap_bytes:
                raise JobError(field, f"{files[i]!r} is {size} bytes, more than {cap_bytes} ({cap_bytes >> 20} MiB)")
            # the file as the job names it, its last 120 characters at most: a JobError is cut at MAX_ERROR
            # characters, and a deep relative path (800 characters) had cut the reader's remedy off the message
            named = files[i] if len(files[i]) <= 120 else "…" + files[i][-119:]
            try:
                sig = _load_one(spec, recorded, path, need=int(round(horizon / ts)) + 1)
            except RecordingColumnError as e:  # a column not in the file: the key that named it
                raise JobError(_column_field(w, e, spec), str(e).replace(path, named)) from None
            except ValueError as e:
                raise JobError(field, str(e).replace(path, named)) from None
            need = int(round(horizon / ts))
            got = sig if isinstance(sig, list) else [sig]  # a drive log's windows, or the file
            sig = got[0]
            if sig.n < need:
                raise JobError(
                    f"{where}.horizon",
                    f"{horizon:g} s needs {need} samples of {ts:g} s; {files[i]!r} gives {sig.n} "
                    f"({(sig.n - 1) * ts:.6g} s)",
                )
            digests.append(sha256(Path(path)))
            lengths.append(sig.n if not spec.windows else need)
            if startup:  # each scenario's speed (a drive log's omega_e: given, or the angle's slope)
                starts += recorded_speeds(stack(cast(DriveRecording, x) for x in got), need)
        t_start = scored_window(spec, t_event, horizon, steady, starts, where)[0]  # it leaves a steady window
        spec = dataclasses.replace(spec, sha256=tuple(digests), startup_s=t_start)
    if len({n for n in lengths}) > 1 and not trim and not windows:
        shown = ", ".join(f"{f} {n}" for f, n in zip(files, lengths))
        raise JobError(
            f"{w}.trim",
            f"the recordings are of different lengths ({shown} samples of {ts:g} s): set trim = true to cut "
            "them to the shortest",
        )
    if recorded.binds and machine is None and base is not None:  # after the logs are read: a refusal alone
        _warn_unchecked(w)
    axes = {"recording": [float(i) for i in range(len(files) * max(windows, 1))]}
    return ScenarioSpec(family.signal, t_event, horizon, steady, axes, 0, seed, recording=spec)


def _warn_unchecked(w: str) -> None:
    """Warn that a job's drive logs, given no ``machine``, were not checked for their voltage timing and power."""
    # the voltage timing (applied or reference, the delay) and the power direction are checked against the
    # machine's flux-linkage equation (Rs, Ld, Lq, ψ_f): the job's [component] Rs, L lack ψ_f, so without the
    # machine a reference logged as applied (a bias of ω_e·ts in every estimate) would pass unseen.
    warnings.warn(
        RecordingWarning(
            f"{w}.machine is not given: the logs' voltage timing (voltage_timing, voltage_delay) and power "
            "direction were not checked (give machine = a shipped machine's name or a drive file)"
        ),
        stacklevel=2,
    )


def _startup_periods(rec: dict, w: str, family: RecordedSignals) -> float:
    """``startup_periods``: electrical periods of a drive log's start skipped by its scores (2 by default: the rule
    above :data:`MAX_STARTUP_PERIODS`; a grid recording: none, the key refused)."""
    if not family.binds:
        if "startup_periods" in rec:
            raise JobError(f"{w}.startup_periods", "applies to drive logs (u and i), not to a grid voltage")
        return 0.0
    n = get_field(rec, "startup_periods", f"{w}.startup_periods", float, 2.0)
    if not 0.0 <= n <= MAX_STARTUP_PERIODS:
        raise JobError(f"{w}.startup_periods", f"must be in [0, {MAX_STARTUP_PERIODS:g}] periods, got {n:g}")
    return n


def scored_window(
    rec: RecordingSpec, t_event: float, horizon: float, steady: float, speeds: list[float], where: str
) -> tuple[float, float, float]:
    """Where a job's scores on drive logs start: past the observer's start-up, ``rec.startup_periods`` electrical
    periods at the slowest recording's speed (:func:`recorded_speeds`; one window for every recording, so that their
    scores add up alike; the slowest's periods cover each).  The event and the steady window begin there at the
    earliest.

    Args:
        rec: The recordings (their ``startup_periods``).
        t_event: The job's event, s.
        horizon: The simulated time, s.
        steady: The steady window's start, s.
        speeds: Each scenario's recorded electrical speed, rad/s (:func:`recorded_speeds`).
        where: The scenario table's name in errors.

    Returns:
        ``(start-up s, the event, the steady window's start)``: s, from each recording's first sample.

    Raises:
        JobError: The start-up leaves fewer than 10 samples of steady window, naming ``startup_periods``.
    """
    if not rec.startup_periods or not speeds:
        return 0.0, t_event, steady
    slowest = min(speeds)
    t_start = rec.startup_periods * 2 * math.pi / slowest if slowest > 0 else math.inf
    if (horizon - max(steady, t_start)) / rec.ts < 10:
        raise JobError(
            f"{where}.recording.startup_periods",
            f"{rec.startup_periods:g} electrical periods at the slowest recording's speed "
            f"({slowest:.4g} rad/s) are {t_start:.4g} s, leaving fewer than 10 samples before the horizon "
            f"({horizon:g} s): lower it, or lengthen the horizon",
        )
    return t_start, max(t_event, t_start), max(steady, t_start)


def scenarios_window(spec: ScenarioSpec, scenarios: eqx.Module) -> tuple[float, float, float]:
    """:func:`scored_window` of a scenario set on its loaded batch.

    Args:
        spec: The scenario set (its ``recording``; a set without one is scored as it says).
        scenarios: Its batch (:func:`load_recordings`).

    Returns:
        ``(start-up s, the event, the steady window's start)``.

    Raises:
        JobError: The start-up leaves fewer than 10 samples of steady window, naming ``startup_periods``.
    """
    rec = spec.recording
    if rec is None:
        return 0.0, spec.t_event, spec.steady_from
    speeds = recorded_speeds(scenarios, round(spec.horizon / rec.ts))
    return scored_window(rec, spec.t_event, spec.horizon, spec.steady_from, speeds, "scenarios")


def recorded_speeds(scenarios: eqx.Module, n: int) -> list[float]:
    """Each drive-log scenario's speed: the median |ω_e| recorded over its first ``n`` samples (the horizon), rad/s
    electrical; none for another batch.  The median, not the first sample: the window that skips the start-up must
    not hinge on one sample either.

    Args:
        scenarios: The job's batch (:func:`load_recordings`), or a drive log's windows stacked.
        n: The samples of the horizon.

    Returns:
        The speeds, one per scenario.
    """
    if not isinstance(scenarios, DriveRecording) or scenarios.omega_e is None:
        return []
    w = np.abs(np.asarray(scenarios.omega_e)[..., :n])
    return [float(x) for x in np.median(w.reshape(-1, w.shape[-1]), axis=-1)]


def _signal_columns(rec: dict, w: str, recorded: RecordedSignals) -> tuple[list, int | None, list[tuple]]:
    """A recording's signal columns: ``columns`` (a grid voltage's one; a drive log's 4 or 6, voltages then
    currents in halves), or a drive log's ``voltages`` and ``currents`` (2 or 3 each: two or three phases, as its
    layout declares).

    Returns:
        ``(the columns, voltages first, how many are voltages (None: half), the (key, list, allowed counts) to
        check)``.
    """
    split = [k for k in ("voltages", "currents") if k in rec]
    if not split:
        cols = rec.get("columns", list(recorded.columns))
        n_cols = (4, 6) if recorded.binds else (len(recorded.columns),)  # u/i: 2 + 2, or 3 + 3 phase columns (abc)
        return cols, None, [("columns", cols, n_cols)]
    if not recorded.binds:
        raise JobError(f"{w}.{split[0]}", "applies to drive logs (u and i), not to a grid voltage: give columns")
    if "columns" in rec:
        raise JobError(f"{w}.columns", "give columns, or voltages and currents, not both")
    if len(split) == 1:
        other = "currents" if split[0] == "voltages" else "voltages"
        raise JobError(f"{w}.{other}", f"is required with {split[0]} (the log's voltage and current columns)")
    volts, amps = rec["voltages"], rec["currents"]
    lists = [("voltages", volts, (2, 3)), ("currents", amps, (2, 3))]
    if not (isinstance(volts, list) and isinstance(amps, list)):
        return [], None, lists  # refused by the caller's check, naming the key
    return [*volts, *amps], len(volts), lists


def _log_options(
    rec: dict, w: str, family: RecordedSignals, cols: list, n_volt: int | None, root: Path, load: bool
) -> tuple[RecordingLayout | None, int, PMSMParams | None, str | None]:
    """A drive log's ``layout`` (table), ``windows`` (count) and ``machine`` (a bench machine's name, or a drive
    file relative to the job), checked; the grid kind takes none of them."""
    keys = [k for k in ("layout", "windows", "machine") if k in rec]
    if keys and not family.binds:
        raise JobError(f"{w}.{keys[0]}", "applies to drive logs (u and i), not to a grid voltage")
    layout = None
    if "layout" in rec:
        try:
            table = get_field(rec, "layout", f"{w}.layout", dict)
            assert table is not None  # the key is there
            layout = RecordingLayout.from_table(table, f"{w}.layout")
        except ValueError as e:  # "<w>.layout.<key>: ..." or "<w>.layout.<key> must be ...": the key, then why
            m = re.match(rf"({re.escape(w)}\.layout\.\w+):? (.*)", str(e))
            raise JobError(*(m.groups() if m else (f"{w}.layout", str(e)))) from None
    if n_volt is None:  # columns: in halves
        three = layout is not None and layout.voltage_frame == "abc" and layout.current_frame == "abc"
        if len(cols) == 6 and not three:
            how = "layout abc for both" if layout is not None else "declare them in layout"
            raise JobError(f"{w}.columns", f"6 columns are three voltage and three current phases: {how}")
    else:  # voltages and currents: three of either are phases, declared so
        frames = (None, None) if layout is None else (layout.voltage_frame, layout.current_frame)
        for key, n, field, frame in (
            ("voltages", n_volt, "voltage_frame", frames[0]),
            ("currents", len(cols) - n_volt, "current_frame", frames[1]),
        ):
            if n == 3 and frame != "abc":
                raise JobError(f"{w}.{key}", f"3 columns are three phases: declare layout.{field} = 'abc'")
    windows = get_field(rec, "windows", f"{w}.windows", int, 0)
    if "windows" in rec and not 1 <= windows <= MAX_WINDOWS:
        raise JobError(f"{w}.windows", f"must be a count in 1..{MAX_WINDOWS}, got {windows}")
    machine = name = None
    if "machine" in rec:
        name = get_field(rec, "machine", f"{w}.machine", str)
        assert name is not None  # the key is there
        if name.endswith(".toml"):
            if load:
                p = Path(name) if Path(name).is_absolute() else root / name
                try:
                    machine = load_drive(p)[0]
                except (OSError, ValueError) as e:
                    raise JobError(f"{w}.machine", f"{cap(name, 80)!r}: {e}") from None
        else:
            try:
                machine = bench_machine(name)
            except ValueError as e:
                raise JobError(f"{w}.machine", str(e)) from None
    return layout, windows, machine, name


def _column_field(w: str, e: RecordingColumnError, spec: RecordingSpec) -> str:
    """The job field of a recording column that the file lacks: ``<w>.columns[i]``, ``<w>.truth[i]`` or
    ``<w>.time_column``."""
    if e.role == "time":
        return f"{w}.time_column"
    key, listed = ("columns", spec.columns) if e.role == "signal" else ("truth", spec.truth)
    if e.spec not in listed:
        return f"{w}.{key}"
    i = listed.index(e.spec)
    if e.role == "signal" and spec.voltages is not None:  # given as voltages and currents
        return f"{w}.voltages[{i}]" if i < spec.voltages else f"{w}.currents[{i - spec.voltages}]"
    return f"{w}.{key}[{i}]"


def _load_one(
    spec: RecordingSpec, family: RecordedSignals, path: str, need: int | None = None
) -> SampledSignal | DriveRecording | list[DriveRecording]:
    """One file's scenario (or its ``spec.windows`` windows of ``need`` samples, a list)."""
    kw = dict(time_column=spec.time_column, sample_rate=spec.sample_rate, ts=spec.ts)
    if not family.binds:
        return read_recorded(path, spec.columns, spec.truth, drive=False, max_bytes=MAX_RECORDING_BYTES, **kw)
    windows = None
    if spec.windows:
        if need is None:  # a window is the horizon's length: without one there is nothing to cut
            raise JobError("scenarios.recording.windows", "windows are cut to the horizon; give scenarios.horizon")
        windows = (spec.windows, need)
    return read_recorded(
        path, spec.columns, spec.truth, drive=True, layout=spec.layout, machine=spec.machine, windows=windows,
        voltages=spec.voltages, max_bytes=MAX_LOG_BYTES, **kw,
    )  # fmt: skip


def load_recordings(
    spec: RecordingSpec, family: RecordedSignals, horizon: float | None = None
) -> SampledSignal | DriveRecording:
    """The recordings of a job as one batched signal, all read at ``spec.ts``.

    Whole files of one length (cut to the shortest with ``spec.trim``), or each drive log's ``spec.windows``
    windows of the horizon.

    Args:
        spec: The :class:`RecordingSpec`.
        family: The :class:`jaxobs.scenarios.families.RecordedSignals` they are (read by
            :func:`jaxobs.signals.read_recorded`).
        horizon: The simulated time, s (the windows' length).

    Returns:
        The batched signal (a :class:`~jaxobs.signals.SampledSignal` or a
        :class:`~jaxobs.signals.DriveRecording`, its leaves with a leading batch axis).
    """
    need = None if horizon is None else int(round(horizon / spec.ts)) + 1
    sigs = []
    for p in spec.paths:
        got = _load_one(spec, family, p, need)
        sigs += got if isinstance(got, list) else [got]
    n = min(s.n for s in sigs)
    return stack(jax.tree.map(lambda x: x[..., :n] if eqx.is_array(x) else x, s) for s in sigs)


def check_recording_job(job: Job, comp_t: dict) -> None:
    """What a recording cannot give: the closed loop's metrics; a flux observer on u/i needs the machine's Rs, L.

    Args:
        job: The parsed job.
        comp_t: The job's ``[component]`` table.

    Raises:
        JobError: The job asks for either, naming the field.
    """
    for spec, where in ((job.scenarios, "scenarios"), (job.holdout, "holdout")):
        if spec is None or spec.recording is None:
            continue
        for i, t in enumerate(job.terms):
            if t.metric in DRIVE_METRICS:
                raise JobError(
                    f"objective.terms[{i}].metric",
                    f"{t.metric!r} needs the closed-loop drive; a recording runs the observer open loop (use "
                    "iae_position, rms_position_steady, ripple_position, rms_speed_error_steady, peak_speed_error)",
                )
        if spec.family.recorded().binds and issubclass(COMPONENTS[job.component].ctor, AbstractFluxObserver):
            for k in ("Rs", "L"):
                if k not in comp_t:
                    raise JobError(
                        f"component.{k}",
                        f"required with a u/i recording ({where}.recording): the machine's {k} "
                        "(the default Rs = 0, L = 1 is for back-EMF signals)",
                    )
