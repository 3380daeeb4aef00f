"""Test configuration: every test runs in float64 (jax_enable_x64), set once here.

Comparisons with closed forms, NumPy loops and python-control need double
precision; a test that checks float32 behaviour asks for float32 arrays
explicitly.

Compilations that take over a second are kept in JAX's persistent cache
(``JAXOBS_TEST_CACHE``, default ``~/.cache/jaxobs/jax-tests``; empty string: off),
so a second ``make test`` on the same machine skips most of XLA's work.  The
cache changes no number: a cached executable is the same program.
"""

import os
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

_cache = os.environ.get("JAXOBS_TEST_CACHE", str(Path.home() / ".cache" / "jaxobs" / "jax-tests"))
# the command line run in a subprocess (tests/test_cli.py, ...) keeps its compilations in the same folder
# (jaxobs.use_compile_cache reads JAXOBS_CACHE_DIR), not in the user's own cache; "off" where the cache is off
os.environ["JAXOBS_CACHE_DIR"] = _cache or "off"
if _cache:
    jax.config.update("jax_compilation_cache_dir", _cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
