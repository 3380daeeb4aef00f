"""The CF-1.8 check of a NetCDF the commands write: compliance-checker's high-priority failures, and the
attributes checked directly (tests/test_cf.py; the command tests call :func:`assert_cf18` on their files)."""

from __future__ import annotations

import numpy as np
import xarray as xr

from jaxobs.io.provenance import CONVENTIONS, cf_missing


def _failed(value) -> bool:
    if isinstance(value, tuple):
        return value[0] < value[1]
    return not value


def cf_failures(path) -> list[str]:
    """compliance-checker's CF 1.8 high-priority failures ("errors") of the NetCDF at ``path``, each as
    ``section: message``; any exception it raised, as ``exception: ...`` (every coordinate variable is numeric:
    the designs' names are a label, jaxobs.io.provenance.cf_labels, so its monotonicity check runs on each)."""
    from compliance_checker.cf.cf_1_8 import CF1_8Check
    from compliance_checker.runner import CheckSuite

    suite = CheckSuite()
    suite.checkers["cf:1.8"] = CF1_8Check  # the CF checker alone (all of them: deprecation warnings of others)
    nc = suite.load_dataset(str(path))
    try:
        results, errors = suite.run_all(nc, ["cf:1.8"], skip_checks=[])["cf:1.8"]
    finally:
        nc.close()
    # a failure scores less than it could (a check that only reports what it found scores 0 of 0: 2.7.1's
    # "found in same group" notes are not failures, and the checker's own report leaves them out)
    failed = [r for r in results if r.weight == 3 and _failed(r.value)]
    out = [f"{r.name}: {m}" for r in failed for m in (r.msgs or ["failed"])]
    out += [f"exception: {k}: {v[0]}" for k, v in errors.items()]
    return out


def assert_cf18(path) -> None:
    """The NetCDF at ``path`` is CF 1.8: no high-priority failure of compliance-checker, the global attributes,
    a long_name on every variable and units on every numeric one, CF integer types, no ``_FillValue`` on a
    coordinate, every coordinate variable numeric and strictly monotonic (a design's name is the label
    ``design_label``)."""
    failures = cf_failures(path)
    assert failures == [], (str(path), failures)
    ds = xr.open_dataset(path, engine="h5netcdf", decode_cf=False)
    try:
        assert ds.attrs["Conventions"] == CONVENTIONS
        for key in ("title", "history", "source", "institution", "references"):
            assert isinstance(ds.attrs.get(key), str) and ds.attrs[key], key
        assert "000" in ds.attrs["references"] and "doi:10.1109/TPEL.2018.2808246" in ds.attrs["references"]
        assert cf_missing(ds) == []
        for name, v in ds.variables.items():
            assert v.dtype.kind not in "iu" or v.dtype.itemsize <= 4, (name, v.dtype)  # no int64 (CF 1.8)
            if name in ds.dims:
                assert "_FillValue" not in v.attrs, name
                assert v.dtype.kind in "if", (name, v.dtype)  # no string coordinate variable
                if v.size > 1:
                    d = np.diff(v.values)
                    assert (d > 0).all() or (d < 0).all(), name
        if "design" in ds.dims:
            assert ds["design_label"].dims == ("design",) and ds["design_label"].dtype.kind in "OUS"
            assert list(ds["design"].values) == list(range(ds.sizes["design"]))
    finally:
        ds.close()
