"""The drive in float64 vs float32: speed, accuracy, and each beside its batch-inner numba kernel.

    python -m benchmarks.drive_f64 [--batch 1024] [--horizon 0.05] [--rounds 3] [--no-numba]

The drive workload of ``make bench`` (:func:`benchmarks.workloads.jax_drive`: paper 000's SPMSM closed
loop, sensorless on the second-order SOIFO + FLL, the per-scenario running cost wrap(θ̂ − θ)²) in both
precisions in this one process (``jax_enable_x64`` switched between them, as ``python -m benchmarks`` does),
and the batch-inner numba kernel of each (``numba-inner``, the ratios' reference; compiled before timing,
1–2 minutes each).  The four implementations are timed interleaved, best of ``--rounds``, so every ratio
compares timings taken side by side; the load average is printed at the start and the end.

Accuracy: float32's per-scenario costs against float64's (relative error: median and worst over the
batch), and the same for numba's float32 against numba's float64: what the cheaper precision costs in
the number a tuning run optimizes.

Where float64 loses (``--ops``, seconds): the cost of one element of each operation the drive's step is
made of, XLA's (a jitted loop over a (1024,) array) beside numba's scalar libm calls, in both precisions,
and ``jaxobs.core.trig.sincos`` (the drive's sine and cosine) beside XLA's pair.

``--xla-trig`` adds the row ``jaxobs-xla-trig``: the same drive with XLA's own ``sin``/``cos`` in place of
``jaxobs.core.trig.sincos`` (the modules that call it are patched while that row is traced and compiled), the
A/B of jaxobs's own sine and cosine against XLA's, timed in the same rounds.  ``--dtypes f64`` leaves float32
out (one numba compile instead of two).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from functools import partial

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # numba's idle threads sleep (benchmarks/__main__.py)

import jax
import numpy as np

import jaxobs
from jaxobs.core.trig import sincos

from . import baselines
from . import workloads as W
from .run import best_time, numba_available

DTYPES = {"f32": np.float32, "f64": np.float64}


def _rel(a, b) -> tuple[float, float]:
    """Median and worst |a − b| / |b| over the batch."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    r = np.abs(a - b) / np.maximum(np.abs(b), np.finfo(np.float64).tiny)
    return float(np.median(r)), float(np.max(r))


OPS = {
    "sin": lambda m, x: m.sin(x),
    "cos": lambda m, x: m.cos(x),
    "atan2": lambda m, x: m.arctan2(x, 1.3 - x) if m is not math else math.atan2(x, 1.3 - x),
    "sin+cos": lambda m, x: m.sin(x) + m.cos(x),
    "sincos (jaxobs)": lambda m, x: sum(sincos(x)),  # float64: jaxobs.core.trig's polynomial; float32: XLA's pair
    "exp": lambda m, x: m.exp(-x),
    "sqrt": lambda m, x: m.sqrt(x + 1.0),
    "divide": lambda m, x: 1.0 / (x + 1.5),
    "multiply-add": lambda m, x: x * 0.999 + 0.001,
}


def op_costs(batch: int = 1024, n: int = 2000, rounds: int = 5) -> dict:
    """ns per element of each of :data:`OPS`: XLA (``y = op(y)·0.5 + 0.25``, n times over a (batch,) array in
    one jitted loop) and numba (the same loop, scalar ``math`` calls), float32 and float64, interleaved."""
    import jax.numpy as jnp

    fns = {}
    for name, op in OPS.items():
        for dt in DTYPES:
            jax.config.update("jax_enable_x64", dt == "f64")
            x = jnp.linspace(0.1, 0.9, batch, dtype=DTYPES[dt])
            f = jax.jit(lambda x, op=op: jax.lax.fori_loop(0, n, lambda i, y: op(jnp, y) * 0.5 + 0.25, x))
            jax.block_until_ready(f(x))
            fns[("XLA", name, dt)] = (dt, partial(f, x))
    if numba_available():
        import numba

        scalar = {  # the transcendental calls, as numba's kernels make them; the rest vectorizes in both
            "sin": numba.njit(lambda v: math.sin(v)),
            "cos": numba.njit(lambda v: math.cos(v)),
            "atan2": numba.njit(lambda v: math.atan2(v, 1.3 - v)),
        }
        for name, one in scalar.items():

            def make(one):
                @numba.njit(error_model="numpy")
                def loop(x):
                    y = x.copy()
                    for _ in range(n):
                        for j in range(y.shape[0]):
                            y[j] = one(y[j]) * 0.5 + 0.25
                    return y

                return loop

            loop = make(one)
            for dt in DTYPES:
                x = np.linspace(0.1, 0.9, batch).astype(DTYPES[dt])
                loop(x)
                fns[("numba", name, dt)] = (dt, partial(loop, x))
    best = {k: math.inf for k in fns}
    for _ in range(rounds):
        for k, (dt, f) in fns.items():
            jax.config.update("jax_enable_x64", dt == "f64")
            best[k] = min(best[k], best_time(f, 1))
    jax.config.update("jax_enable_x64", True)
    return {f"{i} {name} {dt}": t / (batch * n) * 1e9 for (i, name, dt), t in best.items()}


def _xla_sincos(x):
    import jax.numpy as jnp

    return jnp.sin(x), jnp.cos(x)


def _callers_of_sincos():
    """The modules whose drive code calls ``jaxobs.core.trig.sincos`` (patched for ``--xla-trig``)."""
    from jaxobs.drive import control, machine, plant

    return (control, machine, plant)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.drive_f64", description=__doc__.split("\n")[0])
    p.add_argument("--batch", type=int, default=1024, help="scenarios (default 1024)")
    p.add_argument("--horizon", type=float, default=0.05, help="seconds simulated (10 kHz; default 0.05)")
    p.add_argument("--rounds", type=int, default=3, help="interleaved timing rounds, best of (default 3)")
    p.add_argument("--no-numba", action="store_true", help="leave out the numba kernels")
    p.add_argument("--dtypes", nargs="+", choices=list(DTYPES), default=list(DTYPES), help="precisions (default both)")
    p.add_argument("--xla-trig", action="store_true", help="add jaxobs with XLA's sin/cos (an A/B of jaxobs's sincos)")
    p.add_argument("--ops", action="store_true", help="only the per-operation costs (ns a value), XLA beside numba")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    a = p.parse_args(argv)
    if a.ops:
        load0 = os.getloadavg()[0]
        costs = op_costs()
        print(f"ns per value (load average {load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end)")
        for k, v in costs.items():
            print(f"  {k:24s} {v:7.2f}")
        return 0
    jaxobs.use_host_devices()
    jaxobs.use_compile_cache()
    load0 = os.getloadavg()
    have_numba = numba_available() and not a.no_numba
    n = round(a.horizon / W.TS)
    fns, costs = {}, {}
    for dt in a.dtypes:
        jax.config.update("jax_enable_x64", dt == "f64")
        variants = [("jaxobs", None)] + ([("jaxobs-xla-trig", _xla_sincos)] if a.xla_trig else [])
        for name, patch in variants:
            mods = _callers_of_sincos() if patch is not None else ()
            saved = [m.sincos for m in mods]
            for m in mods:
                m.sincos = patch
            try:
                jax.clear_caches()  # simulate's traces are cached by its arguments: trace this variant afresh
                fn, args = W.jax_drive(a.batch, a.horizon)
                # compiled ahead of time, so that the program stays this variant's once the patch is undone
                fn = fn.lower(args).compile()
            finally:
                for m, f in zip(mods, saved):
                    m.sincos = f
            costs[(name, dt)] = np.asarray(jax.block_until_ready(fn(args)))  # compiled, warm
            # the switch is read when a function is traced: each closure keeps its own precision's program
            fns[(name, dt)] = (dt, partial(fn, args))
        if have_numba:
            w = np.asarray(W.drive_setup(a.batch)[3], DTYPES[dt])
            run = baselines.numba_drive(DTYPES[dt], True, inner=True)
            run(np.ones(2, DTYPES[dt]), 3)  # compile
            costs[("numba-inner", dt)] = np.asarray(run(w, n))
            fns[("numba-inner", dt)] = (dt, partial(run, w, n))
    best = {k: math.inf for k in fns}
    for _ in range(a.rounds):
        for k, (dt, f) in fns.items():
            jax.config.update("jax_enable_x64", dt == "f64")
            best[k] = min(best[k], best_time(f, 1))
    jax.config.update("jax_enable_x64", True)
    res = {
        "batch": a.batch,
        "horizon_s": a.horizon,
        "steps": n,
        "devices": len(jax.devices()),
        "load_avg": [round(load0[0], 2), round(os.getloadavg()[0], 2)],
        "steps_per_s": {f"{i} {dt}": a.batch * n / t for (i, dt), t in best.items()},
    }
    both = len(a.dtypes) == 2
    ratios = {"jaxobs f32 / f64 time": best[("jaxobs", "f32")] / best[("jaxobs", "f64")]} if both else {}
    if have_numba:
        if both:
            ratios["numba f32 / f64 time"] = best[("numba-inner", "f32")] / best[("numba-inner", "f64")]
        for dt in a.dtypes:
            ratios[f"jaxobs / numba-inner {dt} (speed)"] = best[("numba-inner", dt)] / best[("jaxobs", dt)]
            if a.xla_trig:
                ratios[f"jaxobs-xla-trig / numba-inner {dt} (speed)"] = (
                    best[("numba-inner", dt)] / best[("jaxobs-xla-trig", dt)]
                )
    if a.xla_trig:
        for dt in a.dtypes:
            ratios[f"jaxobs / jaxobs-xla-trig {dt} (speed)"] = best[("jaxobs-xla-trig", dt)] / best[("jaxobs", dt)]
    res["ratios"] = ratios
    acc = {}
    if both:
        acc["jaxobs f32 vs f64 cost (median, worst rel.)"] = _rel(costs[("jaxobs", "f32")], costs[("jaxobs", "f64")])
    if have_numba and both:
        acc["numba f32 vs f64 cost"] = _rel(costs[("numba-inner", "f32")], costs[("numba-inner", "f64")])
    if have_numba and "f64" in a.dtypes:
        acc["jaxobs f64 vs numba f64 cost"] = _rel(costs[("jaxobs", "f64")], costs[("numba-inner", "f64")])
    if a.xla_trig:
        for dt in a.dtypes:
            acc[f"jaxobs vs jaxobs-xla-trig {dt} cost"] = _rel(costs[("jaxobs", dt)], costs[("jaxobs-xla-trig", dt)])
    res["accuracy"] = acc
    if a.json:
        print(json.dumps(res, indent=1))
        return 0
    print(
        f"drive, batch {a.batch}, {a.horizon:g} s ({n} steps), {res['devices']} host devices, "
        f"load average {res['load_avg'][0]} at the start, {res['load_avg'][1]} at the end"
    )
    for k, v in res["steps_per_s"].items():
        print(f"  {k:18s} {v / 1e6:8.2f} M scenario-steps/s")
    for k, v in ratios.items():
        print(f"  {k}: {v:.2f}")
    for k, (med, worst) in acc.items():
        print(f"  {k}: median {med:.2e}, worst {worst:.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
