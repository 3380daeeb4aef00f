"""The C the code generator writes, as data: scalars (names or literals), statements, and what is done with
them once the walk is over (dead code dropped, operations counted, text written).  See
:mod:`jaxobs_tuning.export.codegen`.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from typing import Any

import numpy as np
from numpy.typing import DTypeLike

__all__ = [
    "S",
    "Let",
    "Assign",
    "Decl",
    "If",
    "Comment",
    "evaluate",
    "c_literal",
    "ctype",
    "lit",
    "deps",
    "prune",
    "count",
]
__all__ += ["ops_summary", "render"]

# --------------------------------------------------------------------------------------------
# scalars, types, literals
# --------------------------------------------------------------------------------------------

_CTYPE = {np.dtype(np.float32): "float", np.dtype(np.float64): "double", np.dtype(np.int32): "int"}
_CTYPE[np.dtype(np.bool_)] = "int"  # truth values: 0 or 1


def ctype(dtype: DTypeLike) -> str:
    """The C type of a dtype: float, double, or int (int32 and truth values).

    Args:
        dtype: The dtype.

    Returns:
        The C type's name.

    Raises:
        ValueError: A dtype C cannot hold here.
    """
    dt = np.dtype(dtype)
    if dt not in _CTYPE:
        raise ValueError(f"export: dtype {dt} cannot be written as C (float32, float64, int32 and bool can)")
    return _CTYPE[dt]


def c_literal(value: Any, dtype: DTypeLike) -> str:
    """``value`` as a C literal of ``dtype`` with every digit (shortest repr that reads back the same number).

    Args:
        value: The number (or truth value).
        dtype: Its dtype.

    Returns:
        The literal (``1.5f``, ``(-2.0)``, ``NAN``, ...).
    """
    dt = np.dtype(dtype)
    if dt == np.bool_:
        return "1" if bool(value) else "0"
    if dt.kind in "iu":
        return str(int(value))
    v = dt.type(value)
    if np.isnan(v):
        return "NAN"
    if np.isinf(v):
        return "INFINITY" if float(v) > 0 else "(-INFINITY)"
    text = str(v)  # numpy's shortest repr that reads back the same float32 (float64) number
    if "." not in text and "e" not in text:
        text += ".0"
    if dt == np.float32:
        text += "f"
    return f"({text})" if text.startswith("-") else text


@dataclasses.dataclass(frozen=True)
class S:
    """One scalar of the C program: a name or a literal (``lit``), its dtype, and whether it depends only on
    constants and gains (``const``: the C compiler folds it, so it is not counted per step)."""

    c: str
    dtype: np.dtype
    lit: Any = None
    const: bool = False
    truth: S | None = None  # an int that is a converted truth value: ``if (truth)`` reads better

    @property
    def is_lit(self) -> bool:
        """Whether it is a literal."""
        return self.lit is not None


def lit(value: Any, dtype: DTypeLike) -> S:
    """A literal scalar (constant).

    Args:
        value: The number.
        dtype: Its dtype.

    Returns:
        The :class:`S`.
    """
    dt = np.dtype(dtype)
    v = dt.type(value)
    return S(c_literal(v, dt), dt, lit=v, const=True)


# --------------------------------------------------------------------------------------------
# statements
# --------------------------------------------------------------------------------------------


@dataclasses.dataclass
class Let:
    """``const T name = expr;``"""

    name: str
    ctype: str
    expr: str
    deps: tuple
    op: str  # what it costs: "add", "mul", "div", "call:sinf", "compare", "select", "logic", "" (none)
    const: bool
    fn: Any = None  # the same operation on numpy scalars (None: a load, ``expr`` names the source)
    args: tuple = ()  # its operands (S)


@dataclasses.dataclass
class Assign:
    """``target = expr;``: a state field or an output written from a local (``value``, the local's scalar)."""

    target: str
    expr: str
    deps: tuple
    value: S


@dataclasses.dataclass
class Decl:
    """``T name;``: a local assigned in both branches of an ``if``."""

    name: str
    ctype: str


@dataclasses.dataclass
class If:
    """``if (cond) { then } else { other }``: a ``cond`` primitive (AB3's RK4 start-up)."""

    cond: str
    deps: tuple
    then: list
    other: list
    outputs: tuple  # names assigned in both branches
    test: Any = None  # env -> bool: the condition on numpy values


@dataclasses.dataclass
class Comment:
    """Where the statements that follow come from (a file:line of the Python step), for the reader."""

    text: str


def deps(*xs: S) -> tuple:
    """The names a statement reads: those of its operands that are not literals.

    Args:
        *xs: The operands.

    Returns:
        Their names.
    """
    return tuple(x.c for x in xs if not x.is_lit)


def evaluate(block: list, env: dict) -> dict:
    """Run ``block`` on numpy scalars: ``env`` maps the sources of the loads (``s->x[0]``, ``u[1]``) to values;
    returns it with every name and target assigned.  float32 numpy arithmetic rounds as C's float does (C99
    without FP contraction), so this is the emitted C, run in Python: the export's check without a C compiler.

    Args:
        block: The statements.
        env: The loads' sources and their values; updated in place.

    Returns:
        ``env``, every name and target assigned.
    """

    def val(x: S):
        return x.lit if x.is_lit else env[x.c]

    for st in block:
        if isinstance(st, Let):
            env[st.name] = env[st.expr] if st.fn is None else st.fn(*(val(a) for a in st.args))
        elif isinstance(st, Assign):
            env[st.target] = val(st.value)
        elif isinstance(st, If):
            evaluate(st.then if st.test(env) else st.other, env)
    return env


# --------------------------------------------------------------------------------------------
# liveness, counts, text
# --------------------------------------------------------------------------------------------


def prune(block: list, live: set) -> list:
    """Drop statements whose results nobody reads (backwards); ``live`` is updated with what is read.

    Args:
        block: The statements.
        live: The names read after the block (stores to the state and outputs are always kept).

    Returns:
        The statements kept, in order.
    """
    kept = []
    for st in reversed(block):
        if isinstance(st, Let):
            if st.name not in live:
                continue
            live.update(st.deps)
        elif isinstance(st, Decl):
            if st.name not in live:
                continue
        elif isinstance(st, Assign):
            if st.target not in live and not st.target.startswith(("s->", "y[")):
                continue
            live.update(st.deps)
        elif isinstance(st, If):
            if not any(n in live for n in st.outputs):
                continue
            live_then, live_else = set(live), set(live)
            st.then = prune(st.then, live_then)
            st.other = prune(st.other, live_else)
            live |= live_then | live_else
            live.update(st.deps)
        kept.append(st)
    return kept[::-1]


def count(block: list) -> tuple[Counter, Counter]:
    """(cheapest, dearest) operation counts of a block: an ``if`` counts its cheaper and its dearer branch.

    Args:
        block: The statements.

    Returns:
        ``(cheapest, dearest)``: operation kind -> count.
    """
    lo, hi = Counter(), Counter()
    for st in block:
        if isinstance(st, Let) and st.op and not st.const:
            lo[st.op] += 1
            hi[st.op] += 1
        elif isinstance(st, If):
            lo_t, hi_t = count(st.then)
            lo_e, hi_e = count(st.other)
            lo.update(min(lo_t, lo_e, key=lambda c: sum(c.values())))
            hi.update(max(hi_t, hi_e, key=lambda c: sum(c.values())))
    return lo, hi


def ops_summary(c: Counter) -> dict:
    """An operation count as JSON: +/- (negations included), *, /, calls by name, compares, selects, logic, total.

    Args:
        c: Operation kind -> count (:func:`count`).

    Returns:
        The summary.
    """
    calls = {k[5:]: v for k, v in sorted(c.items()) if k.startswith("call:")}
    out = {
        "add": c["add"],
        "mul": c["mul"],
        "div": c["div"],
        "call": sum(calls.values()),
        "compare": c["compare"],
        "select": c["select"],
        "logic": c["logic"],
        "calls": calls,
    }
    out["total"] = sum(v for k, v in out.items() if k != "calls")
    return out


def render(block: list, indent: str = "    ") -> list:
    """The C text of a block, one line per statement (a comment kept only before a statement).

    Args:
        block: The statements.
        indent: The indentation of its lines.

    Returns:
        The lines.
    """
    lines = []
    for k, st in enumerate(block):
        if isinstance(st, Comment):
            nxt = block[k + 1] if k + 1 < len(block) else None
            if nxt is not None and not isinstance(nxt, Comment):  # a comment on nothing is dropped
                lines.append(f"{indent}/* {st.text} */")
        elif isinstance(st, Let):
            lines.append(f"{indent}const {st.ctype} {st.name} = {st.expr};")
        elif isinstance(st, Decl):
            lines.append(f"{indent}{st.ctype} {st.name};")
        elif isinstance(st, Assign):
            lines.append(f"{indent}{st.target} = {st.expr};")
        elif isinstance(st, If):
            lines.append(f"{indent}if ({st.cond}) {{")
            lines += render(st.then, indent + "    ")
            lines.append(f"{indent}}} else {{")
            lines += render(st.other, indent + "    ")
            lines.append(f"{indent}}}")
    return lines
