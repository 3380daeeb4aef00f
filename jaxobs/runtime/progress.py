"""Progress of long library calls: silent by default, a tqdm bar on stderr, or the caller's callback.

The library prints nothing unless asked: a long function (a study, a paper's reproduction) takes
``progress=`` and hands it to :class:`Progress`:

- ``None`` or ``False``: nothing;
- ``True``: a `tqdm <https://tqdm.github.io>`_ bar on stderr (stdout stays the command's output);
- ``"auto"``: a bar when stderr is a terminal, else nothing (what the command line asks for: a log or
  a pipe keeps its one line per error, and no carriage-return animation);
- a callable ``progress(done, total)``: called after each unit of work (``total`` may be ``None``
  when the amount is not known in advance).

:meth:`Progress.stage` names what runs now ("compiling SOGIFLL", an experiment's name), so that the
first compilation, which can take tens of seconds, is announced instead of silent.

While a bar is drawn, what Python would print on stderr beside it goes through ``tqdm.write`` (on its own
line above the bar, which is then redrawn) instead of into the bar's line: warnings (``warnings.warn``),
and log records that reach the console (the root logger's console handlers, and logging's last resort,
which JAX's loggers reach by default).  Both are restored when the bar closes.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import warnings
import weakref
from collections.abc import Callable
from typing import Any, TypeAlias

__all__ = ["Progress", "ProgressArg", "check_progress", "close_all"]

# what a ``progress=`` argument may be: None or False (nothing), True (a bar), "auto" (a bar on a terminal), or a
# callable progress(done, total)
ProgressArg: TypeAlias = "bool | str | Callable[[int, int | None], Any] | None"

_OPEN: weakref.WeakSet = weakref.WeakSet()  # the Progress objects whose bar is drawn now (close_all)


def check_progress(progress: ProgressArg, owner: str = "progress") -> ProgressArg:
    """Check a ``progress=`` argument.

    Args:
        progress: None, a bool, ``"auto"`` or a callable ``progress(done, total)`` (module doc).
        owner: The argument's name in the error.

    Returns:
        ``progress``.

    Raises:
        ValueError: ``progress`` is none of these.
    """
    if progress is None or isinstance(progress, bool) or callable(progress) or progress == "auto":
        return progress
    raise ValueError(f"{owner} must be True, False, None, 'auto' or a callable progress(done, total), got {progress!r}")


class Progress:
    """One progress report, as ``progress`` asks (module doc).

    Args:
        progress: None, a bool, ``"auto"`` or a callable ``progress(done, total)``.
        total: The units of work (``None``: unknown).
        desc: The bar's description.
        unit: The unit's name.
    """

    def __init__(self, progress: ProgressArg, total: int | None, desc: str, unit: str = "it"):
        progress = check_progress(progress)
        self.total, self.done, self.desc = total, 0, desc
        self._callback = progress if callable(progress) and not isinstance(progress, bool) else None
        self._bar = None
        if progress == "auto":
            isatty = getattr(sys.stderr, "isatty", None)
            progress = bool(isatty is not None and isatty())
        if progress is True:
            from tqdm import tqdm

            self._bar = tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True, leave=True)
            self._routed = _route_to_bars(tqdm)
            _OPEN.add(self)

    def stage(self, text: str) -> None:
        """Name what runs now (shown at once in the bar's description).

        Args:
            text: What runs now ("": the bar's own name alone).
        """
        if self._bar is not None:
            self._bar.set_description_str(f"{self.desc}: {text}" if text else self.desc, refresh=True)

    def update(self, n: int = 1, **postfix: Any) -> None:
        """Report more units done.

        Args:
            n: The units done since the last call.
            **postfix: Values shown after the bar (objective, best, ...).
        """
        self.done += n
        if self._bar is not None:
            if postfix:
                self._bar.set_postfix(postfix, refresh=False)
            self._bar.update(n)
        if self._callback is not None:
            self._callback(self.done, self.total)

    def close(self) -> None:
        """Close the bar (warnings and logging go where they went before); a second call does nothing."""
        if self._bar is not None:
            self._routed.close()  # warnings and logging as they were
            self._bar.close()
            self._bar = None
            _OPEN.discard(self)

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def close_all() -> int:
    """Close every bar still drawn (a call interrupted by Ctrl-C leaves its bars open until they
    are collected, and tqdm redraws a bar when it closes): the command line calls it before its last line, so
    that nothing is drawn after that line.

    Returns:
        How many bars were closed.
    """
    bars = list(_OPEN)
    for p in bars:
        p.close()
    return len(bars)


class _BarLogHandler(logging.Handler):
    """A log record written by ``tqdm.write`` (above the bars) where the console handler ``like`` wrote it
    (stderr for logging's last resort), with its level and format."""

    def __init__(self, tqdm_cls: Any, like: logging.Handler | None):
        super().__init__(logging.WARNING if like is None else like.level)
        self.tqdm_cls = tqdm_cls
        self.like = like
        if like is not None and like.formatter is not None:
            self.setFormatter(like.formatter)

    def emit(self, record):
        try:
            # read at each record: logging's last resort writes to whatever sys.stderr is now
            stream = self.like.stream if isinstance(self.like, logging.StreamHandler) else sys.stderr
            self.tqdm_cls.write(self.format(record), file=stream)
        except Exception:
            self.handleError(record)


def _route_to_bars(tqdm_cls) -> contextlib.ExitStack:
    """Warnings and console log records through ``tqdm_cls.write`` until the returned stack is closed (module
    doc).  Bars nest (a study's inside a command's): each restores what it found, the innermost first."""
    stack = contextlib.ExitStack()
    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if file is not None and file is not sys.stderr:  # a warning sent to a file of its own goes there
            return shown(message, category, filename, lineno, file, line)
        text = warnings.formatwarning(message, category, filename, lineno, line)
        tqdm_cls.write(text, file=sys.stderr, end="")

    warnings.showwarning = show
    stack.callback(setattr, warnings, "showwarning", shown)
    last = logging.lastResort
    logging.lastResort = _BarLogHandler(tqdm_cls, last)
    stack.callback(setattr, logging, "lastResort", last)
    root = logging.getLogger()
    for h in list(root.handlers):
        if isinstance(h, logging.StreamHandler) and h.stream in (sys.stderr, sys.stdout):
            bar_h = _BarLogHandler(tqdm_cls, h)
            root.removeHandler(h)
            root.addHandler(bar_h)
            stack.callback(root.addHandler, h)
            stack.callback(root.removeHandler, bar_h)
    return stack
