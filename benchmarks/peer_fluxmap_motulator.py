"""motulator's saturated synchronous machine under an open-loop voltage, as JSON (run by
:mod:`benchmarks.peer_fluxmap` with a Python that has motulator 0.18: ``$MOTULATOR_PYTHON
benchmarks/peer_fluxmap_motulator.py CASE.json``).

It imports motulator only (not jaxobs).  The machine is motulator's ``SynchronousMachine`` with
``SaturatedSynchronousMachinePars(i_s_dq_fcn=SaturationModelPMSyRM(...))``, the coefficients the case file gives
(the 5.6-kW PM-SyRM of docs/examples/pmsyrm_5p6kw_sat.toml).  Its own ``rhs`` is integrated at a fixed rotor
speed by SciPy's ``solve_ivp`` (DOP853, rtol 1e-12, atol 1e-12), one control period at a time under the period's
held stationary-frame voltage, from the case's initial flux linkage; it prints the currents i_s_dq at every
sampling instant.
"""

from __future__ import annotations

import json
import sys

import numpy as np
from scipy.integrate import solve_ivp


def main(path):
    from motulator.drive import model, utils

    case = json.loads(open(path).read())
    c = case["coef"]
    curr_map = utils.SaturationModelPMSyRM(
        a_d0=c["a_d0"], a_dd=c["a_dd"], S=c["S"], a_q0=c["a_q0"], a_qq=c["a_qq"], T=c["T"], a_dq=c["a_dq"],
        U=c["U"], V=c["V"], a_b=c["a_b"], a_bp=c["a_bp"], k_q=c["k_q"], psi_n=c["psi_n"], W=c["W"],
    )  # fmt: skip
    par = model.SaturatedSynchronousMachinePars(n_p=case["p"], R_s=case["Rs"], i_s_dq_fcn=curr_map)
    machine = model.SynchronousMachine(par)
    machine.inp.w_M = case["omega_m"]
    ts = case["ts"]
    u = np.asarray(case["u_a"]) + 1j * np.asarray(case["u_b"])

    def f(_t, y):
        machine.state.psi_s_dq = complex(y[0], y[1])
        machine.state.theta_m = complex(y[2], 0.0)
        machine.set_outputs(_t)
        d_psi, d_theta = machine.rhs(_t)
        return [d_psi.real, d_psi.imag, float(np.real(d_theta))]

    y = np.array([case["psi0"][0], case["psi0"][1], case["theta0"]])
    i_d, i_q = [], []
    for k in range(len(u)):
        machine.state.psi_s_dq = complex(y[0], y[1])
        machine.state.theta_m = complex(y[2], 0.0)
        machine.inp.u_s_ab = complex(u[k])
        machine.set_outputs(k * ts)
        i_d.append(machine.out.i_s_dq.real)
        i_q.append(machine.out.i_s_dq.imag)
        sol = solve_ivp(f, (k * ts, (k + 1) * ts), y, method="DOP853", rtol=1e-12, atol=1e-12)
        y = sol.y[:, -1]
    print(json.dumps({"i_d": i_d, "i_q": i_q, "psi_f": par.psi_f}))


if __name__ == "__main__":
    main(sys.argv[1])
