"""Where an exported observer comes from: a ``jaxobs tune`` result.json (its tuned, closed-form or initial
gains, rebuilt as the job built them) or a closed-form design by name (``sogi-fll``, ``wpf``, ``wif``), and
the rule it runs (:func:`parse_rule`)."""

from __future__ import annotations

import dataclasses
import os
import re
from pathlib import Path
from typing import Any, TypeVar

from jaxobs import AB3, RK4, Euler, Tustin
from jaxobs.core.discretize import AbstractRule
from jaxobs.observers import AbstractObserver
from jaxobs.studies.registry import REGISTRY, canonical_key

from ..job import COMPONENTS
from ..results import load_result

_O = TypeVar("_O", bound=AbstractObserver)  # an observer, rebuilt as its own class

# the closed forms `export --design` names (the FLLs' aliases in jaxobs.studies.registry): alias -> class (its rule, the
# source line, is its ClosedForm.rule, evaluated when a design is exported)
DESIGNS = {a: e.cls for e in REGISTRY.values() if e.signal == "grid" for a in e.aliases}


RULES = {"euler": Euler, "tustin": Tustin, "ab3": AB3, "rk4": RK4}


def parse_rule(spec: object, where: str = "rule") -> AbstractRule:
    """A rule from its name (``"AB3"``), its repr (``"Tustin(newton_iters=3)"``) or ``{"name": ..., ...}``.

    Args:
        spec: The name, the repr or the table.
        where: What the errors name.

    Returns:
        The rule.

    Raises:
        ValueError: An unknown rule or option.
    """
    kw = {}
    if isinstance(spec, dict):
        kw = {k: v for k, v in spec.items() if k not in ("name", "kind")}
        spec = spec.get("name", spec.get("kind"))
    if not isinstance(spec, str):
        known = ", ".join(c.__name__ for c in RULES.values())
        raise ValueError(f"{where}: must be a rule name ({known}), got {spec!r}")
    m = re.fullmatch(r"\s*(\w+)\s*(?:\((.*)\))?\s*", spec)
    cls = RULES.get(m.group(1).lower()) if m else None
    if cls is None or m is None:  # no match: no class
        raise ValueError(f"{where}: unknown rule {spec!r}; known: {', '.join(c.__name__ for c in RULES.values())}")
    for item in filter(None, (s.strip() for s in (m.group(2) or "").split(","))):
        k, _, v = item.partition("=")
        try:
            kw[k.strip()] = int(v)
        except ValueError:
            raise ValueError(f"{where}: cannot read the rule option {item!r} in {spec!r}") from None
    try:
        return cls(**kw)
    except TypeError as e:
        raise ValueError(f"{where}: {e}") from None


def observer_from_result(
    path: str | os.PathLike[str], *, gains: str = "tuned", notes: list | None = None
) -> AbstractObserver:
    """The observer of a ``jaxobs tune`` result.json with its ``gains`` ("tuned", "closed_form" or "initial").

    Constructor values are rebuilt as the job built them: the component's
    defaults, then the job's ``[component]`` table, then the chosen gains.  The
    sample time, rule and nominal frequency are read from the result's ``ts``,
    ``rule`` and ``omega_n`` when it has them; otherwise the component's defaults
    are used and a line saying so is appended to ``notes``.

    Args:
        path: The result.json.
        gains: Which design: "tuned", "closed_form" or "initial".
        notes: A list the lines about defaults used are appended to (None: none kept).

    Returns:
        The observer.

    Raises:
        ValueError: A result without that design, or of a component that is not jaxobs's.
    """
    notes = [] if notes is None else notes
    path = Path(path)
    res = load_result(path)
    comp = res.get("component")
    if comp not in COMPONENTS:
        raise ValueError(f"result file {str(path)!r}: component {comp!r} is not a jaxobs component")
    info = COMPONENTS[comp]
    table = res.get("gains", {}).get(gains)
    if not isinstance(table, dict):
        have = ", ".join(res.get("gains", {})) or "none"
        raise ValueError(f"result file {str(path)!r}: no gains.{gains} (has: {have})")
    if gains == "tuned" and str(res.get("status", "")).lower() == "diverged":
        raise ValueError(
            f"result file {str(path)!r}: status 'diverged': the tuned gains are not a design "
            "(export --gains closed_form instead)"
        )
    # the defaults at the result's period: the job's own values where they depend on it (registry defaults_at)
    values = info.defaults_at(float(res["ts"]) if "ts" in res else None)
    values.pop("ts", None)  # set below, from the result, as before
    values.update({canonical_key(info.ctor, k): v for k, v in res.get("job", {}).get("component", {}).items()})
    values.update(table)
    kw = {}
    name = info.ctor.__name__
    if "omega_n" in res and "omega_n" in values:
        values["omega_n"] = float(res["omega_n"])
    elif "omega_n" in values:
        notes.append(f"result.json has no 'omega_n': the job's value {values['omega_n']:.9g} rad/s is used")
    probe = info.ctor(**values)  # defaults of ts and rule
    if "ts" in res:
        kw["ts"] = float(res["ts"])
    else:
        notes.append(f"result.json has no 'ts': the {name} default ts = {probe.ts:g} s is used")
    if res.get("rule") is not None:
        kw["rule"] = parse_rule(res["rule"], "result.json rule")
    elif probe.rule is not None:  # a component without a rule (its step is its own update) has none to read
        notes.append(f"result.json has no 'rule': the {name} default {type(probe.rule).__name__} is used")
    if info.signal == "drive" or res.get("loop") is not None:  # a drive job bound these per scenario
        # LESOs: Rs, Lq and the PLL's initial speed; flux observers: Rs, L and the FLL's or PLL's omega_init
        keys = type(probe).bound_fields.names
        bound = ", ".join(f"{k} = {float(getattr(probe, k)):g}" for k in keys)
        notes.append(f"the job sets {', '.join(keys)} per scenario; exported with {bound}")
    diverged = res.get("scores", {}).get(gains, {}).get("diverged") if gains in res.get("scores", {}) else None
    if diverged:
        notes.append(f"the {gains} design diverged on {diverged} of the job's scenarios")
    return info.ctor(**values, **kw)


def observer_from_design(name: str, **kw: Any) -> AbstractObserver:
    """A closed-form design by name (``sogi-fll``, ``wpf``, ``wif``): its class's ``closed_form(**kw)``.

    Args:
        name: The design's alias (:data:`DESIGNS`).
        **kw: The closed form's keywords (``ts``, ``rule``).

    Returns:
        The observer.

    Raises:
        ValueError: An unknown name.
    """
    if name not in DESIGNS:
        raise ValueError(f"design must be one of {', '.join(DESIGNS)}, got {name!r}")
    return DESIGNS[name].closed_form(**kw)


def rebuild(obs: _O, **kw: Any) -> _O:
    """The same observer with another ts or rule (static fields: rebuilt through the constructor).

    Args:
        obs: The observer (with ``ts`` and ``rule`` fields).
        **kw: ``ts`` and/or ``rule``.

    Returns:
        The rebuilt observer.
    """

    fields = {f.name: getattr(obs, f.name) for f in dataclasses.fields(obs)}
    values = {k: v for k, v in fields.items() if k not in ("ts", "rule")}
    values.update(ts=kw.get("ts", obs.ts), rule=kw.get("rule", fields["rule"]))
    return type(obs)(**values)
