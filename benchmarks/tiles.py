"""Why the precomputed FLL rows fell off at batch 8192 with scenario-major recordings: tile size and input layout.

    python -m benchmarks.tiles [--dtype f32|f64] [--batch 8192]

Precomputed SOGI-FLL, 1 s at 10 kHz, M scenario-steps/s, best of 3, in one process:

- ``tiles``: jaxobs's loop under :func:`jaxobs.map_batch` on every host device over scenario-major
  recordings, the tile 256 … the whole device share, and over the same samples as a time-major batch
  (``SampledSignal(batch_inner=True)``: rows, each device's share whole), beside the hand-written JAX
  scan (:func:`benchmarks.workloads.jax_hand_fll`);
- ``layout``: one device, the whole batch under one ``vmap``: the samples scenario-major (batch, n) as
  jaxobs stores them, the same samples stored time-major (n, batch) and ``vmap``-ed with
  ``in_axes=1``, and ``map_batch``'s 512-tiles of the scenario-major array;
- ``scan over xs``: outside jaxobs's loop, a per-scenario ``lax.scan`` with the samples as its ``xs``,
  ``vmap``-ed over every device, the step on jaxobs's stacked state or on a tuple of components,
  the samples scenario-major or time-major (``in_axes=1``).

About a minute per dtype on a quiet 2-core machine, two under load (compiles included).
"""

from __future__ import annotations

import argparse
import time


def _rate(fn, batch: int, n: int, repeats: int = 3) -> float:
    import jax

    jax.block_until_ready(fn())  # compile
    best = 0.0
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        best = max(best, batch * n / (time.perf_counter() - t0) / 1e6)
    return best


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        prog="python -m benchmarks.tiles",
        description=__doc__.split("\n")[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--dtype", choices=("f32", "f64"), default="f32", help="working precision")
    p.add_argument("--batch", type=int, default=8192, help="scenarios: a multiple of 512 × the host devices")
    a = p.parse_args(argv)

    import warnings

    import jax

    import jaxobs

    ndev = jaxobs.use_host_devices()
    if a.batch < 512 * ndev or a.batch % (512 * ndev):
        p.error(f"--batch must be a positive multiple of {512 * ndev} (512 × {ndev} host devices), got {a.batch}")
    warnings.simplefilter("ignore", jaxobs.PrecisionWarning)  # float32 is asked for here
    jax.config.update("jax_enable_x64", a.dtype == "f64")
    import jax.numpy as jnp

    from . import workloads as W

    n = round(W.FLL_T1 / W.TS)
    obs = W.fll_observer("sogi-fll")

    def one(s):
        return jaxobs.simulate(jaxobs.OnSignal(obs, s), W.FLL_T1, save=jaxobs.SaveFinal(cost=W.fll_cost)).cost

    B = a.batch
    _, sharded = W.jax_fll("sogi-fll", B, "precomputed", layout="scenario")
    rows = {}
    for tile in sorted({t for t in (256, 512, 1024, 2048) if t < B // ndev} | {B // ndev}):
        f = jax.jit(lambda b, tile=tile: jaxobs.map_batch(one, b, tile=tile))
        rows[f"tile {tile}"] = _rate(lambda f=f: f(sharded), B, n)
    rows_fn, rows_batch = W.jax_fll("sogi-fll", B, "precomputed")  # time-major: each device's share whole
    rows["time-major rows"] = _rate(lambda: rows_fn(rows_batch), B, n)
    hand, hargs = W.jax_hand_fll(B)
    rows["jax-hand"] = _rate(lambda: hand(*hargs), B, n)
    print(f"{a.dtype} batch {B}, {ndev} devices:", ", ".join(f"{k} {v:.0f}" for k, v in rows.items()))

    b1 = B // ndev  # one device's share, on one device
    _, sig = W.jax_fll("sogi-fll", b1, "precomputed", shard=False, layout="scenario")
    sig_t = jax.tree.map(lambda x: jnp.asarray(x.T) if x.ndim == 2 else x, sig)
    axes = jax.tree.map(lambda x: 1 if x.ndim == 2 else 0, sig)
    dev0 = jaxobs.batch_mesh(jax.devices()[:1])
    scen, time_major = jax.jit(jax.vmap(one)), jax.jit(jax.vmap(one, in_axes=(axes,)))
    tiled = jax.jit(lambda b: jaxobs.map_batch(one, b, mesh=dev0, tile=512))
    if not bool(jnp.all(scen(sig) == time_major(sig_t))):
        raise SystemExit("the time-major layout changed the costs")
    rows = {
        "scenario-major": _rate(lambda: scen(sig), b1, n),
        "time-major in_axes=1": _rate(lambda: time_major(sig_t), b1, n),
        "512-tiles": _rate(lambda: tiled(sig), b1, n),
    }
    print(f"{a.dtype} batch {b1}, 1 device:", ", ".join(f"{k} {v:.0f}" for k, v in rows.items()))

    # outside jaxobs's loop: a per-scenario lax.scan with the samples as its xs, vmapped, on every device,
    # the step on jaxobs's stacked state (obs.f) or on a tuple of components (as jax-hand), the samples
    # scenario-major (B, n) or time-major (n, B) with in_axes=1; from jax-hand's start-up state
    from jax.sharding import PartitionSpec as P

    h = jnp.asarray(W.TS, jnp.result_type(float))
    tuple_step = W.fll_tuple_step("sogi-fll", obs, h)  # jax-hand's own step

    def stacked_step(c, row):  # the same AB3 step on jaxobs's stacked state, through obs.f
        x, f1, f2, acc = c
        d = x[2] - row[1]
        f0 = obs.f(x, row[0])
        return (x + (h / 12) * (23 * f0 - 16 * f1 + 5 * f2), f0, f1, acc + d * d), None

    def scan_one(stacked, x, f1, f2, acc, u, om):
        if stacked:
            x, f1, f2 = jnp.stack(x), jnp.stack(f1), jnp.stack(f2)
        step = stacked_step if stacked else tuple_step
        return h * jax.lax.scan(step, (x, f1, f2, acc), (u, om))[0][3]

    mesh = jaxobs.batch_mesh()
    sb = P("batch")
    rows = {}
    for stacked in (True, False):
        for major in ("scenario", "time"):
            ax = 0 if major == "scenario" else 1
            spec = P("batch", None) if major == "scenario" else P(None, "batch")
            f = jax.jit(
                jax.shard_map(
                    jax.vmap(lambda *args, s=stacked: scan_one(s, *args), in_axes=(0, 0, 0, 0, ax, ax)),
                    mesh=mesh,
                    in_specs=((sb,) * 3, (sb,) * 3, (sb,) * 3, sb, spec, spec),
                    out_specs=sb,
                    check_vma=False,
                )
            )
            u, om = hargs[4:] if major == "time" else (x.T for x in hargs[4:])
            args = (*hargs[:4], jax.device_put(u, jax.NamedSharding(mesh, spec)), jax.device_put(om, u.sharding))
            # the same arithmetic, fused differently by XLA: equal to the last bits of the working precision
            got, want = f(*args), hand(*hargs)
            rel = float(jnp.max(jnp.abs(got - want) / jnp.abs(want)))
            if rel > (1e-4 if a.dtype == "f32" else 1e-12):
                raise SystemExit(f"the per-scenario scan changed the costs (relative {rel:.1e})")
            rows[f"{'stacked' if stacked else 'tuple'} step, {major}-major"] = _rate(lambda f=f, a=args: f(*a), B, n)
    print(f"{a.dtype} batch {B}, scan over xs:", ", ".join(f"{k} {v:.0f}" for k, v in rows.items()))


if __name__ == "__main__":
    main()
