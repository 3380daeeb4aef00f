"""Running a job: tune, score initial / closed form / tuned on the same scenarios, write the results folder."""

from __future__ import annotations

import hashlib
import json
import sys
import time
from pathlib import Path

import equinox as eqx
import jax
import numpy as np

from jaxobs.drive.drivefile import DriveFile
from jaxobs.io.provenance import versions
from jaxobs.runtime.progress import Progress

from ..objective import MetricContext, Objective
from ..outdir import atomic_path, atomic_write_text
from ..params import GainSpec, Parametrization
from ..report import objective_text, report_figures
from ..solvers import TuneResult, tune
from ..structure import structure
from .components import COMPONENTS
from .drive import job_drive
from .output import at_bounds, claimed_envelope, recordings_provenance, rule_spec, scores_dataset, write_json
from .recordings import scenarios_window
from .scenarios import build_scenarios, job_family
from .spec import DriveSpec, Job, ScenarioSpec
from .verify import EnvelopeSpec, verify_designs


def build_objective(
    job: Job, spec: ScenarioSpec | None = None
) -> tuple[Objective, eqx.Module, tuple[list[str], list[tuple]]]:
    """The job's objective and the scenario batch it is called with.

    Args:
        job: The parsed :class:`Job`.
        spec: The scenarios (default: the job's tuning set; its held-out set for the holdout scores).

    Returns:
        ``(objective, scenarios, (axis names, points))``: the :class:`Objective` and its batch.
    """
    spec = job.scenarios if spec is None else spec
    comp = COMPONENTS[job.component].ctor(**job.values)
    drive = job_drive(job.drive) if spec.family.closed_loop and spec.recording is None else None
    # the family makes each scenario's system: the observer bound to it (a drive scenario's assumed machine and
    # speed, a recording's speed), on its signal or closing the drive's loop
    family = job_family(spec, job.values, drive, job.drive)
    scen, names, combos = build_scenarios(spec, family)
    ctx = MetricContext(t_event=spec.t_event, steady_from=spec.steady_from)
    if spec.recording is not None and spec.recording.startup_periods:  # scored past the observer's start-up
        _, t_event, steady = scenarios_window(spec, scen)
        ctx = MetricContext(t_event=t_event, steady_from=steady)
    param = Parametrization(job.gains)
    obj = Objective(
        comp,
        param,
        horizon=spec.horizon,
        terms=job.terms,
        ctx=ctx,
        aggregation=job.aggregation,
        penalty=job.penalty,
        family=family,
    )
    return obj, scen, (names, combos)


def _inside(g: GainSpec, v: float) -> float:
    """A closed-form value nudged inside the gain's open bounds (the parametrization cannot reach them)."""
    if g.lower is not None:
        v = max(v, g.lower * (1 + 1e-9))
    if g.upper is not None:
        v = min(v, g.upper * (1 - 1e-9))
    return float(v)


def _score_designs(
    obj: Objective, scenarios: eqx.Module, thetas: dict, bar: Progress, what: str, responses: bool = False
) -> tuple[dict, dict, dict | None]:
    """Each design's per-scenario scores and their summary, one progress step each (the first one compiles);
    with ``responses``, each design's response on the scenario where the closed form does worst.

    Returns:
        ``(per, summaries, responses)``: :meth:`Objective.per_scenario` and :meth:`Objective.summarize` by label;
        ``{"worst": index, label: (t, omega, err)}`` or None.
    """
    per, summary = {}, {}
    for i, (k, th) in enumerate(thetas.items()):
        bar.stage(f"{what}{k}" + (" (compiling the metrics)" if i == 0 else ""))
        per[k] = obj.per_scenario(th, scenarios)
        summary[k] = obj.summarize(*per[k])
        bar.update()
    if not responses:
        return per, summary, None
    # the report's responses: on the scenario where the closed form does worst, on the host (no gather to compile)
    worst = int(np.argmax(np.asarray(per["closed_form"][1])))
    sig = jax.tree.map(lambda x: np.asarray(x)[worst], scenarios)
    drawn = {k: tuple(np.asarray(x) for x in obj.response(th, sig)) for k, th in thetas.items()}
    return per, summary, {"worst": worst, **drawn}


CHECKPOINT = "checkpoint.npz"


def _lost_only(per: dict) -> int | None:
    """Scenarios where the tuned design lost lock (or diverged) and the closed form did not (None: no tuned)."""
    if "tuned" not in per:
        return None
    lost = {k: np.asarray(per[k][0]["lost_lock"] | ~per[k][2]) for k in ("tuned", "closed_form")}
    return int(np.sum(lost["tuned"] & ~lost["closed_form"]))


def _verify(
    job: Job, env: EnvelopeSpec, drive: DriveSpec, df: DriveFile, values: dict, result: dict, quiet: bool
) -> None:
    """Initial, closed form and tuned over ``[envelope]`` (:func:`verify_designs`) into ``result``; a tuned
    design that fails where the closed form holds turns the status to ``"unsafe"`` (the solver's own status
    stays in ``tuning_status``)."""
    if not quiet:
        print(f"jaxobs: verifying the designs over {env.horizon:g} s across the envelope", file=sys.stderr)
    info = COMPONENTS[job.component]
    designs = {k: info.ctor(**v) for k, v in values.items() if v is not None}
    ver = verify_designs(designs, env, drive, df.machine, seed=job.seed)  # the drive file's sensors' noise
    result["verification"] = ver
    result["tuning_status"] = result["status"]
    if ver["unsafe_points"]:
        pts = ", ".join(f"{p['speed_rpm']:g} r/min {p['load_nm']:g} N·m" for p in ver["unsafe_points"])
        result["status"] = "unsafe"
        result["reason"] = (
            f"the tuned design loses stability or synchronism inside its stated envelope where the closed form "
            f"holds ({pts}); the solver: {result['reason']}"
        )


def job_fingerprint(job: Job) -> str:
    """What a checkpoint is checked against: the job file's sha256, or the sha256 of the job dict's JSON.

    Args:
        job: The parsed :class:`Job`.

    Returns:
        The hex digest, with the recordings' digests folded in where the job runs on recordings.
    """
    fp = job.sha256 or hashlib.sha256(json.dumps(job.raw, sort_keys=True, default=str).encode()).hexdigest()
    recs = [s.recording.sha256 for s in (job.scenarios, job.holdout) if s is not None and s.recording is not None]
    if any(recs):  # a checkpoint is this job's only on the same recordings
        fp = hashlib.sha256((fp + "".join(d for r in recs for d in r)).encode()).hexdigest()
    return fp


def _designs(
    job: Job, obj: Objective, theta0: jax.Array, tuned: jax.Array | None
) -> tuple[dict, dict, dict, dict, str]:
    """The designs a job scores: ``(thetas, gains, values, drawn, closed-form source)``.

    ``thetas``: each scored design's θ (the closed form nudged inside the gains' open bounds, which the
    parametrization cannot reach; no tuned design where it is None); ``gains``: the free gains reported (the
    closed form exactly; None: no tuned design); ``values``: every constructor value; ``drawn``: the free gains
    at each scored θ (the report's legend); the closed form's source, in one line.
    """
    param = obj.param
    info = COMPONENTS[job.component]
    cf_all = info.closed_form(obj.component, job.values)
    cf = {g.name: cf_all[g.name] for g in job.gains}
    thetas = {"initial": theta0, "closed_form": param.to_theta({g.name: _inside(g, cf[g.name]) for g in job.gains})}
    if tuned is not None:  # never a design that diverged in some scenario
        thetas["tuned"] = tuned
    gains = {
        "initial": param.values(theta0),
        # the closed form is reported exactly; it is scored at θ nudged inside the gains' open bounds
        "closed_form": {g.name: float(cf[g.name]) for g in job.gains},
        "tuned": param.values(tuned) if tuned is not None else None,
    }
    # a LESO's [observer.speed] record stays a record (jaxobs.observers.speed.speed_from_spec)
    fixed = {k: (v if isinstance(v, dict) else float(v)) for k, v in job.values.items() if k not in param.names}
    # a dotted gain (speed.k1) goes inside its record
    values = {k: (None if g is None else info.values_with(fixed, g)) for k, g in gains.items()}
    drawn = {k: {n: float(v) for n, v in param.values(th).items()} for k, th in thetas.items()}
    return thetas, gains, values, drawn, info.closed_form_source


def _outcome(
    job: Job, obj: Objective, scen: eqx.Module, theta0: jax.Array, per: dict, res: TuneResult, n: int
) -> tuple[str, str]:
    """The job's status and reason: the solver's, or ``"overflow"`` where the objective overflows on finite
    simulations (``n``: the scenarios)."""
    status, reason = res.status, res.reason
    n_over = obj.overflowed(theta0, scen, per["initial"][2]) if status == "diverged" else 0
    if status == "overflow" or n_over:
        # nothing diverged: the simulations and the scored metrics are finite, the objective's value or
        # gradient is not (a weight of 1e308 is no divergence of the system).  The solver checks every
        # iteration and stops at the first overflow; the initial design's scores check it once more.
        weights = ", ".join(f"terms[{i}].weight = {t.weight:g}" for i, t in enumerate(job.terms))
        where = (
            reason
            if status == "overflow"
            else f"the objective overflows: its value or gradient is not finite in {n_over} of {n} "
            "scenarios whose simulation is finite"
        )
        status = "overflow"
        reason = f"{where} (objective.{weights}): lower the weights; nothing is tuned"
    return status, reason


def _null_reasons(job: Job, status: str, tuned: dict | None) -> dict[str, str]:
    """Why the result's nulls are null: no nominal frequency, nothing tuned."""
    nulls = {}
    if "omega_n" not in job.values:
        nulls["omega_n"] = f"{job.component} has no nominal frequency omega_n"
    if tuned is None:
        why = (
            "status 'overflow': the objective overflows, so nothing is tuned"
            if status == "overflow"
            else "status 'diverged': every design tried diverged in some tuning scenario, so nothing is tuned"
        )
        for key in ("gains.tuned", "values.tuned", "scores.tuned", "linear.tuned", "lost_lock_tuned_only"):
            nulls[key] = why
    return nulls


def _drive_result(job: Job, df: DriveFile, result: dict, nulls: dict) -> None:
    """A drive job's machine, the note on its per-scenario values and the envelope it claims, into ``result``
    (``nulls``: why the envelope is not verified)."""
    result["machine"] = job.drive.machine if job.drive is not None else None
    result["values_note"] = (
        "Rs, Lq (LESOs) or Rs, L (flux observers) and the PLL's or FLL's initial speed (omega0_pll, omega_init) "
        f"are set per scenario from its estimated machine ({df.description})"
    )
    # the envelope it was tuned for; where the designs hold is `jaxobs envelope RESULT.json`
    result["envelope"] = claimed_envelope(job)
    if result["envelope"] is not None and job.envelope is not None:  # [envelope]: checked after tuning
        result["envelope"]["verified"] = "see 'verification' (the job's [envelope] grid, after tuning)"
    elif result["envelope"] is not None:
        nulls["envelope.verified"] = "not run after tuning: `jaxobs envelope <result.json>` maps it"


def _score_holdout(job: Job, holdout: ScenarioSpec, thetas: dict, bar: Progress, result: dict, out: Path) -> None:
    """The designs' held-out scores into ``result`` and ``holdout_scores.nc``."""
    hobj, hscen, (hn, hc) = build_objective(job, holdout)
    hper, hsum, _ = _score_designs(hobj, hscen, thetas, bar, "held-out ")
    held: dict[str, dict | int | None] = {k: hsum.get(k) for k in result["gains"]}
    held["count"] = len(hc)
    result["holdout"] = held
    result["lost_lock_tuned_only"]["holdout"] = _lost_only(hper)
    with atomic_path(out / "holdout_scores.nc") as tmp:
        scores = scores_dataset(hobj, hn, hc, holdout, hper, title="jaxobs tune: per-scenario scores, held out")
        scores.to_netcdf(tmp, engine="h5netcdf")


def run_job(job: Job, out: Path, resume: bool = False, quiet: bool = False) -> dict:
    """Tune, score initial / tuned / closed form on the same scenarios, write the results folder.

    ``result.json`` (outcome, gains, every constructor value, scores, linear structure, what is needed to
    rebuild the design) and ``history.json`` are byte-identical for two runs of one job; the timings go
    to ``timing.json``, the per-scenario scores to ``scores.nc`` (and ``holdout_scores.nc``).

    Args:
        job: The parsed :class:`Job`.
        out: The results folder (created).
        resume: Continue from the folder's checkpoint.
        quiet: No progress lines.

    Returns:
        The result, as written to ``result.json``.
    """
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    obj, scen, (names, combos) = build_objective(job)
    theta0 = obj.param.theta0()
    res = tune(
        obj,
        job.solver,
        theta0,
        scenarios=scen,
        checkpoint=out / CHECKPOINT,
        resume=resume,
        quiet=quiet,
        fingerprint=job_fingerprint(job),
    )
    thetas, gains, values, drawn, cf_source = _designs(job, obj, theta0, res.theta)
    n_scored = len(thetas) * (2 if job.holdout is not None else 1)
    bar = Progress(not quiet and "auto", n_scored, "score", unit="design")
    per, summary, responses = _score_designs(obj, scen, thetas, bar, "", responses=True)
    assert responses is not None  # asked for
    scores = {k: summary.get(k) for k in gains}
    status, reason = _outcome(job, obj, scen, theta0, per, res, len(combos))
    bar.stage("linear structure of each design (margins, poles)")
    lin = {k: (None if v is None else structure(job.component, v, job)) for k, v in values.items()}
    result = {
        "status": status,
        "reason": reason,
        "job": job.raw,
        "job_sha256": job.sha256,
        "component": job.component,
        "loop": "open loop on recordings"
        if job.scenarios.recording is not None
        else (None if job.drive is None else job.drive.loop),
        "start": None if job.drive is None else job.drive.start,
        "ts": float(obj.component.ts),
        "rule": rule_spec(obj.component.rule),
        "omega_n": float(job.values["omega_n"]) if "omega_n" in job.values else None,
        "closed_form_source": cf_source,
        "gains": gains,
        "values": values,
        "at_bound": at_bounds(job, gains["tuned"]) if gains["tuned"] is not None else {},
        "scores": scores,
        "linear": lin,
        "scenarios": {"axes": names, "count": len(combos)},
        **recordings_provenance(job, scen),
        "iterations": res.iterations,
        "best_iteration": res.best_iteration,
        "versions": versions(),
    }
    nulls = _null_reasons(job, status, gains["tuned"])
    df = job.drive.drive_file if job.drive is not None else None  # the drive file the job runs, read once here
    if job.drive is not None and df is not None:
        _drive_result(job, df, result, nulls)
    if nulls:
        result["null_reasons"] = nulls
    result["lost_lock_tuned_only"] = {"tuning": _lost_only(per)}
    if job.holdout is not None:
        _score_holdout(job, job.holdout, thetas, bar, result, out)
    bar.close()
    if (
        job.envelope is not None and job.drive is not None and df is not None
    ):  # the long-horizon verification across the claimed envelope
        _verify(job, job.envelope, job.drive, df, values, result, quiet)
    with atomic_path(out / "scores.nc") as tmp:
        scores_dataset(obj, names, combos, job.scenarios, per).to_netcdf(tmp, engine="h5netcdf")
    write_json(out / "history.json", res.history)
    figures = report_figures(
        job, job.scenarios.family, objective_text(obj), res.history, responses, drawn, best_iteration=res.best_iteration
    )
    for name, fig in figures.items():
        with atomic_path(out / name) as tmp:
            fig.savefig(tmp, dpi=110)
    timing = {"total_s": time.time() - t0, **res.timing, "iterations": res.iterations}
    atomic_write_text(out / "timing.json", json.dumps(timing, indent=1) + "\n")
    write_json(out / "result.json", result)  # last: a result.json means a complete results folder
    return result
