"""Drive robustness studies: sensorless designs over operating points × mismatches × noise → NetCDF."""

import hashlib
import json
import math
import re
from pathlib import Path

import equinox as eqx
import numpy as np
import pytest
import xarray as xr

import jaxobs
from jaxobs import drive as D
from jaxobs import papers
from jaxobs.io.provenance import by_label
from jaxobs.scenarios.families import DriveScenarios
from jaxobs.studies.drive import QUANTILES, run_drive_study
from jaxobs.studies.study import run_study
from jaxobs_tuning.cli import main
from jaxobs_tuning.job import COMPONENTS, DriveSpec, JobError, job_drive
from jaxobs_tuning.study_file import load_study
from jaxobs_tuning.summary import study_warnings
from tests.cfcheck import assert_cf18

PAR = D.ipmsm_paper002(inertia="motor")
DRIVE = D.Drive(D.FOC.imc(PAR, alpha_c=2 * math.pi * 300, alpha_s=2 * math.pi * 5), sensorless=True)
DESIGNS = {"C-LESO": jaxobs.CLESO(PAR.Rs, PAR.Lq), "FA-LESO": jaxobs.FALESO(PAR.Rs, PAR.Lq)}
FAMILY = DriveScenarios(PAR, DRIVE)
PRESET = Path(__file__).resolve().parents[1] / "tuning" / "presets" / "study_leso_drive.toml"


def test_grid_study_dims_quantiles_and_the_papers_ordering():
    """A 2 × 2 × 2 grid (speed, dRs, dLq): labelled dims, quantiles over the scenarios, and the FA-LESO's
    frequency-adaptive internal model beats the C-LESO's lag on every scenario (002's point)."""
    axes = {"speed_rpm": [300.0, 600.0], "dRs": [-0.3, 0.3], "dLq": [-0.2, 0.2]}
    ds = run_study(DESIGNS, axes, family=FAMILY, horizon=0.06, chunk_size=8)
    assert ds["rms_position_steady"].dims == ("design", "speed_rpm", "dRs", "dLq")
    assert list(ds["quantile"].values) == list(QUANTILES)
    assert int(ds["lost_lock_count"].sum()) == 0
    assert int(ds["lost_speed_count"].sum()) == 0 and ds["lost_speed"].dims == ds["lost_lock"].dims
    c, fa = (np.degrees(ds["rms_position_steady"].sel(design=d)) for d in ("C-LESO", "FA-LESO"))
    assert bool((fa < c).all())
    # the C-LESO's steady lag is its transfer function's phase: 11.4° at 300 r/min, 22.6° at 600 (README)
    np.testing.assert_allclose(c.sel(dRs=0.3, dLq=0.2).values, [11.4, 22.6], atol=3.0)
    # ... which is its steady bias: the rms of a steady lag is the lag
    bias = np.degrees(ds["bias_position"].sel(design="C-LESO", dRs=0.3, dLq=0.2).values)
    np.testing.assert_allclose(bias, c.sel(dRs=0.3, dLq=0.2).values, rtol=0.02)
    # quantile 1.0 is the worst scenario
    q1 = float(ds["rms_position_steady_q"].sel(design="C-LESO", quantile=1.0))
    assert math.degrees(q1) == pytest.approx(float(c.max()))
    for v in ds.data_vars:
        assert "units" in ds[v].attrs, v


def test_sobol_sample_and_bad_axes():
    ds = run_study(
        {"FA-LESO": DESIGNS["FA-LESO"]},
        {"speed_rpm": [300.0, 600.0], "i_noise": [0.0, 0.1]},
        family=FAMILY,
        horizon=0.04,
        sampling="sobol",
        sample=8,
        chunk_size=8,
    )
    assert ds["rms_position_steady"].dims == ("design", "sample") and ds.sizes["sample"] == 8
    spd = ds["speed_rpm"].values
    assert np.all((spd >= 300.0) & (spd <= 600.0)) and np.unique(spd).size == 8
    # current noise shows in the speed estimate's sample-to-sample noise
    noise = ds["speed_noise"].sel(design="FA-LESO").values
    assert np.corrcoef(ds["i_noise"].values, noise)[0, 1] > 0.8
    with pytest.raises(ValueError, match="axes.spin"):
        run_study(DESIGNS, {"spin": [1.0]}, family=FAMILY)
    with pytest.raises(ValueError, match=r"axes.dRs must be .* in \[-0.95, 10\]"):
        run_study(DESIGNS, {"dRs": [-2.0]}, family=FAMILY)
    with pytest.raises(ValueError, match="sensorless"):
        run_study(DESIGNS, {"dRs": [0.0]}, family=DriveScenarios(PAR, D.Drive(DRIVE.foc)))


def _small_preset(tmp_path):
    text = PRESET.read_text()
    start = text.index("[axes]")
    small = text[:start] + "[axes]\nspeed_rpm = [600.0]\ndRs = [-0.2, 0.2]\ndLq = [-0.2, 0.2]\n"
    small = re.sub(r"horizon = [0-9.]+", "horizon = 0.04", small)
    assert "horizon = 0.04" in small
    p = tmp_path / "small.toml"
    p.write_text(small)
    return p


def test_cli_drive_study_writes_netcdf_with_the_axes(tmp_path, capsys):
    """The NetCDF: dims, units and long_name on every variable and coordinate, each design's gains as numbers,
    the machine and provenance (the study file's sha256), and the same bytes from two identical runs."""
    out, again = tmp_path / "out", tmp_path / "again"
    small = _small_preset(tmp_path)
    assert main(["study", str(small), "--out", str(out), "--quiet"]) == 0
    assert_cf18(out / "study.nc")  # CF 1.8: compliance-checker, attributes, types
    ds = by_label(xr.load_dataset(out / "study.nc", engine="h5netcdf"))
    assert {"dRs", "dLq"} <= set(ds["rms_position_steady"].dims) and "quantile" in ds.coords
    assert (out / "drive_study.png").stat().st_size > 10_000
    printed = capsys.readouterr().out
    # columns apart; the table in display units (deg, r/min), the file in SI
    assert "lost lock" in printed and "FA-LESO-tuned  rms_position_steady (deg)" in printed
    assert "speed_noise (r/min)" in printed
    assert "diverged" in printed and "lost speed" in printed  # each design's losses, lost speed included
    for name in [*ds.data_vars, *ds.coords]:
        assert "long_name" in ds[name].attrs, name
        if name != "design":
            assert "units" in ds[name].attrs and "see" not in ds[name].attrs["units"], name
    assert ds["dRs"].attrs["units"] == "1" and "resistance" in ds["dRs"].attrs["long_name"]
    # UDUNITS spellings (CF): r/min and deg are not parseable; the metrics SI
    assert ds["speed_rpm"].attrs["units"] == "min-1" and ds["rms_position_steady"].attrs["units"] == "rad"
    assert ds["speed_noise"].attrs["units"] == "rad s-1" and "pos_err_rms_deg" not in ds  # old names never written
    assert float(ds["gain_k2"].sel(design="FA-LESO-tuned")) == 613.683 and ds["gain_k2"].attrs["units"] == "s-1"
    assert float(ds["gain_omega0"].sel(design="C-LESO")) == pytest.approx(papers.LESO_OMEGA0)
    assert ds["gain_omega0"].attrs["units"] == "rad s-1"
    assert np.isnan(float(ds["gain_k1"].sel(design="C-LESO")))
    assert ds.attrs["study_sha256"] == hashlib.sha256(small.read_bytes()).hexdigest()
    assert ds.attrs["machine"].startswith("ipmsm002") and ds.attrs["machine_J"] == papers.BENCH_J_002
    assert ds.attrs["t_event"] == 0.0 and ds.attrs["jax_version"]
    assert main(["study", str(small), "--out", str(again), "--quiet"]) == 0
    assert (out / "study.nc").read_bytes() == (again / "study.nc").read_bytes()
    bad = tmp_path / "bad.toml"
    bad.write_text(_small_preset(tmp_path).read_text().replace("[axes]", "[axes]\nhorizn = [1.0]"))
    assert main(["study", str(bad), "--out", str(out)]) == 2


def test_drive_study_warnings_name_lost_speed_on_stderr(tmp_path, capsys):
    """A C-LESO of 30 rad/s loses lock and speed in every scenario, the closed form
    in none; stderr names lost speed beside lost lock, one line a design that lost anything.  Over 0.08 s: over
    0.04 s one scenario had not yet lost its speed once the settling phase started the PLL at the rotor's angle
    (init_aligned; from 0 rad the slow LESO's start was worse)."""
    study = tmp_path / "d.toml"
    study.write_text(
        '[study]\nkind = "drive"\nname = "d"\nmachine = "ipmsm002"\nhorizon = 0.08\n'
        '[designs.C-LESO]\nclosed_form = "CLESO"\n[designs.C-LESO-slow]\ncomponent = "CLESO"\nomega0 = 30.0\n'
        "[axes]\nspeed_rpm = [600.0]\ndRs = [-0.2, 0.2]\n"
    )
    assert main(["study", str(study), "--out", str(tmp_path / "o"), "--quiet"]) == 0
    got = capsys.readouterr()
    assert got.err.splitlines() == [
        "jaxobs: warning: C-LESO-slow: diverged in 0, lost lock in 2, lost speed in 2 of 2 scenarios"
    ]
    assert "jaxobs: warning" not in got.out
    # lost speed alone (the case the summary once left out: "lost lock 0", lost_speed = 1 in study.nc)
    ds = xr.Dataset(
        {
            "diverged": (("design", "speed_rpm"), np.zeros((2, 2), np.int8)),
            "lost_lock_count": (("design",), np.array([0, 0])),
            "lost_speed_count": (("design",), np.array([0, 1])),
        },
        coords={"design": ["a", "b"], "speed_rpm": [600.0, 1300.0]},
        attrs={"scenarios": 2},
    )
    assert study_warnings(ds) == ["b: diverged in 0, lost lock in 0, lost speed in 1 of 2 scenarios"]


@pytest.mark.slow
def test_the_leso_drive_preset_runs(tmp_path):
    """The shipped preset: 1024 scenarios per design, dRs and dLq dims and a quantile coordinate."""
    out = tmp_path / "leso"
    assert main(["study", str(PRESET), "--out", str(out), "--quiet"]) == 0
    ds = by_label(xr.open_dataset(out / "study.nc", engine="h5netcdf"))
    assert ds.attrs["scenarios"] >= 1000 and {"dRs", "dLq"} <= set(ds.dims) and "quantile" in ds.coords


def test_a_load_step_at_t_event_is_the_only_transient():
    """load_step_nm steps the load at t_event: before it the drive is steady (error as without a step), after
    it the FA-LESO's PLL sees the deceleration (the error grows)."""
    axes = {"speed_rpm": [600.0], "load_step_nm": [0.0, 5.0]}
    ds = run_study(
        {"FA-LESO": DESIGNS["FA-LESO"]},
        axes,
        family=DriveScenarios(PAR, DRIVE, t_event=0.03),
        horizon=0.08,
        steady_from=0.0,
        chunk_size=2,
    )
    peak = np.degrees(ds["peak_position_steady"].sel(design="FA-LESO", speed_rpm=600.0))
    assert float(peak.sel(load_step_nm=0.0)) < 0.1 < float(peak.sel(load_step_nm=5.0))


# --------------------------------------------------------------------------------------------------
# study files: the jobs' machines, closed forms, t_event (parsing only: cheap)
# --------------------------------------------------------------------------------------------------

STUDY_HEAD = '[study]\nkind = "drive"\nhorizon = 0.2\n'


def _cleso_result(tmp_path, machine: str) -> Path:
    """A drive job's result.json as run_job writes it (the fields a study reads): the C-LESO tuned on machine."""
    import tomllib

    job = tomllib.loads((PRESET.parent / "cleso.toml").read_text())
    job["drive"]["machine"] = machine
    p = tmp_path / f"result_{machine}.json"
    p.write_text(
        json.dumps({"job": job, "component": "CLESO", "gains": {"tuned": {"omega0": 3000.0}}, "machine": machine})
    )
    return p


def test_a_study_runs_the_jobs_machine_and_drive(tmp_path):
    """One machine table: a study of a tuning result runs the machine, bench inertia and FOC of the job that
    tuned it (jaxobs.drive.bench_machine / jaxobs_tuning.job.job_drive), and refuses another machine in one line."""
    res = _cleso_result(tmp_path, "spmsm000")
    st = tmp_path / "s.toml"
    st.write_text(STUDY_HEAD + f'[designs.tuned]\nresult = "{res.name}"\n[axes]\ndRs = [0.0]\n')
    spec = load_study(st)
    assert spec.family.machine == D.bench_machine("spmsm000") and float(spec.family.machine.J) == papers.BENCH_J_000
    want = job_drive(DriveSpec(machine="spmsm000"))
    got = spec.family.drive
    assert got.sensorless and got.ts == want.ts and got.settle == want.settle
    assert bool(eqx.tree_equal(got.foc, want.foc))
    assert float(spec.designs["tuned"].omega0) == 3000.0
    assert spec.provenance["machine"].startswith("spmsm000:")
    assert hashlib.sha256(res.read_bytes()).hexdigest() in spec.provenance["result_files"]
    # without a result: the component's default machine, the IPMSM on its bench (J = BENCH_J_002, not the motor's)
    st.write_text(STUDY_HEAD + '[designs.cf]\nclosed_form = "CLESO"\n[axes]\ndRs = [0.0]\n')
    assert float(load_study(st).family.machine.J) == papers.BENCH_J_002
    # a result tuned on one machine, the study on another: one line naming the design
    st.write_text(STUDY_HEAD + f'machine = "ipmsm002"\n[designs.tuned]\nresult = "{res.name}"\n[axes]\ndRs = [0.0]\n')
    with pytest.raises(JobError, match=r"designs.tuned.result: was tuned on spmsm000, the study runs ipmsm002"):
        load_study(st)


def test_closed_form_designs_have_the_jobs_closed_form_gains(tmp_path):
    st = tmp_path / "s.toml"
    st.write_text(
        STUDY_HEAD + '[designs.c]\nclosed_form = "CLESO"\n[designs.fa]\nclosed_form = "FALESO"\n[axes]\ndRs = [0.0]\n'
    )
    designs = load_study(st).designs
    for name, comp in (("c", "CLESO"), ("fa", "FALESO")):
        info = COMPONENTS[comp]
        cf = info.closed_form(info.ctor(**info.defaults))
        assert cf and all(float(getattr(designs[name], g)) == pytest.approx(v) for g, v in cf.items())
    assert float(designs["fa"].k1) == papers.FALESO_K1 and float(designs["c"].omega0) == papers.LESO_OMEGA0
    # the closed form's short name (as `jaxobs closed-form` takes it) names the same design
    st.write_text(STUDY_HEAD + '[designs.fa]\nclosed_form = "faleso"\n[axes]\ndRs = [0.0]\n')
    assert bool(eqx.tree_equal(load_study(st).designs["fa"], designs["fa"]))


def test_t_event_of_a_drive_study(tmp_path):
    """t_event: given, in [0, horizon); by default the middle of the horizon when a step axis is swept, else 0."""
    st = tmp_path / "s.toml"
    body = '[designs.c]\nclosed_form = "FALESO"\n[axes]\n'
    st.write_text(STUDY_HEAD + body + "load_step_nm = [0.0, 5.0]\n")
    assert load_study(st).family.t_event == pytest.approx(0.1)
    st.write_text(STUDY_HEAD + body + "dRs = [0.0]\n")
    assert load_study(st).family.t_event == 0.0
    st.write_text(STUDY_HEAD + "t_event = 0.05\n" + body + "speed_step_rpm = [100.0]\n")
    assert load_study(st).family.t_event == 0.05
    st.write_text(STUDY_HEAD + "t_event = 0.2\n" + body + "speed_step_rpm = [100.0]\n")
    with pytest.raises(JobError, match=r"study.t_event: must be in \[0, horizon = 0.2\) s"):
        load_study(st)
    with pytest.raises(ValueError, match="t_event must be in"):
        run_study(DESIGNS, {"dRs": [0.0]}, family=DriveScenarios(PAR, DRIVE, t_event=0.05), horizon=0.05)


def test_run_drive_study_is_a_deprecated_alias_of_the_one_preset():
    """The drive study's first preset warns and returns run_study's Dataset on the DriveScenarios it builds (its
    provenance the same function's), and refuses a family given with its own keywords."""
    axes = {"speed_rpm": [600.0], "dRs": [-0.2, 0.2]}
    ref = run_study(DESIGNS, axes, family=FAMILY, horizon=0.04, chunk_size=2)
    with pytest.warns(DeprecationWarning, match="run_study"):
        old = run_drive_study(DESIGNS, axes, machine=PAR, drive=DRIVE, horizon=0.04, chunk_size=2)
    xr.testing.assert_identical(old, ref)
    with pytest.warns(DeprecationWarning), pytest.raises(ValueError, match="not both"):
        run_drive_study(DESIGNS, axes, family=FAMILY, machine=PAR)


def test_a_component_design_on_a_users_drive_file_runs_at_the_files_period(tmp_path):
    """A study's ``component`` design with explicit gains on a drive file sampled at 20 kHz (the Teknic's) runs at
    the file's period, as a closed form does; it was refused ("runs at ts = 0.0001 s ... must agree") with no key
    to set it."""
    teknic = Path(__file__).resolve().parents[1] / "docs" / "examples" / "teknic_m2310p.toml"
    st = tmp_path / "study.toml"
    st.write_text(
        STUDY_HEAD
        + f'[drive]\nfile = "{teknic.as_posix()}"\n'
        + '[designs.FAx]\ncomponent = "FALESO"\nk1 = 40.0\nk2 = 300.0\n'
        + '[designs.CF]\nclosed_form = "FALESO"\n'
        + "[axes]\nspeed_rpm = [1000.0]\n"
    )
    spec = load_study(st)
    assert {float(o.ts) for o in spec.designs.values()} == {5e-5}
    assert float(spec.designs["FAx"].k1) == 40.0
