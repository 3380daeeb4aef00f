"""The sensorless speed loop closed through the FA-LESO's PLL (jaxobs.linear.faleso_speed_loop_poles): why
002's load step rings on our bench, and why field weakening on a 330 V link went unstable sensorless."""

import math

import numpy as np
import pytest

import jaxobs
from jaxobs import drive as D
from jaxobs import linear as L
from jaxobs import papers
from jaxobs.metrics import wrap
from jaxobs.observers import FALESO

PAR = D.bench_machine("ipmsm002")


def _speed_mode(pll_hz, speed_hz, rpm, i_d=0.0, i_q=0.0):
    """The speed loop's least damped pole (rad/s) on the 002 bench (I-P gains as FOC.imc places them)."""
    kp, ki = L.pll_gains(2 * math.pi * pll_hz)
    a = 2 * math.pi * speed_hz
    kp_w, ki_w = 2 * a * float(PAR.J) / float(PAR.kt), a * a * float(PAR.J) / float(PAR.kt)
    we = PAR.p * rpm * D.RPM
    r = np.asarray(
        L.faleso_speed_loop_poles(
            papers.FALESO_K1, papers.FALESO_K2, we, kp, ki, kp_w, ki_w,
            p=PAR.p, psi_f=float(PAR.psi_f), Ld=float(PAR.Ld), Lq=float(PAR.Lq), J=float(PAR.J), i_d=i_d, i_q=i_q,
        )
    )  # fmt: skip
    assert r.size == 8  # J s² P D: 2 + 2 + 4
    r = r[np.abs(r.imag) < we / 2]  # the FA-LESO's slow mode at ±jωe left out (module doc)
    return r[np.argmax(r.real)]


def test_bench_speed_loop_through_the_15_hz_pll_is_barely_damped():
    """The 002 bench: α_s = 2π·5 rad/s on the ω̂ of a 15 Hz PLL — a pair at 10 Hz with ζ ≈ 0.07 (the ±17°
    ringing of the load step); a 30 Hz PLL or a 2.5 Hz speed loop damps it."""
    m = _speed_mode(papers.LESO_PLL_HZ, papers.BENCH_SPEED_HZ, 600)
    assert abs(m.imag) / (2 * math.pi) == pytest.approx(9.95, abs=0.1)
    assert -m.real / abs(m) == pytest.approx(0.067, abs=0.005)
    assert -_speed_mode(30.0, papers.BENCH_SPEED_HZ, 600).real > 20.0
    m = _speed_mode(papers.LESO_PLL_HZ, 2.5, 600)
    assert -m.real / abs(m) > 0.5


def test_field_weakening_current_destabilizes_the_sensorless_speed_loop():
    """At 840 r/min on 330 V the field weakening holds i_d ≈ −6.4 A; a lagging estimate then turns i_d into
    accelerating torque (K_δ = 1.5p ψf i_d < 0), and the 10 Hz pair crosses into Re s > 0; i_d = 0 is stable."""
    assert _speed_mode(papers.LESO_PLL_HZ, papers.BENCH_SPEED_HZ, 840, i_d=0.0).real < 0
    m = _speed_mode(papers.LESO_PLL_HZ, papers.BENCH_SPEED_HZ, 840, i_d=-6.4)
    assert m.real > 5.0 and abs(m.imag) / (2 * math.pi) == pytest.approx(9.4, abs=0.3)
    # the remedies: the speed loop at half the bandwidth, or the PLL at twice
    assert _speed_mode(papers.LESO_PLL_HZ, 2.5, 840, i_d=-6.4).real < -5.0
    assert _speed_mode(30.0, papers.BENCH_SPEED_HZ, 840, i_d=-6.4).real < -5.0


def test_speed_loop_poles_with_a_fast_observer_are_the_designed_double_pole():
    """Sanity of the elimination: an FA-LESO and a PLL far faster than the speed loop (k2 = 3e4 rad/s, PLL at
    1 kHz) leave the I-P loop's double pole at −α_s: the two slow poles' sum −2α_s and product α_s²; with the
    FA-LESO's frequency adaptation too (its angle shift δω̂/k2 vanishes as k2 grows)."""
    a = 2 * math.pi * papers.BENCH_SPEED_HZ
    kp, ki = L.pll_gains(2 * math.pi * 1000.0)
    kp_w, ki_w = 2 * a * float(PAR.J) / float(PAR.kt), a * a * float(PAR.J) / float(PAR.kt)
    for adaptation in (False, True):
        r = np.asarray(
            L.faleso_speed_loop_poles(
                3e3, 3e4, PAR.p * 600 * D.RPM, kp, ki, kp_w, ki_w,
                p=PAR.p, psi_f=float(PAR.psi_f), Ld=float(PAR.Ld), Lq=float(PAR.Lq), J=float(PAR.J),
                adaptation=adaptation,
            )
        )  # fmt: skip
        assert r.size == 8  # the adaptation adds no order: k_i s N_ω is of degree 4 < 6
        slow = r[np.abs(r) < 3 * a]
        assert slow.size == 2, r
        assert float(np.real(slow.sum())) == pytest.approx(-2 * a, rel=0.03)
        assert float(np.real(slow.prod())) == pytest.approx(a * a, rel=0.03)


def test_the_frequency_adaptation_path_is_the_derivative_the_model_adds():
    """The FA-LESO's G(jω_e; ω̂) moves with ω̂ although G(jω̂; ω̂) = 1: ∂G/∂ω̂ at the carrier is j/k2 (to
    k1/(ω_e k2²)), the angle shift per rad/s of ω̂'s error that faleso_speed_loop_poles(adaptation=True) adds;
    with it the bench's 10 Hz pair rises to 11.05 Hz and keeps a quarter of its damping (σ 4.23 -> 1.01 /s)."""
    we, h = PAR.p * 600 * D.RPM, 1e-3

    def g(w_hat):
        return complex(L.faleso_tf(papers.FALESO_K1, papers.FALESO_K2, w_hat).freqresp(we))

    assert g(we) == pytest.approx(1.0, abs=1e-12)
    dg = (g(we + h) - g(we - h)) / (2 * h)
    assert dg.imag == pytest.approx(1 / papers.FALESO_K2, rel=1e-3) and abs(dg.real) < 1e-3 / papers.FALESO_K2


def _ramp_330v(alpha_s):
    inv = D.Inverter(udc=330.0)
    obs = FALESO(0.0, 1.0, papers.FALESO_K1, papers.FALESO_K2).bind(PAR, PAR.p * 600 * D.RPM)
    drive = D.bench_drive(PAR, inverter=inv, field_weakening=D.VoltageFeedbackFW(), alpha_s=alpha_s)
    sc = D.Scenario(PAR, speed_ref=D.Scenario.speed_rpm([0.0, 0.05], [600, 840], ramp=0.25), omega_m0=600 * D.RPM)
    out = jaxobs.simulate(D.ClosedLoop(drive, obs, sc), 0.8).outputs
    err = np.degrees(np.abs(np.asarray(wrap(out.obs.theta - out.theta_e))))
    return np.asarray(out.speed_rpm), err, np.asarray(out.i_d)


@pytest.mark.slow
def test_sensorless_field_weakening_holds_with_the_speed_loop_the_model_prescribes():
    """Simulated, as the model says: at α_s = 2π·5 the FA-LESO-closed drive on 330 V leaves 840 r/min (the
    oscillation grows at ~9 Hz, the speed overshoots past 900 r/min); at α_s = 2π·2.5 it holds."""
    rpm, err, _ = _ramp_330v(2 * math.pi * papers.BENCH_SPEED_HZ)
    assert rpm.max() > 900.0, rpm.max()
    rpm, err, i_d = _ramp_330v(2 * math.pi * 2.5)
    assert np.max(np.abs(rpm[-2000:] - 840.0)) < 5.0, (rpm[-2000:].min(), rpm[-2000:].max())
    assert err.max() < 6.0, err.max()
    assert i_d[-2000:].mean() < -6.0  # the field weakening is acting


def _cleso_closing_speed_band(load_pu):
    """The speed band (r/min, after 0.6 s) of the harmonic bench with the C-LESO closing the loop at 600 r/min
    and a 10 Hz speed loop (sensorless from 0.3 s)."""
    from jaxobs.reproduce.leso import leso_bank

    hpar = D.bench_machine("ipmsm002", a5=papers.IPMSM_002_A5, a7=papers.IPMSM_002_A7)
    sc = D.Scenario(
        hpar,
        speed_ref=D.Profile.constant(600 * D.RPM),
        load=D.Profile.constant(load_pu * float(hpar.T_rated)),
        omega_m0=600 * D.RPM,
    )
    drive = D.bench_drive(hpar, handover=0.3, alpha_s=2 * math.pi * 10.0)
    sol = jaxobs.simulate(D.ClosedLoop(drive, leso_bank(hpar, hpar.p * 600 * D.RPM, primary=0), sc), 1.0)
    rpm = np.asarray(sol.outputs.speed_rpm)[np.asarray(sol.t) >= 0.6]
    return float(np.ptp(rpm))


@pytest.mark.slow
def test_cleso_closing_fails_with_a_fast_speed_loop_but_load_steadies_it():
    """002's C-LESO fails at half load and runs at 40 % (Sec. V-B).  Ours, with the speed loop at 10 Hz,
    oscillates at every load, and *less* with load (docs/papers.md: with i_d* = 0 the C-LESO's steady lag
    puts +i_q sin|δ0| on the d axis, the stabilizing sign): the paper's load dependence is not in our model."""
    no_load, half = _cleso_closing_speed_band(0.0), _cleso_closing_speed_band(0.5)
    assert half > 60.0, half  # fails (±5 % of 600 r/min and more) at half load, as 002's did ...
    assert no_load > half + 50.0, (no_load, half)  # ... but worse without load, unlike 002


def _cleso_closing_at(loads, q_sat=None, dual=False):
    """(speed deviation from 600 r/min, r/min; the C-LESO's mean error, deg) after 0.6 s, the C-LESO closing
    the loop at 600 r/min on the bench speed loop: the harmonic single bench (its plant saturating by
    ``q_sat``, the FOC and the observers assuming the nominal L̂q), or the dual machine's individual sets."""
    from jaxobs.reproduce.leso import leso_bank

    hpar = D.bench_machine("ipmsm002", a5=papers.IPMSM_002_A5, a7=papers.IPMSM_002_A7)
    if dual:
        machine = D.dual_ipmsm_paper002()
        est, rated = machine.per_set(), float(machine.m.T_rated)
        drive = D.dual_bench_drive(machine, mode="individual", handover=0.3)
    else:
        est, rated = hpar, float(hpar.T_rated)
        drive = D.bench_drive(hpar, handover=0.3)
    plant = hpar if q_sat is None else D.bench_machine("ipmsm002", a5=hpar.a5, a7=hpar.a7, q_sat=q_sat)
    out = []
    for load in loads:
        sc = D.Scenario(
            est if dual else plant,
            est_par=est,
            speed_ref=D.Profile.constant(600 * D.RPM),
            load=D.Profile.constant(load * rated),
            omega_m0=600 * D.RPM,
        )
        bank = leso_bank(est, est.p * 600 * D.RPM, primary=0)
        sys_ = D.DualClosedLoop(drive, bank, sc, machine) if dual else D.ClosedLoop(drive, bank, sc)
        sol = jaxobs.simulate(sys_, 1.0)
        assert bool(sol.ok)
        m = np.asarray(sol.t) >= 0.6
        o = sol.outputs
        dev = float(np.max(np.abs(np.asarray(o.speed_rpm)[m] - 600.0)))
        out.append((dev, float(np.degrees(np.asarray(wrap(o.obs.each[0].theta - o.theta_e)))[m].mean())))
    return out


@pytest.mark.slow
def test_neither_q_saturation_nor_the_dual_sets_make_the_cleso_fail_at_half_load():
    """002's C-LESO fails at half load, 600 r/min, and runs at 40 %: the two candidates docs/papers.md names do
    not reproduce it.  A plant whose Lq falls 30 % at rated current (L̂q nominal) adds lag that grows with
    load (eq 43's sign for L̂q > Lq: the stabilizing one with i_d* = 0), and the drive holds both loads; so does
    the dual machine run as two individual sets with the C-LESO on set 1."""
    sat = D.QSaturation.at(0.7, float(PAR.i_rated))
    (dev40, err40), (dev50, err50) = _cleso_closing_at((0.4, 0.5), q_sat=sat)
    assert dev40 < 2.0 and dev50 < 2.0, (dev40, dev50)  # measured 0.41, 0.35 r/min
    (_, lin50), *_ = _cleso_closing_at((0.5,))
    assert err50 < err40 < lin50 - 0.3, (err40, err50, lin50)  # measured −23.2°, −23.6° against −22.7°
    (d40, _), (d50, _) = _cleso_closing_at((0.4, 0.5), dual=True)
    assert d40 < 2.0 and d50 < 2.0, (d40, d50)  # measured 0.3, 0.2 r/min
