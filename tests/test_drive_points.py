"""``jaxobs drive check --simulate`` (jaxobs.analysis.drive_points): the rated point and the top speed of a drive
file, run sensored in one batch, and the verdict printed."""

import re
from pathlib import Path

import numpy as np
import pytest

import jaxobs
import jaxobs.drive as D
from jaxobs.analysis.drive_points import PointResult, check_points, horizon, point_verdict, run_points
from jaxobs_tuning.cli import main

EXAMPLES = Path(__file__).parents[1] / "docs" / "examples"
TRACTION = EXAMPLES / "traction_ipmsm.toml"


def test_the_points_are_the_rating_and_the_lower_of_the_speed_limit_and_1p5_base_speed():
    """Traction: 1.5 × base speed (3997 r/min) is below its 12000 r/min limit, loaded at 95 % of the capability
    there (103.1 N·m); Teknic: its 5172 r/min speed limit is below 1.5 × base, and the curve has no torque there at
    the 95 % voltage margin, so it runs at no load."""
    f = D.read_drive(TRACTION)
    (r_name, r_n, r_t), (t_name, t_n, t_t) = check_points(f)
    assert (r_name, r_n, r_t) == ("rated", 3000.0, 135.0)
    assert t_name == "top" and t_n == pytest.approx(1.5 * f.derived["base_speed_rpm"].value, rel=1e-12)
    assert t_t == pytest.approx(0.95 * float(f.capability([t_n])["torque"][0]), rel=1e-12)
    assert t_t == pytest.approx(97.98, abs=0.01)
    assert horizon(f) == pytest.approx(10.0 / (2 * np.pi * 5.0))
    tek = D.read_drive(EXAMPLES / "teknic_m2310p.toml")
    assert check_points(tek)[1] == ("top", pytest.approx(tek.speed_limit_rpm), 0.0)


@pytest.mark.parametrize(
    ("r", "verdict", "key"),
    [
        (PointResult("rated", 3000.0, 135.0, 2999.9, True, 0.95, 0.95), "held", None),
        (PointResult("top", 5172.0, 0.0, 5169.0, True, 0.004, 1.0), "held, at the voltage limit", None),
        (PointResult("top", 4000.0, 120.0, 3500.0, False, 0.9, 1.0), "NOT held", "raise inverter.u_dc"),
        (PointResult("rated", 3000.0, 200.0, 2500.0, False, 1.0, 0.8), "NOT held", "raise control.i_max_a"),
        (PointResult("rated", 3000.0, 10.0, 2500.0, False, 0.3, 0.5), "NOT held", "control.speed_bandwidth_hz"),
        (PointResult("top", 4000.0, 50.0, 4000.0, True, 1.05, 0.9), "held, current above i_max", "control.i_max_a"),
    ],
)
def test_a_point_not_held_names_the_key_to_change(r, verdict, key):
    """The verdict, and the key: the voltage's where |u| reached u_dc/√3, the current limit's where |i| reached
    i_max, the speed loop's where neither; the rating (rated) or the speed (top) to lower instead."""
    v, w = point_verdict(r)
    assert v == verdict
    if key is None:
        assert w is None
    else:
        assert key in w and ("machine.rated_torque_nm" if r.name == "rated" else "machine.max_speed_rpm") in w


@pytest.mark.slow
def test_traction_ipmsm_holds_both_points_within_i_max_and_the_check_says_so(capsys):
    """GEM's traction IPMSM sensored: the rated point (3000 r/min, 135 N·m) and 1.5 × base speed at 95 % of the
    capability (3997 r/min, 97.98 N·m) are held, |i| ≤ i_max at every sample; the batch of two is the
    simulation a single run gives (the top point run alone), and ``drive check --simulate`` prints its numbers."""
    f = D.read_drive(TRACTION)
    res = run_points(f)
    assert [r.name for r in res] == ["rated", "top"]
    for r in res:
        assert r.held and abs(r.mean_rpm - r.speed_rpm) < 0.5, r
        assert r.i_ratio <= 1.0, r
        assert r.u_ratio <= 1.0 + 1e-6, r
        assert point_verdict(r)[1] is None
    _, n, t = check_points(f)[1]
    sc = D.Scenario(f.machine, speed_ref=D.Profile.constant(n * D.RPM), omega_m0=n * D.RPM,
                    load=D.Profile.constant(t))  # fmt: skip
    out = jaxobs.simulate(D.ClosedLoop(f.drive_for(sensorless=False), None, sc), horizon(f)).outputs
    rpm = np.asarray(out.speed_rpm)
    alone = np.mean(rpm[len(rpm) - len(rpm) // 4 :])
    assert res[1].mean_rpm == pytest.approx(alone, abs=1e-2)
    i_alone = np.max(np.hypot(out.i_d, out.i_q)) / f.derived["i_max"].value
    assert res[1].i_ratio == pytest.approx(i_alone, rel=1e-4)
    assert main(["drive", "check", "--no-cache", str(TRACTION), "--simulate"]) == 0
    text = capsys.readouterr().out
    for r in res:
        line = next(ln for ln in text.splitlines() if ln.startswith(f"  {r.name} "))
        nums = [float(x) for x in re.findall(r"(?<![\w.])[-+]?\d+(?:\.\d+)?", line.split("mean", 1)[1])]
        assert nums[0] == pytest.approx(r.mean_rpm, rel=1e-4)
        assert nums[-2:] == [pytest.approx(r.i_ratio, abs=5e-4), pytest.approx(r.u_ratio, abs=5e-4)]
        assert line.endswith(": held")
    assert "operating points not simulated" not in text and "warning:" not in text
