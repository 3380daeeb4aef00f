"""The golden-vector harness: ``test_main.c`` (written beside every export) and :func:`compile_and_check`,
which compiles it with the system C compiler and replays golden.csv through the generated step."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from importlib import resources
from pathlib import Path

TOLERANCE = 1e-4  # max |y_C − y_golden| / (1 + |y_golden|)


CFLAGS = ("-std=c99", "-O2", "-Wall", "-Werror", "-pedantic")


def harness_text() -> str:
    """The text of test_main.c, the harness written beside every export."""
    return (resources.files("jaxobs_tuning.export") / "test_main.c").read_text()


def compile_and_check(
    out_dir: str | os.PathLike[str], *, cc: str | None = None, extra_flags: Sequence[str] = ()
) -> float:
    """Compile ``out_dir``'s observer.c + test_main.c with the system C compiler and replay golden.csv.

    Runs ``cc -std=c99 -O2 -Wall -Werror -pedantic observer.c test_main.c -lm`` in a temporary
    folder and returns max |y_C − y_golden| / (1 + |y_golden|) over every step and output.

    Args:
        out_dir: The export's folder (observer.c, test_main.c, golden.csv).
        cc: The C compiler (default: ``cc`` on PATH).
        extra_flags: More compiler flags.

    Returns:
        The largest relative error.

    Raises:
        RuntimeError: No compiler, the code does not compile, or the harness cannot read the vectors.
    """
    out = Path(out_dir).resolve()
    cc = cc or shutil.which("cc")
    if cc is None:
        raise RuntimeError("no C compiler (cc) on PATH: export not checked")
    with tempfile.TemporaryDirectory() as tmp:
        exe = Path(tmp) / "jx_test"
        cmd = [cc, *CFLAGS, *extra_flags, str(out / "observer.c"), str(out / "test_main.c"), "-o", str(exe), "-lm"]
        p = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp)
        if p.returncode != 0:
            raise RuntimeError(f"export: {' '.join(cmd)} failed:\n{p.stderr}")
        r = subprocess.run([str(exe), str(out / "golden.csv")], capture_output=True, text=True, timeout=120)
    m = re.search(r"max_rel_err=(\S+)", r.stdout)
    if r.returncode not in (0, 1) or m is None:
        raise RuntimeError(f"export: the harness failed (exit {r.returncode}): {r.stdout}{r.stderr}")
    return float(m.group(1))
