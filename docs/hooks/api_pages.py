"""MkDocs hook: the API reference pages (api/*.md), one per public module, generated from the modules themselves.

A package re-exports its public names from private modules (``from ._loop import X as X``); griffe does not count
such aliases as public members of the package, so ``::: jaxobs`` alone would render the module docstring only.
Each page therefore lists the names the module offers at build time (its ``__all__``, else every name not starting
with ``_`` that is not a submodule), each rendered by mkdocstrings from its docstring: a name added to or removed
from a module appears on or leaves its page at the next build."""

import importlib
import sys
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# page -> module; the lead may rename modules: a page names only public packages
PAGES = {
    "jaxobs": "jaxobs",
    "drive": "jaxobs.drive",
    "observers": "jaxobs.observers",
    "linear": "jaxobs.linear",
    "metrics": "jaxobs.metrics",
    "tuning": "jaxobs_tuning",
}


def public_names(modname: str) -> list[str]:
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    mod = importlib.import_module(modname)
    names = getattr(mod, "__all__", None)
    if names is None:
        names = [n for n, v in vars(mod).items() if not n.startswith("_") and not isinstance(v, types.ModuleType)]
    # names that come from outside the project (a re-exported jax or numpy function) are not documented here
    own = []
    for n in names:
        origin = getattr(getattr(mod, n), "__module__", modname) or modname
        if origin.split(".")[0] in ("jaxobs", "jaxobs_tuning") or not callable(getattr(mod, n)):
            own.append(n)
    return own


def page(modname: str) -> str:
    lines = [
        f"# `{modname}`",
        "",
        f"::: {modname}",
        "    options:",
        "      members: false",
        "      show_root_heading: false",
        "",
    ]
    mod = sys.modules[modname]
    for n in public_names(modname):
        path = f"{modname}.{n}"
        if path in sys.modules and not isinstance(getattr(mod, n), types.ModuleType):
            # a function that shadows a module of the same name (jaxobs.simulate): griffe would find the module
            obj = getattr(mod, n)
            path = f"{obj.__module__}.{obj.__qualname__}"
        lines += [f"::: {path}", "    options:", "      heading_level: 2", ""]
    return "\n".join(lines)


def on_files(files, config):
    from mkdocs.structure.files import File

    for name, mod in PAGES.items():
        files.append(File.generated(config, f"api/{name}.md", content=page(mod)))
    return files
