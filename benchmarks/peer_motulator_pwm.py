"""motulator's carrier-comparison PWM on the 2.2-kW lab IPMSM at 1000 r/min and rated load, open loop, as JSON.

Run by :mod:`benchmarks.pwm_carrier` with a Python that has motulator 0.18 (Aalto University's open motor-drive
simulator; it needs Python 3.12): ``$MOTULATOR_PYTHON benchmarks/peer_motulator_pwm.py ARGS_JSON``.  It imports
motulator only (not jaxobs).  The case, given by the caller as JSON: the machine (n_p, R_s, L_d, L_q, ψf), u_dc,
the sampling period T_s, the steady rotor-frame current and voltage, the speed, the dead time, the run's length
and the window scored.  motulator's model: ``Drive(..., pwm=True, single_update=True, delay=0)`` (its
``CarrierComparison``: one carrier period per sample, the duty ratios computed at the sample apply at once), the
rotor speed imposed (``ExternalRotorSpeed``), a solver at rtol = atol = 1e-9.  The open-loop "controller" rotates
the steady voltage to the middle of each period (the angle known exactly from the imposed speed) and gives the
duty ratios by min-max injection.  It prints the stator current at every solver point of the window (t, i_α, i_β).
"""

from __future__ import annotations

import importlib.metadata
import json
import math
import sys
from types import SimpleNamespace

import numpy as np


class OpenLoop:
    """The least control system motulator's Simulation drives: a callable returning (T_s, d_abc)."""

    def __init__(self, case):
        self.c = case
        self.t = 0.0
        self.enabled = True

    def get_enable(self):
        return True

    def __call__(self, mdl):
        c = self.c
        w_e = c["n_p"] * c["w_M"]
        theta = c["theta0"] + w_e * (self.t + 0.5 * c["T_s"])  # the voltage centred on the period
        u = complex(*c["u_dq"]) * np.exp(1j * theta)
        v = np.array([u.real, -0.5 * u.real + 0.5 * math.sqrt(3) * u.imag, -0.5 * u.real - 0.5 * math.sqrt(3) * u.imag])
        v -= 0.5 * (v.max() + v.min())
        d = np.clip(0.5 + v / c["u_dc"], 0.0, 1.0)
        self.t += c["T_s"]
        return c["T_s"], d

    def post_process(self):
        return SimpleNamespace(t=np.array([]))


def run(case):
    from motulator.common.model import Simulation, SolverCfg
    from motulator.drive import model

    par = model.SynchronousMachinePars(n_p=case["n_p"], R_s=case["R_s"], L_d=case["L_d"], L_q=case["L_q"],
                                       psi_f=case["psi_f"])  # fmt: skip
    machine = model.SynchronousMachine(par)
    i_d, i_q = case["i_dq"]
    machine.state.psi_s_dq = complex(case["L_d"] * i_d + case["psi_f"], case["L_q"] * i_q)
    machine.state.theta_m = complex(case["theta0"])
    mech = model.ExternalRotorSpeed()
    mech.set_external_rotor_speed(case["w_M"])
    conv = model.VoltageSourceConverter(u_dc=case["u_dc"], t_d=case["t_d"])
    mdl = model.Drive(machine, mech, conv, pwm=True, delay=0, single_update=True)
    sim = Simulation(mdl, OpenLoop(case), show_progress=False, cfg=SolverCfg(rtol=1e-9, atol=1e-9))
    res = sim.simulate(t_stop=case["t_end"])
    t = np.asarray(res.mdl.t)
    i_ab = np.asarray(res.mdl.machine.i_s_ab)
    keep = t >= case["t_from"]
    t, i_ab = t[keep], i_ab[keep]
    t, first = np.unique(t, return_index=True)  # interval ends repeat as the next interval's start
    i_ab = i_ab[first]
    return {"t": t.tolist(), "i_a": i_ab.real.tolist(), "i_b": i_ab.imag.tolist()}


def main():
    case = json.loads(sys.argv[1])
    out = run(case)
    out["version"] = importlib.metadata.version("motulator")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
