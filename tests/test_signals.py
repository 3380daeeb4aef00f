"""SampledSignal: a recording (or a waveform sampled once) read back inside the loop."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs
from jaxobs.signals import GridSignal, SampledSignal

TS = 1e-4
N = 3000  # 0.3 s: past the event at 0.2 s


def _grid():
    return GridSignal(1.0, 50.0, 0.3, 0.2, freq_step=1.5, phase_jump=0.4, sag=0.2)


def _sampled(sig, n=N, t0=0.0):
    t = t0 + TS * jnp.arange(n, dtype=jnp.float64)
    return SampledSignal(sig(t), TS, t0, truth=(sig.theta(t), sig.omega(t), sig.fundamental_amplitude(t)))


def _obs():
    return jaxobs.SOGIFLL(1.41, 2000.0, ts=TS)


def test_replayed_samples_give_the_simulation_of_the_signal():
    """Read back at the loop's own sample instants the samples come back exactly (the snap), so
    the replay is the signal's simulation: outputs, truth and a running cost."""
    sig, obs = _grid(), _obs()
    save = jaxobs.SaveAll(cost=lambda o: (o.obs.omega - o.truth.omega) ** 2)
    rec = _sampled(sig)
    a = jaxobs.simulate(jaxobs.OnSignal(obs, sig), N * TS, save=save)
    b = jaxobs.simulate(jaxobs.OnSignal(obs, rec), N * TS, save=save)
    np.testing.assert_array_equal(np.asarray(b.outputs.u), np.asarray(rec.samples))
    # the samples were computed outside jit, where XLA fuses cos(θ(t)) differently: ulps apart
    np.testing.assert_allclose(np.asarray(b.outputs.u), np.asarray(a.outputs.u), rtol=0, atol=1e-13)
    np.testing.assert_allclose(np.asarray(b.outputs.obs.omega), np.asarray(a.outputs.obs.omega), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(np.asarray(b.outputs.truth.theta), np.asarray(a.outputs.truth.theta), rtol=1e-12)
    assert float(b.cost) == pytest.approx(float(a.cost), rel=1e-12)
    assert bool(b.ok)


def test_between_samples_reads_linear_interpolation_and_holds_the_ends():
    s = SampledSignal(jnp.asarray([0.0, 2.0, 1.0, 5.0]), 0.5, t0=1.0)
    t = jnp.asarray([0.0, 1.0, 1.25, 1.5, 1.6, 2.0, 2.4, 2.5, 9.0])
    np.testing.assert_allclose(np.asarray(s(t)), [0.0, 0.0, 1.0, 2.0, 1.8, 1.0, 4.2, 5.0, 5.0], rtol=1e-12)
    # a time a rounding error off a sample instant reads the sample itself
    assert float(s(jnp.asarray(1.5 - 1e-12))) == 2.0
    assert s.t_end == 2.5 and s.n == 4


def test_without_truth_the_solution_has_none():
    rec = SampledSignal(jnp.cos(2 * jnp.pi * 50 * TS * jnp.arange(500.0)), TS)
    sol = jaxobs.simulate(jaxobs.OnSignal(_obs(), rec), 0.05)
    assert sol.outputs.truth is None and bool(sol.ok)
    with pytest.raises(ValueError, match="truth"):
        SampledSignal(jnp.zeros(10), TS).omega(0.0)


def test_vmap_over_recordings_and_gradient_through_the_samples():
    sig = _grid()
    rec = _sampled(sig, n=800)
    batch = jax.tree.map(lambda x: jnp.stack([x, 1.1 * x]), rec)  # two recordings, one scaled
    save = jaxobs.SaveFinal(cost=lambda o: (o.obs.omega - o.truth.omega) ** 2)
    f = jax.jit(jax.vmap(lambda s: jaxobs.simulate(jaxobs.OnSignal(_obs(), s), 800 * TS, save=save).cost))
    c = np.asarray(f(batch))
    one = jaxobs.simulate(jaxobs.OnSignal(_obs(), rec), 800 * TS, save=save).cost
    assert c.shape == (2,) and c[0] == pytest.approx(float(one), rel=1e-12) and c[1] != c[0]

    # d cost / d (scale of the recording), by AD and by central differences
    def loss(a):
        r = SampledSignal(a * rec.samples, TS, truth=rec.truth)
        return jaxobs.simulate(jaxobs.OnSignal(_obs(), r), 800 * TS, save=save).cost

    g = float(jax.jit(jax.grad(loss))(1.0))  # one program (eagerly: forward and backward apart)
    h = 1e-6
    fd = (float(loss(1.0 + h)) - float(loss(1.0 - h))) / (2 * h)
    assert np.isfinite(g) and g == pytest.approx(fd, rel=1e-5)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(samples=[1.0], ts=TS), "SampledSignal.samples"),
        (dict(samples=[1.0, float("nan")], ts=TS), "SampledSignal.samples"),
        (dict(samples=[1.0, 2.0], ts=0.0), "SampledSignal.ts"),
        (dict(samples=[1.0, 2.0], ts=TS, t0=float("inf")), "SampledSignal.t0"),
        (dict(samples=[1.0, 2.0], ts=TS, truth=([0.0, 1.0], [1.0, 1.0])), "SampledSignal.truth"),
        (dict(samples=[1.0, 2.0], ts=TS, truth=([0.0, 1.0], [1.0, 1.0], [1.0])), "SampledSignal.truth.amplitude"),
    ],
)
def test_bad_arguments_raise_value_error_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        SampledSignal(**kwargs)


def test_a_horizon_past_the_recording_is_an_error():
    rec = SampledSignal(jnp.zeros(100), TS, t0=0.0)
    jaxobs.simulate(jaxobs.OnSignal(_obs(), rec), 100 * TS)  # exactly the recording: fine
    with pytest.raises(ValueError, match="horizon"):
        jaxobs.simulate(jaxobs.OnSignal(_obs(), rec), 101 * TS)
    with pytest.raises(ValueError, match="horizon"):
        jaxobs.simulate(jaxobs.OnSignal(_obs(), SampledSignal(jnp.zeros(100), TS, t0=0.01)), 0.005)


def test_a_recording_read_on_and_off_its_sample_instants():
    """From t0 = 0.05 s the loop's instants are samples 500, 501, … (read exactly); from
    t0 = 0.05 + ts/2 they fall between samples (read by interpolation) — both give the signal."""
    sig, obs = _grid(), _obs()
    rec = _sampled(sig)
    save = jaxobs.SaveFinal(cost=lambda o: (o.obs.omega - o.truth.omega) ** 2)
    a = jaxobs.simulate(jaxobs.OnSignal(obs, rec, t0=0.05), 0.25, save=save)
    b = jaxobs.simulate(jaxobs.OnSignal(obs, sig, t0=0.05), 0.25, save=save)
    assert float(a.cost) == pytest.approx(float(b.cost), rel=1e-10)
    c = jaxobs.simulate(jaxobs.OnSignal(obs, rec, t0=0.05 + TS / 2), 0.25, save=save)
    d = jaxobs.simulate(jaxobs.OnSignal(obs, sig, t0=0.05 + TS / 2), 0.25, save=save)
    # linear interpolation of a 50 Hz cosine sampled at 10 kHz: |error| <= (ωts)²/8 ≈ 1.2e-4 of the
    # amplitude, which moves the cost by about as much (measured 1.4e-4 relative)
    assert float(c.cost) == pytest.approx(float(d.cost), rel=1e-3)
    assert float(c.cost) != pytest.approx(float(d.cost), rel=1e-6)  # it did interpolate
    np.testing.assert_allclose(
        np.asarray(rec(0.05 + TS / 2 + TS * jnp.arange(100))),
        np.asarray(sig(0.05 + TS / 2 + TS * jnp.arange(100))),
        atol=1.3e-4,
    )


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(ts=0.0), "EMFSignal.ts"),
        (dict(ts=-1e-4), "EMFSignal.ts"),
        (dict(ts=float("nan")), "EMFSignal.ts"),
        (dict(A1=float("nan")), "EMFSignal.A1"),
        (dict(omega1=0.0), "EMFSignal.omega1"),
        (dict(dc=(float("nan"), 0.0)), "EMFSignal.dc"),
        (dict(dc=(1.0, 2.0, 3.0)), "EMFSignal.dc"),
        (dict(harmonics={0: 1.0}), "EMFSignal.harmonics"),
        (dict(harmonics={5: float("inf")}), "EMFSignal.harmonics"),
    ],
)
def test_emf_signal_bad_arguments_name_the_field(kwargs, field):
    from jaxobs.signals import EMFSignal

    args = dict(A1=100.0, omega1=314.0) | kwargs
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        EMFSignal(**args)


def test_on_signal_rejects_an_emf_with_another_sample_time():
    from jaxobs.signals import EMFSignal

    obs = jaxobs.PureIntegratorFlux(0.0, 1.0, 100.0, 2500.0, ts=1e-4)
    with pytest.raises(ValueError, match=r"EMFSignal\.ts = 5e-05 s.*PureIntegratorFlux\.ts = 0\.0001 s"):
        jaxobs.OnSignal(obs, EMFSignal(A1=100.0, omega1=314.0, ts=5e-5))
    jaxobs.OnSignal(obs, EMFSignal(A1=100.0, omega1=314.0, ts=1e-4))  # the same: fine


def test_grid_signal_vmaps_over_freq_step_and_still_refuses_a_concrete_bad_one():
    """The constructor's freq + freq_step > 0 check runs on concrete values only: a vmap over
    ``freq_step`` (a sweep of frequency steps) builds the signal with a tracer and must not raise
    JAX's ConcretizationTypeError; a concrete step that stops the grid still gets the ValueError."""
    steps = jnp.array([-2.0, 0.0, 3.0])
    f = jax.vmap(lambda s: GridSignal(1.0, 50.0, 0.0, 0.01, freq_step=s).omega(jnp.float64(0.02)))
    np.testing.assert_allclose(np.asarray(f(steps)), 2 * np.pi * (50.0 + np.asarray(steps)), rtol=1e-12)
    with pytest.raises(ValueError, match="freq_step must keep the frequency > 0 Hz"):
        GridSignal(1.0, 50.0, 0.0, 0.01, freq_step=-60.0)


def test_grid_signal_harmonics_in_float64_are_as_accurate_as_the_cosines_they_replace():
    """The float64 cos(h·θ) by the Chebyshev recurrence from one cosine (GridSignal._cos_orders): against an
    extended-precision reference, over 2·10⁵ angles up to 10³ rad and every multiple of π/2 up to 10³, within
    2e-14 absolute up to h = 13 (the error grows with h: measured 1.1e-14 at 13), where ``cos(h*th)`` itself
    was off by up to 3.6e-12 (the product h·θ rounded).  And the Test C signal agrees with the one written
    with ``jnp.cos`` of each multiple to that rounding."""
    rng = np.random.default_rng(0)
    th = np.concatenate([rng.uniform(-1e3, 1e3, 200_000), np.arange(-640, 640) * np.pi / 2])
    orders = (3, 5, 7, 9, 11, 13)
    got = jax.jit(lambda x: GridSignal._cos_orders(x, orders))(jnp.asarray(th))
    assert sorted(got) == [1, *orders]
    for h in (1, *orders):
        ref = np.cos(np.longdouble(h) * th.astype(np.longdouble))
        err = float(np.max(np.abs(np.asarray(got[h]).astype(np.longdouble) - ref)))
        assert err < (2e-16 if h == 1 else 2e-14), (h, err)
    sig = jaxobs.signals.paper001_test("C", t_event=0.05)
    t = TS * jnp.arange(N, dtype=jnp.float64)
    th_t, on = sig.theta(t), sig._on(t)
    plain = sig.fundamental_amplitude(t) * jnp.cos(th_t) + on * sum(
        sig.harmonics[i] * jnp.cos(h * th_t) for i, h in enumerate(sig.orders)
    )
    plain = plain + on * (sig.dc + sig.sub_amplitude * jnp.cos(2 * jnp.pi * sig.sub_freq * t))
    np.testing.assert_allclose(np.asarray(sig(t)), np.asarray(plain), rtol=0, atol=1e-13)
