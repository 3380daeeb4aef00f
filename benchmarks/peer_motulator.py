"""motulator's sensorless drive on the 2.2-kW lab IPMSM, the cases of :mod:`benchmarks.peer_observer`, as JSON.

Run by :mod:`benchmarks.peer_observer` with a Python that has motulator 0.18 (Aalto University's open motor-drive
simulator; it needs Python 3.12): ``$MOTULATOR_PYTHON benchmarks/peer_motulator.py``.  It imports motulator only
(not jaxobs), builds motulator's own sensorless current-vector drive with its default observer (the reduced-order
flux observer with speed estimation, ``SpeedFluxObserver``: k_o = σ0 + 0.2|ω̂m|, α_o = 2π·50 rad/s, no inertia),
a 2π·200 rad/s current loop and a 2π·4 rad/s speed loop (the bandwidths of docs/examples/ipmsm_2p2kw_lab.toml),
8 kHz, an averaged inverter and ideal sensors, and prints one JSON object: per case, the peak electrical angle
error (deg), the lowest and the final speed (r/min) over the case's window.

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

# case -> (speed before, r/min; speed reference after the event as a function of t − T0; load step N·m; t_end)
CASES = {
    "reversal_750": (750.0, lambda s: 750.0 - 1500.0 * min(max(s, 0.0), 1.0), 0.0, 2.3),
    "step_7nm_15rpm": (15.0, lambda s: 15.0, 7.0, 2.0),
    "step_14nm_750rpm": (750.0, lambda s: 750.0, 14.0, 1.6),
}


def run_case(rpm0, ref_after, load, t_end):
    import motulator.drive.control.sm as control
    from motulator.drive import model

    par = model.SynchronousMachinePars(n_p=3, R_s=3.6, L_d=0.036, L_q=0.051, psi_f=0.545)
    mdl = model.Drive(
        model.SynchronousMachine(par), model.MechanicalSystem(J=0.015), model.VoltageSourceConverter(u_dc=540.0)
    )
    i_max = 1.5 * math.sqrt(2) * 4.3  # the drive file's current limit, A peak
    cfg = control.CurrentVectorControllerCfg(i_s_max=i_max, alpha_c=2 * math.pi * 200.0, T_s=125e-6)
    ctrl = control.VectorControlSystem(
        control.CurrentVectorController(par, cfg), control.SpeedController(J=0.015, alpha_s=2 * math.pi * 4.0)
    )

    def ref(t):
        if t < T0:
            return rpm0 * RPM * min(t / 0.5, 1.0)
        return ref_after(t - T0) * RPM

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

    out = {"motulator": version("motulator"), "cases": {}}
    for name, case in CASES.items():
        out["cases"][name] = run_case(*case)
    json.dump(out, sys.stdout)
    print()


if __name__ == "__main__":
    main()
