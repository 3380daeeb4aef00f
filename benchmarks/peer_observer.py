"""The reduced-order flux observer beside motulator's: the same machine, cases and closed-form gains, peak errors.

``python -m benchmarks.peer_observer [--motulator-python PATH] [--json FILE]``

jaxobs runs :class:`jaxobs.ReducedOrderFluxObserver` (closed form) closing the sensorless loop of the 2.2-kW lab
IPMSM drive file (``docs/examples/ipmsm_2p2kw_lab.toml``: 8 kHz, 2π·200 rad/s current loop, 2π·4 rad/s speed
loop, ideal sensors); motulator 0.18 runs its own drive with its default observer, the same observer by its
authors (:mod:`benchmarks.peer_motulator`, in a Python that has motulator: ``--motulator-python`` or
``$MOTULATOR_PYTHON``; skipped, and said so, where there is none).  Cases: a ±750 r/min reversal in 1 s without
load, a 7 N·m step at 15 r/min, a 14 N·m step at 750 r/min.  Printed per case: the peak electrical angle error
and the lowest and final speed over the window from 0.2 s before the event to the end.  The two drives differ
in their speed controllers (jaxobs: I-P on Ĵ/K̂t; motulator: its 2-DOF PI on Ĵ) and in how they start (jaxobs
starts steady after a 0.2 s settle; motulator ramps from standstill), so the speeds differ slightly; the angle
errors are the observers'.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LAB = ROOT / "docs" / "examples" / "ipmsm_2p2kw_lab.toml"
T_EVENT = 0.2  # the event's time in the jaxobs runs (each starts steady at t = 0), s

# case -> (speed before, r/min; the speed profile's knots after it (times from the event, r/min); load step; t_end)
CASES = {
    "reversal_750": (750.0, ((0.0, 750.0), (1.0, -750.0)), 0.0, 1.5),
    "step_7nm_15rpm": (15.0, (), 7.0, 1.0),
    "step_14nm_750rpm": (750.0, (), 14.0, 0.6),
}


def jaxobs_cases() -> dict:
    """The cases run by jaxobs (float64), each ``{"peak_deg", "min_rpm", "final_rpm"}``."""
    import jax
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    import jaxobs
    from jaxobs import drive as D
    from jaxobs import metrics
    from jaxobs.drive.drivefile import read_drive

    f = read_drive(LAB)
    par, drive = f.machine, f.drive_for(sensorless=True)
    out = {}
    for name, (rpm, knots, load, t_end) in CASES.items():
        times = [0.0, *(T_EVENT + dt for dt, _ in knots)] if knots else [0.0]
        values = [rpm * D.RPM, *(r * D.RPM for _, r in knots)] if knots else [rpm * D.RPM]
        sc = D.Scenario(par, speed_ref=D.Profile(times, values), omega_m0=rpm * D.RPM,
                        load=D.Scenario.load_steps([0.0, T_EVENT], [0.0, load]))  # fmt: skip
        obs = jaxobs.ReducedOrderFluxObserver.closed_form(ts=drive.ts).bind(par, par.p * rpm * D.RPM)
        o = jax.jit(lambda s, obs=obs: jaxobs.simulate(D.ClosedLoop(drive, obs, s), t_end))(sc).outputs
        err = np.degrees(np.abs(np.asarray(metrics.wrap(o.obs.theta - o.theta_e))))
        n = np.asarray(o.omega_m) / D.RPM
        out[name] = {"peak_deg": float(err.max()), "min_rpm": float(n.min()), "final_rpm": float(n[-1])}
    return out


def motulator_cases(python: str | None) -> dict | None:
    """The cases run by motulator in ``python`` (:mod:`benchmarks.peer_motulator`), or None without one."""
    if not python:
        return None
    done = subprocess.run([python, str(ROOT / "benchmarks" / "peer_motulator.py")], capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"motulator run failed ({python}):\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def table(ours: dict, peer: dict | None) -> str:
    head = f"{'case':<18} {'jaxobs peak':>12} {'min r/min':>10} {'final':>9}"
    head += f" | {'motulator peak':>14} {'min r/min':>10} {'final':>9}" if peer else " | motulator: not run"
    rows = [head]
    for name, r in ours.items():
        line = f"{name:<18} {r['peak_deg']:>11.3f}° {r['min_rpm']:>10.1f} {r['final_rpm']:>9.1f}"
        if peer:
            p = peer["cases"][name]
            line += f" | {p['peak_deg']:>13.3f}° {p['min_rpm']:>10.1f} {p['final_rpm']:>9.1f}"
        rows.append(line)
    return "\n".join(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--motulator-python",
        default=os.environ.get("MOTULATOR_PYTHON"),
        help="a Python with motulator 0.18 (default $MOTULATOR_PYTHON; none: motulator is skipped)",
    )
    ap.add_argument("--json", type=Path, help="also write the numbers to this file")
    args = ap.parse_args(argv)
    ours = jaxobs_cases()
    peer = motulator_cases(args.motulator_python)
    print(table(ours, peer))
    if peer is None:
        print("motulator: skipped (no --motulator-python or $MOTULATOR_PYTHON)")
    else:
        print(f"motulator {peer['motulator']}")
    if args.json is not None:
        args.json.write_text(json.dumps({"jaxobs": ours, "motulator": peer}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
