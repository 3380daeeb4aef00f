"""benchmarks/saturation_mismatch.py's bookkeeping: the worst case over the dsat × speed grid, the scenarios the
mismatch loses, the ranking, and its arguments (synthetic grids: no simulation)."""

import math

import pytest

from benchmarks.saturation_mismatch import main, rank, summarize

DSAT = (-0.5, 0.0, 1.0)
SPEEDS = (900.0, 1440.0)


def grid(peak, lost):
    return {"peak_deg": peak, "rms_deg": [[p / 2 for p in row] for row in peak], "lost_lock": lost}


def test_worst_case_skips_lost_scenarios_and_names_where():
    g = grid([[4.0, 99.0], [2.0, 3.0], [7.0, 5.0]], [[False, True], [False, False], [False, False]])
    s = summarize(g, DSAT, SPEEDS)
    assert s["worst_peak_deg"] == 7.0 and s["worst_at"] == {"dsat": 1.0, "speed_rpm": 900.0}
    assert s["nominal_peak_deg"] == 3.0 and s["sensitivity_deg"] == 4.0
    assert s["worst_rms_deg"] == 3.5
    assert s["lost_lock"] == [(-0.5, 1440.0)] and s["lost_by_mismatch"] == 1


def test_a_speed_lost_at_dsat_zero_is_not_the_mismatch_s():
    # 900 r/min is lost at every dsat: the mismatch loses nothing there
    lost = [[True, False], [True, False], [True, False]]
    s = summarize(grid([[1.0, 2.0], [1.0, 2.0], [1.0, 2.5]], lost), DSAT, SPEEDS)
    assert s["lost_by_mismatch"] == 0 and s["sensitivity_deg"] == pytest.approx(0.5)
    none = summarize(grid([[1.0] * 2] * 3, [[True] * 2] * 3), DSAT, SPEEDS)
    assert math.isnan(none["worst_peak_deg"]) and math.isnan(none["nominal_peak_deg"])


def test_ranking_puts_lost_lock_before_error_growth():
    calm = summarize(grid([[1.0, 1.0], [1.0, 1.0], [9.0, 1.0]], [[False] * 2] * 3), DSAT, SPEEDS)
    loses = summarize(grid([[1.0, 1.0], [1.0, 1.0], [1.0, 1.0]], [[False] * 2] * 2 + [[False, True]]), DSAT, SPEEDS)
    flat = summarize(grid([[1.0, 1.0]] * 3, [[False] * 2] * 3), DSAT, SPEEDS)
    assert rank({"calm": calm, "loses": loses, "flat": flat}) == ["loses", "calm", "flat"]


@pytest.mark.parametrize("argv", [["--dsat", "1", "2"], ["--dsat", "0", "11"]])
def test_bad_dsat_is_a_usage_error(argv, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2 and "--dsat" in capsys.readouterr().err
