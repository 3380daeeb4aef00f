"""JAX's persistent compilation cache, in one call: compiled once per machine.

Every new process compiles its programs again: a drive closed loop takes several
seconds of XLA work, a tuning job tens.  JAX can keep compiled executables on disk
and reuse them in the next process (``jax_compilation_cache_dir``); a cached
executable is the same program, so no number changes.

``use_compile_cache()`` turns it on in a per-user folder; the ``jaxobs`` command
line calls it first thing (``--no-cache`` or ``JAXOBS_CACHE_DIR=off`` turn it off).
The folder is, in order: the ``path`` argument, ``$JAXOBS_CACHE_DIR``,
``$XDG_CACHE_HOME/jaxobs/jax``, ``~/.cache/jaxobs/jax``.

Every compilation is written (``min_compile_s=0``, JAX's
``jax_persistent_cache_min_compile_time_secs``): a threshold leaves out most of a tuning
job's compilations (the metrics, the scoring, the linear structure, JAX's one-operation
programs), each short but together more compile time than the few big ones; reading an
entry back is cheap and the cache is small (``python -m benchmarks.first_second``,
docs/performance.md).
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

from .programs import ProgramCache, set_program_cache

__all__ = ["use_compile_cache", "CACHE_ENV"]

CACHE_ENV = "JAXOBS_CACHE_DIR"
_OFF = ("", "0", "off", "none", "false", "no")


def _default_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "jaxobs" / "jax"


def use_compile_cache(
    path: str | os.PathLike | None = None, *, min_compile_s: float = 0.0, keep_traces: bool = True
) -> Path | None:
    """Keep JAX's compiled programs in a folder, across processes.

    Call it before the computations whose compilations should be kept; it may be called again to move
    the cache.  The folders are created with mode 0700 (only the user may read them).

    Args:
        path: The folder (default: ``$JAXOBS_CACHE_DIR``, else the user's cache folder).
        min_compile_s: Seconds (≥ 0); compilations shorter than this are not written (default: every one).
        keep_traces: Whether the programs of :func:`jaxobs.kept_jit` keep their traces too, in
            ``<folder>/traced`` (a :class:`jaxobs.ProgramCache`: a second process skips tracing and lowering).

    Returns:
        The folder, or ``None`` where the cache is off (``JAXOBS_CACHE_DIR`` set to ``off``, ``0`` or an
        empty string, with no ``path`` given).

    Raises:
        ValueError: ``min_compile_s`` is not a number ≥ 0, or the folder cannot be created.
    """
    if isinstance(min_compile_s, bool) or not isinstance(min_compile_s, int | float) or not min_compile_s >= 0:
        raise ValueError(f"use_compile_cache: min_compile_s must be a number >= 0 (seconds), got {min_compile_s!r}")
    if path is None:
        env = os.environ.get(CACHE_ENV)
        if env is not None and env.strip().lower() in _OFF:
            return None
        folder = Path(env).expanduser() if env is not None else _default_dir()
    else:
        folder = Path(path).expanduser()
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    except OSError as e:
        raise ValueError(
            f"{CACHE_ENV}: cannot create the compilation cache folder {str(folder)!r} ({e.strerror or e}); "
            f"set {CACHE_ENV}=off to run without it"
        ) from None
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_s))
    set_program_cache(ProgramCache(folder / "traced" if keep_traces else None))
    return folder
