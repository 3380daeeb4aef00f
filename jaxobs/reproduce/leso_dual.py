"""Paper 002's Figs 13-15 on its dual three-phase IPMSM: ``jaxobs reproduce leso --machine dual``.

The machine is :func:`jaxobs.drive.dual_ipmsm_paper002` (ASSUMED: jaxobs.papers, DUAL_LLS_002): two of the
single IPMSM's sets on one shaft, each phase's BEMF with the 5th/7th harmonics a5, a7 of
:mod:`jaxobs.reproduce.leso` (papers.IPMSM_002_A5/A7), Lls = papers.DUAL_LLS_002.  The three LESOs
(002 Table II's gains, an ObserverBank with the FA-LESO closing the loop after an encoder hand-over at
0.3 s) run:

- Figs 13-14, "the DTP-IPMSM is treated as two individual sets ... and the LESOs are only applied to the
  first set": individual dq current control per set, the LESOs on set 1's voltage and current, at
  300 r/min half load and 600 r/min 40 % load;
- Fig. 15, VSD control (xy currents driven to zero) at 600 r/min 80 % load, the LESOs on the VSD αβ
  subspace, where 002 finds the 5th/7th "negligible" (no number: paper = None).

Rows: the 5th/7th content of each LESO's α BEMF estimate (% of its fundamental, ten electrical
periods at the end of 1 s) beside 002's, the FA-LESO's mean and peak-to-peak position error (deg),
the rms xy current (A), and "finite".  The load is a fraction of the dual machine's rated torque.
"""

from __future__ import annotations

import math

import numpy as np

from .. import drive as D
from .._simulate import simulate
from ..metrics import harmonic_amplitude
from ..progress import Progress
from .leso import LESO_NAMES, leso_bank

__all__ = ["DUAL_EXPERIMENTS", "run_leso_dual"]

# (name, current control, r/min, load as a fraction of rated, 002's (5th, 7th) % per LESO or None)
DUAL_EXPERIMENTS = (
    ("dual individual sets 300 r/min 50 % load", "individual", 300, 0.5, ((5.4, 5.9), (3.6, 4.0), (0.8, 0.7))),
    ("dual individual sets 600 r/min 40 % load", "individual", 600, 0.4, ((4.1, 4.5), (2.7, 2.9), (0.6, 0.7))),
    ("dual VSD 600 r/min 80 % load", "vsd", 600, 0.8, None),
)


def run_leso_dual(progress=None, t1: float = 1.0):
    """Returns (rows, traces) for :data:`DUAL_EXPERIMENTS`, rows as :func:`run_leso_experiments`'s."""
    rows, traces = [], {}
    bar = Progress(progress, len(DUAL_EXPERIMENTS), "reproduce leso (dual)", unit="experiment")
    machine = D.dual_ipmsm_paper002()
    est = machine.per_set()  # what the observers assume: one set, the single IPMSM
    for name, mode, rpm, frac, paper in DUAL_EXPERIMENTS:
        bar.stage(f"{name} ({t1:g} s)")
        we = machine.p * rpm * D.RPM
        drive = D.dual_bench_drive(machine, mode=mode, sensorless=True, handover=0.3)
        sc = D.Scenario(
            est,
            speed_ref=D.Profile.constant(rpm * D.RPM),
            load=D.Profile.constant(frac * float(machine.m.T_rated)),
            omega_m0=rpm * D.RPM,
        )
        sol = simulate(D.DualClosedLoop(drive, leso_bank(est, we), sc, machine), t1)
        traces[name] = sol
        o, t = sol.outputs, np.asarray(sol.t)
        n_per = int(round(2 * math.pi / we / drive.ts))
        m = np.zeros_like(t, dtype=bool)
        m[-10 * n_per :] = True  # ten whole electrical periods
        for i, obs in enumerate(LESO_NAMES):
            ea = np.asarray(o.obs.each[i].e_a)
            fund = float(harmonic_amplitude(t, ea, we, m))
            for j, h in enumerate((5, 7)):
                pct = 100 * float(harmonic_amplitude(t, ea, h * we, m)) / fund
                ref = None if paper is None else paper[i][j]
                rows.append(dict(experiment=name, observer=obs, metric=f"h{h}", unit="%", paper=ref, ours=pct))
        err = np.degrees(np.angle(np.exp(1j * (np.asarray(o.theta_e_hat) - np.asarray(o.theta_e)))))[m]
        for metric, v in (("mean_error", err.mean()), ("ripple", np.ptp(err))):
            rows.append(dict(experiment=name, observer="FA-LESO", metric=metric, unit="deg", paper=None, ours=float(v)))
        ixy = float(np.sqrt(np.mean((np.asarray(o.i_x) ** 2 + np.asarray(o.i_y) ** 2)[m])))
        rows.append(dict(experiment=name, observer="drive", metric="xy_rms", unit="A", paper=None, ours=ixy))
        rows.append(
            dict(experiment=name, observer="drive", metric="finite", unit="bool", paper=None, ours=bool(sol.ok))
        )
        bar.update()
    bar.close()
    return rows, traces
