"""Back-EMF LESOs of paper 002 on the simulated IPMSM drive: steady lag, harmonics, mismatch,
the PLL loop, batching and gradients."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from gradcheck import assert_field_grads_match_fd

import jaxobs
from jaxobs import drive as D
from jaxobs import linear as L
from jaxobs import papers
from jaxobs.metrics import harmonic_amplitude, wrap
from jaxobs.reproduce.leso import leso_bank

A5, A7 = papers.IPMSM_002_A5, papers.IPMSM_002_A7
W0, K1_FA, K2_FA = papers.LESO_OMEGA0, papers.FALESO_K1, papers.FALESO_K2
PAR = D.bench_machine("ipmsm002")
DRIVE_BANDWIDTHS = (2 * math.pi * papers.BENCH_CURRENT_HZ, 2 * math.pi * papers.BENCH_SPEED_HZ)


@pytest.fixture(scope="module")
def steady_runs():
    """25, 50 and 70 Hz (300/600/840 r/min), no load, sensorless on the FA-LESO — one vmapped call."""
    rpms = jnp.array([300.0, 600.0, 840.0])

    def run(rpm):
        sc = D.Scenario(PAR, speed_ref=D.Profile.constant(0.0))  # traced speed set below
        sc = eqx.tree_at(lambda s: (s.speed_ref.values, s.omega_m0), sc, (jnp.atleast_1d(rpm * D.RPM), rpm * D.RPM))
        bank = leso_bank(PAR, PAR.p * rpm * D.RPM)
        sol = jaxobs.simulate(D.ClosedLoop(D.bench_drive(PAR, handover=0.3), bank, sc), 0.8)
        errs = jnp.stack([jnp.degrees(wrap(o.theta - sol.outputs.theta_e)) for o in sol.outputs.obs.each])
        return jnp.mean(errs[:, -2000:], axis=1), sol.ok

    return jax.jit(jax.vmap(run))(rpms)


def test_steady_position_errors_c_gi_fa(steady_runs):
    """Measured mean lags (deg) at 25/50/70 Hz: C-LESO 11.42/22.62/31.28 (TF 11.42/22.62/31.28;
    002: 14/23/34), GI-LESO 3.86/7.75/10.92 (TF 3.83/7.70/10.85; 002: 7/10/12), FA-LESO 0.001 (002: ≈ 0)."""
    err, ok = steady_runs
    assert bool(jnp.all(ok))
    lag = -np.asarray(err)  # rows: speeds; cols: C, GI, FA
    for j, f in enumerate((25, 50, 70)):
        we = 2 * math.pi * f
        tf_c = -math.degrees(np.angle(complex(L.cleso_tf(W0).freqresp(we))))
        assert abs(lag[j, 2]) < 0.5
        assert lag[j, 0] == pytest.approx(tf_c, abs=1.0)
        assert lag[j, 2] < lag[j, 1] < lag[j, 0]
    assert lag[0, 0] < lag[1, 0] < lag[2, 0]


@pytest.fixture(scope="module")
def harmonics_run():
    hpar = D.bench_machine("ipmsm002", a5=A5, a7=A7)
    we = hpar.p * 300 * D.RPM
    sc = D.Scenario(
        hpar,
        speed_ref=D.Profile.constant(300 * D.RPM),
        omega_m0=300 * D.RPM,
        load=D.Profile.constant(0.5 * float(hpar.T_rated)),
    )
    sol = jaxobs.simulate(D.ClosedLoop(D.bench_drive(hpar, handover=0.3), leso_bank(hpar, we), sc), 1.0)
    return sol, we


def test_faleso_attenuates_5th_and_7th_more_than_cleso(harmonics_run):
    """300 r/min, half load, BEMF with a5 = 6.75 %, a7 = 8.79 % (set so the C-LESO's transfer function
    predicts 002's measured C-LESO 5.4 % / 5.9 %).  Measured in ê_α: C-LESO 5.50/6.23 %, GI-LESO
    5.50/6.22 %, FA-LESO 2.15/2.91 %; transfer functions at −5ω̂e and +7ω̂e: 5.45/5.96, 5.45/5.94,
    2.13/2.78 %; 002 measured 5.4/5.9, 3.6/4.0, 0.8/0.7 %.

    The closed loop (current loop, PLL) does not explain the gap to the paper: our simulated ratios
    follow the transfer functions within 5 %.  With Table II's k2 = 100π the FA-LESO passes 32 % of a
    −5ω̂e component; 002's 0.8/5.4 needs ~12 %, i.e. a narrower filter (k2 ≈ 35π, checked below) than
    its Table II states.  The GI-LESO's resonance sits at ω̂e only, so at ±5ω̂e, ±7ω̂e it behaves as
    the C-LESO; 002's 3.6/4.0 % would need a lower ω0 than 500π for the GI-LESO."""
    sol, we = harmonics_run
    t = np.asarray(sol.t)
    n_per = int(round(2 * math.pi / we / 1e-4))
    m = np.zeros_like(t, dtype=bool)
    m[-10 * n_per :] = True
    pct = {}
    for name, o in zip(("C", "GI", "FA"), sol.outputs.obs.each):
        ea = np.asarray(o.e_a)
        fund = float(harmonic_amplitude(t, ea, we, m))
        pct[name] = [100 * float(harmonic_amplitude(t, ea, h * we, m)) / fund for h in (5, 7)]
    gi = L.gileso_tf(W0, papers.GILESO_K_R, papers.GILESO_OMEGA_C, we)
    tfs = {"C": L.cleso_tf(W0), "GI": gi, "FA": L.faleso_tf(K1_FA, K2_FA, we)}
    for name, tf in tfs.items():
        for idx, (h, a, sgn) in enumerate(((5, A5, -1), (7, A7, +1))):
            pred = 100 * a * abs(complex(tf.freqresp(sgn * h * we)))
            assert pct[name][idx] == pytest.approx(pred, rel=0.06), (name, h, pct[name][idx], pred)
    r5, r7 = pct["FA"][0] / pct["C"][0], pct["FA"][1] / pct["C"][1]
    assert 0.35 < r5 < 0.43 and 0.42 < r7 < 0.51  # measured 0.392 and 0.467
    # the k2 that would give 002's FA/C ratio at the 5th
    c5 = abs(complex(L.cleso_tf(W0).freqresp(5 * we)))
    g = lambda k2: abs(complex(L.faleso_tf(K1_FA, k2, we).freqresp(-5 * we))) / c5  # noqa: E731
    assert g(35 * math.pi) == pytest.approx(0.8 / 5.4, rel=0.15)


@pytest.mark.parametrize("which, factor", [("Lq", 1.5), ("Lq", 0.5), ("Rs", 1.5), ("Rs", 0.5)])
def test_parameter_mismatch_against_eqs_42_43(which, factor):
    """Rated load, 300 r/min, i_d = 0.  Measured FA-LESO mean error −7.08° / +6.68° for L̂q = 1.5/0.5 Lq
    (eq 43: −6.77° / +6.59°); R̂s errors give < 0.01° (eq 42: 0 with i_d = 0)."""
    est = D.bench_machine("ipmsm002", **{which: factor * float(getattr(PAR, which))})
    we = PAR.p * 300 * D.RPM
    sc = D.Scenario(
        PAR,
        est_par=est,
        speed_ref=D.Profile.constant(300 * D.RPM),
        omega_m0=300 * D.RPM,
        load=D.Profile.constant(float(PAR.T_rated)),
    )
    sol = jaxobs.simulate(D.ClosedLoop(D.bench_drive(PAR, handover=0.3), leso_bank(est, we), sc), 1.2)
    t = np.asarray(sol.t)
    m = t >= 1.0
    out = sol.outputs
    err = float(np.mean(np.degrees(np.asarray(wrap(out.obs.each[2].theta - out.theta_e)))[m]))
    i_d, i_q = float(np.mean(np.asarray(out.i_d)[m])), float(np.mean(np.asarray(out.i_q)[m]))
    e_ex = we * float(PAR.psi_f)
    if which == "Lq":
        pred = math.degrees(float(L.position_error_lq((1 - factor) * float(PAR.Lq), i_d, i_q, e_ex, we)))
        assert err == pytest.approx(pred, rel=0.10)
        assert abs(err) > 5.0
    else:
        assert abs(err) < 0.01


def test_cleso_closing_the_loop_holds_half_load_at_600rpm():
    """002 Sec. V-B: with the C-LESO closing the loop, "the half-rated load test cannot be completed" at
    600 r/min. Not reproduced: on our bench (assumed machine, harmonics a5/a7, 10x inertia) the C-LESO holds
    it. Measured: speed within 0.37 r/min of 600, position error 22.8° at most (its steady lag, 23° in 002
    Fig. 11 too), while the FA-LESO riding along errs by < 0.1°. The primary really is the C-LESO: its lag
    is in the FOC's frame, so the FA-LESO sees the true angle and the C-LESO lags."""
    par = D.bench_machine("ipmsm002", a5=A5, a7=A7)
    sc = D.Scenario(
        par,
        speed_ref=D.Profile.constant(600 * D.RPM),
        load=D.Profile.constant(0.5 * float(par.T_rated)),
        omega_m0=600 * D.RPM,
    )
    bank = leso_bank(par, par.p * 600 * D.RPM, primary=0)
    sol = jaxobs.simulate(D.ClosedLoop(D.bench_drive(par, handover=0.3), bank, sc), 1.0)
    m = np.asarray(sol.t) >= 0.6
    assert bool(sol.ok)
    assert np.max(np.abs(np.asarray(sol.outputs.speed_rpm)[m] - 600.0)) < 2.0
    err = [np.degrees(np.abs(np.asarray(wrap(o.theta - sol.outputs.theta_e))[m])).max() for o in sol.outputs.obs.each]
    assert err[0] == pytest.approx(22.8, abs=0.5), err  # measured 22.8°: its steady lag (002 Fig. 11: 23°)
    assert err[2] < 1.0, err


def test_pll_loop_through_the_faleso_is_stable():
    """Our PLL (ω_b = 2π·15 rad/s, ζ = 1/√2) closed through the FA-LESO's envelope response: stable by the
    generalized Routh test at 25, 50 and 70 Hz, crossover 136 rad/s with 40.5° phase margin."""
    kp, ki = L.pll_gains(2 * math.pi * papers.LESO_PLL_HZ)
    # jitted once for the three loops (same shapes): called eagerly, margins compiles its root finds anew each time
    margins = jax.jit(L.margins)
    for f in (25, 50, 70):
        loop = L.faleso_pll_loop(K1_FA, K2_FA, 2 * math.pi * f, kp, ki)
        assert bool(L.is_hurwitz(loop.feedback().den))
        m = margins(loop)
        assert float(m.phase_margin) == pytest.approx(40.5, abs=0.5)


def test_vmap_over_64_scenarios_and_gradients():
    base = D.Scenario(PAR, load=D.Profile.constant(10.0))
    batch = D.grid(base, speed_rpm=np.linspace(300, 840, 8), dLq=[-0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3, 0.4])
    drv = D.Drive(D.FOC.imc(PAR, *DRIVE_BANDWIDTHS))  # sensored: the FA-LESO runs open loop

    def run(s):
        w0 = s.speed_ref.values[0] * PAR.p
        obs = jaxobs.FALESO(PAR.Rs, PAR.Lq, K1_FA, K2_FA).bind(s.est_par, w0)  # the grid's L̂q (R̂s nominal)
        sol = jaxobs.simulate(D.ClosedLoop(drv, obs, s), 0.8)
        return jnp.mean(jnp.degrees(wrap(sol.outputs.obs.theta - sol.outputs.theta_e))[-1000:]), sol.ok

    err, ok = jax.jit(jax.vmap(run))(batch.scenarios)
    assert err.shape == (64,) and bool(jnp.all(ok))
    err = np.asarray(err).reshape(8, 8)
    assert np.all(np.diff(err, axis=1) < 0)  # more L̂q error, more angle error (eq 43), at every speed
    assert np.all(np.abs(err[:, 3]) < 0.05)  # no mismatch: measured <= 0.0024° after 0.7 s at 10 N·m


@pytest.mark.parametrize(
    "ctor, names",
    [
        pytest.param(jaxobs.FALESO, ("k1", "k2", "kp_pll", "ki_pll"), id="FA"),
        # the C-LESO's one gain: the same code path as the FA-LESO's; in the slow suite for the fast one's budget
        pytest.param(jaxobs.CLESO, ("omega0",), id="C", marks=pytest.mark.slow),
    ],
)
def test_gradients_wrt_leso_and_pll_gains(ctor, names):
    sc = D.Scenario(PAR, speed_ref=D.Profile.constant(600 * D.RPM), omega_m0=600 * D.RPM, load=D.Profile.constant(5.0))
    drv = D.Drive(D.FOC.imc(PAR, *DRIVE_BANDWIDTHS))
    obs = ctor(PAR.Rs, PAR.Lq, omega0_pll=0.95 * PAR.p * 600 * D.RPM)

    def loss(o):
        sol = jaxobs.simulate(D.ClosedLoop(drv, o, sc), 0.08)
        return jnp.mean(wrap(sol.outputs.obs.theta - sol.outputs.theta_e)[200:] ** 2)

    assert_field_grads_match_fd(loss, obs, names, rel=1e-4, abs=1e-12)


def test_bad_leso_arguments():
    with pytest.raises(ValueError, match=r"FALESO\.k1"):
        jaxobs.FALESO(0.6, 0.012, k1=-1.0)  # 002 eq (24): k1 > 0, k2 > 0
    with pytest.raises(ValueError, match=r"FALESO\.k2"):
        jaxobs.FALESO(0.6, 0.012, k2=0.0)
    with pytest.raises(ValueError, match=r"CLESO\.Lq"):
        jaxobs.CLESO(0.6, 0.0)
    with pytest.raises(ValueError, match=r"GILESO\.omega_c"):
        jaxobs.GILESO(0.6, 0.012, omega_c=-1.0)
