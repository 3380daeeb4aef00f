"""Closed-loop stability from the simulated loop (jaxobs.analysis.stability) and the linear view beside it.

Fast: the encoder loop's exponent is the speed loop's designed double pole −α_s (a known answer); the
linear speed loop through the FLL is the design at G = 1 and loses stability at low speed.  Slow: the
verdict against 3 s simulations at 30 operating points (stable and unstable, three flux designs) and
the exponent's derivative in a gain against central differences.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs
from jaxobs import papers
from jaxobs.analysis.envelope import speed_pulse
from jaxobs.analysis.stability import (
    OFF_ORBIT_DEV,
    fll_frequency_soifo,
    fll_frequency_sosoifo,
    floquet,
    linear_speed_loop,
    lyapunov,
    slope_fit,
)
from jaxobs.drive import (
    FOC,
    RPM,
    ClosedLoop,
    Drive,
    DualClosedLoop,
    FOCInput,
    Profile,
    Scenario,
    bench_drive,
    bench_machine,
    dq_to_ab,
    dual_bench_drive,
    dual_ipmsm_paper002,
    spmsm_paper000,
)
from jaxobs.linear import TransferFunction, faleso_tf
from jaxobs.observers import FALESO, GILESO
from jaxobs.studies.drive import bind_observer, drive_scenarios

ALPHA_S = 2 * math.pi * papers.BENCH_SPEED_HZ


def _machine():
    return spmsm_paper000(J=papers.BENCH_J_000)


def _drive(sensorless=True):
    par = _machine()
    return Drive(FOC.imc(par, 2 * math.pi * papers.BENCH_CURRENT_HZ, ALPHA_S), sensorless=sensorless)


def _scenarios(combos, names=("speed_rpm", "load_nm"), **kw):
    return drive_scenarios(_machine(), list(names), combos, **kw)


def _one(sc):
    return jax.tree.map(lambda x: x[0], sc)


def _sosoifo(K1=papers.SECOND_ORDER_SOIFO_K1, K2=papers.SECOND_ORDER_SOIFO_K2, lam=None):
    lam = K1**3 / (2 * K2) if lam is None else lam
    return jaxobs.SecondOrderSOIFO(0.0, 1.0, K1, K2, lam, 100.0)


def _soifo(k=papers.SOIFO_K, lam=None):
    return jaxobs.SOIFO(0.0, 1.0, k, k * k / 4 if lam is None else lam, 100.0)


# --------------------------------------------------------------------------
# fast
# --------------------------------------------------------------------------


def test_encoder_loop_exponent_is_the_designed_speed_pole():
    """With the encoder the slowest mode is the I-P speed loop's double pole at −α_s (FOC.imc): the
    exponent must find it (a double pole converges like 1/window, hence 15 %), and the loop is stable."""
    sc = _one(_scenarios([(600.0, 2.0)]))
    r = jax.jit(lambda s: lyapunov(ClosedLoop(_drive(False), None, s), settle=0.05, warmup=0.05, window=0.3))(sc)
    assert bool(r.stable)
    assert abs(float(r.exponent) + ALPHA_S) < 0.15 * ALPHA_S, float(r.exponent)
    assert float(r.speed_dev) < 1e-3


def test_floquet_finds_the_faleso_slow_root_where_a_window_cannot():
    """The FA-LESO's slowest mode is its integral state: the root of s² + (k2 − jωe)s + k1 (002 eqs 21-22,
    jaxobs.linear.faleso_tf) nearest 0, −k1 k2/(k2² + ωe²) ≈ −0.094 and −0.050 1/s at 150 and 600 r/min for
    Table II's gains, which a 1-4 s Lyapunov window leaves unresolved.  With the encoder closing the
    loop the observer only watches, so the sampled loop's slowest non-neutral multiplier over whole periods
    is that root: within 1 %.  The PLL is slowed 0.3× here because its ω̂ enters the LESO's rotation term
    jω̂ε (the steady ε is not 0), which the LESO-alone model leaves out: measured at 600 r/min −0.04997
    (PLL 0.3×), −0.04919 (1×), −0.0341 (3×) against the model's −0.04999.  At 6 r/min an electrical period
    (2 s) does not fit a 0.5 s max_window: not resolved (resolution inf), so marginal (the window cannot tell),
    not stable."""
    par = bench_machine("ipmsm002")
    pts = [(150.0, 0.0), (600.0, 15.0), (6.0, 0.0)]
    scs = drive_scenarios(par, ("speed_rpm", "load_nm"), pts, seed=0)
    obs = FALESO(par.Rs, par.Lq, kp_pll=0.3 * 133.3, ki_pll=0.09 * 8882.6)
    d = bench_drive(par, sensorless=False)
    kw = dict(window=0.2, max_window=0.5)
    r = jax.jit(jax.vmap(lambda sc: floquet(ClosedLoop(d, bind_observer(obs, sc), sc), **kw)))(scs)
    lam, res = np.asarray(r.exponent), np.asarray(r.resolution)
    for i, (rpm, _) in enumerate(pts[:2]):
        w_e = par.p * rpm * math.pi / 30
        root = float(np.max(np.asarray(faleso_tf(papers.FALESO_K1, papers.FALESO_K2, w_e).poles()).real))
        assert lam[i] == pytest.approx(root, rel=0.01), (rpm, lam[i], root)
        assert res[i] < 1e-3 and bool(r.stable[i]), (rpm, res[i])
        # the pair's other half (α and β of the integral state) is the conjugate root, the same rate
        assert float(r.exponents[i, 1]) == pytest.approx(lam[i], rel=1e-6)
    assert np.isinf(res[2]) and not bool(r.stable[2]) and bool(r.marginal[2]), (lam[2], res[2])


@pytest.mark.parametrize("mode", ["vsd", "individual"])
def test_floquet_on_the_dual_loop_finds_the_faleso_slow_root(mode):
    """The verdict on :class:`~jaxobs.drive.DualClosedLoop`: its state is the whole dual loop's (both sets, the xy
    PIs, set 2's FOC under "individual"), its window whole electrical periods of the dual machine.  With the
    encoder closing the loop and the FA-LESO watching (its PLL slowed 0.3× as in the single machine's test), the
    slowest non-neutral multiplier is the LESO's integral root (jaxobs.linear.faleso_tf) in both modes: under
    "vsd" the observer sees the αβ measurements, under "individual" set 1's, whose 5th/7th it filters (a forced
    input: the LESO is linear in it, so its root does not move).  Under "individual" the split of the speed
    integrators between the sets is neutral too (multiplier 1, :func:`jaxobs.analysis.stability._set_split`),
    taken out as the rotation is: without that the margin was 0 ± 0.04 at every point.  Lyapunov on the same
    loop is finite and, over 0.3 s, cannot resolve that slow root: marginal or stable, never unstable."""
    m = dual_ipmsm_paper002()
    est = m.per_set()
    obs = FALESO(est.Rs, est.Lq, kp_pll=0.3 * 133.3, ki_pll=0.09 * 8882.6)
    d = dual_bench_drive(m, mode=mode, sensorless=False)
    sc = Scenario(est, speed_ref=Profile.constant(600 * RPM), omega_m0=600 * RPM, load=Profile.constant(20.0))

    @jax.jit
    def verdicts(sc):
        loop = DualClosedLoop(d, bind_observer(obs, sc), sc, m)
        return floquet(loop, window=0.2, max_window=0.5), lyapunov(loop, settle=0.1, warmup=0.05, window=0.3)

    f, ly = verdicts(sc)
    w_e = m.p * 600.0 * math.pi / 30
    root = float(np.max(np.asarray(faleso_tf(papers.FALESO_K1, papers.FALESO_K2, w_e).poles()).real))
    assert float(f.exponent) == pytest.approx(root, rel=0.01), (float(f.exponent), root, float(f.resolution))
    # the orbit is periodic to 0.006 /s (measured under "vsd"; the single machine's 1e-3): the xy currents, zero
    # at the steady start, still build up from the 5th/7th over the 0.2 s settle
    assert float(f.resolution) < 0.01 and bool(f.stable) and float(f.speed_dev) < 1e-3
    assert np.isfinite(float(ly.exponent)) and (bool(ly.stable) or bool(ly.marginal)), (ly.exponent, ly.resolution)


@pytest.mark.slow
def test_floquet_on_the_dual_field_weakened_drive_agrees_with_its_runs():
    """The sensorless FA-LESO on the dual drive (VSD, 330 V, field weakening, 2.5 Hz speed loop) at 840 r/min (slow:
    two programs, one per field-weakening budget).  The runs (tests/test_dual.py) hold 840 r/min with the αβ
    budget ("ab", the default) and leave it with the sets' budget ("set", growing at +3.9 /s into a limit cycle);
    the linear model puts the speed pair through the PLL at −4.85 /s at "ab"'s i_d and +3.46 /s at "set"'s.
    Floquet on the same loop: growing with "set" (measured +19.2 /s after a 1 s settle, off its orbit), and with "ab"
    the FA-LESO's integral root, −0.034 /s, but only to ± 1.03 /s: the orbit under field weakening, a set at its
    inverter's limit most of the time, does not come back to itself over whole electrical periods (the neutral
    direction is off by a third after 0.3 s), so that verdict is marginal, not stable.  The test holds what is
    resolved: "set" unstable, "ab" not."""
    from jaxobs.drive import Inverter, VoltageFeedbackFW

    m = dual_ipmsm_paper002()
    est = m.per_set()
    kp, ki = jaxobs.linear.pll_gains(2 * math.pi * papers.LESO_PLL_HZ)
    obs = FALESO(0.0, 1.0, papers.FALESO_K1, papers.FALESO_K2, kp, ki)
    sc = Scenario(est, speed_ref=Profile.constant(840 * RPM), omega_m0=840 * RPM)
    verdict = {}
    for fw in ("ab", "set"):
        d = dual_bench_drive(m, handover=0.0, inverter=Inverter(udc=330.0), alpha_s=2 * math.pi * 2.5,
                             field_weakening=VoltageFeedbackFW(), fw_voltage=fw)  # fmt: skip
        verdict[fw] = jax.jit(
            lambda sc, d=d: floquet(DualClosedLoop(d, bind_observer(obs, sc), sc, m), settle=1.0, window=0.3)
        )(sc)
        print(fw, float(verdict[fw].exponent), float(verdict[fw].resolution), float(verdict[fw].speed_dev))
    ab, st = verdict["ab"], verdict["set"]
    assert bool(ab.stable) or bool(ab.marginal), (ab.exponent, ab.resolution)
    assert float(ab.exponent) < 0 and float(ab.speed_dev) < 0.01, (ab.exponent, ab.speed_dev)
    # "set": unstable.  Since field weakening's i_q keeps the speed loop's torque at the weakened i_d, this run
    # leaves its orbit within the settle (off_orbit; +19.2 /s against a rate bound of 18.2 /s), where no resolution
    # is defined; before, it stayed near it and read +13.1 ± 0.47 /s
    assert not bool(st.stable), (st.exponent, st.resolution)
    assert bool(st.off_orbit) or float(st.exponent) - float(st.resolution) > 0, (st.exponent, st.resolution)


def test_dual_loop_verdict_needs_the_observer_closing_within_the_settle():
    m = dual_ipmsm_paper002()
    est = m.per_set()
    sc = Scenario(est, speed_ref=Profile.constant(600 * RPM), omega_m0=600 * RPM)
    obs = FALESO(est.Rs, est.Lq).bind(est, m.p * 600 * RPM)
    loop = DualClosedLoop(dual_bench_drive(m, handover=0.3), obs, sc, m)
    with pytest.raises(ValueError, match="handover"):
        floquet(loop, settle=0.2)
    with pytest.raises(ValueError, match="handover"):
        lyapunov(loop, settle=0.1)


def test_floquet_agrees_with_long_lyapunov_windows_near_the_boundary():
    """000's closed-form second-order SOIFO on the bench's fixed 5 Hz loop crosses 0 near 411 r/min.  The
    Lyapunov exponent over 2 s windows (docs/stability.md) measures +0.51 ± 0.10 at 400 r/min,
    −0.32 ± 0.04 at 410, −1.26 ± 0.04 at 420 and −21.51 at 1000; the Floquet verdict over ≥ 0.5 s matches each
    within the two resolutions, and resolves 410 r/min, which a 0.4 s Lyapunov window calls marginal."""
    scs = _scenarios([(400.0, 0.0), (410.0, 0.0), (420.0, 0.0), (1000.0, 0.0)])
    obs, d = _sosoifo(), _drive()
    r = jax.jit(jax.vmap(lambda sc: floquet(ClosedLoop(d, bind_observer(obs, sc), sc), window=0.5)))(scs)
    lam, res = np.asarray(r.exponent), np.asarray(r.resolution)
    # within the two estimates' resolutions added (the 2 s fit's, and Floquet's own: near the boundary the
    # settled orbit is not quite periodic, 0.07-0.2 /s, and the estimate moves by that much with the window's
    # whole periods: 0.5 and 0.54 s gave −1.26 and −1.21 at 420 r/min)
    for got, want, tol, own in zip(lam, (0.51, -0.32, -1.26, -21.51), (0.10, 0.04, 0.04, 0.01), res):
        assert abs(got - want) <= tol + own, (lam, res)
    assert list(np.asarray(r.stable)) == [False, True, True, True], (lam, res)
    assert not np.any(np.asarray(r.marginal)), (lam, res)


def test_matrix_free_floquet_matches_the_full_matrix():
    """The matrix-free verdict (subspace iteration with Rayleigh–Ritz on jvp products, ``matrix="free"``) against
    the whole monodromy matrix (``"full"``) on the envelope benchmark's design (000's second-order SOIFO, lam 0.61,
    the bench drive): unstable and off its orbit at 300 r/min and 60 r/min under load, on either side of the
    boundary at 5 N·m (+0.149 /s at 405 r/min, marginal after the 0.2 s settle; −0.295 at 410, stable), stable at
    1000 r/min, 10 N·m.  The top multiplier's relative error is within 10·rtol, so its rate's within 10·rtol/T
    (T ≥ 0.2 s, the window), the resolution moves by no more, and every verdict is the same.  Measured: the rates
    within 3e-6 /s of the full matrix's."""
    par = bench_machine("spmsm000")
    d = bench_drive(par)
    obs = jaxobs.SecondOrderSOIFO(0.0, 1.0, papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2, 0.61, 100.0)
    scs = drive_scenarios(par, ("speed_rpm", "load_nm"), [(300, 0), (60, 8), (405, 5), (410, 5), (1000, 10)], seed=0)
    rtol = 1e-6

    def both(sc):
        loop = ClosedLoop(d, bind_observer(obs, sc), sc)
        return floquet(loop, matrix="full"), floquet(loop, matrix="free", rtol=rtol)

    full, free = jax.jit(jax.vmap(both))(scs)
    bound = 10 * rtol / 0.2
    assert np.all(np.abs(np.asarray(free.exponent - full.exponent)) <= bound), (full.exponent, free.exponent)
    for f in ("stable", "marginal", "off_orbit"):
        assert np.array_equal(np.asarray(getattr(full, f)), np.asarray(getattr(free, f))), f
    assert list(np.asarray(full.stable)) == [False, False, False, True, True]
    assert list(np.asarray(full.off_orbit)) == [True, True, False, False, False]
    assert bool(full.marginal[2])
    on = ~np.asarray(full.off_orbit)
    assert np.all(np.abs(np.asarray(free.resolution - full.resolution))[on] <= bound)


def test_floquet_chooses_the_cheaper_path():
    """``matrix="auto"``: the whole matrix below about 100 states with the defaults (the per-sample overhead is
    about 14 directions' worth: 000's drive has 32, so its verdict is the full matrix's), matrix-free above, where
    the window is long beside the settle, and never where the passes would cost more."""
    from jaxobs.analysis.monodromy import free_is_cheaper

    assert not free_is_cheaper(32, 1, 6, 5, 0.2, 0.2)
    assert free_is_cheaper(120, 1, 6, 5, 0.2, 0.2)
    assert free_is_cheaper(64, 1, 4, 2, 0.2, 2.0)
    assert not free_is_cheaper(64, 1, 4, 8, 0.2, 2.0)


def test_floquet_rejects_bad_options():
    sys_ = ClosedLoop(_drive(False), None, _one(_scenarios([(600.0, 0.0)])))
    with pytest.raises(ValueError, match="n_report"):
        floquet(sys_, n_report=0)
    with pytest.raises(ValueError, match="matrix must be one of auto, full, free"):
        floquet(sys_, matrix="eig")
    with pytest.raises(ValueError, match=r"block must be an integer in \[1, 32\]"):
        floquet(sys_, block=0)
    with pytest.raises(ValueError, match=r"iters must be an integer"):
        floquet(sys_, iters=1.5)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"rtol must be a number in \(0, 1\)"):
        floquet(sys_, rtol=0.0)
    with pytest.raises(ValueError, match="n_report must be <= block"):
        floquet(sys_, matrix="free", block=2, n_report=3)
    with pytest.raises(ValueError, match="window"):
        floquet(sys_, window=0.0)
    with pytest.raises(ValueError, match="system"):
        floquet(object())


@pytest.mark.slow  # two Floquet programs (the settle is static): 100 s to compile on the shared 2-core machine
def test_off_orbit_rate_is_a_bound_that_the_settled_rate_keeps():
    """000's second-order SOIFO at 300 r/min, no load, R̂s 30 % low: unstable at about +7 /s.  After the
    default 0.2 s settle the linearized run has left its operating point (its speed 23 % off), and the rate it
    measures there (+6.06 ± 1.53 /s) is not the point's: the verdict says ``off_orbit``, gives no resolution
    and a lower bound on the rate.  From the settled start (no settle, a 0.1 s window) the run
    stays on the orbit and measures the point's rate, +7.15 ± 0.30 /s; the bound is below it."""
    d = _drive()
    sc = _one(_scenarios([(300.0, 0.0, -0.3)], ("speed_rpm", "load_nm", "dRs")))
    loop = ClosedLoop(d, bind_observer(_sosoifo(), sc), sc)
    off = jax.jit(lambda: floquet(loop))()
    on = jax.jit(lambda: floquet(loop, settle=0.0, window=0.1))()
    assert bool(off.off_orbit) and float(off.speed_dev) > OFF_ORBIT_DEV and not bool(off.stable | off.marginal)
    assert np.isnan(float(off.resolution)), off.resolution
    assert 0.0 < float(off.rate_bound) <= float(off.exponent), (off.exponent, off.rate_bound)
    assert not bool(on.off_orbit) and np.isnan(float(on.rate_bound)) and float(on.speed_dev) < OFF_ORBIT_DEV
    assert float(on.exponent) == pytest.approx(7.15, abs=0.3) and float(on.resolution) < 0.5
    # the bound holds at the point: below the settled rate by more than the settled rate's resolution
    assert float(off.rate_bound) < float(on.exponent) - float(on.resolution), (off.rate_bound, on.exponent)


def test_linear_speed_loop_at_g1_is_the_design_and_fll_destabilizes_at_low_speed():
    par = _machine()
    foc = FOC.imc(par, 2 * math.pi * papers.BENCH_CURRENT_HZ, ALPHA_S)
    kw = dict(J=par.J, kt=par.kt, kp_w=foc.kp_w, ki_w=foc.ki_w)
    one = TransferFunction(jnp.ones(1), jnp.ones(1))
    p = np.sort_complex(np.asarray(linear_speed_loop(one, **kw).loop_poles))
    np.testing.assert_allclose(p.real, [-ALPHA_S, -ALPHA_S], rtol=1e-5)
    K1, K2 = papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2
    for rpm, holds in ((300.0, False), (1000.0, True)):
        w_e = par.p * rpm * math.pi / 30
        for fll in (
            fll_frequency_sosoifo(K1, K2, K1**3 / (2 * K2), w_e),
            fll_frequency_soifo(papers.SOIFO_K, 0.5, w_e),
        ):
            v = linear_speed_loop(fll, **kw)
            assert bool(v.observer_stable)  # the papers' verdict: the FLL alone is always stable
            assert bool(v.loop_stable) == holds, (rpm, np.asarray(v.loop_poles))


def test_lyapunov_rejects_bad_options():
    sys_ = ClosedLoop(_drive(False), None, _one(_scenarios([(600.0, 0.0)])))
    with pytest.raises(ValueError, match="n_dirs"):
        lyapunov(sys_, n_dirs=0)
    with pytest.raises(ValueError, match="window"):
        lyapunov(sys_, window=-1.0)
    with pytest.raises(ValueError, match="system"):
        lyapunov(object())


def test_slope_fit_resolution_covers_a_known_wobble():
    """A known exponent under a bounded oscillating wobble (a lightly damped pair's signature in the log
    growth): the fitted slope is within its resolution of the truth, the resolution falls with the window,
    and a clean exponential has none.  A wobble whose period divides a sixth of the window is the same in
    every part, so the resolution misses it: the slope's error is then within the bound 12A/(ωT²) of
    slope_fit's docstring."""
    dt, lam, amp = 1e-3, -0.3, 0.02

    def fit(n, f):
        t = np.arange(n) * dt
        acc = np.stack([lam * t + amp * np.sin(2 * np.pi * f * t + 0.4), -5.0 * t], axis=1)
        return (np.asarray(a) for a in slope_fit(jnp.asarray(acc), dt))

    res_by_n = []
    for n in (400, 1000, 3000):
        slope, res = fit(n, 6.3)
        assert abs(slope[0] - lam) <= res[0], (n, slope[0], res[0])
        assert res[1] < 1e-9 and abs(slope[1] + 5.0) < 1e-9
        res_by_n.append(res[0])
    assert res_by_n[0] > res_by_n[1] > res_by_n[2], res_by_n
    slope, res = fit(3000, 7.0)  # 7 periods per third, 10.5 per half: nearly the same in every part
    assert res[0] < abs(slope[0] - lam) <= 12 * amp / (2 * np.pi * 7.0 * 3.0**2), (slope[0], res[0])


@pytest.mark.slow  # 60 s on a quiet machine, 256 s at load 12
def test_near_neutral_point_is_marginal_and_a_longer_window_resolves_it():
    """000's closed-form second-order SOIFO on the unscheduled 5 Hz bench loop crosses 0 near 411 r/min
    (docs/stability.md).  Measured (settle 0.2 s, warm-up 0.1 s): at 410 r/min a 0.4 s window
    gives −0.25 ± 0.84 /s (a 2 s window: −0.31), so neither verdict: marginal.  At 400 r/min +0.57 ± 0.43:
    unstable.  At 1000 r/min −21.5 ± 0.03: stable.  A 1 s window at 410 r/min: −0.32 ± 0.16, resolved stable."""
    scs = _scenarios([(400.0, 0.0), (410.0, 0.0), (1000.0, 0.0)])
    obs = _sosoifo()
    d = _drive()

    def verdicts(window, s):
        return jax.jit(jax.vmap(lambda sc: lyapunov(ClosedLoop(d, bind_observer(obs, sc), sc), window=window)))(s)

    r = verdicts(0.4, scs)
    stable, marginal = np.asarray(r.stable), np.asarray(r.marginal)
    res, lam = np.asarray(r.resolution), np.asarray(r.exponent)
    info = (lam, res)
    assert list(stable) == [False, False, True], info
    assert list(marginal) == [False, True, False], info
    assert lam[0] > res[0] and abs(lam[1]) <= res[1] and -lam[2] > res[2], info
    assert np.all(np.asarray(r.speed_dev) < 0.2), info  # all three held their orbit: the verdicts are the exponent's
    longer = verdicts(1.0, jax.tree.map(lambda x: x[1:2], scs))
    assert bool(longer.stable[0]) and not bool(longer.marginal[0]), (longer.exponent, longer.resolution)
    assert float(longer.resolution[0]) < res[1]


# --------------------------------------------------------------------------
# slow: verdicts against long simulations, gradient against finite differences
# --------------------------------------------------------------------------

SPEEDS, LOADS = (300.0, 400.0, 500.0, 600.0, 1000.0), (0.0, 5.0)
DESIGNS = {  # the closed forms of 000 and the noise-tuned SOIFO of soifo_noise.toml (README)
    "sosoifo": _sosoifo(),
    "soifo": _soifo(),
    "soifo_noise": _soifo(0.9958, 0.369),
}


@pytest.mark.slow
def test_verdict_agrees_with_3s_pulse_simulations():
    """30 operating points (5 speeds × 2 loads × 3 designs), 19 stable and 11 unstable: the verdict of
    :func:`lyapunov` (a 0.7 s linearized run) against a 3 s simulation after a +2 % reference pulse of one
    speed-loop time constant 1/α_s (a pulse, not a step: the run stays at its operating point), wherever the
    verdict is resolved (not marginal); and :func:`floquet`'s (≥ 0.5 s) at every point.  The simulation holds
    when its speed deviation in [2, 3] s is under 1 % and at most 2 % above its peak in [0.05 + 4/α_s, 1] s (a
    decaying response; the 2 %: the steady ripple's peaks); otherwise it grew (a limit cycle or a run-away)."""
    combos = [(s, l) for s in SPEEDS for l in LOADS]
    scs = _scenarios(combos)
    scs_step = speed_pulse(scs, 0.05, 1.0 / ALPHA_S, 0.02)
    d = _drive()

    @jax.jit
    def verdicts(obs):
        lv = jax.vmap(lambda sc: lyapunov(ClosedLoop(d, bind_observer(obs, sc), sc)))(scs)

        def sim(sc):
            o = jaxobs.simulate(ClosedLoop(d, bind_observer(obs, sc), sc), 3.0, save=jaxobs.SaveAll()).outputs
            dev = jnp.abs(o.omega_m - o.omega_m_ref) / jnp.abs(o.omega_m_ref)
            dev = jnp.where(jnp.isfinite(dev), dev, jnp.inf)
            early, late = dev[int(round((0.05 + 4 / ALPHA_S) / d.ts)) : 10000].max(), dev[20000:].max()
            return (late < 0.01) & (late <= 1.02 * early)

        fv = jax.vmap(lambda sc: floquet(ClosedLoop(d, bind_observer(obs, sc), sc), window=0.5))(scs)
        return lv.stable, lv.marginal, lv.exponent, lv.resolution, jax.vmap(sim)(scs_step), fv

    # a marginal verdict (the exponent within the window's resolution of 0) claims neither: compared are
    # the resolved points, and they must be most of them.  The Floquet verdict resolves every point.
    n_stable = n_resolved = 0
    for name, obs in DESIGNS.items():
        *arrs, fv = verdicts(obs)
        stable, marginal, lam, res, holds = (np.asarray(a) for a in arrs)
        for c, s, m, e, r, h in zip(combos, stable, marginal, lam, res, holds):
            if not m:
                assert s == h, f"{name} at {c}: exponent {e:.2f} ± {r:.2f} 1/s, stable={s}, the 3 s run holds={h}"
        fs, fm, fe, fr = (np.asarray(a) for a in (fv.stable, fv.marginal, fv.exponent, fv.resolution))
        for c, s, m, e, r, h in zip(combos, fs, fm, fe, fr, holds):
            assert not m and s == h, f"{name} at {c}: Floquet {e:.3f} ± {r:.3f} 1/s, stable={s}, the 3 s run holds={h}"
        n_stable += int(stable.sum())
        n_resolved += int((~marginal).sum())
    assert 0 < n_stable < 3 * len(combos)
    assert n_resolved >= 24, n_resolved


@pytest.mark.slow
def test_exponent_gradient_matches_finite_differences():
    """d(exponent)/d(lam) by forward mode through the linearized run, against central differences, at a
    stable point (600 r/min) where the slowest mode is the FLL's coupling with the speed loop.

    The finite-window exponent is smooth between mode crossings (the two slowest exponents cross near
    lam = 0.64 here) but curves on the scale of 0.01 in lam, so a central difference of h = 0.01 is not the
    oracle: measured at lam = 0.60, forward mode −70.8548 against central differences −75.22
    (h = 1e-2), −70.903 (1e-3), −70.8553 (1e-4), −70.85485 (1e-5): they converge to it.  (With h = 0.01 at
    0.61 and 0.62 the gap is 9 % and 7 %.)  So h = 1e-4, and 1e-3 relative."""
    sc = _one(_scenarios([(600.0, 0.0)]))
    d = _drive()

    def exponent(lam):
        obs = bind_observer(_sosoifo(lam=lam), sc)
        return lyapunov(ClosedLoop(d, obs, sc), settle=0.1, warmup=0.1, window=0.3).exponent

    lam0, h = 0.60, 1e-4
    g = float(jax.jit(jax.jacfwd(exponent))(lam0))
    f = jax.jit(exponent)
    fd = (float(f(lam0 + h)) - float(f(lam0 - h))) / (2 * h)
    assert g < 0  # a faster FLL decouples it from the speed loop
    assert abs(g - fd) < 1e-3 * abs(fd), (g, fd)


@pytest.mark.slow
def test_floquet_gradient_matches_finite_differences():
    """d(exponent)/d(lam) of :func:`floquet` by forward mode (through the window's transition matrix and
    ``eigvals``) against central differences at 600 r/min, where the slowest mode is the FLL's coupling with
    the speed loop (simple there: the top multiplier is a real one, apart from the next, measured)."""
    sc = _one(_scenarios([(600.0, 0.0)]))
    d = _drive()

    def exponent(lam):
        obs = bind_observer(_sosoifo(lam=lam), sc)
        return floquet(ClosedLoop(d, obs, sc), settle=0.1, window=0.3).exponent

    lam0, h = 0.60, 1e-4
    g = float(jax.jit(jax.jacfwd(exponent))(lam0))
    f = jax.jit(exponent)
    fd = (float(f(lam0 + h)) - float(f(lam0 - h))) / (2 * h)
    assert g < 0  # a faster FLL decouples it from the speed loop
    assert abs(g - fd) < 1e-3 * abs(fd), (g, fd)


def test_speed_schedule_keeps_the_speed_loop_inside_the_fll_bandwidth():
    """FOC(speed_schedule=N): the speed loop's double pole is min(α_s, |p ω*|/N), so k_pω scales by r and
    k_iω by r² (r = min(1, |p ω*|/(N α_s))); off (N = 0, the default) the gains are the design's."""
    par = _machine()
    base = FOC.imc(par, 2 * math.pi * papers.BENCH_CURRENT_HZ, ALPHA_S)
    foc = FOC.imc(par, 2 * math.pi * papers.BENCH_CURRENT_HZ, ALPHA_S, speed_schedule=6.0)
    assert base.speed_gains(1.0) == (base.kp_w, base.ki_w)
    for rpm in (20.0, 200.0, 400.0, 2000.0):
        w_m = rpm * math.pi / 30
        r = min(1.0, par.p * w_m / (6.0 * ALPHA_S))
        kp, ki = foc.speed_gains(jnp.asarray(-w_m))
        np.testing.assert_allclose([float(kp), float(ki)], [float(base.kp_w) * r, float(base.ki_w) * r * r], rtol=1e-12)
    with pytest.raises(ValueError, match="speed_schedule"):
        FOC.imc(par, 1.0, 1.0, speed_schedule=-1.0)


@pytest.mark.slow
def test_speed_schedule_makes_the_flux_observers_stable_at_400_and_200_rpm():
    """000's second-order SOIFO closes the bench's 5 Hz speed loop unstably at 400 and 200 r/min (its FLL's
    ω̂ is too slow there, docs/stability.md); with speed_schedule = 6 it is stable at both."""
    par = _machine()
    scs = _scenarios([(400.0, 0.0), (200.0, 0.0)])
    obs = _sosoifo()

    @jax.jit
    def exponents(drive):
        # the presets' settle and window (tuning/presets/sosoifo.toml [envelope]): the default 0.4 s window left
        # both scheduled points marginal (−10.4 ± 18.7 and −6.1 ± 24.7 1/s) once verdicts carried a resolution
        kw = dict(settle=0.5, window=1.0)
        return jax.vmap(lambda sc: lyapunov(ClosedLoop(drive, bind_observer(obs, sc), sc), **kw))(scs)

    fixed = exponents(_drive())
    foc = FOC.imc(par, 2 * math.pi * papers.BENCH_CURRENT_HZ, ALPHA_S, speed_schedule=6.0)
    scheduled = exponents(Drive(foc, sensorless=True))
    assert not np.any(np.asarray(fixed.stable)), np.asarray(fixed.exponent)
    assert np.all(np.asarray(scheduled.stable)), np.asarray(scheduled.exponent)
    assert np.all(np.asarray(scheduled.exponent) < -3.0), np.asarray(scheduled.exponent)


def test_scheduled_speed_loop_is_bumpless_on_a_reference_step():
    """FOC(speed_schedule=N) moves k_pω with the reference; the integrator takes up that change, so a reference
    step does not step the I-P's output −k_pω ω̂ + ∫ (before the fix a +2 % step at 20 r/min cut i_q* by 2 % of
    k_pω ω̂: the speed first fell, and under load that kick lost the drive, docs/stability.md).  The gain the
    next samples use is the new one."""
    par = _machine()
    foc = FOC.imc(par, 2 * math.pi * papers.BENCH_CURRENT_HZ, ALPHA_S, speed_schedule=6.0).bind(par, 300.0)
    w = 20.0 * math.pi / 30
    op = foc.operating_point(par, w, w, 0.0, 4.67)
    cs = foc.init(op)
    i_a, i_b = dq_to_ab(op.i_d, op.i_q, 0.0)  # the rotor at θe = 0, on its operating point

    def out(ref):  # a speed-loop sample (k = 0) with the reference at ``ref``
        return foc.step(cs, FOCInput(0, i_a, i_b, 0.0, par.p * w, w, ref))

    s0, o0 = out(w)
    s1, o1 = out(1.02 * w)
    kp0, kp1 = float(foc.speed_gains(w)[0]), float(foc.speed_gains(1.02 * w)[0])
    assert kp1 == pytest.approx(1.02 * kp0, rel=1e-12)  # the schedule moved the gain...
    assert float(o1.iq_ref) == pytest.approx(float(o0.iq_ref), abs=1e-12)  # ...and the output did not jump
    assert abs((kp1 - kp0) * w) > 1e-5  # the jump the schedule would have made
    assert float(s1.kp_w) == pytest.approx(kp1, rel=1e-12) and float(s0.kp_w) == pytest.approx(kp0, rel=1e-12)


@pytest.mark.slow
def test_sosoifo_holds_20_rpm_sensorless_from_a_settled_start():
    """Paper 000 Figs 16-17: the second-order SOIFO sensorless at 20 r/min (1 % of rated), no load.  With the speed
    loop scheduled at ωe*/6 and the observer settled over 10 electrical periods (Drive.settled_for), a 3 s run
    holds |ω/ω* − 1| ≤ 0.5 % from t = 0 and the position error within 1°; the Lyapunov verdict over a window of
    12/α (11.5 s) is stable and resolved, at the linear model's slowest pole (−0.60 1/s).  The 0.2 s default settle (0.2
    periods) starts the observer 41° off and leaves the band: the weakly damped ring of a start that is not settled."""
    par = _machine()
    foc = FOC.imc(par, 2 * math.pi * papers.BENCH_CURRENT_HZ, ALPHA_S, speed_schedule=6.0)
    w_e = par.p * 20.0 * math.pi / 30
    settled = Drive(foc, sensorless=True).settled_for(w_e)
    assert settled.settle == pytest.approx(10 * 2 * math.pi / w_e)
    sc = _one(_scenarios([(20.0, 0.0)]))
    obs = bind_observer(_sosoifo(), sc)

    def band(drive):
        o = jaxobs.simulate(ClosedLoop(drive, obs, sc), 3.0).outputs
        dev = jnp.max(jnp.abs(o.omega_m / o.omega_m_ref - 1.0))
        return dev, jnp.degrees(jnp.max(jnp.abs(jaxobs.metrics.wrap(o.obs.theta - o.theta_e))))

    dev, err = (float(x) for x in eqx.filter_jit(band)(settled))
    assert dev <= 5e-3 and err <= 1.0, (dev, err)
    dev0, err0 = (float(x) for x in eqx.filter_jit(band)(Drive(foc, sensorless=True)))
    assert dev0 > 5e-3 and err0 > 10.0, (dev0, err0)  # the 0.2 s settle: outside the band
    alpha = 2 * float(foc.speed_gains(20.0 * math.pi / 30)[1] / foc.speed_gains(20.0 * math.pi / 30)[0])
    # the window envelope() uses at its lowest speed: 12/α (11.5 s), so that its thirds span the slow pair
    r = jax.jit(lambda s: lyapunov(ClosedLoop(settled, obs, s), settle=0.5, warmup=1 / alpha, window=12 / alpha))(sc)
    kt = float(par.kt)
    kp, ki = (float(g) for g in foc.speed_gains(20.0 * math.pi / 30))
    fll = fll_frequency_sosoifo(papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2, float(obs.lam), w_e)
    lin = linear_speed_loop(fll, J=float(par.J), kt=kt, kp_w=kp, ki_w=ki)
    slowest = float(jnp.max(lin.loop_poles.real))
    print(
        f"20 r/min: dev {dev:.2e} err {err:.3f} deg; 0.2 s settle: dev {dev0:.3f} err {err0:.1f} deg; "
        f"exponent {float(r.exponent):+.3f} ± {float(r.resolution):.3f} 1/s (linear {slowest:+.3f}), "
        f"orbit dev {float(r.speed_dev):.1e}"
    )
    assert bool(lin.loop_stable) and slowest == pytest.approx(-0.60, abs=0.02), slowest
    assert bool(r.stable) and float(r.speed_dev) < 5e-3, (float(r.exponent), float(r.resolution), float(r.speed_dev))
    assert abs(float(r.exponent) - slowest) < 0.1, (float(r.exponent), slowest)


@pytest.mark.slow
def test_loaded_low_speed_steady_start_is_steady_from_t0():
    """At low speed, the sosoifo preset's drive (speed_schedule = 6) at 144 r/min, 0 to 14 N·m, started
    steady with the observer settled over 10 electrical periods (Drive.settled_for: 1.4 s) holds |ω/ω* − 1| ≤ 0.5 %
    from t = 0.  With the 0.2 s default (1.4 periods) the observer starts 14° off and the loaded points dip
    10-54 %."""
    par = _machine()
    foc = FOC.imc(par, 2 * math.pi * papers.BENCH_CURRENT_HZ, ALPHA_S, speed_schedule=6.0)
    scs = _scenarios([(144.0, ld) for ld in (0.0, 4.67, 9.33, 14.0)])
    obs = _sosoifo()

    @eqx.filter_jit
    def dev(drive):
        def one(sc):
            o = jaxobs.simulate(ClosedLoop(drive, bind_observer(obs, sc), sc), 0.5).outputs
            return jnp.max(jnp.abs(o.omega_m / o.omega_m_ref - 1.0))

        return jax.vmap(one)(scs)

    settled = np.asarray(dev(Drive(foc, sensorless=True).settled_for(par.p * 144.0 * math.pi / 30)))
    short = np.asarray(dev(Drive(foc, sensorless=True)))
    print("144 r/min max |w/w* - 1|: settled", settled, "0.2 s settle", short)
    assert np.all(settled <= 5e-3), settled
    assert np.all(short[1:] > 0.05), short  # the loaded points of the old start


def test_leso_steady_start_does_not_depend_on_the_settle_length():
    """The GI-LESO that tuning/presets/gileso.toml tunes, at 150 r/min and 15 N·m on 002's IPMSM, started
    steady after a settle of 0.2 s or 0.338 s (10 periods of 355 r/min) holds |ω/ω* − 1| ≤ 0.5 % over its
    first 0.1 s: its PLL starts the settling phase at the rotor's angle (init_aligned).  Started at θ̂ = 0
    whatever the rotor's angle, the settled observer depends erratically on the settle's length: dips of 43 %
    and 65 % (a reversal), and a verification that calls the design not stable there."""
    par = bench_machine("ipmsm002")
    sc = _one(drive_scenarios(par, ("speed_rpm", "load_nm"), [(150.0, 15.0)], seed=0))
    obs = bind_observer(GILESO(par.Rs, par.Lq, omega0=932.27, omega_c=3.8557, kp_pll=135.04, ki_pll=19991.9), sc)

    def dev(settle):
        drive = bench_drive(par, sensorless=True, settle=settle)
        o = jaxobs.simulate(ClosedLoop(drive, obs, sc), 0.1).outputs
        return float(jnp.max(jnp.abs(o.omega_m / o.omega_m_ref - 1.0)))

    devs = [dev(s) for s in (0.2, 0.338)]
    print("150 r/min 15 N·m max |w/w* - 1| after a 0.2 / 0.338 s settle:", devs)
    assert max(devs) <= 5e-3, devs
