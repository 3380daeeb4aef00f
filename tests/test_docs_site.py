"""The built documentation site as a reader opens it: from file://, in a real browser (the slow suite), and its HTML.

- ``test_site_html_has_no_sphinx_roles`` and ``test_site_loads_nothing_from_the_network`` read a built site: the
  one ``make docs`` left in ``site/`` where there is one (skipped otherwise); the slow suite builds its own.
- ``test_site_in_a_browser`` opens ``index.html`` from file:// in headless Chromium (Debian's ``chromium`` and
  ``chromium-driver``, driven by ``selenium``; .ci/run installs them), follows the navigation to every page and
  checks that each renders (a title, a heading, the theme's content: not a 404 or a folder listing), that the
  pages' math is typeset, that search finds a page, and that the browser logged no error. It saves a screenshot
  of every page to ``site-screenshots/`` (git-ignored) for a person to look at.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCREENSHOTS = ROOT / "site-screenshots"
ROLE = re.compile(r":(class|func|mod|meth|attr|data):")


def _html_files(site: Path) -> list[Path]:
    return sorted(site.rglob("*.html"))


def _check_no_roles(site: Path):
    left = []
    for f in _html_files(site):
        text = re.sub(r"<(script|style)\b.*?</\1>", "", f.read_text(errors="replace"), flags=re.S)
        left += [f"{f.relative_to(site)}: {m.group(0)}" for m in ROLE.finditer(text)]
    assert not left, f"literal Sphinx roles in the site's HTML ({len(left)}): {left[:10]}"


def _check_offline(site: Path):
    """No page loads a script, a style sheet, a font or an image from the network (links to read are fine)."""
    remote = re.compile(r"<(?:script|img|iframe)\b[^>]*\bsrc=\"(https?:)?//|<link\b[^>]*\bhref=\"(https?:)?//")
    bad = [str(f.relative_to(site)) for f in _html_files(site) if remote.search(f.read_text(errors="replace"))]
    assert not bad, f"pages that load something from the network: {bad[:10]}"


def _built_site() -> Path:
    site = ROOT / "site"
    if not (site / "index.html").exists():
        pytest.skip("no built site in site/ (make docs); the slow suite builds one (test_site_in_a_browser)")
    sources = [ROOT / "mkdocs.yml", *(ROOT / "docs" / "hooks").glob("*.py")]
    if (site / "index.html").stat().st_mtime < max(p.stat().st_mtime for p in sources):
        pytest.skip("site/ is older than mkdocs.yml or docs/hooks/: rebuild it with make docs")
    return site


def test_site_html_has_no_sphinx_roles():
    _check_no_roles(_built_site())


def test_site_loads_nothing_from_the_network():
    _check_offline(_built_site())


def test_role_rendering():
    """The docs hook that renders the roles: a documented class becomes a cross-reference, ``~`` shortens the
    text, a name that resolves nowhere a code span, and the docstrings' roles are all of a form the hook knows."""
    # the hook imports griffe, which comes with the docs extra (make docs): CI runs this file again after make docs
    pytest.importorskip("griffe", reason="the docs extra is not installed (make docs installs it)")
    sys.path.insert(0, str(ROOT / "docs" / "hooks"))
    try:
        import griffe_roles
    finally:
        sys.path.remove(str(ROOT / "docs" / "hooks"))
    import jaxobs

    ctx = [(jaxobs, "jaxobs")]
    out = griffe_roles.render_roles("see :class:`~jaxobs.drive.Drive` and :func:`no_such_thing`.", ctx)
    drive = jaxobs.drive.Drive
    assert f'<autoref identifier="{drive.__module__}.{drive.__qualname__}" optional><code>Drive</code>' in out
    assert "<code>no_such_thing</code>" in out and ":func:" not in out
    out = griffe_roles.render_roles(":meth:`jaxobs.drive.Drive.settled_for`", ctx)
    assert f'identifier="{drive.__module__}.{drive.__qualname__}.settled_for"' in out
    assert "<code>jaxobs.drive.Drive.settled_for</code>" in out
    # every role in the code's docstrings is one the hook's pattern matches (a new role kind would stay literal)
    kinds = set()
    for f in [*ROOT.joinpath("jaxobs").rglob("*.py"), *ROOT.joinpath("tuning").rglob("*.py")]:
        kinds |= set(re.findall(r":(\w+):`", f.read_text()))
    assert kinds <= {"class", "func", "mod", "meth", "attr", "data", "obj", "exc", "const"}, kinds


def _build(site: Path):
    pytest.importorskip("mkdocs", reason="the docs extra is not installed (pip install -e '.[docs]')")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1", "JAXOBS_DOCS_EXECUTE": "false"}
    mkdocs = [sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet", "--site-dir", str(site)]
    r = subprocess.run(mkdocs, cwd=ROOT, capture_output=True, text=True, env=env, timeout=1800, check=False)
    assert r.returncode == 0, r.stderr[-3000:]


def _chrome():
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed (the test extra)")
    browser, driver = shutil.which("chromium"), shutil.which("chromedriver")
    if not (browser and driver):
        pytest.skip("no chromium / chromedriver (apt-get install chromium chromium-driver; .ci/run installs them)")
    opts = webdriver.ChromeOptions()
    opts.binary_location = browser
    for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--window-size=1280,900"):
        opts.add_argument(a)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=webdriver.ChromeService(executable_path=driver), options=opts)


def _wait(drv, condition, timeout=30.0):
    from selenium.webdriver.support.ui import WebDriverWait

    return WebDriverWait(drv, timeout).until(lambda d: condition(d))


@pytest.mark.slow
def test_site_in_a_browser(tmp_path):
    from selenium.webdriver.common.by import By

    drv = _chrome()
    site = tmp_path / "site"
    _build(site)
    _check_no_roles(site)
    _check_offline(site)
    shutil.rmtree(SCREENSHOTS, ignore_errors=True)
    SCREENSHOTS.mkdir()
    errors, visited = [], []
    try:
        home = (site / "index.html").as_uri()
        drv.get(home)
        nav = drv.execute_script(
            "return Array.from(document.querySelectorAll('nav.md-nav--primary a.md-nav__link[href]'))"
            ".map(a => a.href).filter(h => !h.includes('#'))"
        )
        pages = list(dict.fromkeys(nav))
        assert len(pages) >= 20, pages  # the nav of mkdocs.yml: guides, notebooks, results, API pages
        for url in pages:
            assert url.startswith("file://") and url.endswith(".html"), f"a nav link that is no file: {url}"
            drv.get(url)
            _wait(drv, lambda d: d.execute_script("return document.readyState") == "complete")
            name = url.removeprefix(site.as_uri() + "/").replace("/", "__")
            title = drv.title
            assert title and "404" not in title, f"{name}: title {title!r}"
            assert drv.find_elements(By.CSS_SELECTOR, "article.md-content__inner h1"), f"{name}: no heading"
            if drv.find_elements(By.CSS_SELECTOR, ".arithmatex"):  # the math is typeset (MathJax's SVG)
                _wait(drv, lambda d: d.find_elements(By.CSS_SELECTOR, ".arithmatex mjx-container svg"))
                assert not drv.find_elements(By.CSS_SELECTOR, "mjx-merror"), f"{name}: a TeX error"
            drv.save_screenshot(str(SCREENSHOTS / name.replace(".html", ".png")))
            visited.append(name)
            errors += [f"{name}: {e['message']}" for e in drv.get_log("browser") if e["level"] == "SEVERE"]
        # search, offline: the index is inlined in the pages (the offline plugin)
        drv.get(home)
        box = drv.find_element(By.CSS_SELECTOR, "input.md-search__input")
        box.click()
        box.send_keys("observer")
        hits = _wait(drv, lambda d: d.find_elements(By.CSS_SELECTOR, "li.md-search-result__item"))
        assert hits, "search found nothing"
        drv.save_screenshot(str(SCREENSHOTS / "search.png"))
        errors += [f"search: {e['message']}" for e in drv.get_log("browser") if e["level"] == "SEVERE"]
    finally:
        drv.quit()
    assert not errors, f"errors in the browser's console: {errors[:10]}"
    assert len(visited) == len(pages)
