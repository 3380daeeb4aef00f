"""Scenario-steps/s of the jaxobs workloads on this process's default JAX backend (a GPU, or the CPU).

``python -m benchmarks.devices [--batches 1024 8192 65536] [--dtypes f32 f64] [--ways map_batch vmap] [--out FILE]``

The rows are the throughput workloads of :mod:`benchmarks.workloads` as a user runs them — the SOGI-FLL 1 s
(10 000 steps) with its grid signal generated in the loop and read back from precomputed time-major rows, and
the sensorless drive 0.2 s (2 000 steps) — each compiled once and timed best of three after a warm-up call.
Three ways to run a batch can be timed side by side (``--ways``): ``map_batch`` (:func:`jaxobs.map_batch` as
it is called by default: the batch split over the devices, each share run ``jaxobs.runtime.sharding.TILE`` scenarios at
a time on a CPU and whole on an accelerator), ``tiled`` (``map_batch`` with ``tile=jaxobs.runtime.sharding.TILE`` on any
device) and ``vmap`` (one ``jax.vmap`` over the whole batch).  Run it once on the CPU and once on a GPU
(``JAX_PLATFORMS`` chooses); docs/performance.md, "On a GPU", puts the two in one table.  Precomputed rows stop at batch
8192: their inputs are ``batch × 10 000`` samples of four arrays (2.6 GB in float64 at 8192).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from functools import partial
from pathlib import Path

import jax

import jaxobs

from . import workloads as W
from .run import best_time


def rows(batches, dtypes, ways=("map_batch", "vmap"), log=print, out: Path | None = None) -> dict:
    """Time every (workload, dtype, batch, way) row; returns the JSON-ready result (rewritten to ``out`` after
    each row, so a run cut short keeps what it measured)."""
    dev = jax.devices()[0]
    res = {
        "backend": jax.default_backend(),
        "device": getattr(dev, "device_kind", str(dev)),
        "devices": len(jax.devices()),
        "host": platform.node(),
        "cpus": os.cpu_count(),
        "jax": jax.__version__,
        "rows": [],
    }
    for dt in dtypes:
        jax.config.update("jax_enable_x64", dt == "f64")
        for batch in batches:
            work = [("sogi-fll", "loop"), ("drive-sosoifo", "loop")]
            if batch <= 8192:
                work.insert(1, ("sogi-fll", "precomputed"))
            for name, inputs in work:
                for way in ways:
                    shard = way != "vmap"
                    tile = jaxobs.runtime.sharding.TILE if way == "tiled" else None
                    row = dict(workload=name, inputs=inputs, dtype=dt, batch=batch, way=way)
                    t0 = time.perf_counter()
                    try:
                        if name == "drive-sosoifo":
                            fn, args = W.jax_drive(batch, W.DRIVE_T1, shard=shard, tile=tile)
                            n = round(W.DRIVE_T1 / W.TS)
                        else:
                            fn, args = W.jax_fll(name, batch, inputs, W.FLL_T1, shard=shard, tile=tile)
                            n = round(W.FLL_T1 / W.TS)
                        compiled = fn.lower(args).compile()
                        compile_s = time.perf_counter() - t0
                        run = partial(compiled, args)
                        jax.block_until_ready(run())  # warm
                        t = best_time(run, 3)
                        row.update(steps_per_s=batch * n / t, run_s=t, compile_s=compile_s)
                    except Exception as e:  # noqa: BLE001  (out of memory on a big batch: reported, not fatal)
                        row["error"] = f"{type(e).__name__}: {str(e).splitlines()[0][:200]}"
                    res["rows"].append(row)
                    if "error" in row:
                        log(f"{name:14s} {inputs:11s} {dt} {batch:6d} {way:9s}: {row['error']}")
                    else:
                        log(
                            f"{name:14s} {inputs:11s} {dt} {batch:6d} {way:9s}: "
                            f"{row['steps_per_s'] / 1e6:10.1f} M steps/s  (run {t:.3f} s, compile {compile_s:.1f} s)"
                        )
                    if out is not None:
                        out.write_text(json.dumps(res, indent=1))
    return res


def _times(x: float) -> str:
    return f"{x:.1f}×" if x < 10 else f"{x:.0f}×"


def _rows_of(path: Path, backend: str) -> list[dict]:
    d = json.loads(path.read_text())
    return d["rows"] if d.get("backend") == backend else []


def table(gpu: list[dict], cpu: list[dict]) -> str:
    """A Markdown table of the accelerator's rows (each row's best way, and ``map_batch`` as called by default)
    beside the CPU's ``map_batch`` rows of the same workload, dtype and batch (the JSON results of two runs)."""
    key = lambda r: (r["workload"], r["inputs"], r["dtype"], r["batch"])  # noqa: E731
    cpu_rate = {key(r): r["steps_per_s"] for r in cpu if "error" not in r and r["way"] == "map_batch"}
    best: dict = {}
    default: dict = {}
    for r in gpu:
        if "error" in r:
            continue
        k = key(r)
        best[k] = max(best.get(k, 0.0), r["steps_per_s"])
        if r["way"] == "map_batch":
            default[k] = r["steps_per_s"]
    lines = [
        "| workload | dtype | batch | GPU, best way (M/s) | GPU, `map_batch` (M/s) | CPU, `map_batch` (M/s) "
        "| GPU / CPU |",
        "|---|---|---|---|---|---|---|",
    ]
    order = {"f32": 0, "f64": 1}
    for k in sorted(best, key=lambda k: (k[0], k[1], order[k[2]], k[3])):
        c = cpu_rate.get(k)
        d = default.get(k)
        lines.append(
            f"| {k[0]} ({k[1]}) | {k[2]} | {k[3]} | {best[k] / 1e6:.0f} | {'' if d is None else f'{d / 1e6:.0f}'} | "
            f"{'' if c is None else f'{c / 1e6:.1f}'} | {'' if c is None else _times(best[k] / c)} |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m benchmarks.devices",
        description=__doc__.split("``python -m")[0].strip() + " JAX_PLATFORMS=cpu (or cuda) picks the backend.",
    )
    p.add_argument("--batches", type=int, nargs="+", default=[1024, 8192, 65536], help="default 1024 8192 65536")
    p.add_argument("--dtypes", nargs="+", default=["f32", "f64"], choices=["f32", "f64"], help="default both")
    p.add_argument(
        "--ways",
        nargs="+",
        default=["map_batch", "vmap"],
        choices=["map_batch", "tiled", "vmap"],
        help="map_batch as called by default (tiles of 512 on a CPU, whole shares elsewhere), tiled (map_batch "
        "with tiles of 512 on any device), vmap (one vmap of the whole batch); default map_batch vmap",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="write the JSON result here (rewritten after each row; without it nothing is saved)",
    )
    p.add_argument(
        "--table",
        nargs=2,
        type=Path,
        metavar=("GPU_RESULTS", "CPU_RESULT.json"),
        default=None,
        help="print the Markdown table of earlier results instead of measuring: a folder or file of the "
        "accelerator's JSON results, and the CPU's",
    )
    a = p.parse_args(argv)
    if a.table is not None:
        g, c = a.table
        if not g.exists() or not c.is_file():
            p.error(f"--table: {g if not g.exists() else c} is not a results file (or a folder of them)")
        if json.loads(c.read_text()).get("backend") != "cpu":
            p.error(f"--table: {c} is not a CPU run's result (its backend is not cpu)")
        gpu = [r for f in (sorted(g.glob("*.json")) if g.is_dir() else [g]) for r in _rows_of(f, "gpu")]
        print(table(gpu, json.loads(c.read_text())["rows"]))
        return 0
    jaxobs.use_host_devices()  # before any computation: on a CPU, one JAX device per core, as `make bench`
    res = rows(a.batches, a.dtypes, a.ways, out=a.out)
    print(f"backend {res['backend']} ({res['device']}, {res['devices']} device(s), {res['cpus']} CPUs)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
