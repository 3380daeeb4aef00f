"""Ctrl-C that a long run cannot lose.

Python raises ``KeyboardInterrupt`` wherever the main thread next runs Python code.  When that is a
finalizer, a weakref callback or a callback from native code (JAX drops and collects arrays and traced
objects all the time), Python prints "Exception ignored in ..." and the interrupt is gone: the solver
carries on.  ``jaxobs tune``'s Ctrl-C test saw a process still iterating 120 s after its SIGINT, twice in
full test runs (never alone).  So the command line's handler also *records* the Ctrl-C, and the loops that
run for long (each solver iteration) call :func:`check`, which raises it again if it was swallowed.
"""

from __future__ import annotations

import signal
import threading

__all__ = ["installed", "check"]

_hit = threading.Event()


def _handler(signum, frame):
    _hit.set()
    raise KeyboardInterrupt


class installed:
    """``with installed():`` the recording handler on SIGINT, if SIGINT has Python's default handler and this is
    the main thread (an ignored SIGINT, ``nohup``'s, stays ignored); the previous handler back on exit."""

    def __enter__(self):
        _hit.clear()
        self._previous = None
        if threading.current_thread() is threading.main_thread():
            if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
                self._previous = signal.signal(signal.SIGINT, _handler)
        return self

    def __exit__(self, *exc):
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
        _hit.clear()
        return False


def check() -> None:
    """Raise ``KeyboardInterrupt`` if a Ctrl-C came under :class:`installed` (whether or not it was swallowed)."""
    if _hit.is_set():
        raise KeyboardInterrupt
