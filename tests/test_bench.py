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
    # the command's own default device count (one per usable core), not the suite's one device (conftest.py)
    env = {k: v for k, v in os.environ.items() if k != "JAXOBS_HOST_DEVICES"}
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=1800, cwd=ROOT, check=False, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads(r.stdout)
    assert json.loads(out.read_text()) == res
    rows = res["rows"]
    assert {"workload", "impl", "dtype", "batch", "steps_per_s", "ratio_vs_numba_inner"} <= set(rows[0])
    # quick: float64, batch 1024, jaxobs beside the batch-inner numba kernels (the ratios' reference), NumPy and
    # the hand-written JAX kernels (every precomputed FLL)
    assert {r["impl"] for r in rows} == {"jaxobs", "jax-hand", "numba-inner", "numpy"}
    assert {(r["workload"], r["inputs"]) for r in rows if r["impl"] == "jax-hand"} == {
        (k, "precomputed") for k in {r["workload"] for r in rows} if k in W.FLL_KINDS
    }
    assert {r["dtype"] for r in rows} == {"f64"} and {r["batch"] for r in rows} == {1024}
    assert res["ceilings"]["bandwidth_gbs"] > 0
    assert all(r["steps_per_s"] > 0 for r in rows)
    assert res["grad_temp_mb_10s"]["auto"] <= 64.0
    assert set(res["compile_s"]) == {"sogi-fll-wif", "drive-sosoifo"}
    # the bench process gave JAX one host device per usable core
    assert len(res["devices"]) == len(os.sched_getaffinity(0))  # jaxobs.use_host_devices(): one per usable core


# The full run's parts after the throughput rows (time to result and scale): the command line and the tables,
# the measurements themselves replaced by given rows (each runs minutes: benchmarks/README.md)
def test_bench_parts_from_the_command_line(capsys):
    from benchmarks.__main__ import parse_args

    assert parse_args([]).parts == ("throughput", "time-to-result", "scale")
    assert parse_args(["--quick"]).parts == ("throughput",)
    assert parse_args(["--only", "scale", "time-to-result"]).parts == ("time-to-result", "scale")
    assert parse_args(["--no-scale"]).parts == ("throughput", "time-to-result")
    assert parse_args(["--no-time-to-result", "--no-scale", "--batches", "1024"]).parts == ("throughput",)
    for bad in (
        ["--quick", "--only", "scale"],
        ["--only", "scale", "--no-scale"],
        ["--only", "scale", "--batches", "1024"],
        ["--only", "time-to-result", "--no-serial"],
        ["--only", "speed"],
    ):
        with pytest.raises(SystemExit) as e:
            parse_args(bad)
        assert e.value.code == 2, bad
    capsys.readouterr()


TTR_ROWS = [
    {"command": "make-run", "tree": "installed", "run": i, "wall_s": w, "cpu_s": c, "load": [1.0, 1.5]}
    | {"trace_s": 2.0, "lower_s": 1.0, "compile_s": k, "jits": 9, "in_process_s": w - 1, "cache_mib": 0.9}
    for i, w, c, k in ((1, 50.0, 30.0, 20.0), (2, 20.0, 12.0, 2.0))
]


def _scale_row(kind, n):
    return {"kind": kind, "scenarios": n, "streamed": True, "study_s": 60.0, "with_netcdf_s": 62.5}


def test_bench_only_time_to_result_and_scale(monkeypatch, tmp_path, capsys):
    from benchmarks import __main__ as bench
    from benchmarks import first_second, scale

    calls = []

    def fake_ttr(cmds, runs, log=None):
        calls.append(("time-to-result", tuple(cmds), runs))
        for r in TTR_ROWS:
            log(r)
        return TTR_ROWS

    def fake_scale(scenarios, kind, log=print):
        calls.append(("scale", kind, tuple(scenarios)))
        return [
            _scale_row(kind, n) | {"scenarios_per_s": 16000, "peak_rss_mib": 581, "horizon": 0.01, "load": [2.0, 2.5]}
            for n in scenarios
        ]

    def no_throughput(**kw):
        raise AssertionError("--only time-to-result scale ran the throughput rows")

    monkeypatch.setattr(first_second, "measure", fake_ttr)
    monkeypatch.setattr(scale, "measure", fake_scale)
    monkeypatch.setattr(bench, "run_bench", no_throughput)
    out = tmp_path / "bench.json"
    assert bench.main(["--only", "time-to-result", "scale", "--out", str(out)]) == 0
    # the full run's sizes: make run twice; FLL at 10⁶ scenarios, drive at 10⁵
    assert calls == [("time-to-result", ("make-run",), 2), ("scale", "fll", (10**6,)), ("scale", "drive", (10**5,))]
    res = json.loads(out.read_text())
    assert res["time_to_result"] == TTR_ROWS
    assert [(r["kind"], r["scenarios"], r["peak_rss_mib"]) for r in res["scale"]] == [
        ("fll", 10**6, 581),
        ("drive", 10**5, 581),
    ]
    assert "rows" not in res and set(res["parts_s"]) == {"time-to-result", "scale"}
    text = capsys.readouterr().out
    lines = text.splitlines()
    # the time-to-result table: run 2 over run 1, wall 20 / 50 and CPU 12 / 30; the rest = wall - the phases
    assert "| make-run | installed | 2 | 20.0 | 12.0 | 0.40 | 0.40 | 2.0 | 1.0 | 2.0 | 15.0 | 0.9 | 1.0, 1.5 |" in lines
    assert "| fll | 1,000,000 | 0.01 | yes | 60.0 | 62.5 | 16,000 | 581 | 2.0, 2.5 |" in lines
    assert "| drive | 100,000 | 0.01 | yes | 60.0 | 62.5 | 16,000 | 581 | 2.0, 2.5 |" in lines
    assert text.index("time to result") < text.index("scale (")


def test_bench_a_failed_part_keeps_the_others(monkeypatch, tmp_path, capsys):
    from benchmarks import __main__ as bench
    from benchmarks import first_second, scale

    def broken(*a, **kw):
        raise subprocess.CalledProcessError(1, ["python", "-m", "benchmarks.scale"])

    monkeypatch.setattr(first_second, "measure", lambda cmds, runs, log=None: TTR_ROWS)
    monkeypatch.setattr(scale, "measure", broken)
    out = tmp_path / "bench.json"
    assert bench.main(["--only", "time-to-result", "scale", "--json", "--out", str(out)]) == 1
    res = json.loads(out.read_text())
    assert res == json.loads(capsys.readouterr().out)
    assert res["time_to_result"] == TTR_ROWS
    assert res["scale"]["error"].startswith("CalledProcessError")
    assert "failed" in bench.extra.tables(res)


def test_the_gpu_table_pairs_each_accelerator_row_with_the_cpu_row_and_skips_failed_ones():
    from benchmarks.devices import table

    row = dict(workload="drive-sosoifo", inputs="loop", dtype="f64", batch=8192)
    gpu = [
        {**row, "way": "vmap", "steps_per_s": 112e6},
        {**row, "way": "map_batch", "steps_per_s": 111e6},
        {**row, "batch": 65536, "way": "vmap", "error": "TypeError: ..."},
    ]
    cpu = [{**row, "way": "map_batch", "steps_per_s": 7.5e6}, {**row, "way": "tiled", "steps_per_s": 1e9}]
    lines = table(gpu, cpu).splitlines()
    assert len(lines) == 3  # header, rule, one row: the failed row is left out
    assert lines[2] == "| drive-sosoifo (loop) | f64 | 8192 | 112 | 111 | 7.5 | 15× |"


def test_first_second_says_which_command_needs_a_result():
    from benchmarks.first_second import COMMANDS, _one

    with pytest.raises(ValueError, match="--result"):
        _one(COMMANDS["envelope-200x3"], {}, Path("unused"))


def test_first_second_summary_gives_each_target_and_its_verdict(tmp_path):
    """The summary: cold and warm per tree, before → after, the target and met / not met from the wall time (a
    warm make-run against both its 25 s and 0.40 × its cold run), † where the load was above half the cores;
    rows of an earlier file (an old one naming its trees by folder) join with their file's name."""
    from benchmarks.first_second import load_rows, summary

    def row(cmd, tree, run, wall, load=0.5):
        return {"command": cmd, "tree": tree, "run": run, "wall_s": wall, "cpu_s": wall * 0.9, "load": [load, load]}

    rows = [
        row("help", "before", 1, 3.1),
        row("help", "after", 1, 0.1),
        row("make-run", "before", 1, 30.0),
        row("make-run", "after", 1, 18.0, load=1.4),
        row("make-run", "before", 2, 10.0),
        row("make-run", "after", 2, 8.0),  # 8 / 18 = 0.44 > 0.40: not met though under 25 s
    ]
    lines = summary(rows, cpus=2).splitlines()
    assert lines[0].startswith("| command | run | target | before: wall / CPU (s), load | after:")
    assert (
        lines[2] == "| help | cold | ≤ 0.5 s | 3.10 / 2.79: **not met**, 0.5–0.5 | 0.10 / 0.09: met, 0.5–0.5 | 0.03 |"
    )
    assert (
        lines[3]
        == "| make-run | cold | ≤ 20 s | 30.0 / 27.0: **not met**, 0.5–0.5 | 18.0 / 16.2: met, 1.4–1.4† | 0.60 |"
    )
    assert lines[4].startswith(
        "| make-run | warm | ≤ 25 s and ≤ 0.40 × cold | 10.0 / 9.00: met, 0.5–0.5 | 8.00 / 7.20: **not"
    )
    assert lines[-2] == "trees: before = None; after = None" and lines[-1].startswith("† load above 1 (2 cores)")
    old = tmp_path / "old.json"
    old.write_text(json.dumps({"rows": [row("make-test", "/tmp/b", 1, 825.0)], "trees": {"/tmp/b": "18b2a8b"}}))
    (merged,) = load_rows(str(old))
    assert (merged["tree"], merged["commit"], merged["source"]) == ("tree 1", "18b2a8b", "old.json")
    assert "| make-test | cold | ≤ 360 s | 825.0 / 742.5: **not met**, 0.5–0.5 [old.json] |" in summary(
        [merged], cpus=2
    )
