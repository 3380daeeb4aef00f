"""What a job writes: JSON without NaN, the per-scenario scores as a Dataset, provenance."""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import equinox as eqx
import numpy as np

from jaxobs import metrics as M
from jaxobs.core.discretize import AbstractRule
from jaxobs.io.provenance import cf_dataset, cf_labels
from jaxobs.scenarios.families import RecordedSignals
from jaxobs.signals import DriveRecording, SampledSignal

from ..objective import TERM_METRICS, Objective
from ..outdir import atomic_write_text
from .recordings import scenarios_window
from .spec import Job, ScenarioSpec

if TYPE_CHECKING:  # imported where a Dataset is made
    import xarray as xr


def rule_spec(rule: AbstractRule | None) -> dict | None:
    """A discretization rule as JSON that :func:`jaxobs_tuning.export.parse_rule` reads back.

    Args:
        rule: A component's discretization rule, or None.

    Returns:
        ``{"name": ..., options}`` (its plain options); None for a component without a rule (its step is its own
        update).
    """
    if rule is None:
        return None
    opts = {f.name: getattr(rule, f.name) for f in dataclasses.fields(rule)}
    return {"name": type(rule).__name__, **{k: v for k, v in opts.items() if isinstance(v, (bool, int, float, str))}}


def sanitize(obj: object, path: str = "", reasons: dict | None = None) -> object:
    """``obj`` with every non-finite float replaced by ``None``.

    Args:
        obj: A JSON-like value (dicts, lists, tuples, numbers, numpy scalars).
        path: Its path in ``reasons`` (``a.b[2]``).
        reasons: path -> what a replaced value was, filled in.

    Returns:
        The value with plain Python numbers, lists for tuples and None for every non-finite float.
    """
    reasons = {} if reasons is None else reasons
    if isinstance(obj, dict):
        return {k: sanitize(v, f"{path}.{k}" if path else str(k), reasons) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [sanitize(v, f"{path}[{i}]", reasons) for i, v in enumerate(obj)]
    if isinstance(obj, (float, np.floating)) and not math.isfinite(float(obj)):
        reasons[path] = f"not a finite number ({float(obj)})"
        return None
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def write_json(path: Path, obj: object) -> None:
    """JSON without NaN or Infinity tokens: non-finite numbers become null, listed under ``null_reasons``.

    Args:
        path: The file, written atomically.
        obj: A JSON-like value (:func:`sanitize`).
    """
    reasons: dict = {}
    clean = sanitize(obj, "", reasons)
    if reasons and isinstance(clean, dict):
        clean["null_reasons"] = {**clean.get("null_reasons", {}), **reasons}
    atomic_write_text(path, json.dumps(clean, indent=1, allow_nan=False) + "\n")


def at_bounds(job: Job, gains: dict) -> dict:
    """Free gains within 1 % of a bound.

    Args:
        job: The parsed job (its free gains' bounds).
        gains: name -> a design's value.

    Returns:
        ``{name: {"bound": "lower" | "upper", "limit": ..., "value": ...}}``.
    """
    out = {}
    for g in job.gains:
        v = gains[g.name]
        for side, lim in (("lower", g.lower), ("upper", g.upper)):
            if lim is not None and abs(v - lim) <= 0.01 * abs(lim):
                out[g.name] = {"bound": side, "limit": lim, "value": v}
    return out


def scores_dataset(
    obj: Objective,
    names: Sequence[str],
    combos: Sequence[tuple],
    spec: ScenarioSpec,
    per: dict,
    title: str = "jaxobs tune: per-scenario scores",
) -> xr.Dataset:
    """Per-scenario metrics of each design as an xarray Dataset: the grid's axes as dims (a full grid),
    else one ``scenario`` dim with the axes as coordinates (sampled scenarios).  Every variable carries a
    ``long_name`` and every numeric one CF ``units`` (the metrics': :data:`jaxobs_tuning.objective.TERM_METRICS`;
    flags ``1``); the CF-1.8 global attributes, ``title`` among them (:func:`jaxobs.io.provenance.cf_dataset`); a
    numeric ``design`` index and its label ``design_label`` (:func:`jaxobs.io.provenance.cf_labels`).

    Args:
        obj: The objective that scored them (its terms, flags and family).
        names: The axes' names.
        combos: The scenarios' points.
        spec: The scenario set.
        per: design -> ``(metrics, totals, finite)`` of :meth:`~jaxobs_tuning.objective.Objective.per_scenario`.
        title: The dataset's title.

    Returns:
        The Dataset.
    """
    import xarray as xr

    designs = list(per)
    recorded = isinstance(obj.family, RecordedSignals)  # its one axis: the recordings, each named by its file
    grid = spec.sample == 0
    if grid:
        dims = ("design", *names)
        shape = tuple(len(spec.axes[n]) for n in names)
        coords = {"design": designs, **{n: list(spec.axes[n]) for n in names}}
        if spec.recording is not None:  # a recording is named by its file (a log's window: file@index)
            coords["recording"] = spec.recording.labels()
    else:
        dims, shape = ("design", "scenario"), (len(combos),)
        coords = {"design": designs, "scenario": np.arange(len(combos))}
        coords.update({n: ("scenario", [c[i] for c in combos]) for i, n in enumerate(names)})
    data = {}
    keys = [t.metric for t in obj.terms]
    flag_keys = ("diverged", *obj.flags)  # the table's flags (jaxobs.metrics.METRICS): lost_lock, the drive's too
    for key in (*keys, "total", *flag_keys):
        rows = []
        for d in designs:
            mets, total, good = per[d]
            flags = {"total": total, "diverged": ~good, "lost_lock": mets["lost_lock"] | ~good}
            x = flags.get(key, mets.get(key) if key in mets else None)
            rows.append(np.asarray(x, dtype=float).reshape(shape))
        data[key] = (dims, np.stack(rows))
    ds = xr.Dataset(data, coords=coords)
    for key in keys:
        ds[key].attrs.update(units=TERM_METRICS[key].units, long_name=TERM_METRICS[key].long_name)
    # the weights carry the metrics' units (a term's weight is per its metric's unit): the total is a number
    ds["total"].attrs.update(units="1", long_name="weighted objective of the scenario (the penalty where diverged)")
    for key in flag_keys:
        ds[key] = ds[key].astype("int8")
        ds[key].attrs.update(units="1", long_name=M.METRICS[key].long_name)
    ds.attrs["note"] = "total: the weighted objective per scenario (the penalty where diverged); " + "; ".join(
        f"{key}: {M.METRICS[key].long_name}" for key in flag_keys
    )
    what = "observer design (closing the loop sensorless)" if obj.closed_loop else "observer design"
    ds["design"].attrs["long_name"] = f"{what}: its initial, closed-form or tuned gains"
    for name in names:
        if recorded:  # a recording is named by its file (a string label: no unit)
            ds[name].attrs["long_name"] = "recording (its file; a window of a log: file@index)"
        elif name in spec.family.axes:  # the family's axis: CF units and long name
            ds[name].attrs.update(spec.family.axes[name].attrs)
        else:
            ds[name].attrs.update(units="1", long_name=name)
    if not grid:
        ds["scenario"].attrs.update(units="1", long_name=f"scenario: one of {len(combos)} random points of the axes")
    ds.attrs["source"] = "jaxobs tune (jaxobs_tuning.run_job)"
    # as the file holds it: a numeric design index, the names its label (jaxobs.io.provenance.by_label reads it back)
    return cf_labels(cf_dataset(ds, title))


def recordings_provenance(job: Job, scenarios: eqx.Module | None = None) -> dict:
    """The recordings of a job on recordings: each file, and each of its scenarios with the speed it starts from
    (rad/s, electrical: the encoder's, or a grid recording's true frequency, at its first sample), read from the
    batch ``scenarios`` when given.  The observer's own initial speed does not apply: it is bound to these.

    Args:
        job: The parsed job.
        scenarios: Its batch (a :class:`~jaxobs.signals.DriveRecording` or a
            :class:`~jaxobs.signals.SampledSignal` with ``truth``), or None.

    Returns:
        ``{"recordings": [{"file", "sha256", "scenarios": [{"name", "omega_start"}, ...]}, ...], "loop_note"}``,
        with ``"startup"`` (``periods``, ``seconds``, and the ``t_event`` and ``steady_from`` scored) where drive
        logs' scores skip the observer's start-up; empty for a job not on recordings.
    """
    rec = job.scenarios.recording
    if rec is None:
        return {}
    labels = rec.labels()
    starts = [None] * len(labels)
    if scenarios is not None:
        w = None  # the recorded speed at each window's start: a drive log's, or a grid voltage's true ω
        if isinstance(scenarios, DriveRecording):
            w = scenarios.omega_e
        elif isinstance(scenarios, SampledSignal) and scenarios.truth is not None:
            w = scenarios.truth[1]
        if w is not None:
            starts = [float(x) for x in np.asarray(w)[..., 0].reshape(-1)]
    per = max(rec.windows, 1)
    out = []
    for i, (f, h) in enumerate(zip(rec.files, rec.sha256 or [None] * len(rec.files))):
        sc = [{"name": labels[i * per + k], "omega_start": starts[i * per + k]} for k in range(per)]
        out.append({"file": f, "sha256": h, "scenarios": sc})
    got = {"recordings": out, "loop_note": "open loop on recordings: each scenario starts at its own speed"}
    if rec.startup_periods and scenarios is not None:  # the scores' window, past the observer's start-up
        t_start, t_event, steady = scenarios_window(job.scenarios, scenarios)
        got["startup"] = {"periods": rec.startup_periods, "seconds": t_start, "t_event": t_event, "steady_from": steady}
    return got


def claimed_envelope(job: Job) -> dict | None:
    """The operating envelope a drive job was tuned for, from its scenarios: the speed range
    (r/min, the grid's speeds and where its speed steps take them), the load range (N·m, with the load
    steps), the other axes' ranges.  Where the designs hold inside it is not computed after tuning (minutes on
    the presets): ``jaxobs envelope <result.json>`` maps it.

    Args:
        job: The parsed job.

    Returns:
        ``{"speed_rpm", "load_nm", "other_axes", "machine", "verified", "verify_with"}``; None for a job that is
        not a simulated drive.
    """
    spec = job.scenarios
    if job.drive is None or not spec.family.closed_loop or spec.recording is not None:
        return None
    axes = spec.axes
    speeds = [float(v) for v in axes.get("speed_rpm", [600.0])]
    after = [s + float(d) for s in speeds for d in axes.get("speed_step_rpm", [0.0])]
    loads = [float(v) for v in axes.get("load_nm", [0.0])]
    after_l = [ld + float(d) for ld in loads for d in axes.get("load_step_nm", [0.0])]
    skip = ("speed_rpm", "speed_step_rpm", "load_nm", "load_step_nm")
    return {
        "speed_rpm": [min(speeds + after), max(speeds + after)],
        "load_nm": [min(loads + after_l), max(loads + after_l)],
        "other_axes": {k: [float(min(v)), float(max(v))] for k, v in axes.items() if k not in skip},
        "machine": job.drive.machine,
        "verified": None,
        "verify_with": "jaxobs envelope <this result.json>: where initial, closed form and tuned hold, 1 % to 100 % "
        "of rated speed x 0..rated torque",
    }
