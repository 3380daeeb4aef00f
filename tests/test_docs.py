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

Output blocks.  A ```text block shows what something printed, and a test produces it again and compares:

- right after a ```bash block (nothing but blank lines between), it is the stdout of the block's last command;
  right after a ```python block, the stdout of that block (the page's blocks run in order in one process, each
  block's prints apart);
- ``<!-- output: CMD -->`` on the line before it: the stdout of the ``jaxobs`` command CMD, run at that place of
  the page's commands (for a block shown apart from its command, ``make run``'s job, ...);
- ``<!-- output -->``: the stdout of the nearest code block above (prose between);
- the flags ``excerpt`` (``<!-- output excerpt: CMD -->``: the block's lines are consecutive lines of the output)
  and ``wrapped`` (whitespace runs, line ends included, compare as one space: a long line wrapped for the page).

The comparison (``_same_output``), line by line: words and signs exactly; numbers to a relative 1e-3 (a result
computed on another machine, with another count of CPU devices, differs in its last digits); a command's wall time
(``, 46.2 s, `` in a tune's first line) not at all.  A block whose command is cheap (``_cheap``) is compared in the
main suite, every other in the slow suite with its page's commands.  A ```text block that is no output says so
with ``<!-- not-output: why -->`` (``test_every_text_block_is_checked``).
"""

from __future__ import annotations

import importlib.util
import math
import os
import re
import subprocess
import sys
import tomllib
from dataclasses import dataclass
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
    words = cmd.split()
    if words[:3] in (["python", "-m", "benchmarks.through_zero"], ["python", "-m", "benchmarks.envelope_agreement"]):
        return "--table" in words  # prints the stored results' table, runs nothing
    return (
        words[1] in CHEAP_CLI
        or "--check" in words
        and words[1] in ("tune", "study", "envelope")
        or words[1:3] in (["drive", "check"], ["log", "check"])
        and "--simulate" not in words  # drive check --simulate compiles and runs a closed loop: slow suite
    )


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


def _run_cmd(cmd: str, cwd: Path) -> subprocess.CompletedProcess:
    """A ``jaxobs`` command as :func:`_run_cli` runs it, or ``python -m benchmarks.X ...`` at the repository's root
    (benchmarks/ is not installed)."""
    if cmd.startswith("python -m benchmarks."):
        return subprocess.run(
            [sys.executable, *cmd.split()[1:]], capture_output=True, text=True, cwd=ROOT, timeout=1800, check=False
        )
    return _run_cli(cmd, cwd)


# --------------------------------------------------------------------------------------------------
# output blocks: what a page shows printed, produced again
# --------------------------------------------------------------------------------------------------

FENCE_ALL = re.compile(r"^((?:<!--[^\n]*-->\n)*)( *)```(\w*)[^\n]*\n(.*?)^\2```[ \t]*$", re.M | re.S)
OUTPUT_MARK = re.compile(r"<!-- output((?: (?:excerpt|wrapped))*)(?:: (.*?))? -->")
NOT_OUTPUT_MARK = re.compile(r"<!-- not-output: .+ -->")
NUMBER = re.compile(r"\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
WALL_TIME = re.compile(r", \d+(?:\.\d+)? s, ")  # a tune's first line: "..., 46.2 s, 4 scenarios"


@dataclass(frozen=True)
class Fence:
    """A fenced block of a page: its language, its text, the comment lines right above it, the text before them."""

    lang: str
    body: str
    marks: tuple[str, ...]
    gap: str


@dataclass(frozen=True)
class Output:
    """A ```text block that shows output: of the code fence ``source`` (its index) or of a command."""

    shown: str
    source: int | str
    excerpt: bool
    wrapped: bool


def _fences(page: Path) -> list[Fence]:
    text, out, last = page.read_text(), [], 0
    for m in FENCE_ALL.finditer(text):
        body = "\n".join(ln[len(m.group(2)) :] for ln in m.group(4).splitlines())
        out.append(Fence(m.group(3), body, tuple(m.group(1).splitlines()), text[last : m.start()]))
        last = m.end()
    return out


def _outputs(page: Path) -> dict[int, Output]:
    """The page's output blocks by their fence's index (the conventions above)."""
    fences, found = _fences(page), {}
    for i, f in enumerate(fences):
        if f.lang != "text":
            continue
        mark = next((m for m in map(OUTPUT_MARK.fullmatch, f.marks) if m), None)
        adjacent = i > 0 and fences[i - 1].lang in ("bash", "python") and not f.gap.strip() and not f.marks
        if mark is None and not adjacent:
            continue
        flags = mark.group(1).split() if mark else []
        if mark and mark.group(2):
            source: int | str = mark.group(2)
        else:
            source = max(k for k in range(i) if fences[k].lang in ("bash", "python"))
        found[i] = Output(f.body, source, "excerpt" in flags, "wrapped" in flags)
    return found


def _tokens(text: str) -> list[str]:
    """Numbers and every other non-blank character, a wall time replaced (the comparison's unit)."""
    text = WALL_TIME.sub(", <wall> s, ", text)
    return re.findall(NUMBER.pattern + r"|<wall>|\S", text)


def _same_line(shown: str, got: str) -> bool:
    a, b = _tokens(shown), _tokens(got)
    if len(a) != len(b):
        return False
    for x, y in zip(a, b, strict=True):
        if NUMBER.fullmatch(x) and NUMBER.fullmatch(y):
            if not math.isclose(float(x), float(y), rel_tol=1e-3, abs_tol=1e-12):
                return False
        elif x != y:
            return False
    return True


def _same_output(out: Output, got: str) -> str | None:
    """None where ``got`` prints what the block shows (the rule above); else where they part."""
    shown = out.shown.rstrip("\n").splitlines()
    lines = got.rstrip("\n").splitlines()
    if out.wrapped:
        shown, lines = [" ".join(out.shown.split())], [" ".join(got.split())]
    if out.excerpt:
        for start in range(len(lines) - len(shown) + 1):
            if all(_same_line(s, g) for s, g in zip(shown, lines[start:], strict=False)):
                return None
        return f"the excerpt is not in the output:\n{got}"
    for k, (s, g) in enumerate(zip(shown, lines, strict=False)):
        if not _same_line(s, g):
            return f"line {k + 1} shows\n  {s}\nand the run prints\n  {g}\n(the whole output:\n{got})"
    if len(shown) != len(lines):
        return f"{len(shown)} lines shown, {len(lines)} printed:\n{got}"
    return None


def _is_jaxobs_block(body: str) -> list[str]:
    """The commands of a bash block that is all jaxobs commands (comments and blank lines aside), else []."""
    lines = [ln.split(" #")[0].strip() for ln in body.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    return lines if lines and all(ln.startswith("jaxobs ") for ln in lines) else []


@dataclass(frozen=True)
class Step:
    """One command of a page as its reader runs it, with the output blocks that show what it prints."""

    cmd: str
    shows: tuple[Output, ...]


def _steps(page: Path) -> list[Step]:
    """The page's commands in order: its jaxobs bash blocks' and its output blocks' own."""
    fences, outputs, steps = _fences(page), _outputs(page), []
    for i, f in enumerate(fences):
        if f.lang == "bash" and not any(m == "<!-- no-run -->" for m in f.marks):
            cmds = _is_jaxobs_block(f.body)
            shows = tuple(o for o in outputs.values() if o.source == i)
            assert cmds or not shows, f"{page.name}: output shown for a bash block that does not run"
            steps += [Step(c, shows if k == len(cmds) - 1 else ()) for k, c in enumerate(cmds)]
        elif i in outputs and isinstance(outputs[i].source, str):
            steps.append(Step(outputs[i].source, (outputs[i],)))
    return steps


def _run_steps(page: Path, steps: list[Step], cwd: Path):
    for step in steps:
        r = _run_cmd(step.cmd if step.cmd.startswith("python") else step.cmd + " --quiet", cwd)
        assert r.returncode == 0, (step.cmd, r.stderr[-2000:])
        for out in step.shows:
            why = _same_output(out, r.stdout)
            assert why is None, f"{page.name}, `{step.cmd}`: {why}"


def test_every_text_block_is_checked():
    """Every ```text block is an output block a test compares, or says why it is none."""
    unchecked = []
    for page in PAGES:
        outputs = _outputs(page)
        for i, f in enumerate(_fences(page)):
            if f.lang == "text" and i not in outputs and not any(map(NOT_OUTPUT_MARK.fullmatch, f.marks)):
                unchecked.append(f"{page.name}: {f.body.splitlines()[0][:60] if f.body else ''}")
    assert not unchecked, f"text blocks that no test compares: {unchecked}"


def test_output_comparison_rule():
    """Numbers to 1e-3, words exactly, a tune's wall time free, excerpts and wrapped lines."""
    out = Output("CLESO: budget after 8 iterations, 46.2 s, 4 scenarios\nobjective   1.349   0.2234", 0, False, False)
    assert (
        _same_output(out, "CLESO: budget after 8 iterations, 112.5 s, 4 scenarios\nobjective  1.3491 0.22345\n") is None
    )
    assert (
        _same_output(out, "CLESO: budget after 8 iterations, 46.2 s, 4 scenarios\nobjective 1.349 0.2254") is not None
    )
    assert _same_output(out, "CLESO: converged after 8 iterations, 46.2 s, 4 scenarios\nobjective 1.349 0.2234")
    assert _same_output(Output("3 speeds 40..4000", 0, False, False), "3 speeds 40..5069") is not None
    assert _same_output(Output("b 2\nc 3", 0, True, False), "a 1\nb 2\nc 3\nd 4") is None
    assert _same_output(Output("b 2\nd 3", 0, True, False), "a 1\nb 2\nc 3\nd 4") is not None
    assert _same_output(Output("one long\nline", 0, False, True), "one long line\n") is None


@pytest.mark.parametrize(
    "page", [p for p in PAGES if any(_cheap(s.cmd) and s.shows for s in _steps(p))], ids=lambda p: p.name
)
def test_cheap_outputs_print_what_they_show(page, tmp_path):
    _run_steps(page, [s for s in _steps(page) if _cheap(s.cmd) and s.shows], tmp_path)


PY_PAGES = [p for p in PAGES if _blocks(p, "python")]
CLI_PAGES = [p for p in PAGES if _jaxobs_commands(p)]


def test_the_docs_have_runnable_blocks():
    """The conventions find something: a rename of the fences would otherwise skip every block silently."""
    assert PY_PAGES and CLI_PAGES
    assert any(_blocks(p, "console") for p in PAGES)
    assert sum(len(_outputs(p)) for p in PAGES) >= 15  # the output blocks (a changed marker would find none)


@pytest.mark.parametrize("page", PY_PAGES, ids=lambda p: p.name)
def test_python_blocks_compile(page):
    for i, block in enumerate(_blocks(page, "python")):
        compile(block, f"{page.name} block {i}", "exec")


BLOCK_SEP = "<<docs-block-{}>>"


def _run_python_page(page: Path, tmp_path: Path):
    """The page's python blocks in one process, each block's prints apart, compared with its output blocks."""
    fences = _fences(page)
    code = [
        f"print({BLOCK_SEP.format(i)!r}, flush=True)\n{f.body}"
        for i, f in enumerate(fences)
        if f.lang == "python" and not any(m == "<!-- no-run -->" for m in f.marks)
    ]
    script = tmp_path / f"{page.stem}.py"
    script.write_text("\n".join(code))
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=tmp_path, timeout=1800)
    assert r.returncode == 0, f"{page.name}: {r.stderr[-3000:]}"
    printed = dict(zip(*[iter(re.split(r"^<<docs-block-(\d+)>>\n", r.stdout, flags=re.M)[1:])] * 2, strict=True))
    for out in _outputs(page).values():
        if isinstance(out.source, int) and fences[out.source].lang == "python":
            why = _same_output(out, printed[str(out.source)])
            assert why is None, f"{page.name}, python block {out.source}: {why}"


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
@pytest.mark.parametrize("page", [p for p in PAGES if not all(_cheap(s.cmd) for s in _steps(p))], ids=lambda p: p.name)
def test_cli_blocks_run(page, tmp_path):
    """The page's commands in order in one folder, each output block compared with what its command prints."""
    steps = _steps(page)
    cmds = [s.cmd for s in steps]
    if any("out/tune/result.json" in c for c in cmds) and not any("--out out/tune" in c for c in cmds):
        r = _run_cli("jaxobs tune --out out/tune --quiet", tmp_path)  # what `make run` leaves there
        assert r.returncode == 0, r.stderr[-2000:]
    _run_steps(page, steps, tmp_path)


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


def test_concepts_layout_names_what_exists():
    """The layout on the Concepts page (its bare block under "Where the code lives"): each entry exists, and
    every package of jaxobs has its line."""
    layout = next(f.body for f in _fences(DOCS / "concepts.md") if f.lang == "" and f.body.startswith("jaxobs/"))
    entries, top = [], ""
    for ln in layout.splitlines():
        m = re.match(r"( ?)( ?)(\S+)", ln)
        if not m or ln.startswith(" " * 3):
            continue  # a description's continuation line
        name = m.group(3)
        if m.group(1):
            entries.append(top + name)
        else:
            top = name if name.endswith("/") else ""
            entries.append(name)
    missing = [e for e in entries if not (ROOT / e.rstrip("/")).exists()]
    assert not missing, f"docs/concepts.md's layout names what does not exist: {missing}"
    packages = {f"jaxobs/{p.parent.name}/" for p in (ROOT / "jaxobs").glob("*/__init__.py")}
    assert packages <= set(entries), f"packages missing from docs/concepts.md's layout: {packages - set(entries)}"
