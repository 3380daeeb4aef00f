"""Recordings from CSV files: SampledSignal.from_csv, DriveRecording, and recordings as job scenarios."""

import dataclasses
import math
import shutil
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs
from jaxobs import drive as D
from jaxobs import metrics as M
from jaxobs import papers
from jaxobs.io.provenance import by_label
from tests.cfcheck import assert_cf18

ROOT = Path(__file__).resolve().parents[1]
RECORDINGS = ROOT / "tuning" / "presets" / "recordings"
GRID_CSV = RECORDINGS / "grid_50_51hz.csv"
DRIVE_CSV = RECORDINGS / "drive_spmsm_1000rpm.csv"


def _write(path, header, cols, fmt="%.17g"):
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=header, comments="", fmt=fmt)
    return path


def _sine(tmp_path, rate=12_800.0, seconds=0.05, f=50.0):
    t = np.arange(round(seconds * rate)) / rate
    return _write(tmp_path / "s.csv", "t,v", (t, np.cos(2 * np.pi * f * t))), t


# --------------------------------------------------------------------------
# SampledSignal.from_csv
# --------------------------------------------------------------------------


def test_from_csv_resamples_to_the_observer_ts_by_linear_interpolation(tmp_path):
    """A 50 Hz sine recorded at 12.8 kHz, read at ts = 1e-4 s: the interpolation error of a straight line
    between samples 1/12800 s apart is at most (ω·dt)²/8 = 7.5e-5 of the amplitude, and no larger."""
    path, _ = _sine(tmp_path)
    sig = jaxobs.SampledSignal.from_csv(path, time_column="t", columns="v", ts=1e-4)
    assert sig.ts == 1e-4 and sig.n == 500  # 0..0.04992 s: the last whole sample of 1e-4 s inside it
    tk = 1e-4 * np.arange(sig.n)
    err = np.max(np.abs(np.asarray(sig.samples) - np.cos(2 * np.pi * 50 * tk)))
    bound = (2 * np.pi * 50 / 12_800) ** 2 / 8
    assert 0.1 * bound < err <= bound * 1.001


def test_from_csv_time_column_or_sample_rate_and_columns_by_name_or_index(tmp_path):
    path, t = _sine(tmp_path, rate=10_000.0)
    a = jaxobs.SampledSignal.from_csv(path, time_column="t", columns="v")  # its own rate: samples unchanged
    b = jaxobs.SampledSignal.from_csv(path, sample_rate=10_000.0, columns=1)
    c = jaxobs.SampledSignal.from_csv(path, time_column=0)  # the one other column
    assert a.ts == pytest.approx(1e-4, rel=1e-9) and b.ts == 1e-4
    np.testing.assert_array_equal(a.samples, np.cos(2 * np.pi * 50 * t))
    np.testing.assert_array_equal(a.samples, b.samples)
    np.testing.assert_array_equal(a.samples, c.samples)
    two = jaxobs.SampledSignal.from_csv(path, sample_rate=10_000.0, columns=["v", "t"])  # a batch of channels
    assert two.samples.shape == (2, t.size)


def test_from_csv_truth_columns_feed_the_metrics():
    """The shipped grid recording: the WIF tracks the recorded 51 Hz (its truth column) to 0.02 Hz."""
    sig = jaxobs.SampledSignal.from_csv(
        GRID_CSV, time_column="t", columns="v", ts=1e-4, truth=("theta", "omega", "amplitude")
    )
    sol = jaxobs.simulate(jaxobs.OnSignal(jaxobs.linear.wif_closed_form(), sig), 0.4)
    steady = np.asarray(sol.t) >= 0.3
    f_hat = np.asarray(sol.outputs.obs.omega)[steady] / (2 * np.pi)
    f_true = np.asarray(sol.outputs.truth.omega)[steady] / (2 * np.pi)
    assert np.all(np.abs(f_true - 51.0) < 1e-3)
    assert abs(np.mean(f_hat) - 51.0) < 0.02


@pytest.mark.parametrize(
    "body, kw, match",
    [
        ("t,v\n0,1\n2e-4,2\n1e-4,3\n3e-4,1\n", dict(time_column="t", ts=1e-4), "not strictly increasing"),
        ("t,v\n0,1\n1e-4,nan\n2e-4,3\n", dict(time_column="t"), "'v' is not finite at data row 2"),
        ("t,v\n0,1\n", dict(time_column="t"), "at least 2"),
        ("t,v\n0,1\n2e-4,2\n4e-4,3\n", dict(time_column="t", ts=1e-4), "slower than the observer's ts"),
        ("t,v\n0,1\n1e-4,2\n", dict(time_column="t", columns="w"), "no signal column 'w'; columns: t, v"),
        ("t,v\n0,1\n1e-4,2\n", dict(time_column="t", columns=5), "index 5 is outside 0..1"),
        ("t,v\n0,1\n1e-4,2\n", dict(time_column="t", sample_rate=1e4), "exactly one of time_column and sample_rate"),
        ("t,v\n0,1\n1e-4,2\n", dict(columns="v"), "exactly one of time_column and sample_rate"),
        ("0,1\n1e-4,2\n", dict(time_column="t"), "no header row"),
        ("t,v\n0,1\n1e-4,2,3\n", dict(time_column="t"), "line 3 has 3 fields"),
        ("t,v\n0,1\n1e-4,x\n", dict(time_column="t"), "line 3 holds a field that is not a number"),
        ("t,v\n0,1\n1e-4,2\n3e-4,2\n", dict(time_column="t"), "not uniform"),
        ("t,v\n0,1\n1e-4,2\n", dict(time_column="t", ts=3e-4), "fewer than 2 samples"),
        ("t,v\n0,1\n1e-4,2\n", dict(time_column="t", truth=("v",)), "truth must be 3 columns"),
    ],
)
def test_from_csv_refuses_what_it_cannot_read(tmp_path, body, kw, match):
    path = tmp_path / "r.csv"
    path.write_text(body)
    with pytest.raises(ValueError, match=match):
        jaxobs.SampledSignal.from_csv(path, **kw)


def test_from_csv_refuses_missing_and_oversized_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="none.csv': no such file"):
        jaxobs.SampledSignal.from_csv(tmp_path / "none.csv", sample_rate=1e4)
    with pytest.raises(FileNotFoundError, match="no such file"):
        jaxobs.DriveRecording.from_csv(tmp_path / "none.csv", sample_rate=1e4)
    with pytest.raises(ValueError, match="not a file"):
        jaxobs.SampledSignal.from_csv(tmp_path, sample_rate=1e4)
    path, _ = _sine(tmp_path)
    with pytest.raises(ValueError, match="more than the limit of 100 bytes"):
        jaxobs.SampledSignal.from_csv(path, time_column="t", max_bytes=100)


# --------------------------------------------------------------------------
# DriveRecording
# --------------------------------------------------------------------------


def test_drive_recording_resamples_voltages_as_period_averages(tmp_path):
    """Recorded at 20 kHz, read at 10 kHz: each new period's voltage is the mean of the two recorded
    periods it covers (what the inverter applied over it); the currents are the samples at t_k."""
    n = 40
    t = np.arange(n) / 20_000.0
    rng = np.random.default_rng(0)
    u_a, u_b, i_a, i_b = rng.standard_normal((4, n))
    path = _write(tmp_path / "d.csv", "t,u_a,u_b,i_a,i_b", (t, u_a, u_b, i_a, i_b))
    rec = jaxobs.DriveRecording.from_csv(path, time_column="t", ts=1e-4)
    assert rec.n == n // 2 and not rec.has_truth
    m = jax.vmap(rec)(jnp.asarray(1e-4 * np.arange(rec.n)))  # rec(t) is one sample, t a scalar
    np.testing.assert_allclose(m.u_a, 0.5 * (u_a[0::2] + u_a[1::2]), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(m.u_b, 0.5 * (u_b[0::2] + u_b[1::2]), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(m.i_a, i_a[0::2], rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="must equal the observer's"):
        jaxobs.OnSignal(jaxobs.SOIFO(0.8, 0.005, 1.0, 0.25, 100.0, ts=2e-4), rec)


def test_drive_recording_runs_a_flux_observer_open_loop_against_the_encoder():
    """The shipped u/i recording (000's SPMSM, sensored FOC, 1000 r/min): 000's second-order SOIFO on the
    machine's Rs, L, run open loop on it, follows the recorded encoder angle; its wrapped angle column
    is unwrapped (the speed from it is the recorded one)."""
    par = D.spmsm_paper000(inertia="motor")
    rec = jaxobs.DriveRecording.from_csv(DRIVE_CSV, time_column="t", theta_e="theta_e", ts=1e-4)
    rec_w = jaxobs.DriveRecording.from_csv(DRIVE_CSV, time_column="t", theta_e="theta_e", omega_e="omega_e")
    assert rec.has_truth and rec.n == 3000
    # the derivative of the unwrapped angle is the recorded speed (to the angle's float32 rounding)
    assert float(jnp.max(jnp.abs(rec.omega_e[1:-1] - rec_w.omega_e[1:-1]))) < 0.05 * 2 * math.pi * 50
    k1, k2 = papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2
    obs = jaxobs.SecondOrderSOIFO(par.Rs, par.Ld, k1, k2, k1**3 / (2 * k2), 2 * math.pi * 50)
    sol = jaxobs.simulate(jaxobs.OnSignal(obs, rec_w), 0.3)
    assert bool(sol.ok)
    err = np.degrees(np.asarray(M.wrap(sol.outputs.obs.theta - sol.outputs.truth.theta)))
    steady = np.asarray(sol.t) >= 0.2
    assert np.sqrt(np.mean(err[steady] ** 2)) < 5.0  # measured 2.5 deg (the observer's own lag and ripple)
    # a wrong machine (L 5x too large) is visibly worse: the truth discriminates
    bad = jaxobs.SecondOrderSOIFO(par.Rs, 5 * par.Ld, k1, k2, k1**3 / (2 * k2), 2 * math.pi * 50)
    e_bad = np.degrees(np.asarray(M.wrap(jaxobs.simulate(jaxobs.OnSignal(bad, rec_w), 0.3).outputs.obs.theta)))
    e_bad = np.degrees(np.asarray(M.wrap(np.radians(e_bad) - np.asarray(sol.outputs.truth.theta))))
    assert np.sqrt(np.mean(e_bad[steady] ** 2)) > 2 * np.sqrt(np.mean(err[steady] ** 2))
    # the throughput loop (SaveFinal) reads the recording a block at a time (OnSignal.input_block, one slice
    # per block): the same samples and truth as the per-step read (the amplitude |u_ab| to its last bit: XLA
    # contracts the vectorized sum of squares differently), and the same running cost
    system = jaxobs.OnSignal(obs, rec_w)
    assert system._sample_offset() == 0
    ks = jnp.arange(5, 133, dtype=jnp.int32)
    for a, b in zip(jax.tree.leaves(system.input_block(ks)), jax.tree.leaves(jax.lax.map(system.input, ks))):
        np.testing.assert_allclose(a, b, rtol=4e-16, atol=0)

    def cost(o):
        return M.wrap(o.obs.theta - o.truth.theta) ** 2 + 1e-3 * o.truth.amplitude + 1e-6 * o.u.i_b

    fast = jaxobs.simulate(system, 0.3, save=jaxobs.SaveFinal(cost=cost))
    np.testing.assert_allclose(fast.cost, jaxobs.simulate(system, 0.3, save=jaxobs.SaveAll(cost=cost)).cost, rtol=1e-12)


def test_shipped_grid_recording_is_reproducible():
    """tuning/presets/recordings/grid_50_51hz.csv is what tests/make_recordings.py writes (to its 7 digits)."""
    import make_recordings

    header, cols = make_recordings.grid_table()
    text = GRID_CSV.read_text().splitlines()
    assert text[1] == header
    shipped = np.loadtxt(GRID_CSV, delimiter=",", skiprows=2)
    np.testing.assert_allclose(shipped, cols, rtol=1e-6, atol=1e-6)
    assert GRID_CSV.stat().st_size + DRIVE_CSV.stat().st_size < 500_000


# --------------------------------------------------------------------------
# recordings in job files
# --------------------------------------------------------------------------


def test_recording_job_runs_tiny(tmp_path):
    """tuning/presets/recording_wif.toml (the grid recording) runs two solver steps end to end: scores
    against the recording's truth, the recording's sha256 in result.json, one scenario."""
    from jaxobs_tuning.job import load_job, run_job

    job = load_job(ROOT / "tuning" / "presets" / "recording_wif.toml")
    job.solver = dataclasses.replace(job.solver, steps=2)
    res = run_job(job, tmp_path / "o", quiet=True)
    assert res["scenarios"]["count"] == 1
    assert res["recordings"][0]["file"] == "recordings/grid_50_51hz.csv"
    assert len(res["recordings"][0]["sha256"]) == 64
    for design in ("initial", "closed_form", "tuned"):
        s = res["scores"][design]
        assert s["diverged"] == 0 and 0 < s["itae_freq_mean"] < 0.01, (design, s)
    assert_cf18(tmp_path / "o" / "scores.nc")  # CF 1.8, the recordings labelled by file


@pytest.mark.slow
def test_drive_recording_job_runs_tiny(tmp_path):
    from jaxobs_tuning.job import load_job, run_job

    job = load_job(ROOT / "tuning" / "presets" / "recording_sosoifo.toml")
    job.solver = dataclasses.replace(job.solver, steps=2)
    res = run_job(job, tmp_path / "o", quiet=True)
    s = res["scores"]["initial"]
    assert s["diverged"] == 0 and s["rms_position_steady_mean"] < math.radians(5.0)
    assert_cf18(tmp_path / "o" / "scores.nc")  # a drive job's: lost_sync and lost_speed among the flags


def _job_copy(tmp_path, name="recording_wif.toml"):
    shutil.copytree(RECORDINGS, tmp_path / "recordings", dirs_exist_ok=True)
    path = tmp_path / name
    path.write_text((ROOT / "tuning" / "presets" / name).read_text())
    return path


@pytest.mark.parametrize(
    "old, new, field, words",
    [
        ('file = "recordings/grid_50_51hz.csv"', 'file = "recordings/none.csv"', "scenarios.recording.file", "cannot"),
        ('columns = ["v"]', 'columns = ["volts"]', "scenarios.recording.columns[0]", "no signal column 'volts'"),
        ('columns = ["v"]', "columns = [7]", "scenarios.recording.columns[0]", "index 7 is outside"),
        ('"omega", "amplitude"]', '"w", "amplitude"]', "scenarios.recording.truth[1]", "no truth column 'w'"),
        ('time_column = "t"', 'time_column = "time"', "scenarios.recording.time_column", "no time column"),
        ('time_column = "t"', 'time_column = "t"\nsample_rate = 1e4', "scenarios.recording", "exactly one"),
        ('time_column = "t"', "sample_rate = 5000.0", "scenarios.recording.file", "slower than the observer's ts"),
        ("horizon = 0.4", "horizon = 0.5", "scenarios.horizon", "needs 5000 samples"),
        ('truth = ["theta", "omega", "amplitude"]', 'truth = ["theta"]', "scenarios.recording.truth", "3 column"),
        ("[scenarios.recording]", "[scenarios.grid]\nsag = [0.1]\n[scenarios.recording]", "scenarios.grid", "apply"),
    ],
)
def test_recording_job_errors_name_the_field(tmp_path, capsys, old, new, field, words):
    from jaxobs_tuning.cli import main

    path = _job_copy(tmp_path)
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))
    assert main(["tune", str(path), "--check"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and field in err and words in err, err


def test_responses_plot_names_a_recording_scenario_by_its_file(tmp_path):
    """responses.png's title names a recording job's scenario by its file, not "recording = 0"; a grid
    job's scenario keeps its axis values."""
    from jaxobs_tuning.job import load_job
    from jaxobs_tuning.report import _describe

    job = load_job(_job_copy(tmp_path))
    assert _describe(job.scenarios, job.scenarios.family, 0) == "scenario #0: recording grid_50_51hz.csv"
    grid = load_job(ROOT / "tuning" / "presets" / "sogi_fll.toml")
    shown = _describe(grid.scenarios, grid.scenarios.family, 0)
    assert "recording" not in shown and " = " in shown
    # the axes by their long names and units, as the NetCDF coordinates name them, not the TOML keys
    wif = load_job(ROOT / "tuning" / "presets" / "wif_robust.toml")
    text = _describe(wif.scenarios, wif.scenarios.family, 17)
    assert "frequency step at the event = -2 Hz" in text and "phase jump at the event = 40 deg" in text, text
    assert "dc offset = 0.1 p.u." in text and "harmonic distortion = 1 × 001 Test C's spectrum" in text, text
    assert "freq_step" not in text and all(len(line) <= 110 for line in text.splitlines()), text


def test_recording_job_checks_size_and_the_closed_loop_metrics(tmp_path, capsys, monkeypatch):
    from jaxobs_tuning.cli import main
    from jaxobs_tuning.job import recordings as J

    path = _job_copy(tmp_path)
    monkeypatch.setattr(J, "MAX_RECORDING_BYTES", 1000)
    assert main(["tune", str(path), "--check"]) == 2
    assert "more than 1000" in capsys.readouterr().err
    monkeypatch.undo()
    drive = _job_copy(tmp_path, "recording_sosoifo.toml")
    drive.write_text(drive.read_text().replace("Rs = 0.8\n", ""))
    assert main(["tune", str(drive), "--check"]) == 2
    assert "component.Rs: required with a u/i recording" in capsys.readouterr().err


def test_study_file_on_a_recording(tmp_path, capsys):
    """A study file's [study.recording] (tuning/presets/study_recording_fll.toml, one design here): the
    designs run on the recording, study.nc has dims (design, recording) with units and the file's sha256."""
    import xarray as xr

    from jaxobs_tuning.cli import main

    path = _job_copy(tmp_path, "study_recording_fll.toml")
    text = path.read_text()
    path.write_text(text[: text.index("[designs.SOGI-FLL]")] + '[designs.WIF]\nclosed_form = "wif"\n')
    assert main(["study", str(path), "--out", str(tmp_path / "o"), "--quiet"]) == 0
    assert capsys.readouterr().err == ""
    with xr.open_dataset(tmp_path / "o" / "study.nc", engine="h5netcdf") as ds:
        ds = by_label(ds)
        assert ds["ripple_freq"].dims == ("design", "recording")
        assert str(ds["recording"].values[0]) == "recordings/grid_50_51hz.csv"
        assert all("units" in ds[v].attrs for v in ds.data_vars)
        assert 0 < float(ds["ripple_freq"].sel(design="WIF")[0]) < 0.1 and bool(ds["settled"].all())
        assert len(ds.attrs["recordings_sha256"]) == 64
    path.write_text(path.read_text().replace('time_column = "t"', 'time_column = "time"'))
    assert main(["study", str(path), "--out", str(tmp_path / "o2"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "study.recording.time_column" in err and "no time column 'time'" in err, err
