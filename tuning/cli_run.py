"""The command line's runner: a parsed command run with its error handling (one line and exit 2 for bad input,
an internal error's traceback to a log), the parser class and the options every command takes.

Apart from :mod:`jaxobs_tuning.cli` so that the console script (:mod:`jaxobs_tuning.cli_entry`) can run ``jaxobs
drive ...`` through a parser of that command alone: the full parser imports every command's module (the tuning
jobs, their solvers, optax and optimistix: about half a second) that a drive file's check never uses.
"""

from __future__ import annotations

import argparse
import linecache
import os
import sys
import tempfile
import traceback
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

import jaxobs
from jaxobs import use_compile_cache, use_host_devices

from .cli_common import native_stderr_to_log
from .outdir import atomic_write_text

__all__ = ["Parser", "quiet_parent", "run_parser"]


class Parser(argparse.ArgumentParser):
    """The command line's parser: an argparse error is one line and exit 2, no usage dump."""

    def error(self, message: str) -> NoReturn:
        """One line on stderr and exit 2, no usage dump.

        Args:
            message: argparse's message.

        Raises:
            SystemExit: Always (status 2).
        """
        self.exit(2, f"jaxobs: error: {message}\n")


def quiet_parent() -> argparse.ArgumentParser:
    """The options every command takes: --quiet, no progress on stderr (stdout, the results, is the same either
    way), and --no-cache.

    Returns:
        The parent parser.
    """
    quiet = Parser(add_help=False)
    quiet.add_argument(
        "--quiet",
        action="store_true",
        help="no progress bars or compile notices on stderr; XLA's own messages (its slow-compile alarms) go to "
        "$JAXOBS_NATIVE_LOG or ~/.cache/jaxobs/xla.log",
    )
    quiet.add_argument(
        "--no-cache",
        action="store_true",
        help="do not keep compiled programs on disk (default: kept in $JAXOBS_CACHE_DIR or ~/.cache/jaxobs/jax, "
        "so a second run skips most of XLA's work; JAXOBS_CACHE_DIR=off turns it off too)",
    )
    return quiet


def run_parser(parser: argparse.ArgumentParser, argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` with ``parser`` and run the command it names (``args.func``): bad input (a ``ValueError``,
    an ``OSError``) one line and exit 2, Ctrl-C exit 130, an internal error one line and its traceback in a log.

    Args:
        parser: The parser (the full one, or one command's).
        argv: The arguments (default ``sys.argv[1:]``).

    Returns:
        The exit status.
    """
    args = None
    shown = warnings.showwarning

    # a recording's warning (RecordingWarning), an old metric name read (MetricNameWarning) as the tool's own line
    def one_line(message, category, *a, **k):
        if category.__name__ in ("RecordingWarning", "MetricNameWarning"):
            print(f"jaxobs: warning: {message}", file=sys.stderr)
        else:
            shown(message, category, *a, **k)

    warnings.showwarning = one_line
    warnings.filterwarnings("default", ".*is an old metric name", DeprecationWarning)  # shown once per place
    try:
        use_host_devices()  # before any JAX computation: one CPU device per usable core
        args = parser.parse_args(argv)
        if args.cmd is None:  # `jaxobs` alone: the commands, not argparse's "arguments are required: cmd"
            parser.print_help(sys.stderr)
            return 2
        if not getattr(args, "no_cache", False):
            use_compile_cache()  # before any compilation: compiled programs are reused by the next process
        with native_stderr_to_log(getattr(args, "quiet", False)):  # XLA's own alarms to a log under --quiet
            return args.func(args)
    except ValueError as e:
        if not _raised_by_a_check(e):  # numpy, JAX, math.log...: a fault of ours, not the user's input
            return _internal_error(e, args)
        print(f"jaxobs: error: {e}", file=sys.stderr)  # bad input, job-file errors (JobError) included
        return 2
    except OSError as e:  # an output folder that cannot be made or written, a file that cannot be read
        where = f": {e.filename}" if e.filename else ""
        print(f"jaxobs: error: {e.strerror or e}{where}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        from jaxobs.runtime.progress import close_all

        # the bars closed first (tqdm draws a bar as it closes: nothing is drawn after the line below), which
        # ends their line; else on a line of its own, a bar may hold the terminal's current line
        start = "" if close_all() or not sys.stderr.isatty() else "\n"
        print(f"{start}jaxobs: interrupted{_interrupt_hint(args)}", file=sys.stderr)
        return 130
    except (Exception, MemoryError) as e:  # an internal error: the traceback to a log, one line here
        return _internal_error(e, args)
    finally:
        warnings.showwarning = shown


# the folders of the two packages, each with its separator (``.../tuning/``, ``.../jaxobs/``)
_OURS = tuple(str(Path(f).resolve().parent) + os.sep for f in (__file__, jaxobs.__file__))


def _raised_by_a_check(e: BaseException) -> bool:
    """Whether ``e`` is a check's verdict on the input: raised by a ``raise`` statement in jaxobs or its tuning
    package (a field's range, a job file's key, a recording's column), not by a library or an operation of ours
    that met a value it cannot take (``math.log(-1)``, a shape NumPy cannot broadcast, JAX's own ``ValueError``).

    Both are ``ValueError``; only the first is the user's to fix, and shown as one line.  The second is a fault
    of ours: one line too, but its traceback goes to a log, as for any internal error.  Told apart by where the
    exception was raised (its traceback's last frame) and how (that line is a ``raise``).
    """
    tb = e.__traceback__
    if tb is None:
        return False
    while tb.tb_next is not None:
        tb = tb.tb_next
    filename = str(Path(tb.tb_frame.f_code.co_filename).resolve())
    if not filename.startswith(_OURS):
        return False
    return linecache.getline(filename, tb.tb_lineno).lstrip().startswith("raise")


def _internal_error(e: BaseException, args: argparse.Namespace | None) -> int:
    """One line for an internal error, its traceback in a log (``args.log_dir``, else a temporary file); exit 1."""
    log = _write_error_log(getattr(args, "log_dir", None))
    what = "out of memory" if isinstance(e, MemoryError) else f"internal error ({type(e).__name__})"
    print(f"jaxobs: {what}: {' '.join(str(e).split())[:120]} — traceback in {log}", file=sys.stderr)
    return 1


def _interrupt_hint(args: argparse.Namespace | None) -> str:
    """What Ctrl-C adds to "interrupted": ``args.on_interrupt``, a text or a callable that gives it."""
    hint = getattr(args, "on_interrupt", "")
    try:
        return str(hint()) if callable(hint) else str(hint)
    except OSError:
        return ""


def _write_error_log(out) -> str:
    """The current exception's traceback to ``<out>/error.log`` (else a temporary file); its path."""
    text = traceback.format_exc()
    if out is not None:
        try:
            path = Path(out) / "error.log"
            atomic_write_text(path, text)  # renamed over the name: a link there is replaced, never written through
            return str(path)
        except OSError:
            pass
    try:
        fd, path = tempfile.mkstemp(prefix="jaxobs-error-", suffix=".log")
        with open(fd, "w") as f:
            f.write(text)
        return path
    except OSError:
        return "(no log: nothing writable)"
