"""Drive robustness studies: sensorless designs over operating points × mismatches × noise → NetCDF."""

import math
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import jaxobs
from jaxobs import drive as D
from jaxobs.drive_study import QUANTILES, run_drive_study
from tuning.cli import main

PAR = D.ipmsm_paper002()
DRIVE = D.Drive(D.FOC.imc(PAR, alpha_c=2 * math.pi * 300, alpha_s=2 * math.pi * 5), sensorless=True)
DESIGNS = {"C-LESO": jaxobs.CLESO(PAR.Rs, PAR.Lq), "FA-LESO": jaxobs.FALESO(PAR.Rs, PAR.Lq)}
PRESET = Path(__file__).resolve().parents[1] / "tuning" / "presets" / "study_leso_drive.toml"


def test_grid_study_dims_quantiles_and_the_papers_ordering():
    """A 2 × 2 × 2 grid (speed, dRs, dLq): labelled dims, quantiles over the scenarios, and the FA-LESO's
    frequency-adaptive internal model beats the C-LESO's lag on every scenario (002's point)."""
    axes = {"speed_rpm": [300.0, 600.0], "dRs": [-0.3, 0.3], "dLq": [-0.2, 0.2]}
    ds = run_drive_study(DESIGNS, axes, machine=PAR, drive=DRIVE, horizon=0.06, chunk_size=8)
    assert ds["pos_err_rms_deg"].dims == ("design", "speed_rpm", "dRs", "dLq")
    assert list(ds["quantile"].values) == list(QUANTILES)
    assert int(ds["lost_lock_count"].sum()) == 0
    assert int(ds["lost_speed_count"].sum()) == 0 and ds["lost_speed"].dims == ds["lost_lock"].dims
    c, fa = (ds["pos_err_rms_deg"].sel(design=d) for d in ("C-LESO", "FA-LESO"))
    assert bool((fa < c).all())
    # the C-LESO's steady lag is its transfer function's phase: 11.4° at 300 r/min, 22.6° at 600 (README)
    np.testing.assert_allclose(c.sel(dRs=0.3, dLq=0.2).values, [11.4, 22.6], atol=3.0)
    # quantile 1.0 is the worst scenario
    assert float(ds["pos_err_rms_deg_q"].sel(design="C-LESO", quantile=1.0)) == pytest.approx(float(c.max()))
    for v in ds.data_vars:
        assert "units" in ds[v].attrs, v


def test_sobol_sample_and_bad_axes():
    ds = run_drive_study(
        {"FA-LESO": DESIGNS["FA-LESO"]},
        {"speed_rpm": [300.0, 600.0], "i_noise": [0.0, 0.1]},
        machine=PAR,
        drive=DRIVE,
        horizon=0.04,
        sampling="sobol",
        sample=8,
        chunk_size=8,
    )
    assert ds["pos_err_rms_deg"].dims == ("design", "sample") and ds.sizes["sample"] == 8
    spd = ds["speed_rpm"].values
    assert np.all((spd >= 300.0) & (spd <= 600.0)) and np.unique(spd).size == 8
    # current noise shows in the speed estimate's sample-to-sample noise
    noise = ds["speed_noise_rpm"].sel(design="FA-LESO").values
    assert np.corrcoef(ds["i_noise"].values, noise)[0, 1] > 0.8
    with pytest.raises(ValueError, match="axes.spin"):
        run_drive_study(DESIGNS, {"spin": [1.0]}, machine=PAR, drive=DRIVE)
    with pytest.raises(ValueError, match=r"axes.dRs must be .* in \[-0.95, 10\]"):
        run_drive_study(DESIGNS, {"dRs": [-2.0]}, machine=PAR, drive=DRIVE)
    with pytest.raises(ValueError, match="sensorless"):
        run_drive_study(DESIGNS, {"dRs": [0.0]}, machine=PAR, drive=D.Drive(DRIVE.foc))


def _small_preset(tmp_path):
    text = PRESET.read_text()
    start = text.index("[axes]")
    small = text[:start] + "[axes]\nspeed_rpm = [600.0]\ndRs = [-0.2, 0.2]\ndLq = [-0.2, 0.2]\n"
    small = small.replace("horizon = 0.3", "horizon = 0.04")
    p = tmp_path / "small.toml"
    p.write_text(small)
    return p


def test_cli_drive_study_writes_netcdf_with_the_axes(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["study", str(_small_preset(tmp_path)), "--out", str(out), "--quiet"]) == 0
    ds = xr.open_dataset(out / "study.nc", engine="scipy")
    assert {"dRs", "dLq"} <= set(ds["pos_err_rms_deg"].dims) and "quantile" in ds.coords
    assert (out / "drive_study.png").stat().st_size > 10_000
    assert "lost lock" in capsys.readouterr().out
    bad = tmp_path / "bad.toml"
    bad.write_text(_small_preset(tmp_path).read_text().replace("[axes]", "[axes]\nhorizn = [1.0]"))
    assert main(["study", str(bad), "--out", str(out)]) == 2


@pytest.mark.slow
def test_the_leso_drive_preset_runs(tmp_path):
    """The shipped preset: 1024 scenarios per design, dRs and dLq dims and a quantile coordinate."""
    out = tmp_path / "leso"
    assert main(["study", str(PRESET), "--out", str(out), "--quiet"]) == 0
    ds = xr.open_dataset(out / "study.nc", engine="scipy")
    assert ds.attrs["scenarios"] >= 1000 and {"dRs", "dLq"} <= set(ds.dims) and "quantile" in ds.coords


def test_a_load_step_at_t_event_is_the_only_transient():
    """load_step_nm steps the load at t_event: before it the drive is steady (error as without a step), after
    it the FA-LESO's PLL sees the deceleration (the error grows)."""
    axes = {"speed_rpm": [600.0], "load_step_nm": [0.0, 5.0]}
    ds = run_drive_study(
        {"FA-LESO": DESIGNS["FA-LESO"]},
        axes,
        machine=PAR,
        drive=DRIVE,
        horizon=0.08,
        steady_from=0.0,
        t_event=0.03,
        chunk_size=2,
    )
    peak = ds["pos_err_max_deg"].sel(design="FA-LESO", speed_rpm=600.0)
    assert float(peak.sel(load_step_nm=0.0)) < 0.1 < float(peak.sel(load_step_nm=5.0))
