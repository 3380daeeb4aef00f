"""C99 from a step's jaxpr: any pure ``step(state, u) -> (state, out)`` written as straight-line C.

:func:`generate` traces ``observer.step(state, u)`` with :func:`jax.make_jaxpr` (the
observer's array leaves, its gains, are inputs of the trace, so they stay named in the
C: ``JX_LAM``), then walks the jaxpr once.  Every array is unrolled into C scalars (a
state of shape (5,) is five locals): observers' arrays hold a handful of entries, and
scalar code is what a DSP compiler vectorizes or not as it likes.  Per equation:

- scalar arithmetic and the C99 ``<math.h>`` functions (``sinf``, ``atan2f``, ...) as
  one SSA local each, ``const float t12 = t3 * t5;``;
- comparisons give ``int`` truth values that feed selects (``c ? a : b``); an ``int``
  counter (AB3's start-up count) is the only other integer;
- data movement (slice, squeeze, reshape, broadcast, concatenate, stack, split,
  transpose, pad, gather/scatter and dynamic slices at constant indices) emits no code:
  it re-arranges the scalars.  Which element goes where is found by running the
  primitive itself on an array of element ids, so it has XLA's semantics exactly;
- ``jit``, ``closed_call``, ``custom_jvp_call``, ``custom_vjp_call``, ``remat`` are
  inlined; ``cond`` becomes ``if``/``else`` (AB3's RK4 start-up);
- an equation whose inputs are all constants is evaluated now (by the primitive itself)
  and written as a literal with every digit of its float32 (or float64) value.

Anything else (loops, random numbers, FFTs, ...) raises a ``ValueError`` naming the
primitive and the line of Python that made it.  Dead code is dropped; the operation
count per step is that of the emitted C, arithmetic only (data movement is free).
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import numpy as np
from numpy.typing import ArrayLike

from jaxobs.core.validate import key_part

from .ir import Assign, If, Let, S, c_literal, count, ctype, deps, evaluate, ops_summary, prune, render
from .lower import Emitter, Walker

__all__ = [
    "CStep",
    "Leaf",
    "generate",
    "leaf_name",
    "gain_macro",
    "is_angle",
    "write_c",
    "reference",
    "rule_doc",
    "statics",
]

# --------------------------------------------------------------------------------------------
# the step of an observer
# --------------------------------------------------------------------------------------------


def leaf_name(path: Sequence[Any]) -> str:
    """A pytree key path as a C identifier: ``.rule.f1`` -> ``rule_f1``, ``[0]`` (a tuple's) -> ``leaf0``.

    Args:
        path: The key path (:func:`jax.tree_util.tree_flatten_with_path`'s).

    Returns:
        The identifier.
    """
    parts = []
    for k in path:
        parts.append(str(key_part(k)))
    name = re.sub(r"\W", "_", "_".join(parts)) or "value"
    return f"leaf{name}" if name[0].isdigit() else name


# C keywords and the names the generated code uses itself: a local named like one of them gets a '_'
_RESERVED = {"s", "u", "y", "auto", "break", "case", "char", "const", "continue", "default", "do", "double"}
_RESERVED |= {"else", "enum", "extern", "float", "for", "goto", "if", "inline", "int", "long", "register"}
_RESERVED |= {"restrict", "return", "short", "signed", "sizeof", "static", "struct", "switch", "typedef"}
_RESERVED |= {"union", "unsigned", "void", "volatile", "while", "_Bool", "_Complex", "_Imaginary", "jx_state"}


def _local(name: str) -> str:
    """A C local for a state or input scalar that no temporary (t12, b4, c7), macro or keyword shadows."""
    clash = name in _RESERVED or re.fullmatch(r"[tbc]\d+", name) or name.startswith("JX_") or name in dir(math)
    return f"{name}_" if clash else name


@dataclasses.dataclass
class Leaf:
    """One array leaf of the state, the input, the output or the gains, as C sees it."""

    name: str  # C identifier part (the pytree path joined by '_')
    shape: tuple
    dtype: np.dtype
    value: np.ndarray | None = None  # initial state / gain value

    @property
    def size(self) -> int:
        """Its number of scalars."""
        return int(np.prod(self.shape, dtype=int))

    def scalars(self) -> list[str]:
        """Column names of its scalars: the name, or ``name_0, name_1, ...``."""
        return [self.name] if self.shape == () else [f"{self.name}_{i}" for i in range(self.size)]


@dataclasses.dataclass
class CStep:
    """A step written as C: its leaves and the body of ``jx_step`` (reads ``s``, ``u``; writes ``s``, ``y``)."""

    gains: list  # [Leaf]: macros JX_<NAME> with their values
    state: list  # [Leaf]: fields of jx_state with their initial values
    inputs: list  # [Leaf]: u[0..] in order
    outputs: list  # [Leaf]: y[0..] in order
    body: str
    ops_steady: dict
    ops_worst: dict
    has_branch: bool
    block: list  # the statements of the body (jaxobs_tuning.export.ir)

    def run(self, state: list, u: ArrayLike) -> tuple[list, np.ndarray]:
        """The emitted step on numpy scalars: the C, run in Python.

        Args:
            state: The values of the state leaves (as ``Leaf.value``).
            u: The inputs.

        Returns:
            ``(the new state leaves, the outputs y)``.
        """
        env = {}
        for g in self.gains:
            for i, v in enumerate(np.asarray(g.value).reshape(-1)):
                env[gain_macro(g, None if g.shape == () else i)] = v
        for leaf, value in zip(self.state, state):
            for i, v in enumerate(np.asarray(value, leaf.dtype).reshape(-1)):
                env[f"s->{leaf.name}" if leaf.shape == () else f"s->{leaf.name}[{i}]"] = v
        dtypes = [leaf.dtype for leaf in self.inputs for _ in range(leaf.size)]
        for k, (v, dt) in enumerate(zip(np.asarray(u).reshape(-1), dtypes)):
            env[f"u[{k}]"] = dt.type(v)
        env = evaluate(self.block, env)
        new = []
        for leaf, value in zip(self.state, state):
            flat = np.asarray(value, leaf.dtype).reshape(-1).copy()
            for i in range(flat.size):
                key = f"s->{leaf.name}" if leaf.shape == () else f"s->{leaf.name}[{i}]"
                flat[i] = env.get(key, flat[i])  # a leaf the step leaves as it is is not stored
            new.append(flat.reshape(leaf.shape))
        y = np.asarray([env[f"y[{j}]"] for j in range(len(self.output_names))])
        return new, y

    @property
    def input_names(self) -> list:
        """The names of the inputs' scalars, u[0..] in order."""
        return [n for leaf in self.inputs for n in leaf.scalars()]

    @property
    def output_names(self) -> list:
        """The names of the outputs' scalars, y[0..] in order."""
        return [n for leaf in self.outputs for n in leaf.scalars()]


def _leaves(tree, values=True) -> list:
    out = []
    for path, leaf in jax.tree_util.tree_flatten_with_path(tree)[0]:
        a = np.asarray(leaf)
        out.append(Leaf(leaf_name(path), a.shape, a.dtype, a if values else None))
    return out


def gain_macro(leaf: Leaf, i: int | None = None) -> str:
    """The C macro of a gain's scalar: ``JX_<NAME>`` or ``JX_<NAME>_<i>``.

    Args:
        leaf: The gain's leaf.
        i: The scalar's index in it (None: a scalar leaf).

    Returns:
        The macro's name.
    """
    return "JX_" + leaf.name.upper() + ("" if i is None else f"_{i}")


def generate(observer: eqx.Module, state: Any, u: Any, *, input_names: Sequence[str] | None = None) -> CStep:
    """``observer.step(state, u)`` as the body of a C function ``jx_step(jx_state *s, const T *u, T *y)``.

    ``state`` and ``u`` give the structure, shapes and dtypes (their values: the initial state, recorded in
    the result); the observer's array leaves become named constants ``JX_<PATH>``.  ``input_names`` names
    the scalars of ``u`` (default: its pytree paths).  Floats must be all float32 or all float64.

    Args:
        observer: The observer (any module with a pure ``step(state, u) -> (state, out)``).
        state: Its state.
        u: An input of its step.
        input_names: The names of ``u``'s scalars (default: its pytree paths).

    Returns:
        The :class:`CStep`.

    Raises:
        ValueError: A primitive or dtype the export cannot write as C.
    """
    params, static = eqx.partition(observer, eqx.is_array)
    gains = _leaves(params)
    st_leaves = _leaves(state)
    in_leaves = _leaves(u, values=False)
    if input_names is not None:
        if len(input_names) != sum(x.size for x in in_leaves):
            raise ValueError(f"export: {len(input_names)} input names for {sum(x.size for x in in_leaves)} inputs")
        if len(in_leaves) == 1 and in_leaves[0].shape == ():
            in_leaves[0].name = input_names[0]
        else:
            for leaf, name in zip(in_leaves, input_names):
                leaf.name = name
    for kind, leaves in (("gain", gains), ("state", st_leaves), ("input", in_leaves)):
        names = [x.name for x in leaves]
        if len(set(names)) != len(names):
            raise ValueError(f"export: two {kind} leaves share a C name: {sorted(names)}")
    floats = {x.dtype for x in gains + st_leaves + in_leaves if x.dtype.kind == "f"}
    if len(floats) > 1:
        raise ValueError(f"export: the step mixes float types {sorted(map(str, floats))}: give one (float32)")
    fdt = floats.pop() if floats else np.dtype(np.float32)

    def step(p, s, x):
        return eqx.combine(p, static).step(s, x)

    closed, out_shape = jax.make_jaxpr(step, return_shape=True)(params, state, u)
    em = Emitter(fdt)
    args = []
    for g in gains:
        arr = np.empty(g.shape, dtype=object)
        for i, idx in enumerate(np.ndindex(g.shape)):
            arr[idx] = S(gain_macro(g, None if g.shape == () else i), g.dtype, const=True)
        args.append(arr)
    for leaf in st_leaves:
        arr = np.empty(leaf.shape, dtype=object)
        for i, idx in enumerate(np.ndindex(leaf.shape)):
            name = _local(leaf.name if leaf.shape == () else f"{leaf.name}_{i}")
            src = f"s->{leaf.name}" if leaf.shape == () else f"s->{leaf.name}[{i}]"
            em.block.append(Let(name, ctype(leaf.dtype), src, (), "", False))
            arr[idx] = S(name, leaf.dtype)
        args.append(arr)
    k = 0
    for leaf in in_leaves:
        arr = np.empty(leaf.shape, dtype=object)
        for i, idx in enumerate(np.ndindex(leaf.shape)):
            name = _local(leaf.scalars()[i])
            em.block.append(Let(name, ctype(leaf.dtype), f"u[{k}]", (), "", False))
            arr[idx] = S(name, leaf.dtype)
            k += 1
        args.append(arr)
    outs = Walker(em).run(closed.jaxpr, closed.consts, args)
    new_state, y = jax.tree.unflatten(jax.tree.structure(out_shape), outs)
    out_leaves = [
        Leaf(leaf_name(path), np.shape(a), a.flat[0].dtype if a.size else fdt)
        for path, a in jax.tree_util.tree_flatten_with_path(y)[0]
    ]
    # stores last: every read of s happened into locals above, so the order of the stores does not matter
    for leaf, arr in zip(st_leaves, jax.tree.leaves(new_state)):
        arr = np.broadcast_to(arr, leaf.shape)
        for i, s_ in enumerate(arr.flat):
            target = f"s->{leaf.name}" if leaf.shape == () else f"s->{leaf.name}[{i}]"
            s_ = em.convert(s_, leaf.dtype)
            if s_.c != _local(leaf.name if leaf.shape == () else f"{leaf.name}_{i}"):  # not stored if unchanged
                em.block.append(Assign(target, s_.c, deps(s_), s_))
    j = 0
    for arr in jax.tree.leaves(y):
        for s_ in arr.flat:
            s_ = em.convert(s_, fdt)
            em.block.append(Assign(f"y[{j}]", s_.c, deps(s_), s_))
            j += 1
    block = prune(em.block, set())
    lo, hi = count(block)
    has_branch = any(isinstance(st, If) for st in block)
    body = "\n".join(render(block))
    if not any("u[" in st.expr for st in block if isinstance(st, Let)):
        body = "    (void)u;\n" + body
    return CStep(gains, st_leaves, in_leaves, out_leaves, body, ops_summary(lo), ops_summary(hi), has_branch, block)


# --------------------------------------------------------------------------------------------
# the files observer.h and observer.c
# --------------------------------------------------------------------------------------------


def is_angle(name: str) -> bool:
    """Whether an output is an angle (rad), compared modulo 2π by the check: those named ``theta...``.

    Args:
        name: The output's name.

    Returns:
        Whether it is an angle.
    """
    return name.startswith("theta")


def _ops_text(o: dict) -> str:
    calls = ", ".join(f"{k} {v}" for k, v in o["calls"].items())
    parts = [
        f"{o['add']} +/-",
        f"{o['mul']} *",
        f"{o['div']} /",
        f"{o['call']} calls" + (f" ({calls})" if calls else ""),
    ]
    if o["compare"] or o["select"] or o["logic"]:
        parts.append(f"{o['compare']} compares, {o['select']} selects, {o['logic']} logic")
    return f"{o['total']} = " + ", ".join(parts)


_STEP_DOC = {
    "signal": """ * jx_step returns the estimate at t_n from the samples before t_n: the outputs of the state before
 * u is integrated over the period (jaxobs/observers/base.py, signal-level observers).""",
    "drive": """ * u = (u_a, u_b, i_a, i_b): the current sampled at t_n and the voltage about to be applied.  jx_step
 * integrates the period that just ended (the voltage given one step earlier, the current from
 * i_prev to i) and returns the estimate at t_n (jaxobs/observers/base.py, drive observers); the
 * first call only records u and i.""",
}


def reference(observer: eqx.Module) -> str:
    """The first line of the observer's docstring: its paper and equations (every observer's docstring names them).

    Args:
        observer: The observer.

    Returns:
        The line (its class's name where it has no docstring).
    """
    doc = (type(observer).__doc__ or "").strip().splitlines()
    return doc[0].rstrip(".") if doc else type(observer).__name__


def rule_doc(rule: Any) -> dict:
    """The rule's name, first docstring line and options; an observer without a rule integrates in its step.

    Args:
        rule: The discretization rule (a dataclass), or None.

    Returns:
        ``{"name", "description", <option>: value...}``.
    """
    if rule is None:
        return {"name": "none", "description": "the step's own update"}
    doc = (type(rule).__doc__ or "").strip().splitlines()
    fields = {f.name: getattr(rule, f.name) for f in dataclasses.fields(rule)}
    return {"name": type(rule).__name__, "description": doc[0] if doc else "", **fields}


def statics(observer: Any) -> dict:
    """The observer's static fields but ts and rule (floors, options), for the record.

    Args:
        observer: The observer (a dataclass).

    Returns:
        Field name -> value, for the int, float, str and bool fields.
    """
    out = {}
    for f in dataclasses.fields(observer):
        v = getattr(observer, f.name)
        if f.name not in ("ts", "rule") and not eqx.is_array(v) and isinstance(v, (int, float, str, bool)):
            out[f.name] = v
    return out


def write_c(
    obs32: eqx.Module, step: CStep, kind: str, source: str, notes: Sequence[str], rule: Any = None
) -> tuple[str, str]:
    """observer.h and observer.c of a generated step.

    Args:
        obs32: The float32 observer the step was generated from.
        step: The generated step (:func:`generate`).
        kind: "signal" or "drive": the step convention documented in the header.
        source: Where the design comes from, for the header.
        notes: Lines for the header.
        rule: The observer's discretization rule (None: it integrates in its own step).

    Returns:
        The texts of observer.h and observer.c.
    """
    gains = _gain_macros(step)
    return _header_c(obs32, step, kind, source, notes, rule, gains), _source_c(obs32, step, gains)


# the C type of the step's inputs and outputs
_C_TYPE = "float"


def _gain_macros(step: CStep) -> list[tuple[str, str, str]]:
    """(macro, its C literal, the leaf's name), one per scalar of every array leaf of the gains."""
    return [
        (gain_macro(g, None if g.shape == () else i), c_literal(v, g.dtype), g.name)
        for g in step.gains
        for i, v in enumerate(g.value.flat)
    ]


def _state_fields(step: CStep) -> list[str]:
    """The fields of ``jx_state``, one line per state leaf."""
    fields = []
    for leaf in step.state:
        ct = "float" if leaf.dtype.kind == "f" else "int"
        dims = "" if leaf.shape == () else f"[{leaf.size}]"
        what = "truth value" if leaf.dtype == np.bool_ else "counter" if leaf.dtype.kind == "i" else ""
        fields.append(f"    {ct} {leaf.name}{dims};" + (f" /* {what} */" if what else ""))
    return fields


def _header_c(obs32, step: CStep, kind: str, source: str, notes, rule, gains: list[tuple[str, str, str]]) -> str:
    """observer.h: the design, its gains, the step's convention and operation count, and the C declarations."""
    component = type(obs32).__name__
    c_type = _C_TYPE
    gains_doc = "\n".join(f" *   {m:<14} {v:<16} {n}" for m, v, n in gains)
    options = ", ".join(f"{k} = {v!r}" for k, v in statics(obs32).items())
    note_lines = "".join(f"\n *   note: {n}" for n in notes)
    in_doc = "\n".join(f" *   u[{i}]  {n}" for i, n in enumerate(step.input_names))
    out_doc = "\n".join(
        f" *   y[{i}]  {n}" + (" (angle, rad)" if is_angle(n) else "") for i, n in enumerate(step.output_names)
    )
    fields = _state_fields(step)
    angle_mask = ", ".join("1" if is_angle(n) else "0" for n in step.output_names)
    worst = ""
    if step.has_branch:
        dearer = _ops_text(step.ops_worst)
        worst = f"\n *   a step taking the dearer branch of each if (e.g. AB3's RK4 start-up):\n *     {dearer}"
    rule = rule_doc(rule)
    opts = ", ".join(f"{k}={v!r}" for k, v in rule.items() if k not in ("name", "description"))
    header = f"""/* observer.h -- {component} exported by `jaxobs export` (float32, C99), generated from the jaxpr of
 * its step (jaxobs_tuning.export.codegen): the same operations as the JAX step, in the same order.
 *
 * {reference(obs32)}.
 * Design: {source}.{note_lines}
 * Discretization: {rule["name"]}({opts}): {rule["description"].rstrip(".")}; ts = {obs32.ts!r} s.
 * Gains (float32, baked into observer.c as macros):
{gains_doc}
 *   static options: {options or "none"}
 *
 * Call jx_init(&s) once, then jx_step(&s, u, y) once per sample period:
{in_doc}
{out_doc}
{_STEP_DOC[kind]}
 *
 * Operations per step, outputs included (+/- counts negations too; operations on constants
 * only, which the C compiler folds, are not counted):
 *   {_ops_text(step.ops_steady)}{worst}
 *
 * golden.csv holds the JAX step's float32 outputs; test_main.c checks this code against them
 * (max |y_C - y_golden| / (1 + |y_golden|) <= 1e-4, angles modulo 2 pi).
 */
#ifndef JX_OBSERVER_H
#define JX_OBSERVER_H

#ifdef __cplusplus
extern "C" {{
#endif

#define JX_NU {len(step.input_names)} /* inputs per step */
#define JX_NY {len(step.output_names)} /* outputs per step */
#define JX_Y_IS_ANGLE {{{angle_mask}}} /* outputs compared modulo 2 pi */
#define JX_TS {float(obs32.ts)!r}f /* sample period, s: call jx_step once per period (a drive's 1/f_sample_hz) */

/* the JAX step's state, leaf by leaf (pytree paths joined by '_') */
typedef struct {{
{chr(10).join(fields)}
}} jx_state;

void jx_init(jx_state *s);
void jx_step(jx_state *s, const {c_type} *u, {c_type} *y);

#ifdef __cplusplus
}}
#endif

#endif /* JX_OBSERVER_H */
"""
    return header


def _source_c(obs32, step: CStep, gains: list[tuple[str, str, str]]) -> str:
    """observer.c: the gains as macros, ``jx_init`` with the initial state and ``jx_step`` with the body."""
    component = type(obs32).__name__
    c_type = _C_TYPE
    macros = "\n".join(f"#define {m} {v} /* {n} */" for m, v, n in gains)
    init = []
    for leaf in step.state:
        for i, v in enumerate(np.asarray(leaf.value).flat):
            target = f"s->{leaf.name}" if leaf.shape == () else f"s->{leaf.name}[{i}]"
            init.append(f"    {target} = {c_literal(v, leaf.dtype)};")
    source_c = f"""/* observer.c -- {component} exported by `jaxobs export`; see observer.h. */
#include <math.h>

#include "observer.h"

{macros}

void jx_init(jx_state *s)
{{
{chr(10).join(init)}
}}

/* One period: reads the state into locals, computes, then stores the new state and the outputs. */
void jx_step(jx_state *s, const {c_type} *u, {c_type} *y)
{{
{step.body}
}}
"""
    return source_c
