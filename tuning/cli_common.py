"""What every command of the command line shares: its output folder, its progress, float64."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Literal

from .outdir import OutDir


class CommandOut(OutDir):
    """``with CommandOut(args, files) as out``: ``--out`` checked and locked before any work (jaxobs_tuning.outdir), its
    path as the value; an internal error's log goes there."""

    def __init__(self, args: argparse.Namespace, files: Sequence[str]):
        super().__init__(Path(args.out), files, force=args.force)
        self.args = args

    def __enter__(self) -> Path:
        super().__enter__()
        self.args.log_dir = self.path
        return self.path


def progress_of(args: argparse.Namespace | None = None, quiet: bool | None = None) -> Literal[False, "auto"]:
    """The library's ``progress`` for a command: bars when stderr is a terminal, none with --quiet.

    Args:
        args: The command's arguments, read for ``--quiet`` when ``quiet`` is None.
        quiet: Whether --quiet was given (None: from ``args``).

    Returns:
        False with --quiet, else ``"auto"``.

    Raises:
        TypeError: Neither ``args`` nor ``quiet`` given.
    """
    if quiet is None:
        if args is None:
            raise TypeError("progress_of: give args or quiet")
        quiet = args.quiet
    return False if quiet else "auto"


def enable_x64() -> None:
    """64-bit floats in JAX for the rest of the process (what the commands compute in)."""
    import jax

    jax.config.update("jax_enable_x64", True)


def native_log_path() -> Path:
    """Where a ``--quiet`` run sends what native code writes to stderr: ``$JAXOBS_NATIVE_LOG``, else
    ``xla.log`` beside the compile cache (``$XDG_CACHE_HOME/jaxobs``, default ``~/.cache/jaxobs``).

    Returns:
        The log's path (appended to; its folder made when used).
    """
    given = os.environ.get("JAXOBS_NATIVE_LOG")
    if given:
        return Path(given)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "jaxobs" / "xla.log"


@contextlib.contextmanager
def native_stderr_to_log(quiet: bool) -> Iterator[Path | None]:
    """With ``quiet``, what native code writes to the process's stderr (file descriptor 2: XLA's C++ logging, its
    "Very slow compile" and constant-folding alarms) goes to :func:`native_log_path` for the block, while
    Python's ``sys.stderr`` (the one-line errors and warnings) stays on the terminal; both restored after.

    Only where ``sys.stderr`` is the process's own stderr (a console script, ``python -m jaxobs``): a caller that
    replaced it (a test's capture, a notebook) keeps what it has.  A log that cannot be opened changes nothing.

    Args:
        quiet: Whether the command was given ``--quiet``.

    Yields:
        The log's path, or None where nothing was redirected.
    """
    try:
        own = quiet and sys.stderr is sys.__stderr__ and sys.stderr.fileno() == 2
    except (AttributeError, OSError, ValueError):  # a stderr without a file descriptor
        own = False
    if not own:
        yield None
        return
    path = native_log_path()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        log = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    except OSError:
        yield None
        return
    sys.stderr.flush()
    terminal = os.dup(2)
    python_stderr = sys.stderr
    os.dup2(log, 2)
    os.close(log)
    sys.stderr = open(terminal, "w", buffering=1, encoding=python_stderr.encoding, errors="backslashreplace")  # noqa: SIM115
    try:
        yield path
    finally:
        sys.stderr.flush()
        os.dup2(terminal, 2)  # the descriptor back on the terminal, then Python's stream on it
        sys.stderr.close()  # closes the duplicate descriptor
        sys.stderr = python_stderr
