"""What every command of the command line shares: its output folder, its progress, float64."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
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
