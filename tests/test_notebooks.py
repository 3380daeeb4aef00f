"""Every notebook executes without error (small-grid switch JAXOBS_NOTEBOOK_SMALL=1).

Budget: each notebook under 240 s on 2 CPU cores (measured: see README); slow-marked, run by CI.
No notebook forces a matplotlib backend: under ipykernel the inline backend shows its figures, and
every executed notebook must show at least one (an ``image/png`` output).
"""

import time
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = sorted((Path(__file__).parents[1] / "notebooks").glob("*.ipynb"))
BUDGET_S = 240


def test_notebooks_are_stripped():
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code"), path.name


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes(path, monkeypatch):
    monkeypatch.setenv("JAXOBS_NOTEBOOK_SMALL", "1")
    nb = nbformat.read(path, as_version=4)
    t0 = time.time()
    NotebookClient(
        nb, timeout=BUDGET_S, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}
    ).execute()
    elapsed = time.time() - t0
    print(f"\n{path.name}: {elapsed:.1f} s")
    assert elapsed < BUDGET_S
    images = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if "image/png" in o.get("data", {})]
    assert images, f"{path.name} shows no figure (an image/png output)"


def test_notebooks_force_no_backend():
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        assert not any("matplotlib.use(" in c.source for c in nb.cells), path.name
