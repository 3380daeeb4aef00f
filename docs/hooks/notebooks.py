"""MkDocs hook: the four notebooks of notebooks/ become pages under notebooks/ without a copy in docs/.

They are added before mkdocs-jupyter's own ``on_files`` (a higher event priority), which then renders them
with their stored outputs (``execute: false`` in mkdocs.yml: the build never runs a simulation)."""

from pathlib import Path

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[2]


@event_priority(100)
def on_files(files, config):
    for nb in sorted((ROOT / "notebooks").glob("*.ipynb")):
        files.append(
            File(
                f"notebooks/{nb.name}",
                src_dir=str(ROOT),
                dest_dir=config["site_dir"],
                use_directory_urls=config["use_directory_urls"],
            )
        )
    return files
