"""The times and counts the README and the docs quote, measured: ``python -m benchmarks.readme_numbers``.

Writes ``benchmarks/results/readme_numbers.json`` (merged with what is already there, so one part can be
re-measured alone) and prints it.  Parts (``--only`` picks some; the default runs the cheap ones):

- ``count``: the tests ``make test`` runs and the ones ``make test-slow`` runs (``pytest --collect-only``; seconds);
- ``tour``: the wall time of each CLI command of the README's tour that is cheap (``closed-form``, ``study``,
  the two ``export``\\ s; about 2 minutes on 2 busy cores), in a fresh folder;
- ``run`` (expensive): ``make run``'s command, the default tuning job, in a fresh folder (40 s quiet, minutes under
  load);
- ``venv`` (expensive, network): the first-use build of ``.venv`` (``python -m venv`` and ``pip install -e
  .[test,bench]``) into a temporary folder;
- ``test`` (expensive): ``make test``'s wall time (``--cached``: the compile cache as it is; else on an empty one).

Every timing records its wall and CPU seconds (``getrusage`` of the children), the machine's load average and
core count beside it: the README quotes a time with the load
it was measured under.  Times on a shared 2-core machine vary by up to 4x within minutes.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "readme_numbers.json"
CHEAP = ("count", "tour")
ALL = ("count", "tour", "run", "venv", "test")


def _context() -> dict:
    return {
        "when": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "load_average_1min": round(os.getloadavg()[0], 2),
        "cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
    }


def _timed(cmd: list[str], cwd: Path, env: dict | None = None, timeout: float = 3600) -> dict:
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)  # the command and the children it waited for
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({r.returncode}): {r.stderr[-1500:]}")
    shown = [Path(cmd[0]).name, *cmd[1:]]  # `jaxobs ...`, `python -m ...`: not this machine's paths
    return {"command": " ".join(shown), "wall_s": round(wall, 1), "cpu_s": round(cpu, 1), **_context()}


def _jaxobs() -> str:
    return str(Path(sys.executable).with_name("jaxobs"))


def count_tests() -> dict:
    out = {}
    for name, marker in (("make_test", "not slow and not repro"), ("make_test_slow", "slow")):
        r = subprocess.run(
            [sys.executable, "-m", "pytest", "--collect-only", "-q", "-m", marker, "-p", "no:randomly"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=900,
        )
        m = re.search(r"(\d+)(?:/\d+)? tests? collected", r.stdout) or re.search(r"(\d+) selected", r.stdout)
        if m is None:
            raise RuntimeError(f"pytest --collect-only -m {marker!r}: no count in {r.stdout[-500:]}")
        out[name] = int(m.group(1))
    return {"tests": {**out, **_context()}}


def tour() -> dict:
    """The README's cheap tour commands (not `tune`: that is `run`), each in order in one fresh folder; the
    exports read the default job's result, so a result is made first by a short job (its time is not quoted)."""
    from importlib import resources

    with tempfile.TemporaryDirectory() as d:
        cwd = Path(d)
        j = _jaxobs()
        rows = {"closed_form": _timed([j, "closed-form", "wif", "--quiet"], cwd)}
        rows["study"] = _timed([j, "study", "--out", "out/tour/study", "--quiet"], cwd)
        job = cwd / "short.toml"
        text = (resources.files("jaxobs_tuning") / "presets" / "wif_robust.toml").read_text()
        job.write_text(re.sub(r"(?m)^steps = \d+", "steps = 2", text))
        subprocess.run(
            [j, "tune", str(job), "--out", "out/tour/tune", "--quiet"],
            cwd=cwd,
            check=True,
            timeout=1800,
            capture_output=True,
        )
        rows["export_result"] = _timed(
            [j, "export", "out/tour/tune/result.json", "--out", "out/tour/c-tuned", "--quiet"], cwd
        )
        rows["export_closed_form"] = _timed(
            [j, "export", "--design", "wif", "--rule", "tustin", "--out", "out/tour/c-wif", "--quiet"], cwd
        )
    return {"tour": rows}


def make_run() -> dict:
    with tempfile.TemporaryDirectory() as d:
        return {"make_run": _timed([_jaxobs(), "tune", "--out", "out/tune", "--force", "--quiet"], Path(d))}


def venv_build() -> dict:
    with tempfile.TemporaryDirectory() as d:
        venv = Path(d) / "venv"
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        py = str(venv / "bin" / "python")
        subprocess.run([py, "-m", "pip", "install", "--quiet", "--upgrade", "pip"], check=True)
        subprocess.run([py, "-m", "pip", "install", "--quiet", f"{ROOT}[test,bench]"], check=True)
        return {"venv_build": {"wall_s": round(time.perf_counter() - t0, 1), **_context()}}


def make_test(cached: bool) -> dict:
    env = dict(os.environ)
    tmp = None
    if not cached:
        tmp = tempfile.mkdtemp()
        env["JAXOBS_TEST_CACHE"] = tmp  # an empty compile cache: the first run's time
    try:
        cmd = [sys.executable, "-m", "pytest", "-m", "not slow and not repro", "-n", "auto", "-q"]  # the Makefile's
        key = "make_test_cached" if cached else "make_test_first"
        return {key: _timed(cmd, ROOT, env=env, timeout=7200)}
    finally:
        if tmp:
            shutil.rmtree(tmp, ignore_errors=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.readme_numbers", description=__doc__.splitlines()[0])
    p.add_argument("--only", nargs="+", choices=ALL, default=list(CHEAP), help="parts to measure (default: cheap)")
    p.add_argument("--cached", action="store_true", help="test: time make test with the compile cache as it is")
    p.add_argument("--out", type=Path, default=OUT)
    a = p.parse_args(argv)
    data = json.loads(a.out.read_text()) if a.out.exists() else {}
    parts = {"count": count_tests, "tour": tour, "run": make_run, "venv": venv_build}
    for part in a.only:
        data.update(make_test(a.cached) if part == "test" else parts[part]())
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")  # after each part: a kill keeps the rest
    print(json.dumps(data, indent=2, sort_keys=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
