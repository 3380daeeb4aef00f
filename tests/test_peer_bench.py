"""benchmarks/peer.py (motulator as a yardstick): its operating points, horizons and command line, without running
either simulator (the benchmark itself takes minutes)."""

from __future__ import annotations

import pytest

from benchmarks import peer


def test_operating_points_are_the_batch_sizes_asked_for_and_distinct():
    assert peer.operating_points(1) == [(peer.SCENARIO["rpm"], peer.SCENARIO["load_nm"])]
    for n in (2, 64, 1000, 1024, 8192):
        pts = peer.operating_points(n)
        assert len(pts) == n and len(set(pts)) == n
        speeds, loads = zip(*pts, strict=True)
        assert min(speeds) == 250.0 and max(speeds) <= 1250.0
        assert min(loads) == 0.0 and max(loads) <= 14.0
    assert {s for s, _ in peer.operating_points(64, 0.5)} == {0.5 * (250 + 1000 * i / 7) for i in range(8)}  # 8 x 8
    with pytest.raises(ValueError, match="batch size"):
        peer.operating_points(0)


def test_batch_horizon_scales_the_scenario_and_is_checked():
    b = peer.batch_scenario(0.2)
    assert b["t_end"] == 0.2 and b["ramp_s"] == pytest.approx(0.05) and b["load_at"] == pytest.approx(0.1)
    assert b["ramp_s"] < b["load_at"] < b["t_end"]
    for bad in (0.0, -1.0, 11.0):
        with pytest.raises(ValueError, match="--batch-horizon must be in"):
            peer.batch_scenario(bad)


def test_agreement_is_zero_on_identical_trajectories_and_sees_a_difference():
    import numpy as np

    n, i_d, i_q = np.linspace(0, 1000, 50), np.zeros(50), np.linspace(0, 5, 50)
    same = peer.agreement((n, i_d, i_q), {"rpm": n, "i_d": i_d, "i_q": i_q}, 6.0)
    assert same["speed_rpm"] == 0.0 and same["i_dq_pu"] == 0.0 and same["samples"] == 50
    off = peer.agreement((n + 2.0, i_d + 0.6, i_q), {"rpm": n, "i_d": i_d, "i_q": i_q}, 6.0)
    assert off["speed_rpm"] == pytest.approx(2.0) and off["i_dq_pu"] == pytest.approx(0.1)


def test_help_and_bad_arguments():
    with pytest.raises(SystemExit) as done:
        peer.main(["--help"])
    assert done.value.code == 0
    with pytest.raises(SystemExit) as done:
        peer.main(["--batches", "0"])
    assert done.value.code == 2
    with pytest.raises(SystemExit) as done:
        peer.main(["--motulator-python", "/nonexistent/python3.12"])
    assert done.value.code == 2
