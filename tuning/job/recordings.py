"""``[scenarios.recording]``: recorded signals as a job's scenarios (parsed, checked, loaded, bound)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import equinox as eqx
import jax

import jaxobs
from jaxobs.families import FAMILIES, RecordedSignals
from jaxobs.observers import AbstractFluxObserver
from jaxobs.provenance import sha256
from jaxobs.signals import stack

from ..objective import DRIVE_METRICS
from .components import COMPONENTS
from .fields import JobError, cap, get_field, no_unknown, show
from .spec import RecordingSpec, ScenarioSpec

MAX_RECORDING_BYTES = 8 * 2**20  # a recording file of a job or study larger than this is refused


MAX_RECORDINGS = 64  # files of one [scenarios.recording]


# what each kind of job reads from a recording: its signal columns and its truth columns (defaults), the family's
RECORDING_COLUMNS = {name: family.recording_columns for name, family in FAMILIES.items()}


def _col_spec(v, field: str):
    if isinstance(v, bool) or not isinstance(v, (str, int)) or (isinstance(v, int) and not 0 <= v < 10_000):
        raise JobError(field, f"must be a column name or a 0-based index, got {show(v)}")
    return v


def parse_recording_scenarios(tab, where, kind, t_event, horizon, steady, seed, ts, base) -> ScenarioSpec:
    """``[<where>.recording]`` of recordings that stand for the family ``kind`` (:mod:`jaxobs.families`): the
    file(s), the time base, the columns; read and checked now when the job file's folder is known (``base``):
    exists, at most :data:`MAX_RECORDING_BYTES`, the columns present, finite, time strictly increasing, sampled
    at least at 1/ts, long enough for the horizon."""
    w = f"{where}.recording"
    if "grid" in tab or "sample" in tab:
        key = "grid" if "grid" in tab else "sample"
        raise JobError(f"{where}.{key}", "does not apply with a recording: the recordings are the scenarios")
    rec = get_field(tab, "recording", w, dict)
    no_unknown(rec, ("file", "time_column", "sample_rate", "columns", "truth"), w)
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
    family = RecordedSignals(kind)
    cols_default, truth_default = (list(c) for c in family.kind.recording_columns)
    cols, truth = rec.get("columns", cols_default), rec.get("truth", truth_default)
    n_truth = family.kind.truth_counts  # grid: theta, omega, amplitude; u/i: theta_e [, omega_e]
    for key, v, n_ok in (("columns", cols, (len(cols_default),)), ("truth", truth, n_truth)):
        if not isinstance(v, list) or len(v) not in n_ok:
            raise JobError(f"{w}.{key}", f"must be a list of {' or '.join(map(str, n_ok))} column(s), got {show(v)}")
        for i, c in enumerate(v):
            _col_spec(c, f"{w}.{key}[{i}]")
    root = Path.cwd() if base is None else Path(base)
    paths = tuple(str(Path(f) if Path(f).is_absolute() else root / f) for f in files)
    spec = RecordingSpec(tuple(files), paths, tcol, rate, tuple(cols), tuple(truth), ts)
    if base is not None:
        digests = []
        for i, path in enumerate(paths):
            field = f"{w}.file" if len(files) == 1 else f"{w}.file[{i}]"
            try:
                size = Path(path).stat().st_size
            except OSError as e:
                msg = f"cannot read {cap(files[i], 80)!r} (relative to the job file): {e.strerror}"
                raise JobError(field, msg) from None
            if size > MAX_RECORDING_BYTES:
                raise JobError(field, f"{files[i]!r} is {size} bytes, more than {MAX_RECORDING_BYTES} (8 MiB)")
            try:
                sig = _load_one(spec, family, path)
            except jaxobs.signals.RecordingColumnError as e:  # a column not in the file: the key that named it
                raise JobError(_column_field(w, e, spec), str(e).replace(path, files[i])) from None
            except ValueError as e:
                raise JobError(field, str(e).replace(path, files[i])) from None
            need = int(round(horizon / ts))
            if sig.n < need:
                raise JobError(
                    f"{where}.horizon",
                    f"{horizon:g} s needs {need} samples of {ts:g} s; {files[i]!r} gives {sig.n} "
                    f"({(sig.n - 1) * ts:.6g} s)",
                )
            digests.append(sha256(Path(path)))
        spec = dataclasses.replace(spec, sha256=tuple(digests))
    axes = {"recording": [float(i) for i in range(len(files))]}
    return ScenarioSpec(kind.signal, t_event, horizon, steady, axes, 0, seed, recording=spec)


def _column_field(w: str, e, spec: RecordingSpec) -> str:
    """The job field of a recording column that the file lacks: ``<w>.columns[i]``, ``<w>.truth[i]`` or
    ``<w>.time_column``."""
    if e.role == "time":
        return f"{w}.time_column"
    key, listed = ("columns", spec.columns) if e.role == "signal" else ("truth", spec.truth)
    return f"{w}.{key}[{listed.index(e.spec)}]" if e.spec in listed else f"{w}.{key}"


def _load_one(spec: RecordingSpec, family: RecordedSignals, path: str):
    kw = dict(time_column=spec.time_column, sample_rate=spec.sample_rate, ts=spec.ts, max_bytes=MAX_RECORDING_BYTES)
    return family.read(path, spec.columns, spec.truth, **kw)


def load_recordings(spec: RecordingSpec, family: RecordedSignals):
    """The recordings of a job as one batched signal (each cut to the shortest, all read at ``spec.ts``), read
    as ``family`` (:class:`jaxobs.families.RecordedSignals`) reads them."""
    sigs = [_load_one(spec, family, p) for p in spec.paths]
    n = min(s.n for s in sigs)
    return stack(jax.tree.map(lambda x: x[..., :n] if eqx.is_array(x) else x, s) for s in sigs)


def check_recording_job(job, comp_t: dict) -> None:
    """What a recording cannot give: the closed loop's metrics; a flux observer on u/i needs the machine's Rs, L."""
    for spec, where in ((job.scenarios, "scenarios"), (job.holdout, "holdout")):
        if spec is None or spec.recording is None:
            continue
        for i, t in enumerate(job.terms):
            if t.metric in DRIVE_METRICS:
                raise JobError(
                    f"objective.terms[{i}].metric",
                    f"{t.metric!r} needs the closed-loop drive; a recording runs the observer open loop "
                    "(use iae_position, rms_position_steady, ripple_position)",
                )
        if RecordedSignals(spec.family).binds and issubclass(COMPONENTS[job.component].ctor, AbstractFluxObserver):
            for k in ("Rs", "L"):
                if k not in comp_t:
                    raise JobError(
                        f"component.{k}",
                        f"required with a u/i recording ({where}.recording): the machine's {k} "
                        "(the default Rs = 0, L = 1 is for back-EMF signals)",
                    )
