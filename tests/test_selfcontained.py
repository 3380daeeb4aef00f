"""The repository reads on its own: no internal issue numbers (the word followed by a number), no references
to a design file that is not in it (``docs/architecture.md`` is the design record), and no test function names on the
documentation pages or in the presets.  The history of measurements lives in ``CHANGELOG.md``, which is not
scanned.  Text only: nothing is imported."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCANNED = ("docs", "tuning", "jaxobs", "tests")  # tuning/ holds the presets
SUFFIXES = {".py", ".md", ".toml", ".yml", ".yaml", ".txt", ".ipynb", ".json", ".cfg", ".ini", ".c", ".h"}
ISSUE = re.compile(r"\bissues? #?[0-9]", re.IGNORECASE)
DESIGN = re.compile(r"\bDESIGN\.md\b")
# a test function named on a user page or in a preset: `test_x` or tests/test_x.py::test_y (a file name is fine)
TEST_NAME = re.compile(r"::test_\w+|`test_\w+`(?!\.)")


def _files(folders=SCANNED):
    for folder in folders:
        for p in sorted((ROOT / folder).rglob("*")):
            if p.is_file() and p.suffix in SUFFIXES and "__pycache__" not in p.parts:
                yield p


def _sites(pattern, files) -> list[str]:
    """``path:line: text`` of every line of ``files`` that ``pattern`` finds."""
    out = []
    for p in files:
        for i, line in enumerate(p.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            if pattern.search(line):
                out.append(f"{_rel(p)}:{i}: {line.strip()[:120]}")
    return out


def _rel(p: Path) -> str:
    return p.relative_to(ROOT).as_posix() if p.is_relative_to(ROOT) else str(p)


def test_the_patterns_find_what_they_are_for(tmp_path):
    """The scan is not vacuous: each pattern finds its kind of site, and leaves the legitimate ones alone."""
    page = tmp_path / "page.md"
    word, design = "is" + "sue", "DESIGN" + ".md"  # built here so that this file does not match itself
    page.write_text(
        f"as {word} 26 asks\n{word.title()}s #31 and 32\nsee {design}\nchecked by `test_floquet_x`\n"
        f"tests/test_stability.py::test_y\nin `tests/test_trig.py`\nthis t{word} 3, {design.lower()}\n"
    )
    assert len(_sites(ISSUE, [page])) == 2
    assert len(_sites(DESIGN, [page])) == 1
    assert len(_sites(TEST_NAME, [page])) == 2
    assert sum(len(list(_files((f,)))) for f in SCANNED) > 100


def test_no_issue_numbers_or_design_md_anywhere():
    sites = _sites(ISSUE, list(_files())) + _sites(DESIGN, list(_files()))
    why = "cite no issue numbers and no design file outside the repository (state the fact or the reason):\n"
    assert not sites, why + "\n".join(sites)


def test_no_test_function_names_on_user_pages_or_presets():
    files = sorted((ROOT / "docs").glob("*.md"))
    files += sorted((ROOT / "tuning" / "presets").glob("*.toml"))
    sites = _sites(TEST_NAME, files)
    assert not sites, "name the test file, not the test function:\n" + "\n".join(sites)
