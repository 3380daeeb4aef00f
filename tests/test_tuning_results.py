"""What a tuning job reports: an honest outcome (diverged, at a bound, never NaN), the linear structure of
the tuned design, byte-identical reproducible results, BFGS's iterations; and the flux observers
of paper 000 tuned as sensorless drive jobs on its SPMSM.  Tuning itself and the job files: tests/test_tuning.py."""

import dataclasses
import json
import math
import time
from pathlib import Path

import jax
import numpy as np
import pytest

from jaxobs import drive as D
from jaxobs import linear, papers
from jaxobs.io.provenance import by_label
from jaxobs_tuning import load_job
from jaxobs_tuning.cli import main
from jaxobs_tuning.targets import flux_settling_time
from tests.cfcheck import assert_cf18
from tests.test_tuning import GOOD

W_N = papers.FLL_OMEGA_N


# --------------------------------------------------------------------------
# honest outcome, linear structure, reproducible results, BFGS
# --------------------------------------------------------------------------

UNSTABLE = GOOD.replace(
    "[gains.lam]\ninit = 12337.0\nlower = 1000.0\nupper = 100000.0",
    "[gains.k]\ninit = 40.0\nlower = 0.01\nupper = 100.0",
)


def _strict_json(path):
    """result.json parsed with NaN / Infinity tokens refused."""

    def refuse(token):
        raise AssertionError(f"{path.name} holds a bare {token}")

    return json.loads(path.read_text(), parse_constant=refuse)


def test_unstable_start_exits_3_with_status_diverged_and_no_nan(tmp_path, capsys):
    """k = 40 diverges in every scenario: status "diverged", exit 3, no tuned gains, null (with a reason)
    where the metrics are undefined, never a bare NaN token."""
    path = tmp_path / "job.toml"
    path.write_text(UNSTABLE)
    assert main(["tune", str(path), "--out", str(tmp_path / "o"), "--quiet"]) == 3
    assert "DIVERGED" in capsys.readouterr().out
    res = _strict_json(tmp_path / "o" / "result.json")
    assert res["status"] == "diverged"
    assert res["gains"]["tuned"] is None and res["scores"]["tuned"] is None
    assert res["scores"]["initial"]["diverged"] == 2 and res["scores"]["initial"]["itae_freq_mean"] is None
    assert "gains.tuned" in res["null_reasons"] and res["scores"]["initial"]["null_reason"]
    assert all(h["diverged"] == 2 for h in _strict_json(tmp_path / "o" / "history.json"))


def test_tiny_penalty_and_huge_steps_never_report_diverging_gains_as_tuned(tmp_path):
    """penalty = 1e-9 makes diverging cheaper than tracking and a learning rate of 3 jumps there at once:
    every iterate after the first diverges; the stable initial design comes back, as "no_improvement"."""
    text = (
        GOOD.replace("steps = 3", "steps = 3\nlearning_rate = 3.0\npatience = 100")
        .replace("upper = 100000.0", "upper = 1.0e9")
        .replace("[objective]", "[objective]\npenalty = 1e-9")
    )
    path = tmp_path / "job.toml"
    path.write_text(text)
    assert main(["tune", str(path), "--out", str(tmp_path / "o"), "--quiet"]) == 0
    res = _strict_json(tmp_path / "o" / "result.json")
    hist = _strict_json(tmp_path / "o" / "history.json")
    assert any(h["diverged"] for h in hist)  # the solver did wander into divergence
    assert res["status"] == "no_improvement" and "diverged" in res["reason"]
    assert res["scores"]["tuned"]["diverged"] == 0
    assert res["gains"]["tuned"]["lam"] == pytest.approx(12337.0)
    best = [h for h in hist if h["iteration"] == res["best_iteration"]][0]
    assert best["diverged"] == 0


def test_gain_at_a_bound_is_flagged(tmp_path, capsys):
    """A gain that ends within 1 % of its bound is listed under at_bound and a warning goes to stderr."""
    text = GOOD.replace(
        "init = 12337.0\nlower = 1000.0\nupper = 100000.0", "init = 12337.0\nlower = 1000.0\nupper = 12400.0"
    )
    path = tmp_path / "job.toml"
    path.write_text(text.replace("steps = 3", "steps = 3\nlearning_rate = 1.0"))
    assert main(["tune", str(path), "--out", str(tmp_path / "o"), "--quiet"]) == 0
    res = _strict_json(tmp_path / "o" / "result.json")
    assert res["at_bound"]["lam"]["bound"] == "upper"
    assert "within 1 % of its upper bound" in capsys.readouterr().err


def test_two_runs_write_byte_identical_results_that_rebuild_the_design(tmp_path):
    """result.json and history.json are byte-identical for two runs (timings go to timing.json); they hold
    ts, rule, omega_n, every value, versions and the job file's sha256; export rebuilds the tuned design
    from them; scores.nc has the grid's axis as a dim; the linear structure is there for every design."""
    import hashlib

    import xarray as xr

    from jaxobs_tuning.export import observer_from_result

    path = tmp_path / "job.toml"
    path.write_text(GOOD)
    for o in ("a", "b"):
        assert main(["tune", str(path), "--out", str(tmp_path / o), "--quiet"]) == 0
    for f in ("result.json", "history.json"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes(), f
    res = _strict_json(tmp_path / "a" / "result.json")
    assert res["job_sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert res["versions"]["x64"] is True and res["versions"]["jax"] == jax.__version__
    assert res["rule"] == {"name": "AB3"} and res["ts"] == pytest.approx(1e-4) and res["omega_n"] == W_N
    assert res["values"]["tuned"]["k"] == papers.SOGI_FLL_K and "lam" in res["values"]["tuned"]
    assert "time_s" not in res and "total_s" in json.loads((tmp_path / "a" / "timing.json").read_text())
    hist = _strict_json(tmp_path / "a" / "history.json")
    assert [h["iteration"] for h in hist] == [0, 1, 2, 3] and all("lam" in h["gains"] for h in hist)
    notes = []
    obs = observer_from_result(tmp_path / "a" / "result.json", notes=notes)
    assert float(obs.lam) == res["gains"]["tuned"]["lam"] and obs.ts == res["ts"] and type(obs.rule).__name__ == "AB3"
    assert not any("has no" in n for n in notes)
    assert_cf18(tmp_path / "a" / "scores.nc")  # CF 1.8: compliance-checker, attributes, types
    ds = by_label(xr.open_dataset(tmp_path / "a" / "scores.nc", engine="h5netcdf"))
    assert ds["itae_freq"].dims == ("design", "freq_step") and list(ds["freq_step"].values) == [1.0, 2.0]
    # CF units on every variable and numeric coordinate (NetCDF4)
    for name in [*ds.data_vars, *ds.coords]:
        if name != "design":
            assert ds[name].attrs.get("units"), name
    assert ds["itae_freq"].attrs["units"] == "Hz s2" and ds["freq_step"].attrs["units"] == "Hz"
    assert ds["diverged"].attrs["units"] == "1"
    for d in ("closed_form", "tuned"):
        lin = res["linear"][d]
        assert lin["phase_margin_deg"] > 0 and lin["crossover_hz"] > 0 and 0 < lin["dominant_damping"] <= 1
    # the closed form at the closed-form design: ζ = 1/√2, the rule's λ
    cf = res["linear"]["closed_form"]
    assert cf["dominant_damping"] == pytest.approx(1 / math.sqrt(2), rel=1e-4)
    assert cf["closed_form_rule"]["lam_over_rule"] == pytest.approx(1.0, rel=1e-4)


def test_wif_structure_of_the_symmetric_optimum():
    """At 001's WIF gains the linear model gives the symmetric optimum back: PM 45°, crossover 18.8 Hz,
    ζ = 1/√2 for the pair, b = 1 + √2 and λ = 2ωc²/b at the design's k1, k2."""
    from jaxobs_tuning.structure import structure

    s = structure("SOGIFLLWIF", dict(k1=papers.WIF_K1, k2=papers.WIF_K2, lam=papers.WIF_LAM, omega_n=W_N))
    assert s["phase_margin_deg"] == pytest.approx(45.0, abs=0.1)
    assert s["crossover_hz"] == pytest.approx(18.8, rel=1e-3)
    assert s["dominant_damping"] == pytest.approx(1 / math.sqrt(2), rel=1e-3)
    rule = s["closed_form_rule"]
    assert rule["b_implied"] == pytest.approx(1 + math.sqrt(2), rel=1e-3)
    assert rule["lam_rule"] == pytest.approx(papers.WIF_LAM, rel=1e-3)
    assert s["gain_margin_db"] is None and "gain_margin_db" in s["not_available"]
    fa = structure("FALESO", load_job(Path(__file__).parents[1] / "tuning" / "presets" / "faleso.toml").values)
    assert fa["routh_stable"] is True


def _oracle_dominant(num, den, cancel_tol=None):
    """python-control's dominant damping: the pole of largest real part of the closed loop, after minreal
    cancels pole-zero pairs closer than ``cancel_tol`` rad/s (None: no cancellation)."""
    import control  # python-control, the test extra's oracle: a hard dependency of the suite, never skipped

    t = control.tf(np.asarray(num, dtype=float), np.asarray(den, dtype=float))
    if cancel_tol is not None:
        t = t.minreal(tol=cancel_tol)
    p = np.asarray(t.poles())
    dom = p[np.argmax(p.real)]
    return -dom.real / abs(dom), abs(dom) / (2 * math.pi), len(p)


def test_leso_structure_is_linearized_at_the_jobs_machine_speed(tmp_path):
    """A LESO job's linear structure is taken at its first speed_rpm in electrical rad/s on the job's own machine:
    300 r/min is 5 · 10π rad/s on 002's IPMSM (p = 5) and 3 · 10π on 000's SPMSM (p = 3).  (It used 002's pole
    pairs for every LESO job, so a LESO on the SPMSM was linearized at 5/3 of its speed.)"""
    from jaxobs_tuning.structure import structure

    text = (Path(__file__).parents[1] / "tuning" / "presets" / "faleso.toml").read_text()
    for machine, p in (("ipmsm002", 5), ("spmsm000", 3)):
        f = tmp_path / f"{machine}.toml"
        f.write_text(text.replace('loop = "sensorless"', f'loop = "sensorless"\nmachine = "{machine}"', 1))
        job = load_job(f)
        assert job.drive.machine == machine and D.bench_machine(machine).p == p
        fa = structure("FALESO", job.values, job)
        assert fa["omega_e"] == pytest.approx(300.0 * math.pi / 30 * p, rel=1e-12)
        assert "omega_e = " + f"{fa['omega_e']:.6g}" in fa["model"]


def test_dominant_damping_leaves_out_the_poles_a_zero_cancels():
    """The FA-LESO's PLL loop at 002's closed form (faleso.toml, 300 r/min) has a pole pair at -0.106 ± j157.13
    rad/s (damping 0.0007) with a zero pair 0.03 rad/s away: a doublet left out of the dominant damping, which
    becomes the real dominant mode's (the oracle: python-control after minreal); a loop without a doublet
    (the SOGI-FLL's) is unchanged: nothing cancelled, the oracle without minreal."""
    from jaxobs_tuning.structure import structure

    job = load_job(Path(__file__).parents[1] / "tuning" / "presets" / "faleso.toml")
    v = job.values
    fa = structure("FALESO", v, job)
    we = fa["omega_e"]
    loop = linear.faleso_pll_loop(v["k1"], v["k2"], we, v["kp_pll"], v["ki_pll"]).feedback()
    # 1 rad/s: the doublet is 0.03 rad/s apart; every other pole is > 50 rad/s from every zero
    zeta, hz, n_left = _oracle_dominant(loop.num, loop.den, cancel_tol=1.0)
    assert n_left < len(fa["poles"])  # minreal did cancel something
    assert fa["dominant_damping"] == pytest.approx(zeta, rel=1e-9) and fa["dominant_damping"] > 0.5
    assert fa["dominant_hz"] == pytest.approx(hz, rel=1e-9)
    assert fa["least_pair_damping"] == pytest.approx(zeta, rel=1e-9)  # the remaining complex pair is dominant
    cancelled = [complex(*z) for z in fa["cancelled_poles"]]
    pair = [z for z in cancelled if abs(abs(z.imag) - we) < 1.0]
    assert len(pair) == 2 and all(-z.real / abs(z) < 1e-3 for z in pair)  # the ~0.0007 pair
    raw, _, _ = _oracle_dominant(loop.num, loop.den)
    assert raw < 1e-3  # without the cancellation the dominant pair would be the doublet
    assert fa["stable"] is True and len(fa["poles"]) == 6  # every pole still listed
    # no doublet: unchanged (001's WIF, whose closed loop has a zero: ζ = 1/√2 for its pair)
    wif = structure("SOGIFLLWIF", dict(k1=papers.WIF_K1, k2=papers.WIF_K2, lam=papers.WIF_LAM, omega_n=W_N))
    model = linear.wif_model(papers.WIF_K1, papers.WIF_K2, papers.WIF_LAM, W_N).frequency
    assert wif["cancelled_poles"] == []
    zeta, hz, _ = _oracle_dominant(model.num, model.den)
    assert wif["dominant_damping"] == pytest.approx(zeta, rel=1e-9) and wif["dominant_hz"] == pytest.approx(hz)


def test_sosoifo_structure_gives_the_settling_time_k1_rule_at_its_k2():
    """000's rule (equal 2 % envelope settling with the SOIFO at k = 1.414: 17.6 ms at 100π rad/s) at the
    design's K2: at 000's K2 = 3.11 the smallest K1 that settles as fast is 0.949 (000 chose 1.56, 17.2 ms);
    just below it the settling is slower; at K2 = 1 no K1 settles as fast (the envelope decays at K2ω'/4).
    The settling times scale as 1/ω0; K1 does not."""
    from jaxobs_tuning.structure import structure
    from jaxobs_tuning.targets import k1_for_settling_time_at_k2, soifo_settling_time

    w1 = papers.FLUX_FIG5_OMEGA
    target = soifo_settling_time(papers.SOIFO_K, w1)
    assert target == pytest.approx(float(flux_settling_time((papers.SOIFO_K,), w1)), rel=1e-6)
    K1, K2 = papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2
    v = dict(K1=K1, K2=K2, lam=K1**3 / (2 * K2), omega_init=w1)
    t0 = time.process_time()  # this process's CPU seconds: other processes' load does not stretch them
    rule = structure("SecondOrderSOIFO", v)["closed_form_rule"]
    assert time.process_time() - t0 < 30  # ~3 s (one compile): a bound on the search, not on the machine
    k1 = rule["k1_rule"]
    assert k1 == pytest.approx(0.949, abs=2e-3)
    assert float(flux_settling_time((k1, K2), w1)) == pytest.approx(target, rel=1e-5)
    assert float(flux_settling_time((0.99 * k1, K2), w1)) > 1.001 * target  # the smallest such K1
    assert rule["settling_time_target_ms"] == pytest.approx(17.61, abs=0.01)
    assert rule["settling_time_ms"] == pytest.approx(17.24, abs=0.01)
    assert rule["k1_over_rule"] == pytest.approx(K1 / k1)
    half = structure("SecondOrderSOIFO", {**v, "omega0": w1 / 2})["closed_form_rule"]
    assert half["k1_rule"] == pytest.approx(k1, rel=1e-9)
    assert half["settling_time_ms"] == pytest.approx(2 * rule["settling_time_ms"], rel=1e-9)
    slow = structure("SecondOrderSOIFO", {**v, "K2": 1.0})
    assert slow["closed_form_rule"]["k1_rule"] is None and "K2 = 1" in slow["not_available"]["k1_rule"]
    assert k1_for_settling_time_at_k2(target, 1.0, w1) is None


def test_bfgs_records_every_iteration_with_a_readable_reason(tmp_path, capsys):
    """optimistix BFGS run step by step: one history entry per accepted iterate, a status and a sentence
    (never the raw enum text), and options that do not apply to BFGS rejected at --check."""
    text = GOOD.replace('kind = "adam"', 'kind = "bfgs"')
    path = tmp_path / "job.toml"
    path.write_text(text)
    assert main(["tune", str(path), "--out", str(tmp_path / "o"), "--quiet"]) == 0
    res = _strict_json(tmp_path / "o" / "result.json")
    hist = _strict_json(tmp_path / "o" / "history.json")
    assert res["status"] in ("converged", "budget", "no_improvement")
    assert "has no roots" not in res["reason"] and "BFGS" in res["reason"] or res["status"] == "no_improvement"
    assert len(hist) >= 2 and hist[0]["iteration"] == 0
    assert res["gains"]["tuned"]["lam"] == pytest.approx(min(hist, key=lambda h: h["value"])["gains"]["lam"])
    # a run that used its budget says so on stderr (and nothing else does)
    assert ("budget ran out" in capsys.readouterr().err) == (res["status"] == "budget")
    path.write_text(text.replace("steps = 3", "steps = 3\nlearning_rate = 0.1"))
    assert main(["tune", str(path), "--check"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "solver.learning_rate" in err[0] and "bfgs" in err[0]


def test_nelder_mead_respects_the_bounds_and_reports_its_evaluations(tmp_path, capsys):
    """``kind = "nelder_mead"`` (gradient-free, docs/tuning.md): the tuned gain is the best recorded iterate, inside
    its bounds (the simplex lives in θ, the bounds' unconstrained coordinate), and the reason and timing.json give
    the objective evaluations; a learning rate is refused at --check."""
    text = GOOD.replace('kind = "adam"', 'kind = "nelder_mead"')
    path = tmp_path / "job.toml"
    path.write_text(text)
    assert main(["tune", str(path), "--out", str(tmp_path / "o"), "--quiet"]) == 0
    res = _strict_json(tmp_path / "o" / "result.json")
    hist = _strict_json(tmp_path / "o" / "history.json")
    timing = _strict_json(tmp_path / "o" / "timing.json")
    assert res["status"] in ("converged", "budget", "no_improvement") and res["iterations"] == 3
    assert all(1000.0 < h["gains"]["lam"] < 100000.0 for h in hist)
    if res["status"] != "no_improvement":
        assert res["gains"]["tuned"]["lam"] == pytest.approx(min(hist, key=lambda h: h["value"])["gains"]["lam"])
    # d + 1 = 2 for the first simplex and each shrink, 2 for each of the 2 later steps: even, at least 6
    assert timing["evaluations"] >= 6 and timing["evaluations"] % 2 == 0
    if res["status"] != "no_improvement":  # that reason is the outcome's alone
        assert f"({timing['evaluations']} objective evaluations)" in res["reason"]
    capsys.readouterr()
    path.write_text(text.replace("steps = 3", "steps = 3\nlearning_rate = 0.1"))
    assert main(["tune", str(path), "--check"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "solver.learning_rate" in err[0] and "nelder_mead" in err[0]


def test_report_names_scenarios_in_the_objectives_order():
    """responses.png names its scenario by the values jaxobs_tuning.report enumerates: the job's own order, grid or
    sampled."""
    from jaxobs_tuning.job import load_job
    from jaxobs_tuning.job.scenarios import scenario_points
    from jaxobs_tuning.report import scenario_values

    job = load_job(Path(__file__).parents[1] / "tuning" / "presets" / "wif_robust.toml")
    assert scenario_values(job.scenarios) == scenario_points(job.scenarios)
    sampled = dataclasses.replace(job.scenarios, sample=7, seed=3)
    assert scenario_values(sampled) == scenario_points(sampled)


# --------------------------------------------------------------------------
# flux observers of paper 000 as sensorless drive jobs on its SPMSM
# --------------------------------------------------------------------------

FLUX_DRIVE = """
[job]
name = "soifo-drive"
component = "SOIFO"
[gains.k]
init = 1.414
lower = 0.2
upper = 5.0
[gains.lam]
init = 0.5
lower = 0.01
upper = 5.0
[drive]
loop = "sensorless"
settle = 0.05
[scenarios]
signal = "drive"
t_event = 0.005
horizon = 0.02
steady_from = 0.01
[scenarios.grid]
speed_rpm = [1000.0]
load_step_nm = [2.0]
[objective]
terms = [{ metric = "rms_position_steady", weight = 1.0 }]
[solver]
kind = "adam"
steps = 2
"""


def _lpf(text: str) -> str:
    """FLUX_DRIVE as a job of 000's LPF observer: its cut-off and its PLL's kp free."""
    return (
        text.replace('"SOIFO"', '"LPFFlux"')
        .replace("[gains.k]\ninit = 1.414\nlower = 0.2\nupper = 5.0", "[gains.omega_c]\ninit = 100.0\nupper = 1000.0")
        .replace("[gains.lam]\ninit = 0.5\nlower = 0.01\nupper = 5.0", "[gains.kp_pll]\ninit = 177.7\nupper = 2000.0")
    )


def test_flux_observer_drive_job_runs_sensorless_on_the_spmsm(tmp_path, capsys):
    """A SOIFO job with signal = "drive" closes the loop of 000's SPMSM (the component's default
    machine): result.json says loop "sensorless" and machine "spmsm000", scores every design with its
    lost-sync count, and scores.nc holds the per-scenario lost_sync flag; 2 solver steps end in "budget",
    which is warned about."""
    path = tmp_path / "job.toml"
    path.write_text(FLUX_DRIVE)
    assert main(["tune", str(path), "--check"]) == 0
    assert "sensorless drive on spmsm000" in capsys.readouterr().out
    assert main(["tune", str(path), "--out", str(tmp_path / "o"), "--quiet"]) == 0
    res = _strict_json(tmp_path / "o" / "result.json")
    assert res["loop"] == "sensorless" and res["machine"] == "spmsm000"
    # the envelope it was tuned for, stated; its verification is `jaxobs envelope RESULT.json`
    env = res["envelope"]
    assert env["machine"] == "spmsm000" and env["speed_rpm"][0] > 0 and env["verified"] is None
    assert "envelope.verified" in res["null_reasons"]
    assert res["gains"]["closed_form"]["k"] == pytest.approx(papers.SOIFO_K)
    for design in ("initial", "closed_form", "tuned"):
        assert res["scores"][design]["diverged"] == 0 and res["scores"][design]["lost_sync"] == 0
        assert res["scores"][design]["lost_speed"] == 0  # it follows its speed reference
        # rad: it holds the drive (a loss of synchronism is > 90°; 000 measured 0.15 rad peak at 2000 r/min)
        assert res["scores"][design]["rms_position_steady_worst"] < 0.1
    import xarray as xr

    with xr.open_dataset(tmp_path / "o" / "scores.nc") as ds:
        ds = by_label(ds)
        assert ds["lost_sync"].dims == ("design", "speed_rpm", "load_step_nm")
        assert int(ds["lost_sync"].sum()) == 0
        assert ds["lost_speed"].dims == ds["lost_sync"].dims and int(ds["lost_speed"].sum()) == 0
    err = capsys.readouterr().err
    assert (res["status"] == "budget") == ("budget ran out before its stopping rule" in err)


@pytest.mark.parametrize(
    "edit, field, words",
    [
        # (a flux observer on ipmsm002 runs now, through the active flux: tests/test_zero_speed.py)
        (
            lambda s: s.replace('loop = "sensorless"', 'loop = "sensorless"\nmachine = "spmsm"'),
            "drive.machine",
            "must be one of ipmsm002, spmsm000",
        ),
        (lambda s: s.replace('loop = "sensorless"', "loop = 'sensorless'\nmachine = 3"), "drive.machine", "string"),
        (lambda s: s.replace('"SOIFO"', '"PureIntegratorFlux"'), "job.component", "not tunable"),
        (lambda s: s.replace('signal = "drive"', 'signal = "grid"'), "scenarios.signal", "'emf' or 'drive'"),
        # on EMF signals there is no drive: [drive] is refused
        (
            lambda s: s.replace('signal = "drive"', 'signal = "emf"').replace(
                "speed_rpm = [1000.0]\nload_step_nm = [2.0]", "speed_hz = [50.0]"
            ),
            "drive",
            "applies to drive jobs",
        ),
        # the LPF observer runs in the drive only (on 002's IPMSM too, through the active flux)
        (
            lambda s: _lpf(s).replace('signal = "drive"', 'signal = "emf"'),
            "scenarios.signal",
            "'drive' signals",
        ),
    ],
)
def test_flux_drive_job_bad_machine_or_component_exits_2(tmp_path, capsys, edit, field, words):
    """--check refuses an unknown machine, the pure integrator (its
    integration constant never decays), and a signal the component cannot run on: exit 2, one line."""
    path = tmp_path / "job.toml"
    path.write_text(edit(FLUX_DRIVE))
    assert main(["tune", str(path), "--check"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err and words in err, err


def test_every_drive_component_may_be_tuned_by_a_job():
    """Every drive observer of papers 000 and 002 (but the pure integrator) is a job component whose
    observer gains, PLL or FLL included, are free gains; LESOs default to 002's IPMSM, flux observers to
    000's SPMSM."""
    import tomllib

    from jaxobs_tuning.job import COMPONENTS, parse_job

    want = {
        "CLESO": {"omega0", "kp_pll", "ki_pll"},
        "GILESO": {"omega0", "K_r", "omega_c", "kp_pll", "ki_pll"},
        "FALESO": {"k1", "k2", "kp_pll", "ki_pll"},
        "SOIFO": {"k", "lam"},
        "SecondOrderSOIFO": {"K1", "K2", "lam"},
        "LPFFlux": {"omega_c", "kp_pll", "ki_pll"},
    }
    for comp, gains in want.items():
        info = COMPONENTS[comp]
        assert set(info.gains) == gains and "drive" in info.signals, comp
        assert info.machines[0] == ("ipmsm002" if "LESO" in comp else "spmsm000"), comp
        cf = info.closed_form(None)
        assert set(cf) >= gains - {"K_r"}, comp
    assert "PureIntegratorFlux" not in COMPONENTS
    # a LESO may run on 000's SPMSM (its model with Ld = Lq), asked for explicitly
    raw = tomllib.loads((Path(__file__).parents[1] / "tuning" / "presets" / "cleso.toml").read_text())
    raw["drive"]["machine"] = "spmsm000"
    assert parse_job(raw).drive.machine == "spmsm000"
    assert load_job(Path(__file__).parents[1] / "tuning" / "presets" / "cleso.toml").drive.machine == "ipmsm002"


def test_every_metric_has_cf_units():
    """scores.nc labels each metric with its entry's units: a term metric is every run and system entry of the one
    table, each with units."""
    from jaxobs.metrics import METRICS
    from jaxobs_tuning.objective import TERM_METRICS

    assert set(TERM_METRICS) == {k for k, m in METRICS.items() if m.kind in ("run", "system")}
    assert all(TERM_METRICS[k] is METRICS[k] and METRICS[k].units for k in TERM_METRICS)


def test_report_marks_events_only_where_the_scenario_has_one_and_draws_a_negative_objective(tmp_path):
    """responses.png marks "events at t_event" only where the worst scenario steps (cleso.toml has no event and
    showed the mark over its trace); convergence.png of an objective that goes negative (sosoifo.toml's margin
    term) was an empty log axis: it is linear there, log where every value is positive."""
    from jaxobs_tuning.report import _has_event, convergence_figure

    drive = load_job(Path(__file__).resolve().parents[1] / "tuning" / "presets" / "cleso.toml").scenarios
    assert drive.signal == "drive" and "load_step_nm" not in drive.axes
    assert not any(_has_event(drive, i) for i in range(4))
    stepped = dataclasses.replace(drive, axes={**drive.axes, "load_step_nm": [0.0, 10.0]})
    n = math.prod(len(v) for v in stepped.axes.values())
    flags = [_has_event(stepped, i) for i in range(n)]
    assert any(flags) and not all(flags)  # the scenarios with a 10 N·m step, not those with none
    grid = load_job(Path(__file__).resolve().parents[1] / "tuning" / "presets" / "sogi_fll.toml").scenarios
    assert grid.signal == "grid" and any(_has_event(grid, i) for i in range(3))
    for values, scale in (([0.3, -0.01, -0.012], "linear"), ([0.3, 0.1, 0.02], "log")):
        fig = convergence_figure([{"iteration": i, "value": v} for i, v in enumerate(values)], "x")
        fig.savefig(tmp_path / "c.png")
        (ax,) = fig.axes
        assert ax.get_yscale() == scale and (tmp_path / "c.png").stat().st_size > 0
        lo, hi = ax.get_ylim()
        assert lo <= min(values) and hi >= max(values)  # every value drawn inside the axis


def test_convergence_marks_the_best_iteration_and_responses_note_designs_drawn_on_one_line(tmp_path):
    """convergence.png: the objective's definition under the axis and the tuned design's iteration starred (the
    least stable value where the result names none); responses.png's legend says when a design's curves lie on
    another's (an initial design at the closed form), with how far apart their gains are."""
    from jaxobs_tuning.aggregations import CVaR
    from jaxobs_tuning.objective import Term
    from jaxobs_tuning.report import _coincide, convergence_figure, objective_text

    runs = [(3.0, 0), (0.5, 2), (1.0, 0), (2.0, 0)]  # (objective, diverged scenarios)
    hist = [{"iteration": i, "value": v, "diverged": d} for i, (v, d) in enumerate(runs)]
    for best, want in ((None, 2), (3, 3)):  # iteration 1 diverged in two scenarios: never the best
        fig = convergence_figure(hist, "x", "J = mean of 1·itae_freq", best)
        (ax,) = fig.axes
        star = [ln for ln in ax.lines if ln.get_marker() == "*"]
        assert len(star) == 1 and list(star[0].get_xdata()) == [want]
        assert ax.get_legend().get_texts()[1].get_text().startswith(f"best: iteration {want}, J = ")
        assert ax.get_ylabel() == "objective J (1)" and "J = mean of 1·itae_freq" in [t.get_text() for t in fig.texts]

    class _Obj:
        aggregation, penalty = CVaR(0.9), 1e3
        terms = [Term("itae_freq", 1.0), Term("ripple_freq", 0.01)]

    text = objective_text(_Obj())
    assert text.startswith("J = CVaR (α = 0.9: the mean of the worst 10 %) over the scenarios of 1·itae_freq + ")
    assert "0.01·ripple_freq" in text and "penalty 1000" in text
    f = np.sin(np.linspace(0, 6, 50))
    traces = {"initial": (f, f), "closed_form": (f + 1e-6, f), "tuned": (1.5 * f, f)}
    gains = {"initial": {"lam": 100.0}, "closed_form": {"lam": 100.0001}, "tuned": {"lam": 150.0}}
    assert _coincide(traces, gains) == {"closed_form": " (on the initial line: gains within 0.0001 %)"}
    same = _coincide({"a": (f,), "b": (f,)}, {"a": {"k": 1.0}, "b": {"k": 1.0}})
    assert same == {"b": " (on the a line: the same gains)"}
