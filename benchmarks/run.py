"""Timing, the result rows, the text table: scenario-steps per second of jaxobs beside NumPy and numba.

Implementations: ``jaxobs`` (:mod:`benchmarks.workloads`: ``jit`` of
:func:`jaxobs.map_batch` over ``simulate``); ``jax-hand`` (each precomputed FLL hand-written in JAX: one
scan over time-major rows, :func:`benchmarks.workloads.jax_hand_fll`, equal to jaxobs; it separates what is
jaxobs's loop from what is XLA's CPU code generation); ``numba-inner``, the reference of
the ratios (the batch the inner SIMD loop over time-major arrays, threads over
batch blocks: how a performance engineer writes it); the earlier scalar
baselines, one scenario at a time, ``numba-scalar-par`` (``prange`` over
scenarios) and ``numba-scalar`` (serial); ``numpy`` (a Python loop over time,
vectorized over the batch): :mod:`benchmarks.baselines`, checked equal to
jaxobs in tests/test_bench.py and tests/test_bench_inner.py.  numba is
optional (``pip install -e '.[bench]'``).  The implementations of one row group
(workload, dtype, batch, inputs) are timed interleaved, best of ``repeats``
rounds, so a ratio compares timings taken side by side on this shared machine.

Besides throughput: compile time of a new observer shape, the
``value_and_grad``/forward time ratio per checkpointing strategy, and XLA's
temporary-buffer size of a 10 s (100k-step) gradient at batch 1024.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import jax
import numpy as np

from . import baselines
from . import workloads as W

DTYPES = {"f32": np.float32, "f64": np.float64}
CHECKPOINTS = ("auto", "none", "step", "chunk")


@dataclasses.dataclass
class Row:
    workload: str
    impl: str  # jaxobs | jax-hand | numba-inner | numba-scalar-par | numba-scalar | numpy
    dtype: str
    batch: int
    inputs: str  # loop | precomputed
    steps_per_s: float
    ratio_vs_numba_inner: float | None = None
    ratio_vs_numba_scalar_par: float | None = None


REF = "numba-inner"  # the ratios' reference: the batch-inner numba kernels


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


def _load_avg() -> list[float] | None:
    """The 1, 5 and 15 min load averages (other work on this machine at measurement time)."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


def _set_dtype(dt: str):
    jax.config.update("jax_enable_x64", dt == "f64")


def numba_available() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def run_bench(
    quick: bool = False,
    log: Callable[[str], None] = print,
    batches: tuple[int, ...] | None = None,
    serial: bool = True,
    partial_out: str | None = None,
) -> dict:
    """Run every benchmark; returns ``{"rows": [...], "grad_over_forward": ..., ...}``.

    ``batches`` replaces the default batch sizes; ``serial=False`` leaves out the serial scalar numba rows;
    ``partial_out``: a file rewritten with the rows measured so far after each row.

    ``quick``: a look at the reference rows: batch 1024, float64, the SOGI-FLL 0.1 s and the drive 0.05 s,
    jaxobs beside the batch-inner numba kernels (the ratios' reference) only, two rounds; most of its time is
    numba's compilation.
    """
    if batches is None:
        batches = (1024,) if quick else (1, 64, 1024, 8192)
    fll_t1, drive_t1 = (0.1, 0.05) if quick else (W.FLL_T1, W.DRIVE_T1)
    kinds = ("sogi-fll",) if quick else W.FLL_KINDS
    repeats = 2 if quick else 3
    dtypes = ("f64",) if quick else ("f32", "f64")
    scalar = not quick  # the scalar numba kernels: extra rows, not the reference
    serial = serial and scalar
    have_numba = numba_available()
    rows: list[Row] = []
    extra: dict = {"devices": [str(d) for d in jax.devices()], "numba": have_numba, "quick": quick}
    extra["batches"] = list(batches)
    extra["load_avg_start"] = _load_avg()
    if not have_numba:
        log("numba is not installed (pip install -e '.[bench]'): numba rows and ratios are left out")

    def add(row):
        rows.append(row)
        if partial_out:  # a run cut short keeps what it measured
            Path(partial_out).write_text(json.dumps({"rows": [dataclasses.asdict(r) for r in rows], "partial": True}))
        log(
            f"  {row.workload:14s} {row.impl:15s} {row.dtype} {row.inputs:11s} batch {row.batch:5d}: "
            f"{row.steps_per_s / 1e6:9.2f} M steps/s"
        )

    def timed(group: dict, steps: int, key: tuple):
        """Time the implementations of one row group interleaved: best of ``repeats`` rounds each."""
        for fn in group.values():
            jax.block_until_ready(fn())  # compiled and warm
        best = {k: math.inf for k in group}
        for _ in range(repeats):
            for k, fn in group.items():
                best[k] = min(best[k], best_time(fn, 1))
        for k, t in best.items():
            add(Row(key[0], k, key[1], key[2], key[3], steps / t))

    # batch outermost: the batch-1024 rows of every workload and dtype come first (a partial run has them)
    for batch in batches:
        for dt in dtypes:
            _set_dtype(dt)
            dtype = DTYPES[dt]
            n = round(fll_t1 / W.TS)
            for kind in kinds:
                for inputs in ("loop", "precomputed"):
                    fn, args = W.jax_fll(kind, batch, inputs, fll_t1)
                    group = {"jaxobs": partial(fn, args)}
                    if inputs == "precomputed":
                        # the same program hand-written in JAX: XLA's pace on the minimal step
                        hand, hargs = W.jax_hand_fll(batch, fll_t1, kind)
                        group["jax-hand"] = partial(hand, *hargs)
                    if have_numba:
                        run = baselines.numba_fll_inner(kind, dtype, inputs)
                        run(*baselines.fll_inner_args(kind, 2, dtype, inputs, 3))  # compile
                        group[REF] = partial(run, *baselines.fll_inner_args(kind, batch, dtype, inputs, n))
                        for par in (True, False) if scalar else ():
                            if not par and (batch > 1024 or not serial):
                                continue  # serial numba at 8192 adds minutes and no information
                            run = baselines.numba_fll(kind, dtype, par, inputs)
                            run(*baselines.fll_baseline_args(kind, 2, dtype, inputs, 3))  # compile
                            bargs = baselines.fll_baseline_args(kind, batch, dtype, inputs, n)
                            group["numba-scalar-par" if par else "numba-scalar"] = partial(run, *bargs)
                    timed(group, batch * n, (kind, dt, batch, inputs))
                if batch == 1024:
                    n_np = min(n, 1000)
                    t = best_time(partial(baselines.numpy_fll, kind, batch, dtype, n_np), 1)
                    add(Row(kind, "numpy", dt, batch, "loop", batch * n_np / t))
            # drive
            n = round(drive_t1 / W.TS)
            fn, args = W.jax_drive(batch, drive_t1)
            group = {"jaxobs": partial(fn, args)}
            if have_numba:
                w = np.asarray(W.drive_setup(batch)[3], dtype)
                run = baselines.numba_drive(dtype, True, inner=True)
                run(np.ones(2, dtype), 3)  # compile
                group[REF] = partial(run, w, n)
                for par in (True, False) if scalar else ():
                    if not par and (batch > 1024 or not serial):
                        continue
                    run = baselines.numba_drive(dtype, par)
                    run(np.ones(2, dtype), 3)  # compile
                    group["numba-scalar-par" if par else "numba-scalar"] = partial(run, w, n)
            timed(group, batch * n, ("drive-sosoifo", dt, batch, "loop"))
            if batch == 1024:
                n_np = min(n, 200)
                t = best_time(partial(baselines.numpy_drive, batch, dtype, n_np), 1)
                add(Row("drive-sosoifo", "numpy", dt, batch, "loop", batch * n_np / t))

    # ratios against the batch-inner numba kernels (and the scalar parallel ones) of the same row group
    for ref_impl, field in ((REF, "ratio_vs_numba_inner"), ("numba-scalar-par", "ratio_vs_numba_scalar_par")):
        ref = {(r.workload, r.dtype, r.batch, r.inputs): r.steps_per_s for r in rows if r.impl == ref_impl}
        for r in rows:
            key = (r.workload, r.dtype, r.batch, r.inputs)
            if key in ref:
                setattr(r, field, r.steps_per_s / ref[key])

    if have_numba:
        from .ceiling import ceilings

        log("ceilings:")
        extra["ceilings"] = ceilings(kinds, log)
    extra["load_avg"] = _load_avg()
    _set_dtype("f64")
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
    for ck in CHECKPOINTS:
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
    # three gains, one of which (ω_n) also sets the initial state
    names3 = ("k", "lam", "omega_n")
    loss3, params3 = W.fll_loss_fn(kind, t1, "auto", names3)
    fwd3, vg3 = jax.jit(loss3), jax.jit(jax.value_and_grad(loss3))
    jax.block_until_ready(vg3(params3, sig))
    jax.block_until_ready(fwd3(params3, sig))
    t_f, t_g = math.inf, math.inf
    for _ in range(3):
        t_f = min(t_f, best_time(partial(fwd3, params3, sig), 1))
        t_g = min(t_g, best_time(partial(vg3, params3, sig), 1))
    out["grad_over_forward_3_gains"] = t_g / t_f
    log(f"  value_and_grad / forward ({kind} gains {names3}, batch {batch}, {t1:g} s, f64, auto): {t_g / t_f:.2f}")
    for ck in CHECKPOINTS:
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
    head = ("workload", "impl", "dtype", "inputs", "batch", "M steps/s", "vs inner", "vs scalar-par")
    lines = [
        f"{head[0]:14s} {head[1]:16s} {head[2]:5s} {head[3]:11s} {head[4]:>6s} {head[5]:>10s} {head[6]:>9s} "
        f"{head[7]:>13s}"
    ]
    for r in res["rows"]:
        ratios = [
            "" if r.get(f) is None else f"{r[f]:.2f}" for f in ("ratio_vs_numba_inner", "ratio_vs_numba_scalar_par")
        ]
        lines.append(
            f"{r['workload']:14s} {r['impl']:16s} {r['dtype']:5s} {r['inputs']:11s} {r['batch']:6d} "
            f"{r['steps_per_s'] / 1e6:10.2f} {ratios[0]:>9s} {ratios[1]:>13s}"
        )
    g = res["grad_over_forward"]
    lines.append("value_and_grad / forward: " + ", ".join(f"{k} {v:.2f}" for k, v in g.items()))
    if res.get("grad_over_forward_3_gains") is not None:
        lines.append(f"value_and_grad / forward, gains k, lam, omega_n (auto): {res['grad_over_forward_3_gains']:.2f}")
    mem = res["grad_temp_mb_10s"]
    lines.append("10 s gradient temporaries, MB: " + ", ".join(f"{k} {v:,.1f}" for k, v in mem.items()))
    lines.append("compile, s: " + ", ".join(f"{k} {v:.2f}" for k, v in res["compile_s"].items()))
    lines.append(f"devices: {len(res['devices'])} ({', '.join(res['devices'])})")
    if res.get("ceilings"):
        c = res["ceilings"]
        lines.append(f"memory bandwidth (STREAM triad): {c['bandwidth_gbs']:.1f} GB/s")
        for dt, per in c["bound"].items():
            lines.append(
                f"ceiling {dt}, precomputed input, M steps/s: "
                + ", ".join(f"{k} {v / 1e6:.0f} (compute {c['compute'][dt][k] / 1e6:.0f})" for k, v in per.items())
            )
    lines.append(f"load average at start / end: {res.get('load_avg_start')} / {res.get('load_avg')}")
    return "\n".join(lines)
