"""Reading a tuning run's ``result.json`` back: the tuned design as a component.

``run_job`` writes ``result.json`` (the job as given, the component's name,
the initial / tuned / closed-form gains, the scores).  Whoever wants the tuned
design back (a robustness study, a notebook) reads it here, in the layer that
wrote it; the library only ever receives the component itself::

    obs = tuned_component(load_result("out/wif-robust/result.json"))
    ds = run_study({"tuned": obs}, axes)            # jaxobs.studies.study.run_study

Every command that reads a result back (``study``, ``export``, ``envelope``) reads it through
:func:`load_result`: a regular file of bounded size and nesting, then :func:`check_result`'s schema, the
gains inside the job's bounds.  Errors are ``ValueError``s of one line that name the file and the field.
"""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

from jaxobs.io.provenance import read_file
from jaxobs.observers import AbstractObserver
from jaxobs.observers.speed import MECHANICAL_GAINS, speed_from_spec
from jaxobs.studies.registry import KEY_ALIASES, canonical_key, registered

from .job import COMPONENTS, Job, parse_job

__all__ = [
    "MAX_RESULT_BYTES",
    "MAX_RESULT_DEPTH",
    "check_result",
    "load_result",
    "result_designs",
    "tuned_component",
]

MAX_RESULT_BYTES = 16 * 2**20  # a result.json larger than this is refused before it is parsed
MAX_RESULT_DEPTH = 64  # nesting of arrays and objects (run_job writes about 6)

_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"')
GAIN_SETS = ("initial", "closed_form", "tuned")
BOUND_SLACK = 1e-9  # relative: a gain tuned to its bound comes back through exp(log(bound)), a rounding off
CLOSED_FORM_RTOL = 1e-6  # a closed form outside the bounds must be the job's own (float32 or float64 alike)


def check_nesting(text: str, where: str) -> None:
    """Refuse JSON nested deeper than :data:`MAX_RESULT_DEPTH` before it is parsed (the parser recurses on
    nesting: 100 000 × ``[`` raise a RecursionError).  A scan of the brackets outside strings, no recursion.

    Args:
        text: The JSON text.
        where: The file's name in errors.

    Raises:
        ValueError: Nested deeper than :data:`MAX_RESULT_DEPTH`, naming ``where``.
    """
    depth = 0
    for m in re.finditer(r"[\[\]{}]", _JSON_STRING.sub('""', text)):
        depth += 1 if m.group() in "[{" else -1
        if depth > MAX_RESULT_DEPTH:
            raise ValueError(f"{where}: nested deeper than {MAX_RESULT_DEPTH} levels")


def _no_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")


def _is_number(v) -> bool:
    """A JSON number (int or float, not a bool, not a string) that is finite."""
    return type(v) in (int, float) and math.isfinite(v)


def _table(v, where: str, what: str) -> dict:
    if not isinstance(v, dict):
        raise ValueError(f"{where}: {what} must be a table, got {type(v).__name__}")
    return v


def _numbers(table: dict, allowed, where: str, what: str) -> None:
    for k, v in table.items():
        if k not in allowed:
            raise ValueError(
                f"{where}: {what}.{str(k)[:40]} is not a value of the component (allowed: {', '.join(allowed)})"
            )
        if not _is_number(v):
            raise ValueError(f"{where}: {what}.{k} must be a finite number, got {json.dumps(v)[:40]}")


def _inside(v: float, lower, upper) -> bool:
    lo_ok = lower is None or v >= lower - BOUND_SLACK * abs(lower)
    return lo_ok and (upper is None or v <= upper + BOUND_SLACK * abs(upper))


def _job_closed_form(job: Job) -> dict:
    """The closed form the run reported for ``job`` (run_job: the component of the job's values)."""
    info = COMPONENTS[job.component]
    cf = info.closed_form(info.ctor(**job.values), job.values)
    return {g.name: float(cf[g.name]) for g in job.gains}


def _check_bounds(job: Job, table: dict, where: str, what: str, closed: bool) -> None:
    """The job's free gains in ``table`` inside their bounds (a log gain > 0); a closed form, reported exactly,
    may lie outside them only as the job's own closed form."""
    cf = None
    for g in job.gains:
        if g.name not in table:
            continue
        v = float(table[g.name])
        if _inside(v, g.lower, g.upper) and (not g.log or v > 0):
            continue
        if closed:
            try:
                cf = _job_closed_form(job) if cf is None else cf
            except (ArithmeticError, TypeError, ValueError):  # no closed form at these values: not the job's
                cf = {}
            if g.name in cf and math.isclose(v, cf[g.name], rel_tol=CLOSED_FORM_RTOL):
                continue
        lo = "-inf" if g.lower is None else f"{g.lower:g}"
        hi = "inf" if g.upper is None else f"{g.upper:g}"
        lo = "0 (exclusive: a log gain)" if g.log and g.lower is None else lo
        extra = " and is not the job's closed form" if closed else ""
        raise ValueError(
            f"{where}: {what}.{g.name} = {v:.6g} is outside the job's bounds [{lo}, {hi}] (job.gains.{g.name}){extra}"
        )


def check_result(res: object, where: str = "result") -> dict:
    """The one schema of a ``result.json`` read back (by ``study``, ``export``, ``envelope``); ``ValueError`` of one
    line naming the field.  ``component``: a known component; ``job``: a table (its ``job.component``, when
    given, the same component; its ``[component]`` values of that component, finite numbers); ``gains``:
    a table of ``initial`` / ``closed_form`` / ``tuned``, each null or a non-empty table of that component's
    values, finite JSON numbers (``"lam": "12337"`` is refused); ``gains.tuned`` null only when nothing was
    tuned (status ``diverged`` or ``overflow``), and at least one design; ``values`` (when given) the same
    for every constructor value of each design; ``ts`` a number > 0, ``omega_n`` a number or null, ``scores``
    a table when given.  The job must parse (:func:`jaxobs_tuning.parse_job`, its recordings not read)
    and the free gains of ``gains`` and ``values`` lie inside its bounds (``initial`` and ``tuned``; the
    closed form, reported exactly, inside them or equal to the job's own closed form).  The other keys are
    reports, not read back.

    Args:
        res: The parsed JSON.
        where: The file's name in errors.

    Returns:
        ``res``, checked.

    Raises:
        ValueError: One line naming the field that fails the schema.
    """
    if not isinstance(res, dict):
        raise ValueError(f"{where}: not a tuning result (a JSON object with job, component and gains)")
    for key in ("job", "component", "gains"):
        if key not in res:
            raise ValueError(f"{where}: not a tuning result (no {key!r})")
    comp = res["component"]
    if not isinstance(comp, str) or comp not in COMPONENTS:
        raise ValueError(
            f"{where}: component {json.dumps(comp)[:40].replace(chr(34), chr(39))} is not a jaxobs component"
        )
    ctor = COMPONENTS[comp].ctor  # a flux observer's job.component may name omega_init as omega0
    allowed = tuple(COMPONENTS[comp].defaults) + tuple(k for k in KEY_ALIASES if canonical_key(ctor, k) != k)
    job = _table(res["job"], where, "job")
    named = _table(job.get("job", {}), where, "job.job").get("component", comp)
    try:  # a job names its component by its class or a short name ("rofo"); the result by its class
        same = isinstance(named, str) and registered(named).name == comp
    except ValueError:
        same = False
    if not same:
        raise ValueError(f"{where}: component {comp!r} differs from the job's job.component {str(named)[:40]!r}")
    _numbers(_table(job.get("component", {}), where, "job.component"), allowed, where, "job.component")
    gains = _table(res["gains"], where, "gains")
    status = res.get("status")
    if status is not None and not isinstance(status, str):
        raise ValueError(f"{where}: status must be a string, got {type(status).__name__}")
    for name, table in gains.items():
        if name not in GAIN_SETS:
            raise ValueError(f"{where}: gains.{str(name)[:40]} is not one of {', '.join(GAIN_SETS)}")
        if table is None:
            continue
        if not _table(table, where, f"gains.{name}"):
            raise ValueError(f"{where}: gains.{name} is empty (a table of the tuned gains' values)")
        # a mechanical speed observer's free gains are named by their path (speed.k1; jaxobs_tuning.job.components)
        _numbers(table, (*allowed, *(f"speed.{k}" for k in MECHANICAL_GAINS)), where, f"gains.{name}")
    if "tuned" not in gains or (gains["tuned"] is None and status not in ("diverged", "overflow")):
        raise ValueError(f"{where}: gains.tuned must be a table of gain values")
    if "ts" in res and not (_is_number(res["ts"]) and res["ts"] > 0):
        raise ValueError(f"{where}: ts must be a sample time > 0 s, got {json.dumps(res['ts'])[:40]}")
    if res.get("omega_n") is not None and not _is_number(res["omega_n"]):
        raise ValueError(f"{where}: omega_n must be a finite number or null, got {json.dumps(res['omega_n'])[:40]}")
    if "scores" in res:  # (the rule is checked where it is read: jaxobs_tuning.export's parse_rule)
        _table(res["scores"], where, "scores")
    for name, sc in res.get("scores", {}).items():
        if sc is not None:
            _table(sc, where, f"scores.{str(name)[:40]}")
    for key in ("machine", "loop"):
        if res.get(key) is not None and not isinstance(res[key], str):
            raise ValueError(f"{where}: {key} must be a string, got {type(res[key]).__name__}")
    if not any(t is not None for t in gains.values()):
        raise ValueError(f"{where}: gains holds no design (initial, closed_form and tuned all null or absent)")
    if "values" in res:  # every constructor value of each design (what `jaxobs envelope` builds)
        values = _table(res["values"], where, "values")
        for name, table in values.items():
            if name not in GAIN_SETS:
                raise ValueError(f"{where}: values.{str(name)[:40]} is not one of {', '.join(GAIN_SETS)}")
            if table is None:
                continue
            if not _table(table, where, f"values.{name}"):
                raise ValueError(f"{where}: values.{name} is empty (a table of the design's values)")
            if "speed" in table:  # a speed estimator's record ([observer.speed], its tuned gains)
                try:
                    speed_from_spec(table["speed"], f"values.{name}.speed")
                except ValueError as e:
                    raise ValueError(f"{where}: {' '.join(str(e).split())[:160]}") from None
            # and the sample period where the job's drive file sets it (its 1/f_sample_hz), and a LESO's faded phase
            # detector where the job's [observer.speed] sets it (jaxobs_tuning.job.schema: zero_fade)
            plain = {k: v for k, v in table.items() if k != "speed"}
            _numbers(plain, (*allowed, "ts", *_speed_keys(job)), where, f"values.{name}")
        if not any(t is not None for t in values.values()):
            raise ValueError(f"{where}: values holds no design (initial, closed_form and tuned all null or absent)")
    # a JobError (a ValueError of one line) names the job's field; its recordings are not read (no base folder:
    # a result.json lies elsewhere than its job file)
    parsed = parse_job(job)
    for top in ("gains", "values"):
        for name, table in (res.get(top) or {}).items():
            if table is not None:
                _check_bounds(parsed, table, where, f"{top}.{name}", closed=name == "closed_form")
    return res


def _speed_keys(job: dict) -> tuple[str, ...]:
    """The constructor values a job's ``[observer.speed]`` adds beside the speed record: ``zero_fade`` where set."""
    speed = job.get("observer", {}).get("speed") if isinstance(job.get("observer"), dict) else None
    return ("zero_fade",) if isinstance(speed, dict) and "zero_fade" in speed else ()


def load_result(path: str | os.PathLike) -> dict:
    """The parsed ``result.json`` of a tuning run, checked against :func:`check_result`'s schema.

    Read as a regular file of at most :data:`MAX_RESULT_BYTES`, its nesting checked before the JSON parser
    sees it.

    Args:
        path: The ``result.json``.

    Returns:
        The result, a dict.

    Raises:
        ValueError: An unreadable, oversized, non-UTF-8 or invalid file, or one that fails the schema.
    """
    where = f"result file {str(path)[:120]!r}"
    try:
        data = read_file(Path(path), MAX_RESULT_BYTES)
    except ValueError as e:
        raise ValueError(f"result file: {e}") from None
    try:
        text = data.decode()
    except UnicodeDecodeError as e:
        raise ValueError(f"{where}: not UTF-8 text (byte {e.start})") from None
    check_nesting(text, where)
    try:
        res = json.loads(text, parse_constant=_no_constant)
    except (json.JSONDecodeError, ValueError, RecursionError) as e:
        raise ValueError(f"{where}: not valid JSON: {str(e)[:80]}") from None
    return check_result(res, where)


def result_designs(result: dict, where: str = "result") -> dict:
    """Every design of a checked result (:func:`load_result`) by its constructor values: {name: component}.

    Args:
        result: A checked result.
        where: The file's name in errors.

    Returns:
        name -> the component built from its ``values`` (the designs whose values are null left out).

    Raises:
        ValueError: no ``values`` table (not a ``jaxobs tune`` result.json), or values a constructor refuses.
    """
    values = result.get("values")
    if not isinstance(values, dict):
        raise ValueError(f"{where}: no 'values' (each design's constructor values): not a `jaxobs tune` result.json")
    ctor = COMPONENTS[result["component"]].ctor
    designs = {}
    for name, v in values.items():
        if v is None:
            continue
        try:
            designs[name] = ctor(**v)
        except (TypeError, ArithmeticError) as e:
            raise ValueError(f"{where}: values.{name}: {' '.join(str(e).split())[:120]}") from None
    return designs


def tuned_component(result: dict) -> AbstractObserver:
    """The tuned component of a result: the job's component values with the tuned gains set.

    The job's values are rebuilt by :func:`jaxobs_tuning.parse_job` (its defaults,
    then the job's ``[component]`` table), so the design equals the one the
    run tuned and scored.

    Args:
        result: A result (:func:`load_result`).

    Returns:
        The tuned component.

    Raises:
        ValueError: Nothing was tuned (``gains.tuned`` is null), or the result's job names another component.
    """
    if result["gains"]["tuned"] is None:
        raise ValueError(f"result: gains.tuned is null (status {result.get('status')!r}): nothing was tuned")
    job = parse_job(result["job"])
    if job.component != result["component"]:
        raise ValueError(f"result: component {result['component']!r} differs from the job's {job.component!r}")
    free = {g.name for g in job.gains}
    for name in result["gains"]["tuned"]:
        if name not in job.values and name not in free:
            raise ValueError(f"result: gains.tuned.{name} is not a value of {job.component}")
    info = COMPONENTS[job.component]
    tuned = {k: float(v) for k, v in result["gains"]["tuned"].items()}
    return info.ctor(**info.values_with(job.values, tuned))
