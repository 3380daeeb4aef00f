"""Recording jobs on a drive engineer's own logs: the layout declared in the job, the checks' messages through the
command line, windows of a long log, recordings of different lengths, the speed estimate scored, honest reports."""

import dataclasses
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from jaxobs.io.provenance import by_label
from jaxobs_tuning.cli import main
from jaxobs_tuning.job import load_job, run_job
from jaxobs_tuning.job.recordings import load_recordings

ROOT = Path(__file__).resolve().parents[1]
PRESET = ROOT / "tuning" / "presets" / "recording_sosoifo.toml"
DRIVE_CSV = ROOT / "tuning" / "presets" / "recordings" / "drive_spmsm_1000rpm.csv"
NAMES = ["t", "u_a", "u_b", "i_a", "i_b", "theta_e", "omega_e"]


def _cols():
    return dict(zip(NAMES, np.loadtxt(DRIVE_CSV, delimiter=",", comments="#", skiprows=2).T))


def _write(path, cols: dict):
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="",
               fmt="%.17g")  # fmt: skip
    return path


def _job(tmp_path, recording: str, objective: str | None = None, steps: int = 2) -> Path:
    """The second-order SOIFO preset on ``recording`` (a [scenarios.recording] table's body)."""
    text = PRESET.read_text()
    head, rest = text.split("[scenarios.recording]\n", 1)
    rest = rest.split("\n[objective]", 1)[1]
    text = head + "[scenarios.recording]\n" + recording.strip() + "\n\n[objective]" + rest
    if objective is not None:
        text = text.replace(text[text.index("terms = ") :].split("\n", 1)[0], objective)
    text = text.replace("steps = 30", f"steps = {steps}")
    path = tmp_path / "job.toml"
    path.write_text(text)
    return path


def _phase_log(tmp_path, name="ctrl.csv"):
    """The shipped log as a controller writes it: phase currents a, b and the voltage reference at t_k."""
    c = _cols()
    c["i_b"] = -0.5 * c["i_a"] + math.sqrt(3) / 2 * c["i_b"]
    c["u_a"], c["u_b"] = np.roll(c["u_a"], -1), np.roll(c["u_b"], -1)
    return _write(tmp_path / name, c)


def test_a_job_declares_its_logs_layout_and_scores_the_speed_estimate(tmp_path, capsys):
    """Phase currents and reference voltages, declared in the job: the run reads them as the α-β applied form,
    names the loop honestly, lists the recording's starting speed, labels scores.nc by file, and scores the
    speed estimate against the encoder (rad/s electrical)."""
    _phase_log(tmp_path)
    rec = """
file = "ctrl.csv"
time_column = "t"
columns = ["u_a", "u_b", "i_a", "i_b"]
truth = ["theta_e", "omega_e"]
machine = "spmsm000"
layout = { current_frame = "abc", voltage_timing = "reference" }
"""
    terms = 'terms = [{ metric = "iae_position", weight = 1.0 }, { metric = "rms_speed_error_steady", weight = 0.01 }]'
    path = _job(tmp_path, rec, terms)
    # the reference's delay drops the first row (its applied voltage is before the log): 2999 samples
    path.write_text(path.read_text().replace("horizon = 0.3", "horizon = 0.29"))
    assert main(["tune", str(path), "--check"]) == 0
    assert "open loop on 1 recording(s)" in capsys.readouterr().out
    job = load_job(path)
    res = run_job(job, tmp_path / "o", quiet=True)
    assert res["loop"] == "open loop on recordings"
    (scen,) = res["recordings"][0]["scenarios"]
    assert scen["name"] == "ctrl.csv" and scen["omega_start"] == pytest.approx(314.1592, abs=1e-3)
    # scored past the start-up: 2 electrical periods at the recorded 314 rad/s (docs/recordings.md)
    assert res["startup"]["periods"] == 2 and res["startup"]["t_event"] == pytest.approx(0.04, rel=1e-3)
    s = res["scores"]["initial"]
    assert s["diverged"] == 0 and 0 < s["rms_speed_error_steady_mean"] < 20.0  # rad/s electrical, 1000 r/min
    import xarray as xr

    with xr.open_dataset(tmp_path / "o" / "scores.nc", engine="h5netcdf") as ds:
        ds = by_label(ds)
        assert list(ds["recording"].values) == ["ctrl.csv"]
        assert ds["rms_speed_error_steady"].attrs["units"] == "rad s-1"
    # the same log undeclared: refused before anything runs, naming the columns and the declaration
    path.write_text(path.read_text().replace('layout = { current_frame = "abc", voltage_timing = "reference" }\n', ""))
    assert main(["tune", str(path), "--check"]) == 2
    err = capsys.readouterr().err
    assert "scenarios.recording.file" in err and "not an α-β pair" in err and "current_frame = 'abc'" in err
    assert err.count("\n") == 1


def test_reference_voltages_undeclared_warn_in_one_line(tmp_path, capsys):
    c = _cols()
    c["u_a"], c["u_b"] = np.roll(c["u_a"], -1), np.roll(c["u_b"], -1)
    _write(tmp_path / "late.csv", c)
    rec = 'file = "late.csv"\ntime_column = "t"\ntruth = ["theta_e", "omega_e"]\nmachine = "spmsm000"'
    assert main(["tune", str(_job(tmp_path, rec)), "--check"]) == 0
    err = capsys.readouterr().err
    assert err.startswith("jaxobs: warning: recording ") and "match the machine's model best 1 period" in err


@pytest.mark.parametrize(
    "extra, field, words",
    [
        ('layout = { current_frames = "abc" }', "scenarios.recording.layout.current_frames", "unknown key"),
        ('layout = { angle_unit = "grad" }', "scenarios.recording.layout.angle_unit", "must be one of 'rad', 'deg'"),
        ("windows = 0", "scenarios.recording.windows", "a count in 1..256"),
        ('machine = "pmsm9"', "scenarios.recording.machine", "pmsm9"),
    ],
)
def test_recording_keys_refused_naming_the_field(tmp_path, capsys, extra, field, words):
    shutil.copy(DRIVE_CSV, tmp_path / "log.csv")
    rec = f'file = "log.csv"\ntime_column = "t"\ntruth = ["theta_e", "omega_e"]\n{extra}'
    assert main(["tune", str(_job(tmp_path, rec)), "--check"]) == 2
    err = capsys.readouterr().err
    assert field in err and words in err and err.count("\n") == 1


def test_recordings_of_different_lengths_need_trim(tmp_path, capsys):
    shutil.copy(DRIVE_CSV, tmp_path / "a.csv")
    _write(tmp_path / "b.csv", {k: v[:2900] for k, v in _cols().items()})
    rec = 'file = ["a.csv", "b.csv"]\ntime_column = "t"\ntruth = ["theta_e", "omega_e"]'
    path = _job(tmp_path, rec)
    path.write_text(path.read_text().replace("horizon = 0.3", "horizon = 0.25"))
    assert main(["tune", str(path), "--check"]) == 2
    err = capsys.readouterr().err
    assert "scenarios.recording.trim" in err and "a.csv 3000, b.csv 2900 samples" in err
    path.write_text(
        path.read_text().replace('truth = ["theta_e", "omega_e"]', 'truth = ["theta_e", "omega_e"]\ntrim = true')
    )
    assert main(["tune", str(path), "--check"]) == 0


def test_windows_of_a_log_are_scenarios_from_their_own_speed(tmp_path):
    """A log cut into 3 windows of the horizon (0.1 s of its 0.3 s): three scenarios, each starting from the
    encoder's speed at its first sample (the speed steps +10 % at 0.1 s), labelled file@k."""
    shutil.copy(DRIVE_CSV, tmp_path / "log.csv")
    rec = 'file = "log.csv"\ntime_column = "t"\ntruth = ["theta_e", "omega_e"]\nwindows = 3'
    path = _job(tmp_path, rec)
    path.write_text(
        path.read_text().replace("horizon = 0.3", "horizon = 0.1").replace("steady_from = 0.2", "steady_from = 0.05")
    )
    job = load_job(path)
    job.solver = dataclasses.replace(job.solver, steps=1)
    res = run_job(job, tmp_path / "o", quiet=True)
    scen = res["recordings"][0]["scenarios"]
    assert [s["name"] for s in scen] == ["log.csv@0", "log.csv@1", "log.csv@2"]
    w0 = _cols()["omega_e"]
    starts = [round(i * (3000 - 1001) / 2) for i in range(3)]
    assert [s["omega_start"] for s in scen] == pytest.approx([w0[a] for a in starts], abs=1e-9)
    assert json.loads((tmp_path / "o" / "result.json").read_text())["scenarios"]["count"] == 3


def test_a_job_declares_three_phase_currents_beside_two_voltages(tmp_path, capsys):
    """`voltages` and `currents` (2 or 3 each) declare what labs log: three phase currents beside α-β voltages read
    as the clean α-β log; two phase voltages give the third as −a − b only with voltage_zero_sequence = 'none', and
    each miscount is one line naming its key."""
    c = _cols()
    a, b = c["i_a"], -0.5 * c["i_a"] + math.sqrt(3) / 2 * c["i_b"]
    lab = {"t": c["t"], "u_a": c["u_a"], "u_b": c["u_b"], "ia": a, "ib": b, "ic": -a - b}
    lab.update(theta_e=c["theta_e"], omega_e=c["omega_e"])
    _write(tmp_path / "lab.csv", lab)
    shutil.copy(DRIVE_CSV, tmp_path / "clean.csv")
    head = 'time_column = "t"\ntruth = ["theta_e", "omega_e"]\n'
    three = head + 'file = "lab.csv"\nvoltages = ["u_a", "u_b"]\ncurrents = ["ia", "ib", "ic"]\n'
    job3 = load_job(_job(tmp_path, three + 'layout = { current_frame = "abc" }'))
    assert job3.scenarios.recording.voltages == 2 and len(job3.scenarios.recording.columns) == 5
    (tmp_path / "c").mkdir()
    job_clean = load_job(_job(tmp_path / "c", head + 'file = "../clean.csv"'))
    got = load_recordings(job3.scenarios.recording, job3.scenarios.family.recorded())
    want = load_recordings(job_clean.scenarios.recording, job_clean.scenarios.family.recorded())
    np.testing.assert_allclose(np.asarray(got.samples), np.asarray(want.samples), rtol=1e-12, atol=1e-12)
    # three phase voltages beside α-β currents: 3 + 2 (half of 5 would split them 2 + 3)
    ua, ub = c["u_a"], -0.5 * c["u_a"] + math.sqrt(3) / 2 * c["u_b"]
    _write(tmp_path / "lab2.csv", {"t": c["t"], "ua": ua, "ub": ub, "uc": -ua - ub, "i_a": c["i_a"], "i_b": c["i_b"],
                                   "theta_e": c["theta_e"], "omega_e": c["omega_e"]})  # fmt: skip
    rec2 = head + 'file = "lab2.csv"\nvoltages = ["ua", "ub", "uc"]\ncurrents = ["i_a", "i_b"]\n'
    job2 = load_job(_job(tmp_path, rec2 + 'layout = { voltage_frame = "abc" }'))
    got2 = load_recordings(job2.scenarios.recording, job2.scenarios.family.recorded())
    np.testing.assert_allclose(np.asarray(got2.samples), np.asarray(want.samples), rtol=1e-12, atol=1e-12)
    for rec, field, words in (
        (three, "scenarios.recording.currents", "3 columns are three phases: declare layout.current_frame = 'abc'"),
        (head + 'file = "lab.csv"\nvoltages = ["u_a", "u_b"]', "scenarios.recording.currents", "is required with"),
        (three + 'columns = ["u_a"]', "scenarios.recording.columns", "not both"),
        (three.replace('"ic"]', '"ic", "t"]'), "scenarios.recording.currents", "a list of 2 or 3 column(s)"),
    ):
        assert main(["tune", str(_job(tmp_path, rec)), "--check"]) == 2, rec
        err = capsys.readouterr().err
        assert field in err and words in err and err.count("\n") == 1, err
    # two phase voltages (of a file with u in abc): refused unless their zero sequence is declared absent
    volts = head + 'file = "lab.csv"\nvoltages = ["ia", "ib"]\ncurrents = ["ia", "ib", "ic"]\n'
    lay = 'layout = { current_frame = "abc", voltage_frame = "abc"'
    assert main(["tune", str(_job(tmp_path, volts + lay + " }")), "--check"]) == 2
    err = capsys.readouterr().err
    assert "give the third column, or declare voltage_zero_sequence = 'none'" in err and err.count("\n") == 1
    path = _job(tmp_path, volts + lay + ', voltage_zero_sequence = "none" }')
    assert load_job(path).scenarios.recording.layout.voltage_zero_sequence == "none"
