"""Study files (``jaxobs study FILE``): read and check everything before a single scenario runs.

The same machinery as job files (:mod:`jaxobs_tuning.job`): the size, nesting and encoding are checked before the
TOML is parsed; every table and key is known (an unknown one is refused in one line that names it and the
allowed ones); every number is finite and in its physical range; the scenario count, the time steps and
the memory of one chunk are bounded.  ``jaxobs study FILE --check`` stops there.

A FLL study::

    [study]
    name = "fll-family"            # the output folder's default name (out/<name>)
    kind = "fll"                   # "fll" (default) or "drive"
    t_event = 0.1                  # s, the event of every scenario
    horizon = 0.4                  # s
    steady_from = 0.325            # s (default t_event + 0.75 (horizon - t_event))
    band_hz = 0.05                 # settling band, Hz
    sample = 0                     # 0: the full grid; n: n random points inside the axes' ranges
    seed = 0                       # the random points and the noise
    chunk_size = 2048              # scenarios per compiled call

    [designs.WIF]                  # one of: closed_form, result, component (+ its gains)
    closed_form = "wif"
    [designs.tuned]
    result = "out/tune/result.json"   # a tuning run's result; relative to the study file's folder
    [designs.mine]
    component = "SOGIFLL"
    k = 1.0
    lam = 20000.0

    [axes]                         # GridSignals.axes, each a non-empty list of numbers in its range
    freq_step = [-2.0, 2.0]

A drive study::

    [study]
    kind = "drive"
    machine = "ipmsm002"           # a shipped drive file (jaxobs.drive.SHIPPED_DRIVES, the jobs' benches);
                                   # default: the machine a result design was tuned on, else the first design's
    horizon = 0.3                  # s
    steady_from = 0.15             # s (default horizon / 2)
    t_event = 0.15                 # s, the steps' instant (default horizon / 2 with a step axis, else 0)
    sampling = "grid"              # grid | random | sobol | lhs (with sample = n; jaxobs.scenarios.SAMPLINGS)
    [drive]
    settle = 0.2                   # s, the observer's unscored settling phase before t = 0
    # file = "my_drive.toml"       # or the user's drive file (relative to the study file), instead of
                                   # study.machine; or its tables inline: [drive.machine], [drive.inverter], ...
    [designs.C-LESO]
    closed_form = "CLESO"          # a drive component's closed-form gains (jaxobs_tuning.job.COMPONENTS)
    [designs.tuned]
    result = "out/cleso/result.json"
    [designs.mine]
    component = "FALESO"
    k1 = 16.1
    [axes]                         # jaxobs.scenarios.families.DriveScenarios.axes
    dRs = [-0.2, 0.2]

``result`` paths: a relative path is read relative to the folder of the study file (not the working
directory), so a study file and the results it names move together; an absolute path is read as it is.
Either must exist and be a tuning ``result.json`` of the right family.  Reading is all a study does with
it (nothing is written there), and its content never reaches an error message.
"""

from __future__ import annotations

import inspect
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

from jaxobs.drive import SHIPPED_DRIVES, DriveFile, bench_machine, shipped_drive
from jaxobs.io.provenance import sha256, versions
from jaxobs.observers import AbstractFluxObserver, AbstractObserver
from jaxobs.scenarios import SAMPLINGS, Grid
from jaxobs.scenarios.families import FAMILIES, AbstractFamily, DriveScenarios, DriveSetting, GridSignals
from jaxobs.studies.registry import REGISTRY, canonical_key

from .job import (
    COMPONENTS,
    DRIVE_TABLES,
    MAX_SCENARIOS,
    MAX_STEPS,
    DriveSpec,
    JobError,
    available_memory,
    axes_field,
    cap,
    check_speed_axes,
    drive_source,
    get_field,
    job_drive,
    no_unknown,
    parse_job,
    parse_recording_scenarios,
    read_toml,
    show,
)
from .results import load_result, tuned_component

__all__ = [
    "StudySpec",
    "load_study",
    "parse_study",
    "study_fingerprint",
    "FLL_CLOSED_FORMS",
    "FLL_COMPONENTS",
    "DRIVE_OBSERVERS",
]

WHAT = "study file"
# the designs a study may name, from jaxobs.studies.registry: the FLLs (and their closed forms' aliases), the drive
# # observers (a grid signal's design is no drive observer; a drive observer may run on a family that closes the loop)
FLL_CLOSED_FORMS = {
    a: e.cls.closed_form for e in REGISTRY.values() if not FAMILIES[e.signal].drive_observer for a in e.aliases
} | {n: e.cls.closed_form for n, e in REGISTRY.items() if not FAMILIES[e.signal].drive_observer}
# a closed form's short name (as `jaxobs closed-form` takes it) -> its class's name (as jobs name components)
_ALIAS_CLASS = {alias: name for name, e in REGISTRY.items() for alias in e.aliases}
FLL_COMPONENTS = tuple(name for name, e in REGISTRY.items() if not FAMILIES[e.signal].drive_observer)
DRIVE_OBSERVERS = tuple(name for name, e in REGISTRY.items() if any(FAMILIES[s].closed_loop for s in e.signals))
# the drive jobs' shipped drive files (jaxobs.drive.SHIPPED_DRIVES: the same names, bench inertias and FOC), so a
# study scores a tuned result on the drive that tuned it
MACHINES = tuple(SHIPPED_DRIVES)
MAX_CHUNK = 100_000
# (the bytes one scenario keeps per time step while a chunk runs, for the memory check: each family's
# study_bytes_per_step, jaxobs.scenarios.families)

_FLL_STUDY_KEYS = (
    "kind",
    "name",
    "t_event",
    "horizon",
    "steady_from",
    "band_hz",
    "sample",
    "seed",
    "chunk_size",
    "recording",
)
_DRIVE_STUDY_KEYS = (
    "kind",
    "name",
    "machine",
    "t_event",
    "horizon",
    "steady_from",
    "sampling",
    "sample",
    "seed",
    "chunk_size",
)
STEP_AXES = ("speed_step_rpm", "load_step_nm")


@dataclass
class StudySpec:
    """A checked study file: the one study preset (``jaxobs.studies.study.run_study``)
    takes ``designs``, ``axes``, ``family`` and ``opts``.

    Attributes:
        name: The study's name.
        family: The scenarios' family (:mod:`jaxobs.scenarios.families`):
        :class:`~jaxobs.scenarios.families.GridSignals`, its
            recordings (:meth:`~jaxobs.scenarios.families.AbstractFamily.recorded`), or
            :class:`~jaxobs.scenarios.families.DriveScenarios`, built by its own ``from_toml`` from ``[study]``.
        designs: name -> design.
        axes: name -> values.
        opts: The runner's other options.
        scenarios: The scenario count.
        provenance: NetCDF attributes: the sha256 of the study file and of every result file it reads (names
            relative to the study file, as written there), and the drive study's machine.
    """

    name: str
    family: AbstractFamily
    designs: dict[str, AbstractObserver]
    axes: dict[str, list[float]]
    opts: dict = field(default_factory=dict)
    scenarios: int = 0
    # NetCDF attributes: the sha256 of the study file and of every result file it reads (names relative
    # to the study file, as written there), and the drive study's machine
    provenance: dict = field(default_factory=dict)


def load_study(path: str | os.PathLike) -> StudySpec:
    """Read, check and build a study file.

    Args:
        path: The study file.

    Returns:
        The :class:`StudySpec`.

    Raises:
        JobError: One line naming the field (exit 2).
    """
    path = Path(path)
    raw, data = read_toml(path, WHAT)  # size, nesting and encoding checked before parsing
    spec = parse_study(raw, base=path.resolve().parent)
    spec.provenance = {"study_file": path.name, "study_sha256": sha256(data), **spec.provenance}
    return spec


def study_fingerprint(spec: StudySpec) -> str:
    """What a study's chunks (``--resume``) are checked against, as a job's checkpoint is: the sha256 of the
    study file, of every result file and recording it reads, and of the versions that compute it (another
    JAX may give other last bits, and a resumed study must equal one run in one go).

    Args:
        spec: The checked study.

    Returns:
        The hex digest.
    """
    rec = spec.opts.get("recording")
    what = {
        "provenance": {k: v for k, v in spec.provenance.items() if k != "study_file"},
        "recordings": list(getattr(rec, "sha256", None) or ()),
        "versions": versions(),
    }
    return sha256(json.dumps(what, sort_keys=True, default=str).encode())


def parse_study(raw: dict, base: Path | None = None) -> StudySpec:
    """Check a parsed study file.

    Args:
        raw: The parsed TOML.
        base: The folder relative ``result`` paths are read from (default the working folder).

    Returns:
        The :class:`StudySpec`.

    Raises:
        JobError: A field out of its range, naming it.
    """
    base = Path.cwd() if base is None else Path(base)
    st = get_field(raw, "study", "study", dict, {})
    kind = get_field(st, "kind", "study.kind", str, "fll")
    if kind not in KINDS:
        raise JobError("study.kind", f"must be 'fll' or 'drive', got {show(kind)}")
    family, parse, default_name = KINDS[kind]  # the one place a study file's kind is read
    no_unknown(raw, ("study", "designs", "axes", "drive"), WHAT)  # every table a study file may have
    if not family.closed_loop and "drive" in raw:
        raise JobError("drive", "applies to drive studies (study.kind = 'drive')")
    return parse(raw, st, get_field(st, "name", "study.name", str, default_name), base)


def _family(family: type[AbstractFamily], st: dict, **run) -> AbstractFamily:
    """``family`` built by its own ``from_toml`` from ``[study]`` (its keys checked there, a ValueError naming
    the field) and what the run gives it."""
    try:
        return family.from_toml(st, "study", **run)
    except ValueError as e:  # "study.<key>: why"
        field, _, why = str(e).partition(": ")
        raise JobError(field, why or str(e)) from None


# --------------------------------------------------------------------------------------------------
# shared pieces
# --------------------------------------------------------------------------------------------------


def _axes(raw: dict, family, limits: dict | None = None) -> dict:
    """``[axes]``: known names (the family's), non-empty lists of finite numbers inside each axis's range."""
    return axes_field(get_field(raw, "axes", "axes", dict, {}), family, "axes", limits)


def _count(axes: dict, sample: int) -> int:
    n = sample or math.prod(len(v) for v in axes.values())
    if n > MAX_SCENARIOS:
        raise JobError("axes", f"{n} scenarios (the product of the axes' lengths) > {MAX_SCENARIOS}")
    return n


def _check_steps(horizon: float, steady_from: float, ts: float, n: int, chunk: int, family, extra_s=0.0) -> None:
    """Time steps of one run, the steady window's samples, and the memory of one chunk, against the machine."""
    if horizon < ts:
        raise JobError("study.horizon", f"shorter than one sample (ts = {ts:g} s), got {horizon:g} s")
    steps = (horizon + extra_s) / ts
    if steps > MAX_STEPS:
        raise JobError("study.horizon", f"{steps:.3g} time steps of {ts:g} s > {MAX_STEPS:g}: too long")
    if (horizon - steady_from) / ts < 10:
        raise JobError(
            "study.steady_from",
            f"the steady window [{steady_from:g}, {horizon:g}) s holds fewer than 10 samples of {ts:g} s",
        )
    need = steps * min(n, chunk) * family.study_bytes_per_step
    have = available_memory()
    if need > have:
        raise JobError(
            "study.chunk_size",
            f"{min(n, chunk)} scenarios per chunk x {steps:.3g} steps need about {need / 2**30:.3g} GiB, "
            f"{have / 2**30:.3g} GiB available: a smaller chunk_size or a shorter horizon",
        )


def _seed(st: dict) -> int:
    seed = get_field(st, "seed", "study.seed", int, 0)
    if not 0 <= seed < 2**32:
        raise JobError("study.seed", f"must be in [0, 2^32), got {show(seed)}")
    return seed


def _chunk(st: dict, default: int) -> int:
    chunk = get_field(st, "chunk_size", "study.chunk_size", int, default)
    if not 1 <= chunk <= MAX_CHUNK:
        raise JobError("study.chunk_size", f"must be in [1, {MAX_CHUNK}], got {show(chunk)}")
    return chunk


def _result(spec: dict, where: str, base: Path, family: tuple, out: dict | None = None):
    """A tuning result's tuned design; ``result`` relative to the study file's folder (module doc).  ``out``,
    when given, receives the result (``"result"``) and the file's sha256 (``"sha256"``)."""
    no_unknown(spec, ("result",), where)
    rel = get_field(spec, "result", f"{where}.result", str)
    if not rel or "\x00" in rel:
        raise JobError(f"{where}.result", f"must be the path of a tuning result.json, got {show(rel)}")
    p = Path(rel)
    p = p if p.is_absolute() else base / p
    if not p.is_file():
        raise JobError(f"{where}.result", f"no such file {cap(str(p), 100)!r} (relative paths: from the study file)")
    try:
        res = load_result(p)
        if res["component"] not in family:
            raise ValueError(f"component {show(res['component'])} is not one of {', '.join(family)}")
        comp = tuned_component(res)
        if out is not None:
            out.update(result=res, sha256=sha256(p), path=rel)
        return comp
    except (ValueError, TypeError, KeyError, AttributeError, ArithmeticError) as e:  # a malformed result
        raise JobError(f"{where}.result", str(e)) from None


def _results_attr(results: dict) -> dict:
    """The result files' provenance as one NetCDF attribute (``design: path sha256 HEX``, one a line)."""
    return {"result_files": "\n".join(f"{d}: {v}" for d, v in results.items())} if results else {}


def _ctor_params(ctor, exclude=()) -> dict:
    """The constructor's settable parameters: name -> default (inspect.Parameter.empty: required)."""
    sig = inspect.signature(ctor)
    # a key another field is accepted under (a flux observer's omega0, its omega_init) is no parameter of its own
    return {
        n: p.default for n, p in sig.parameters.items() if n not in ("rule", *exclude) and canonical_key(ctor, n) == n
    }


def _component(spec: dict, where: str, comp: str, exclude=(), fixed=None):
    """A component from its gains: known keys (typos named), each of its default's type, then the constructor."""
    ctor = REGISTRY[comp].cls
    params = _ctor_params(ctor, exclude)
    no_unknown(spec, ("component", *params), where)
    kw = {}
    for k, default in params.items():
        f = f"{where}.{k}"
        if k not in spec:
            if default is inspect.Parameter.empty and k not in (fixed or {}):
                raise JobError(f, f"missing (required by {comp})")
            continue
        if isinstance(default, bool):
            kw[k] = get_field(spec, k, f, bool)
        elif isinstance(default, str):
            kw[k] = get_field(spec, k, f, str)
        else:
            kw[k] = get_field(spec, k, f, float)
    try:
        return ctor(**(fixed or {}), **kw)
    except (ValueError, TypeError, ArithmeticError) as e:
        raise JobError(where, str(e)) from None


def _designs(raw: dict, build) -> dict:
    designs_t = get_field(raw, "designs", "designs", dict, {})
    if not designs_t:
        raise JobError("designs", "at least one design is required")
    designs = {}
    for name in designs_t:
        where = f"designs.{cap(str(name), 40)}"
        spec = get_field(designs_t, name, where, dict, required=True)
        given = [k for k in ("closed_form", "result", "component") if k in spec]
        if len(given) != 1:
            raise JobError(where, f"give exactly one of closed_form, result, component (got {len(given)})")
        designs[name] = build(spec, where, given[0])
    return designs


# --------------------------------------------------------------------------------------------------
# FLL studies
# --------------------------------------------------------------------------------------------------


def _parse_fll(raw: dict, st: dict, name: str, base: Path) -> StudySpec:
    no_unknown(st, _FLL_STUDY_KEYS, "study")
    results = {}  # provenance: each result file's sha256

    def build(spec, where, how):
        if how == "closed_form":
            no_unknown(spec, ("closed_form",), where)
            cf = get_field(spec, "closed_form", f"{where}.closed_form", str)
            if cf not in FLL_CLOSED_FORMS:
                raise JobError(f"{where}.closed_form", f"must be one of {', '.join(FLL_CLOSED_FORMS)}, got {show(cf)}")
            return FLL_CLOSED_FORMS[cf]()
        if how == "result":
            info = {}
            obs = _result(spec, where, base, FLL_COMPONENTS, info)
            results[where.split(".", 1)[1]] = f"{info['path']} sha256 {info['sha256']}"
            return obs
        comp = get_field(spec, "component", f"{where}.component", str)
        if comp not in FLL_COMPONENTS:
            raise JobError(f"{where}.component", f"must be one of {', '.join(FLL_COMPONENTS)}, got {show(comp)}")
        return _component(spec, where, comp)

    designs = _designs(raw, build)
    t_event = get_field(st, "t_event", "study.t_event", float, 0.1)
    horizon = get_field(st, "horizon", "study.horizon", float, 0.4)
    if t_event < 0:
        raise JobError("study.t_event", f"must be >= 0 s, got {t_event:g}")
    if not horizon > t_event:
        raise JobError("study.horizon", f"must exceed t_event ({t_event:g} s), got {horizon:g}")
    ts = min(float(d.ts) for d in designs.values())
    if horizon / ts > MAX_STEPS:
        raise JobError("study.horizon", f"{horizon:g} s is more than {MAX_STEPS:g} time steps of {ts:g} s")
    steady = get_field(st, "steady_from", "study.steady_from", float, t_event + 0.75 * (horizon - t_event))
    if not 0 <= steady < horizon:
        raise JobError("study.steady_from", f"must be in [0, horizon = {horizon:g}) s, got {steady:g}")
    band = get_field(st, "band_hz", "study.band_hz", float, 0.05)
    if not 0 < band <= 100:
        raise JobError("study.band_hz", f"must be in (0, 100] Hz, got {band:g}")
    sample = get_field(st, "sample", "study.sample", int, 0)
    if not 0 <= sample <= MAX_SCENARIOS:
        raise JobError("study.sample", f"must be in [0, {MAX_SCENARIOS}] (0: the full grid), got {show(sample)}")
    seed, chunk = _seed(st), _chunk(st, 2048)
    # the step is tied to the nominal frequency and the sample rate (the run takes the first design's ω_n)
    freq = float(next(iter(designs.values())).omega_n) / (2 * math.pi)
    if "recording" in st:  # [study.recording]: recorded voltages instead of the axes' grid
        return _fll_recordings(raw, st, name, base, designs, t_event, horizon, steady, band, results)
    axes = _axes(raw, GridSignals, GridSignals.limits(freq, ts))
    n = _count(axes, sample)
    family = _family(GridSignals, {"t_event": t_event, "seed": seed}, freq_n=freq)
    _check_steps(horizon, steady, ts, n, chunk, family)
    opts = dict(horizon=horizon, steady_from=steady, band_hz=band, sample=sample, chunk_size=chunk)
    return StudySpec(name, family, designs, axes, opts, n, _results_attr(results))


def _fll_recordings(raw, st, name, base, designs, t_event, horizon, steady, band, results) -> StudySpec:
    """``[study.recording]``: the keys of a job's ``[scenarios.recording]`` (:mod:`jaxobs_tuning.job`), every file
    read and checked now at the designs' one sample time; no ``[axes]``, ``sample`` or ``chunk_size``."""
    for key in ("sample", "chunk_size"):
        if key in st:
            raise JobError(f"study.{key}", "does not apply with study.recording (the recordings are the scenarios)")
    if "axes" in raw:
        raise JobError("axes", "does not apply with study.recording (the recordings are the scenarios)")
    ts = sorted({float(d.ts) for d in designs.values()})
    if len(ts) != 1:
        raise JobError("designs", f"a study on recordings needs one sample time for all designs, got {ts}")
    spec = parse_recording_scenarios(
        {"recording": st["recording"]}, "study", GridSignals, t_event, horizon, steady, 0, ts[0], base
    )
    rec = spec.recording
    assert rec is not None  # parse_recording_scenarios reads [study.recording]
    opts = dict(t_event=t_event, horizon=horizon, steady_from=steady, band_hz=band, recording=rec)
    family = GridSignals.recorded()  # the recordings stand for grid voltages
    return StudySpec(name, family, designs, {}, opts, len(rec.files), _results_attr(results))


# --------------------------------------------------------------------------------------------------
# drive studies
# --------------------------------------------------------------------------------------------------


def _result_machine(res: dict) -> str | None:
    """The drive machine a result was tuned on (``machine``; older results: its job's ``[drive]``); None for a
    result that is no drive job (a flux observer tuned on EMF signals)."""
    if res.get("machine") is not None:
        return str(res["machine"])
    job = parse_job(res["job"])
    return job.drive.machine if job.drive is not None else None


def _drive_machine(
    st: dict, designs: dict, tuned_on: dict[str, str], file_name: str, file: DriveFile | None
) -> tuple[str, DriveFile]:
    """A drive study's machine (``study.machine``, else the one the results were tuned on, else the first
    design's default), every design checked against it.

    Returns:
        ``(machine, its drive file)``.
    """
    first = type(next(iter(designs.values()))).__name__
    default: str = next(iter(tuned_on.values()), None) or COMPONENTS.get(first, COMPONENTS["CLESO"]).machines[0]
    machine = file_name if file is not None else get_field(st, "machine", "study.machine", str, default)
    if file is None and machine not in MACHINES:
        raise JobError("study.machine", f"must be one of {', '.join(MACHINES)}, got {show(machine)}")
    for where, m in tuned_on.items():
        if m != machine:
            raise JobError(f"{where}.result", f"was tuned on {m}, the study runs {machine}: give study.machine = {m!r}")
    df = shipped_drive(machine) if file is None else file
    for dname, obs in designs.items():
        comp = type(obs).__name__
        why = REGISTRY[comp].refusal(df.machine) if file is not None and comp in REGISTRY else None
        if file is None and comp in COMPONENTS and machine not in COMPONENTS[comp].machines:
            why = f"{comp} cannot run on {machine} ({df.description}); allowed: {', '.join(COMPONENTS[comp].machines)}"
        if why is not None:
            raise JobError(f"designs.{cap(str(dname), 40)}", why)
        if file is not None and abs(float(obs.ts) - df.ts) > 1e-12 * df.ts:
            raise JobError(
                f"designs.{cap(str(dname), 40)}",
                f"runs at ts = {float(obs.ts):g} s, the drive file at {df.ts:g} s (1/f_sample_hz): they must agree",
            )
    return machine, df


def _drive_file_of_study(raw: dict, st: dict, base: Path) -> tuple[float, str, DriveFile | None]:
    """A drive study's ``[drive]``: the observer's settling phase and the user's drive file (``file``, or its
    tables inline), if any.

    Returns:
        ``(settle, the file's name, the file)``; ``("", None)`` for the name and file of a shipped drive.
    """
    dr = get_field(raw, "drive", "drive", dict, {})
    # the FOC is the drive jobs' (jaxobs_tuning.job.job_drive: the bench's IMC current and I-P speed loops), so a tuned
    # result is scored on the drive that tuned it; only the observer's unscored settling phase is the study's
    no_unknown(dr, ("settle", "file", "name", "description", *DRIVE_TABLES), "drive")
    settle = get_field(dr, "settle", "drive.settle", float, 0.2)
    if not 0 <= settle <= 10:
        raise JobError("drive.settle", f"must be in [0, 10] s, got {settle:g}")
    # the user's drive file ([drive] file, or its tables inline), else a shipped one (study.machine)
    file_name, file = "", None
    if isinstance(dr.get("machine"), str):
        raise JobError("drive.machine", "a shipped machine is named by study.machine; [drive.machine] is a table")
    if "file" in dr or any(isinstance(dr.get(k), dict) for k in DRIVE_TABLES):
        if "machine" in st:
            raise JobError("study.machine", "give study.machine or the [drive] file (or its tables), not both")
        file_name, file = drive_source(dr, "", base)
    return settle, file_name, file


def _drive_designs(raw: dict, base: Path, ts_file: float | None) -> tuple[dict, dict[str, str], dict[str, str]]:
    """A drive study's ``[designs]``: each a tuning result, a drive component's closed form or its gains.

    Args:
        raw: The parsed study file.
        base: The study file's folder.
        ts_file: The drive file's period, which the closed forms run at (None: the shipped drive's).

    Returns:
        ``(designs, tuned_on, results)``: name -> observer; ``"designs.NAME"`` -> the machine its result was
        tuned on; name -> its result file and sha256.
    """
    tuned_on: dict[str, str] = {}  # "designs.NAME" -> the machine its result was tuned on
    results: dict[str, str] = {}  # design -> its result file and sha256

    def build(spec: dict, where: str, how: str):
        if how == "result":
            info = {}
            obs = _result(spec, where, base, DRIVE_OBSERVERS, info)
            results[where.split(".", 1)[1]] = f"{info['path']} sha256 {info['sha256']}"
            try:
                m = _result_machine(info["result"])
            except (ValueError, TypeError, KeyError, AttributeError) as e:
                raise JobError(f"{where}.result", str(e)) from None
            if m is not None:
                tuned_on[where] = m
            return obs
        if how == "closed_form":  # the component's closed-form gains, as a job's closed_form scores them
            no_unknown(spec, ("closed_form",), where)
            comp = get_field(spec, "closed_form", f"{where}.closed_form", str, required=True)
            comp = _ALIAS_CLASS.get(comp, comp)
            if comp not in DRIVE_OBSERVERS or comp not in COMPONENTS:
                names = [c for c in DRIVE_OBSERVERS if c in COMPONENTS]
                allowed = ", ".join([*names, *(a for a, c in _ALIAS_CLASS.items() if c in names)])
                raise JobError(f"{where}.closed_form", f"must be one of {allowed}, got {show(comp)}")
            info = COMPONENTS[comp]
            try:  # designed at the drive's period, as it runs (the reduced-order flux observer's matched pole)
                values = info.defaults_at(ts_file)
                values.update(info.closed_form(info.ctor(**values)))
                return info.ctor(**values)
            except (ValueError, TypeError, ArithmeticError) as e:
                raise JobError(where, str(e)) from None
        comp = get_field(spec, "component", f"{where}.component", str, required=True)
        if comp not in DRIVE_OBSERVERS:
            raise JobError(f"{where}.component", f"must be one of {', '.join(DRIVE_OBSERVERS)}, got {show(comp)}")
        # the bound fields (Rs, the inductance, the start speed) are placeholders: the study binds each
        # scenario's assumed machine and speed (AbstractDriveObserver.bind); the drive's ts rules
        ctor = REGISTRY[comp].cls
        par = bench_machine("spmsm000" if issubclass(ctor, AbstractFluxObserver) else "ipmsm002")
        # valid for the constructor, then bound: 0 for the resistance, 1 for the rest
        bound = ctor.bound_fields
        fixed = {f: (0.0 if f == bound.resistance else 1.0) for f in bound.names}
        if ts_file is not None:  # a user's drive file: the design runs at its period, as a closed form does
            fixed["ts"] = ts_file
        return _component(spec, where, comp, (*bound.names, "ts"), fixed).bind(par, 0.0)

    return _designs(raw, build), tuned_on, results


def _drive_window(raw: dict, st: dict, ts: float) -> tuple[float, float, float]:
    """A drive study's ``horizon``, ``steady_from`` and ``t_event`` (s), checked at the drive's period ``ts``."""
    horizon = get_field(st, "horizon", "study.horizon", float, 0.3)
    if not horizon > 0:
        raise JobError("study.horizon", f"must be > 0 s, got {horizon:g}")
    if horizon / ts > MAX_STEPS:
        raise JobError("study.horizon", f"{horizon:g} s is more than {MAX_STEPS:g} time steps of {ts:g} s")
    steady = get_field(st, "steady_from", "study.steady_from", float, 0.5 * horizon)
    if not 0 <= steady < horizon:
        raise JobError("study.steady_from", f"must be in [0, horizon = {horizon:g}) s, got {steady:g}")
    # the steps' instant: by default the middle of the horizon when a step axis is swept (the steady window's
    # default start, so the scored window holds the step's response and a steady stretch before it does not
    # count), else 0 (no step: the value does not matter)
    has_step = any(a in get_field(raw, "axes", "axes", dict, {}) for a in STEP_AXES)
    t_event = get_field(st, "t_event", "study.t_event", float, 0.5 * horizon if has_step else 0.0)
    if not 0 <= t_event < horizon:
        raise JobError("study.t_event", f"must be in [0, horizon = {horizon:g}) s, got {t_event:g}")
    return horizon, steady, t_event


def _drive_sampling(st: dict) -> tuple[str, int]:
    """A drive study's ``sampling`` and ``sample`` (a grid: 0; a drawn sampling: its count)."""
    sampling = get_field(st, "sampling", "study.sampling", str, "grid")
    if sampling not in SAMPLINGS:  # the presets' one table (jaxobs.scenarios.sampler_of)
        raise JobError("study.sampling", f"must be {', '.join(SAMPLINGS)}, got {show(sampling)}")
    sample = get_field(st, "sample", "study.sample", int, 0)
    drawn = SAMPLINGS[sampling] is not Grid
    if not drawn and sample:
        raise JobError(
            "study.sample", "applies to sampling = 'random', 'sobol' or 'lhs' (a grid runs every combination)"
        )
    if drawn and not 1 <= sample <= MAX_SCENARIOS:
        raise JobError("study.sample", f"must be in [1, {MAX_SCENARIOS}] with sampling = {sampling!r}, got {sample}")
    return sampling, sample


def _parse_drive(raw: dict, st: dict, name: str, base: Path) -> StudySpec:
    """A drive study: its ``[drive]``, designs, machine, window, sampling and axes, in that order."""
    no_unknown(st, _DRIVE_STUDY_KEYS, "study")
    settle, file_name, file = _drive_file_of_study(raw, st, base)
    ts_file = None if file is None else file.ts  # the designs run at the drive file's period
    designs, tuned_on, results = _drive_designs(raw, base, ts_file)
    machine, df = _drive_machine(st, designs, tuned_on, file_name, file)
    par = df.machine
    try:
        drive = job_drive(DriveSpec(loop="sensorless", settle=settle, machine=machine, file=file))
    except JobError:  # names its own field
        raise
    except (ValueError, ArithmeticError) as e:
        raise JobError("drive", str(e)) from None
    provenance = {"machine": f"{machine}: {df.description}", **_results_attr(results)}
    if file is not None:  # the drive file's tables as read: the study's record, and what --resume checks
        provenance["drive_file"] = json.dumps(file.table, sort_keys=True, ensure_ascii=False)
    ts = float(drive.ts)
    horizon, steady, t_event = _drive_window(raw, st, ts)
    sampling, sample = _drive_sampling(st)
    seed, chunk = _seed(st), _chunk(st, 256)
    axes = _axes(raw, DriveScenarios)
    check_speed_axes(axes, "axes", machine, file)  # the jobs' check: speeds within the inverter's limit
    n = _count(axes, sample)
    sensors = None if file is None else file.sensors  # a shipped bench's: ideal
    family = _family(DriveScenarios, {"t_event": t_event, "seed": seed}, drive=DriveSetting(par, drive, sensors))
    _check_steps(horizon, steady, ts, n, chunk, family, extra_s=settle)
    opts = dict(horizon=horizon, steady_from=steady, sampling=sampling, sample=sample, chunk_size=chunk)
    return StudySpec(name, family, designs, axes, opts, n, provenance)


# a study file's ``study.kind`` -> (its family, its parser, its default name): the one place the kind is read
KINDS = {"fll": (GridSignals, _parse_fll, "study"), "drive": (DriveScenarios, _parse_drive, "drive-study")}
