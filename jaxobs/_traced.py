"""Traced programs kept across processes (issue 31: compiled once per machine, traced once too).

JAX's persistent compilation cache (:func:`jaxobs.use_compile_cache`) keeps XLA's work, but it keys
on the lowered program, so every new process still traces each jitted function to a jaxpr and lowers
it to StableHLO before it can look the executable up: for the default tuning job, 2-4 s of a 10 s warm
run (the objective's value-and-gradient, the scoring, the margins).  :func:`kept_jit` keeps that
work too.  The first call with a given key exports the program (``jax.export``: the traced and lowered
StableHLO, serialized) to ``<cache folder>/traced/``; a later process reads it back and runs it
(``Exported.call``), which compiles, or reads from the compilation cache, the same program.

The key is the caller's word for everything static the function depends on (the job file's digest,
say: the scenarios and the component a closure holds are baked into the program as constants).  To
it are added the source of the packages the code comes from (every ``.py`` file of ``jaxobs`` and of
the function's top package: an edited file is a new key), the versions of JAX and the libraries that
trace, the JAX options that change a trace, and the arrays' shapes, dtypes and tree structure.  What
the key does not name must not change the program: a call site without such a key uses plain
``eqx.filter_jit``.

A program run through ``Exported.call`` gives the same numbers bit for bit as the plain jit
(tests/test_traced.py; result.json of the default job compared byte for byte).  Off (plain
``eqx.filter_jit``) where no folder is set: :func:`jaxobs.use_compile_cache` sets it (the command
line, unless ``--no-cache`` or ``JAXOBS_CACHE_DIR=off``), or where a program cannot be exported
(a host callback, an output that is not arrays in tuples, lists, dicts and registered NamedTuples): then it
is traced as before.
The folder keeps the :data:`MAX_KEPT` most recently used programs (an edited source makes new keys).
"""

from __future__ import annotations

import hashlib
import os
import sys
import tempfile
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _pkg_version
from pathlib import Path

import equinox as eqx
import jax
from jax import export  # serialization needs flatbuffers (a dependency)

__all__ = ["kept_jit", "set_traced_dir", "traced_dir"]

# the libraries whose code runs while a jaxobs program is traced
_LIBS = ("jax", "jaxlib", "equinox", "diffrax", "optax", "optimistix", "lineax", "numpy")
# the JAX options that change what a trace produces
_OPTIONS = (
    "jax_enable_x64",
    "jax_default_matmul_precision",
    "jax_numpy_dtype_promotion",
    "jax_numpy_rank_promotion",
    "jax_default_prng_impl",
    "jax_threefry_partitionable",
    "jax_enable_checks",
    "jax_debug_nans",
    "jax_debug_infs",
    "jax_disable_jit",
)

_state: dict = {"dir": None}
_digests: dict[str, str] = {}


def set_traced_dir(folder: str | os.PathLike | None) -> None:
    """Keep exported programs in ``folder`` (``None``: do not; every :func:`kept_jit` traces as a plain jit)."""
    _state["dir"] = None if folder is None else Path(folder)


def traced_dir() -> Path | None:
    """The folder exported programs are kept in, or ``None`` (off)."""
    return _state["dir"]


def _package_digest(package: str) -> str:
    """sha256 over every ``.py`` file (relative path and bytes) of the installed package ``package``."""
    if package not in _digests:
        mod = sys.modules.get(package)
        h = hashlib.sha256(package.encode())
        files = getattr(mod, "__file__", None)
        if files is not None:
            root = Path(files).resolve().parent
            for f in sorted(root.rglob("*.py")):
                h.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes() + b"\0")
        _digests[package] = h.hexdigest()
    return _digests[package]


def _lib_version(name: str) -> str:
    try:
        return _pkg_version(name)
    except PackageNotFoundError:
        return "unknown"


def _environment() -> str:
    if "libs" not in _digests:  # read once: importlib.metadata costs ~1 ms a package, and this runs every call
        _digests["libs"] = ",".join(f"{n}={_lib_version(n)}" for n in _LIBS)
    libs = _digests["libs"]
    opts = ",".join(f"{o}={getattr(jax.config, o, None)!r}" for o in _OPTIONS)
    dev = jax.devices()[0]
    # the device count too: a program split over two host devices is another program than one device's
    kind = f"{dev.platform};{getattr(dev, 'device_kind', '')};{jax.device_count()};{jax.process_count()}"
    return f"{libs};{opts};{kind};{sys.version_info[:2]}"


class _Kept:
    """``eqx.filter_jit(fn)``, with the traced program kept in :func:`traced_dir` under ``key``."""

    def __init__(self, fn, key: str, packages: tuple[str, ...]):
        self.fn, self.key = fn, key
        self.packages = tuple(sorted({"jaxobs", *packages}))
        self.jitted = eqx.filter_jit(fn)
        self.programs: dict[str, object] = {}  # full key -> a jitted Exported.call (None: not exportable)

    def __call__(self, *args):
        folder = traced_dir()
        if folder is None:
            return self.jitted(*args)
        dynamic, static = eqx.partition(args, eqx.is_array)
        leaves, tree = jax.tree.flatten(dynamic)
        avals = ";".join(f"{x.shape}{x.dtype}{'w' if getattr(x, 'weak_type', False) else ''}" for x in leaves)
        parts = [self.key, _environment(), str(tree), avals, *(_package_digest(p) for p in self.packages)]
        full = hashlib.sha256("\n".join(parts).encode()).hexdigest()
        if full not in self.programs:
            self.programs[full] = self._program(folder / f"{full}.jaxexport", leaves, tree, static)
        run = self.programs[full]
        return self.jitted(*args) if run is None else run(*leaves)

    def _program(self, path: Path, leaves, tree, static):
        try:
            exp = export.deserialize(bytearray(path.read_bytes()))
            os.utime(path)  # recently used: the last to go when the folder is trimmed
        except Exception:  # absent, unreadable or corrupt (flatbuffers raises what it meets): exported anew
            exp = None

        def flat(*xs):
            return self.fn(*eqx.combine(jax.tree.unflatten(tree, xs), static))

        if exp is None:
            try:
                exp = export.export(jax.jit(flat))(*leaves)
                blob = exp.serialize()
            except Exception:
                # not exportable (a host callback, an output of custom classes): a plain jit, as before (a
                # real error in fn is raised there)
                return None
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".jaxexport")
                with os.fdopen(fd, "wb") as f:
                    f.write(blob)
                os.replace(tmp, path)  # whole or absent: a concurrent reader never sees half a file
                _trim(path.parent)
            except OSError:  # a read-only cache: the program still runs, the next process traces again
                pass
        run = jax.jit(exp.call)
        if exp.nr_devices != 1:
            return run
        # an exported program's results are committed to their device, so a later call that passes them back
        # (the solver's θ) would differ in its arguments' placement from the first and compile the program a
        # second time; placing every argument on the device first gives one placement, one compilation
        dev = jax.devices()[0]
        return lambda *xs: run(*jax.device_put(xs, dev))


# Every edit of the source is a new key, so the folder keeps at most this many programs (the least recently
# used go first): the default job keeps 7, a study 2-3, each 10-100 kB.
MAX_KEPT = 1000


def _trim(folder: Path, keep: int = MAX_KEPT) -> None:
    """Delete the least recently used programs of ``folder`` beyond ``keep`` (another process may race: ignored)."""
    try:
        files = sorted(folder.glob("*.jaxexport"), key=lambda f: f.stat().st_mtime)
        for f in files[: max(0, len(files) - keep)]:
            f.unlink(missing_ok=True)
    except OSError:
        pass


def kept_jit(fn, key: str, *, packages: tuple[str, ...] = ()):
    """``eqx.filter_jit(fn)`` whose traced and lowered program is kept across processes under ``key``.

    ``key`` (a string) must name everything static that ``fn`` depends on and that is not in its array
    arguments' shapes and dtypes or the source of ``jaxobs``, of ``fn``'s top package and of ``packages``
    (top-level package names, e.g. ``("jaxobs_tuning",)`` for code that made a closure ``fn`` calls):
    a job's digest, the values a closure captured.  Called with positional arguments only; the outputs
    must be arrays in tuples, lists, dicts and NamedTuples registered for ``jax.export`` (the drive's step
    outputs are, by :mod:`jaxobs.reproduce._run`) to be kept (else the call traces every time, as a plain jit).
    """
    if not isinstance(key, str) or not key:
        raise ValueError(f"kept_jit: key must be a non-empty string, got {key!r}")
    top = (getattr(fn, "__module__", None) or "jaxobs").split(".")[0]
    return _Kept(fn, key, (top, *packages))
