"""Metrics: exact values on known signals, and smooth surrogates converging to the exact ones."""

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxobs import metrics as M
from jaxobs import papers

T = jnp.linspace(0.0, 1.0, 10001)


def _response(t, t_event=0.2, tau=0.05):
    return jnp.where(t >= t_event, 1 - jnp.exp(-(t - t_event) / tau) * jnp.cos(40 * (t - t_event)), 0.0)


def test_settling_time_exact_and_smooth_converges():
    x = _response(T)
    exact = float(M.settling_time(T, x, 1.0, 0.02, 0.2))
    dt = float(T[1] - T[0])
    # exact: the envelope e^{-t/τ} falls below 2 % at τ ln 50 = 0.1956 s (the cosine makes it a little earlier)
    assert 0.17 < exact <= 0.1957
    errs = []
    for temp in (1e-2, 1e-3, 1e-4, 1e-5):
        smooth = float(M.smooth_settling_time(T, x, 1.0, 0.02, 0.2, temperature=temp, sharpness=0.02 * temp))
        errs.append(abs(smooth - (exact - dt)))
    assert errs[-1] < 2 * dt
    assert errs[0] > errs[-1]
    # and it has a gradient w.r.t. a parameter of the response
    g = jax.grad(lambda tau: M.smooth_settling_time(T, _response(T, tau=tau), 1.0, 0.02, 0.2))(0.05)
    assert np.isfinite(float(g)) and float(g) > 0


def test_smooth_max_and_peak_to_peak_converge():
    x = jnp.sin(2 * math.pi * 5 * T) + 0.3
    mask = T > 0.5
    exact_pp = float(M.peak_to_peak(x, mask))
    assert exact_pp == pytest.approx(2.0, abs=1e-6)
    errs = [abs(float(M.smooth_peak_to_peak(x, mask, temp)) - exact_pp) for temp in (0.1, 0.01, 0.001)]
    assert errs[0] > errs[1] > errs[2] and errs[2] < 0.02
    assert float(M.smooth_abs(jnp.asarray(-0.3), 1e-8)) == pytest.approx(0.3)


def test_overshoot_iae_itae():
    x = _response(T)
    os_ = float(M.overshoot(x, 1.0, 0.0, T >= 0.2))
    # by hand: x − 1 = −e^(−u/τ) cos(40u) peaks where tan(40u) = −1/(40τ), at 40u = π − atan(1/2), where it is
    # e^(−u/τ) · 2/√5 = 0.2344426; the 0.1 ms grid misses the peak by at most ½|x''|(dt/2)² < 1e-6
    u = (math.pi - math.atan(0.5)) / 40
    assert os_ == pytest.approx(math.exp(-u / 0.05) * 2 / math.sqrt(5), abs=1e-6)
    e = jnp.where(T >= 0.2, jnp.exp(-(T - 0.2) / 0.05), 0.0)
    assert float(M.iae(T, e, 0.2)) == pytest.approx(0.05 * (1 - math.exp(-16)), rel=2e-3)
    assert float(M.itae(T, e, 0.2)) == pytest.approx(0.05**2, rel=2e-3)


def test_harmonic_amplitude_dc_offset_and_imbalance():
    w = 2 * math.pi * 50
    mask = (T >= 0.5) & (T < 1.0)  # exactly 25 whole periods (5000 samples)
    x = 0.1 + 0.35 * jnp.cos(w * T + 0.3) + 0.02 * jnp.sin(5 * w * T)
    assert float(M.harmonic_amplitude(T, x, w, mask)) == pytest.approx(0.35, rel=1e-6)
    assert float(M.harmonic_amplitude(T, x, 5 * w, mask)) == pytest.approx(0.02, rel=1e-5)
    assert float(M.harmonic_amplitude(T, x, 0.0, mask)) == pytest.approx(0.1, rel=1e-6)
    pa, pb = 0.05 + 0.35 * jnp.cos(w * T), 0.30 * jnp.sin(w * T)
    assert float(M.flux_offset(pa, pb, mask)) == pytest.approx(0.05, rel=1e-6)
    assert float(M.flux_imbalance(pa, pb, mask)) == pytest.approx(0.05, abs=1e-4)


def test_wrap_and_moving_average():
    assert float(M.wrap(jnp.asarray(3 * math.pi / 2))) == pytest.approx(-math.pi / 2)
    assert float(M.wrap(jnp.asarray(math.pi))) == pytest.approx(math.pi)
    ma = np.asarray(M.moving_average(jnp.arange(10.0), 3))
    np.testing.assert_allclose(ma, [0, 0.5, 1, 2, 3, 4, 5, 6, 7, 8])
    with pytest.raises(ValueError, match="window"):
        M.moving_average(jnp.arange(3.0), 0)


# --------------------------------------------------------------------------
# empty windows, bad bands, censored settling times, lost lock
# --------------------------------------------------------------------------


def test_an_empty_concrete_window_raises_and_a_traced_one_gives_nan():
    x = jnp.arange(10.0)
    empty = jnp.zeros(10, bool)
    for f in (M.peak_to_peak, M.steady_mean, M.rms):
        with pytest.raises(ValueError, match="no samples"):
            f(x, empty)
        assert np.isnan(float(jax.jit(f)(x, empty)))
    t = jnp.linspace(0.0, 0.9, 10)
    for f in (M.iae, M.itae):
        with pytest.raises(ValueError, match="t_event"):
            f(t, x, 5.0)
        assert np.isnan(float(jax.jit(f)(t, x, 5.0)))


def test_settling_time_rejects_a_bad_band_or_final():
    t = jnp.linspace(0.0, 1.0, 101)
    x = 1.0 - jnp.exp(-t / 0.1)
    for band in (float("nan"), -0.1, float("inf")):
        with pytest.raises(ValueError, match="band"):
            M.settling_time(t, x, 1.0, band)
        with pytest.raises(ValueError, match="band"):
            M.smooth_settling_time(t, x, 1.0, band)
        assert np.isnan(float(jax.jit(M.settling_time)(t, x, 1.0, band)))
    with pytest.raises(ValueError, match="final"):
        M.settling_time(t, x, float("nan"), 0.05)


def test_settled_marks_censored_settling_times():
    t = jnp.linspace(0.0, 1.0, 1001)
    x = 1.0 - jnp.exp(-t / 0.1)
    assert bool(M.settled(t, x, 1.0, 0.05))  # settles at 0.3 s
    assert not bool(M.settled(t, x, 1.0, 0.05, min_hold=0.8))  # but not held for 0.8 s
    ramp = t  # never within 0.05 of 2
    assert not bool(M.settled(t, ramp, 2.0, 0.05))
    assert float(M.settling_time(t, ramp, 2.0, 0.05)) == pytest.approx(1.0)  # capped at the horizon
    assert bool(jax.jit(M.settled)(t, x, 1.0, 0.05))


def test_lost_lock():
    t = jnp.linspace(0.0, 1.0, 1001)
    theta = 2 * jnp.pi * 50 * t
    w = M.window_mask(t, 0.9)
    assert not bool(M.lost_lock(theta + 0.05 * jnp.sin(t * 300), theta, w))  # locked, with ripple
    slipping = theta + 2 * jnp.pi * 10.0 * t  # 10 Hz off: slips through every angle in the window
    assert bool(M.lost_lock(slipping, theta, w))
    assert bool(M.lost_lock(theta.at[-1].set(jnp.nan), theta, w))  # a NaN estimate is not locked
    assert bool(M.lost_lock(theta + 0.5, theta, w, tol_rad=0.4))
    with pytest.raises(ValueError, match="no samples"):
        M.lost_lock(theta, theta, jnp.zeros_like(w))
    batch = jnp.stack([theta, slipping])
    np.testing.assert_array_equal(np.asarray(jax.jit(M.lost_lock)(batch, theta, w)), [False, True])


def test_lost_speed():
    """A drive that misses its speed reference: a reversal (the standstill start that ran backwards), 25 %
    off, a NaN; not a locked drive with ±5 % ripple, nor a small error at a near-zero reference (the floor)."""
    t = jnp.linspace(0.0, 1.0, 1001)
    w = M.window_mask(t, 0.7)
    ref = jnp.full_like(t, 1000 * jnp.pi / 30)
    assert not bool(M.lost_speed(ref * (1 + 0.05 * jnp.sin(2 * jnp.pi * 11 * t)), ref, w))
    assert bool(M.lost_speed(-0.4 * ref, ref, w))  # −400 r/min against +1000
    assert bool(M.lost_speed(0.75 * ref, ref, w)) and not bool(M.lost_speed(0.85 * ref, ref, w))
    assert bool(M.lost_speed(ref.at[-1].set(jnp.nan), ref, w))
    small = jnp.full_like(t, 5 * jnp.pi / 30)  # 5 r/min reference, 15 r/min off: under the 20 r/min floor
    assert not bool(M.lost_speed(small + 15 * jnp.pi / 30, small, w))
    assert bool(M.lost_speed(small + 30 * jnp.pi / 30, small, w))
    with pytest.raises(ValueError, match="no samples"):
        M.lost_speed(ref, ref, jnp.zeros_like(w))
    np.testing.assert_array_equal(np.asarray(jax.jit(M.lost_speed)(jnp.stack([ref, -ref]), ref, w)), [False, True])


def test_lost_lock_frequency_test_catches_a_wrong_frequency_beside_a_bounded_angle():
    """On a signal θ̂ comes from filters, so a wrong ω̂ can sit beside a bounded angle error: the mean
    frequency error (> LOCK_FREQ_TOL of the true one) flags it; a locked ripple does not."""
    t = jnp.linspace(0.0, 1.0, 1001)
    theta = 2 * jnp.pi * 50 * t
    w = M.window_mask(t, 0.9)
    omega = jnp.full_like(t, 2 * jnp.pi * 50)
    kw = dict(omega=omega, freq_tol=M.LOCK_FREQ_TOL)
    ripple = omega * (1 + 0.3 * jnp.sin(2 * jnp.pi * 100 * t))  # 30 % ripple, mean right: locked
    assert not bool(M.lost_lock(theta + 0.1, theta, w, omega_hat=ripple, **kw))
    assert bool(M.lost_lock(theta + 0.1, theta, w, omega_hat=0.85 * omega, **kw))  # 15 % low: lost
    assert not bool(M.lost_lock(theta + 0.1, theta, w, omega_hat=0.95 * omega, **kw))
    assert bool(M.lost_lock(theta, theta, w, omega_hat=omega.at[-1].set(jnp.nan), **kw))
    with pytest.raises(ValueError, match="omega_hat"):
        M.lost_lock(theta, theta, w, freq_tol=0.1)


def test_lost_lock_of_a_simulation_under_jit():
    """jaxobs.lost_lock_of(sol): the closed-form SOGI-FLL keeps lock after a 2 Hz step; k = 20, λ = 1e4 (which
    the constructor would refuse, set under jit) settles at 115 rad/s against the true 326.7 with ok = True:
    lost lock.  A flux observer on an EMFSignal is checked against the signal's flux angle."""
    import equinox as eqx

    import jaxobs
    from jaxobs import linear

    sig = jaxobs.GridSignal(t_event=0.1, freq_step=2.0)
    good = linear.sogi_fll_closed_form()

    @jax.jit
    def run(k, lam):
        sol = jaxobs.simulate(jaxobs.OnSignal(eqx.tree_at(lambda o: (o.k, o.lam), good, (k, lam)), sig), 0.4)
        return jaxobs.lost_lock_of(sol), jaxobs.lost_lock_of(sol, 0.3, freq_tol=None), sol.ok

    assert [bool(x) for x in run(good.k, good.lam)] == [False, False, True]
    # arrays of the gains' own dtype and weak type: Python floats (weakly typed) would compile run again
    lost, lost_angle, ok = run(jnp.full_like(good.k, 20.0), jnp.full_like(good.lam, 1e4))
    assert bool(ok) and bool(lost) and bool(lost_angle)  # finite, "ok", and far from the truth
    # a flux observer on a back EMF (no truth in the outputs): the signal's flux angle is the truth
    emf = jaxobs.signals.EMFSignal(A1=100.0, omega1=2 * math.pi * 50)
    obs = jaxobs.SOIFO(Rs=0.0, L=1.0, k=papers.SOIFO_K, lam=0.5, omega0=2 * math.pi * 50)
    sol = jaxobs.simulate(jaxobs.OnSignal(obs, emf), 0.3)
    assert not bool(jaxobs.lost_lock_of(sol, signal=emf))
    assert bool(jaxobs.lost_lock_of(sol, signal=jaxobs.signals.EMFSignal(A1=100.0, omega1=2 * math.pi * 40)))
    with pytest.raises(ValueError, match="EMFSignal"):
        jaxobs.lost_lock_of(sol)
    with pytest.raises(ValueError, match="SaveAll"):
        jaxobs.lost_lock_of(jaxobs.simulate(jaxobs.OnSignal(obs, emf), 0.01, save=jaxobs.SaveFinal()))
    # position_error: the same truths, one function (the objective's and the report's position error)
    err = M.position_error(sol, emf)
    assert float(jnp.max(jnp.abs(err - M.wrap(sol.outputs.obs.theta - emf.flux_angle(sol.t))))) == 0.0
    with pytest.raises(ValueError, match="EMFSignal"):
        M.position_error(sol)
    grid = jaxobs.simulate(jaxobs.OnSignal(good, sig), 0.05)
    want = M.wrap(grid.outputs.obs.theta - grid.outputs.truth.theta)
    assert float(jnp.max(jnp.abs(M.position_error(grid) - want))) == 0.0


# --------------------------------------------------------------------------
# drive metrics: settling to the own final value, speed against its reference, load-step dip
# --------------------------------------------------------------------------


def test_settling_to_steady_settles_a_biased_signal_and_reports_the_bias_apart():
    """A position error that decays from 0.5 rad onto a steady lag of −0.3 rad: e(t) = −0.3 + 0.5 e^{−(t−0.2)/τ}
    after the event at 0.2 s.  It enters the ±0.02 band around −0.3 when 0.5 e^{−s/τ} = 0.02, s = τ ln 25 = 0.1609 s;
    settling to 0 (the old settling_position) never happens: censored at the horizon, 0.8 s."""
    tau = 0.05
    e = jnp.where(T >= 0.2, -0.3 + 0.5 * jnp.exp(-(T - 0.2) / tau), 0.2)
    steady = T >= 0.8
    exact = float(M.settling_to_steady(T, e, 0.02, steady, 0.2))
    dt = float(T[1] - T[0])
    assert exact == pytest.approx(tau * math.log(25), abs=dt)
    # the bias, its own metric: −0.3 plus the tail's mean over [0.8, 1], 0.5 τ/0.2 (e^{−12} − e^{−16}) = 7.7e-7
    bias = -0.3 + 0.5 * tau / 0.2 * (math.exp(-12) - math.exp(-16))
    assert float(M.steady_mean(e, steady)) == pytest.approx(bias, abs=1e-8)
    assert float(M.settling_time(T, e, 0.0, 0.02, 0.2)) == pytest.approx(0.8)  # the ill-posed one: censored
    # the smooth surrogate converges to the exact one (minus one sample, as smooth_settling_time)
    errs = []
    for temp in (1e-2, 1e-3, 1e-4, 1e-5):
        sm = M.smooth_settling_to_steady(T, e, 0.02, steady, 0.2, temperature=temp, sharpness=0.02 * temp)
        errs.append(abs(float(sm) - (exact - dt)))
    assert errs[-1] < 2 * dt and errs[0] > errs[-1]
    # a gradient with respect to the decay's time constant: slower decay, later settling; the exact one's is
    # d(τ ln 25)/dτ = ln 25 = 3.22, the surrogate's at its default sharpness (band/20) a little less: the
    # sigmoid counts a sample as outside from a little inside the band (measured 2.99)
    g = jax.grad(lambda tau: M.smooth_settling_to_steady(T, -0.3 + 0.5 * jnp.exp(-(T - 0.2) / tau), 0.02, steady, 0.2))(
        0.05
    )
    assert 0.9 * math.log(25) < float(g) < math.log(25)
    # a window with no sample raises (concrete), NaN under jit; a non-finite signal gives NaN
    with pytest.raises(ValueError, match="settling_to_steady"):
        M.settling_to_steady(T, e, 0.02, T > 2.0)
    assert np.isnan(float(jax.jit(M.settling_to_steady)(T, e, 0.02, T > 2.0)))
    assert np.isnan(float(M.settling_to_steady(T, e.at[-1].set(jnp.nan), 0.02, steady)))


def _dip(t, t_event, depth, tau):
    """A speed dip after a load step: depth·s·e^{1 − s}, s = (t − t_event)/τ, peaking at ``depth`` when s = 1."""
    s = jnp.maximum(t - t_event, 0.0) / tau
    return depth * s * jnp.exp(1.0 - s)


def test_peak_deviation_and_recovery_after_a_load_step():
    """The true speed against a ramping reference, ω = ω* − dip: the dip of 30 r/min peaks τ = 20 ms after the step
    (a sample), and the speed is back within ±1 r/min for good when s e^{1−s} = 1/30, s > 1 (solved by bisection)."""
    t_event, depth, tau = 0.3, 30.0, 0.02
    ref = 600.0 + 50.0 * T  # r/min: the reference itself moves, the metric follows it
    w = ref - _dip(T, t_event, depth, tau)
    lo, hi = 1.0, 20.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mid * math.exp(1 - mid) > 1 / depth else (lo, mid)
    dt = float(T[1] - T[0])
    assert float(M.peak_deviation(T, w, ref, t_event)) == pytest.approx(depth, rel=1e-12)
    rec = float(M.settling_to_reference(T, w, ref, 1.0, t_event))
    assert rec == pytest.approx(lo * tau, abs=dt)
    # before the event nothing counts: a larger deviation at t < t_event does not change them
    w2 = w - jnp.where(T < 0.1, 100.0, 0.0)
    assert float(M.peak_deviation(T, w2, ref, t_event)) == pytest.approx(depth, rel=1e-12)
    assert float(M.settling_to_reference(T, w2, ref, 1.0, t_event)) == rec
    # smooth versions converge; gradients exist
    n_after = int(jnp.sum(T >= t_event))
    for temp in (1.0, 1e-1, 1e-2, 1e-3):
        sm = float(M.smooth_peak_deviation(T, w, ref, t_event, temperature=temp))
        assert depth - temp * (1 + math.log(n_after)) <= sm <= depth + 1e-12
    assert abs(float(M.smooth_peak_deviation(T, w, ref, t_event, 1e-4)) - depth) < 1e-2
    sm = float(M.smooth_settling_to_reference(T, w, ref, 1.0, t_event, temperature=1e-5, sharpness=1e-5))
    assert abs(sm - (rec - dt)) < 2 * dt
    g = jax.grad(lambda d: M.smooth_peak_deviation(T, ref - _dip(T, t_event, d, tau), ref, t_event))(depth)
    assert float(g) == pytest.approx(1.0, rel=1e-3)
    # the event after the record raises
    with pytest.raises(ValueError, match="t_event"):
        M.peak_deviation(T, w, ref, 2.0)


# --------------------------------------------------------------------------
# the one metric table (jaxobs.metrics.METRICS): SI units, kinds, old names, display units, the families' defaults
# --------------------------------------------------------------------------

SI_UNITS = {"s", "Hz", "Hz s", "Hz s2", "rad", "rad s", "rad s2", "rad s-1", "s-1", "1"}


def test_the_metric_table_holds_one_si_entry_per_quantity_and_flags_are_boolean_metrics():
    assert len(M.METRICS) == len({m.long_name for m in M.METRICS.values()})  # no quantity twice under two names
    for name, m in M.METRICS.items():
        assert m.name == name and m.units in SI_UNITS, (name, m.units)
        assert m.kind in ("run", "flag", "system")
        if m.kind == "flag":
            assert m.units == "1" and m.display is None, name
        if m.kind == "run":
            assert m.exact is not None or m.smooth is not None, name
    assert M.METRICS["stability_margin"].kind == "system" and M.METRICS["stability_margin"].exact is None
    assert {k for k, m in M.METRICS.items() if m.kind == "flag"} == {
        "diverged",
        "settled",
        "lost_lock",
        "lost_speed",
        "lost_sync",
    }
    assert M.DIVERGED is M.METRICS["diverged"]
    with pytest.raises(ValueError, match="stability_margin is not a function of one run"):
        M.METRICS["stability_margin"](None, None, M.MetricContext())
    with pytest.raises(ValueError, match="kind must be"):
        M.Metric("x", "1", "x", kind="bool")
    with pytest.raises(ValueError, match="no display transform"):
        M.Metric("x", "s", "x", display="degree")


def test_display_units_are_a_presentation_transform():
    pos, spd = M.METRICS["rms_position_steady"], M.METRICS["peak_speed_deviation"]
    assert pos.units == "rad" and pos.display_units == "degree" and pos.shown(math.pi) == pytest.approx(180.0)
    assert spd.units == "rad s-1" and spd.display_units == "min-1" and spd.shown(math.pi / 30) == pytest.approx(1.0)
    itae = M.METRICS["itae_freq"]
    assert itae.display_units == itae.units and itae.shown(2.5) == 2.5


def test_old_names_are_read_with_one_line_of_warning_and_their_unit_conversion():
    for old, alias in M.ALIASES.items():
        assert old not in M.METRICS and alias.new in M.METRICS  # an old name is never an entry
        with pytest.warns(M.MetricNameWarning, match=rf"^here: '{old}' is an old metric name, read as '{alias.new}'"):
            assert M.canonical(old, "here") == (alias.new, alias.scale)
    assert issubclass(M.MetricNameWarning, DeprecationWarning)
    assert M.ALIASES["pos_err_rms_deg"].scale == pytest.approx(math.pi / 180)  # deg -> rad
    assert M.ALIASES["speed_noise_rpm"].scale == pytest.approx(math.pi / 30)  # r/min -> rad/s
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert M.canonical("itae_freq") == ("itae_freq", 1.0)  # a name of the table: no warning


def test_each_family_declares_its_default_metrics_and_flags():
    from jaxobs.scenarios.families import DriveScenarios, EMFSignals, GridSignals, RecordedSignals
    from jaxobs.studies.drive import DRIVE_STUDY_METRICS
    from jaxobs.studies.study import STUDY_METRICS

    for fam in (GridSignals, EMFSignals, DriveScenarios, RecordedSignals):
        assert fam.metrics and all(M.METRICS[k].kind == "run" and M.METRICS[k].exact is not None for k in fam.metrics)
        assert "diverged" in fam.flags and all(M.METRICS[k].kind == "flag" for k in fam.flags)
        assert fam.closed_loop or not any(M.METRICS[k].closed_loop for k in (*fam.metrics, *fam.flags))
    assert STUDY_METRICS == GridSignals.metrics and DRIVE_STUDY_METRICS == DriveScenarios.metrics


def test_a_term_of_an_old_name_is_the_same_term_in_si():
    from jaxobs_tuning.objective import TERM_METRICS, Term

    assert "lost_lock" not in TERM_METRICS and "stability_margin" in TERM_METRICS  # a run or system metric
    with pytest.warns(M.MetricNameWarning, match="speed_noise_rpm"):
        t = Term("speed_noise_rpm", 0.01)
    assert t.metric == "speed_noise" and t.measure is M.METRICS["speed_noise"]
    assert t.weight == pytest.approx(0.01 * 30 / math.pi, rel=1e-15)  # per rad/s: the same term


def test_a_job_file_reads_an_old_metric_name_and_never_writes_it(tmp_path, capsys):
    import tomllib

    from jaxobs_tuning.cli import main
    from jaxobs_tuning.job import parse_job
    from tests.test_tuning import GOOD

    old = GOOD.replace('metric = "itae_freq", weight = 1.0', 'metric = "rms_phase", weight = 2.0')
    assert "rms_phase" in old
    with pytest.warns(M.MetricNameWarning, match=r"^objective.terms\[0\].metric: 'rms_phase' is an old metric name"):
        job = parse_job(tomllib.loads(old))
    assert [(t.metric, t.weight) for t in job.terms] == [("rms_phase_steady", 2.0)]
    assert job.raw["objective"]["terms"] == [{"metric": "rms_phase_steady", "weight": 2.0}]  # what result.json holds
    # the command line: the warning as its own one line, the job refused or run on the new name
    path = tmp_path / "job.toml"
    path.write_text(old.replace("steps = 3", "steps = 1"))
    assert main(["tune", str(path), "--out", str(tmp_path / "o"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "jaxobs: warning: objective.terms[0].metric: 'rms_phase' is an old metric name" in err
    text = (tmp_path / "o" / "result.json").read_text()
    assert '"rms_phase_steady"' in text and '"rms_phase"' not in text and "rms_phase_mean" not in text
