"""What every command of the command line shares: its output folder, its progress, float64."""

from __future__ import annotations

from pathlib import Path

from .outdir import OutDir


class CommandOut(OutDir):
    """``with CommandOut(args, files) as out``: ``--out`` checked and locked before any work (jaxobs_tuning.outdir), its
    path as the value; an internal error's log goes there."""

    def __init__(self, args, files):
        super().__init__(Path(args.out), files, force=args.force)
        self.args = args

    def __enter__(self) -> Path:
        super().__enter__()
        self.args.log_dir = self.path
        return self.path


def progress_of(args=None, quiet=None):
    """The library's ``progress`` for a command: bars when stderr is a terminal, none with --quiet."""
    quiet = args.quiet if quiet is None else quiet
    return False if quiet else "auto"


def enable_x64():
    import jax

    jax.config.update("jax_enable_x64", True)
