"""The fast loop (jaxobs.runtime._loop) changes no number; checkpointing and sharding give the same results.

Also: long-horizon gradients stay within their memory budget, forward
sensitivities equal reverse mode, the noise-free sensor path and the vectorized
profiles equal what they replace.
"""

import os
import re
import subprocess
import sys
import textwrap

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs
from benchmarks import workloads as B
from jaxobs import drive as D
from jaxobs.runtime._loop import run_loop

T1 = 0.05


@pytest.fixture(scope="module")
def wif_batch():
    return B.grid_signal_batch(B.fll_scenarios(4), jnp.float64)


def _plain_costs(obs, sig, t1):
    """Reference: the plain trajectory (SaveAll: the system's step scanned plainly), cost summed afterwards."""

    def one(s):
        sol = jaxobs.simulate(jaxobs.OnSignal(obs, s), t1, checkpoint=jaxobs.NoCheckpoint())
        return obs.ts * jnp.sum((sol.outputs.obs.omega - sol.outputs.truth.omega) ** 2), sol.final_state

    return jax.jit(jax.vmap(one))(sig)


@pytest.mark.parametrize("kind", B.FLL_KINDS)
def test_streaming_cost_modes_equal_the_plain_trajectory(kind, wif_batch):
    """The fast SaveFinal loop (blocked inputs, peeled AB3 start-up, split state, unrolled) under every
    checkpoint strategy: the plain trajectory's cost and final state to rounding (1e-12)."""
    obs = B.fll_observer(kind)
    ref_cost, ref_state = _plain_costs(obs, wif_batch, T1)
    for ck in ("auto", "chunk", "step", "none"):

        def one(s, ck=ck):
            save = jaxobs.SaveFinal(cost=B.fll_cost)
            return jaxobs.simulate(jaxobs.OnSignal(obs, s), T1, save=save, checkpoint=B.CHECKPOINTS[ck])

        sol = jax.jit(jax.vmap(one))(wif_batch)
        np.testing.assert_allclose(sol.cost, ref_cost, rtol=1e-12)
        assert jax.tree.structure(sol.final_state) == jax.tree.structure(ref_state)  # the rule state's own form
        for a, b in zip(jax.tree.leaves(sol.final_state), jax.tree.leaves(ref_state)):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
        assert sol.outputs is None and bool(jnp.all(sol.ok))


def test_save_all_fast_keeps_every_output_of_the_plain_trajectory(wif_batch):
    """SaveAll(fast=True) (the tuning objective's trajectories): the fast loop with every step's outputs gives
    the plain scan's outputs, final state and ok to rounding (the AB3 SOGI-FLL-WIF: peeled start-up, blocked
    inputs, split state, unrolled); a bad flag is a ValueError naming it."""
    obs = B.fll_observer("sogi-fll-wif")

    def run(save):
        return jax.jit(jax.vmap(lambda s: jaxobs.simulate(jaxobs.OnSignal(obs, s), T1, save=save)))(wif_batch)

    ref, got = run(jaxobs.SaveAll()), run(jaxobs.SaveAll(fast=True))
    np.testing.assert_array_equal(got.t, ref.t)
    assert jax.tree.structure(got.outputs) == jax.tree.structure(ref.outputs)
    for a, b in zip(jax.tree.leaves(got.outputs), jax.tree.leaves(ref.outputs)):
        assert a.shape == b.shape
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    for a, b in zip(jax.tree.leaves(got.final_state), jax.tree.leaves(ref.final_state)):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    assert bool(jnp.all(got.ok))
    with pytest.raises(ValueError, match="SaveAll.fast"):
        jaxobs.SaveAll(fast=1)


def test_run_loop_is_a_scan():
    """Split carry, peeled start-up, unrolling and chunking return exactly lax.scan's carry and outputs."""

    def body(c, x):
        v, acc = c
        v = jnp.stack([v[1], -0.3 * v[0] + jnp.sin(x)])
        return (v, acc + v[0]), v[1] * x

    carry = (jnp.array([1.0, 0.5]), jnp.zeros(()))
    xs = jnp.linspace(0.0, 3.0, 103)
    ref_c, ref_y = jax.lax.scan(body, carry, xs)
    for ck in ("none", "step", "chunk"):
        for unroll in (1, 8):
            c, y = run_loop(body, carry, xs, 103, unroll=unroll, checkpoint=B.CHECKPOINTS[ck])
            np.testing.assert_allclose(c[0], ref_c[0], rtol=1e-15)
            np.testing.assert_allclose(y, ref_y, rtol=1e-15)


def test_run_loop_maps_inputs_a_block_at_a_time():
    """xs_map (the signal evaluated per block of steps) gives the scan over the mapped inputs, in every mode."""

    def body(c, x):
        t, u = x
        return c + u * t, u

    idx = jnp.arange(301, dtype=jnp.int32)
    xs_map = lambda k: (0.01 * k, jnp.cos(0.01 * k))  # noqa: E731
    ref_c, ref_y = jax.lax.scan(body, jnp.zeros(()), xs_map(idx))
    for ck in ("none", "step", "chunk", "auto"):
        c, y = run_loop(body, jnp.zeros(()), idx, 301, unroll=8, checkpoint=B.CHECKPOINTS[ck], xs_map=xs_map)
        np.testing.assert_allclose(c, ref_c, rtol=1e-15)
        np.testing.assert_allclose(y, ref_y, rtol=1e-15)
    with pytest.raises(ValueError, match="xs_map needs xs"):
        run_loop(body, jnp.zeros(()), None, 3, xs_map=xs_map)


@pytest.mark.parametrize("n_dirs", [2, 5])
def test_multi_jvp_matches_jacfwd_and_prunes_mixed_terms(n_dirs):
    """Forward sensitivities along several directions at once: nested (≤ NESTED_MAX) or vmapped, both = jacfwd."""
    from jaxobs.runtime._sensitivity import NESTED_MAX, multi_jvp

    def fun(p):
        def body(x, t):
            return jnp.stack([x[1], -p[0] * x[0] - p[1] * x[1] + jnp.sum(p[2:]) * jnp.sin(t)]), None

        return jax.lax.scan(body, jnp.array([1.0, 0.0]), jnp.linspace(0.0, 2.0, 50))[0]

    p = jnp.linspace(1.0, 2.0, n_dirs)
    y, jac = multi_jvp(fun, (p,), [jnp.eye(n_dirs)])
    np.testing.assert_allclose(y, fun(p), rtol=1e-15)
    np.testing.assert_allclose(jac.T, jax.jacfwd(fun)(p), rtol=1e-13)
    if n_dirs <= NESTED_MAX:
        # one loop carrying the primal and one tangent per direction: the 2**d - 1 - d mixed terms are gone
        # before XLA sees the loop (JAX's dead-code elimination at lowering).  Each direction adds two
        # carried values to the lowered while loop (the state's tangent and the parameter's, a loop
        # invariant); the unpruned nested JVP carries 5 more at d = 2 and 10 more at d = 3.
        def carried(f):
            return [int(m) for m in re.findall(r"%[\w]+:(\d+) = stablehlo.while", jax.jit(f).lower(p).as_text())]

        plain = carried(fun)
        nested = carried(lambda p: multi_jvp(fun, (p,), [jnp.eye(n_dirs)]))
        assert len(plain) == 1 and len(nested) == 1, (plain, nested)
        assert nested[0] - plain[0] == 2 * n_dirs, (plain, nested)


def test_run_loop_rejects_bad_settings():
    with pytest.raises(ValueError, match="checkpoint must be a checkpoint strategy"):
        run_loop(lambda c, x: (c, None), jnp.zeros(()), None, 3, checkpoint="sometimes")
    with pytest.raises(ValueError, match="unroll must be an integer >= 1"):
        run_loop(lambda c, x: (c, None), jnp.zeros(()), None, 3, unroll=0)
    with pytest.raises(ValueError, match="fallback must be a reverse-mode strategy"):
        jaxobs.ForwardSensitivity(fallback=jaxobs.AutoCheckpoint())
    with pytest.raises(ValueError, match="ForwardSensitivity serves loops without per-step outputs"):
        run_loop(lambda c, x: (c, c), jnp.zeros(()), None, 3, checkpoint=jaxobs.ForwardSensitivity())


def test_auto_checkpoint_picks_a_strategy_and_hands_it_the_loop():
    """AutoCheckpoint owns no loop of its own: forward sensitivities without per-step outputs (reverse mode
    past forward_max scalars by chunks above chunk_above steps, per-step checkpoints below), else those."""
    from jaxobs.runtime._steps import Loop

    def loop(n, outputs):
        return Loop(lambda c, x: (c, None), lambda c: c, n, 1, True, None, True, outputs)

    auto = jaxobs.AutoCheckpoint(chunk_above=100)
    assert auto.pick(loop(101, True)) == jaxobs.ChunkCheckpoint()
    assert auto.pick(loop(100, True)) == jaxobs.StepCheckpoint()
    assert auto.pick(loop(101, False)) == jaxobs.ForwardSensitivity(8, jaxobs.ChunkCheckpoint())
    assert auto.pick(loop(100, False)) == jaxobs.ForwardSensitivity(8, jaxobs.StepCheckpoint())
    assert jaxobs.AutoCheckpoint(forward_max=0).pick(loop(5, False)) == jaxobs.StepCheckpoint()
    # the peeled start-up steps are never chunked
    assert jaxobs.ChunkCheckpoint().startup == jaxobs.StepCheckpoint()
    assert jaxobs.NoCheckpoint().startup == jaxobs.NoCheckpoint()


@pytest.mark.parametrize(
    "modes",
    [
        ("auto",),
        # per-step and per-chunk checkpoints: two more reverse-mode compiles, over the fast suite's budget cold
        pytest.param(("step", "chunk"), marks=pytest.mark.slow),
    ],
    ids=["auto", "step-chunk"],
)
def test_gradients_agree_across_checkpoint_modes(wif_batch, modes):
    """Forward sensitivities (auto), per-step and per-chunk checkpoints against plain reverse mode: one gradient."""
    grads = {}
    for ck in ("none", *modes):
        loss, params = B.fll_loss_fn("sogi-fll-wif", T1, ck)
        v, g = jax.jit(jax.value_and_grad(loss))(params, wif_batch)
        grads[ck] = (float(v), np.array([g[n] for n in B.GAINS["sogi-fll-wif"]]))
    for ck in modes:
        assert grads[ck][0] == pytest.approx(grads["none"][0], rel=1e-13)
        np.testing.assert_allclose(grads[ck][1], grads["none"][1], rtol=1e-9)


def test_forward_gradient_matches_central_differences(wif_batch):
    """The default (forward-sensitivity) gradient against central differences of the loss as a function of
    the observer."""
    from gradcheck import assert_field_grads_match_fd

    obs = B.fll_observer("sogi-fll-wif")

    def loss_of(o, sig):
        def one(s):
            return jaxobs.simulate(jaxobs.OnSignal(o, s), T1, save=jaxobs.SaveFinal(cost=B.fll_cost)).cost

        return jnp.mean(jax.vmap(one)(sig))

    assert_field_grads_match_fd(loss_of, obs, B.GAINS["sogi-fll-wif"], wif_batch, rel=1e-5)


def test_ten_second_gradient_fits_in_64_mb():
    """10 s at 10 kHz (100k steps), batch 1024: XLA's temporaries, compiled not run."""
    assert B.grad_temp_mb("sogi-fll", 1024, 10.0, "auto") <= 64.0
    # a plain reverse-mode scan over that horizon keeps every step's residuals
    assert B.grad_temp_mb("sogi-fll", 1024, 10.0, "none") > 1000.0


@pytest.mark.slow  # one more long compile, over the fast suite's budget on a cold cache
def test_ten_second_gradient_with_chunk_checkpoints_fits_in_64_mb():
    assert B.grad_temp_mb("sogi-fll", 1024, 10.0, "chunk") <= 64.0


def test_a_gain_that_sets_the_initial_state_is_one_forward_direction(wif_batch):
    """omega_n sets the SOGI-FLL's initial ω̂.  The loop builds its initial carry inside the forward-sensitivity
    region (run_loop's carry_fn), so omega_n is one perturbed scalar there, not the three state components (and
    AB3 history) it reaches.  With max_scalars=1 the gradient therefore stays in forward mode: O(1) memory in
    the horizon, where the NoCheckpoint fallback (taken when the directions outnumber max_scalars) stores every
    step's residuals."""
    obs = B.fll_observer("sogi-fll")
    sig = jax.tree.map(lambda x: x[:2], wif_batch)

    def loss_for(ck):
        def loss(wn):
            o = eqx.tree_at(lambda m: m.omega_n, obs, wn)

            def one(s):
                return jaxobs.simulate(
                    jaxobs.OnSignal(o, s), 0.5, save=jaxobs.SaveFinal(cost=B.fll_cost), checkpoint=ck
                ).cost

            return jnp.mean(jax.vmap(one)(sig))

        return jax.jit(jax.value_and_grad(loss))

    one_dir = jaxobs.ForwardSensitivity(max_scalars=1, fallback=jaxobs.NoCheckpoint())
    f = loss_for(one_dir)
    mb = f.lower(obs.omega_n).compile().memory_analysis().temp_size_in_bytes / 1e6
    none = loss_for(jaxobs.NoCheckpoint())
    mb_none = none.lower(obs.omega_n).compile().memory_analysis().temp_size_in_bytes / 1e6
    # 5000 steps x 2 scenarios of stored residuals (the fallback) is megabytes; the forward pass, kilobytes
    assert mb < 0.5 < mb_none, (mb, mb_none)
    (v1, g1), (v2, g2) = f(obs.omega_n), none(obs.omega_n)
    assert float(v1) == pytest.approx(float(v2), rel=1e-13)
    assert float(g1) == pytest.approx(float(g2), rel=1e-9)


def test_drive_streaming_cost_equals_trajectory():
    drive, obs, sc, _ = B.drive_setup(3)
    full = jax.jit(jax.vmap(lambda s: jaxobs.simulate(D.ClosedLoop(drive, obs, s), 0.03)))(sc)
    o = full.outputs
    ref = 1e-4 * np.sum(np.asarray(jaxobs.metrics.wrap(o.obs.theta - o.theta_e)) ** 2, axis=1)
    save = jaxobs.SaveFinal(cost=B.drive_cost)
    fin = jax.jit(jax.vmap(lambda s: jaxobs.simulate(D.ClosedLoop(drive, obs, s), 0.03, save=save)))(sc)
    np.testing.assert_allclose(fin.cost, ref, rtol=1e-10)
    np.testing.assert_allclose(fin.final_state.plant.x, full.final_state.plant.x, rtol=1e-12, atol=1e-12)
    assert fin.outputs is None and bool(jnp.all(fin.ok))


def test_noise_free_sensors_skip_the_prng_and_noisy_ones_do_not():
    s0 = D.Sensors(i_offset=(0.1, 0.0))
    s1 = D.Sensors(i_offset=(0.1, 0.0), i_noise=0.2)
    assert not s0.noisy and s1.noisy
    key = jax.random.PRNGKey(0)
    a = s0.measure(key, 3, 1.0, 2.0, 0.5, -0.5)
    b = s1.measure(key, 3, 1.0, 2.0, 0.5, -0.5)
    assert a[2] == pytest.approx(0.6) and a[0] == 1.0
    assert b[2] != pytest.approx(0.6)


def test_profile_matches_numpy_interp_and_steps():
    p = D.Profile([0.1, 0.2, 0.2, 0.5], [1.0, 3.0, -1.0, 2.0])
    t = np.linspace(-0.1, 0.7, 801)
    np.testing.assert_allclose(p(jnp.asarray(t)), np.interp(t, [0.1, 0.2, 0.2, 0.5], [1.0, 3.0, -1.0, 2.0]), atol=1e-15)
    s = D.Profile([0.0, 0.3], [2.0, 5.0], kind="step")
    np.testing.assert_array_equal(s(jnp.asarray([-1.0, 0.0, 0.29, 0.3, 9.0])), [2.0, 2.0, 2.0, 5.0, 5.0])


_SHARD_SCRIPT = textwrap.dedent(
    """
    import os, sys
    import jaxobs, jax, numpy as np
    jaxobs.use_host_devices(4)
    jax.config.update("jax_enable_x64", True)
    from benchmarks import workloads as B
    assert len(jax.devices()) == 4, jax.devices()
    out = {}
    for kind in ("sogi-fll-wif",):
        fn, sharded = B.jax_fll(kind, 8, "loop", 0.05)
        fn_plain, plain = B.jax_fll(kind, 8, "loop", 0.05, shard=False)
        assert len(sharded.freq.sharding.device_set) == 4
        # sharded over 4 devices and tiled (map_batch) vs plain vmap on one device
        a, b = np.asarray(fn(sharded)), np.asarray(fn_plain(jax.device_put(plain, jax.devices()[0])))
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=0)
        # tiles of one scenario per lax.map iteration: the same numbers
        obs = B.fll_observer(kind)
        save = jaxobs.SaveFinal(cost=B.fll_cost)
        one = lambda s: jaxobs.simulate(jaxobs.OnSignal(obs, s), 0.05, save=save).cost
        c = np.asarray(jax.jit(lambda s: jaxobs.map_batch(one, s, tile=1))(sharded))
        np.testing.assert_allclose(c, b, rtol=1e-12, atol=0)
    fn, sharded = B.jax_drive(8, 0.02)
    fn_plain, plain = B.jax_drive(8, 0.02, shard=False)
    a, b = np.asarray(fn(sharded)), np.asarray(fn_plain(jax.device_put(plain, jax.devices()[0])))
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=0)
    # a study over the 4 host devices (6 scenarios: chunks padded to 8) equals it on one device
    from jaxobs import linear
    from jaxobs.studies.study import run_study
    axes = {"freq_step": [-2.0, 1.0], "dc": [0.0, 0.05, 0.1]}
    designs = {"SOGI-FLL": linear.sogi_fll_closed_form()}
    one = run_study(designs, axes, horizon=0.2, mesh=jaxobs.batch_mesh(jax.devices()[:1]))
    four = run_study(designs, axes, horizon=0.2)
    for k in one.data_vars:
        np.testing.assert_allclose(four[k].values, one[k].values, rtol=1e-12, atol=0, err_msg=k)
    # a time-major batch (time first, scenarios second) is split along its second axis
    tm = jaxobs.SampledSignal(np.ones((50, 8)), 1e-4, batch_inner=True)
    placed = jaxobs.shard_batch((tm, jax.numpy.linspace(1.0, 2.0, 8)))
    assert placed[0].samples.sharding.spec == jax.sharding.PartitionSpec(None, "batch"), placed[0].samples.sharding
    assert placed[1].sharding.spec == jax.sharding.PartitionSpec("batch"), placed[1].sharding
    print("SHARDED-EQUALS-SINGLE")
    """
)


@pytest.mark.slow  # a fresh process on 4 host devices compiles everything again (15-45 s on 2 cores)
def test_sharded_batch_equals_single_device_run():
    """4 host devices in a fresh process (XLA reads the flag at start-up)."""
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    # from the repository root, where `benchmarks` is importable
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    r = subprocess.run(
        [sys.executable, "-c", _SHARD_SCRIPT], capture_output=True, text=True, env=env, timeout=600, cwd=root
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert "SHARDED-EQUALS-SINGLE" in r.stdout


def test_map_batch_equals_vmap_with_a_short_last_tile_and_rejects_bad_input():
    f = lambda d: {"s": jnp.sum(jnp.sin(d["a"]) * d["b"]), "v": d["b"] * 2.0}  # noqa: E731
    x = {"a": jnp.linspace(0.0, 1.0, 7), "b": jnp.arange(14.0).reshape(7, 2)}
    want = jax.vmap(f)(x)
    got = jax.jit(lambda x: jaxobs.map_batch(f, x, tile=3))(x)  # tiles 3, 3, 1
    np.testing.assert_array_equal(  # a NumPy integer is a tile size too
        np.asarray(jax.jit(lambda x: jaxobs.map_batch(f, x, tile=np.int64(3)))(x)["v"]), np.asarray(got["v"])
    )
    # sin over a tile of 3 and over 7 is vectorized differently by XLA: last-bit differences
    np.testing.assert_allclose(np.asarray(got["s"]), np.asarray(want["s"]), rtol=1e-14, atol=0)
    np.testing.assert_array_equal(np.asarray(got["v"]), np.asarray(want["v"]))
    with pytest.raises(ValueError, match="tile"):
        jaxobs.map_batch(f, x, tile=0)
    with pytest.raises(ValueError, match="tile"):
        jaxobs.map_batch(f, x, tile=True)
    with pytest.raises(ValueError, match="scalar leaf"):
        jaxobs.map_batch(f, {"a": x["a"], "b": jnp.asarray(1.0)})


def test_map_batch_tiles_on_cpus_and_runs_whole_shares_on_accelerators():
    from types import SimpleNamespace

    from jaxobs.runtime.sharding import TILE, _default_tile

    cpu, gpu = SimpleNamespace(platform="cpu"), SimpleNamespace(platform="gpu")
    assert _default_tile([cpu, cpu], 65536) == TILE
    assert _default_tile([gpu], 65536) == 65536  # an H100 ran 16-19x faster whole than in tiles of 512
    assert _default_tile(jax.devices(), 10**6) == TILE  # this test machine's CPU devices


def test_shard_batch_leaves_uneven_batches_whole():
    x = {"a": jnp.arange(5.0), "b": jnp.ones((5, 2))}
    y = jaxobs.shard_batch(x)
    assert len(y["a"].sharding.device_set) == 1
    with pytest.raises(ValueError, match="common leading axis"):
        jaxobs.shard_batch({"a": jnp.arange(5.0), "b": jnp.ones(4)})


def test_recording_is_read_a_block_at_a_time():
    """OnSignal.input_block: a SampledSignal on the loop's sample grid is sliced a block at a time (the same
    numbers as reading it per step); off the grid (t0 half a sample in) it is read per step, interpolated."""
    obs = B.fll_observer("sogi-fll")
    n = 700
    t = 1e-4 * np.arange(n)
    u = np.cos(2 * np.pi * 50.3 * t) + 0.1 * np.cos(2 * np.pi * 150.0 * t)
    truth = (2 * np.pi * 50.3 * t, np.full(n, 2 * np.pi * 50.3), np.ones(n))
    rec = jaxobs.SampledSignal(jnp.asarray(u), 1e-4, truth=tuple(map(jnp.asarray, truth)))
    for t0, blocked in ((0.0, True), (0.5e-4, False)):
        system = jaxobs.OnSignal(obs, rec, t0=t0)
        assert (system._sample_offset() is not None) == blocked
        t1 = t0 + 600 * 1e-4
        fast = jaxobs.simulate(system, t1, save=jaxobs.SaveFinal(cost=B.fll_cost))
        plain = jaxobs.simulate(system, t1, save=jaxobs.SaveAll(cost=B.fll_cost))
        np.testing.assert_allclose(fast.cost, plain.cost, rtol=1e-12)
        ks = jnp.arange(5, 133, dtype=jnp.int32)
        per_step = jax.lax.map(system.input, ks)
        for a, b in zip(jax.tree.leaves(system.input_block(ks)), jax.tree.leaves(per_step)):
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("kind", B.FLL_KINDS)
def test_hand_written_jax_kernel_equals_jaxobs(kind):
    """The bench's `jax-hand` rows (benchmarks.workloads.jax_hand_fll: each precomputed FLL written directly
    as one scan over time-major rows) compute jaxobs's costs, past the event at 0.2 s where the scenarios part."""
    fn, args = B.jax_fll(kind, 4, "precomputed", 0.25, shard=False)
    ref = np.asarray(fn(args))
    hand, hargs = B.jax_hand_fll(4, 0.25, kind)
    np.testing.assert_allclose(np.asarray(hand(*hargs)), ref, rtol=1e-10)
    assert np.ptp(ref) > 1e-3 * np.max(np.abs(ref))
