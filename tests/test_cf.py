"""Every NetCDF the commands write is CF 1.8 (jaxobs.io.provenance.cf_dataset; compliance-checker, tests/cfcheck.py):
the helper itself, and a tune's scores.nc on sampled scenarios with its holdout_scores.nc.  The grid scores.nc,
both kinds of study.nc and envelope.nc are checked where their command tests write them (test_tuning_results,
test_study, test_drive_study, test_envelope)."""

import numpy as np
import pytest
import xarray as xr

from jaxobs.io.provenance import CONVENTIONS, REFERENCES, by_label, cf_dataset, cf_labels, cf_missing
from jaxobs_tuning.cli import main
from tests.cfcheck import assert_cf18, cf_failures
from tests.test_tuning import GOOD


def _dataset():
    return xr.Dataset(
        {"count": (("design",), np.array([3, 0], dtype=np.int64), {"units": "1", "long_name": "scenarios lost"})},
        coords={
            "design": ("design", ["a", "b"], {"long_name": "observer design"}),
            "scenario": ("scenario", np.arange(2, dtype=np.uint64), {"units": "1", "long_name": "scenario"}),
        },
        attrs={"source": "here"},
    )


def test_cf_dataset_sets_the_global_attributes_int32_and_no_fill_on_coordinates(tmp_path):
    ds = cf_dataset(_dataset(), "a test")
    assert ds.attrs["Conventions"] == CONVENTIONS == "CF-1.8" and ds.attrs["title"] == "a test"
    assert ds.attrs["source"] == "here" and "here" in ds.attrs["history"] and ds.attrs["references"] == REFERENCES
    assert ds["count"].dtype == np.int32 and ds["scenario"].dtype == np.int32  # CF 1.8: no int64, no unsigned
    assert ds["count"].attrs["long_name"] == "scenarios lost" and ds["scenario"].attrs["units"] == "1"
    assert list(ds["count"].values) == [3, 0] and cf_missing(ds) == []
    # the designs' names as a string coordinate variable: compliance-checker's monotonicity check fails on it
    ds.to_netcdf(tmp_path / "names.nc", engine="h5netcdf")
    assert any("monotonicity" in f for f in cf_failures(tmp_path / "names.nc"))
    # as the commands write it: a numeric design index, the names its label; read back by name
    cf_labels(ds).to_netcdf(tmp_path / "x.nc", engine="h5netcdf")
    assert_cf18(tmp_path / "x.nc")
    back = by_label(xr.load_dataset(tmp_path / "x.nc", engine="h5netcdf"))
    assert list(back["design"].values) == ["a", "b"] and int(back["count"].sel(design="b")) == 0
    assert back["design"].attrs["long_name"] == "observer design" and "design_label" not in back.variables
    # what the checks catch: a variable without long_name or units, a coordinate with a _FillValue, int64
    bad = _dataset()
    bad["value"] = ("design", [1.0, 2.0])
    bad.coords["speed"] = ("speed", [1.0, 2.0], {"units": "min-1", "long_name": "speed"})
    assert cf_missing(bad) == ["value: no long_name", "value: no units"]
    bad.to_netcdf(tmp_path / "bad.nc", engine="h5netcdf")
    failures = " ".join(cf_failures(tmp_path / "bad.nc"))
    assert "_FillValue" in failures and "int64" in failures and "long_name" in failures
    big = _dataset().assign(count=("design", np.array([2**40, 0]), {"units": "1", "long_name": "n"}))
    with pytest.raises(ValueError, match=r"^count must hold integers in \[-2147483648, 2147483647\]"):
        cf_dataset(big, "too big")


def test_tune_on_sampled_scenarios_writes_cf_scores_and_holdout_scores(tmp_path):
    """The cheapest tune (one step) with a sampled scenario set (a ``scenario`` dim) and a held-out grid."""
    job = GOOD.replace(
        "[scenarios.grid]\nfreq_step = [1.0, 2.0]", "sample = 2\n[scenarios.grid]\nfreq_step = [1.0, 2.0]"
    )
    job = job.replace("steps = 3", "steps = 1") + "[holdout.grid]\nfreq_step = [1.5]\n"
    assert "sample = 2" in job and "steps = 1" in job
    path = tmp_path / "job.toml"
    path.write_text(job)
    assert main(["tune", str(path), "--out", str(tmp_path / "o"), "--quiet"]) == 0
    for name in ("scores.nc", "holdout_scores.nc"):
        assert_cf18(tmp_path / "o" / name)
    raw = xr.load_dataset(tmp_path / "o" / "scores.nc", engine="h5netcdf")
    assert raw["design"].dtype == np.int32 and list(raw["design_label"].values) == ["initial", "closed_form", "tuned"]
    ds = by_label(raw)
    assert ds["itae_freq"].dims == ("design", "scenario") and ds["scenario"].dtype == np.int32
    assert (
        "held out" in by_label(xr.load_dataset(tmp_path / "o" / "holdout_scores.nc", engine="h5netcdf")).attrs["title"]
    )
