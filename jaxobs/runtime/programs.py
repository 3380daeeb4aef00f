"""Traced programs kept across processes: compiled once per machine, traced once too.

JAX's persistent compilation cache (:func:`jaxobs.use_compile_cache`) keeps XLA's work, but it keys
on the lowered program, so every new process still traces each jitted function to a jaxpr and lowers
it to StableHLO before it can look the executable up: seconds of a warm tuning run (the objective's
value-and-gradient, the scoring, the margins; docs/performance.md).  :func:`kept_jit` keeps that
work too.  The first call exports the program (``jax.export``: the traced and lowered StableHLO,
serialized) to the folder of the :class:`ProgramCache` in use; a later process reads it back and runs
it (``Exported.call``), which compiles, or reads from the compilation cache, the same program.

The key is computed, not named by the caller.  It covers what can reach the program:

- the function: its code, and the values its closure, its defaults and its bound object hold (arrays
  by value: a closure's arrays are constants of the program); an object that is neither a dataclass,
  an equinox Module, a container, a number nor a string names its defining attributes in a
  ``kept_fields`` class attribute, else the program is not kept (a plain ``eqx.filter_jit``);
- the static half of every argument (``eqx.partition``'s: Python numbers, strings, static fields,
  callables, digested as above) and the tree structure, shape, dtype and weak type of every array;
- the caller's optional ``key`` string;
- the source of every package the code above comes from (each ``.py`` file of ``jaxobs`` and of the
  packages of the functions and classes met: an edited file is a new key), the versions of JAX and
  the libraries that trace, the JAX options that change a trace, the device kind and count.

A kept program is one file ``<sha256 of the key>.jaxexport`` holding its whole key, the sha256 of
its serialized program and the digest of its output structure.  A read goes through ``O_NOFOLLOW``
and ``fstat`` (a regular file of at most ``max_bytes``, never a symlink, a FIFO or a folder); the key,
the content digest, the program's input tree and avals and its output structure must all match.
Anything else (a mismatch, a corrupt file, a failed deserialization, a read-back program that fails
at its first run) is reported once per process in one line on stderr naming the folder, and the
program is traced again and its entry replaced: the cache can make a run faster, never different.
Entries are written to a uniquely named ``*.tmp`` file in the same folder and renamed; a temp file
is removed when its rename fails, and trimming removes stale ones a killed process left.

The folder is created with mode 0700.  A folder that others may write to and that the user does not
own is not used (as ssh and pip refuse such files), and the warning says so.  Off (plain
``eqx.filter_jit``) where no folder is set: :func:`jaxobs.use_compile_cache` sets one (the command line,
unless ``--no-cache`` or ``JAXOBS_CACHE_DIR=off``); off too where a program cannot be exported (a host
callback, an output that is not arrays in tuples, lists, dicts and registered NamedTuples), in a traced
context, and across several processes.  A program run through ``Exported.call`` gives the same numbers bit
for bit as the plain jit (tests/test_traced.py; result.json of the default job compared byte for byte).
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
import struct
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
from jax import export  # serialization needs flatbuffers (a dependency)
from jax.core import Tracer

from ._digest import Digest, NoKey, environment, package_digest

__all__ = ["ProgramCache", "kept_jit", "program_cache", "set_program_cache", "set_traced_dir", "traced_dir"]

# Every edit of the source is a new key, so the folder keeps at most this many programs (the least recently
# used go first); a job or a study keeps a few (docs/performance.md).
MAX_KEPT = 1000
MAX_BYTES = 256 * 2**20  # the largest entry read back
_STALE_TMP_S = 3600.0  # a temp file this old is a killed writer's: trimming removes it
_MAGIC = b"jaxobs kept program 2\n"
_SUFFIX = ".jaxexport"


class ProgramCache:
    """Where :func:`kept_jit` keeps its programs, and how many: the one cache policy.

    Args:
        folder: the folder the programs are kept in (created with mode 0700); ``None``: off, every
            :func:`kept_jit` is a plain ``eqx.filter_jit``.
        max_kept: how many programs the folder keeps (the least recently used go first), ≥ 1.
        max_bytes: the largest entry that is read back (bytes, ≥ 1); a larger one is traced again.

    Raises:
        ValueError: ``max_kept`` or ``max_bytes`` is not a positive integer.

    It also holds this process's programs, read back or exported, by their key (``programs``), so that
    every caller of one program shares it.
    """

    def __init__(
        self, folder: str | os.PathLike | None = None, *, max_kept: int = MAX_KEPT, max_bytes: int = MAX_BYTES
    ):
        for name, v in (("max_kept", max_kept), ("max_bytes", max_bytes)):
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"ProgramCache: {name} must be an integer >= 1, got {v!r}")
        self.folder = None if folder is None else Path(folder)
        self.max_kept, self.max_bytes = max_kept, max_bytes
        self.programs: dict[str, _Program] = {}
        self._warned = False
        self._checked: bool | None = None  # the folder made and its owner checked (None: not yet)

    @property
    def enabled(self) -> bool:
        """Whether programs are kept: a folder is set, and it is safe to use."""
        return self.folder is not None and self._usable()

    def __repr__(self) -> str:
        return f"ProgramCache({None if self.folder is None else str(self.folder)!r}, max_kept={self.max_kept})"

    def warn(self, what: str) -> None:
        """Report a problem of the folder, once per process, in one line on stderr.

        Args:
            what: The problem.
        """
        if not self._warned:
            self._warned = True
            print(f"jaxobs: warning: program cache {str(self.folder)!r}: {what}", file=sys.stderr, flush=True)

    def _usable(self) -> bool:
        if self._checked is None:
            self._checked = self._check_folder()
        return self._checked

    def _check_folder(self) -> bool:
        if self.folder is None:
            return False
        try:
            self.folder.mkdir(mode=0o700, parents=True, exist_ok=True)
            st = os.stat(self.folder)
        except OSError as e:  # read-only or missing: the programs run, traced in this process
            self.warn(f"cannot be created ({e.strerror or e}): not used")
            return False
        if not stat.S_ISDIR(st.st_mode):
            self.warn("is not a folder: not used")
            return False
        if st.st_uid != os.getuid() and st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
            self.warn(f"owned by uid {st.st_uid} and writable by others: not used (programs are traced anew)")
            return False
        return True

    # --- one entry
    def path(self, name: str) -> Path:
        """The file of a kept program.

        Args:
            name: The program's file name, less its suffix.

        Returns:
            The path in the folder.

        Raises:
            ValueError: The cache has no folder (it is off).
        """
        if self.folder is None:
            raise ValueError("ProgramCache: no folder (the cache is off)")
        return self.folder / f"{name}{_SUFFIX}"

    def read(self, name: str, key: dict) -> tuple[export.Exported | None, str | None]:
        """The program kept under a name, if its file holds the key and its own digest.

        Args:
            name: The program's file name.
            key: The program's key.

        Returns:
            ``(the program, None)``, or ``(None, why not)``; ``(None, None)`` where there is no file.
        """
        path = self.path(name)
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
        except FileNotFoundError:
            return None, None
        except OSError as e:
            return None, f"{path.name} cannot be read ({e.strerror or e})"
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                return None, f"{path.name} is not a regular file"
            if st.st_size > self.max_bytes:
                return None, f"{path.name} is larger than {self.max_bytes} bytes"
            data = _read_all(fd, st.st_size)
            try:
                os.utime(fd)  # recently used: the last to go when the folder is trimmed
            except OSError:
                pass
        except OSError as e:
            return None, f"{path.name} cannot be read ({e.strerror or e})"
        finally:
            os.close(fd)
        header, blob = _unpack(data)
        if header is None:
            return None, f"{path.name} is not a kept program (corrupt)"
        if header.get("key") != key:
            return None, f"{path.name} holds another program's key"
        if header.get("sha256") != hashlib.sha256(blob).hexdigest():
            return None, f"{path.name} does not match its digest (corrupt)"
        try:
            exp = export.deserialize(bytearray(blob))
        except Exception as e:  # flatbuffers and JAX raise what they meet
            return None, f"{path.name} cannot be deserialized ({type(e).__name__})"
        if header.get("out") != _out_signature(exp):
            return None, f"{path.name} has another output structure than its key"
        return exp, None

    def write(self, name: str, key: dict, exp: export.Exported) -> None:
        """Keep a program: whole or absent (a temp file renamed), its temp file removed if that fails.

        Args:
            name: The program's file name.
            key: The program's key.
            exp: The exported program.
        """
        if self.folder is None or not self._usable():
            return
        blob = exp.serialize()
        header = {
            "key": key,
            "sha256": hashlib.sha256(blob).hexdigest(),
            "out": _out_signature(export.deserialize(blob)),
        }
        data = _pack(header, bytes(blob))
        tmp = None
        try:
            fd, tmp = tempfile.mkstemp(dir=self.folder, prefix=f"{name}.", suffix=".tmp")
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            os.replace(tmp, self.path(name))  # a concurrent reader never sees half a file
            tmp = None
        except OSError as e:  # read-only, full, or something not a file in the way: still runs, traced anew
            self.warn(f"{name}{_SUFFIX} cannot be written ({e.strerror or e})")
        finally:
            if tmp is not None:
                try:
                    os.unlink(tmp)
                except OSError:
                    pass
        _trim(self.folder, self.max_kept)


def _read_all(fd: int, size: int) -> bytes:
    parts, left = [], size
    while left > 0:
        b = os.read(fd, min(left, 1 << 20))
        if not b:
            break
        parts.append(b)
        left -= len(b)
    return b"".join(parts)


def _pack(header: dict, blob: bytes) -> bytes:
    head = json.dumps(header, sort_keys=True, separators=(",", ":")).encode()
    return _MAGIC + struct.pack("<Q", len(head)) + head + blob


def _unpack(data: bytes) -> tuple[dict | None, bytes]:
    n = len(_MAGIC)
    if not data.startswith(_MAGIC) or len(data) < n + 8:
        return None, b""
    (size,) = struct.unpack("<Q", data[n : n + 8])
    if size > len(data) - n - 8:
        return None, b""
    try:
        header = json.loads(data[n + 8 : n + 8 + size])
    except (ValueError, RecursionError):  # not JSON, or nested past the parser's depth
        return None, b""
    return (header if isinstance(header, dict) else None), data[n + 8 + size :]


def _out_signature(exp: export.Exported) -> str:
    avals = ";".join(f"{a.shape}{a.dtype}" for a in exp.out_avals)
    return hashlib.sha256(f"{exp.out_tree}|{avals}|{exp.nr_devices}".encode()).hexdigest()


def _trim(folder: Path, keep: int = MAX_KEPT) -> None:
    """Delete the least recently used programs of ``folder`` beyond ``keep``, and temp files a killed writer left
    (older than an hour: a live writer's is seconds old).  Another process may race: ignored."""
    try:
        kept, now = [], time.time()
        with os.scandir(folder) as it:
            for e in it:
                if not e.is_file(follow_symlinks=False):
                    continue
                t = e.stat(follow_symlinks=False).st_mtime
                if e.name.endswith(_SUFFIX):
                    kept.append((t, e.path))
                elif e.name.endswith(".tmp") and now - t > _STALE_TMP_S:
                    os.unlink(e.path)
        kept.sort()
        for _, p in kept[: max(0, len(kept) - keep)]:
            os.unlink(p)
    except OSError:
        pass


_state: dict = {"cache": ProgramCache(None)}


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


def set_traced_dir(folder: str | os.PathLike | None) -> None:
    """Keep exported programs in a folder (a new :class:`ProgramCache`).

    Args:
        folder: The folder, or ``None``: off.
    """
    set_program_cache(ProgramCache(folder))


def traced_dir() -> Path | None:
    """The folder exported programs are kept in, or ``None`` (off)."""
    return program_cache().folder


_LOCAL = 16  # the static values a kept function remembers, the most recent


def _is_array(x) -> bool:
    return eqx.is_array(x)


class _Program:
    """A kept program as this process runs it: ``run(*arrays)``, and whether it came from the folder (its first run
    may still fail: then it is traced anew)."""

    def __init__(self, exp: export.Exported, from_disk: bool):
        self.from_disk = from_disk
        call = jax.jit(exp.call)
        if exp.nr_devices != 1:
            self.run = call
        else:
            # an exported program's results are committed to their device, so a later call that passes them back
            # (the solver's θ) would differ in its arguments' placement from the first and compile the program a
            # second time; placing every argument on the device first gives one placement, one compilation
            dev = jax.devices()[0]
            self.run = lambda *xs: call(*jax.device_put(xs, dev))


class _Kept:
    """``eqx.filter_jit(fn)``, with the traced program kept by :func:`program_cache` under its computed key."""

    def __init__(self, fn, key: str):
        self.fn, self.key = fn, key
        self.jitted = eqx.filter_jit(fn)
        self._fn_key: tuple[str, frozenset] | None = None
        # (tree, static leaves and avals) -> the _Program (None: a plain jit) in this process; the most recent few
        # only, since the static leaves may hold large objects (an objective's scenarios): a miss costs a digest
        self.local: dict = {}

    def _function_key(self) -> tuple[str, frozenset]:
        if self._fn_key is None:  # once: the function, its closure and bound object do not change
            d = Digest(avals=False)
            d.add(self.fn)
            self._fn_key = (d.hexdigest(), frozenset(d.packages))
        return self._fn_key

    def full_key(self, args) -> dict:
        """Everything the program depends on (module doc); raises ``NoKey`` where that cannot be computed."""
        fn_digest, fn_packages = self._function_key()
        d = Digest(avals=True)
        d.add(args)
        packages = sorted({"jaxobs", *fn_packages, *d.packages})
        return {
            "caller": self.key,
            "function": fn_digest,
            "arguments": d.hexdigest(),
            "sources": {p: package_digest(p) for p in packages},
            "environment": environment(),
        }

    def __call__(self, *args):
        cache = program_cache()
        if not cache.enabled or jax.process_count() > 1:
            return self.jitted(*args)
        leaves, tree = jax.tree.flatten(args)
        if any(isinstance(x, Tracer) for x in leaves):  # inside another trace: part of its program
            return self.jitted(*args)
        arrays = [x for x in leaves if _is_array(x)]
        local = (tree, tuple((x.shape, x.dtype, getattr(x, "weak_type", False)) if _is_array(x) else x for x in leaves))
        try:
            prog = self.local.pop(local) if local in self.local else self._program(cache, args, leaves, tree)
            self.local[local] = prog  # the most recent last
            while len(self.local) > _LOCAL:
                del self.local[next(iter(self.local))]
        except (TypeError, ValueError):  # a static value that cannot be hashed or compared: what jit makes of it
            return self.jitted(*args)
        if prog is None:
            return self.jitted(*args)
        if not prog.from_disk:
            return prog.run(*arrays)
        try:
            out = prog.run(*arrays)
        except Exception as e:  # a read-back program that cannot be compiled or run: traced anew
            cache.warn(f"a kept program failed to run ({type(e).__name__}): traced again and replaced")
            prog = self._program(cache, args, leaves, tree, fresh=True)
            self.local[local] = prog
            return self.jitted(*args) if prog is None else prog.run(*arrays)
        prog.from_disk = False  # it ran: a later failure is the computation's own
        return out

    def _program(self, cache: ProgramCache, args, leaves, tree, fresh: bool = False) -> _Program | None:
        try:
            key = self.full_key(args)
        except NoKey:
            return None
        name = _entry_name(key)
        if not fresh and name in cache.programs:
            return cache.programs[name]
        arrays = [x for x in leaves if _is_array(x)]
        exp = None
        if not fresh:
            exp, why = cache.read(name, key)
            if exp is not None:
                why = _check_inputs(exp, arrays)
                exp = None if why else exp
            if why:
                cache.warn(f"{why}: traced again and replaced")
        from_disk = exp is not None
        if exp is None:
            statics = [None if _is_array(x) else x for x in leaves]
            where = [i for i, x in enumerate(leaves) if _is_array(x)]

            def flat(*xs):
                full = list(statics)
                for i, x in zip(where, xs):
                    full[i] = x
                return self.fn(*jax.tree.unflatten(tree, full))

            try:
                exp = export.export(jax.jit(flat))(*arrays)
                exp.serialize()
            except Exception:
                # not exportable (a host callback, an output of custom classes): a plain jit (a real error in fn is
                # raised there)
                return None
            cache.write(name, key, exp)
        prog = _Program(exp, from_disk)
        cache.programs[name] = prog
        return prog


def _entry_name(key: dict) -> str:
    """The file name (less its suffix) of the program kept under ``key``."""
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()


def _check_inputs(exp, arrays) -> str | None:
    """Why a read-back program does not take these arrays (None: it does)."""
    if exp.in_tree != jax.tree.structure((tuple(arrays), {})):
        return "a kept program has another input structure than its key"
    if [(a.shape, a.dtype) for a in exp.in_avals] != [(x.shape, x.dtype) for x in arrays]:
        return "a kept program has other input shapes than its key"
    return None


def kept_jit(fn: Callable[..., Any], key: str | None = None) -> Callable[..., Any]:
    """``eqx.filter_jit(fn)`` whose traced and lowered program is kept across processes (module doc).

    Args:
        fn: the function; called with positional arguments only.  Its outputs must be arrays in tuples,
            lists, dicts and NamedTuples registered for ``jax.export`` (the drive's step outputs are, by
            :mod:`jaxobs.reproduce._run`) to be kept; else each process traces it, as a plain jit.
        key: an optional name added to the computed key (a non-empty string).  The key already covers ``fn``'s
            code, closure and bound object, the static half of every argument and the arrays' avals.

    Returns:
        A callable with ``fn``'s signature and results.

    Raises:
        ValueError: ``key`` is not a non-empty string.
    """
    if key is not None and (not isinstance(key, str) or not key):
        raise ValueError(f"kept_jit: key must be a non-empty string, got {key!r}")
    return _Kept(fn, key or "")
