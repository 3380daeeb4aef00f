"""The key of a kept program (:mod:`jaxobs.runtime.programs`): a stable digest of Python values, the source of
the packages they come from, and the environment that traces them.

:class:`Digest` hashes a value the same way in every process for equal values (no ``id``, no ``repr`` of an
object): numbers and strings by value, arrays by value or by shape, dtype and weak type, functions by their
code, closure and defaults, classes and library functions by module and name (their package's source, or the
library's version, is in the key), objects by their fields.  A value it cannot hash raises :class:`NoKey`:
the program is then not kept.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import hashlib
import sys
import types
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _pkg_version
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import numpy as np
from jax.core import Tracer

# the libraries whose code runs while a jaxobs program is traced: their versions are in the key, their
# functions and classes are named by module and name
_LIBS = ("jax", "jaxlib", "equinox", "diffrax", "optax", "optimistix", "lineax", "numpy")
_NAMED = frozenset((*_LIBS, "scipy", "jaxtyping", *sys.stdlib_module_names))
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

_digests: dict[str, str] = {}
_ABSENT = object()


def package_digest(top: str) -> str:
    """sha256 over every ``.py`` file (relative path and bytes) of the top-level package or module ``top``.

    Computed once per process and cached.

    Args:
        top: The name of a top-level package or module (already imported).

    Returns:
        The hex digest, or an empty string where no file holds it (an interactive session, ``python -c``) or a
        file cannot be read.
    """
    if top not in _digests:
        file = getattr(sys.modules.get(top), "__file__", None)
        if not isinstance(file, str):
            _digests[top] = ""
            return ""
        h = hashlib.sha256(top.encode())
        try:
            path = Path(file).resolve(strict=True)
            files = sorted(path.parent.rglob("*.py")) if path.name == "__init__.py" else [path]
            for f in files:
                h.update(str(f.relative_to(path.parent)).encode() + b"\0" + f.read_bytes() + b"\0")
            _digests[top] = h.hexdigest()
        except OSError:
            _digests[top] = ""
    return _digests[top]


def _lib_version(name: str) -> str:
    try:
        return _pkg_version(name)
    except PackageNotFoundError:
        return "unknown"


def environment() -> str:
    """The versions of the libraries that trace, the JAX options that change a trace, the devices and Python."""
    if "libs" not in _digests:  # read once: importlib.metadata is slow
        _digests["libs"] = ",".join(f"{n}={_lib_version(n)}" for n in _LIBS)
    opts = ",".join(f"{o}={getattr(jax.config, o, None)!r}" for o in _OPTIONS)
    dev = jax.devices()[0]
    # the device count too: a program split over two host devices is another program than one device's
    kind = f"{dev.platform};{getattr(dev, 'device_kind', '')};{jax.device_count()};{jax.process_count()}"
    return f"{_digests['libs']};{opts};{kind};{sys.version_info[:2]}"


class NoKey(Exception):
    """A value the key cannot be computed from: the program is not kept."""


class Digest:
    """A stable sha256 of Python values: the same in every process for equal values (no ``id``, no ``repr`` of an
    object).  Arrays by value (``avals=False``), or with ``avals=True`` by shape, dtype and weak type where they are
    a program's inputs (leaves of the pytree given: containers, NamedTuples, an equinox Module's fields that are not
    static) and by value where they are its constants (held by a function, an object or a static field)."""

    def __init__(self, avals: bool):
        self.h = hashlib.sha256()
        self.avals = avals
        self.packages: set[str] = set()
        self.seen: dict[tuple[int, bool], int] = {}

    def hexdigest(self) -> str:
        """The digest so far, in hex."""
        return self.h.hexdigest()

    def constant(self, *objs: Any) -> None:
        """Hash ``objs`` as constants of the program: their arrays by value.

        Args:
            *objs: The values.

        Raises:
            NoKey: A value the key cannot be computed from.
        """
        avals, self.avals = self.avals, False
        try:
            for obj in objs:
                self.add(obj)
        finally:
            self.avals = avals

    def put(self, tag: str, text: str = "") -> None:
        """Hash a tagged text (its length first: no two sequences of puts hash alike).

        Args:
            tag: The tag.
            text: The text.
        """
        self.h.update(f"{tag}:{len(text)}:{text};".encode())

    def named(self, obj: Any) -> bool:
        """Hash a function or class by where it is defined: its package's source is in the key.

        Args:
            obj: The function or class.

        Returns:
            Whether it is a library's (named by its module and name alone: the library's version is in the key).

        Raises:
            NoKey: It has no module and name, or its package has no source file.
        """
        module = getattr(obj, "__module__", None)
        name = getattr(obj, "__qualname__", None) or getattr(obj, "__name__", None)
        if not isinstance(module, str) or not isinstance(name, str):
            raise NoKey(f"{obj!r} has no module and name")
        top = module.split(".")[0]
        if top not in _NAMED:
            if not package_digest(top):  # defined where no file holds it (an interactive session)
                raise NoKey(f"{module}.{name} has no source file")
            self.packages.add(top)
        self.put("named", f"{module}:{name}")
        return top in _NAMED

    def code(self, co: types.CodeType, names: dict[str, Any]) -> None:
        """Hash a function's code, and the module constants it reads: a constant changed at run time (a test's
        monkeypatch) is then another key, as an edited file is.

        Args:
            co: The function's code object.
            names: Its globals.
        """
        self.put("code", co.co_name)
        self.h.update(co.co_code)
        self.put("names", ",".join(co.co_names))
        for name in co.co_names:
            value = names.get(name, _ABSENT)
            if value is not _ABSENT and plain(value):
                self.put("global", name)
                self.constant(value)
        for c in co.co_consts:
            self.code(c, names) if isinstance(c, types.CodeType) else self.add(c)

    def methods(self, cls: type) -> None:
        """Hash the code of every method of ``cls`` and its bases defined outside the libraries.

        Args:
            cls: The class.
        """
        for klass in cls.__mro__:
            if (getattr(klass, "__module__", "") or "").split(".")[0] in _NAMED:
                continue
            for name, v in sorted(vars(klass).items()):
                f = getattr(v, "__func__", v)  # staticmethod, classmethod
                if isinstance(f, types.FunctionType):
                    self.put("method", name)
                    self.code(f.__code__, f.__globals__)

    def add(self, obj: Any) -> None:
        """Hash a value: a number, string, array, dtype, type or enum as itself (:meth:`_atom`); the same object
        met again as a reference to the first; else a callable (:meth:`_callable`), a container
        (:meth:`_container`) or an object (:meth:`_object`).

        Args:
            obj: The value.

        Raises:
            NoKey: The value cannot be hashed (a traced value, an object array, an object that is neither a
                dataclass, an equinox Module, a container, nor names its ``kept_fields``).
        """
        if self._atom(obj):
            return
        mark = (id(obj), self.avals)  # as an input, or as a constant (its arrays by value)
        if mark in self.seen:  # a cycle, or the same object again
            self.put("again", str(self.seen[mark]))
            return
        self.seen[mark] = len(self.seen)
        if not (self._callable(obj) or self._container(obj)):
            self._object(obj)

    def _atom(self, obj: Any) -> bool:
        """Hash a value that holds no other: a number, a string, bytes, a dtype, an array, a type, an enum member.
        Whether ``obj`` was one."""
        t = type(obj)
        if obj is None or obj is Ellipsis or t in (bool, int, float, complex, str):
            self.put(t.__name__, repr(obj))
            return True
        if t is bytes:
            self.put("bytes", obj.hex())
            return True
        if isinstance(obj, Tracer):
            raise NoKey("a traced value")
        if isinstance(obj, np.dtype):
            self.put("dtype", obj.str)
            return True
        if eqx.is_array(obj) or isinstance(obj, np.generic):
            weak = bool(getattr(obj, "weak_type", False))
            a = np.asarray(obj)
            if a.dtype == object:
                raise NoKey("an object array")
            self.put("array", f"{a.dtype.str}{a.shape}{weak}")
            if not self.avals:
                self.h.update(np.ascontiguousarray(a).tobytes())
            return True
        if isinstance(obj, type):
            self.named(obj)
            return True
        if isinstance(obj, enum.Enum):
            self.named(t)
            self.put("enum", obj.name)
            return True
        return False

    def _callable(self, obj: Any) -> bool:
        """Hash a function (its code, defaults and closure), a bound method, a partial or a builtin.  Whether
        ``obj`` was one."""
        if isinstance(obj, types.FunctionType):
            if self.named(obj) and "<locals>" not in obj.__qualname__ and not obj.__closure__:
                return True  # a library's function: its version names it
            self.code(obj.__code__, obj.__globals__)
            self.constant(obj.__defaults__, obj.__kwdefaults__)
            for cell in obj.__closure__ or ():
                try:
                    self.constant(cell.cell_contents)
                except ValueError:  # an empty cell
                    self.put("empty")
            return True
        if isinstance(obj, types.MethodType):
            self.put("method")
            self.constant(obj.__func__, obj.__self__)
            return True
        if isinstance(obj, functools.partial):
            self.put("partial")
            self.constant(obj.func, obj.args, obj.keywords)
            return True
        if isinstance(obj, (types.BuiltinFunctionType, np.ufunc)):
            self.named(obj)
            return True
        return False

    def _container(self, obj: Any) -> bool:
        """Hash a tuple, list, dict (in order: a pytree's) or set (in no order).  Whether ``obj`` was one."""
        t = type(obj)
        if isinstance(obj, (tuple, list)):
            self.named(t)
            self.put("items", str(len(obj)))
            for x in obj:
                self.add(x)
            return True
        if isinstance(obj, dict):
            self.named(t)
            self.put("items", str(len(obj)))
            for k, v in obj.items():  # in order: a pytree's order
                self.add(k)
                self.add(v)
            return True
        if isinstance(obj, (set, frozenset)):
            subs = []
            for x in obj:
                d = Digest(avals=False)
                d.add(x)
                self.packages |= d.packages
                subs.append(d.hexdigest())
            self.put("set", ",".join(sorted(subs)))
            return True
        return False

    def _object(self, obj: Any) -> None:
        """Hash an object by its fields: a dataclass or equinox Module, a mesh, an object naming its
        ``kept_fields``, or a wrapper (``__wrapped__``); else raise :class:`NoKey`."""
        t = type(obj)
        if dataclasses.is_dataclass(obj):  # equinox Modules (their bound methods too) and dataclasses
            self.named(t)
            pytree = isinstance(obj, eqx.Module)  # a plain dataclass is a static leaf: its arrays are constants
            for f in dataclasses.fields(obj):
                self.put("field", f.name)
                value = getattr(obj, f.name, None)
                if pytree and not f.metadata.get("static", False):
                    self.add(value)
                else:
                    self.constant(value)
            return
        if isinstance(obj, jax.sharding.Mesh):
            self.put("mesh", repr(tuple(obj.axis_names)) + repr(obj.devices.shape))
            self.put("devices", ",".join(f"{d.platform}{d.id}" for d in obj.devices.flat))
            return
        fields = getattr(t, "kept_fields", None)
        if isinstance(fields, tuple):  # an object that names the attributes its programs depend on
            self.named(t)
            self.methods(t)
            for name in fields:
                self.put("field", name)
                self.constant(getattr(obj, name))
            return
        wrapped = getattr(obj, "__wrapped__", None)  # jax's jitted functions, custom_jvp, ...
        if wrapped is not None:
            self.named(t)
            self.constant(wrapped)
            return
        raise NoKey(f"a value of type {t.__module__}.{t.__qualname__}")


def plain(value: Any, depth: int = 0) -> bool:
    """Whether ``value`` is a module constant made of numbers and strings (what a key can hold).

    Args:
        value: The value.
        depth: How deep in containers ``value`` is (a container at depth 3 or more is not plain).

    Returns:
        Whether it is plain: ``None``, a number, a string or bytes, or a small tuple, list, frozenset or dict of
        plain values.
    """
    if value is None or type(value) in (bool, int, float, complex, str, bytes):
        return True
    if depth < 3 and type(value) in (tuple, list, frozenset):
        return len(value) <= 64 and all(plain(v, depth + 1) for v in value)
    if depth < 3 and type(value) is dict:
        return len(value) <= 64 and all(plain(k, depth + 1) and plain(v, depth + 1) for k, v in value.items())
    return False
