"""The dual three-phase IPMSM (paper 002's machine): the VSD transformation, the plant, both current-control
modes closed loop with the encoder and with the FA-LESO (jaxobs.drive.dual, jaxobs.drive.dual_loop)."""

import math
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from jaxobs import drive as D
from jaxobs import linear, papers
from jaxobs.drive import dual, dual_loop
from jaxobs.io.provenance import by_label
from jaxobs.metrics import harmonic_amplitude
from jaxobs.observers import CLESO, FALESO
from jaxobs.runtime.simulation import simulate

TH = dual.PHASE_ANGLES
rng = np.random.default_rng(0)


def _vsd(x6):
    return np.asarray(dual.phases_to_vsd(jnp.asarray(x6)))


# --- the transformation -------------------------------------------------------------------------------------


def test_vsd_matrix_is_zhao_lipo_and_orthogonal():
    T = dual.vsd_matrix()
    np.testing.assert_allclose(T @ T.T, np.eye(6), atol=1e-14)
    r3 = math.sqrt(3) / 2
    # Zhao & Lipo 1995 eq. (4), phase order A B C X Y Z = a1 b1 c1 a2 b2 c2, factor 1/√3
    zl = np.array(
        [
            [1, -0.5, -0.5, r3, -r3, 0],
            [0, r3, -r3, 0.5, 0.5, -1],
            [1, -0.5, -0.5, -r3, r3, 0],
            [0, -r3, r3, 0.5, 0.5, -1],
            [1, 1, 1, 0, 0, 0],
            [0, 0, 0, 1, 1, 1],
        ]
    ) / math.sqrt(3)
    np.testing.assert_allclose(T, zl, atol=1e-14)


def test_vsd_power_invariance_and_inverse():
    T = dual.vsd_matrix()
    u, i = rng.normal(size=(2, 6))
    assert (T @ u) @ (T @ i) == pytest.approx(u @ i, rel=1e-12)
    # the model's amplitude-invariant scaling: P = Σ u_k i_k = 3 Σ over the six VSD coordinates
    assert 3 * _vsd(u) @ _vsd(i) == pytest.approx(u @ i, rel=1e-12)
    np.testing.assert_allclose(np.asarray(dual.vsd_to_phases(_vsd(u))), u, atol=1e-12)


@pytest.mark.parametrize("wt", [0.0, 0.7, 2.9])
def test_balanced_pair_30deg_apart_maps_to_alpha_beta_only(wt):
    amp = 3.0
    x6 = amp * np.cos(wt - TH)  # each phase displaced as its winding: set 2 30° after set 1
    v = _vsd(x6)
    np.testing.assert_allclose(v[:2], [amp * math.cos(wt), amp * math.sin(wt)], atol=1e-12)  # amplitude invariant
    np.testing.assert_allclose(v[2:], 0.0, atol=1e-12)


@pytest.mark.parametrize("h,subspace", [(5, "xy"), (7, "xy"), (11, "ab"), (13, "ab"), (3, "o"), (1, "ab")])
def test_harmonics_map_as_vsd_says(h, subspace):
    # a harmonic of order h in every phase, e.g. the BEMF's: x_k = cos(h(ωt − θ_k))
    v = _vsd(np.cos(h * (0.4 - TH)))
    where = {"ab": slice(0, 2), "xy": slice(2, 4), "o": slice(4, 6)}
    for name, sl in where.items():
        norm = np.linalg.norm(v[sl])
        if name == subspace:
            assert norm == pytest.approx(1.0, rel=1e-12)
        else:
            assert norm < 1e-12, (h, name, v)


def test_sets_and_vsd_agree_with_the_phases():
    x6 = rng.normal(size=6)
    x6[:3] -= x6[:3].mean()  # isolated neutrals: no zero sequence per set
    x6[3:] -= x6[3:].mean()

    def clarke(xa, xb, xc):
        return (2 * xa - xb - xc) / 3, (xb - xc) / math.sqrt(3)

    a1, b1 = clarke(*x6[:3])
    c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
    a2o, b2o = clarke(*x6[3:])  # set 2 in its own frame, its a-axis 30° ahead: rotate into set 1's
    a2, b2 = c * a2o - s * b2o, s * a2o + c * b2o
    np.testing.assert_allclose(dual.sets_to_vsd(a1, b1, a2, b2), _vsd(x6)[:4], atol=1e-12)
    np.testing.assert_allclose(dual.vsd_to_sets(*dual.sets_to_vsd(a1, b1, a2, b2)), [a1, b1, a2, b2], atol=1e-12)


# --- the machine --------------------------------------------------------------------------------------------


def test_set_one_is_the_single_machine_and_torque_is_twice_it():
    m = dual.dual_ipmsm_paper002()
    single = m.per_set()
    th, w_e = 0.83, 157.0
    k = dual.pm_flux_vsd(m, jnp.asarray(th))
    # set 1's BEMF (z_αβ + conj(z_xy)) is the single machine's, harmonics included
    e1 = dual.vsd_to_sets(*(w_e * np.asarray(k)))[:2]
    np.testing.assert_allclose(e1, D.bemf_ab(single, w_e, th), rtol=1e-12)
    # αβ holds the fundamental only (the 5th/7th went to xy)
    np.testing.assert_allclose(np.asarray(k[:2]), [-float(m.m.psi_f) * math.sin(th), float(m.m.psi_f) * math.cos(th)])
    # both sets carrying the same dq current (xy = 0): twice the single machine's torque without its 6th
    # harmonic ripple (the two sets' 6th-order ripples are 180° apart and cancel)
    x = jnp.asarray([-1.5, 4.0, 0.0, 0.0, 10.0, th])
    smooth = D.torque(eqx.tree_at(lambda q: (q.a5, q.a7), single, (0.0, 0.0)), -1.5, 4.0, th)
    assert float(dual.dual_torque(m, x)) == pytest.approx(2 * float(smooth), rel=1e-12)
    assert float(D.torque(single, -1.5, 4.0, th)) != pytest.approx(float(smooth), rel=1e-3)
    # power balance with xy current and harmonics: Te ωm = Σ_k e_k i_k + reluctance
    x = jnp.asarray([0.0, 4.0, 0.7, -0.4, 10.0, th])
    i6 = np.asarray(dual.vsd_to_phases(jnp.asarray([*D.dq_to_ab(0.0, 4.0, th), 0.7, -0.4, 0.0, 0.0])))
    e6 = m.p * 10.0 * np.asarray(dual.vsd_to_phases(jnp.asarray([*k, 0.0, 0.0])))
    assert float(dual.dual_torque(m, x)) * 10.0 == pytest.approx(e6 @ i6, rel=1e-12)


def test_bad_input_names_the_field():
    m = dual.dual_ipmsm_paper002()
    with pytest.raises(ValueError, match="Lls"):
        dual.dual_ipmsm_paper002(Lls=-1e-3)
    with pytest.raises(ValueError, match="mode"):
        dual_loop.dual_bench_drive(m, mode="six-step")
    with pytest.raises(ValueError, match="DualPMSM.par"):
        dual.DualPMSM(m.m)
    with pytest.raises(ValueError, match="DualDrive.startup must be an IfStartup or None"):
        dual_loop.dual_bench_drive(m, startup=0.1)
    with pytest.raises(ValueError, match="DualFOC.fw_voltage must be 'ab' or 'set'"):
        dual_loop.dual_bench_drive(m, fw_voltage="phase")
    with pytest.raises(ValueError, match=r"DualDrive.settle must be in \[0, 60\] s"):
        dual_loop.dual_bench_drive(m, settle=-1.0)
    with pytest.raises(ValueError, match="DualDrive.settled_for: omega_e_min must be a speed > 0"):
        dual_loop.dual_bench_drive(m).settled_for(0.0)
    # ten periods: 1 s at 10 Hz; at 100 Hz (0.1 s) the default 0.2 s stays
    assert dual_loop.dual_bench_drive(m).settled_for(2 * math.pi * 10).settle == pytest.approx(1.0)
    assert dual_loop.dual_bench_drive(m).settled_for(2 * math.pi * 100).settle == pytest.approx(0.2)


# --- closed loop --------------------------------------------------------------------------------------------


def _run(mode, rpm, load_pu, observer=None, t1=0.4, handover=0.2):
    m = dual.dual_ipmsm_paper002()
    est = m.per_set()
    drv = dual_loop.dual_bench_drive(m, mode=mode, sensorless=observer is not None, handover=handover)
    sc = D.Scenario(
        est,
        speed_ref=D.Profile.constant(rpm * D.RPM),
        load=D.Profile.constant(load_pu * float(m.m.T_rated)),
        omega_m0=rpm * D.RPM,
    )
    return m, simulate(dual_loop.DualClosedLoop(drv, observer, sc, m), t1)


@pytest.mark.parametrize("mode", ["vsd", "individual"])
def test_encoder_steady_state_holds_speed_and_current_references(mode):
    m, sol = _run(mode, 300, 0.5, t1=0.5)  # the start ignores the xy currents: a 0.5 r/min dip, settled by 0.3 s
    o = sol.outputs
    last = slice(-1000, None)  # the last 0.1 s: 2.5 electrical periods
    assert abs(float(o.speed_rpm[last].mean()) - 300) < 0.05
    assert float(np.ptp(o.speed_rpm[last])) < 1.0
    assert float(np.abs(o.i_q[last] - o.iq_ref[last]).mean()) < 0.02 * float(o.iq_ref[last].mean())
    assert float(np.abs(o.i_d[last]).max()) < 0.2
    assert float(o.torque[last].mean()) == pytest.approx(30.0 + float(m.m.B) * 300 * D.RPM, rel=0.01)
    # the sets share the load: their fundamental currents match (the xy current is the 5th/7th they differ by)
    i1 = np.hypot(o.i_a1[last], o.i_b1[last]).mean()
    i2 = np.hypot(o.i_a2[last], o.i_b2[last]).mean()
    assert i1 == pytest.approx(i2, rel=0.05)


@pytest.mark.parametrize("mode", ["vsd", "individual"])
def test_faleso_closes_the_loop_on_the_mode_s_observer_input(mode):
    m = dual.dual_ipmsm_paper002()
    est = m.per_set()
    we = m.p * 600 * D.RPM
    kp, ki = linear.pll_gains(2 * math.pi * papers.LESO_PLL_HZ)
    obs = FALESO(est.Rs, est.Lq, papers.FALESO_K1, papers.FALESO_K2, kp, ki, we)
    _, sol = _run(mode, 600, 0.4, obs, t1=0.5)
    o = sol.outputs
    t = np.asarray(o.t)
    n_per = int(round(2 * math.pi / we / 1e-4))
    last = np.zeros_like(t, dtype=bool)
    last[-5 * n_per :] = True
    assert abs(float(o.speed_rpm[last].mean()) - 600) < 0.5
    err = np.degrees(np.angle(np.exp(1j * (np.asarray(o.theta_e_hat) - np.asarray(o.theta_e)))))[last]
    assert abs(err.mean()) < 0.5 and np.ptp(err) < 2.0
    ea = np.asarray(o.obs.e_a)
    fund = float(harmonic_amplitude(t, ea, we, last))
    h57 = [100 * float(harmonic_amplitude(t, ea, h * we, last)) / fund for h in (5, 7)]
    if mode == "vsd":
        # 002 Fig. 15: under VSD the 5th and 7th live in xy; the αβ observer sees none of them
        assert max(h57) < 0.05
    else:
        # Figs 13-14: the first set's equivalent BEMF carries them, the FA-LESO attenuates but shows them
        assert min(h57) > 0.5


def test_a_biased_observer_closing_from_t0_starts_where_it_settles():
    """The dual loop's steady start is ClosedLoop's (jaxobs.drive.loop.AbstractDriveLoop): the C-LESO, which
    lags, closing the loop from t = 0 after settling starts at its own steady error and the speed holds;
    without the settling (settle=0; the default is 0.2, as Drive's) it starts at the rotor's angle and the
    drive dips."""
    m = dual.dual_ipmsm_paper002()
    est = m.per_set()
    we = m.p * 300 * D.RPM
    kp, ki = linear.pll_gains(2 * math.pi * papers.LESO_PLL_HZ)
    obs = CLESO(est.Rs, est.Lq, papers.LESO_OMEGA0, kp, ki, we)
    sc = D.Scenario(
        est,
        speed_ref=D.Profile.constant(300 * D.RPM),
        load=D.Profile.constant(0.5 * float(m.m.T_rated)),
        omega_m0=300 * D.RPM,
    )
    res = {}
    for settle in (0.2, 0.0):
        drv = dual_loop.dual_bench_drive(m, mode="vsd", handover=0.0, settle=settle)
        o = simulate(dual_loop.DualClosedLoop(drv, obs, sc, m), 0.05).outputs
        err = np.degrees(np.angle(np.exp(1j * (np.asarray(o.theta_e_hat) - np.asarray(o.theta_e)))))
        res[settle] = (float(np.abs(np.asarray(o.speed_rpm) - 300).max()), err)
    dip, err = res[0.2]
    # measured: 1.04 r/min (the xy currents' start, as with the encoder), the error -11.4° throughout
    assert dip < 2.0 and err[:50].mean() < -5.0 and np.ptp(err) < 0.5
    dip0, err0 = res[0.0]
    assert dip0 > 10.0 and abs(err0[0]) < 0.1  # measured 14.7 r/min; the error grows from 0 to its lag


def _damped_sine(t, x):
    """(frequency Hz, decay rate σ 1/s, rms residual / peak to peak) of the least-squares fit
    x ≈ A e^(−σt) cos(2πft + φ) + c."""
    from scipy.optimize import least_squares

    t = t - t[0]

    def res(q):
        return q[0] * np.exp(-q[1] * t) * np.cos(2 * math.pi * q[2] * t + q[3]) + q[4] - x

    fits = [least_squares(res, [np.ptp(x) / 2, 2.0, f0, 0.0, float(x.mean())]) for f0 in (9.0, 10.0, 11.0)]
    best = min(fits, key=lambda r: r.cost)
    return best.x[2], best.x[1], float(np.sqrt(np.mean(best.fun**2)) / np.ptp(x))


def test_if_startup_from_standstill_hands_over_to_the_faleso():
    """The dual loop shares ClosedLoop's I-f start-up (IfStartup on each set's FOC, the observer held at the
    I-f frequency): from standstill the drive switches to the FA-LESO once the ramp and hold are done and
    runs at the reference on it.  The speed rings after the hand-over: the speed loop's mode through the
    FA-LESO's PLL, 10.3 Hz decaying at 1.8 /s (ζ 0.028), between jaxobs.linear.faleso_speed_loop_poles
    without the FA-LESO's frequency adaptation (9.95 Hz, 4.23 /s) and with it (11.05 Hz, 1.01 /s)."""
    m = dual.dual_ipmsm_paper002()
    est = m.per_set()
    kp, ki = linear.pll_gains(2 * math.pi * papers.LESO_PLL_HZ)
    obs = FALESO(est.Rs, est.Lq, papers.FALESO_K1, papers.FALESO_K2, kp, ki)
    sc = D.Scenario(est, speed_ref=D.Profile.constant(300 * D.RPM), omega_m0=300 * D.RPM)
    drv = dual_loop.dual_bench_drive(m, mode="vsd", handover=0.0, startup=D.IfStartup.for_machine(est))
    o = simulate(dual_loop.DualClosedLoop(drv, obs, sc, m), 1.6).outputs
    mode, speed, t = np.asarray(o.mode), np.asarray(o.speed_rpm), np.asarray(o.t)
    assert speed[0] == 0.0 and mode[0] == 0
    # measured: the switch at 0.586 s (if_handover_earliest 0.587 s), 299.6 r/min over 0.9-1.0 s (the speed
    # loop still ringing: 36 r/min peak to peak, 14 at 1.4-1.5 s), the angle error 0.02° mean
    t_switch = float(np.argmax(mode == 1)) * 1e-4
    assert t_switch == pytest.approx(0.586, abs=2e-3) and mode[int(t_switch * 1e4) :].all()
    late = (t >= 0.9) & (t < 1.0)
    assert abs(speed[late].mean() - 300) < 2.0
    err = np.degrees(np.angle(np.exp(1j * (np.asarray(o.obs.theta) - np.asarray(o.theta_e)))))[late]
    assert abs(err.mean()) < 0.5
    # the ringing, fitted over 0.9-1.6 s (7 periods; measured 10.31 Hz, σ = 1.85 /s, residual 0.2 % of 36 r/min:
    # a clean linear mode, the same as a 2 r/min speed step from a steady start gives, 10.31 Hz and 1.83 /s)
    f, sigma, resid = _damped_sine(t[t >= 0.9], speed[t >= 0.9])
    assert f == pytest.approx(10.31, abs=0.1) and sigma == pytest.approx(1.85, abs=0.2) and resid < 0.01
    # the linear model of that loop (ideal current control, continuous speed loop) brackets it: the FA-LESO's
    # frequency adaptation (ω̂ fed back into it) raises the pair and takes most of its damping; the sampled
    # loop's delays (1 kHz speed loop, 1.5 periods, the 300 Hz current loop) give some back (docs/papers.md)
    a = 2 * math.pi * papers.BENCH_SPEED_HZ
    kp_w, ki_w = 2 * a * float(est.J) / float(est.kt), a * a * float(est.J) / float(est.kt)
    we = est.p * 300 * D.RPM
    modes = {}
    for adaptation in (False, True):
        r = np.asarray(
            linear.faleso_speed_loop_poles(
                papers.FALESO_K1, papers.FALESO_K2, we, kp, ki, kp_w, ki_w, p=est.p, psi_f=float(est.psi_f),
                Ld=float(est.Ld), Lq=float(est.Lq), J=float(est.J), adaptation=adaptation,
            )
        )  # fmt: skip
        r = r[(np.abs(r.imag) > 1.0) & (np.abs(r.imag) < we / 2)]  # the speed loop's pair
        modes[adaptation] = (abs(r[0].imag) / (2 * math.pi), -r[0].real)
    (f0, s0), (f1, s1) = modes[False], modes[True]
    assert f0 == pytest.approx(9.95, abs=0.02) and s0 == pytest.approx(4.23, abs=0.02)
    assert f1 == pytest.approx(11.05, abs=0.02) and s1 == pytest.approx(1.01, abs=0.02)
    assert f0 < f < f1 and s1 < sigma < s0


# --- jaxobs reproduce leso --machine dual -------------------------------------------------------------------


def test_reproduce_leso_dual_rows():
    """Figs 13-15 on the dual machine: the FA-LESO attenuates the first set's 5th/7th most; under VSD the
    αβ subspace carries none (002: "negligible"); every run finite and the FA-LESO's angle held; the
    C-LESO meets 002's numbers (the calibration)."""
    from jaxobs.reproduce.leso_dual import DUAL_EXPERIMENTS, run_leso_dual

    rows, traces = run_leso_dual(dynamics=False)
    assert list(traces) == [e[0] for e in DUAL_EXPERIMENTS]
    by = {(r["experiment"], r["observer"], r["metric"]): r for r in rows}
    assert len(rows) == len(DUAL_EXPERIMENTS) * (3 * 2 + 4)
    for name, mode, *_ in DUAL_EXPERIMENTS:
        assert by[(name, "drive", "finite")]["ours"] is True
        assert abs(by[(name, "FA-LESO", "mean_error")]["ours"]) < 1.0
        for h in ("h5", "h7"):
            fa, c = by[(name, "FA-LESO", h)]["ours"], by[(name, "C-LESO", h)]["ours"]
            if mode == "vsd":
                assert max(fa, c) < 0.05 and by[(name, "C-LESO", h)]["paper"] is None
            else:
                assert fa < c / 1.5 and by[(name, "C-LESO", h)]["paper"] is not None
                # the calibration (papers.DUAL_LLS_002, DUAL_A5_002/A7): the C-LESO meets 002 at 300 r/min
                # (a5, a7 fitted there: 5.42 / 5.87 %) and at 600 r/min (Lls fitted on the ratio: 4.20 / 4.49 %)
                assert c == pytest.approx(by[(name, "C-LESO", h)]["paper"], rel=0.05)
    # paper vs ours: within the tolerance or explained (the GI- and FA-LESO's harmonics are not within)
    for r in rows:
        assert (r["within"] is None) == (r["paper"] is None) and (r["within"] is not False or r["explanation"]), r
    assert by[(DUAL_EXPERIMENTS[0][0], "C-LESO", "h5")]["within"]
    assert not by[(DUAL_EXPERIMENTS[0][0], "FA-LESO", "h5")]["within"]


@pytest.mark.slow
def test_reproduce_leso_dual_transients_each_leso_closing(tmp_path):
    """002 Figs 16-17 on the dual machine under VSD: the ramp to 840 r/min (field weakening on, idle at 540 V,
    acting at 330 V) and the load step, each LESO closing the loop; every figure draws (the CLI's)."""
    from jaxobs.plot import position_error_figure
    from jaxobs.reproduce.leso import LESO_NAMES
    from jaxobs.reproduce.leso_dual import (
        DUAL_DYNAMICS,
        DUAL_EXPERIMENTS,
        DUAL_LOAD_STEP,
        DUAL_RAMP,
        DUAL_RAMP_FW,
        run_leso_dual,
    )
    from jaxobs_tuning.cli_papers import REPRODUCE_DUAL_FILES

    rows, traces = run_leso_dual()
    keys = [e[0] for e in DUAL_EXPERIMENTS] + list(DUAL_DYNAMICS)
    assert list(traces) == keys and len(REPRODUCE_DUAL_FILES) == len(keys)
    for key, fname in zip(keys, REPRODUCE_DUAL_FILES):
        position_error_figure(traces[key], LESO_NAMES, key, tmp_path / fname, t_from=0.4)
    assert sorted(p.name for p in tmp_path.glob("*.png")) == sorted(REPRODUCE_DUAL_FILES)
    by = {(r["experiment"], r["observer"], r["metric"]): r for r in rows}
    for key in keys:
        assert by[(key, "drive", "finite")]["ours"] is True
    for i, obs in enumerate(LESO_NAMES):
        ramp = DUAL_RAMP if i == 2 else f"{DUAL_RAMP}, {obs} closing the loop"
        step = DUAL_LOAD_STEP if i == 2 else f"{DUAL_LOAD_STEP}, {obs} closing the loop"
        assert by[(ramp, obs, "max_abs")]["paper"] == (4.5 if i == 2 else None)
        assert by[(step, obs, "max_abs")]["paper"] == (3.2 if i == 2 else None)
        assert by[(ramp, "drive", "max_speed")]["ours"] == pytest.approx(840.0, abs=5.0)  # each closing holds it
        # 540 V: 840 r/min is below base speed; the field weakening stays idle (i_d only tracks its zero)
        assert by[(ramp, "drive", "max_u_ab")]["ours"] < 0.8 and by[(ramp, "drive", "min_id")]["ours"] > -1.0
        # steady lag + the PLL's acceleration error: measured 36.55° (C-LESO), 26.96° (GI-LESO), 19.81° (FA-LESO)
        peak = {"C-LESO": 36.55, "GI-LESO": 26.96, "FA-LESO": 19.81}[obs]
        assert by[(step, obs, "max_abs")]["ours"] == pytest.approx(peak, abs=0.05)
    # FA-LESO closing: 002's ramp peak (4.1 against 4.5 deg); C-LESO / GI-LESO peaks are their steady lags and more
    assert by[(DUAL_RAMP, "FA-LESO", "max_abs")]["ours"] < 6.0
    # 330 V, the FA-LESO closing on the 2.5 Hz speed loop: the field weakening holds 840 r/min with negative i_d,
    # the αβ voltage near its 0.95 margin (fw_voltage="ab"; measured 3.55° / 11.1 r/min against 002's 4.5° /
    # 13, i_d −7.18 A, αβ 0.964 u_max, 838.7 r/min at the end of the plateau)
    fw = DUAL_RAMP_FW
    assert by[(fw, "FA-LESO", "max_abs")]["within"] and by[(fw, "FA-LESO", "max_speed_err")]["within"]
    assert by[(fw, "drive", "max_speed")]["ours"] == pytest.approx(840.0, abs=5.0)
    assert by[(fw, "drive", "min_id")]["ours"] < -5.0 and by[(fw, "drive", "max_u_ab")]["ours"] < 0.98
    for r in rows:
        assert r["within"] is not False or r["explanation"], r


def _fw_speed_pair(i_d, speed_hz=2.5, rpm=840):
    """The sensorless speed loop's least damped pair (rad/s) at ``i_d`` (A): the per-set machine's speed loop
    closed through the FA-LESO's 15 Hz PLL (jaxobs.linear.faleso_speed_loop_poles; each set is the single
    machine on half the rotor, so the single bench's model)."""
    par = D.bench_machine("ipmsm002")
    kp, ki = linear.pll_gains(2 * math.pi * papers.LESO_PLL_HZ)
    a = 2 * math.pi * speed_hz
    kp_w, ki_w = 2 * a * float(par.J) / float(par.kt), a * a * float(par.J) / float(par.kt)
    we = par.p * rpm * D.RPM
    r = np.asarray(
        linear.faleso_speed_loop_poles(
            papers.FALESO_K1, papers.FALESO_K2, we, kp, ki, kp_w, ki_w,
            p=par.p, psi_f=float(par.psi_f), Ld=float(par.Ld), Lq=float(par.Lq), J=float(par.J), i_d=i_d,
        )
    )  # fmt: skip
    r = r[np.abs(r.imag) < we / 2]
    return r[np.argmax(r.real)]


def test_field_weakening_depth_decides_the_sensorless_speed_loop():
    """Why the dual drive's field weakening budgets the αβ voltage by default: on 330 V at 840 r/min with the
    2.5 Hz speed loop, "ab" settles at i_d = −7.3 A and "set" at −11.8 A (the xy voltage fitted under the
    margin too); the speed loop's pair through the PLL crosses into Re s > 0 near −9.5 A."""
    assert _fw_speed_pair(-7.29).real < -4.0  # measured −4.85 /s
    assert _fw_speed_pair(-11.1).real > 2.0  # +3.46 /s
    assert _fw_speed_pair(-9.0).real < 0.0 < _fw_speed_pair(-10.0).real


def test_sensorless_dual_field_weakening_holds_840_rpm_by_default():
    """The FA-LESO closing the dual drive (VSD) on 330 V at 840 r/min, speed loop 2.5 Hz, the default
    field-weakening budget: the drive holds 840 r/min (measured 840.0 ± 0.05 r/min, 0.01°, i_d −7.29 A).
    With fw_voltage="set" (the budget that was the default) the same run leaves 840 r/min: 801–942 r/min over
    0.6–1.5 s, growing at +3.9 /s into a 774–972 r/min cycle."""
    from jaxobs.reproduce.leso import leso_bank

    m = dual.dual_ipmsm_paper002()
    est = m.per_set()
    inv = D.Inverter(udc=330.0)
    drv = dual_loop.dual_bench_drive(
        m, sensorless=True, handover=0.3, inverter=inv, alpha_s=2 * math.pi * 2.5, field_weakening=D.VoltageFeedbackFW()
    )
    assert drv.ctrl.fw_voltage == "ab"
    sc = D.Scenario(est, speed_ref=D.Profile.constant(840 * D.RPM), omega_m0=840 * D.RPM)
    o = simulate(dual_loop.DualClosedLoop(drv, leso_bank(est, m.p * 840 * D.RPM), sc, m), 1.0).outputs
    late = np.asarray(o.t) >= 0.6
    rpm = np.asarray(o.speed_rpm)[late]
    err = np.degrees(np.abs(np.angle(np.exp(1j * (np.asarray(o.theta_e_hat) - np.asarray(o.theta_e))))))[late]
    assert np.max(np.abs(rpm - 840.0)) < 1.0, (rpm.min(), rpm.max())
    assert err.max() < 1.0 and np.asarray(o.i_d)[late].mean() < -6.0


def test_dual_steady_start_under_field_weakening():
    """The dual loop's steady start at 840 r/min on 330 V (encoder, 10 N·m) begins field-weakened: Δi_d in the
    FOC's integrator, i_d at the αβ voltage's margin.  Over 0.2 s the xy currents build up from zero and a set
    reaching its inverter's limit deepens i_d a little (measured: 838.4–840.0 r/min, i_d −6.86 → −7.69 A)."""
    m = dual.dual_ipmsm_paper002()
    inv = D.Inverter(udc=330.0)
    drv = dual_loop.dual_bench_drive(
        m, sensorless=False, inverter=inv, alpha_s=2 * math.pi * 2.5, field_weakening=D.VoltageFeedbackFW()
    )
    sc = D.Scenario(
        m.per_set(), speed_ref=D.Profile.constant(840 * D.RPM), omega_m0=840 * D.RPM, load=D.Profile.constant(10.0)
    )
    loop = dual_loop.DualClosedLoop(drv, None, sc, m)
    op = loop.operating_point()
    assert float(op.id_fw) < -5.0 and float(loop.init().ctrl.main.id_fw) == pytest.approx(float(op.id_fw))
    o = simulate(loop, 0.2).outputs
    rpm, i_d = np.asarray(o.speed_rpm), np.asarray(o.i_d)
    assert np.max(np.abs(rpm - 840.0)) < 3.0, (rpm.min(), rpm.max())
    assert np.max(np.abs(i_d - float(op.i_d))) < 1.5, (i_d.min(), i_d.max(), float(op.i_d))
    assert np.max(np.abs(i_d[:20] - float(op.i_d))) < 0.05  # at the start: steady, not from i_d = 0


def test_reproduce_leso_runs_the_dual_machine_by_default():
    """`jaxobs reproduce leso` includes 002's dual machine unless --machine single."""
    from jaxobs_tuning.cli import build_parser
    from jaxobs_tuning.cli_papers import (
        REPRODUCE_DUAL_FILES,
        REPRODUCE_DUAL_LAYOUT_FILES,
        REPRODUCE_FILES,
        reproduce_files,
    )

    for argv, files in (
        (["reproduce", "leso"], REPRODUCE_FILES["leso"] + REPRODUCE_DUAL_FILES + REPRODUCE_DUAL_LAYOUT_FILES),
        (["reproduce", "leso", "--machine", "single"], REPRODUCE_FILES["leso"]),
        (["reproduce", "flux"], REPRODUCE_FILES["flux"]),
    ):
        args = build_parser().parse_args(argv)
        assert reproduce_files(args) == files


def test_reproduce_flux_refuses_the_dual_machine(tmp_path, capsys):
    from jaxobs_tuning.cli import main

    assert main(["reproduce", "flux", "--machine", "dual", "--out", str(tmp_path)]) == 2
    assert "--machine" in capsys.readouterr().err


def test_both_sets_fed_alike_are_the_single_machine_on_half_the_rotor():
    """With no harmonics and the same voltage on both sets (xy stays zero) the dual plant is the single PMSM
    of per_set() carrying half the load, step for step (the xy subspace and the coupling are consistent)."""
    import jax

    m = dual.dual_ipmsm_paper002(a5=0.0, a7=0.0)
    single = D.PMSM(m.per_set(), ts=1e-4, n_sub=2)
    twin = dual.DualPMSM(m, ts=1e-4, n_sub=2)
    op = D.OperatingPoint(*(jnp.asarray(v) for v in (40.0, 40.0, 0.3, 10.0, 0.5, 4.0, 0.0, 0.0)))
    k = jnp.arange(300)
    u_a, u_b = 120 * jnp.cos(0.01 * k * 20), 120 * jnp.sin(0.01 * k * 20)

    def run_single(s, x):
        s, y = single.step(s, D.PlantInput(x[0], x[1], 10.0))
        return s, (y.i_d, y.i_q, y.omega_m, y.theta_e)

    def run_dual(s, x):
        s, y = twin.step(s, dual.DualPlantInput(x[0], x[1], x[0], x[1], 20.0))
        return s, (y.i_d, y.i_q, y.omega_m, y.theta_e, y.i_x, y.i_y)

    _, ys = jax.lax.scan(run_single, single.init(op), (u_a, u_b))
    _, yd = jax.lax.scan(run_dual, twin.init(op), (u_a, u_b))
    for a, b in zip(ys, yd[:4]):
        np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(np.asarray(yd[4:]), 0.0, atol=1e-12)


@pytest.mark.parametrize("mode", ["vsd", "individual"])
def test_the_two_sets_get_the_same_voltage_for_the_same_current(mode):
    """Set 2's dq frame (30° behind in its own Clarke coordinates) is set 1's rotor frame: fed the same
    Clarke current both sets get the same voltage; and a differential current is opposed by each set."""
    m = dual.dual_ipmsm_paper002()
    drv = dual_loop.dual_bench_drive(m, mode=mode, sensorless=False)
    foc = drv.ctrl.foc.bind(drv.ctrl.foc.est, drv.inverter.u_max, None)
    ctrl = eqx.tree_at(lambda c: c.foc, drv.ctrl, foc)
    cs = ctrl.init(None)
    f = jnp.asarray
    _, o = ctrl.step(
        cs, dual_loop.DualFOCInput(f(1), f(2.0), f(-3.0), f(2.0), f(-3.0), f(0.7), f(150.0), f(30.0), f(30.0))
    )
    np.testing.assert_allclose([o.u_a2, o.u_b2], [o.u_a1, o.u_b1], rtol=1e-12)
    # +1 A on set 1's α and −1 A on set 2's: an xy current; each set's voltage pushes its own back
    _, o = ctrl.step(cs, dual_loop.DualFOCInput(f(1), f(1.0), f(0.0), f(-1.0), f(0.0), f(0.7), f(0.0), f(0.0), f(0.0)))
    assert float(o.u_a1) < 0 < float(o.u_a2)


@pytest.mark.slow
def test_envelope_of_a_dual_faleso_job_agrees_with_pulse_simulations(tmp_path):
    """``jaxobs envelope`` on a job whose drive file declares 002's dual machine on 330 V with field weakening
    (docs/examples/ipmsm002_dual_faleso.toml) writes a map, and at each point (150 and 840 r/min × 0 and 30 N·m)
    its verdict `holds` agrees with 3 s simulations of the same dual drive pulsed +2 % and −2 % for one time
    constant of the speed loop (held: the late speed deviation under 1 % and not above the early one).

    Measured: it holds at 150 r/min at both loads and at 840 r/min unloaded, with the margin the FA-LESO's
    integral root k1 k2/(k2² + ωe²) = 0.0338 /s at 840 r/min (the job's 1 s Floquet windows resolve it to
    ±0.027 /s; 0.2 s windows left it marginal, ±0.089).  At 840 r/min and 30 N·m the sensorless drive does not
    hold (i_d −8.9 A, near the −9.5 A where the speed loop's pair through the PLL crosses; the encoder holds it):
    Floquet −1.25 ± 0.21 /s, the simulations stay 5 % off the reference both ways."""
    import dataclasses

    import xarray as xr
    from pulses import pulse_held

    from jaxobs.scenarios.families import bind_observer
    from jaxobs_tuning.cli import main
    from jaxobs_tuning.envelope import envelope_designs
    from jaxobs_tuning.job import job_drive

    job_file = Path(__file__).parents[1] / "docs" / "examples" / "ipmsm002_dual_faleso.toml"
    out = tmp_path / "env"
    rc = main(["envelope", str(job_file), "--speeds", "150,840", "--loads", "0,30", "--out", str(out), "--quiet"])
    assert rc == 0 and (out / "envelope.png").is_file()
    ds = by_label(xr.open_dataset(out / "envelope.nc").load())
    assert ds.attrs["machine"] == "ipmsm002_dual_330v" and "machine_Lls" in ds.attrs

    job, designs = envelope_designs(job_file)
    spec = dataclasses.replace(job.drive, loop="sensorless", start="steady", handover=0.0)
    par, dual_m = spec.drive_file.machine, spec.drive_file.dual
    points = [(s, ld) for s in (150.0, 840.0) for ld in (0.0, 30.0)]
    drive = job_drive(spec, dual=True).settled_for(150.0 * D.RPM * par.p)
    foc = drive.ctrl.foc.bind(par, drive.inverter.u_max)

    def held(height):
        system = lambda obs, sc: dual_loop.DualClosedLoop(drive, bind_observer(obs, sc), sc, dual_m)  # noqa: E731
        cf = {"closed_form": designs["closed_form"]}
        return pulse_held(system, cf, par, foc, points, height=height)["closed_form"].tolist()

    verdict = [int(ds["holds"].sel(design="closed_form", speed_rpm=s, load_nm=ld)) == 1 for s, ld in points]
    assert verdict == [True, True, True, False], ds["margin"].values
    assert held(0.02) == verdict and held(-0.02) == verdict
    w_e = par.p * 840.0 * np.pi / 30
    root = papers.FALESO_K1 * papers.FALESO_K2 / (papers.FALESO_K2**2 + w_e**2)
    sel = ds.sel(design="closed_form", speed_rpm=840.0, load_nm=0.0)
    assert abs(float(sel["margin"]) - root) <= float(sel["resolution"]), (float(sel["margin"]), root)
