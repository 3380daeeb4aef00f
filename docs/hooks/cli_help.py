"""MkDocs hook: ``<!-- cli: jaxobs ARGS -->`` in a page becomes a console block with what ``jaxobs ARGS`` prints now.

Help texts change whenever a command or an option is added; generated at build time they cannot drift, and no test
has to chase them."""

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MARK = re.compile(r"<!-- cli: jaxobs ([^>]*?) -->")


def _run(args: str) -> str:
    env = {**os.environ, "COLUMNS": "100", "PYTHONPATH": str(ROOT)}  # argparse wraps to the terminal's width
    r = subprocess.run(
        [sys.executable, "-m", "jaxobs", *args.split()], capture_output=True, text=True, env=env, timeout=300
    )
    if r.returncode != 0:
        raise RuntimeError(f"jaxobs {args} failed while building the docs: {r.stderr[-500:]}")
    return f"```console\n$ jaxobs {args}\n{r.stdout.rstrip()}\n```"


def on_page_markdown(markdown, page, config, files):
    return MARK.sub(lambda m: _run(m.group(1)), markdown)
