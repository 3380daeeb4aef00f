"""Test configuration: every test runs in float64 (jax_enable_x64), set once here.

Comparisons with closed forms, NumPy loops and python-control need double
precision; a test that checks float32 behaviour asks for float32 arrays
explicitly.

Every compilation is kept in JAX's persistent cache (``JAXOBS_TEST_CACHE``,
default ``~/.cache/jaxobs/jax-tests``; empty string: off), so a second ``make test``
on the same machine skips most of XLA's work, and the two pytest workers and the
command lines run in subprocesses reuse each other's programs.  All of them, as the
command line keeps them (jaxobs.runtime.cache): with only those over 1 s kept, the small
ones (metrics, eager operations, the linear analysis) were compiled again in every
process; tests/test_fll.py cached went 14.0 -> 10.4 CPU-s, cold unchanged.  The
cache changes no number: a cached executable is the same program.

Every test process has one CPU device unless a test asks for more: ``JAXOBS_HOST_DEVICES=1``, which
``jaxobs.use_host_devices`` (and so the command line) reads, here and in the processes tests start.  A
study's chunks are padded to a multiple of the device count, so a count taken from the machine's cores
(the command line's default) made chunk counts depend on the machine, and on whether the command line
was the first JAX computation of its pytest worker.
"""

import os
from pathlib import Path

import jax
import pytest

jax.config.update("jax_enable_x64", True)
os.environ["JAXOBS_HOST_DEVICES"] = "1"

_cache = os.environ.get("JAXOBS_TEST_CACHE", str(Path.home() / ".cache" / "jaxobs" / "jax-tests"))
# the command line run in a subprocess (tests/test_cli.py, ...) keeps its compilations in the same folder
# (jaxobs.use_compile_cache reads JAXOBS_CACHE_DIR), not in the user's own cache; "off" where the cache is off
os.environ["JAXOBS_CACHE_DIR"] = _cache or "off"
if _cache:
    jax.config.update("jax_compilation_cache_dir", _cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)


@pytest.fixture(autouse=True)
def _no_program_cache_after():
    """The command line run in this process (``main``) sets a program cache (jaxobs.use_compile_cache): off again
    after the test, so that what one test kept is not what the next one runs."""
    yield
    from jaxobs.runtime.programs import set_program_cache

    set_program_cache(None)
