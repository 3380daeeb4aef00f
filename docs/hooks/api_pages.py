"""MkDocs hook: the API reference pages (api/*.md), one per public module, generated from the modules themselves.

A package re-exports its public names from private modules (``from ._loop import X as X``); griffe does not count
such aliases as public members of the package, so ``::: jaxobs`` alone would render the module docstring only.
Each page therefore lists the names the module offers at build time (its ``__all__``, else every name not starting
with ``_`` that is not a submodule), each rendered by mkdocstrings from its docstring: a name added to or removed
from a module appears on or leaves its page at the next build.

Submodules and data tables (a dict, list or tuple: ``COMPONENTS``, ``METRICS``) are left out: their repr is no
reference. The components' registry is a table generated here instead (:func:`components_markdown`), read through
:func:`component_registry`."""

import importlib
import math
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
    # a name of __all__ the module lacks has no page entry (``from module import *`` fails on it: a bug of the
    # module's, for its own tests to catch, not a reason to leave the whole site unbuilt)
    names = [n for n in names if hasattr(mod, n)]
    # names that come from outside the project (a re-exported jax or numpy function) are not documented here
    own = []
    for n in names:
        origin = getattr(getattr(mod, n), "__module__", modname) or modname
        if origin.split(".")[0] in ("jaxobs", "jaxobs_tuning") or not callable(getattr(mod, n)):
            own.append(n)
    return [n for n in own if not isinstance(getattr(mod, n), (types.ModuleType, dict, list, tuple, set, frozenset))]


def component_registry() -> dict:
    """The tunable components, name -> info with ``ctor``, ``gains``, ``defaults``, ``closed_form``,
    ``closed_form_source`` and ``signal``: the one place the components' table reads the registry from."""
    from jaxobs_tuning.job.components import COMPONENTS

    return COMPONENTS


def gain_unit(info, gain: str) -> str:
    """A gain's unit (UDUNITS), from the observer class's own field metadata (jaxobs.observers.gain_fields)."""
    from jaxobs.observers import gain_fields

    g = gain_fields(info.ctor).get(gain)
    return "" if g is None else g.units


def components_markdown() -> str:
    """The components' table: tunable gains with their units and closed-form values, and the closed form's source."""
    rows = [
        "| component | signal | tunable gain | unit | closed form | source of the closed form |",
        "|---|---|---|---|---|---|",
    ]
    for name, info in component_registry().items():
        cf = info.closed_form(info.ctor(**info.defaults))
        for i, g in enumerate(info.gains):
            first = i == 0
            value = float(cf[g]) if g in cf else math.nan
            rows.append(
                f"| {f'`{name}`' if first else ''} | {info.signal if first else ''} | `{g}` | {gain_unit(info, g)} "
                f"| {value:.6g} | {info.closed_form_source if first else ''} |"
            )
    return "\n".join(rows)


def page(modname: str) -> str:
    lines = [
        f"::: {modname}",
        "    options:",
        "      members: false",
        "      show_root_heading: true",
        "      heading_level: 1",
        "",
    ]
    if modname == "jaxobs_tuning":
        lines += [
            "## Components",
            "",
            "The components a job tunes (`job.component`, `jaxobs_tuning.COMPONENTS`): each tunable gain with its",
            "unit (`1`: dimensionless) and the value of the closed-form design a job starts from and compares with.",
            "",
            components_markdown(),
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
