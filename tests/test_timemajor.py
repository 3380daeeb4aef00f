"""Time-major recordings (``SampledSignal(batch_inner=True)``, leaves (n, B)): the loop reads them as scan rows
(jaxobs.runtime._loop, point 6) and computes what the scenario-major batch computes; nothing is transposed or sliced."""

import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs
from benchmarks import workloads as W
from jaxobs.core.discretize import AB3State, ab3_steady_from_start
from jaxobs.runtime.onsignal import OnRows
from jaxobs.runtime.sharding import batch_axes, batch_size

TS = W.TS
N = 600  # samples in each recording


def _recordings(b, n=N):
    """b recordings of a grid voltage, 49-51 Hz and 0.8-1.2 p.u. with a 5th harmonic, and their truth:
    (the scenario-major batch, leaves (b, n); the same samples time-major, leaves (n, b))."""
    t = TS * np.arange(n)[:, None]
    f, a = np.linspace(49.0, 51.0, b), np.linspace(0.8, 1.2, b)
    th = 2 * np.pi * f * t + 0.3
    u = a * np.cos(th) + 0.05 * np.cos(5 * th)
    truth = (th, np.broadcast_to(2 * np.pi * f, (n, b)), np.broadcast_to(a, (n, b)))
    time_major = jaxobs.SampledSignal(u, TS, truth=truth, batch_inner=True)
    by_scenario = jax.vmap(lambda u, th, om, a: jaxobs.SampledSignal(u, TS, truth=(th, om, a)))(
        jnp.asarray(u.T), *(jnp.asarray(np.ascontiguousarray(x.T)) for x in truth)
    )
    return by_scenario, time_major


@pytest.fixture(scope="module")
def recs():
    return _recordings(6)


def _run(obs, t1, save, t0=0.0):
    def one(s):
        return jaxobs.simulate(jaxobs.OnSignal(obs, s, t0=t0), t1, save=save)

    return jax.jit(lambda b: jaxobs.map_batch(one, b))


@pytest.mark.parametrize("kind", ["sogi-fll", "sogi-fll-wif"])
def test_time_major_batch_computes_what_the_scenario_major_batch_computes(kind, recs):
    """Costs, final states and every output agree to rounding (1e-12): the rows loop fills the AB3 start-up
    into a steady history instead of peeling it, which moves the last bits only."""
    by_scenario, time_major = recs
    obs = W.fll_observer(kind)
    for save in (jaxobs.SaveFinal(cost=W.fll_cost), jaxobs.SaveAll(fast=True, cost=W.fll_cost)):
        f = _run(obs, (N - 1) * TS, save)
        a, b = f(by_scenario), f(time_major)
        assert a.cost.shape == b.cost.shape == (6,)
        np.testing.assert_allclose(b.cost, a.cost, rtol=1e-12)
        assert np.ptp(np.asarray(a.cost)) > 1e-3 * np.max(np.abs(a.cost))  # the scenarios differ
        for x, y in zip(jax.tree.leaves((a.final_state, a.outputs)), jax.tree.leaves((b.final_state, b.outputs))):
            np.testing.assert_allclose(y, x, rtol=1e-12, atol=1e-12 * float(np.max(np.abs(x))))
        assert bool(np.all(b.ok))


def test_plain_loop_and_offsets_on_a_time_major_batch(recs):
    """SaveAll() (the plain step, reading samples through sig(t)) gives the rows loop's numbers; a horizon that
    starts 5 samples in and ends before the recording does reads the rows [5, 5 + n) (a static slice)."""
    _, time_major = recs
    obs = W.fll_observer("sogi-fll")
    t0, t1 = 5 * TS, 5 * TS + 401 * TS  # 401 steps: odd, so the rows loop runs without unrolling
    fast = _run(obs, t1, jaxobs.SaveFinal(cost=W.fll_cost), t0=t0)(time_major)
    plain = _run(obs, t1, jaxobs.SaveAll(cost=W.fll_cost), t0=t0)(time_major)
    np.testing.assert_allclose(fast.cost, plain.cost, rtol=1e-12)
    system = jaxobs.OnSignal(obs, jax.tree.map(lambda a: a[:, 0], time_major), t0=t0).throughput()
    assert isinstance(system, OnRows)  # the throughput loop's system: the rows
    u, truth = system.input_rows(401)
    np.testing.assert_array_equal(u, time_major.samples[5:406, 0])
    np.testing.assert_array_equal(truth[1], time_major.truth[1][5:406, 0])
    u7, _, truth7 = system.row_input(jax.tree.map(lambda a: a[7], (u, truth)))
    assert float(u7) == float(time_major.samples[12, 0]) and float(truth7.omega) == float(time_major.truth[1][12, 0])


def test_rows_are_read_where_they_lie():
    """The compiled program of a time-major batch holds no transposed (B, n) copy of the recording and no
    (n - 2, B) slice of it: the loop reads row k of the (n, B) array the caller gave."""
    _, time_major = _recordings(8, 1000)
    obs = W.fll_observer("sogi-fll")
    f = _run(obs, 1000 * TS, jaxobs.SaveFinal(cost=W.fll_cost))
    hlo = f.lower(time_major).compile().as_text()
    shapes = set(re.findall(r"f64\[(\d+),(\d+)\]", hlo))
    assert ("1000", "8") in shapes or ("1000", "4") in shapes  # the rows, whole or a device's share
    assert not {("8", "1000"), ("4", "1000"), ("998", "8"), ("998", "4")} & shapes, sorted(shapes)


def test_gradient_through_a_time_major_batch(recs):
    """d(Σ cost)/d(k, λ) through the rows loop equals the scenario-major batch's (forward sensitivities on
    both) and reverse mode's on the rows loop."""
    by_scenario, time_major = recs
    obs0 = W.fll_observer("sogi-fll")

    def total(gains, batch, checkpoint=jaxobs.AutoCheckpoint()):
        obs = eqx.tree_at(lambda o: (o.k, o.lam), obs0, gains)

        def one(s):
            sol = jaxobs.simulate(
                jaxobs.OnSignal(obs, s), 300 * TS, save=jaxobs.SaveFinal(cost=W.fll_cost), checkpoint=checkpoint
            )
            return sol.cost

        return jnp.sum(jaxobs.map_batch(one, batch))

    gains = (jnp.asarray(obs0.k), jnp.asarray(obs0.lam))
    g_s = jax.jit(jax.grad(total))(gains, by_scenario)
    g_t = jax.jit(jax.grad(total))(gains, time_major)
    g_r = jax.jit(jax.grad(lambda g, b: total(g, b, jaxobs.StepCheckpoint())))(gains, time_major)
    for a, b, c in zip(g_s, g_t, g_r):
        assert abs(float(a)) > 0
        np.testing.assert_allclose(b, a, rtol=1e-9)
        np.testing.assert_allclose(c, a, rtol=1e-9)


def test_filled_history_repeats_the_start_up():
    """ab3_steady_from_start: two steady AB3 steps from x₀ with the filled history land on the start-up's x₁
    and x₂ (to rounding); a carry whose AB3 state is not a component's (x, rule) gets None (its start-up is peeled)."""
    obs = W.fll_observer("sogi-fll-wif")
    u = jnp.cos(2 * jnp.pi * 50.0 * TS * jnp.arange(3.0)) * 1.2
    c0 = obs.init(u[0])
    c1, _ = obs.step(c0, u[0])
    c2, _ = obs.step(c1, u[1])
    steady = ab3_steady_from_start(c0, c1, c2, h=TS)
    assert steady.rule.n is None
    s1, _ = obs.step(steady, u[0])
    s2, _ = obs.step(s1, u[1])
    for got, want in ((s1.x, c1.x), (s2.x, c2.x)):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * float(jnp.max(jnp.abs(want))))
    np.testing.assert_allclose(s2.rule.f1, c2.rule.f1, rtol=1e-12)
    bare = (c0.rule, c0.x)  # an AB3 state outside any component
    assert ab3_steady_from_start(bare, (c1.rule, c1.x), (c2.rule, c2.x), h=TS) is None
    assert isinstance(c2.rule, AB3State)


def test_batch_axes_and_sharding_of_a_time_major_batch(recs):
    _, time_major = recs
    gains = jnp.linspace(1.0, 2.0, 6)
    assert batch_axes((time_major, gains)) == (1, 0)
    assert batch_size((time_major, gains)) == 6
    placed = jaxobs.shard_batch((time_major, gains))
    assert placed[0].samples.shape == (N, 6)
    # the suite's one device (conftest.py): the batch placed whole; its split on its second axis is checked in
    # tests/test_perf.py's process of 4 host devices
    assert placed[0].samples.sharding.device_set == {jax.devices()[0]}
    got = jax.jit(lambda b: jaxobs.map_batch(lambda t: t[0].samples[3] * t[1], b))((time_major, gains))
    np.testing.assert_array_equal(got, time_major.samples[3] * gains)
    with pytest.raises(ValueError, match="common leading axis"):
        batch_size((time_major, jnp.ones(5)))


def test_time_major_signal_rejects_bad_input():
    with pytest.raises(ValueError, match=r"samples of a time-major batch .* \(n, B\)"):
        jaxobs.SampledSignal(np.ones(10), TS, batch_inner=True)
    with pytest.raises(ValueError, match=r"batch_inner must be True or False"):
        jaxobs.SampledSignal(np.ones((10, 2)), TS, batch_inner=1)
    with pytest.raises(ValueError, match=r"truth.amplitude must have the shape of samples"):
        jaxobs.SampledSignal(
            np.ones((10, 2)), TS, batch_inner=True, truth=(np.ones((10, 2)),) * 2 + (np.ones((2, 10)),)
        )
    sig = jaxobs.SampledSignal(np.arange(20.0).reshape(10, 2), TS, batch_inner=True)
    assert sig.n == 10 and sig.t_end == pytest.approx(9 * TS)
    np.testing.assert_array_equal(sig(3 * TS), [6.0, 7.0])  # the batch object read at a sample instant


def test_a_time_major_batch_simulated_whole_or_mapped_along_time_is_refused():
    """simulate runs one scenario: a time-major batch given to it unmapped, or mapped along time by jax.vmap's
    default in_axes=0 (each "recording" then one row, B samples long), is a ValueError naming the remedy."""
    _, time_major = _recordings(3, 200)
    obs = W.fll_observer("sogi-fll")

    def run(s):
        return jaxobs.simulate(jaxobs.OnSignal(obs, s), 100 * TS, save=jaxobs.SaveFinal(cost=W.fll_cost)).cost

    with pytest.raises(ValueError, match=r"OnSignal.signal is a time-major batch of 3 recordings .*batch_axes"):
        run(time_major)
    u = np.asarray(time_major.samples)
    drive_batch = jaxobs.DriveRecording(u, u, u, u, TS, batch_inner=True)
    with pytest.raises(ValueError, match=r"time-major batch of 3 recordings \(DriveRecording"):
        jaxobs.OnSignal(W.fll_observer("sogi-fll"), drive_batch).check_horizon(100)
    with pytest.raises(
        ValueError, match=r"mapped along its time axis \(each scenario sees 3 values of a recording of 200"
    ):
        jax.vmap(run)(time_major)  # B = 3 < the 100 steps: the horizon check would have caught it too
    wide = jaxobs.SampledSignal(np.ones((50, 120)), TS, batch_inner=True)  # B = 120 > 40 steps: only this check
    with pytest.raises(ValueError, match=r"each scenario sees 120 values of a recording of 50 samples.*batch_axes"):
        jax.vmap(lambda s: jaxobs.simulate(jaxobs.OnSignal(obs, s), 40 * TS).ok)(wide)
    with pytest.raises(ValueError, match=r"stack: .*time-major batch"):
        jaxobs.stack([time_major, time_major])
    got = jax.vmap(run, in_axes=(batch_axes(time_major),))(time_major)  # the remedy the messages name
    np.testing.assert_allclose(got, jax.jit(lambda b: jaxobs.map_batch(run, b))(time_major), rtol=1e-12)


def test_time_major_drive_recordings_compute_what_scenario_major_ones_compute():
    """Three drive recordings (the shipped one, its currents scaled by 0.97 and 1.03), as a scenario-major
    batch and as a time-major one (``DriveRecording(batch_inner=True)``, leaves (n, B, 4) and (n, B)): 000's
    second-order SOIFO by RK4 (its default: no start-up to fill) and by AB3 (the filled history on a drive
    observer's state, which carries the previous sample's current beside x) gives the same costs."""
    from pathlib import Path

    from jaxobs import drive as D
    from jaxobs import metrics as M
    from jaxobs import papers

    csv = Path(__file__).resolve().parents[1] / "tuning" / "presets" / "recordings" / "drive_spmsm_1000rpm.csv"
    rec = jaxobs.DriveRecording.from_csv(csv, time_column="t", theta_e="theta_e", omega_e="omega_e")
    m = np.asarray(rec.samples)  # (4, n)
    scale = np.array([0.97, 1.0, 1.03])
    chans = [np.outer(m[c], np.ones(3)) * (scale if c >= 2 else 1.0) for c in range(4)]  # each (n, 3)
    th, om = (np.outer(np.asarray(a), np.ones(3)) for a in (rec.theta_e, rec.omega_e))
    time_major = jaxobs.DriveRecording(*chans, rec.ts, theta_e=th, omega_e=om, batch_inner=True)
    by_scenario = jaxobs.DriveRecording(*(c.T for c in chans), rec.ts, theta_e=th.T, omega_e=om.T)
    assert time_major.samples.shape == (rec.n, 3, 4) and time_major.n == rec.n
    np.testing.assert_array_equal(time_major(5 * rec.ts).i_a, by_scenario(5 * rec.ts).i_a)

    par = D.spmsm_paper000(inertia="motor")
    k1, k2 = papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2

    def cost(o):
        return M.wrap(o.obs.theta - o.truth.theta) ** 2 + 1e-3 * o.truth.amplitude + 1e-6 * o.u.i_b

    for rule in (None, jaxobs.AB3()):
        obs = jaxobs.SecondOrderSOIFO(par.Rs, par.Ld, k1, k2, k1**3 / (2 * k2), 2 * np.pi * 50, rule=rule)
        for save in (jaxobs.SaveFinal(cost=cost), jaxobs.SaveAll(cost=cost)):
            f = jax.jit(
                lambda b, obs=obs, save=save: jaxobs.map_batch(
                    lambda r: jaxobs.simulate(jaxobs.OnSignal(obs, r), 0.2, save=save).cost, b
                )
            )
            a, b = f(by_scenario), f(time_major)
            np.testing.assert_allclose(b, a, rtol=1e-12)
            assert np.ptp(np.asarray(a)) > 1e-4 * np.max(np.abs(a))
