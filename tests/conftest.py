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

import faulthandler
import os
import tempfile
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


# ---- a worker killed by a native fault -----------------------------------------------------------------------
# XLA's CPU runtime is native code: a fault there (SIGSEGV, SIGABRT) kills the pytest worker, not only its test.
# CI saw it once, in a closed-loop reversal (tests/test_zero_speed.py) that passed in every run here, with the
# compilation cache cold and warm, alone and beside the rest of the slow suite; what CI kept of the log was the
# tail of the fault dump, without the signal or the frames.  So each worker writes its fault dump to a file of
# its own; a test whose worker died runs once more, on the worker that replaces it (a second crash fails it); and
# the summary names the test and prints the head of the dump.  An assertion that fails is never run again.
_CRASH_DIR = "JAXOBS_TEST_CRASH_DIR"
_crash_reruns: set[str] = set()
_crash_heads: list[tuple[str, str]] = []


@pytest.hookimpl(trylast=True)  # after pytest's own faulthandler plugin, which sends the dump to stderr
def pytest_configure(config):
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if worker is None:
        os.environ.setdefault(_CRASH_DIR, tempfile.mkdtemp(prefix="jaxobs-test-crash-"))
    elif os.environ.get(_CRASH_DIR):
        # kept open for the worker's life: faulthandler writes to the file descriptor when the process dies
        config._jaxobs_fault_file = open(Path(os.environ[_CRASH_DIR]) / f"{worker}.txt", "w")  # noqa: SIM115
        faulthandler.enable(file=config._jaxobs_fault_file, all_threads=False)


@pytest.hookimpl(optionalhook=True)  # pytest-xdist's hook: absent under -p no:xdist
def pytest_handlecrashitem(crashitem, report, sched):
    """pytest-xdist's hook, called in the controller when a worker died while running ``crashitem``."""
    dump = Path(os.environ.get(_CRASH_DIR, ".")) / f"{report.node.gateway.id}.txt"
    lines = dump.read_text(errors="replace").splitlines() if dump.is_file() else []
    head = "\n".join(line for line in lines[:24] if not line.startswith("Extension modules")) or "(no fault dump)"
    _crash_heads.append((crashitem, head))
    report.longrepr = f"{report.longrepr}\n{head}"
    if crashitem not in _crash_reruns:
        _crash_reruns.add(crashitem)
        sched.mark_test_pending(crashitem)
        report.outcome = "rerun"


def pytest_report_teststatus(report):
    if report.outcome == "rerun":
        return "rerun", "R", ("RERUN", {"yellow": True})
    return None


def pytest_terminal_summary(terminalreporter):
    for nodeid, head in _crash_heads:
        terminalreporter.write_sep("!", f"a worker died in {nodeid}; its fault dump begins")
        terminalreporter.write_line(head)


# ---- each test's time and its worker's memory, as it ends ----------------------------------------------------
# ``JAXOBS_TEST_TIMES=<file>``: one line per test phase appended as it ends (wall s, the worker's peak RSS in MiB,
# the node id), so that a run killed before pytest's own --durations table (a time-out, memory exhausted) still
# tells which tests took the time and the memory.  CI's slow suite sets it and prints the file's slowest lines.
@pytest.hookimpl(wrapper=True)  # where the test runs (an xdist worker, or this process): each report written once
def pytest_runtest_makereport(item, call):
    report = yield
    path = os.environ.get("JAXOBS_TEST_TIMES")
    if path and (report.when == "call" or report.duration >= 1.0):
        import resource

        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024
        worker = os.environ.get("PYTEST_XDIST_WORKER", "-")
        with open(path, "a") as f:  # one short write per line: the workers' lines do not interleave
            f.write(f"{report.duration:9.1f} s {peak:7d} MiB {worker} {report.when} {report.nodeid}\n")
    return report
