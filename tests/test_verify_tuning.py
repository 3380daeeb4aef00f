"""Tuning that cannot hide a failure: ``[drive] speed_schedule``, ``[envelope]``, the long-horizon
verification after tuning and the ``unsafe`` status (exit 4)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from jaxobs_tuning.cli import main
from jaxobs_tuning.job import UNSAFE_EXIT, job_drive, load_job, parse_job
from jaxobs_tuning.job.verify import EnvelopeSpec, unsafe_points, verification_points

PRESETS = Path(__file__).parents[1] / "tuning" / "presets"
DRIVE_PRESETS = ("cleso", "gileso", "faleso", "soifo", "sosoifo", "soifo_noise")

JOB = """
[job]
name = "soifo-verify"
component = "SOIFO"
[gains.k]
init = 1.414
lower = 0.2
upper = 5.0
[drive]
loop = "sensorless"
settle = 0.05
speed_schedule = 6.0
[envelope]
speed_rpm = [1000.0, 1000.0]
load_nm = [2.0, 2.0]
horizon = 0.5
settle = 0.0
window = 0.02
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
steps = 1
"""


def _raw(text=JOB):
    import tomllib

    return tomllib.loads(text)


def test_speed_schedule_reaches_the_foc_and_is_off_by_default():
    """[drive] speed_schedule = N is the FOC's speed-loop schedule; without it the FOC's is 0 (off)."""
    job = parse_job(_raw())
    assert job.drive.speed_schedule == 6.0 and job_drive(job.drive).foc.speed_schedule == 6.0
    raw = _raw()
    del raw["drive"]["speed_schedule"]
    assert job_drive(parse_job(raw).drive).foc.speed_schedule == 0.0


@pytest.mark.parametrize(
    "edit, field, words",
    [
        (lambda s: s.replace("speed_schedule = 6.0", "speed_schedule = -1.0"), "drive.speed_schedule", "(0, 1000]"),
        (lambda s: s.replace("speed_schedule = 6.0", "speed_schedule = 2e3"), "drive.speed_schedule", "(0, 1000]"),
        (lambda s: s.replace("speed_rpm = [1000.0, 1000.0]", "speed_rpm = [900.0]"), "envelope.speed_rpm", "[lo, hi]"),
        (lambda s: s.replace("speed_rpm = [1000.0, 1000.0]", "speed_rpm = [0.0, 900.0]"), "envelope.speed_rpm", "1"),
        (lambda s: s.replace("speed_rpm = [1000.0, 1000.0]", "speed_rpm = [900, 9e3]"), "envelope.speed_rpm", "2835"),
        (lambda s: s.replace("speed_rpm = [1000.0, 1000.0]", "speed_rpm = [900, 800]"), "envelope.speed_rpm", "lo"),
        (lambda s: s.replace("load_nm = [2.0, 2.0]", "load_nm = [-1.0, 2.0]"), "envelope.load_nm", "0 <= lo"),
        (lambda s: s.replace("horizon = 0.5", "horizon = 20.0"), "envelope.horizon", "[0.5, 10]"),
        (lambda s: s.replace("window = 0.02", "windw = 0.02"), "envelope", "windw"),
        (lambda s: s.replace('loop = "sensorless"', 'loop = "sensored"'), "envelope", "sensorless"),
        (lambda s: s.replace("window = 0.02", "window = 0.02\nideal_sensors = 1"), "envelope.ideal_sensors", "true or"),
    ],
)
def test_bad_schedule_or_envelope_exits_2(tmp_path, capsys, edit, field, words):
    """--check refuses a schedule or an envelope out of range with one line naming the field and the range."""
    path = tmp_path / "job.toml"
    path.write_text(edit(JOB))
    assert main(["tune", str(path), "--check"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err and words in err, err


def test_envelope_defaults_to_the_tuning_grid_and_its_coarse_grid():
    """Without speed_rpm / load_nm the envelope is the span of the tuning grid; the verification grid is
    lo, the geometric middle and hi × the two loads; no [envelope]: nothing is verified (None)."""
    raw = _raw()
    raw["envelope"] = {}
    raw["scenarios"]["grid"] = {"speed_rpm": [400.0, 1600.0], "load_nm": [0.0, 3.0]}
    env = parse_job(raw).envelope
    assert env.speed_rpm == (400.0, 1600.0) and env.load_nm == (0.0, 3.0) and env.horizon == 2.0
    assert verification_points(env) == ([400.0, 800.0, 1600.0], [0.0, 3.0])
    del raw["envelope"]
    assert parse_job(raw).envelope is None


def test_unsafe_points_are_where_the_tuned_fails_and_the_closed_form_holds():
    """A hand-made verification: the tuned design loses synchronism at one point and is unstable at another
    where the closed form is unstable too; only the first is unsafe."""

    def pt(s, passes=True):
        return {"speed_rpm": s, "load_nm": 0.0, "passes": passes}

    ver = {
        "designs": {
            "closed_form": {"points": [pt(200.0), pt(400.0, False), pt(800.0)]},
            "tuned": {"points": [pt(200.0, False), pt(400.0, False), pt(800.0)]},
        }
    }
    assert unsafe_points(ver) == [{"speed_rpm": 200.0, "load_nm": 0.0}]
    del ver["designs"]["tuned"]  # nothing tuned (diverged): nothing unsafe
    assert unsafe_points(ver) == []


def test_a_tuned_design_failing_inside_its_envelope_is_unsafe_exit_4(tmp_path, capsys, monkeypatch):
    """The real verification (jaxobs.analysis.envelope.envelope, 0.5 s, a short Lyapunov window) runs after
    tuning and writes the verification block; a tuned design that then loses synchronism where the closed form
    passes (both forced here) turns the status to "unsafe", warns on stderr and exits 4; the solver's status stays in
    tuning_status."""
    import jaxobs_tuning.job.run as run

    real = run.verify_designs
    seen = {}

    def lose_sync(designs, env, drive, machine=None, seed=0):
        seen["seed"] = seed  # the job's seed draws the sensors' noise
        ver = real(designs, env, drive, machine, seed=seed)
        seen["real"] = json.loads(json.dumps(ver))
        # hand-made: the closed form passes (a 0.02 s Lyapunov window is too short for a verdict), the tuned
        # design loses synchronism
        ver["designs"]["closed_form"]["points"][0].update(passes=True)
        ver["designs"]["tuned"]["points"][0].update(synchronous=False, lost_lock=True, passes=False)
        ver["unsafe_points"] = unsafe_points(ver)
        return ver

    monkeypatch.setattr(run, "verify_designs", lose_sync)
    path = tmp_path / "job.toml"
    path.write_text(JOB)
    assert main(["tune", str(path), "--out", str(tmp_path / "o"), "--quiet"]) == UNSAFE_EXIT == 4
    err = capsys.readouterr().err
    assert "UNSAFE" in err and "1000 r/min 2 N·m" in err
    res = json.loads((tmp_path / "o" / "result.json").read_text())
    assert res["status"] == "unsafe" and res["tuning_status"] in ("budget", "converged", "no_improvement")
    ver = seen["real"]
    assert set(ver["designs"]) == {"initial", "closed_form", "tuned"} and ver["horizon_s"] == 0.5
    assert seen["seed"] == 0 and ver["sensors"] == "ideal (a shipped bench)"  # 000's bench: its scenarios' sensors
    assert ver["speed_schedule"] == 6.0 and ver["points"] == [{"speed_rpm": 1000.0, "load_nm": 2.0}]
    for d in ver["designs"].values():  # the 1000 r/min point holds synchronism for every design, unforced
        (p,) = d["points"]
        assert p["synchronous"] and not p["lost_lock"] and math.degrees(p["peak_position_late"]) < 5.0
        assert isinstance(p["stable"], bool) and p["passes"] == p["stable"] and math.isfinite(p["margin_per_s"])
        # a verdict within the window's resolution is marginal, never stable (a 0.02 s window resolves little)
        assert isinstance(p["marginal"], bool) and not (p["marginal"] and p["stable"])
        assert p["resolution_per_s"] is not None and p["resolution_per_s"] >= 0.0
        assert p["marginal"] == (abs(p["margin_per_s"]) <= p["resolution_per_s"])
    assert ver["unsafe_points"] == []
    assert res["verification"]["unsafe_points"] == [{"speed_rpm": 1000.0, "load_nm": 2.0}]


def test_every_drive_preset_states_its_envelope_and_a_holdout_outside_its_grid():
    """Every drive preset claims an envelope ([envelope]) verified over >= 2 s, and its held-out set reaches
    outside the tuning grid: a lower speed or another load."""
    for name in DRIVE_PRESETS:
        job = load_job(PRESETS / f"{name}.toml")
        assert isinstance(job.envelope, EnvelopeSpec) and job.envelope.horizon >= 2.0, name
        assert job.holdout is not None, name
        g, h = job.scenarios.axes, job.holdout.axes
        lower = min(h.get("speed_rpm", [600.0])) < min(g.get("speed_rpm", [600.0]))
        loads = set(h.get("load_nm", [0.0])) - set(g.get("load_nm", [0.0]))
        assert lower or loads, name
        assert job.envelope.speed_rpm[0] <= min(h.get("speed_rpm", [600.0])), name


@pytest.mark.slow  # the reverse-mode compile through lyapunov: ~6.5 min cold on 2 shared cores, ~1 min cached
def test_stability_margin_is_a_differentiable_objective_term(monkeypatch):
    """metric = "stability_margin": the Lyapunov exponent (1/s, minus the margin) of the loop each scenario
    closes, weighted into the objective with a finite gradient; reported per scenario like any metric (a
    tiny Lyapunov run here: compile time)."""
    import jax.numpy as jnp

    import jaxobs_tuning.objective as O
    from jaxobs_tuning.job import build_objective

    monkeypatch.setattr(O, "MARGIN_KW", {"settle": 0.0, "warmup": 0.0, "window": 0.002, "n_dirs": 1})
    raw = _raw()
    del raw["envelope"]
    raw["objective"]["terms"].append({"metric": "stability_margin", "weight": 1e-3})
    job = parse_job(raw)
    obj, scen, _ = build_objective(job)
    theta = obj.param.theta0()
    v, g = obj.value_and_grad(theta, scen)
    assert jnp.isfinite(v) and jnp.all(jnp.isfinite(g)) and jnp.any(g != 0)
    mets, total, good = obj.per_scenario(theta, scen)
    lam = float(mets["stability_margin"][0])
    assert bool(good[0]) and math.isfinite(lam)
    assert float(total[0]) == pytest.approx(float(mets["rms_position_steady"][0]) + 1e-3 * lam, rel=1e-9)


def test_stability_margin_needs_a_steady_start():
    """An I-f start has no operating point to linearize about: the term is refused, naming it."""
    raw = _raw()
    del raw["envelope"]
    raw["objective"]["terms"].append({"metric": "stability_margin", "weight": 1e-3})
    raw["drive"]["start"] = "standstill"
    raw["scenarios"].update(horizon=0.6, steady_from=0.5)
    with pytest.raises(ValueError, match=r"objective.terms\[1\].metric.*steady"):
        parse_job(raw)
    raw["drive"]["start"] = "steady"
    assert parse_job(raw).terms[1].metric == "stability_margin"


TEKNIC_JOB = """
[job]
name = "teknic-verify"
component = "CLESO"
[gains.omega0]
init = 1570.8
[drive]
file = "{file}"
[envelope]
speed_rpm = [1000.0, 1000.0]
load_nm = [0.1, 0.1]
horizon = 0.5
settle = 0.0
window = 0.02
{extra}
[scenarios]
signal = "drive"
t_event = 0.005
horizon = 0.02
steady_from = 0.01
[scenarios.grid]
speed_rpm = [1000.0]
[objective]
terms = [{{ metric = "rms_position_steady", weight = 1.0 }}]
[solver]
kind = "adam"
steps = 1
"""


def test_the_verification_measures_through_the_drive_files_sensors_unless_turned_off(tmp_path):
    """On the Teknic drive file (a 12-bit ADC over ±16.5 A: its quantization as current noise) the verification
    runs its [sensors], as `jaxobs envelope` does: the late position error and the Floquet margin differ from the
    ideal sensors' run; `[envelope] ideal_sensors = true` gives exactly the run of the same file without
    [sensors] (one point, 0.5 s, the closed form only)."""
    from jaxobs_tuning.job.components import COMPONENTS
    from jaxobs_tuning.job.verify import verify_designs

    teknic = Path(__file__).parents[1] / "docs" / "examples" / "teknic_m2310p.toml"
    (tmp_path / "teknic.toml").write_text(teknic.read_text())
    (tmp_path / "bare.toml").write_text(teknic.read_text().split("\n[sensors]")[0] + "\n")

    def verify(file, extra=""):
        path = tmp_path / f"{file}-{len(extra)}.job.toml"
        path.write_text(TEKNIC_JOB.format(file=file, extra=extra))
        job = load_job(path)
        designs = {"closed_form": COMPONENTS[job.component].ctor(**job.values)}
        ver = verify_designs(designs, job.envelope, job.drive, seed=job.seed)
        (p,) = ver["designs"]["closed_form"]["points"]
        return ver["sensors"], p

    keys = ("margin_per_s", "peak_position_late", "ripple_position_late", "peak_speed_deviation_late")
    words, noisy = verify("teknic.toml")
    assert words == "the drive file's [sensors]" and noisy["passes"]
    words, off = verify("teknic.toml", "ideal_sensors = true")
    assert words == "ideal (envelope.ideal_sensors)" and off["passes"]
    assert all(noisy[k] != off[k] for k in keys), (noisy, off)
    _, bare = verify("bare.toml")
    assert {k: bare[k] for k in keys} == {k: off[k] for k in keys}
