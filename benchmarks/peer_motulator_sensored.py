"""motulator's sensored speed drive on a drive file's machine: one scenario's trajectory and per-run times, as JSON.

Run by :mod:`benchmarks.peer` with a Python that has motulator 0.18 (Aalto University's open motor-drive
simulator; it needs Python 3.12): ``$MOTULATOR_PYTHON benchmarks/peer_motulator_sensored.py SETUP_JSON``.  It
imports motulator only (not jaxobs) and builds, for every run, motulator's own sensored current-vector drive
(``CurrentVectorControllerCfg(sensorless=False)``: the measured rotor angle drives its speed observer, poles
2π·400 rad/s; its 2DOF PI speed controller on J; an averaged inverter, ideal sensors; the default solver, RK45 at
rtol 1e-3, atol 1e-6), as a user of motulator runs it: a fresh drive and simulation per scenario.

A scenario starts at rest; its speed reference ramps from 0 to ``rpm`` over ``ramp_s`` and holds; the load steps
from 0 to ``load_nm`` at ``load_at``; it ends at ``t_end``.  SETUP_JSON: ``{"drive": {n_p, R_s, L_d, L_q, psi_f,
J, B, u_dc, T_s, i_max, alpha_c, alpha_s}, "scenario": {rpm, ramp_s, load_nm, load_at, t_end}, "warm": N,
"batch": {"scenarios": [[rpm, load_nm], ...], ramp_s, load_at, t_end, max_runs, budget_s}}``.  It runs the scenario once
(``cold``: the process's first run), ``warm`` times more, then the batch's scenarios one after another until
``max_runs`` are done or ``budget_s`` has passed, then the scenario once per ``"variants"`` entry (optional: a list of
``CurrentVectorControllerCfg`` keywords, e.g. ``{"alpha_ref": ..., "alpha_o": ...}``; untimed, their
trajectories returned as ``"variants"``).  Each run is timed (wall: ``time.perf_counter``, CPU:
``time.process_time``), building the drive included.  Printed: one JSON object with the times, the import's, and
the first run's trajectory at the sampling instants t_k = k T_s (the model's state there: speed, r/min; the rotor
frame's currents i_d, i_q, A).
"""

from __future__ import annotations

import json
import math
import sys
import time

import numpy as np

RPM = 2 * math.pi / 60

_t0, _c0 = time.perf_counter(), time.process_time()
import motulator.drive.control.sm as control  # noqa: E402  # pyright: ignore[reportMissingImports] (motulator's own Python)
from motulator.drive import model  # noqa: E402  # pyright: ignore[reportMissingImports]

IMPORT_S = (time.perf_counter() - _t0, time.process_time() - _c0)


def run(d, rpm, ramp_s, load_nm, load_at, t_end, **cfg_kw):
    """One scenario on a fresh drive: the result and (wall, CPU) seconds, building the drive included.
    ``cfg_kw``: other ``CurrentVectorControllerCfg`` keywords (a variant's ``alpha_ref``, ``alpha_o``)."""
    t0, c0 = time.perf_counter(), time.process_time()
    par = model.SynchronousMachinePars(n_p=d["n_p"], R_s=d["R_s"], L_d=d["L_d"], L_q=d["L_q"], psi_f=d["psi_f"])
    mdl = model.Drive(
        model.SynchronousMachine(par),
        model.MechanicalSystem(J=d["J"], B_L=d["B"]),
        model.VoltageSourceConverter(u_dc=d["u_dc"]),
    )
    cfg = control.CurrentVectorControllerCfg(i_s_max=d["i_max"], alpha_c=d["alpha_c"], T_s=d["T_s"], sensorless=False,
                                              **cfg_kw)  # fmt: skip
    ctrl = control.VectorControlSystem(
        control.CurrentVectorController(par, cfg), control.SpeedController(J=d["J"], alpha_s=d["alpha_s"])
    )
    w_ref = rpm * RPM
    ctrl.set_speed_ref(lambda t: w_ref * min(t / ramp_s, 1.0))
    mdl.mechanics.set_external_load_torque(lambda t: load_nm if t >= load_at else 0.0)
    res = model.Simulation(mdl, ctrl, show_progress=False).simulate(t_stop=t_end)
    return res, (time.perf_counter() - t0, time.process_time() - c0)


def trajectory(res, t_end):
    """The model's speed (r/min) and rotor-frame currents (A) at the sampling instants up to ``t_end``."""
    t = np.asarray(res.ctrl.t)
    t = t[t <= t_end + 1e-9]
    idx = np.searchsorted(np.asarray(res.mdl.t), t - 1e-12)  # the model's state at each sampling instant
    i_dq = np.asarray(res.mdl.machine.i_s_dq)[idx]
    n = np.asarray(res.mdl.mechanics.w_M)[idx] / RPM
    return {"t": t.tolist(), "rpm": n.tolist(), "i_d": np.real(i_dq).tolist(), "i_q": np.imag(i_dq).tolist()}


def main():
    from importlib.metadata import version

    setup = json.loads(sys.argv[1])
    d, sc, batch = setup["drive"], setup["scenario"], setup["batch"]
    args = (sc["rpm"], sc["ramp_s"], sc["load_nm"], sc["load_at"], sc["t_end"])
    res, cold = run(d, *args)
    out = {"motulator": version("motulator"), "import_s": IMPORT_S, "cold_s": cold,
           "trajectory": trajectory(res, sc["t_end"])}  # fmt: skip
    out["warm_s"] = [run(d, *args)[1] for _ in range(int(setup["warm"]))]
    runs, start = [], time.perf_counter()
    for rpm, load in batch["scenarios"][: int(batch["max_runs"])]:
        if runs and time.perf_counter() - start > float(batch["budget_s"]):
            break
        runs.append(run(d, rpm, batch["ramp_s"], load, batch["load_at"], batch["t_end"])[1])
    out["batch_s"] = runs
    out["variants"] = [trajectory(run(d, *args, **kw)[0], sc["t_end"]) for kw in setup.get("variants", [])]
    json.dump(out, sys.stdout)
    print()


if __name__ == "__main__":
    main()
