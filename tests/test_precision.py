"""float32 runs: exact signal phases from the sample index, steady metrics within 5 % of float64, one warning.

The suite runs in float64 (conftest.py); the float32 runs here switch x64 off inside ``jax.enable_x64(False)``.
"""

import importlib
import math
import warnings
from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs
from jaxobs import metrics as M
from jaxobs import papers
from jaxobs.core.sampletime import SampleTime, cycles
from jaxobs.signals import EMFSignal, GridSignal


def _frac_ref(rate32, scale, t0, ts, k):
    """frac(rate·scale·(t0 + k·ts)) in exact rational arithmetic, in [−½, ½)."""
    x = Fraction(float(rate32)) * Fraction(scale) * (Fraction(t0) + Fraction(ts) * int(k))
    return float((x + Fraction(1, 2)) % 1 - Fraction(1, 2))


@pytest.mark.parametrize("scale", [1.0, 1 / (2 * math.pi)])
@pytest.mark.parametrize("t0", [0.0, 0.2, 99.6])
def test_cycles_in_float32_are_exact_to_1e_7_at_any_sample_index(scale, t0):
    rates = np.asarray([50.0, 52.123, -1.5, 314.159], np.float32)
    ks = np.asarray([0, 1, 4095, 4096, 995_000, 2**24 + 3, 2**31 - 1])
    with jax.enable_x64(False):
        got = np.asarray(
            cycles(jnp.asarray(rates)[None, :], SampleTime(jnp.asarray(ks[:, None], jnp.int32), 1e-4, t0), scale)
        )
    for i, k in enumerate(ks):
        for j, r in enumerate(rates):
            d = (got[i, j] - _frac_ref(r, scale, t0, 1e-4, k) + 0.5) % 1 - 0.5
            assert abs(d) < 2e-7, (k, r, d)


def test_float32_phase_and_its_gradient_from_a_sample_time():
    """theta(SampleTime) in float32 agrees with float64 modulo 2π at 100 s; the plain float32 time does not."""
    k = np.arange(999_000, 1_000_000, 37)
    kw = dict(freq=50.0, t_event=0.2, freq_step=2.0, phase_jump=0.5, phase=0.3)
    ref = np.asarray(GridSignal(**kw).theta(SampleTime(jnp.asarray(k), 1e-4, 0.0)))  # float64
    with jax.enable_x64(False):
        sig = GridSignal(**kw)
        exact = np.asarray(sig.theta(SampleTime(jnp.asarray(k, jnp.int32), 1e-4, 0.0)))
        plain = np.asarray(sig.theta(jnp.asarray(k * 1e-4, jnp.float32)))
        g = jax.grad(lambda f: GridSignal(freq=f, t_event=0.2).theta(SampleTime(jnp.int32(999_000), 1e-4, 0.0)))(
            jnp.float32(50.0)
        )
    assert exact.dtype == np.float32
    assert np.max(np.abs(M.wrap(exact - ref))) < 2e-6
    assert np.max(np.abs(M.wrap(plain - ref))) > 1e-4  # what it was: the float32 time itself is off
    np.testing.assert_allclose(float(g), 2 * math.pi * 99.9, rtol=1e-6)  # d θ/d f = 2π t


def test_float32_emf_from_a_sample_time_matches_float64():
    # ω1 as float32 holds it: float32(2π·50) differs from 2π·50 by 1e-8 relative, 3e-4 rad after 90 s —
    # a different signal, not a rounding error of the phase
    w1 = float(np.float32(2 * math.pi * 50))
    sig64 = EMFSignal(A1=100.0, omega1=w1, phase=0.2, dc=(1.0, -2.0), harmonics={-5: 8.0, 7: 5.0})
    k = jnp.asarray(np.arange(899_000, 900_000, 101))
    ea64, eb64 = sig64.emf(SampleTime(k, 1e-4, 0.0))
    with jax.enable_x64(False):
        sig = EMFSignal(A1=100.0, omega1=w1, phase=0.2, dc=(1.0, -2.0), harmonics={-5: 8.0, 7: 5.0})
        ea, eb = sig.emf(SampleTime(jnp.asarray(k, jnp.int32), 1e-4, 0.0))
        ang = sig.flux_angle(SampleTime(jnp.asarray(k, jnp.int32), 1e-4, 0.0))
    assert ea.dtype == np.float32
    np.testing.assert_allclose(np.asarray(ea), np.asarray(ea64), atol=1e-3)  # 1e-5 of the amplitude
    np.testing.assert_allclose(np.asarray(eb), np.asarray(eb64), atol=1e-3)
    ang64 = sig64.flux_angle(SampleTime(k, 1e-4, 0.0))
    assert np.max(np.abs(M.wrap(np.asarray(ang, np.float64) - np.asarray(ang64)))) < 2e-6


def test_the_float64_path_is_unchanged_by_sample_times():
    sig = jaxobs.paper001_test("A", t_event=0.1)
    k = jnp.arange(0, 5000, 7)
    t = 1e-4 * k.astype(float)
    st = SampleTime(k, 1e-4, 0.0)
    for f in (sig, sig.theta, sig.omega, sig.fundamental_amplitude):
        np.testing.assert_array_equal(np.asarray(f(st)), np.asarray(f(t)))


def _steady_metrics(H, window=1.0):
    """WIF on the default job's distorted scenario, event at H − 2 s; ripple and rms phase error over the last s."""
    harm = dict(papers.TEST_C_HARMONICS)
    sig = GridSignal(freq=50.0, t_event=H - 2.0, freq_step=2.0, phase_jump=math.radians(40.0), dc=0.05, harmonics=harm)
    obs = jaxobs.SOGIFLLWIF(papers.WIF_K1, papers.WIF_K2, papers.WIF_LAM)
    pre = jaxobs.simulate(jaxobs.OnSignal(obs, sig), H - window, save=jaxobs.SaveFinal())
    sol = jaxobs.simulate(jaxobs.OnSignal(obs, sig, t0=H - window), H, state0=pre.final_state)
    o = sol.outputs
    f_err = np.asarray(o.obs.omega - o.truth.omega, np.float64) / (2 * math.pi)
    perr = np.asarray(M.wrap(o.obs.theta - o.truth.theta), np.float64)
    mask = np.ones(f_err.shape, bool)
    return float(M.peak_to_peak(f_err, mask)), float(M.rms(perr, mask))


def _compare(H):
    ref = _steady_metrics(H)
    with jax.enable_x64(False), warnings.catch_warnings():
        warnings.simplefilter("ignore", jaxobs.PrecisionWarning)
        got = _steady_metrics(H)
    np.testing.assert_allclose(got, ref, rtol=0.05)


def test_float32_steady_metrics_within_5_percent_of_float64_at_20_s():
    _compare(20.0)


@pytest.mark.slow
def test_float32_steady_metrics_within_5_percent_of_float64_at_100_s():
    _compare(100.0)


def test_one_precision_warning_per_process_in_float32(monkeypatch):
    monkeypatch.setattr(importlib.import_module("jaxobs.runtime.simulation"), "_warned_float32", False)
    obs = jaxobs.SOGIFLL(papers.SOGI_FLL_K, papers.SOGI_FLL_LAM)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        jaxobs.simulate(jaxobs.OnSignal(obs, GridSignal()), 0.01)  # x64 on: silent
        with jax.enable_x64(False):
            obs = jaxobs.SOGIFLL(papers.SOGI_FLL_K, papers.SOGI_FLL_LAM)  # float32 leaves
            jaxobs.simulate(jaxobs.OnSignal(obs, GridSignal()), 0.011)
            jaxobs.simulate(jaxobs.OnSignal(obs, GridSignal()), 0.012)  # a new trace, still once
    mine = [w for w in seen if issubclass(w.category, jaxobs.PrecisionWarning)]
    assert len(mine) == 1
    assert "float32" in str(mine[0].message) and "jax_enable_x64" in str(mine[0].message)
