"""A drive job, a drive study and the export design a component at the drive file's period, not at its class's
default: the reduced-order flux observer's speed gains are the matched pole α' = (1 − e^{−α_o T_s})/T_s
(jaxobs/observers/rofo.py), so a closed form computed at 100 µs and run at the PM-SyRM's 125 µs is another design
(kθ 618.55 against 616.14 1/s), and a job whose "tuned" design is its closed form would score a design that is not.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from jaxobs.drive import read_drive
from jaxobs.observers.rofo import ROFO_ALPHA_O_HZ, ReducedOrderFluxObserver, speed_gains
from jaxobs.studies.registry import closed_form_gains, registered

ROOT = Path(__file__).resolve().parents[1]
SAT_JOB = ROOT / "docs" / "examples" / "pmsyrm_sat_tune.toml"
PMSYRM = ROOT / "docs" / "examples" / "pmsyrm_5p6kw_sat.toml"


def test_the_drive_file_runs_at_another_period_than_the_default():
    """The premise: the PM-SyRM file samples at 8 kHz, and the matched pole moves between 100 and 125 µs."""
    assert read_drive(PMSYRM).ts == pytest.approx(1.25e-4, rel=1e-12)
    assert speed_gains(ROFO_ALPHA_O_HZ, 1.25e-4)[0] == pytest.approx(616.1414, rel=1e-6)
    assert speed_gains(ROFO_ALPHA_O_HZ, 1e-4)[0] == pytest.approx(618.5515, rel=1e-6)


def test_the_registry_gives_the_defaults_and_the_closed_form_at_a_period():
    """``defaults_at(ts)`` is the closed form at ts; ``closed_form_gains`` takes the component's ts."""
    e = registered("rofo")
    kt, kw = speed_gains(ROFO_ALPHA_O_HZ, 1.25e-4)
    d = e.defaults_at(1.25e-4)
    assert (d["k_theta"], d["k_omega"]) == pytest.approx((kt, kw), rel=1e-12)
    assert e.defaults_at(None) == e.defaults and "ts" not in d
    comp = ReducedOrderFluxObserver(**d, ts=1.25e-4)
    cf = closed_form_gains("rofo", comp)
    assert (cf["k_theta"], cf["k_omega"]) == pytest.approx((kt, kw), rel=1e-6)
    # a class whose closed form does not depend on the period keeps its defaults
    assert registered("cleso").defaults_at(1.25e-4) == registered("cleso").defaults


def test_a_drive_jobs_designs_run_the_closed_form_at_the_drive_files_period(tmp_path):
    """The saturation job (c_σ and ζ∞ free) runs its initial, closed-form and tuned designs with the speed gains of
    the closed form at the drive file's 125 µs, and a job that frees kθ starts it there."""
    from jaxobs_tuning.job import COMPONENTS, load_job

    kt, kw = speed_gains(ROFO_ALPHA_O_HZ, 1.25e-4)
    job = load_job(SAT_JOB)
    assert job.values["ts"] == pytest.approx(1.25e-4, rel=1e-12)
    assert (job.values["k_theta"], job.values["k_omega"]) == pytest.approx((kt, kw), rel=1e-12)
    info = COMPONENTS[job.component]
    comp = info.ctor(**job.values)
    cf = info.closed_form(comp, job.values)
    assert (cf["k_theta"], cf["k_omega"]) == pytest.approx((job.values["k_theta"], job.values["k_omega"]), rel=1e-6)
    text = SAT_JOB.read_text().replace("[gains.zeta_inf]", "[gains.k_theta]\nlower = 10.0\n\n[gains.zeta_inf]")
    (tmp_path / "job.toml").write_text(text)
    (tmp_path / PMSYRM.name).write_text(PMSYRM.read_text())
    free = {g.name: g for g in load_job(tmp_path / "job.toml").gains}
    assert free["k_theta"].init == pytest.approx(kt, rel=1e-12)


def test_a_drive_studys_closed_form_runs_at_the_drive_files_period():
    """A study's ``closed_form = "rofo"`` design on a drive file is designed at the file's period."""
    from jaxobs_tuning.study_file import _drive_designs

    designs = _drive_designs({"designs": {"cf": {"closed_form": "rofo"}}}, ROOT, 1.25e-4)[0]
    obs = designs["cf"]
    assert float(obs.ts) == pytest.approx(1.25e-4, rel=1e-12)
    assert (float(obs.k_theta), float(obs.k_omega)) == pytest.approx(speed_gains(ROFO_ALPHA_O_HZ, 1.25e-4), rel=1e-6)


SAT_V5 = ROOT / "benchmarks" / "results" / "2026-12-03-pmsyrm-sat-tune-v5-result.json"
MISMATCH_V5 = ROOT / "benchmarks" / "results" / "2026-12-03-saturation-mismatch-v5.json"


def test_the_stored_saturation_tuning_rebuilds_at_the_drive_period_and_cuts_the_worst_case():
    """The job's stored run (Nelder–Mead, benchmarks/results/2026-12-03-pmsyrm-sat-tune-v5.txt) rebuilds its tuned
    design and its closed form with the speed gains of 125 µs; the benchmark's stored run of it
    (…-saturation-mismatch-v5.json) has the tuned design's worst steady peak over dsat −0.5…2 × 540, 900,
    1440 r/min below the closed form's (15.20° against 21.11°), lock held in every scenario, and every scenario out
    of the job's grid with a mismatch lower than the closed form's (at the matched map, 540 r/min, out of the grid:
    0.03° against 0.00°)."""
    import json

    from jaxobs_tuning.results import load_result, result_designs, tuned_component

    res = load_result(SAT_V5)
    kt, kw = speed_gains(ROFO_ALPHA_O_HZ, 1.25e-4)
    tuned, cf = tuned_component(res), result_designs(res, str(SAT_V5))["closed_form"]
    for obs in (tuned, cf):
        assert isinstance(obs, ReducedOrderFluxObserver) and float(obs.ts) == pytest.approx(1.25e-4, rel=1e-12)
        assert (float(obs.k_theta), float(obs.k_omega)) == pytest.approx((kt, kw), rel=1e-9)
    assert isinstance(tuned, ReducedOrderFluxObserver)
    assert float(tuned.c_sigma) == pytest.approx(res["gains"]["tuned"]["c_sigma"], rel=1e-9)
    assert res["job"]["solver"]["kind"] == "nelder_mead" and res["job"]["scenarios"]["grid"]["dsat"] == [0.0, 1.0, 2.0]
    bench = json.loads(MISMATCH_V5.read_text())
    s = bench["summary"]
    assert s["rofo_tuned"]["worst_peak_deg"] < 0.8 * s["rofo"]["worst_peak_deg"]
    assert s["rofo_tuned"]["lost_lock"] == [] and s["rofo"]["lost_lock"] == []
    rows = bench["tuned"]
    by = {(r["design"], r["dsat"], r["speed_rpm"]): r for r in rows}
    out = [(d, v) for (name, d, v), r in by.items() if name == "rofo" and not r["in_grid"]]
    assert len(out) == 9
    for d, v in out:
        tuned_pk, cf_pk = by[("rofo_tuned", d, v)]["peak_deg"], by[("rofo", d, v)]["peak_deg"]
        assert tuned_pk < cf_pk if d != 0.0 else tuned_pk < cf_pk + 0.05, (d, v, tuned_pk, cf_pk)


@pytest.mark.slow
def test_the_tuned_design_keeps_a_rated_load_step_where_its_low_damping_could_show():
    """ζ∞ 0.088 damps the flux poles less than the closed form's 0.2, which the job's steady runs do not score: a
    rated load step (0 → 29.7 N·m at 0.1 s, 1440 r/min, scored from the step to 0.4 s) on the matched map reads as
    the closed form's (measured 0.56° peak both: with an exact model the flux error, which the gains act on, stays
    near 0), and at dsat 1 the tuned design's peak is below the closed form's (measured 4.18° against 5.54°)."""
    import jax
    import numpy as np

    from jaxobs.scenarios.families.drive import DriveScenarios
    from jaxobs.studies.study import run_study
    from jaxobs_tuning.results import load_result

    jax.config.update("jax_enable_x64", True)
    g = load_result(SAT_V5)["gains"]["tuned"]
    f = read_drive(PMSYRM)
    drive = f.drive_for(sensorless=True)
    designs = {
        "cf": ReducedOrderFluxObserver.closed_form(ts=drive.ts),
        "tuned": ReducedOrderFluxObserver.closed_form(ts=drive.ts, c_sigma=g["c_sigma"], zeta_inf=g["zeta_inf"]),
    }
    axes = {"speed_rpm": [1440.0], "load_nm": [0.0], "load_step_nm": [29.7], "dsat": [0.0, 1.0]}
    family = DriveScenarios(f.machine, drive, t_event=0.1)  # type: ignore[arg-type]  # a single machine's drive
    ds = run_study(designs, axes, family=family, horizon=0.4, steady_from=0.1)
    assert not isinstance(ds, tuple) and not ds["lost_lock"].values.any()
    peak = np.degrees(ds["peak_position_steady"].values.reshape(2, 2))  # design x dsat
    print("rated load step, peak deg (design x dsat 0, 1):", peak.round(2).tolist())
    assert peak[1, 0] == pytest.approx(peak[0, 0], abs=0.05), peak
    assert peak[1, 1] < 0.8 * peak[0, 1], peak
