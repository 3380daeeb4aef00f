"""The benchmark's baselines compute what jaxobs computes (float64), and `python -m benchmarks` runs."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks import baselines as B
from benchmarks import workloads as W

numba = pytest.importorskip("numba", reason="numba is the benchmark extra: pip install -e '.[bench]'")

ROOT = Path(__file__).resolve().parents[1]


# The baselines are the benchmark's concern and numba compiles each for 30-60 s on 2 cores: the slow suite
# (CI runs it) checks them; the default suite keeps the jaxobs side (tests/test_perf.py).
@pytest.mark.slow
@pytest.mark.parametrize("kind", W.FLL_KINDS)
def test_fll_baselines_equal_jaxobs(kind):
    n = 1500
    fn, args = W.jax_fll(kind, 4, "loop", n * W.TS, shard=False)
    ref = np.asarray(fn(args))
    # jaxobs reading the precomputed samples (SampledSignal) computes the same
    fn_pre, args_pre = W.jax_fll(kind, 4, "precomputed", n * W.TS, shard=False)
    np.testing.assert_allclose(np.asarray(fn_pre(args_pre)), ref, rtol=1e-12)
    for inputs in ("loop", "precomputed"):
        for par in (False, True):
            got = B.numba_fll(kind, np.float64, par, inputs)(*B.fll_baseline_args(kind, 4, np.float64, inputs, n))
            np.testing.assert_allclose(got, ref, rtol=1e-12)
    np.testing.assert_allclose(B.numpy_fll(kind, 4, np.float64, n), ref, rtol=1e-12)


@pytest.mark.slow
def test_drive_baselines_equal_jaxobs():
    n = 1200  # 0.12 s: past the hand-over to the observer (0.05 s) and the load step (0.1 s)
    fn, args = W.jax_drive(3, n * W.TS, shard=False)
    ref = np.asarray(fn(args))
    w = np.asarray(W.drive_setup(3)[3])
    for par in (False, True):
        np.testing.assert_allclose(B.numba_drive(np.float64, par)(w, n), ref, rtol=1e-10)
    np.testing.assert_allclose(B.numpy_drive(3, np.float64, n), ref, rtol=1e-10)


@pytest.mark.slow
def test_bench_quick_json(tmp_path):
    out = tmp_path / "bench.json"
    cmd = [sys.executable, "-m", "benchmarks", "--quick", "--json", "--out", str(out)]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=1800, cwd=ROOT, check=False)
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads(r.stdout)
    assert json.loads(out.read_text()) == res
    rows = res["rows"]
    assert {"workload", "impl", "dtype", "batch", "steps_per_s", "ratio_vs_numba_inner"} <= set(rows[0])
    # quick: float64, batch 1024, jaxobs beside the batch-inner numba kernels (the ratios' reference), NumPy and
    # the hand-written JAX kernel (precomputed SOGI-FLL only)
    assert {r["impl"] for r in rows} == {"jaxobs", "jax-hand", "numba-inner", "numpy"}
    assert {(r["workload"], r["inputs"]) for r in rows if r["impl"] == "jax-hand"} == {("sogi-fll", "precomputed")}
    assert {r["dtype"] for r in rows} == {"f64"} and {r["batch"] for r in rows} == {1024}
    assert res["ceilings"]["bandwidth_gbs"] > 0
    assert all(r["steps_per_s"] > 0 for r in rows)
    assert res["grad_temp_mb_10s"]["auto"] <= 64.0
    assert set(res["compile_s"]) == {"sogi-fll-wif", "drive-sosoifo"}
    # the bench process gave JAX one host device per usable core
    assert len(res["devices"]) == len(os.sched_getaffinity(0))  # jaxobs.use_host_devices(): one per usable core
