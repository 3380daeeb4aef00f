"""``jaxobs log check``: a log read as a job reads it, and what was understood of it printed before any job runs."""

import re
from pathlib import Path

import numpy as np

from jaxobs_tuning.cli import main
from jaxobs_tuning.cli_log import events

LOG = Path(__file__).parents[1] / "tuning" / "presets" / "recordings" / "drive_spmsm_1000rpm.csv"


def test_the_shipped_log_is_understood_with_its_events(capsys):
    """000's SPMSM at 1000 r/min with a speed step at 0.1 s and a load step at 0.2 s: the layout, rate, speed range
    and both events are printed, and no warning."""
    assert main(["log", "check", str(LOG), "--machine", "spmsm000", "--omega", "omega_e"]) == 0
    out = capsys.readouterr().out
    assert "voltages u_a, u_b: alpha_beta, V, applied over the period from their row" in out
    assert "sampled at 10000 Hz (ts = 0.0001 s), from 0 s, 0.3 s long" in out
    assert re.search(r"electrical speed 276\.\d+ … 340\.\d+ rad/s \(878\.\d+ … 1082\.\d+ r/min, p = 3\)", out)
    found = [(float(t), what) for t, what in re.findall(r"\n    ([0-9.]+) s: (speed|current amplitude)", out)]
    assert any(0.1 <= t <= 0.12 and w == "speed" for t, w in found), out  # the speed step's response
    assert any(0.2 <= t <= 0.205 and w == "current amplitude" for t, w in found), out  # the load step
    assert "warnings: none" in out


def test_a_mistake_the_reader_refuses_is_one_line(tmp_path, capsys):
    c = np.loadtxt(LOG, delimiter=",", comments="#", skiprows=2)
    c[:, 5] = np.degrees(np.mod(c[:, 5], 2 * np.pi))  # the angle in degrees, declared as radians
    f = tmp_path / "deg.csv"
    np.savetxt(f, c, delimiter=",", header="t,u_a,u_b,i_a,i_b,theta_e,omega_e", comments="", fmt="%.17g")
    assert main(["log", "check", str(f)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "it is in degrees (declare angle_unit = 'deg')" in err[0]


def test_a_warning_of_the_checks_is_listed(tmp_path, capsys):
    """References logged as applied voltages (one period early): the timing check's warning is printed."""
    c = np.loadtxt(LOG, delimiter=",", comments="#", skiprows=2)
    c[:, 1], c[:, 2] = np.roll(c[:, 1], -1), np.roll(c[:, 2], -1)
    f = tmp_path / "ref.csv"
    np.savetxt(f, c, delimiter=",", header="t,u_a,u_b,i_a,i_b,theta_e,omega_e", comments="", fmt="%.17g")
    assert main(["log", "check", str(f), "--machine", "spmsm000"]) == 0
    out = capsys.readouterr().out
    assert "warnings: 1" in out and "voltage_timing = 'reference', voltage_delay = 1" in out


def test_events_in_a_synthetic_record():
    """A step of 10 and a ramp of 10 over 0.1 s in a flat record: one step and one ramp at their times."""
    ts = 1e-4
    t = np.arange(0, 0.6, ts)
    x = 100 + 10 * (t >= 0.2) + np.clip((t - 0.4) / 0.1, 0, 1) * 10
    found = events(0.0, ts, x, np.full_like(t, 5.0))
    assert len(found) == 2, found
    assert found[0].startswith("0.2") and "speed step, 100 → 110" in found[0]
    assert found[1].startswith("0.4") and "speed ramp, 110 → 120" in found[1]
