"""motulator's sensorless drive on a drive file's machine, the cases of :mod:`benchmarks.peer_observer`, as JSON.

Run by :mod:`benchmarks.peer_observer` with a Python that has motulator 0.18 (Aalto University's open motor-drive
simulator; it needs Python 3.12): ``$MOTULATOR_PYTHON benchmarks/peer_motulator.py [SETUP_JSON]``.  It imports
motulator only (not jaxobs), builds motulator's own sensorless current-vector drive with its default observer (the
reduced-order flux observer with speed estimation, ``SpeedFluxObserver``: k_o = σ0 + 0.2|ω̂m|, α_o = 2π·50 rad/s,
no inertia), an averaged inverter and ideal sensors, and prints one JSON object: per case, the peak electrical
angle error (deg), the lowest and the final speed (r/min) over the case's window.  SETUP_JSON
(:func:`benchmarks.peer_observer.motulator_setup`) gives the drive file's machine (n_p, R_s, L_d, L_q, psi_f, J,
B), u_dc, sampling period T_s, current limit i_max (peak), current- and speed-loop bandwidths alpha_c, alpha_s,
and the cases; without it, the 2.2-kW lab IPMSM of docs/examples/ipmsm_2p2kw_lab.toml (a 2π·200 rad/s current
loop, a 2π·4 rad/s speed loop, 8 kHz) and its three cases.

motulator starts at standstill, so each case first ramps to its speed over 0.5 s and holds it to t0 = 1 s; the
window scored starts 0.2 s before the event at t0 (the jaxobs runs start steady with their event at 0.2 s and
are scored from 0: the same 0.2 s before the event).
"""

from __future__ import annotations

import json
import math
import sys

import numpy as np

RPM = 2 * math.pi / 60
T0 = 1.0  # the event's time in these runs, s

# the lab drive (docs/examples/ipmsm_2p2kw_lab.toml), when no setup is given
LAB_DRIVE = {"n_p": 3, "R_s": 3.6, "L_d": 0.036, "L_q": 0.051, "psi_f": 0.545, "J": 0.015, "B": 0.0, "u_dc": 540.0,
             "T_s": 125e-6, "i_max": 1.5 * math.sqrt(2) * 4.3, "alpha_c": 2 * math.pi * 200.0,
             "alpha_s": 2 * math.pi * 4.0}  # fmt: skip
# case -> (speed before, r/min; the speed reference's knots after the event (times from it, r/min); load step N·m;
# t_end)
LAB_CASES = {
    "reversal_750": (750.0, ((0.0, 750.0), (1.0, -750.0)), 0.0, 2.3),
    "step_7nm_15rpm": (15.0, (), 7.0, 2.0),
    "step_14nm_750rpm": (750.0, (), 14.0, 1.6),
}


def ref_after(rpm0, knots, s):
    """The speed reference (r/min) at s after the event: rpm0 before the first knot, linear between knots, the
    last knot's speed after it."""
    if not knots or s <= knots[0][0]:
        return rpm0 if not knots else knots[0][1]
    for (s0, n0), (s1, n1) in zip(knots, knots[1:]):
        if s <= s1:
            return n0 + (n1 - n0) * min(max((s - s0) / (s1 - s0), 0.0), 1.0)
    return knots[-1][1]


def run_case(d, rpm0, knots, load, t_end):
    import motulator.drive.control.sm as control  # pyright: ignore[reportMissingImports] (motulator's own Python)
    from motulator.drive import model  # pyright: ignore[reportMissingImports]

    par = model.SynchronousMachinePars(n_p=d["n_p"], R_s=d["R_s"], L_d=d["L_d"], L_q=d["L_q"], psi_f=d["psi_f"])
    mdl = model.Drive(
        model.SynchronousMachine(par),
        model.MechanicalSystem(J=d["J"], B_L=d["B"]),
        model.VoltageSourceConverter(u_dc=d["u_dc"]),
    )
    cfg = control.CurrentVectorControllerCfg(i_s_max=d["i_max"], alpha_c=d["alpha_c"], T_s=d["T_s"])
    ctrl = control.VectorControlSystem(
        control.CurrentVectorController(par, cfg), control.SpeedController(J=d["J"], alpha_s=d["alpha_s"])
    )

    def ref(t):
        if t < T0:
            return rpm0 * RPM * min(t / 0.5, 1.0)
        return ref_after(rpm0, knots, t - T0) * RPM

    ctrl.set_speed_ref(ref)
    mdl.mechanics.set_external_load_torque(lambda t: load if t >= T0 else 0.0)
    res = model.Simulation(mdl, ctrl, show_progress=False).simulate(t_stop=t_end)
    t = np.asarray(res.ctrl.t)
    idx = np.searchsorted(np.asarray(res.mdl.t), t)  # the model's state at each sampling instant
    theta = np.asarray(res.mdl.machine.theta_m)[idx]
    err = np.degrees(np.abs(np.angle(np.exp(1j * (np.asarray(res.ctrl.fbk.theta_m) - theta)))))
    n = np.asarray(res.mdl.mechanics.w_M)[idx] / RPM
    win = t >= T0 - 0.2
    return {"peak_deg": float(err[win].max()), "min_rpm": float(n[win].min()), "final_rpm": float(n[-1])}


def main():
    from importlib.metadata import version

    setup = json.loads(sys.argv[1]) if len(sys.argv) > 1 else {"drive": LAB_DRIVE, "cases": LAB_CASES}
    out = {"motulator": version("motulator"), "cases": {}}
    for name, case in setup["cases"].items():
        out["cases"][name] = run_case(setup["drive"], *case)
    json.dump(out, sys.stdout)
    print()


if __name__ == "__main__":
    main()
