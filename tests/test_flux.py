"""Rotor-flux observers of paper 000: transfer-function facts in simulation, dc disturbances on the
drive, sensorless closed loop, batching and gradients."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from gradcheck import assert_field_grads_match_fd

import jaxobs
from jaxobs import drive as D
from jaxobs import linear as L
from jaxobs import papers
from jaxobs.metrics import wrap
from jaxobs.reproduce.flux import flux_bank
from jaxobs.signals import EMFSignal

K_SOIFO, K1, K2 = papers.SOIFO_K, papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2
LPF_WC = papers.LPF_OMEGA_C
W1 = 100 * math.pi
KP, KI = L.pll_gains(2 * math.pi * papers.FLUX_PLL_HZ)
FROZEN = 1e-12  # an FLL gain this small keeps ω̂ at ω1: the filters' own transfer functions are tested


def _observers(omega0=W1, lam_scale=FROZEN):
    return {
        "integrator": jaxobs.PureIntegratorFlux(0.0, 1.0, KP, KI, omega0=omega0),
        "LPF": jaxobs.LPFFlux(0.0, 1.0, LPF_WC, KP, KI, omega0=omega0),
        "SOIFO": jaxobs.SOIFO(0.0, 1.0, K_SOIFO, lam_scale, omega0=omega0),
        "second-order SOIFO": jaxobs.SecondOrderSOIFO(0.0, 1.0, K1, K2, lam_scale, omega0=omega0),
    }


def _dft(x, t, w):
    """Amplitude of the component at angular frequency w (whole periods), and the mean for w = 0."""
    if w == 0:
        return float(np.mean(x))
    return float(2 * np.abs(np.mean(x * np.exp(-1j * w * t))))


@pytest.fixture(scope="module")
def table_i_runs():
    """e = 5 V dc on α + 100 V fundamental at 50 Hz + harmonics 2…13, both sequences."""
    harm = {2: 4.0, -3: 3.0, 4: 2.0, -5: 10.0, 7: 8.0, -11: 3.0, 13: 2.0}
    sig = EMFSignal(A1=100.0, omega1=W1, dc=(5.0, 0.0), harmonics=harm)
    out = {}
    for name, obs in _observers().items():
        sol = jaxobs.simulate(jaxobs.OnSignal(obs, sig), 2.0)
        out[name] = (np.asarray(sol.t), np.asarray(sol.outputs.obs.psi_a), np.asarray(sol.outputs.obs.psi_b))
    return harm, out


def test_integrator_dc_offset_grows_with_time(table_i_runs):
    """000 eq (10): A0 t — the integrator's α flux drifts by 5 V × 1 s = 5 Wb per second."""
    _, out = table_i_runs
    t, pa, _ = out["integrator"]
    m1, m2 = (t >= 0.9) & (t < 1.0), (t >= 1.9) & (t < 2.0)
    assert np.mean(pa[m2]) - np.mean(pa[m1]) == pytest.approx(5.0, rel=0.01)


def test_lpf_attenuation_and_phase_match_eq_11(table_i_runs):
    _, out = table_i_runs
    t, pa, _ = out["LPF"]
    m = t >= 1.8
    z = 2 * np.mean(pa[m] * np.exp(-1j * W1 * t[m]))  # complex amplitude of ψα at ω1
    ideal = 100.0 / (1j * W1)  # the integrator's: A1/ω1 at −π/2 (e_α = A1 cos ω1 t)
    assert abs(z) == pytest.approx(100.0 / math.hypot(W1, LPF_WC), rel=0.02)  # A1/√(ω1² + ωc²)
    assert np.angle(z / ideal) == pytest.approx(math.atan(LPF_WC / W1), rel=0.02)  # lead θ1 = atan(ωc/ω1)
    assert _dft(pa[m], t[m], 0) == pytest.approx(5.0 / LPF_WC, rel=0.02)  # dc A0/ωc


def test_soifo_dc_offset_is_k_A0_over_omega1_and_second_order_removes_it(table_i_runs):
    _, out = table_i_runs
    t, pa, _ = out["SOIFO"]
    m = t >= 1.8
    assert _dft(pa[m], t[m], 0) == pytest.approx(K_SOIFO * 5.0 / W1, rel=0.02)  # 000 eq (29)
    t, pa2, _ = out["second-order SOIFO"]
    assert abs(_dft(pa2[m], t[m], 0)) < 1e-4 * K_SOIFO * 5.0 / W1  # 000 eq (36): → 0


@pytest.mark.parametrize("h", [2, -3, 4, -5, 7, -11, 13])
def test_harmonic_attenuation_per_order_eqs_16_21(table_i_runs, h):
    """Each harmonic's flux amplitude relative to a pure integrator's (A_h/(|h|ω1)) equals
    (16) for the SOIFO and (21) for the second-order SOIFO within 2 %.  At h = 2 and 3 the
    second-order SOIFO passes *more* than the SOIFO — 000's "h²/K1K2 ≫ h/k" holds only from h = 4."""
    harm, out = table_i_runs
    ah, hh = harm[h], abs(h)
    ref = ah / (hh * W1)
    t, pa, _ = out["SOIFO"]
    m = t >= 1.8
    f1 = _dft(pa[m], t[m], hh * W1) / ref
    t, pa2, _ = out["second-order SOIFO"]
    f2 = _dft(pa2[m], t[m], hh * W1) / ref
    assert f1 == pytest.approx(float(L.soifo_harmonic_factor(hh, K_SOIFO)), rel=0.02)
    assert f2 == pytest.approx(float(L.sosoifo_harmonic_factor(hh, K1, K2)), rel=0.02)
    assert (f2 > f1) == (hh <= 3)


# --------------------------------------------------------------------------
# on the drive
# --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def du_alpha_run():
    par = D.bench_machine("spmsm000")
    we = par.p * 1000 * D.RPM
    sc = D.Scenario(
        par, speed_ref=D.Profile.constant(1000 * D.RPM), omega_m0=1000 * D.RPM, sensors=D.Sensors(u_offset=(5.0, 0.0))
    )
    return jaxobs.simulate(D.ClosedLoop(D.bench_drive(par, handover=0.4), flux_bank(par, we), sc), 0.8)


def test_du_alpha_ripple_orders_lpf_soifo_second_order(du_alpha_run):
    """Δuα = 5 V at 1000 r/min (000 Fig. 21).  Measured ripple p-p: LPF 0.301, SOIFO 0.156,
    second-order SOIFO 1.3e-9 rad (paper: 0.65, 0.25, none); flux-circle offsets LPF 0.0500 Wb
    (= 5 V/ωc; paper 0.05), SOIFO 0.0268 (kA0/ω1 = 0.0225 plus the FLL's share; paper 0.03),
    second-order SOIFO 1e-8 (paper: none)."""
    sol = du_alpha_run
    t = np.asarray(sol.t)
    m = t >= 0.6
    out = sol.outputs
    ripple = [float(np.ptp(np.asarray(wrap(o.theta - out.theta_e))[m])) for o in out.obs.each[1:]]
    lpf, soifo, so2 = ripple
    assert lpf > soifo > so2
    assert 1.6 <= lpf / soifo <= 2.3  # measured 1.93
    assert so2 < 1e-3 * soifo
    offs = [float(np.hypot(np.mean(np.asarray(o.psi_a)[m]), np.mean(np.asarray(o.psi_b)[m]))) for o in out.obs.each[1:]]
    assert offs[0] == pytest.approx(5.0 / LPF_WC, rel=0.02)
    assert 0.0225 <= offs[1] <= 0.030
    assert offs[2] < 1e-5


@pytest.fixture(scope="module")
def sensorless_runs():
    par = D.bench_machine("spmsm000")
    out = {}
    steps = D.Scenario.load_steps([0.0, 0.4], [0.0, 10.0])
    for rpm, t1, hand, load in ((400, 1.4, 0.8, None), (2000, 0.8, 0.2, steps)):
        we = par.p * rpm * D.RPM
        obs = jaxobs.SecondOrderSOIFO(par.Rs, par.Ld, K1, K2, L.second_order_soifo_lambda(K1, K2), omega0=we)
        sc = D.Scenario(par, speed_ref=D.Profile.constant(rpm * D.RPM), omega_m0=rpm * D.RPM, load=load)
        out[rpm] = jaxobs.simulate(D.ClosedLoop(D.bench_drive(par, handover=hand), obs, sc), t1)
    return out


def test_sensorless_second_order_soifo_holds_400_and_2000_rpm_and_the_load_step(sensorless_runs):
    """Sensorless on the second-order SOIFO after the hand-over.  Measured steady |θ̂e − θe|:
    6e-5 rad at 400 r/min, 1e-4 at 2000 r/min (paper: 0.03 and 0.13).  We do not model the
    sampling delay the paper blames: the observer pairs the current samples with the voltage
    applied between them (e over the period that just ended), so its estimate at t_k carries
    no delay; one sample of delay would cost ωe·Ts = 0.063 rad at 2000 r/min.  Bound: 5e-3 rad.
    During the 10 N·m step the error peaks at 0.06 rad (paper 0.20) and the speed recovers."""
    for rpm, sol in sensorless_runs.items():
        t = np.asarray(sol.t)
        err = np.abs(np.asarray(wrap(sol.outputs.obs.theta - sol.outputs.theta_e)))
        speed = np.asarray(sol.outputs.speed_rpm)
        steady = t >= t[-1] - 0.1
        assert bool(sol.ok)
        assert err[steady].max() < 5e-3, (rpm, err[steady].max())
        assert np.abs(speed[steady] - rpm).max() < 0.01 * rpm
        if rpm == 2000:
            after = t >= 0.4
            assert err[after].max() < 0.1  # measured 0.06 rad through the load step
            assert speed[after].min() > 1500  # the dip (measured 1645 r/min) does not lose the rotor


def test_vmap_over_64_scenarios_with_the_second_order_soifo():
    par = D.bench_machine("spmsm000")
    base = D.Scenario(par, load=D.Profile.constant(2.0))
    batch = D.grid(base, speed_rpm=np.linspace(1400, 2000, 8), dRs=np.linspace(-0.5, 0.5, 8))
    drv = D.Drive(D.FOC.imc(par, 2 * math.pi * papers.BENCH_CURRENT_HZ, 2 * math.pi * papers.BENCH_SPEED_HZ))

    def run(s):
        we0 = s.speed_ref.values[0] * par.p
        obs = jaxobs.SecondOrderSOIFO(par.Rs, par.Ld, K1, K2, 0.6, omega0=1.0).bind(s.est_par, we0)  # grid's R̂s
        sol = jaxobs.simulate(D.ClosedLoop(drv, obs, s), 0.4)  # sensored: the observer runs open loop
        return jnp.max(jnp.abs(wrap(sol.outputs.obs.theta - sol.outputs.theta_e)[-500:])), sol.ok

    err, ok = jax.jit(jax.vmap(run))(batch.scenarios)
    assert err.shape == (64,) and bool(jnp.all(ok))
    # measured 4e-5 … 7e-5 rad: with i_d = 0 an Rs error is parallel to the BEMF and moves the
    # flux amplitude, not its angle (cf. 002 eq 42)
    assert float(jnp.max(err)) < 1e-3


def _flux_loss(obs, sig, t1=0.15):
    sol = jaxobs.simulate(jaxobs.OnSignal(obs, sig), t1)
    t = sol.t
    th_true = sig.omega1 * t + sig.phase - math.pi / 2  # ψ = ∫e lags e by 90°
    return jnp.mean(wrap(sol.outputs.obs.theta - th_true)[500:] ** 2)


@pytest.mark.parametrize(
    "names", [("SOIFO", ("k", "lam")), ("second-order SOIFO", ("K1", "K2", "lam"))], ids=["SOIFO", "SOSOIFO"]
)
def test_gradients_wrt_observer_gains_match_finite_differences(names):
    which, fields = names
    sig = EMFSignal(A1=100.0, omega1=W1, dc=(3.0, -1.0), harmonics={-5: 8.0, 7: 5.0})
    obs = _observers(omega0=0.9 * W1, lam_scale=0.5)[which]  # FLL active: starts 10 % off
    assert_field_grads_match_fd(_flux_loss, obs, fields, sig, rel=1e-4)


def test_paper_discretization_of_the_second_order_soifo():
    """000 eqs (22)-(25) as difference equations track like the continuous model, half a sample later
    (the direct form treats the period's average e as a sample at its end): 0.5 ω1 Ts = 0.0157 rad."""
    sig = EMFSignal(A1=100.0, omega1=W1)
    ours = jaxobs.SecondOrderSOIFO(0.0, 1.0, K1, K2, 0.6, omega0=W1)
    paper = jaxobs.SecondOrderSOIFO(0.0, 1.0, K1, K2, 0.6, omega0=W1, discretization="paper")
    th = {}
    for name, o in (("ours", ours), ("paper", paper)):
        sol = jaxobs.simulate(jaxobs.OnSignal(o, sig), 1.0)
        th[name] = np.asarray(wrap(sol.outputs.obs.theta - (W1 * sol.t - math.pi / 2)))[-2000:]
    assert np.abs(th["ours"]).max() < 1e-3
    assert np.mean(th["paper"]) == pytest.approx(-0.5 * W1 * 1e-4, rel=0.05)


@pytest.mark.parametrize(
    "ctor, kwargs, field",
    [
        (jaxobs.SOIFO, dict(Rs=0.8, L=5e-3, k=0.0, lam=0.5, omega0=100.0), "SOIFO.k"),
        (jaxobs.SOIFO, dict(Rs=0.8, L=5e-3, k=1.4, lam=-1.0, omega0=100.0), "SOIFO.lam"),
        (jaxobs.SOIFO, dict(Rs=-0.8, L=5e-3, k=1.4, lam=0.5, omega0=100.0), "SOIFO.Rs"),
        (jaxobs.SecondOrderSOIFO, dict(Rs=0.8, L=0.0, K1=1.5, K2=3.0, lam=0.5, omega0=100.0), "SecondOrderSOIFO.L"),
        (
            jaxobs.SecondOrderSOIFO,
            dict(Rs=0.8, L=5e-3, K1=1.5, K2=float("nan"), lam=0.5, omega0=100.0),
            "SecondOrderSOIFO.K2",
        ),
        (jaxobs.LPFFlux, dict(Rs=0.8, L=5e-3, omega_c=0.0, kp_pll=10.0, ki_pll=10.0), "LPFFlux.omega_c"),
        (jaxobs.PureIntegratorFlux, dict(Rs=0.8, L=5e-3, kp_pll=10.0, ki_pll=10.0, ts=0.0), "PureIntegratorFlux.ts"),
    ],
)
def test_bad_flux_observer_arguments(ctor, kwargs, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        ctor(**kwargs)
