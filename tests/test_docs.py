"""The documentation pages (docs/*.md) as a reader uses them, and the TOML reference against the schema.

Conventions of the pages' code blocks:

- every ```python block of a page runs, the page's blocks in order in one fresh process (a reader runs a page top
  to bottom); a page whose blocks are expensive says so with the comment ``<!-- docs-test: slow -->`` and runs in
  the slow suite (``make test-slow``);
- a ```bash block runs when every command in it is a ``jaxobs`` command; ``closed-form``, ``--help``,
  ``--version`` and ``--check`` runs are cheap and run here, the others (tune, study, export, ...) run in the slow
  suite, a page's commands in order in one fresh folder; where a command reads ``out/tune/result.json`` and no
  earlier command wrote it, the folder first gets what ``make run`` writes there;
- a ```console block shows ``$ jaxobs ...`` commands with their output: the command runs and its stdout must be
  the output shown;
- ``<!-- no-run -->`` on the line before a block keeps it from running (it needs a cluster, a file of the reader's
  own, ...): used sparingly.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = sorted(p for p in DOCS.glob("*.md"))
FENCE = re.compile(r"(<!-- no-run -->\n)?```(\w+)[^\n]*\n(.*?)```", re.S)
CHEAP_CLI = ("closed-form", "--help", "--version")


def _blocks(page: Path, lang: str) -> list[str]:
    return [body for skip, lg, body in FENCE.findall(page.read_text()) if lg == lang and not skip]


def _is_slow(page: Path) -> bool:
    return "<!-- docs-test: slow -->" in page.read_text()


def _jaxobs_commands(page: Path) -> list[str]:
    """The page's bash commands, when a whole block is jaxobs commands (comments and blank lines aside)."""
    cmds = []
    for body in _blocks(page, "bash"):
        lines = [
            ln.split(" #")[0].strip() for ln in body.splitlines() if ln.strip() and not ln.lstrip().startswith("#")
        ]
        if lines and all(ln.startswith("jaxobs ") for ln in lines):
            cmds += lines
    return cmds


def _cheap(cmd: str) -> bool:
    return cmd.split()[1] in CHEAP_CLI or "--check" in cmd.split() and cmd.split()[1] in ("tune", "study")


def _jaxobs_exe() -> str:
    return str(Path(sys.executable).with_name("jaxobs"))


def _run_cli(cmd: str, cwd: Path) -> subprocess.CompletedProcess:
    """``cmd`` in ``cwd`` as a reader runs it at the repository's root (``tuning/presets/...`` and
    ``docs/examples/...`` resolve)."""
    for d in ("tuning", "docs"):
        if not (cwd / d).exists():
            (cwd / d).symlink_to(ROOT / d)
    env = {**os.environ, "COLUMNS": "100"}  # argparse wraps its help to the terminal's width
    return subprocess.run(
        [_jaxobs_exe(), *cmd.split()[1:]], capture_output=True, text=True, cwd=cwd, timeout=1800, check=False, env=env
    )


PY_PAGES = [p for p in PAGES if _blocks(p, "python")]
CLI_PAGES = [p for p in PAGES if _jaxobs_commands(p)]


def test_the_docs_have_runnable_blocks():
    """The conventions find something: a rename of the fences would otherwise skip every block silently."""
    assert PY_PAGES and CLI_PAGES
    assert any(_blocks(p, "console") for p in PAGES)


@pytest.mark.parametrize("page", PY_PAGES, ids=lambda p: p.name)
def test_python_blocks_compile(page):
    for i, block in enumerate(_blocks(page, "python")):
        compile(block, f"{page.name} block {i}", "exec")


def _run_python_page(page: Path, tmp_path: Path):
    script = tmp_path / f"{page.stem}.py"
    script.write_text("\n".join(_blocks(page, "python")))
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=tmp_path, timeout=1800)
    assert r.returncode == 0, f"{page.name}: {r.stderr[-3000:]}"


@pytest.mark.parametrize("page", [p for p in PY_PAGES if not _is_slow(p)], ids=lambda p: p.name)
def test_python_page_runs(page, tmp_path):
    _run_python_page(page, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("page", [p for p in PY_PAGES if _is_slow(p)], ids=lambda p: p.name)
def test_python_page_runs_slow(page, tmp_path):
    _run_python_page(page, tmp_path)


@pytest.mark.parametrize("page", [p for p in PAGES if _blocks(p, "console")], ids=lambda p: p.name)
def test_console_blocks_print_what_they_show(page, tmp_path):
    for body in _blocks(page, "console"):
        lines = body.rstrip("\n").splitlines()
        assert lines[0].startswith("$ jaxobs "), lines[0]
        r = _run_cli(lines[0][2:], tmp_path)
        assert r.returncode == 0, r.stderr[-2000:]
        assert [ln.rstrip() for ln in r.stdout.rstrip("\n").splitlines()] == [ln.rstrip() for ln in lines[1:]]


@pytest.mark.parametrize("page", [p for p in CLI_PAGES if any(map(_cheap, _jaxobs_commands(p)))], ids=lambda p: p.name)
def test_cheap_cli_blocks_run(page, tmp_path):
    for cmd in filter(_cheap, _jaxobs_commands(page)):
        r = _run_cli(cmd, tmp_path)
        assert r.returncode == 0, (cmd, r.stderr[-2000:])


@pytest.mark.slow
@pytest.mark.parametrize(
    "page", [p for p in CLI_PAGES if not all(map(_cheap, _jaxobs_commands(p)))], ids=lambda p: p.name
)
def test_cli_blocks_run(page, tmp_path):
    cmds = _jaxobs_commands(page)
    if any("out/tune/result.json" in c for c in cmds) and not any("--out out/tune" in c for c in cmds):
        r = _run_cli("jaxobs tune --out out/tune --quiet", tmp_path)  # what `make run` leaves there
        assert r.returncode == 0, r.stderr[-2000:]
    for cmd in cmds:
        r = _run_cli(cmd + " --quiet", tmp_path)
        assert r.returncode == 0, (cmd, r.stderr[-2000:])


# --------------------------------------------------------------------------------------------------
# the TOML reference against the schema
# --------------------------------------------------------------------------------------------------


def _reference() -> str:
    spec = importlib.util.spec_from_file_location("toml_reference", DOCS / "hooks" / "toml_reference.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.reference_markdown()


def _schema_keys(parse, raw: dict, base: Path, where=(), found=None) -> set:
    """Every key the validator allows in every table of the valid file ``raw`` that it reports (a probe key in each
    table, recursively; a table of names — gains, designs — reports none and is skipped)."""
    import copy

    found = set() if found is None else found
    table = raw
    for k in where:
        table = table[k]
    probe = copy.deepcopy(raw)
    t = probe
    for k in where:
        t = t[k]
    t["zz_probe"] = 1
    try:
        parse(probe, base=base)
    except ValueError as e:
        m = re.search(r"allowed: (.*)$", str(e))
        if m and "zz_probe" in str(e):
            found |= {(".".join(map(str, where)), k.strip()) for k in m.group(1).split(",")}
    for k, v in list(table.items()):
        if isinstance(v, dict):
            _schema_keys(parse, raw, base, (*where, k), found)
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            _schema_keys(parse, raw, base, (*where, k, 0), found)
    return found


def test_toml_reference_lists_every_schema_key():
    import jaxobs_tuning
    from jaxobs_tuning import study_file

    ref = _reference()
    presets = ROOT / "tuning" / "presets"
    jobs = [p for p in sorted(presets.glob("*.toml")) if not p.name.startswith("study_")]
    studies = [*sorted(presets.glob("study_*.toml")), ROOT / "jaxobs" / "data" / "default_study.toml"]
    keys = set()
    for files, parse in ((jobs, jaxobs_tuning.parse_job), (studies, study_file.parse_study)):
        for f in files:
            keys |= _schema_keys(parse, tomllib.loads(f.read_text()), f.parent)
    assert len(keys) > 50  # the probe found the schema (a changed error format would find nothing)
    missing = sorted(f"{table}.{key}" for table, key in keys if f"`{key}`" not in ref)
    assert not missing, f"keys of the schema missing from the TOML reference: {missing}"
    for table in {t.split(".")[0] for t, _ in keys if t}:
        assert f"`[{table}" in ref, f"no section for [{table}]"


# --------------------------------------------------------------------------------------------------
# names and paths the pages quote exist
# --------------------------------------------------------------------------------------------------


def _resolves(name: str) -> bool:
    """``jaxobs.x.y`` / ``jaxobs_tuning.x``: the longest importable module prefix, then attributes."""
    import importlib

    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def test_docs_quote_names_and_files_that_exist():
    """A module, function or file renamed in the code and not in the docs fails here, naming the page."""
    stale = []
    for page in [*PAGES, ROOT / "README.md"]:
        text = page.read_text()
        for m in re.finditer(r"`((?:jaxobs_tuning|jaxobs)(?:\.[A-Za-z_]\w*)+)", text):
            if not m.group(1).endswith("_") and not _resolves(m.group(1)):  # `jaxobs.papers.IF_*`: a family
                stale.append(f"{page.name}: {m.group(1)}")
        for m in re.finditer(r"`((?:jaxobs|tuning|tests|benchmarks|notebooks)/[\w./-]+?)[`:\s]", text):
            path = m.group(1).rstrip(".")
            if not (ROOT / path).exists():
                stale.append(f"{page.name}: {path}")
    assert not stale, "the docs quote names or files that do not exist: " + ", ".join(sorted(set(stale)))
