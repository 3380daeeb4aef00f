"""A few rows of ``make bench`` in one short run: jaxobs beside the batch-inner numba kernel (and ``jax-hand``).

    python -m benchmarks.rows [--kinds sogi-fll] [--inputs precomputed loop] [--dtypes f32 f64] [--batches 1024]

The row groups of :func:`benchmarks.run.run_bench` for the FLL workloads only (the drive's rows are
``python -m benchmarks.drive_f64``), without the scalar baselines, NumPy, the ceilings and the gradient
figures, so that the rows a change is about can be re-measured in minutes (most of it numba's compilation)
on a shared machine: each group's implementations timed interleaved, best of ``--rounds``, the ratio to
``numba-inner`` taken within the group, the load average printed at the start and the end.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from functools import partial

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # numba's idle threads sleep (benchmarks/__main__.py)

import jax
import numpy as np

import jaxobs

from . import baselines
from . import workloads as W
from .run import REF, best_time, numba_available


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.rows", description=__doc__.split("\n")[0])
    p.add_argument("--kinds", nargs="+", default=["sogi-fll"], choices=W.FLL_KINDS)
    p.add_argument("--inputs", nargs="+", default=["precomputed", "loop"], choices=("precomputed", "loop"))
    p.add_argument("--dtypes", nargs="+", default=["f32", "f64"], choices=("f32", "f64"))
    p.add_argument("--batches", nargs="+", type=int, default=[1024])
    p.add_argument("--horizon", type=float, default=W.FLL_T1, help="seconds simulated (10 kHz; default 1)")
    p.add_argument("--rounds", type=int, default=3)
    a = p.parse_args(argv)
    jaxobs.use_host_devices()
    jaxobs.use_compile_cache()
    if not numba_available():
        raise SystemExit("numba is not installed (pip install -e '.[bench]')")
    print(f"load average {os.getloadavg()[0]:.1f} at the start; {len(jax.devices())} host devices")
    n = round(a.horizon / W.TS)
    for batch in a.batches:
        for dt in a.dtypes:
            jax.config.update("jax_enable_x64", dt == "f64")
            dtype = {"f32": np.float32, "f64": np.float64}[dt]
            for kind in a.kinds:
                for inputs in a.inputs:
                    fn, args = W.jax_fll(kind, batch, inputs, a.horizon)
                    group = {"jaxobs": partial(fn, args)}
                    if inputs == "precomputed":
                        hand, hargs = W.jax_hand_fll(batch, a.horizon, kind)
                        group["jax-hand"] = partial(hand, *hargs)
                    run = baselines.numba_fll_inner(kind, dtype, inputs)
                    run(*baselines.fll_inner_args(kind, 2, dtype, inputs, 3))  # compile
                    group[REF] = partial(run, *baselines.fll_inner_args(kind, batch, dtype, inputs, n))
                    for f in group.values():
                        jax.block_until_ready(f())  # compiled and warm
                    best = {k: math.inf for k in group}
                    for _ in range(a.rounds):
                        for k, f in group.items():
                            best[k] = min(best[k], best_time(f, 1))
                    rate = {k: batch * n / t for k, t in best.items()}
                    cols = "  ".join(f"{k} {v / 1e6:7.1f} M" for k, v in rate.items())
                    ratios = "  ".join(f"{k}/{REF} {v / rate[REF]:.2f}" for k, v in rate.items() if k != REF)
                    print(f"{kind:13s} {inputs:11s} {dt} batch {batch:5d}: {cols}  |  {ratios}", flush=True)
    print(f"load average {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
