"""Execute the notebooks in place, storing their outputs: the documentation site renders them as stored.

    python notebooks/execute.py                  # all of them (minutes: the full grids, not the CI's small ones)
    python notebooks/execute.py 03_leso_robustness.ipynb

Run it after changing a notebook, or code whose results a notebook shows.  Each notebook is executed at
full size (``JAXOBS_NOTEBOOK_SMALL=0``) from a clean state, without cell timings (two runs write the same
file where the results are the same), and stamped in its metadata (``metadata.jaxobs``) with the sha256
of its code cells' sources and the versions that ran it.  ``tests/test_notebooks.py`` fails when a code
cell changed after the stamp (the stored outputs are not that code's), and its slow test re-executes each
notebook and compares the lines it prints with the stored ones.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
TIMEOUT_S = 1200  # per cell


def code_sha256(nb) -> str:
    """The sha256 of a notebook's code cells' sources, in order: what its stored outputs were computed from."""
    sources = [c.source for c in nb.cells if c.cell_type == "code"]
    return hashlib.sha256(json.dumps(sources, ensure_ascii=False).encode()).hexdigest()


def execute(path: Path) -> float:
    """Execute ``path`` in place (its folder as the working directory); the seconds it took."""
    import nbformat
    from nbclient import NotebookClient

    from jaxobs.io.provenance import versions

    nb = nbformat.read(path, as_version=4)
    for c in nb.cells:  # from a clean state: nothing of an earlier run survives a cell that fails
        if c.cell_type == "code":
            c.outputs, c.execution_count = [], None
            c.metadata.pop("execution", None)
    os.environ["JAXOBS_NOTEBOOK_SMALL"] = "0"
    t0 = time.time()
    NotebookClient(
        nb,
        timeout=TIMEOUT_S,
        kernel_name="python3",
        record_timing=False,
        resources={"metadata": {"path": str(path.parent)}},
    ).execute()
    seconds = time.time() - t0
    ran = {k: v for k, v in versions().items() if k != "x64"}  # x64 is set by each notebook, not here
    nb.metadata["jaxobs"] = {"code_sha256": code_sha256(nb), "versions": ran}
    # no widget state: for it the site would load the widgets' JavaScript from a CDN; the site is offline, and the
    # gain sliders' widget cell shows no output there (mkdocs.yml, remove_tag_config)
    nb.metadata.pop("widgets", None)
    nbformat.write(nb, path)
    return seconds


def main(names: list[str]) -> int:
    paths = [HERE / n for n in names] if names else sorted(HERE.glob("*.ipynb"))
    for p in paths:
        print(f"{p.name}: executed in {execute(p):.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
