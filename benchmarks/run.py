"""Timing, the result rows, the text table: scenario-steps per second of jaxobs beside NumPy and numba.

Implementations: ``jaxobs`` (:mod:`benchmarks.workloads`: ``jit`` of
:func:`jaxobs.map_batch` over ``simulate``), ``numba-serial`` and
``numba-parallel`` (``njit`` loops over the batch, ``parallel=True`` a
``prange`` over every core), ``numpy`` (a Python loop over time, vectorized
over the batch): :mod:`benchmarks.baselines`, checked equal to jaxobs in
tests/test_bench.py.  numba is optional (``pip install -e '.[bench]'``).

Besides throughput: compile time of a new observer shape, the
``value_and_grad``/forward time ratio per checkpointing strategy, and XLA's
temporary-buffer size of a 10 s (100k-step) gradient at batch 1024.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from functools import partial

import jax
import numpy as np

from . import baselines
from . import workloads as W

DTYPES = {"f32": np.float32, "f64": np.float64}
CHECKPOINTS = ("auto", "none", "step", "chunk")


@dataclasses.dataclass
class Row:
    workload: str
    impl: str  # jaxobs | numba-parallel | numba-serial | numpy
    dtype: str
    batch: int
    inputs: str  # loop | precomputed
    steps_per_s: float
    ratio_vs_numba_parallel: float | None = None


def best_time(fn: Callable, repeats: int, min_time: float = 0.0) -> float:
    """Best wall time of ``fn()`` (waiting for its results): ``repeats`` runs, ``min_time`` s in all, 20 at most."""
    best = math.inf
    spent = 0.0
    i = 0
    while i < repeats or spent < min_time:
        t0 = time.perf_counter()
        out = fn()
        jax.block_until_ready(out)
        dt = time.perf_counter() - t0
        best, spent, i = min(best, dt), spent + dt, i + 1
        if i >= 20:
            break
    return best


def _set_dtype(dt: str):
    jax.config.update("jax_enable_x64", dt == "f64")


def numba_available() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def run_bench(quick: bool = False, log: Callable[[str], None] = print) -> dict:
    """Run every benchmark; returns ``{"rows": [...], "grad_over_forward": ..., ...}``.

    ``quick``: a look in about 80 s on 2 cores (measured 78 s), most of it compilation (numba's kernels compile
    10-30 s each): batch 1024 only, float64 only, the SOGI-FLL 0.1 s and the drive 0.05 s, numba's
    parallel kernels only (the ratios' reference), the gradient with the default checkpointing only.
    """
    batches = (1024,) if quick else (1, 64, 1024, 8192)
    fll_t1, drive_t1 = (0.1, 0.05) if quick else (W.FLL_T1, W.DRIVE_T1)
    kinds = ("sogi-fll",) if quick else W.FLL_KINDS
    repeats = 2 if quick else 3
    dtypes = ("f64",) if quick else ("f32", "f64")
    numba_kinds = (True,) if quick else (True, False)  # parallel, serial
    have_numba = numba_available()
    rows: list[Row] = []
    extra: dict = {"devices": [str(d) for d in jax.devices()], "numba": have_numba, "quick": quick}
    if not have_numba:
        log("numba is not installed (pip install -e '.[bench]'): numba rows and ratios are left out")

    def add(row):
        rows.append(row)
        log(
            f"  {row.workload:14s} {row.impl:15s} {row.dtype} {row.inputs:11s} batch {row.batch:5d}: "
            f"{row.steps_per_s / 1e6:9.2f} M steps/s"
        )

    for dt in dtypes:
        _set_dtype(dt)
        dtype = DTYPES[dt]
        for kind in kinds:
            n = round(fll_t1 / W.TS)
            for batch in batches:
                for inputs in ("loop", "precomputed"):
                    fn, args = W.jax_fll(kind, batch, inputs, fll_t1)
                    jax.block_until_ready(fn(args))
                    t = best_time(partial(fn, args), repeats)
                    add(Row(kind, "jaxobs", dt, batch, inputs, batch * n / t))
                    if have_numba:
                        for par in numba_kinds:
                            if not par and batch > 1024:
                                continue  # serial numba at 8192 adds minutes and no information
                            run = baselines.numba_fll(kind, dtype, par, inputs)
                            bargs = baselines.fll_baseline_args(kind, batch, dtype, inputs, n)
                            run(*baselines.fll_baseline_args(kind, 2, dtype, inputs, 3))  # compile
                            t = best_time(partial(run, *bargs), repeats)
                            impl = "numba-parallel" if par else "numba-serial"
                            add(Row(kind, impl, dt, batch, inputs, batch * n / t))
                if batch == 1024:
                    n_np = min(n, 1000)
                    t = best_time(partial(baselines.numpy_fll, kind, batch, dtype, n_np), 1)
                    add(Row(kind, "numpy", dt, batch, "loop", batch * n_np / t))
        # drive
        n = round(drive_t1 / W.TS)
        for batch in batches:
            fn, args = W.jax_drive(batch, drive_t1)
            jax.block_until_ready(fn(args))
            t = best_time(partial(fn, args), repeats)
            add(Row("drive-sosoifo", "jaxobs", dt, batch, "loop", batch * n / t))
            if have_numba:
                for par in numba_kinds:
                    if not par and batch > 1024:
                        continue
                    run = baselines.numba_drive(dtype, par)
                    run(np.ones(2, dtype), 3)  # compile
                    w = np.asarray(W.drive_setup(batch)[3], dtype)
                    t = best_time(partial(run, w, n), repeats)
                    impl = "numba-parallel" if par else "numba-serial"
                    add(Row("drive-sosoifo", impl, dt, batch, "loop", batch * n / t))
            if batch == 1024:
                n_np = min(n, 200)
                t = best_time(partial(baselines.numpy_drive, batch, dtype, n_np), 1)
                add(Row("drive-sosoifo", "numpy", dt, batch, "loop", batch * n_np / t))

    # ratios against numba-parallel of the same workload, dtype, batch and inputs
    ref = {(r.workload, r.dtype, r.batch, r.inputs): r.steps_per_s for r in rows if r.impl == "numba-parallel"}
    for r in rows:
        key = (r.workload, r.dtype, r.batch, r.inputs)
        if key in ref:
            r.ratio_vs_numba_parallel = r.steps_per_s / ref[key]

    _set_dtype("f64")
    extra["dtypes"] = list(dtypes)
    extra.update(gradient_benchmarks(quick, log))
    extra.update(compile_benchmarks(log))
    return {"rows": [dataclasses.asdict(r) for r in rows], **extra}


def gradient_benchmarks(quick: bool, log) -> dict:
    """value_and_grad vs forward time (batch 1024, 1 s, float64) and 10 s gradient memory."""
    kind, batch = "sogi-fll", 1024
    t1 = 0.2 if quick else W.FLL_T1
    sig = W.fll_signal_batch(batch)
    out = {"grad_over_forward": {}, "grad_temp_mb_10s": {}, "grad_10s_s": None}
    loss, params = W.fll_loss_fn(kind, t1, "auto")
    fwd = jax.jit(loss)
    jax.block_until_ready(fwd(params, sig))
    checkpoints = ("auto",) if quick else CHECKPOINTS  # each one is a compilation of its gradient
    for ck in checkpoints:
        loss_c, _ = W.fll_loss_fn(kind, t1, ck)
        vg = jax.jit(jax.value_and_grad(loss_c))
        jax.block_until_ready(vg(params, sig))
        # interleaved, best of each: a ratio of two timings taken side by side
        t_f, t_g = math.inf, math.inf
        for _ in range(3):
            t_f = min(t_f, best_time(partial(fwd, params, sig), 1))
            t_g = min(t_g, best_time(partial(vg, params, sig), 1))
        out["grad_over_forward"][ck] = t_g / t_f
        log(
            f"  value_and_grad / forward ({kind} gains {W.GAINS[kind]}, batch {batch}, {t1:g} s, f64, "
            f"checkpoint={ck}): {t_g / t_f:.2f}"
        )
    for ck in checkpoints:
        mb = W.grad_temp_mb(kind, batch, 10.0, ck)
        out["grad_temp_mb_10s"][ck] = mb
        log(f"  10 s gradient temporaries ({kind}, batch {batch}, f64, checkpoint={ck}): {mb:,.1f} MB")
    if not quick:
        loss10, _ = W.fll_loss_fn(kind, 10.0, "auto")
        vg10 = jax.jit(jax.value_and_grad(loss10))
        t0 = time.perf_counter()
        val, g = jax.block_until_ready(vg10(params, sig))
        out["grad_10s_s"] = time.perf_counter() - t0
        finite = np.isfinite(float(val)) and all(np.all(np.isfinite(x)) for x in jax.tree.leaves(g))
        out["grad_10s_finite"] = bool(finite)
        log(f"  10 s gradient at batch {batch} (compile + run, checkpoint=auto): {out['grad_10s_s']:.1f} s")
    return out


def compile_benchmarks(log) -> dict:
    """Seconds to trace and compile a new observer / scenario shape (batch 1024, 1 s)."""
    res = {}
    for name, build in (
        ("sogi-fll-wif", lambda: W.jax_fll("sogi-fll-wif", 1024, "loop", 1.0)),
        ("drive-sosoifo", lambda: W.jax_drive(1024, W.DRIVE_T1)),
    ):
        fn, args = build()
        t0 = time.perf_counter()
        fn.lower(args).compile()
        res[name] = time.perf_counter() - t0
        log(f"  compile {name} (batch 1024): {res[name]:.2f} s")
    return {"compile_s": res}


def table(res: dict) -> str:
    """The results as a text table: throughput rows, then the gradient, memory and compile figures."""
    head = ("workload", "impl", "dtype", "inputs", "batch", "M steps/s", "vs numba-par")
    lines = [f"{head[0]:14s} {head[1]:15s} {head[2]:5s} {head[3]:11s} {head[4]:>6s} {head[5]:>10s} {head[6]:>12s}"]
    for r in res["rows"]:
        ratio = "" if r["ratio_vs_numba_parallel"] is None else f"{r['ratio_vs_numba_parallel']:.2f}"
        lines.append(
            f"{r['workload']:14s} {r['impl']:15s} {r['dtype']:5s} {r['inputs']:11s} {r['batch']:6d} "
            f"{r['steps_per_s'] / 1e6:10.2f} {ratio:>12s}"
        )
    g = res["grad_over_forward"]
    lines.append("value_and_grad / forward: " + ", ".join(f"{k} {v:.2f}" for k, v in g.items()))
    mem = res["grad_temp_mb_10s"]
    lines.append("10 s gradient temporaries, MB: " + ", ".join(f"{k} {v:,.1f}" for k, v in mem.items()))
    lines.append("compile, s: " + ", ".join(f"{k} {v:.2f}" for k, v in res["compile_s"].items()))
    lines.append(f"devices: {len(res['devices'])} ({', '.join(res['devices'])})")
    return "\n".join(lines)
