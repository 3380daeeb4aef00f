"""Griffe extension (mkdocs.yml, mkdocstrings' ``extensions``): the docstrings' Sphinx roles rendered as links.

The code's docstrings name other objects with Sphinx roles (``:class:`~jaxobs.drive.Drive```, ``:func:`simulate```,
``:mod:`jaxobs.linear```, ``:meth:``, ``:attr:``, ``:data:``). Before mkdocstrings renders a docstring, each role
becomes an mkdocs-autorefs cross-reference to the object's canonical path (``module.qualname``, which
mkdocstrings registers beside the path a page renders it under): a link where the object is documented on
some page, a code span where it is not. A target is resolved as Python would from the docstring's place: the
class that holds it, its module, then the packages ``jaxobs`` and ``jaxobs_tuning``, then a full import.

The extension also drops private bases (``Bases: _Drawn``): a reader cannot look a private class up.
"""

from __future__ import annotations

import html
import importlib
import inspect
import re
import types

import griffe

ROLE = re.compile(r":(?:py:)?(class|func|mod|meth|data|attr|obj|exc|const):`(~?)([^`]+?)`")
PACKAGES = ("jaxobs", "jaxobs_tuning")
_MISSING = object()


def _import(path: str):
    try:
        return importlib.import_module(path)
    except Exception:  # noqa: BLE001 - a docstring's module that does not import (optional dependency): no context
        return None


def _canonical(obj, fallback: str) -> str:
    if isinstance(obj, types.ModuleType):
        return obj.__name__
    mod, qual = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if isinstance(mod, str) and isinstance(qual, str) and "<" not in qual:
        return f"{mod}.{qual}"
    return fallback


def _walk(start, start_path: str, parts: list[str]) -> str | None:
    """The identifier of ``start.parts...``: the canonical path of the last class or module passed through, then
    the remaining names (a method, a field, a module's constant)."""
    obj, ident = start, start_path
    for name in parts:
        attr = inspect.getattr_static(obj, name, _MISSING) if inspect.isclass(obj) else getattr(obj, name, _MISSING)
        if attr is _MISSING:
            fields = getattr(obj, "__dataclass_fields__", {}) or getattr(obj, "__annotations__", {})
            if name not in fields:
                return None
            return f"{ident}.{name}"
        if isinstance(attr, (staticmethod, classmethod)):
            attr = attr.__func__
        if isinstance(attr, types.ModuleType) or inspect.isclass(attr):
            ident = _canonical(attr, f"{ident}.{name}")
        elif inspect.isfunction(attr) and not inspect.isclass(obj):  # a function a module re-exports
            ident = _canonical(attr, f"{ident}.{name}")
        else:
            ident = f"{ident}.{name}"
        obj = attr
    return ident


def resolve(target: str, context: list[tuple[object, str]]) -> str | None:
    """The identifier ``target`` names, seen from the namespaces ``context`` (innermost first), or None."""
    parts = target.split(".")
    for ns, path in context:
        if ns is None:
            continue
        found = _walk(ns, path, parts)
        if found is not None:
            return found
    for i in range(len(parts), 0, -1):  # a full dotted path: its longest importable module, then attributes
        mod = _import(".".join(parts[:i]))
        if mod is not None:
            return _walk(mod, mod.__name__, parts[i:])
    return None


def _context(obj: griffe.Object) -> list[tuple[object, str]]:
    mod = _import(obj.module.path)
    ctx = []
    if mod is not None:
        cls_obj = obj if obj.is_class else obj.parent if obj.parent is not None and obj.parent.is_class else None
        if cls_obj is not None:
            pyobj = mod
            for name in cls_obj.path[len(obj.module.path) + 1 :].split("."):
                pyobj = getattr(pyobj, name, None)
            if pyobj is not None:
                ctx.append((pyobj, _canonical(pyobj, cls_obj.path)))
        ctx.append((mod, mod.__name__))
    return ctx + [(_import(p), p) for p in PACKAGES]


def render_roles(text: str, context: list[tuple[object, str]]) -> str:
    """``text`` with its roles replaced by optional autorefs (a code span where nothing is documented)."""

    def sub(m: re.Match) -> str:
        _, tilde, target = m.groups()
        target = target.strip().removesuffix("()")
        shown = target.split(".")[-1] if tilde else target
        ident = resolve(target, context)
        code = f"<code>{html.escape(shown)}</code>"
        if ident is None:
            return code
        return f'<autoref identifier="{html.escape(ident)}" optional>{code}</autoref>'

    return ROLE.sub(sub, text)


class SphinxRoles(griffe.Extension):
    def on_package(self, *, pkg: griffe.Module, **kwargs) -> None:
        self.on_object(obj=pkg)  # a package's own docstring (on_object sees its members)

    def on_object(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is not None and ":" in obj.docstring.value and ROLE.search(obj.docstring.value):
            obj.docstring.value = render_roles(obj.docstring.value, _context(obj))
        if obj.is_class:
            obj.bases = [b for b in obj.bases if not str(b).split(".")[-1].split("[")[0].startswith("_")]
