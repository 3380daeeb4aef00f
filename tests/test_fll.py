"""The SOGI-FLL family of paper 001: parity, small-signal models, Tests A–E, batching, gradients, validation."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from gradcheck import assert_field_grads_match_fd

import jaxobs
from jaxobs import linear, metrics
from jaxobs.studies.demo import DEMO_TESTS, fll_demo

TE = 0.2  # event time of the test signals


# --------------------------------------------------------------------------
# NumPy parity
# --------------------------------------------------------------------------


def _numpy_sogi_fll(k, lam, wn, v, h, v_floor=1e-3):
    """Plain NumPy loop of 001 eqs (6)-(8) with AB3 (RK4 start-up), written independently."""

    def f(x, u):
        y, q, w = x
        e = u - y
        return np.array([w * (k * e - q), w * y, -lam * e * q / max(y * y + q * q, v_floor**2)])

    x = np.array([0.0, 0.0, wn])
    out = np.empty((len(v), 3))
    f1 = f2 = None
    for n, u in enumerate(v):
        out[n] = x
        f0 = f(x, u)
        if n < 2:
            k1 = f0
            k2 = f(x + 0.5 * h * k1, u)
            k3 = f(x + 0.5 * h * k2, u)
            k4 = f(x + h * k3, u)
            x_new = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        else:
            x_new = x + h / 12 * (23 * f0 - 16 * f1 + 5 * f2)
        f2, f1 = f1, f0
        x = x_new
    return out


def test_numpy_loop_parity_1s_at_10khz():
    obs = linear.sogi_fll_closed_form()
    sig = jaxobs.paper001_test("C", t_event=0.3)
    sol = jaxobs.simulate(jaxobs.OnSignal(obs, sig), 1.0)
    ref = _numpy_sogi_fll(float(obs.k), float(obs.lam), float(obs.omega_n), np.asarray(sol.outputs.u), obs.ts)
    assert len(sol.t) == 10_000
    np.testing.assert_allclose(np.asarray(sol.outputs.obs.v_alpha), ref[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(sol.outputs.obs.v_beta), ref[:, 1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(sol.outputs.obs.omega), ref[:, 2], rtol=1e-12, atol=0)


# --------------------------------------------------------------------------
# small-signal models (001 Sec. V, Tests 1-3)
# --------------------------------------------------------------------------

FLLS = {
    "SOGI-FLL": (linear.sogi_fll_closed_form, lambda o: linear.sogi_fll_model(o.k, o.lam, o.omega_n)),
    "SOGI-FLL-WPF": (linear.wpf_closed_form, lambda o: linear.wpf_model(o.k1, o.k2, o.lam, o.omega_n)),
    "SOGI-FLL-WIF": (linear.wif_closed_form, lambda o: linear.wif_model(o.k1, o.k2, o.lam, o.omega_n)),
}


def _model_deviation(obs, model, test, t1=0.6):
    """Peak |period-average(nonlinear) − period-average(linear model)|, as a fraction of the step.

    Both traces go through the same one-period (20 ms) moving average, which
    removes the double-frequency ripple the LTI models cannot predict (001
    footnote 2) without shifting one against the other.
    """
    sig = jaxobs.paper001_test(test, t_event=TE)
    sol = jaxobs.simulate(jaxobs.OnSignal(obs, sig), t1)
    t = np.asarray(sol.t)
    after = t >= TE
    tau = jnp.asarray(t[after] - TE)
    wn = 2 * math.pi * 50
    if test == "1":  # ω̂ after a +2 Hz step: ω̂ = ωn + Δω · step(G_ω)
        lin = np.full_like(t, wn)
        lin[after] += 2 * math.pi * 2 * np.asarray(model.frequency.step(tau))
        x, scale = np.asarray(sol.outputs.obs.omega), 2 * math.pi * 2
    elif test == "2":  # ω̂ after a 20° jump: ω = Δφ δ(t) ⇒ ω̂ = ωn + Δφ · impulse(G_ω)
        lin = np.full_like(t, wn)
        lin[after] += math.radians(20) * np.asarray(model.frequency.impulse(tau))
        x = np.asarray(sol.outputs.obs.omega)
        scale = np.max(np.abs(lin - wn))  # the step has no frequency size: use the model's peak
    else:  # V̂ after a 0.75 p.u. sag: V̂ = 1 − 0.75 · step(G_V)
        lin = np.ones_like(t)
        lin[after] -= 0.75 * np.asarray(model.amplitude.step(tau))
        x, scale = np.asarray(sol.outputs.obs.amplitude), 0.75
    n_period = int(round(0.02 / obs.ts))
    xa = np.asarray(metrics.moving_average(jnp.asarray(x), n_period))
    la = np.asarray(metrics.moving_average(jnp.asarray(lin), n_period))
    window = t >= TE - 0.05
    return np.max(np.abs(xa - la)[window]) / scale


# Bounds, each set from a measured value with margin (measured, float64, AB3, 10 kHz):
#   Test 1 (+2 Hz): SOGI 0.96 %, WPF 1.06 %, WIF 1.18 %            -> bound 2 %
#   Test 2 (+20°):  SOGI 6.0 %, WPF 5.5 %, WIF 5.6 % of model peak -> bound 10 %
#       (a 20° jump is not small: sin 20° is 2 % below 20° in rad, and the
#        amplitude dip it causes couples into the frequency loop, which the
#        models omit — 001 Sec. V says as much)
#   Test 3 (0.75 sag): SOGI 1.7 %, WPF 2.5 %, WIF 3.0 %             -> bound 5 %
BOUNDS = {"1": 0.02, "2": 0.10, "3": 0.05}


@pytest.mark.parametrize("fll", list(FLLS))
@pytest.mark.parametrize("test", ["1", "2", "3"])
def test_linearized_models_predict_period_average(fll, test):
    make, model = FLLS[fll]
    obs = make()
    dev = _model_deviation(obs, model(obs), test)
    assert dev <= BOUNDS[test], (fll, test, dev)


def test_wif_fll_derivation_matters():
    """The FLL error derived for the WIF (input of the output GI) has 001's model; the naive one does not.

    With the SOGI-FLL's error (v − v')qv' on the WIF, the loop's s-coefficient is
    a + λ/2 instead of a (see SOGIFLLWIF's docstring): measured deviation on
    Test 1 is 8.0 % of the step against 1.2 % for the derived detector.
    """
    derived = linear.wif_closed_form()
    naive = linear.wif_closed_form(fll_error="residual")
    model = linear.wif_model(derived.k1, derived.k2, derived.lam, derived.omega_n)
    d_derived = _model_deviation(derived, model, "1")
    d_naive = _model_deviation(naive, model, "1")
    assert d_derived <= BOUNDS["1"]
    assert d_naive >= 3 * d_derived, (d_naive, d_derived)
    # and the naive loop follows its own model instead: with c = λ/2,
    # ω̂/ω = c (s + b) / (s³ + b s² + (a + c) s + c b)  (derivation in SOGIFLLWIF's docstring)
    a = naive.k1 * naive.k2 * naive.omega_n**2 / 4
    b = naive.k1 * naive.omega_n / 2
    c = naive.lam / 2
    naive_model = eqx.tree_at(lambda m: m.frequency, model, linear.TransferFunction([c, c * b], [1.0, b, a + c, c * b]))
    assert _model_deviation(naive, naive_model, "1") <= BOUNDS["1"]


# --------------------------------------------------------------------------
# paper 001 Sec. VI, Tests A-E
# --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def demo_rows():
    rows, _ = fll_demo(t_event=TE)
    return {(r["test"], r["fll"]): r for r in rows}


def test_demo_covers_every_test_and_fll(demo_rows):
    assert set(demo_rows) == {(t, f) for t in DEMO_TESTS for f in FLLS}
    assert all(r["ok"] for r in demo_rows.values())


def test_A_settles_in_about_two_and_a_half_cycles(demo_rows):
    """001 Sec. VI: all three respond in "around 2.5 cycles", at close speeds.

    Measured (cycles of 50 Hz after the 50 -> 52 Hz step, f̂ band around 52 Hz):
    5 % band 1.80 / 1.74 / 1.79, 2 % band 3.60 / 3.10 / 2.13 (SOGI / WPF / WIF).
    "About 2.5" is read as 2.5 ± 1 cycle for the 5 % band; the 2 % band is
    bounded at 4 cycles; "close speed" as the three 5 % times within 0.25 cycle.
    """
    s5 = [demo_rows[("A", f)]["settle_cycles"] for f in FLLS]
    s2 = [demo_rows[("A", f)]["settle2_cycles"] for f in FLLS]
    assert all(1.5 <= s <= 3.5 for s in s5), s5
    assert all(s <= 4.0 for s in s2), s2
    assert max(s5) - min(s5) <= 0.25, s5


def test_B_sogi_fll_overshoots_least(demo_rows):
    """001 Sec. VI (Fig. 10) and Fig. 14: in Test B "the quantities estimated by the
    SOGI-FLL experience rather smaller overshoots" than the WPF's and WIF's (its
    phase margin is the highest).

    Measured (SOGI / WPF / WIF, Table I gains): peak |f̂ − 50| 5.58 / 6.46 / 6.24 Hz;
    phase-error overshoot past zero 13.2 / 19.8 / 24.2°; V̂ dip below 0.5 p.u.
    0.0091 / 0.070 / 0.083 p.u. "Rather smaller" is read as at least 5 % smaller
    for each quantity, against each of the other two.
    """
    for key in ("freq_peak_hz", "phase_overshoot_deg", "amp_overshoot_pu"):
        sogi = demo_rows[("B", "SOGI-FLL")][key]
        for fll in ("SOGI-FLL-WPF", "SOGI-FLL-WIF"):
            assert sogi <= 0.95 * demo_rows[("B", fll)][key], (key, fll, sogi, demo_rows[("B", fll)][key])
    # every one overshoots: the check compares overshoots, not a missing transient
    assert all(demo_rows[("B", f)]["phase_overshoot_deg"] > 5.0 for f in FLLS)


def test_D_and_E_prefilter_and_inloop_filter_cut_the_ripple(demo_rows):
    """001 Figs. 12-13: WPF and WIF reject the dc offset and suppress the sub-harmonic.

    Measured frequency ripple (p-p, Hz): Test D SOGI-FLL 1.36, WPF and WIF
    ~1e-4 (what is left is discretization ripple); Test E SOGI-FLL 1.36,
    WPF 0.070 (19x), WIF 0.043 (31x).
    """
    for fll, min_d, min_e in (("SOGI-FLL-WPF", 1000.0, 15.0), ("SOGI-FLL-WIF", 1000.0, 25.0)):
        d = demo_rows[("D", "SOGI-FLL")]["freq_pp_hz"] / demo_rows[("D", fll)]["freq_pp_hz"]
        e = demo_rows[("E", "SOGI-FLL")]["freq_pp_hz"] / demo_rows[("E", fll)]["freq_pp_hz"]
        assert d >= min_d, (fll, d)
        assert e >= min_e, (fll, e)
    # Test C: "a bit higher harmonic filtering" for both (measured 0.160 vs 0.151 / 0.115 Hz)
    c0 = demo_rows[("C", "SOGI-FLL")]["freq_pp_hz"]
    assert demo_rows[("C", "SOGI-FLL-WPF")]["freq_pp_hz"] < c0
    assert demo_rows[("C", "SOGI-FLL-WIF")]["freq_pp_hz"] < 0.8 * c0


# --------------------------------------------------------------------------
# batching, divergence reporting, gradients
# --------------------------------------------------------------------------


def test_jit_vmap_over_1024_signals():
    rng = np.random.default_rng(0)
    n = 1024
    sigs = jaxobs.stack(
        [
            jaxobs.GridSignal(freq=50.0, phase=float(p), t_event=0.1, freq_step=float(df))
            for p, df in zip(rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n))
        ]
    )
    obs = linear.wif_closed_form()
    run = jax.jit(jax.vmap(lambda s: jaxobs.simulate(jaxobs.OnSignal(obs, s), 0.5).outputs.obs.omega[-1]))
    w_end = np.asarray(run(sigs))
    assert w_end.shape == (n,)
    np.testing.assert_allclose(w_end / (2 * np.pi), 50.0 + np.asarray(sigs.freq_step), atol=1e-3)


def test_vmap_over_gains_reports_divergence_per_scenario():
    """A batch of gains where one design is unstable: the batch finishes, ``ok`` flags the bad one."""
    good = jaxobs.SOGIFLL(k=0.7, lam=12000.0, rule=jaxobs.Euler(), ts=1e-3)
    bad = jaxobs.SOGIFLL(k=40.0, lam=12000.0, rule=jaxobs.Euler(), ts=1e-3)  # k·ω·ts ≫ 2: Euler blows up
    batch = jaxobs.stack([good, bad, good])
    sig = jaxobs.paper001_test("A", t_event=0.1)
    ok = jax.vmap(lambda o: jaxobs.simulate(jaxobs.OnSignal(o, sig), 0.3).ok)(batch)
    assert ok.tolist() == [True, False, True]


def _freq_loss(obs, sig, t1=0.3):
    sol = jaxobs.simulate(jaxobs.OnSignal(obs, sig), t1)
    return jnp.mean((sol.outputs.obs.omega - sol.outputs.truth.omega) ** 2)


@pytest.mark.parametrize("make", [linear.sogi_fll_closed_form, linear.wif_closed_form], ids=["SOGI-FLL", "WIF"])
def test_grad_matches_central_differences(make):
    obs = make()
    sig = jaxobs.paper001_test("A", t_event=0.1)
    names = ["k", "lam"] if hasattr(obs, "k") else ["k1", "k2", "lam"]
    assert_field_grads_match_fd(_freq_loss, obs, names, sig, rel=1e-4)


# --------------------------------------------------------------------------
# validation
# --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "ctor, kwargs, field",
    [
        (jaxobs.SOGIFLL, dict(k=0.0, lam=1.0), "SOGIFLL.k"),
        (jaxobs.SOGIFLL, dict(k=-1.0, lam=1.0), "SOGIFLL.k"),
        (jaxobs.SOGIFLL, dict(k=1.0, lam=0.0), "SOGIFLL.lam"),
        (jaxobs.SOGIFLL, dict(k=1.0, lam=-5.0), "SOGIFLL.lam"),
        (jaxobs.SOGIFLL, dict(k=float("nan"), lam=1.0), "SOGIFLL.k"),
        (jaxobs.SOGIFLL, dict(k=1.0, lam=float("inf")), "SOGIFLL.lam"),
        (jaxobs.SOGIFLL, dict(k=1.0, lam=1.0, ts=0.0), "SOGIFLL.ts"),
        (jaxobs.SOGIFLL, dict(k=1.0, lam=1.0, ts=-1e-4), "SOGIFLL.ts"),
        (jaxobs.SOGIFLLWPF, dict(k1=0.0, k2=1.0, lam=1.0), "SOGIFLLWPF.k1"),
        (jaxobs.SOGIFLLWPF, dict(k1=1.0, k2=-1.0, lam=1.0), "SOGIFLLWPF.k2"),
        (jaxobs.SOGIFLLWPF, dict(k1=1.0, k2=1.0, lam=0.0), "SOGIFLLWPF.lam"),
        (jaxobs.SOGIFLLWIF, dict(k1=1.0, k2=1.0, lam=float("nan")), "SOGIFLLWIF.lam"),
        (jaxobs.SOGIFLLWIF, dict(k1=1.0, k2=0.0, lam=1.0), "SOGIFLLWIF.k2"),
        (jaxobs.SOGIFLLWIF, dict(k1=1.0, k2=1.0, lam=1.0, ts=float("nan")), "SOGIFLLWIF.ts"),
        (jaxobs.SOGIFLLWIF, dict(k1=1.0, k2=1.0, lam=1.0, rule="AB3"), "SOGIFLLWIF.rule"),
        (jaxobs.GridSignal, dict(sag=1.5), "GridSignal.sag"),
        (jaxobs.GridSignal, dict(freq=-50.0), "GridSignal.freq"),
    ],
)
def test_bad_arguments_raise_value_error_naming_the_field(ctor, kwargs, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        ctor(**kwargs)


def test_bad_test_name():
    with pytest.raises(ValueError, match="test name"):
        jaxobs.paper001_test("Z")


def test_gradients_stay_finite_through_the_zero_initial_state():
    """Amplitude √(v'² + qv'²) and phase atan2 are evaluated at the zero initial state; their
    gradients there must not be NaN (see jaxobs/core/numerics.py)."""
    obs = linear.sogi_fll_closed_form()
    sig = jaxobs.paper001_test("B", t_event=0.05)

    def loss(o):
        out = jaxobs.simulate(jaxobs.OnSignal(o, sig), 0.1).outputs
        return jnp.mean((out.obs.amplitude - out.truth.amplitude) ** 2) + jnp.mean(
            metrics.wrap(out.obs.theta - out.truth.theta) ** 2
        )

    g = eqx.filter_jit(eqx.filter_grad(loss))(obs)  # one program (eagerly: forward and backward apart)
    assert np.isfinite(float(g.k)) and np.isfinite(float(g.lam))
    assert float(g.k) != 0.0
