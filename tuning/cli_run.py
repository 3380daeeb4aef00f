"""The command line's runner: a parsed command run with its error handling (one line and exit 2 for bad input,
an internal error's traceback to a log), the parser class and the options every command takes.

Apart from :mod:`jaxobs_tuning.cli` so that the console script (:mod:`jaxobs_tuning.cli_entry`) can run ``jaxobs
drive ...`` through a parser of that command alone: the full parser imports every command's module (the tuning
jobs, their solvers, optax and optimistix: about half a second) that a drive file's check never uses.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import traceback
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

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
    except ValueError as e:  # bad input, job-file errors (JobError) included: one line, exit 2
        print(f"jaxobs: error: {e}", file=sys.stderr)
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
        log = _write_error_log(getattr(args, "log_dir", None))
        what = "out of memory" if isinstance(e, MemoryError) else f"internal error ({type(e).__name__})"
        print(f"jaxobs: {what}: {' '.join(str(e).split())[:120]} — traceback in {log}", file=sys.stderr)
        return 1
    finally:
        warnings.showwarning = shown


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
