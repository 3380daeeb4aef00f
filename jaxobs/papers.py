"""Every number jaxobs takes from a paper, each with its source; and, marked ASSUMED, the
set-up values our copies of the papers leave open.

This module is the one home of these numbers: observers, closed forms, reproductions,
tuning jobs, tests and notebooks import them from here and never type them again.
The TOML presets of ``tuning/presets`` cannot import; ``tests/test_papers.py`` checks
that their paper values agree with this module.  It imports nothing from jaxobs: it is
the bottom layer (``tests/test_layers.py``).

The papers (``jaxobs`` numbers them as the README does):

- 000: Xu, Jiang, Mu, Blaabjerg, "Improved nonlinear flux observer-based second-order
  SOIFO for PMSM sensorless control", IEEE TPEL 2018.
- 001: Golestan, Guerrero, Vasquez, Abusorrah, Al-Turki, "Modeling, tuning, and
  performance comparison of second-order-generalized-integrator-based FLLs", IEEE TPEL 2018.
- 002: Li, Hu, Ma, Liu, "Sensorless control of dual three-phase IPMSM based on frequency
  adaptive linear extended state observer".

SI units; angles in rad unless a name ends in ``_DEG``; bandwidths ending in ``_HZ`` are
used as 2π·f rad/s.  A value marked ASSUMED is ours, not the paper's: the reason is given
beside it (and in the README's notes on the reproductions).
"""

from __future__ import annotations

import math
from types import MappingProxyType

__all__ = [
    # 000
    "SOIFO_K",
    "SECOND_ORDER_SOIFO_K1",
    "SECOND_ORDER_SOIFO_K2",
    "SOIFO_SETTLING_TIME",
    "LPF_OMEGA_C",
    "FLUX_FIG5_OMEGA",
    "SPMSM_000",
    "BENCH_J_000",
    "FLUX_PLL_HZ",
    # 001
    "FLL_OMEGA_N",
    "FLL_ZETA",
    "SOGI_FLL_K",
    "SOGI_FLL_LAM",
    "WPF_K1",
    "WPF_K2",
    "WPF_LAM",
    "WIF_K1",
    "WIF_K2",
    "WIF_LAM",
    "WIF_B",
    "WIF_OMEGA_C",
    "TEST_C_HARMONICS",
    "TESTS_001",
    # 002
    "LESO_OMEGA0",
    "GILESO_K_R",
    "GILESO_OMEGA_C",
    "FALESO_K1",
    "FALESO_K2",
    "LESO_TABLE_II_OMEGA_E",
    "IPMSM_002",
    "BENCH_J_002",
    "IPMSM_002_A5",
    "IPMSM_002_A7",
    "DUAL_LLS_002",
    "DUAL_A5_002",
    "DUAL_A7_002",
    "LESO_PLL_HZ",
    "PLL_ZETA",
    # the simulated benches of 000 and 002
    "BENCH_CURRENT_HZ",
    "BENCH_SPEED_HZ",
    # I-f start-up from standstill
    "IF_SWITCH_RPM_000",
    "IF_CURRENT_PU",
    "IF_SWITCH_PU",
    "IF_ACCEL_TORQUE_PU",
    "IF_HOLD",
    "IF_RAMP_SWING_PERIODS",
]

# --------------------------------------------------------------------------
# 000: rotor-flux observers (pure integrator, LPF, SOIFO, second-order SOIFO)
# --------------------------------------------------------------------------

# Sec. III-B (Fig. 5) and Sec. IV: "the experiential coefficients k, K1, and K2 are taken as
# 1.414, 1.56, and 3.11", chosen so that "the setting time t_s of SOIFO and second-order SOIFO
# are both kept as 0.018 s" (Sec. III-B; the paper does not define t_s: see jaxobs_tuning.targets).
SOIFO_K = 1.414
SECOND_ORDER_SOIFO_K1 = 1.56
SECOND_ORDER_SOIFO_K2 = 3.11
SOIFO_SETTLING_TIME = 0.018
# Sec. III-B, Fig. 5: the LPF's cut-off ωc = 100 rad/s and the centre frequency ω' = ω1 = 100π rad/s.
LPF_OMEGA_C = 100.0
FLUX_FIG5_OMEGA = 100 * math.pi

# Table II, the SPMSM of the bench: ψf = 0.35 Wb, 2000 r/min, 3 pole pairs, L = 5.0 mH (d and q),
# Rs = 0.8 Ω, 14 N·m, J = 3.78e-4 kg·m².  B is not given: 0 (ASSUMED).  Keyword arguments of
# jaxobs.drive.PMSMParams.
SPMSM_000 = MappingProxyType(
    dict(Rs=0.8, Ld=5e-3, Lq=5e-3, psi_f=0.35, J=3.78e-4, p=3, B=0.0, T_rated=14.0, n_rated=2000.0)
)
# ASSUMED: the bench inertia.  Table II's J is the motor's; the bench couples a load machine, and
# with the motor's J alone a 10 N·m step decelerates the rotor at 26,000 rad/s².  We take 10×.
BENCH_J_000 = 10 * SPMSM_000["J"]
# ASSUMED: the type-2 PLL (ζ = 1/√2) that gives the pure integrator and the LPF a speed; 000 gives none.
FLUX_PLL_HZ = 20.0

# --------------------------------------------------------------------------
# 001: the SOGI-FLL family
# --------------------------------------------------------------------------

# Sec. VI (Test A: "from 50 Hz to 52 Hz"): the nominal grid frequency, 50 Hz; Table I's λ follow from it.
FLL_OMEGA_N = 100 * math.pi
# Secs. II-B, III-B, IV-B: "the optimum damping factor ζ = 1/√2 is selected" (eqs 22, 29, 34).
FLL_ZETA = 1 / math.sqrt(2)
# Table I, control parameters.
SOGI_FLL_K = 1 / math.sqrt(2)
SOGI_FLL_LAM = 12337.0
WPF_K1 = math.sqrt(2)
WPF_K2 = math.sqrt(2)
WPF_LAM = 23948.0
WIF_K1 = 1.815
WIF_K2 = 0.752
WIF_LAM = 11559.0
# Sec. IV-B: the WIF's symmetric optimum (eq 34) with b = 1 + √2 (ζ = 1/√2, PM = 45°) and the
# crossover of the WPF design, ωc = 2π·18.8 rad/s, "to have a fair comparison".
WIF_B = 1 + math.sqrt(2)
WIF_OMEGA_C = 2 * math.pi * 18.8

# Sec. VI, Test C: harmonic magnitudes, p.u. of the fundamental (THD ≈ 7.7 %).
TEST_C_HARMONICS = MappingProxyType({3: 0.054, 5: 0.048, 7: 0.022, 9: 0.005, 11: 0.012, 13: 0.006})
# Sec. V (Tests 1–3, model accuracy) and Sec. VI (Tests A–E, performance): what each test does
# at its event, in Hz, degrees and p.u. of the nominal amplitude.  jaxobs.signals.paper001_test
# builds the signals (and says how it reads "sag": as the depth).
TESTS_001 = MappingProxyType(
    {
        "1": MappingProxyType(dict(freq_step=2.0)),  # "a +2 Hz frequency step change"
        "2": MappingProxyType(dict(phase_jump_deg=20.0)),  # "a +20° phase jump"
        "3": MappingProxyType(dict(sag=0.75)),  # "a 0.75 p.u. voltage sag"
        "A": MappingProxyType(dict(freq_step=2.0)),  # "from 50 Hz to 52 Hz"
        "B": MappingProxyType(dict(sag=0.5, phase_jump_deg=60.0)),  # "0.5 p.u. voltage sag with 60° phase jump"
        "C": MappingProxyType(dict(harmonics_scale=1.0)),  # × TEST_C_HARMONICS
        "D": MappingProxyType(dict(dc=0.1)),  # "a large DC component (0.1 p.u.)"
        "E": MappingProxyType(dict(sub_amplitude=0.1, sub_freq=1.0)),  # "a 1-Hz sub-harmonic ... 0.1 p.u."
    }
)

# --------------------------------------------------------------------------
# 002: back-EMF LESOs (C-LESO, GI-LESO, FA-LESO)
# --------------------------------------------------------------------------

# Table II, parameters: C-LESO and GI-LESO ω0 = 500π; GI-LESO K_r = 2ω0², ωc = π;
# FA-LESO k1 = 10π, k2 = 100π; both evaluated at ω̂e = 100π.
LESO_OMEGA0 = 500 * math.pi
GILESO_K_R = 2 * LESO_OMEGA0**2
GILESO_OMEGA_C = math.pi
FALESO_K1 = 10 * math.pi
FALESO_K2 = 100 * math.pi
LESO_TABLE_II_OMEGA_E = 100 * math.pi

# ASSUMED: the IPMSM.  Our copy of 002 lacks its machine table; only p = 5 follows from the paper
# (Sec. IV: 300/600/840 r/min are 25/50/70 Hz).  The rest is a plausible ~2 kW lab machine:
# saliency 2, ψf giving 141 V peak at 600 r/min, rated 30 N·m at 600 r/min (8.9 A at i_d = 0).
# Keyword arguments of jaxobs.drive.PMSMParams.
IPMSM_002 = MappingProxyType(
    dict(Rs=0.6, Ld=6e-3, Lq=12e-3, psi_f=0.45, J=5e-3, p=5, B=1e-3, T_rated=30.0, n_rated=600.0)
)
# ASSUMED: the bench inertia, 10× the motor's (a load machine is coupled; with the motor alone
# an 80 % load step stalls the drive before any speed loop reacts).
BENCH_J_002 = 10 * IPMSM_002["J"]
# ASSUMED: the 5th and 7th BEMF harmonics of one winding set (Sec. V-B gives no content); set so
# that the C-LESO's transfer function at 300 r/min predicts the C-LESO percentages 002 measured.
IPMSM_002_A5 = 0.0675
IPMSM_002_A7 = 0.0879
# The dual three-phase IPMSM (jaxobs.drive.dual_ipmsm_paper002; 002's machine, Sec. V), calibrated on Figs 13-14
# (two individual sets, LESOs on set 1; docs/papers.md).  Under individual-set control the first set's equivalent
# BEMF, the LESO's u − Rs i − L̂q di/dt, is not the phase BEMF: the 5th/7th live in xy, drive xy currents through
# the xy (leakage) inductance Lls, and the LESO, modelling the set with the αβ L̂q, reads (L̂q − Lls) di_xy/dt as
# BEMF too.  How much depends on Lls and rises with speed (the xy impedance ω Lls grows against the current PIs'
# gain), so the C-LESO's 600/300 r/min ratio fixes Lls and its 300 r/min numbers then fix a5, a7:
# ASSUMED-FITTED: Lls, H.  002 gives no xy inductance; the C-LESO's ratios 4.1/5.4 = 0.759 (5th) and 4.5/5.9 =
# 0.763 (7th) are met at Lls ≈ 5.0 and 4.5 mH (a search over 2-8 mH, docs/performance.md); 4.5 mH is the
# least-squares point.  With the assumed Ld = 6 mH that is 0.75 Ld: a large leakage, as the
# xy inductance of a concentrated-winding dual three-phase machine can be.  The fit leans on the assumed current
# loops (papers.BENCH_CURRENT_HZ): with them at half that bandwidth it moves to ≈ 5.7 mH.
DUAL_LLS_002 = 4.5e-3
# ASSUMED-FITTED: each phase's 5th and 7th BEMF harmonic (fraction of the fundamental), such that the C-LESO on
# set 1 under individual-set control gives 002's 5.4 / 5.9 % at 300 r/min, half load (Fig. 13).  The VSD maps them
# to xy, which is why Fig. 15 (VSD, 600 r/min, 80 % load) shows them "negligible" in αβ.  The 11th/13th (which VSD
# keeps in αβ) are "relatively low" (Sec. V-B) and left out.  Lower than IPMSM_002_A5/A7 (6.75 / 8.79 %, the single
# machine's, fitted the same way), by the xy currents' share above.
DUAL_A5_002 = 0.0615
DUAL_A7_002 = 0.0751
# ASSUMED: the type-2 PLL after each LESO, ω_b = 2π·15 rad/s (our copy lacks 002's PLL section).  002's speed
# ramp pair (4.5°, 13 r/min) supports it: ours at 15 Hz gives 4.1°, 13.2 r/min (docs/papers.md).
LESO_PLL_HZ = 15.0
# ASSUMED: the damping of our type-2 PLLs, pole placement k_p = 2ζω_b, k_i = ω_b² (jaxobs.linear.pll_gains).
PLL_ZETA = 1 / math.sqrt(2)

# --------------------------------------------------------------------------
# The simulated benches of 000 and 002 (ASSUMED: neither paper gives its loop bandwidths)
# --------------------------------------------------------------------------

# IMC current loop α_c = 2π·300 rad/s at 10 kHz; I-P speed loop α_s = 2π·5 rad/s (below the
# FLL's bandwidth at 400 r/min: a 10 Hz speed loop oscillated there when closed through ω̂).
BENCH_CURRENT_HZ = 300.0
BENCH_SPEED_HZ = 5.0

# --------------------------------------------------------------------------
# I-f start-up from standstill (jaxobs.drive.IfStartup.for_machine)
# --------------------------------------------------------------------------

# 000 Sec. IV (Fig. 20): "The PMSM starts up in open loop and switches to sensorless operation at
# 20 r/min" (1 % of its 2000 r/min).  002 says nothing of its start-up.
IF_SWITCH_RPM_000 = 20.0
# ASSUMED (neither paper sizes its start-up): the defaults of jaxobs.drive.IfStartup.for_machine.
# I_f = 0.5 × rated current: carries half the rated torque at a zero load angle, with room to accelerate.
IF_CURRENT_PU = 0.5
# Switch at 20 % of rated speed (000 switched at 1 %), where a sensorless speed loop at the benches'
# α_s = 2π·BENCH_SPEED_HZ is stable through every observer here.  Measured (tests/test_startup.py):
# at 10 % the SOIFOs' frequency-normalized FLLs (natural frequency ≈ ω̂e/2 = α_s at 200 r/min on the SPMSM)
# put the loop in a 230–610 r/min limit cycle, and the LESOs' PLLs at 60 r/min (5 Hz) in a ±11 % one;
# at 20 % the hand-over stays within ±4 %.
IF_SWITCH_PU = 0.2
# The ramp's peak acceleration torque is 20 % of K_t I_f (the rest is margin for load and swing).
IF_ACCEL_TORQUE_PU = 0.2
# The ramp lasts at least 3 periods of the rotor's undamped swing on the I-f current (the torque-angle spring).
IF_RAMP_SWING_PERIODS = 3.0
# Least time at the switch speed before the hand-over, s (observers converge; SOGI/PLL settle in ~0.05 s there).
IF_HOLD = 0.1
