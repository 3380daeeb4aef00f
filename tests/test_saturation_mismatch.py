"""benchmarks/saturation_mismatch.py's bookkeeping: the worst case over the dsat × speed grid, the scenarios the
mismatch loses, the ranking, and its arguments (synthetic grids: no simulation)."""

import math

import pytest

from benchmarks.saturation_mismatch import main, rank, summarize
from benchmarks.saturation_worst import rank_by_gradient, sensitivity

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


# --- the worst case by gradients (benchmarks/saturation_worst.py) ---


def test_a_derivative_that_disagrees_with_its_central_difference_is_rough():
    from benchmarks.saturation_worst import smooth

    assert smooth(4.732, 4.821)  # rofo at 900 r/min, dsat 0.5: forward mode and h = 1e-3 within 2 %
    assert not smooth(-2.30, -83.2)  # SOIFO in its limit cycle at 1440 r/min: the difference grows as 1/h
    assert smooth(0.01, 0.04)  # both below the flat slope's 0.05 deg/unit
    assert not smooth(math.nan, 1.0) and not smooth(1.0, math.inf)


def _found(worst=None, lost=()):
    return {"starts": [], "worst": worst, "lost": list(lost)}


def test_sensitivity_is_measured_against_dsat_zero_at_the_same_speed():
    # 900 r/min: rms 1 at dsat 0, 5 at dsat 1 (+4); 1440: 3 at dsat 0, 6 at dsat 1 (+3): the largest rise is 900's,
    # though 1440's rms is the larger
    g = grid([[2.0, 4.0], [1.0, 3.0], [5.0, 6.0]], [[False] * 2] * 3)
    g["rms_deg"] = [[2.0, 4.0], [1.0, 3.0], [5.0, 6.0]]
    s = sensitivity(_found(), g, DSAT, SPEEDS)
    assert s["sensitivity_deg"] == 4.0 and s["at"] == {"dsat": 1.0, "speed_rpm": 900.0} and s["by"] == "grid"
    # the ascent's worst replaces the grid's where it rises more, and a lost point it met counts as lost
    w = {"dsat": 1.7, "speed_rpm": 1440.0, "rms_deg": 8.0, "lost_lock": False}
    s = sensitivity(_found(w, [(2.0, 1440.0)]), g, DSAT, SPEEDS)
    assert s["by"] == "gradient" and s["sensitivity_deg"] == 5.0 and s["grid_sensitivity_deg"] == 4.0
    assert s["lost_by_mismatch"] == [(2.0, 1440.0)]


def test_gradient_ranking_puts_the_mismatch_s_lost_lock_first():
    def s(sens, lost=()):
        return {"sensitivity_deg": sens, "lost_by_mismatch": list(lost)}

    order = rank_by_gradient({"calm": s(1.0), "steep": s(9.0), "loses": s(0.5, [(2.0, 900.0)]), "none": s(math.nan)})
    assert order == ["loses", "steep", "calm", "none"]


# 44 s and 1.7 GiB.  Before the steady point's Newton iterations on a map became loops (jaxobs/drive/_operating.py,
# _iterate) its trace took 67 s and XLA's compile grew past 10 GiB, which exhausted CI's machine.
@pytest.mark.slow
def test_the_ascent_s_derivative_matches_central_differences():
    """d rms / d dsat by forward mode through the closed loop against the central difference, on a short run of the
    reduced-order flux observer at 900 r/min, dsat 0.5 (the voltage limit not reached): a NaN or a garbage
    derivative (the peak's through a loss of lock was 1e11 to 1e30) fails."""
    import dataclasses

    from benchmarks.saturation_mismatch import DRIVE, closed_forms
    from benchmarks.saturation_worst import Evaluator, check
    from jaxobs.drive import Drive, read_drive
    from jaxobs.scenarios.families.drive import DriveScenarios

    f = read_drive(DRIVE)
    drive = f.drive_for(sensorless=True)
    assert isinstance(drive, Drive)
    drive = dataclasses.replace(drive, settle=0.05)  # a short settle: a cheap case
    ev = Evaluator(DriveScenarios(f.machine, drive), closed_forms(drive.ts)["rofo"], [900.0], float(f.machine.T_rated),
                   0.05, 3)  # fmt: skip
    (r,) = check(ev, [0.5], [0])
    assert not r["lost_lock"] and 0.5 < r["rms_deg"] < 10.0
    assert abs(r["ad"]) > 1.0  # the mismatch moves the error: not a vanished derivative
    assert r["ad"] == pytest.approx(r["fd"], rel=0.02) and r["smooth"]
