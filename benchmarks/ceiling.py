"""This machine's ceilings: memory bandwidth, a compute rate per workload, and the bound they set.

``python -m benchmarks.ceiling`` prints them; :func:`ceilings` is also part of ``python -m benchmarks``.

- **Memory bandwidth**: the STREAM triad a = b + s·c (numba, every thread, arrays of 64 MB, far
  beyond the caches), best of 5; bytes moved = 3 arrays × 8 B per element (the write-allocate read
  of ``a`` not counted, as STREAM does).
- **Compute rate of the FLL family**: the batch-inner numba kernel (benchmarks.kernels) reading a
  64-row input table round and round, so every operand stays in cache: the scenario-steps/s of the
  arithmetic alone (the 1/V̂² divide of the FLL normalization and the AB3 update), per dtype.
- **Bound per workload** (scenario-steps/s): with precomputed inputs each step streams the input
  sample and the true ω (2 numbers: 16 B in float64, 8 B in float32) while the state stays in cache,
  so the bound is min(bandwidth / bytes per step, compute rate).  With the input generated in the
  loop and for the drive nothing streams: they are compute-bound, and the only compute figure here
  is what the fastest implementation measured (no independent peak is claimed for them).

The clock (``/proc/cpuinfo``) is reported for reference.
"""

from __future__ import annotations

import math
import time

import numpy as np

from . import baselines
from . import kernels as K
from . import workloads as W

TRIAD_MB = 64
TABLE_ROWS = 64


def _best(fn, repeats: int = 5) -> float:
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def bandwidth_gbs() -> float:
    """STREAM triad bandwidth over every numba thread, GB/s (10^9 B/s)."""
    run = K.NUMBA_TRIAD[True]
    n = TRIAD_MB * 2**20 // 8
    a, b, c = np.zeros(n), np.ones(n), np.full(n, 2.0)
    run(a, b, c, 3.0)
    return 3 * 8 * n / _best(lambda: run(a, b, c, 3.0)) / 1e9


def fll_compute_rate(kind: str, dtype, batch: int = 1024, n: int = 5000) -> float:
    """Scenario-steps/s of the batch-inner FLL kernel with its inputs in cache (a 64-row table reused)."""
    run = K.NUMBA_FLL_INNER_CACHED[True]
    p, x0 = W.fll_baseline_params(kind)
    U, OM, _ = baselines.fll_inner_args(kind, batch, dtype, "precomputed", TABLE_ROWS)
    args = (baselines.FLL_KERNEL[kind], tuple(dtype(v) for v in x0), tuple(dtype(v) for v in p), U, OM)
    run(*args, 10, W.TS, dtype)
    return batch * n / _best(lambda: run(*args, n, W.TS, dtype))


def clock_mhz() -> float | None:
    try:
        with open("/proc/cpuinfo") as f:
            mhz = [float(line.split(":")[1]) for line in f if line.startswith("cpu MHz")]
        return max(mhz) if mhz else None
    except OSError:
        return None


def ceilings(kinds=W.FLL_KINDS, log=print) -> dict:
    """{"bandwidth_gbs", "clock_mhz", "compute": {dtype: {kind: steps/s}}, "bound": {dtype: {kind: steps/s}}}."""
    bw = bandwidth_gbs()
    log(f"  memory bandwidth (STREAM triad, every thread): {bw:.1f} GB/s")
    out = {"bandwidth_gbs": bw, "clock_mhz": clock_mhz(), "compute": {}, "bound": {}}
    for name, dtype in (("f32", np.float32), ("f64", np.float64)):
        item = np.dtype(dtype).itemsize
        out["compute"][name], out["bound"][name] = {}, {}
        for kind in kinds:
            c = fll_compute_rate(kind, dtype)
            mem = bw * 1e9 / (2 * item)
            out["compute"][name][kind] = c
            out["bound"][name][kind] = min(c, mem)
            log(
                f"  {kind} {name}: compute (inputs in cache) {c / 1e6:.0f} M steps/s, bandwidth bound "
                f"{mem / 1e6:.0f} M steps/s at {2 * item} B/step -> ceiling {min(c, mem) / 1e6:.0f} M steps/s "
                f"({'memory' if mem < c else 'compute'}-bound)"
            )
    return out


if __name__ == "__main__":
    ceilings()
