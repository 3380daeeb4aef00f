"""Traced programs kept across processes: a second process skips tracing and lowering.

JAX's persistent compilation cache (:func:`jaxobs.use_compile_cache`) keeps XLA's work, but every process still
traces and lowers each jitted function to find it.  :func:`kept_jit` exports the program (``jax.export``) to the
folder of the :class:`ProgramCache` in use, and a later process runs it read back (``Exported.call``), bit for
bit the plain jit's numbers (tests/test_traced.py).  Its key is the sha256 of what can reach the program: the
functions and classes met, by module and qualified name (a function by its place in the file too) and the values
a closure, defaults or method's object hold; the arguments' arrays by shape, dtype and weak type (by value where
no pytree reaches them) and their other values; the source of every package those names come from (every ``.py``
file: ``jaxobs``, ``jaxobs_tuning``, a user's), the libraries' versions, the JAX options that change a trace, the
devices.  What it cannot name (no source file; an object neither a container, a dataclass nor naming its
``kept_fields``) is not kept: a plain ``eqx.filter_jit``, as in a trace, across processes, or where ``jax.export``
fails.  An entry that is not a regular file holding its key and its program's sha256, or takes other inputs, is
reported once per process in one line on stderr naming the folder, and traced again and replaced.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import stat
import sys
import time
import types
from collections.abc import Callable
from importlib.metadata import version
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import numpy as np
from jax import export
from jax.core import Tracer

from ..io.files import atomic_write_bytes, is_temp

__all__ = ["ProgramCache", "kept_jit", "program_cache", "set_program_cache"]

MAX_KEPT = 1000  # every edit of the source is a new key: the least recently used entries go first
MAX_BYTES = 256 * 2**20  # the largest entry read back
_MAGIC, _SUFFIX = b"jaxobs kept program 3\n", ".jaxexport"
_LIBS = ("jax", "jaxlib", "equinox", "diffrax", "optax", "optimistix", "lineax", "numpy")  # versions in the key
_NAMED = frozenset((*_LIBS, "scipy", "jaxtyping", *sys.stdlib_module_names))  # named by module and name alone
_OPTIONS = (
    "enable_x64 default_matmul_precision numpy_dtype_promotion numpy_rank_promotion default_prng_impl "
    "threefry_partitionable enable_checks debug_nans debug_infs disable_jit".split()
)  # they change a trace
_memo: dict[str, str] = {}  # this process's package digests and library versions


def _source(top: str) -> str:
    """sha256 of every ``.py`` file of the imported top-level package or module ``top``; "" where none holds it."""
    if top not in _memo:
        _memo[top] = ""
        path = Path(getattr(sys.modules.get(top), "__file__", None) or "/")
        if path.suffix == ".py":  # else defined where no file holds it (an interactive session)
            h = hashlib.sha256()
            for f in sorted(path.parent.rglob("*.py")) if path.name == "__init__.py" else [path]:
                h.update(f"{f.relative_to(path.parent)}\0".encode() + f.read_bytes() + b"\0")
            _memo[top] = h.hexdigest()
    return _memo[top]


class _Key:
    """The sha256 of the values a program meets (module doc); a ValueError where one cannot be named."""

    def __init__(self) -> None:
        self.h, self.tops, self.seen = hashlib.sha256(), {"jaxobs"}, {}

    def put(self, *parts: Any) -> None:
        for p in map(str, parts):  # each with its length: no two sequences of parts hash alike
            self.h.update(f"{len(p)}:{p};".encode())

    def name(self, obj: Any, *consts: Any) -> None:
        module, qual = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
        if not isinstance(module, str) or not isinstance(qual, str):
            raise ValueError(f"{obj!r} has no module and name")
        top = module.split(".")[0]
        if top not in _NAMED:
            if not _source(top):
                raise ValueError(f"{module}.{qual} has no source file")
            self.tops.add(top)
        self.put("name", module, qual, len(consts))
        for x in consts:
            self.add(x, True)

    def add(self, x: Any, const: bool) -> None:
        """Hash ``x``; its arrays by value where ``const`` (a constant of the program), else by shape and dtype."""
        t = type(x)
        if x is None or t in (bool, int, float, complex, str, bytes) or isinstance(x, np.dtype):
            return self.put(t.__name__, repr(x))
        if isinstance(x, Tracer) or (eqx.is_array(x) and x.dtype == object):
            raise ValueError("a traced value or an object array")
        if eqx.is_array(x) or isinstance(x, np.generic):
            self.put("array", x.dtype.str, x.shape, bool(getattr(x, "weak_type", False)))
            if const:
                self.h.update(np.ascontiguousarray(x).tobytes())
            return None
        if (id(x), const) in self.seen:  # the same object again, or a cycle
            return self.put("again", self.seen[id(x), const][0])
        self.seen[id(x), const] = (len(self.seen), x)  # x held: its id is not reused by another while hashing
        if isinstance(x, (type, types.BuiltinFunctionType, np.ufunc)):
            return self.name(x)
        if isinstance(x, types.FunctionType):  # its place in the file (whose digest is in the key), its values
            co = x.__code__  # two lambdas of one line end at another column
            where = max((p for p in co.co_positions() if None not in p), default=co.co_firstlineno)
            cells = [c.cell_contents for c in x.__closure__ or ()]  # an empty cell: a ValueError too
            return self.name(x, where, x.__defaults__, x.__kwdefaults__, *cells)
        if isinstance(x, types.MethodType):
            return self.name(x.__func__, x.__self__)
        if isinstance(x, (tuple, list, dict)):  # a pytree's nodes, in order; another subclass is a leaf to jax
            self.name(t, len(x))
            leaf = const or (t not in (tuple, list, dict) and getattr(t, "_fields", None) is None)
            for v in (v for kv in x.items() for v in kv) if isinstance(x, dict) else x:
                self.add(v, leaf)
            return None
        if dataclasses.is_dataclass(x):  # a Module's dynamic fields are pytree nodes, a dataclass's constants
            self.name(t)
            node = isinstance(x, eqx.Module) and not const
            for f in dataclasses.fields(x):
                self.put(f.name)
                self.add(getattr(x, f.name, None), not node or f.metadata.get("static", False))
            return None
        if isinstance(x, jax.sharding.Mesh):
            return self.put("mesh", x.axis_names, x.devices.shape, [f"{d.platform}{d.id}" for d in x.devices.flat])
        fields = getattr(t, "kept_fields", None)  # an object that names the attributes its programs depend on
        if not isinstance(fields, tuple):
            raise ValueError(f"a value of type {t.__module__}.{t.__qualname__}")
        return self.name(t, *((f, getattr(x, f)) for f in fields))


def _key(fn: Callable, args: tuple) -> str:
    """The name of the program ``fn(*args)``: its whole key, hashed (module doc)."""
    k = _Key()
    k.add(fn, True)
    k.add(args, False)
    if "versions:" not in _memo:  # read once (importlib.metadata is slow); ":" is in no module name
        _memo["versions:"] = ",".join(f"{n}={version(n)}" for n in _LIBS)
    dev = jax.devices()[0]
    k.put(_memo["versions:"], *(getattr(jax.config, f"jax_{o}", None) for o in _OPTIONS), sys.version_info[:2])
    k.put(dev.platform, dev.device_kind, jax.device_count(), *(f"{t}={_source(t)}" for t in sorted(k.tops)))
    return k.h.hexdigest()


class ProgramCache:
    """Where :func:`kept_jit` keeps its programs (``programs``: this process's, by key).

    The folder keeps the :data:`MAX_KEPT` most recently used programs, and reads back none over :data:`MAX_BYTES`.

    Args:
        folder: the folder the programs are kept in (created with mode 0700); ``None``: off, every
            :func:`kept_jit` is a plain ``eqx.filter_jit``.
    """

    def __init__(self, folder: str | os.PathLike | None = None):
        self.folder = None if folder is None else Path(folder)
        self.programs: dict[str, Callable | None] = {}  # None: not kept, a plain jit
        self._warned, self._unusable = False, None  # why the folder is not used ("": it is; None: not checked)

    @property
    def enabled(self) -> bool:
        """Whether programs are kept: a folder is set, can be made, and no other user may plant programs in it."""
        if self.folder is not None and self._unusable is None:
            try:
                self.folder.mkdir(mode=0o700, parents=True, exist_ok=True)
                st = os.stat(self.folder)
                theirs = st.st_uid != os.getuid() and st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)
                self._unusable = f"owned by uid {st.st_uid} and writable by others: not used" if theirs else ""
            except OSError as e:  # read-only, or a file in the way: the programs are traced in this process
                self._unusable = f"cannot be created ({e.strerror or e}): not used"
            self._warn(self._unusable)
        return self.folder is not None and not self._unusable

    def _warn(self, what: str | None) -> None:
        if what and not self._warned:  # once per process, in one line
            self._warned = True
            print(f"jaxobs: warning: program cache {str(self.folder)!r}: {what}", file=sys.stderr, flush=True)

    def _read(self, path: Path, arrays: list) -> export.Exported | None:
        try:
            st = os.lstat(path)
        except FileNotFoundError:
            return None
        try:
            if not stat.S_ISREG(st.st_mode) or st.st_size > MAX_BYTES:  # a link, a FIFO, a folder, too large
                raise ValueError(f"is not a regular file of at most {MAX_BYTES} bytes")
            data = path.read_bytes()
            os.utime(path)  # recently used: the last to go when the folder is trimmed
            n, blob = len(_MAGIC), data[len(_MAGIC) + 128 :]
            if data[:n] != _MAGIC or data[n : n + 64] != path.stem.encode():
                raise ValueError("holds another program's key (or is corrupt)")
            if data[n + 64 : n + 128] != hashlib.sha256(blob).hexdigest().encode():
                raise ValueError("does not match its digest (corrupt)")
            exp = export.deserialize(bytearray(blob))
            if [(a.shape, a.dtype) for a in exp.in_avals] != [(x.shape, x.dtype) for x in arrays]:
                raise ValueError("takes other inputs than its key")
            return exp
        except Exception as e:  # the checks above, the file system's errors, and what deserialization raises
            return self._warn(f"{path.name} {e if isinstance(e, ValueError) else type(e).__name__}: traced again")

    def _write(self, path: Path, blob: bytes) -> None:
        try:  # a temp file renamed: whole or absent
            atomic_write_bytes(path, _MAGIC + path.stem.encode() + hashlib.sha256(blob).hexdigest().encode() + blob)
        except OSError as e:  # read-only, full, a folder in the way: the program runs, traced anew next time
            self._warn(f"{path.name} cannot be written ({e.strerror or e})")
        try:  # the least recently used entries beyond MAX_KEPT, and a killed writer's temp files (over an hour old)
            with os.scandir(path.parent) as it:
                entries = [(e.stat(follow_symlinks=False).st_mtime, e) for e in it if e.is_file(follow_symlinks=False)]
            kept = sorted((t, e.path) for t, e in entries if e.name.endswith(_SUFFIX))
            old = [e.path for t, e in entries if is_temp(e.name) and time.time() - t > 3600]
            for p in old + [p for _, p in kept[: max(0, len(kept) - MAX_KEPT)]]:
                os.unlink(p)
        except OSError:  # another process trims too
            pass


_state: dict[str, ProgramCache] = {"cache": ProgramCache(None)}


def set_program_cache(cache: ProgramCache | None) -> None:
    """Use ``cache`` for every :func:`kept_jit` from now on.

    Args:
        cache: The :class:`ProgramCache` to use, or ``None`` (off).

    Raises:
        ValueError: ``cache`` is neither a :class:`ProgramCache` nor ``None``.
    """
    if cache is not None and not isinstance(cache, ProgramCache):
        raise ValueError(f"set_program_cache: cache must be a jaxobs.ProgramCache or None, got {cache!r}")
    _state["cache"] = ProgramCache(None) if cache is None else cache


def program_cache() -> ProgramCache:
    """The :class:`ProgramCache` in use."""
    return _state["cache"]


def kept_jit(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``eqx.filter_jit(fn)`` whose traced and lowered program is kept across processes (module doc).

    Args:
        fn: the function, called with positional arguments only.  Its outputs must be arrays in tuples, lists,
            dicts and NamedTuples registered for ``jax.export`` (:mod:`jaxobs.reproduce._run`) to be kept.

    Returns:
        A callable with ``fn``'s signature and results.
    """
    jitted = eqx.filter_jit(fn)

    def program(cache: ProgramCache, path: Path, leaves: list, tree: Any, arrays: list) -> Callable | None:
        exp = cache._read(path, arrays)
        if exp is None:

            def flat(*xs):  # fn of its arrays alone, its other leaves baked in
                it = iter(xs)
                return fn(*jax.tree.unflatten(tree, [next(it) if eqx.is_array(x) else x for x in leaves]))

            try:
                exp = export.export(jax.jit(flat))(*arrays)
                blob = bytes(exp.serialize())
            except Exception:  # not exportable (a host callback, custom output classes): a plain jit
                return None
            cache._write(path, blob)
        call, dev = jax.jit(exp.call), jax.devices()[0]
        # an exported program's results are committed to their device: passed back (the solver's θ) they would be
        # placed otherwise than the first call's and compile the program again, unless all are placed alike
        return call if exp.nr_devices != 1 else lambda *xs: call(*jax.device_put(xs, dev))

    def kept(*args: Any) -> Any:
        cache = _state["cache"]
        leaves, tree = jax.tree.flatten(args)
        if not cache.enabled or jax.process_count() > 1 or any(isinstance(x, Tracer) for x in leaves):
            return jitted(*args)  # off, or inside another trace: part of its program
        try:
            name = _key(fn, args)
        except (ValueError, OSError, ImportError):  # a value the key cannot name, a source or version unread
            return jitted(*args)
        arrays = [x for x in leaves if eqx.is_array(x)]
        if name not in cache.programs:
            assert cache.folder is not None  # enabled
            cache.programs[name] = program(cache, cache.folder / f"{name}{_SUFFIX}", leaves, tree, arrays)
        run = cache.programs[name]
        return jitted(*args) if run is None else run(*arrays)

    return kept
