"""Reading a tuning run's ``result.json`` back: the tuned design as a component.

``run_job`` writes ``result.json`` (the job as given, the component's name,
the initial / tuned / closed-form gains, the scores).  Whoever wants the tuned
design back (a robustness study, a notebook) reads it here, in the layer that
wrote it; the library only ever receives the component itself::

    obs = tuned_component(load_result("out/wif-robust/result.json"))
    ds = run_study({"tuned": obs}, axes)            # jaxobs.study.run_study

Errors are ``ValueError``s of one line that name the file and the field.
"""

from __future__ import annotations

import json
from pathlib import Path

from .job import COMPONENTS, parse_job

__all__ = ["load_result", "tuned_component"]


def load_result(path) -> dict:
    """The parsed ``result.json`` of a tuning run (checked for the fields :func:`tuned_component` needs)."""
    where = f"result file {str(path)!r}"
    try:
        res = json.loads(Path(path).read_text())
    except OSError as e:
        raise ValueError(f"{where}: cannot read: {e.strerror}") from None
    except json.JSONDecodeError as e:
        raise ValueError(f"{where}: not valid JSON: {e}") from None
    if not isinstance(res, dict):
        raise ValueError(f"{where}: not a tuning result (a JSON object with job, component and gains)")
    for key in ("job", "component", "gains"):
        if key not in res:
            raise ValueError(f"{where}: not a tuning result (no {key!r})")
    if not isinstance(res["gains"], dict) or not isinstance(res["gains"].get("tuned"), dict):
        raise ValueError(f"{where}: gains.tuned must be a table of gain values")
    return res


def tuned_component(result: dict):
    """The tuned component of a result: the job's component values with the tuned gains set.

    The job's values are rebuilt by :func:`tuning.parse_job` (its defaults,
    then the job's ``[component]`` table), so the design equals the one the
    run tuned and scored.
    """
    job = parse_job(result["job"])
    if job.component != result["component"]:
        raise ValueError(f"result: component {result['component']!r} differs from the job's {job.component!r}")
    values = dict(job.values)
    for name, v in result["gains"]["tuned"].items():
        if name not in values:
            raise ValueError(f"result: gains.tuned.{name} is not a value of {job.component}")
        values[name] = float(v)
    return COMPONENTS[job.component].ctor(**values)
