"""JAX's persistent compilation cache, in one call: compiled once per machine.

``use_compile_cache()`` keeps compiled executables on disk (``jax_compilation_cache_dir``) for the next process:
the same programs, so no number changes.  The ``jaxobs`` command line calls it first thing (``--no-cache`` or
``JAXOBS_CACHE_DIR=off`` turn it off).  Every compilation is written (``min_compile_s=0``): a threshold leaves out
most of a tuning job's compilations, each short but together more than the few big ones
(``python -m benchmarks.first_second``, docs/performance.md).
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

from .programs import ProgramCache, set_program_cache

__all__ = ["use_compile_cache", "CACHE_ENV"]

CACHE_ENV = "JAXOBS_CACHE_DIR"
_OFF = ("", "0", "off", "none", "false", "no")


def use_compile_cache(
    path: str | os.PathLike | None = None, *, min_compile_s: float = 0.0, keep_traces: bool = True
) -> Path | None:
    """Keep JAX's compiled programs in a folder (mode 0700), across processes; call it again to move it.

    Args:
        path: The folder (default: ``$JAXOBS_CACHE_DIR``, else ``$XDG_CACHE_HOME/jaxobs/jax``, else
            ``~/.cache/jaxobs/jax``).
        min_compile_s: Seconds (≥ 0); compilations shorter than this are not written (default: every one).
        keep_traces: Whether :func:`jaxobs.kept_jit` keeps its traced programs too, in ``<folder>/traced``
            (a :class:`jaxobs.ProgramCache`: a second process skips tracing and lowering).

    Returns:
        The folder, or ``None`` where the cache is off (``JAXOBS_CACHE_DIR`` set to ``off``, ``0`` or an
        empty string, with no ``path`` given).

    Raises:
        ValueError: ``min_compile_s`` is not a number ≥ 0, or the folder cannot be created.
    """
    if isinstance(min_compile_s, bool) or not isinstance(min_compile_s, int | float) or not min_compile_s >= 0:
        raise ValueError(f"use_compile_cache: min_compile_s must be a number >= 0 (seconds), got {min_compile_s!r}")
    env = os.environ.get(CACHE_ENV) if path is None else str(path)
    if path is None and env is not None and env.strip().lower() in _OFF:
        return None
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    folder = Path(env).expanduser() if env is not None else Path(base) / "jaxobs" / "jax"
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
