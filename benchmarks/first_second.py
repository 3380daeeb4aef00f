"""Time to result: a command's first run with an empty compilation cache, then its second.

    python -m benchmarks.first_second [--runs 2] [--cmd NAME ...] [--tree BEFORE AFTER] [--result FILE]
        [--out F] [--with EARLIER.json ...]

Each command runs ``--runs`` times in fresh processes sharing one compilation cache folder
(``JAXOBS_CACHE_DIR``, and ``JAXOBS_TEST_CACHE`` for the test suite) that starts empty: run 1 compiles
everything (*cold*), the later runs read what the persistent cache kept (*warm*).  A command runs as the
``jaxobs`` console script runs it (``jaxobs_tuning.cli_entry.main``; in a tree from before that entry,
``jaxobs_tuning.cli.main``, its console script then), in a process that has imported nothing else of the
project: the worker is this file run as a script, whose own imports (the standard library's) take a few
hundredths of a second.  Reported per run: the wall time, the CPU time the process and its children used
(user + system, ``resource.getrusage(RUSAGE_CHILDREN)``: on a shared machine this moves far less with the
load than the wall time does), the cache folder's size after it, and the 1-minute load average at its start
and end.

Where a run's time goes, from JAX's own monitoring events (``jax.monitoring``, time spans; nested spans of
one kind counted once): *trace* (Python tracing of jitted functions to jaxprs), *lower* (jaxpr → StableHLO,
which the persistent cache needs for its key), *compile* (XLA compilation, or the cache's read on a hit),
and the rest of the wall time (*run + Python*: the computations themselves, imports, I/O, figures).  The
persistent cache keeps only the *compile* part: tracing and lowering are paid by every process.  The
commands that must answer without a compilation (``help``, ``drive-check``, :data:`LIGHT`) are run without
the listener (registering it imports JAX, the very cost they are timed for): no phases, and the row says
whether JAX was imported at all.

The commands (:data:`COMMANDS`) and the project's targets (:data:`TARGETS`, wall seconds on a quiet machine):
``jaxobs --help`` ≤ 0.5 s; ``jaxobs drive check`` of the lab IPMSM file ≤ 2 s; the default job
(``make-run``) ≤ 20 s cold and warm ≤ 25 s and ≤ 0.40 of its cold run; a C-LESO result's envelope at
200 points × 3 designs (``envelope-200x3``, ``--result`` the result.json of ``jaxobs tune
tuning/presets/cleso.toml --out X``; one per tree where a tree cannot read another's) ≤ 30 s cold, ≤ 15 s
warm; ``make test`` (``make-test``: the suite as the Makefile runs it, in the tree's folder, with an empty
``JAXOBS_TEST_CACHE``) ≤ 6 min cold.  The summary
table (:func:`summary`) gives each command's cold and warm wall / CPU seconds per tree (``before → after``
with two trees) and whether each meets its target; a run at a load above half the cores is marked, since
the targets are a quiet machine's.

``make-test`` is opt-in: about 14 minutes a tree on the shared 2-core machine, so it is not run beside the
other commands.  Run it alone (``--cmd make-test --runs 1 --tree BEFORE AFTER --out A.json``, its own
date and load in that file) and merge it into the full table with ``--with A.json``; a merged row names
the file it came from, so a row is never presented as measured in a run it was not.

``--tree`` takes a folder (a checkout) or a git revision of this repository (exported with ``git archive``
into a temporary folder: the commit as committed); the first is labelled *before* and the last *after*.

:func:`measure` gives the rows, :func:`table` the per-run Markdown table and :func:`summary` the targets'
table; ``make bench`` (``python -m benchmarks``) calls :func:`measure` and :func:`table` for ``make-run``, two
runs, after its throughput rows (:mod:`benchmarks.extra`).
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

ROOT = Path(__file__).resolve().parents[1]
PRESETS = ROOT / "tuning" / "presets"
DRIVE_FILE = ROOT / "docs" / "examples" / "ipmsm_2p2kw_lab.toml"

# name -> the command line's arguments (after `jaxobs`); OUT is replaced by a fresh output folder; a command that
# starts with PYTEST is the tree's test suite (`python -m pytest ARGS` in the tree's folder), not a jaxobs command
COMMANDS = {
    "help": ["--help"],
    # the plain check of the lab IPMSM file (the file's arithmetic, no closed loop; the same file for every tree)
    "drive-check": ["drive", "check", str(DRIVE_FILE)],
    # the same with its closed-loop runs (the rated point and the top speed, one compiled batch; no target; a tree
    # without --simulate, 7af787e among them, exits 2: time it on the trees that have it)
    "drive-simulate": ["drive", "check", str(DRIVE_FILE), "--simulate", "--quiet"],
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
    # a new user's map of the traction IPMSM: 4 speeds x 3 loads of its reduced-order flux observer job's two
    # designs (docs/examples/traction_rofo_tune.toml; a tree from before that file cannot run it)
    "envelope-traction-4x3": [
        "envelope",
        str(PRESETS.parents[1] / "docs" / "examples" / "traction_rofo_tune.toml"),
        *("--speeds", "4", "--loads", "3"),
        *("--out", "OUT", "--force", "--quiet"),
    ],
    # `make test` as the Makefile runs it (-q only shortens its output); opt-in: about 14 min a tree
    "make-test": ["PYTEST", "-m", "not slow and not repro", "-n", "auto", "-q"],
}

# commands timed without JAX's monitoring listener: they must answer without compiling (or importing) JAX
LIGHT = frozenset({"help", "drive-check"})

# name -> the targets, wall seconds on a quiet machine: "any" every run, "cold" run 1 (empty cache), "warm" the
# later runs, "warm_ratio" a later run's wall over its tree's run 1
TARGETS = {
    "help": {"any": 0.5},
    "drive-check": {"any": 2.0},
    "make-run": {"cold": 20.0, "warm": 25.0, "warm_ratio": 0.40},
    "envelope-200x3": {"cold": 30.0, "warm": 15.0},
    "envelope-traction-4x3": {"cold": 120.0},
    "make-test": {"cold": 360.0},
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


def _worker(report: str, mode: str, argv: list[str]) -> int:
    """Run the command line as the console script does, JAX's compile events recorded unless ``mode`` is
    ``light``; the phases (or None) and whether JAX was imported to ``report``."""
    t0 = time.time()
    spans: dict[str, list] = {k: [] for k in _PHASES}
    if mode != "light":
        import jax.monitoring

        kinds = {v: k for k, v in _PHASES.items()}

        def on_span(event, start, end, **_):
            if event in kinds:
                spans[kinds[event]].append((start, end))

        jax.monitoring.register_event_time_span_listener(on_span)
    import jaxobs_tuning

    # the tree's own files decide: find_spec would also find this checkout's module through its editable install
    if any((Path(p) / "cli_entry.py").is_file() for p in jaxobs_tuning.__path__):
        from jaxobs_tuning.cli_entry import main
    else:  # a tree from before the console script's own entry: it was jaxobs_tuning.cli:main
        from jaxobs_tuning.cli import main
    try:
        rc = main(argv)
    except SystemExit as e:  # argparse's exit after --help in the trees whose main lets it through
        rc = e.code if isinstance(e.code, int) else 0
    if mode == "light":
        phases: dict = {k: None for k in _PHASES} | {"jits": None}
    else:
        phases = {k: round(_union(v), 2) for k, v in spans.items()} | {"jits": len(spans["compile_s"])}
    phases["jax_imported"] = "jax" in sys.modules
    phases["in_process_s"] = round(time.time() - t0, 2)
    Path(report).write_text(json.dumps(phases))
    return rc


def _dir_size(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def _one(args: list[str], env: dict, out: Path, result: str | None = None, light: bool = False, cwd=None) -> dict:
    """One run of ``args`` (a :data:`COMMANDS` value) in a fresh process; its row (times, load, phases)."""
    if "RESULT" in args and result is None:
        raise ValueError("first_second: this command needs --result PATH (a drive job's result.json)")
    suite = args[:1] == ["PYTEST"]
    report = out.with_suffix(".phases.json")
    if suite:  # the tree's test suite, in its folder (its conftest reads JAXOBS_TEST_CACHE)
        argv = [sys.executable, "-m", "pytest", *args[1:]]
    else:  # this file run as a script: with --tree, jaxobs and jaxobs_tuning come from that tree's PYTHONPATH
        argv = [sys.executable, str(Path(__file__).resolve()), "--worker", str(report), "light" if light else "full"]
        res = str(Path(result).resolve()) if result is not None else ""
        argv += [str(out) if a == "OUT" else res if a == "RESULT" else a for a in args]
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    proc = subprocess.run(argv, env=env, capture_output=True, text=True, cwd=cwd)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    ok = (0, 1) if suite else (0, 3, 4)  # a suite with failures still gives its time (its summary line says so)
    if proc.returncode not in ok:
        sys.stderr.write(proc.stdout[-2000:] + proc.stderr[-4000:])
        raise SystemExit(f"{' '.join(argv)} exited {proc.returncode}")
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    row = {"wall_s": round(wall, 2), "cpu_s": round(cpu, 2), "load": [round(load0, 1), round(os.getloadavg()[0], 1)]}
    row["rc"] = proc.returncode
    if suite:
        lines = [s for s in proc.stdout.splitlines() if s.strip()]
        return {**row, **{k: None for k in _PHASES}, "jits": None, "in_process_s": None, "summary": lines[-1:]}
    return {**row, **json.loads(report.read_text())}


def _git(*args: str) -> str:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, check=True).stdout.strip()


def _tree(spec: str, tmp: Path, j: int) -> tuple[Path, str | None]:
    """A tree's folder and commit: ``spec`` a folder (its HEAD, ``+dirty`` with uncommitted changes) or a git
    revision of this repository, exported into ``tmp`` as committed."""
    path = Path(spec)
    if path.is_dir():
        git = subprocess.run(["git", "-C", spec, "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
        if git.returncode != 0:
            return path.resolve(), None
        dirty = subprocess.run(["git", "-C", spec, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True).stdout.strip()  # fmt: skip
        return path.resolve(), git.stdout.strip() + ("+dirty" if dirty else "")
    try:
        commit = _git("rev-parse", "--short", "--verify", f"{spec}^{{commit}}")
    except subprocess.CalledProcessError:
        raise ValueError(f"first_second: --tree {spec!r} is neither a folder nor a revision of {ROOT}") from None
    dest = tmp / f"tree-{j}-{commit}"
    dest.mkdir()
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", commit], capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)
    return dest, commit


def labels(trees: list[str] | None) -> list[str]:
    """The trees' labels: ``before`` and ``after`` for two, ``tree 1``, ... otherwise, ``installed`` for none."""
    if not trees:
        return ["installed"]
    return ["before", "after"] if len(trees) == 2 else [f"tree {j + 1}" for j in range(len(trees))]


def measure(
    cmds=("make-run",),
    runs: int = 2,
    trees: list[str] | None = None,
    keep_cache: str | None = None,
    log=None,
    result: str | list[str] | None = None,
) -> list[dict]:
    """First and later runs of each of ``cmds`` (names of :data:`COMMANDS`), ``runs`` each; one row a run.

    ``trees``: source trees to compare, folders or git revisions (each its own cache, their runs interleaved),
    default the installed jaxobs; ``keep_cache``: use (and keep) this cache folder instead of a temporary one;
    ``log``: called with each row as it is measured (default: its JSON on stderr); ``result``: the result file
    of the commands that read one (``envelope-200x3``), or one per tree (a tree that cannot read another's).
    A row: ``command``, ``tree`` (its label, :func:`labels`), ``commit``, ``run``, ``wall_s``, ``cpu_s``,
    ``load`` (1-min load average at its start and end), ``rc``, the phases ``trace_s``, ``lower_s``,
    ``compile_s`` (s; None for :data:`LIGHT` commands and the suite), ``jits``, ``jax_imported``,
    ``in_process_s`` and ``cache_mib`` (the cache after it).
    """
    results = result if isinstance(result, list) else [result] * len(trees or [None])
    if len(results) != len(trees or [None]):
        raise ValueError(
            f"first_second: {len(results)} result files for {len(trees or [None])} trees: give one, or one per tree"
        )
    unknown = [c for c in cmds if c not in COMMANDS]
    if unknown:
        raise ValueError(f"first_second: unknown command(s) {unknown}; known: {sorted(COMMANDS)}")
    if log is None:

        def log(row):
            print(json.dumps(row), file=sys.stderr, flush=True)

    rows = []
    with tempfile.TemporaryDirectory(prefix="jaxobs-first-second-") as tmp:
        envs = {}
        for j, (spec, label) in enumerate(zip(trees or [None], labels(trees))):
            env = dict(os.environ)
            path, commit = ROOT, None
            if spec is not None:  # the tree's jaxobs, and its tuning/ as jaxobs_tuning (the installed layout)
                path, commit = _tree(spec, Path(tmp), j)
                pp = Path(tmp) / f"pp-{j}"
                pp.mkdir()
                (pp / "jaxobs_tuning").symlink_to(path / "tuning")
                # the caller's PYTHONPATH after the tree's (e.g. another version of a dependency to compare)
                env["PYTHONPATH"] = os.pathsep.join(filter(None, (str(path), str(pp), env.get("PYTHONPATH"))))
            envs[label] = (env, path, commit, results[j])
        for name in cmds:
            caches = {}
            for t in envs:
                cache = Path(keep_cache) if keep_cache else Path(tmp) / f"cache-{name}-{len(caches)}"
                shutil.rmtree(cache, ignore_errors=True)
                caches[t] = cache
            for i in range(1, runs + 1):
                for t, (env, path, commit, res) in envs.items():
                    env = {**env, "JAXOBS_CACHE_DIR": str(caches[t]), "JAXOBS_TEST_CACHE": str(caches[t])}
                    out = Path(tmp) / f"out-{name}-{len(rows)}"
                    one = _one(COMMANDS[name], env, out, res, light=name in LIGHT, cwd=path)
                    row = {"command": name, "tree": t, "commit": commit, "run": i, **one}
                    row["cache_mib"] = round(_dir_size(caches[t]) / 2**20, 1) if caches[t].exists() else 0.0
                    rows.append(row)
                    log(row)
    return rows


def _s(x: float) -> str:
    return f"{x:.2f}" if x < 10 else f"{x:.1f}"


def _ph(x) -> str:
    return "–" if x is None else f"{x:.1f}"


def table(rows: list[dict]) -> str:
    """The rows of :func:`measure` as a Markdown table, each run's times also over its command's run 1."""
    lines = [
        "| command | tree | run | wall (s) | CPU (s) | wall / run 1 | CPU / run 1 | trace (s) | lower (s) | compile or "
        "cache read (s) | run + Python (s) | cache (MiB) | load (start, end) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    first = {}
    for r in rows:
        f = first.setdefault((r["command"], r["tree"], r.get("source")), r)
        phases = [r.get(k) for k in _PHASES]
        known = [p for p in phases if p is not None]
        rest = f"{r['wall_s'] - sum(known):.1f}" if len(known) == len(phases) else "–"
        lines.append(
            f"| {r['command']} | {r['tree']} | {r['run']} | {_s(r['wall_s'])} | {_s(r['cpu_s'])} | "
            f"{r['wall_s'] / f['wall_s']:.2f} | "
            f"{r['cpu_s'] / f['cpu_s']:.2f} | {_ph(phases[0])} | {_ph(phases[1])} | {_ph(phases[2])} | "
            f"{rest} | {r['cache_mib']:.1f} | {r['load'][0]:.1f}, {r['load'][1]:.1f} |"
        )
    return "\n".join(lines)


def verdict(command: str, row: dict, cold: dict) -> tuple[str, bool | None]:
    """A run's target (:data:`TARGETS`) in words and whether its wall time meets it (None: no target).

    ``cold`` is the same command's and tree's run 1 (the warm ratio's reference).
    """
    t = TARGETS.get(command, {})
    if "any" in t:
        return f"≤ {t['any']:g} s", row["wall_s"] <= t["any"]
    if row["run"] == 1:
        return (f"≤ {t['cold']:g} s", row["wall_s"] <= t["cold"]) if "cold" in t else ("–", None)
    words, met = [], []
    if "warm" in t:
        words.append(f"≤ {t['warm']:g} s")
        met.append(row["wall_s"] <= t["warm"])
    if "warm_ratio" in t:
        words.append(f"≤ {t['warm_ratio']:.2f} × cold")
        met.append(row["wall_s"] <= t["warm_ratio"] * cold["wall_s"])
    return (" and ".join(words), all(met)) if words else ("–", None)


def summary(rows: list[dict], cpus: int | None = None) -> str:
    """Each command's cold run and warm runs per tree (``before → after`` with two trees), wall / CPU seconds,
    the load, its target and whether it is met; a run at a load above half the cores (``cpus``) is marked †."""
    cpus = cpus or os.cpu_count() or 1
    trees = list(dict.fromkeys(r["tree"] for r in rows))
    head = " | ".join(f"{t}: wall / CPU (s), load" for t in trees)
    ratio = len(trees) == 2
    lines = [f"| command | run | target | {head} |" + (f" {trees[1]} / {trees[0]} (wall) |" if ratio else "")]
    lines.append("|---|---|---|" + "---|" * (len(trees) + ratio))
    loaded = False
    for command in dict.fromkeys(r["command"] for r in rows):
        mine = [r for r in rows if r["command"] == command]
        for kind in ("cold", "warm"):
            cells, walls, target = [], [], "–"
            for t in trees:
                runs = [r for r in mine if r["tree"] == t and (r["run"] == 1) == (kind == "cold")]
                cold = next((r for r in mine if r["tree"] == t and r["run"] == 1), None)
                if not runs or cold is None:
                    cells.append("–")
                    continue
                r = sorted(runs, key=lambda r: r["wall_s"])[(len(runs) - 1) // 2]  # the median run (the lower of two)
                target, met = verdict(command, r, cold)
                mark = "†" if max(r["load"]) > cpus / 2 else ""
                loaded |= bool(mark)
                word = "" if met is None else (": met" if met else ": **not met**")
                n = "" if len(runs) == 1 else " (lower of 2)" if len(runs) == 2 else f" (median of {len(runs)})"
                src = f" [{r['source']}]" if r.get("source") else ""
                cells.append(f"{_s(r['wall_s'])} / {_s(r['cpu_s'])}{word}{n}, {r['load'][0]:.1f}–{r['load'][1]:.1f}"
                             f"{mark}{src}")  # fmt: skip
                walls.append(r["wall_s"])
            if all(c == "–" for c in cells):
                continue
            line = f"| {command} | {kind} | {target} | " + " | ".join(cells) + " |"
            if ratio:
                line += f" {walls[1] / walls[0]:.2f} |" if len(walls) == 2 else " – |"
            lines.append(line)
    commits = {t: sorted({str(r.get("commit")) for r in rows if r["tree"] == t}) for t in trees}
    lines.append("\ntrees: " + "; ".join(f"{t} = {', '.join(c)}" for t, c in commits.items()))
    if loaded:
        lines.append(f"† load above {cpus / 2:g} ({cpus} cores): the targets are a quiet machine's")
    return "\n".join(lines)


def load_rows(path: str) -> list[dict]:
    """The rows of an earlier ``--out`` file, each marked with the file's name (``source``); a file from before
    the trees were labelled (its rows name a tree's folder) gets the labels of :func:`labels` in its order."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:  # a missing file, or the .txt beside the .json
        raise SystemExit(f"first_second: --with {path}: not an earlier --out file ({type(e).__name__}: {e})") from None
    if not isinstance(data, dict) or not isinstance(data.get("rows"), list):
        raise SystemExit(f"first_second: --with {path}: not an earlier --out file (no 'rows')")
    trees = list(data.get("trees") or {})
    names = dict(zip(trees, labels(trees))) if trees else {}
    out = []
    for r in data["rows"]:
        r = {**r, "source": Path(path).name}
        if "commit" not in r and r["tree"] in names:
            r["commit"] = data["trees"][r["tree"]]
            r["tree"] = names[r["tree"]]
        out.append(r)
    return out


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["--worker"]:
        return _worker(argv[1], argv[2], argv[3:])
    p = argparse.ArgumentParser(prog="python -m benchmarks.first_second", description=__doc__.split("\n")[0])
    p.add_argument(
        "--cmd",
        nargs="+",
        choices=sorted(COMMANDS),
        metavar="CMD",  # the choices listed once, in the help, not twice in the usage line
        help=f"commands to time, of {', '.join(sorted(COMMANDS))} (default make-run, or none with --with: the "
        "earlier files' table alone; each "
        "one's command line is in COMMANDS, this file; make-test takes about 14 min a tree: run it alone, merge it "
        "with --with)",
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
        help="source trees to compare, folders or git revisions of this repository (each its own cache; their runs "
        "interleaved: run 1 of each, then run 2 ...; two are labelled before and after); default: the installed "
        "jaxobs",
    )
    p.add_argument(
        "--result",
        nargs="+",
        help="a drive job's result.json, for envelope-200x3; or one per --tree, in their order (a tree that cannot "
        "read another tree's result: each tuned by its own tree)",
    )
    p.add_argument("--out", help="also write the rows (and the trees' commits, the cores, the date) to this JSON file")
    p.add_argument(
        "--with",
        dest="merge",
        nargs="+",
        default=[],
        metavar="FILE",
        help="earlier --out files whose rows join the tables (each row names its file), e.g. a make-test run",
    )
    p.add_argument("--json", action="store_true", help="print the rows as JSON")
    a = p.parse_args(argv)
    if a.cmd is None:
        a.cmd = [] if a.merge else ["make-run"]
    if a.runs < 1:
        p.error(f"--runs must be >= 1, got {a.runs}")
    if any("RESULT" in COMMANDS[c] for c in a.cmd) and not a.result:
        p.error("--result PATH is needed by: " + ", ".join(c for c in a.cmd if "RESULT" in COMMANDS[c]))
    earlier = [r for f in a.merge for r in load_rows(f)]
    result = a.result[0] if a.result and len(a.result) == 1 else a.result
    rows = measure(a.cmd, a.runs, a.tree, a.keep_cache, result=result) if a.cmd else []
    if a.out and rows:
        trees = {r["tree"]: r["commit"] for r in rows}
        meta = {"date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "argv": argv, "cpus": os.cpu_count()}
        Path(a.out).write_text(json.dumps({"rows": rows, "trees": trees, **meta}, indent=1) + "\n")
    rows = rows + earlier
    if a.json:
        print(json.dumps(rows, indent=1))
        return 0
    print(summary(rows))
    print()
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
