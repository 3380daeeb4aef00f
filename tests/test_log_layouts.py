"""Every layout a drive log is read in scores as the clean α-β file does (benchmarks/log_layouts.py, the table of
docs/recordings.md): a few layouts here, on one compiled scoring function."""

import jax
import pytest

from benchmarks import log_layouts as B

jax.config.update("jax_enable_x64", True)

PICKED = (
    "three phase currents",
    "two phase voltages, zero sequence none",
    "d-q voltages, turned by the angle",
    "mechanical degrees, r/min",
    "';' and decimal ','",
    "d-q references + phase currents, delay 1",
)


@pytest.fixture(scope="module")
def measured():
    layouts = tuple(lay for lay in B.LAYOUTS if lay.name in PICKED)
    assert len(layouts) == len(PICKED)
    return B.measure(layouts=layouts)


def test_a_layout_without_delay_scores_as_the_clean_file_to_1e_6(measured):
    rows = [r for r in measured["rows"] if not r["delay"]]
    assert len(rows) == 5
    for r in rows:
        assert r["rel_diff"] < 1e-6, (r["layout"], r["rel_diff"])


def test_a_reference_layout_scores_as_the_clean_file_from_its_first_kept_row(measured):
    """The delay drops the first row: against the whole clean file the run differs (1e-4 relative, started a period
    later), against the clean file read from row 1 it is the same run to 1e-6."""
    (r,) = [r for r in measured["rows"] if r["delay"]]
    assert r["delay"] == 1
    assert 1e-5 < r["rel_diff"] < 1e-2
    assert r["rel_diff_same_row"] < 1e-6


def test_the_table_shows_every_layout():
    res = {"clean": dict.fromkeys(B.METRICS, 1.0), "rows": []}
    for lay in B.LAYOUTS:
        row = {"layout": lay.name, "scores": dict.fromkeys(B.METRICS, 1.0), "rel_diff": 0.0, "delay": lay.delay}
        res["rows"].append({**row, "rel_diff_same_row": 0.0} if lay.delay else row)
    text = B.table(res)
    assert len(text.splitlines()) == 3 + len(B.LAYOUTS)
    assert all(lay.name in text for lay in B.LAYOUTS)
