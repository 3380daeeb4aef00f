"""Paper 002's Figs 13-15 on its dual three-phase IPMSM: ``jaxobs reproduce leso --machine dual``.

The machine is :func:`jaxobs.drive.dual_ipmsm_paper002`: two of the single IPMSM's sets on one shaft, its xy
inductance Lls and each phase's 5th/7th BEMF harmonics a5, a7 fitted on the C-LESO rows below (jaxobs.papers,
DUAL_LLS_002, DUAL_A5_002, DUAL_A7_002: Lls on the 600/300 r/min ratio, a5 and a7 on 300 r/min; everything
else here is then a prediction).  The three LESOs
(002 Table II's gains, an ObserverBank with the FA-LESO closing the loop after an encoder hand-over at
0.3 s) run:

- Figs 13-14, "the DTP-IPMSM is treated as two individual sets ... and the LESOs are only applied to the
  first set": individual dq current control per set, the LESOs on set 1's voltage and current, at
  300 r/min half load and 600 r/min 40 % load;
- Fig. 15, VSD control (xy currents driven to zero) at 600 r/min 80 % load, the LESOs on the VSD αβ
  subspace, where 002 finds the 5th/7th "negligible" (no number: paper = None).

Rows: the 5th/7th content of each LESO's α BEMF estimate (% of its fundamental, ten electrical
periods at the end of 1 s) beside 002's, the FA-LESO's mean and peak-to-peak position error (deg),
the rms xy current (A), and "finite"; then Fig. 17's load step under VSD control, the FA-LESO's peak
error beside 002's 3.2°.  Loads are fractions of the dual machine's rated torque.
"""

from __future__ import annotations

import math

import numpy as np

from .. import drive as D
from .._simulate import simulate
from ..metrics import harmonic_amplitude
from ..progress import Progress
from .leso import LESO_NAMES, leso_bank

__all__ = ["DUAL_EXPERIMENTS", "DUAL_LOAD_STEP", "run_leso_dual"]

# (name, current control, r/min, load as a fraction of rated, 002's (5th, 7th) % per LESO or None)
DUAL_EXPERIMENTS = (
    ("dual individual sets 300 r/min 50 % load", "individual", 300, 0.5, ((5.4, 5.9), (3.6, 4.0), (0.8, 0.7))),
    ("dual individual sets 600 r/min 40 % load", "individual", 600, 0.4, ((4.1, 4.5), (2.7, 2.9), (0.6, 0.7))),
    ("dual VSD 600 r/min 80 % load", "vsd", 600, 0.8, None),
)
# Fig. 17 on the dual machine under VSD control
DUAL_LOAD_STEP = "dual VSD load step 0-80 % at 600 r/min"


def _simulate(machine, mode, rpm0, speed_ref, load, t1):
    est = machine.per_set()  # what the observers assume: one set, the single IPMSM
    drive = D.dual_bench_drive(machine, mode=mode, sensorless=True, handover=0.3)
    sc = D.Scenario(est, speed_ref=speed_ref, load=load, omega_m0=rpm0 * D.RPM)
    return simulate(D.DualClosedLoop(drive, leso_bank(est, machine.p * rpm0 * D.RPM), sc, machine), t1)


def _fa_error_deg(sol):
    o = sol.outputs
    return np.degrees(np.angle(np.exp(1j * (np.asarray(o.theta_e_hat) - np.asarray(o.theta_e)))))


def run_leso_dual(progress=None, t1: float = 1.0, dynamics: bool = True):
    """Returns (rows, traces) for :data:`DUAL_EXPERIMENTS` (``t1`` s each) and, with ``dynamics``, Fig. 17's
    load step 0-80 %-0 at 600 r/min (1.2 s) under VSD control, rows as :func:`run_leso_experiments`'s."""
    rows, traces = [], {}
    bar = Progress(progress, len(DUAL_EXPERIMENTS) + dynamics, "reproduce leso (dual)", unit="experiment")
    machine = D.dual_ipmsm_paper002()
    rated = float(machine.m.T_rated)
    for name, mode, rpm, frac, paper in DUAL_EXPERIMENTS:
        bar.stage(f"{name} ({t1:g} s)")
        we = machine.p * rpm * D.RPM
        sol = _simulate(machine, mode, rpm, D.Profile.constant(rpm * D.RPM), D.Profile.constant(frac * rated), t1)
        traces[name] = sol
        o, t = sol.outputs, np.asarray(sol.t)
        n_per = int(round(2 * math.pi / we / float(t[1] - t[0])))
        m = np.zeros_like(t, dtype=bool)
        m[-10 * n_per :] = True  # ten whole electrical periods
        for i, obs in enumerate(LESO_NAMES):
            ea = np.asarray(o.obs.each[i].e_a)
            fund = float(harmonic_amplitude(t, ea, we, m))
            for j, h in enumerate((5, 7)):
                pct = 100 * float(harmonic_amplitude(t, ea, h * we, m)) / fund
                ref = None if paper is None else paper[i][j]
                rows.append(dict(experiment=name, observer=obs, metric=f"h{h}", unit="%", paper=ref, ours=pct))
        err = _fa_error_deg(sol)[m]
        for metric, v in (("mean_error", err.mean()), ("ripple", np.ptp(err))):
            rows.append(dict(experiment=name, observer="FA-LESO", metric=metric, unit="deg", paper=None, ours=float(v)))
        ixy = float(np.sqrt(np.mean((np.asarray(o.i_x) ** 2 + np.asarray(o.i_y) ** 2)[m])))
        rows.append(dict(experiment=name, observer="drive", metric="xy_rms", unit="A", paper=None, ours=ixy))
        bar.update()
    if dynamics:
        name = DUAL_LOAD_STEP
        bar.stage(f"{name} (1.2 s)")
        load = D.Scenario.load_steps([0.0, 0.6, 0.9], [0.0, 0.8 * rated, 0.0])
        sol = _simulate(machine, "vsd", 600, D.Profile.constant(600 * D.RPM), load, 1.2)
        traces[name] = sol
        peak = float(np.abs(_fa_error_deg(sol)[np.asarray(sol.t) >= 0.55]).max())
        rows.append(dict(experiment=name, observer="FA-LESO", metric="max_abs", unit="deg", paper=3.2, ours=peak))
        bar.update()
    for name, sol in traces.items():
        rows.append(
            dict(experiment=name, observer="drive", metric="finite", unit="bool", paper=None, ours=bool(sol.ok))
        )
    bar.close()
    return rows, traces
