"""Why the precomputed FLL rows fall off at batch 8192 (README, Performance): tile size and input layout.

    python -m benchmarks.tiles [--dtype f32|f64] [--batch 8192]

Precomputed SOGI-FLL, 1 s at 10 kHz, M scenario-steps/s, best of 3, in one process:

- ``tiles``: jaxobs's loop under :func:`jaxobs.map_batch` on every host device, the tile 256 … the
  whole device share, beside the hand-written JAX scan (:func:`benchmarks.workloads.jax_hand_fll`);
- ``layout``: one device, the whole batch under one ``vmap``: the samples scenario-major (batch, n) as
  jaxobs stores them, the same samples stored time-major (n, batch) and ``vmap``\\ ped with
  ``in_axes=1``, and ``map_batch``'s 512-tiles of the scenario-major array.

About 30 s per dtype on a 2-core machine (compiles included).
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
    p.add_argument("--dtype", choices=("f32", "f64"), default="f32")
    p.add_argument("--batch", type=int, default=8192, help="scenarios (a multiple of 2 × the host devices)")
    a = p.parse_args(argv)

    import jax

    import jaxobs

    ndev = jaxobs.use_host_devices()
    jax.config.update("jax_enable_x64", a.dtype == "f64")
    import jax.numpy as jnp

    from . import workloads as W

    n = round(W.FLL_T1 / W.TS)
    obs = W.fll_observer("sogi-fll")

    def one(s):
        return jaxobs.simulate(jaxobs.OnSignal(obs, s), W.FLL_T1, save=jaxobs.SaveFinal(cost=W.fll_cost)).cost

    B = a.batch
    _, sharded = W.jax_fll("sogi-fll", B, "precomputed")
    rows = {}
    for tile in sorted({256, 512, 1024, 2048, B // ndev}):
        f = jax.jit(lambda b, tile=tile: jaxobs.map_batch(one, b, tile=tile))
        rows[f"tile {tile}"] = _rate(lambda f=f: f(sharded), B, n)
    hand, hargs = W.jax_hand_fll(B)
    rows["jax-hand"] = _rate(lambda: hand(*hargs), B, n)
    print(f"{a.dtype} batch {B}, {ndev} devices:", ", ".join(f"{k} {v:.0f}" for k, v in rows.items()))

    b1 = B // ndev  # one device's share, on one device
    _, sig = W.jax_fll("sogi-fll", b1, "precomputed", shard=False)
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


if __name__ == "__main__":
    main()
