"""Time to result: a command's first run with an empty compilation cache, then its second.

    python -m benchmarks.first_second [--runs 2] [--cmd NAME ...] [--tree BEFORE AFTER] [--result FILE] [--out F]

Each command runs ``--runs`` times in fresh processes (``python -m jaxobs_tuning.cli ...``) sharing one
compilation cache folder (``JAXOBS_CACHE_DIR``) that starts empty: run 1 compiles everything, the later runs
read what the persistent cache kept.  Reported per run: the wall time, the CPU time the process used
(user + system, ``resource.getrusage(RUSAGE_CHILDREN)``: on a shared machine this moves far less with the
load than the wall time does), the cache folder's size after it, and the 1-minute load average at its start
and end.  The ratio run 2 / run 1 is given for both times; ``make run``'s target is ≤ 0.40 and ≤ 25 s warm.

Where a run's time goes, from JAX's own monitoring events (``jax.monitoring``, time spans; nested spans of
one kind counted once): *trace* (Python tracing of jitted functions to jaxprs), *lower* (jaxpr → StableHLO,
which the persistent cache needs for its key), *compile* (XLA compilation, or the cache's read on a hit),
and the rest of the wall time (*run + Python*: the computations themselves, imports, I/O, figures).  The
persistent cache keeps only the *compile* part: tracing and lowering are paid by every process.

:func:`measure` gives the rows and :func:`table` the Markdown table; ``make bench`` (``python -m benchmarks``)
calls them for ``make-run``, two runs, after its throughput rows (:mod:`benchmarks.extra`).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PRESETS = Path(__file__).resolve().parents[1] / "tuning" / "presets"

# name -> the command line's arguments (after `jaxobs`); OUT is replaced by a fresh output folder
COMMANDS = {
    "make-run": ["tune", "--out", "OUT", "--force", "--quiet"],
    # a drive preset: the C-LESO on the IPMSM (30 Adam steps, 2 s horizon), verified over its envelope
    "drive-preset": ["tune", str(PRESETS / "cleso.toml"), "--out", "OUT", "--force", "--quiet"],
    "study-fll": ["study", "--out", "OUT", "--force", "--quiet"],
    "study-drive": ["study", str(PRESETS / "study_flux_drive.toml"), "--out", "OUT", "--force", "--quiet"],
    "reproduce-flux": ["reproduce", "flux", "--quick", "--out", "OUT", "--force"],
    "reproduce-leso": ["reproduce", "leso", "--out", "OUT", "--force"],
    # a drive result's envelope at its default size: 20 speeds x 10 loads x its 3 designs (RESULT: --result,
    # e.g. the result.json of `jaxobs tune tuning/presets/cleso.toml`)
    "envelope-200x3": [
        "envelope",
        "RESULT",
        *("--speeds", "20", "--loads", "10"),
        "--out",
        "OUT",
        "--force",
        "--quiet",
    ],
    # the envelope's smallest map: 2 speeds x 1 load of the SOIFO preset, 0.5 s runs
    "envelope": [
        "envelope",
        str(PRESETS / "soifo.toml"),
        *("--speeds", "2", "--loads", "1", "--horizon", "0.5"),
        *("--out", "OUT", "--force", "--quiet"),
    ],
}


_PHASES = {
    "trace_s": "/jax/core/compile/jaxpr_trace_duration",
    "lower_s": "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "compile_s": "/jax/core/compile/backend_compile_duration",
}


def _union(spans: list[tuple[float, float]]) -> float:
    """Seconds covered by ``spans`` (a span inside another, a nested jit's trace, counted once)."""
    total, end = 0.0, -float("inf")
    for a, b in sorted(spans):
        if b > end:
            total += b - max(a, end)
            end = b
    return total


def _worker(report: str, argv: list[str]) -> int:
    """Run the command line in this process with JAX's compile events recorded; the phases to ``report``."""
    t0 = time.time()
    import jax.monitoring

    spans: dict[str, list] = {k: [] for k in _PHASES}
    kinds = {v: k for k, v in _PHASES.items()}

    def on_span(event, start, end, **_):
        if event in kinds:
            spans[kinds[event]].append((start, end))

    jax.monitoring.register_event_time_span_listener(on_span)
    from jaxobs_tuning.cli import main

    rc = main(argv)
    phases = {k: round(_union(v), 2) for k, v in spans.items()}
    phases["jits"] = len(spans["compile_s"])
    phases["in_process_s"] = round(time.time() - t0, 2)
    Path(report).write_text(json.dumps(phases))
    return rc


def _dir_size(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def _one(args: list[str], env: dict, out: Path, result: str | None = None) -> dict:
    report = out.with_suffix(".phases.json")
    # this file run as a script: with --tree, jaxobs and jaxobs_tuning come from that tree's PYTHONPATH
    argv = [sys.executable, str(Path(__file__).resolve()), "--worker", str(report)]
    if "RESULT" in args and result is None:
        raise ValueError("first_second: this command needs --result PATH (a drive job's result.json)")
    argv += [str(out) if a == "OUT" else str(Path(result).resolve()) if a == "RESULT" else a for a in args]
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    proc = subprocess.run(argv, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode not in (0, 3, 4):
        sys.stderr.write(proc.stdout[-2000:] + proc.stderr[-4000:])
        raise SystemExit(f"{' '.join(argv)} exited {proc.returncode}")
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    row = {"wall_s": round(wall, 2), "cpu_s": round(cpu, 2), "load": [round(load0, 1), round(os.getloadavg()[0], 1)]}
    return {**row, **json.loads(report.read_text())}


def measure(
    cmds=("make-run",),
    runs: int = 2,
    trees: list[str] | None = None,
    keep_cache: str | None = None,
    log=None,
    result: str | None = None,
) -> list[dict]:
    """First and later runs of each of ``cmds`` (names of :data:`COMMANDS`), ``runs`` each; one row a run.

    ``trees``: source trees to compare (each its own cache, their runs interleaved), default the installed
    jaxobs; ``keep_cache``: use (and keep) this cache folder instead of a temporary one; ``log``: called with
    each row as it is measured (default: its JSON on stderr); ``result``: the result file of the commands
    that read one (``envelope-200x3``).  A row: ``command``, ``tree``, ``run``,
    ``wall_s``, ``cpu_s``, ``load`` (1-min load average at its start and end), the phases ``trace_s``,
    ``lower_s``, ``compile_s`` (s), ``jits``, ``in_process_s`` and ``cache_mib`` (the cache after it).
    """
    unknown = [c for c in cmds if c not in COMMANDS]
    if unknown:
        raise ValueError(f"first_second: unknown command(s) {unknown}; known: {sorted(COMMANDS)}")
    if log is None:

        def log(row):
            print(json.dumps(row), file=sys.stderr, flush=True)

    rows = []
    with tempfile.TemporaryDirectory(prefix="jaxobs-first-second-") as tmp:
        envs = {}
        for j, tree in enumerate(trees or [None]):
            env = dict(os.environ)
            if tree is not None:  # the tree's jaxobs, and its tuning/ as jaxobs_tuning (the installed layout)
                pp = Path(tmp) / f"pp-{j}"
                pp.mkdir()
                (pp / "jaxobs_tuning").symlink_to(Path(tree).resolve() / "tuning")
                env["PYTHONPATH"] = f"{Path(tree).resolve()}{os.pathsep}{pp}"
            envs[tree or "installed"] = env
        for name in cmds:
            caches = {}
            for t in envs:
                cache = Path(keep_cache) if keep_cache else Path(tmp) / f"cache-{name}-{len(caches)}"
                shutil.rmtree(cache, ignore_errors=True)
                caches[t] = cache
            for i in range(1, runs + 1):
                for t, env in envs.items():
                    env = {**env, "JAXOBS_CACHE_DIR": str(caches[t])}
                    out = Path(tmp) / f"out-{name}-{len(rows)}"
                    row = {"command": name, "tree": t, "run": i, **_one(COMMANDS[name], env, out, result)}
                    row["cache_mib"] = round(_dir_size(caches[t]) / 2**20, 1)
                    rows.append(row)
                    log(row)
    return rows


def table(rows: list[dict]) -> str:
    """The rows of :func:`measure` as a Markdown table, each run's times also over its command's run 1."""
    lines = [
        "| command | tree | run | wall (s) | CPU (s) | wall / run 1 | CPU / run 1 | trace (s) | lower (s) | compile or "
        "cache read (s) | run + Python (s) | cache (MiB) | load (start, end) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    first = {}
    for r in rows:
        f = first.setdefault((r["command"], r["tree"]), r)
        lines.append(
            f"| {r['command']} | {r['tree']} | {r['run']} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | "
            f"{r['wall_s'] / f['wall_s']:.2f} | "
            f"{r['cpu_s'] / f['cpu_s']:.2f} | {r['trace_s']:.1f} | {r['lower_s']:.1f} | {r['compile_s']:.1f} | "
            f"{r['wall_s'] - r['trace_s'] - r['lower_s'] - r['compile_s']:.1f} | {r['cache_mib']:.1f} | "
            f"{r['load'][0]:.1f}, {r['load'][1]:.1f} |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["--worker"]:
        return _worker(argv[1], argv[2:])
    p = argparse.ArgumentParser(prog="python -m benchmarks.first_second", description=__doc__.split("\n")[0])
    p.add_argument(
        "--cmd",
        nargs="+",
        default=["make-run"],
        choices=sorted(COMMANDS),
        help="commands to time (default make-run; each one's command line is in COMMANDS, this file)",
    )
    p.add_argument("--runs", type=int, default=2, help="runs per command (the first with an empty cache)")
    p.add_argument(
        "--keep-cache",
        help="a cache folder to use instead of a temporary one: EMPTIED before each command's first run and kept "
        "after (shared by every --tree); never point it at a cache you want to keep",
    )
    p.add_argument(
        "--tree",
        nargs="+",
        help="source trees to compare (each its own cache; their runs interleaved: run 1 of each, then run 2 "
        "...); default: the installed jaxobs",
    )
    p.add_argument("--result", help="a drive job's result.json, for envelope-200x3")
    p.add_argument("--out", help="also write the rows (and the load, the trees' commits) to this JSON file")
    p.add_argument("--json", action="store_true", help="print the rows as JSON")
    a = p.parse_args(argv)
    if any("RESULT" in COMMANDS[c] for c in a.cmd) and not a.result:
        p.error("--result PATH is needed by: " + ", ".join(c for c in a.cmd if "RESULT" in COMMANDS[c]))
    rows = measure(a.cmd, a.runs, a.tree, a.keep_cache, result=a.result)
    if a.out:
        commits = {}
        for t in a.tree or []:
            git = subprocess.run(["git", "-C", t, "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
            commits[t] = git.stdout.strip() or None
        Path(a.out).write_text(json.dumps({"rows": rows, "trees": commits, "cpus": os.cpu_count()}, indent=1))
    if a.json:
        print(json.dumps(rows, indent=1))
        return 0
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
