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
from collections import Counter
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["CStep", "Leaf", "generate", "leaf_name", "c_literal"]


# --------------------------------------------------------------------------------------------
# scalars, types, literals
# --------------------------------------------------------------------------------------------

_CTYPE = {np.dtype(np.float32): "float", np.dtype(np.float64): "double", np.dtype(np.int32): "int"}
_CTYPE[np.dtype(np.bool_)] = "int"  # truth values: 0 or 1


def _ctype(dtype) -> str:
    dt = np.dtype(dtype)
    if dt not in _CTYPE:
        raise ValueError(f"export: dtype {dt} cannot be written as C (float32, float64, int32 and bool can)")
    return _CTYPE[dt]


def c_literal(value, dtype) -> str:
    """``value`` as a C literal of ``dtype`` with every digit (shortest repr that reads back the same number)."""
    dt = np.dtype(dtype)
    if dt == np.bool_:
        return "1" if bool(value) else "0"
    if dt.kind in "iu":
        return str(int(value))
    v = dt.type(value)
    if np.isnan(v):
        return "NAN"
    if np.isinf(v):
        return "INFINITY" if v > 0 else "(-INFINITY)"
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
    def is_lit(self):
        return self.lit is not None


def _lit(value, dtype) -> S:
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


@dataclasses.dataclass
class Assign:
    target: str
    expr: str
    deps: tuple


@dataclasses.dataclass
class Decl:
    name: str
    ctype: str


@dataclasses.dataclass
class If:
    cond: str
    deps: tuple
    then: list
    other: list
    outputs: tuple  # names assigned in both branches


def _deps(*xs: S) -> tuple:
    return tuple(x.c for x in xs if not x.is_lit)


# --------------------------------------------------------------------------------------------
# the primitives
# --------------------------------------------------------------------------------------------

_UNARY_CALLS = {  # primitive -> C99 <math.h> function (float32 name; the double one drops the "f")
    "sqrt": "sqrtf",
    "exp": "expf",
    "exp2": "exp2f",
    "log": "logf",
    "log1p": "log1pf",
    "expm1": "expm1f",
    "sin": "sinf",
    "cos": "cosf",
    "tan": "tanf",
    "asin": "asinf",
    "acos": "acosf",
    "atan": "atanf",
    "sinh": "sinhf",
    "cosh": "coshf",
    "tanh": "tanhf",
    "asinh": "asinhf",
    "acosh": "acoshf",
    "atanh": "atanhf",
    "abs": "fabsf",
    "floor": "floorf",
    "ceil": "ceilf",
    "cbrt": "cbrtf",
    "erf": "erff",
}
_BINARY_CALLS = {"atan2": "atan2f", "pow": "powf", "rem": "fmodf", "max": "fmaxf", "min": "fminf"}
_BINARY_OPS = {"add": ("+", "add"), "add_any": ("+", "add"), "sub": ("-", "add"), "mul": ("*", "mul")}
_BINARY_OPS["div"] = ("/", "div")
_COMPARE = {"eq": "==", "ne": "!=", "lt": "<", "le": "<=", "gt": ">", "ge": ">="}
_LOGIC = {"and": "&&", "or": "||"}
_IDENTITY = {"copy", "copy_p", "stop_gradient", "optimization_barrier", "pvary", "device_put"}
_CALLS = {"jit": "jaxpr", "pjit": "jaxpr", "closed_call": "call_jaxpr", "core_call": "call_jaxpr"}
_CALLS |= {"custom_jvp_call": "call_jaxpr", "custom_vjp_call": "call_jaxpr", "custom_vjp_call_jaxpr": "fun_jaxpr"}
_CALLS |= {"remat": "jaxpr", "checkpoint": "jaxpr"}
# data movement: which operands are data (moved) and which are indices (must be constants)
_MOVE_INDEX_OPERANDS = {"dynamic_slice": (1, None), "dynamic_update_slice": (2, None), "gather": (1, 2)}
_MOVE_INDEX_OPERANDS["scatter"] = (1, 2)
_MOVE = {"slice", "squeeze", "reshape", "broadcast_in_dim", "transpose", "concatenate", "stack", "split", "rev"}
_MOVE |= {"pad", "expand_dims", *_MOVE_INDEX_OPERANDS}
_REDUCE = {"reduce_sum": "add", "reduce_max": "max", "reduce_min": "min", "reduce_prod": "mul"}
_REDUCE |= {"reduce_and": "and", "reduce_or": "or"}
_OTHER = {"neg", "sign", "integer_pow", "square", "rsqrt", "logistic", "round", "not", "is_finite", "select_n"}
_OTHER |= {"convert_element_type", "clamp", "iota", "dot_general", "cond", "xor", "nextafter"}
SUPPORTED = sorted(
    {*_UNARY_CALLS, *_BINARY_CALLS, *_BINARY_OPS, *_COMPARE, *_LOGIC, *_IDENTITY, *_CALLS, *_MOVE, *_REDUCE, *_OTHER}
)


def _where(eqn) -> str:
    """The line of user code that made ``eqn`` (its innermost frame outside jax), for error messages."""
    try:
        frames = eqn.source_info.traceback.frames
    except AttributeError:
        return "unknown"
    for f in frames:
        name = f.file_name.replace("\\", "/")
        if "/jax/" not in name and "/jaxlib/" not in name and "/equinox/" not in name:
            return f"{name.rsplit('/', 2)[-1] if '/' in name else name}:{f.line_num} ({f.function_name})"
    return "unknown"


def _sub_jaxpr(j):
    """(jaxpr, consts) of a ClosedJaxpr or an open Jaxpr parameter."""
    if hasattr(j, "jaxpr") and hasattr(j, "consts"):
        return j.jaxpr, list(j.consts)
    return j, []


class _Emitter:
    def __init__(self, dtype):
        self.fdt = np.dtype(dtype)
        self.double = self.fdt == np.float64
        self.n = 0
        self.block: list = []
        self.memo: dict = {}  # (type, expression) -> its scalar: common subexpressions computed once

    # --- naming and statements ------------------------------------------------------------

    def fresh(self, prefix="t") -> str:
        self.n += 1
        return f"{prefix}{self.n}"

    def let(self, expr: str, dtype, deps: tuple, op: str, const: bool, truth=None) -> S:
        key = (_ctype(dtype), expr)
        if key in self.memo:
            return self.memo[key]
        name = self.fresh("b" if np.dtype(dtype) == np.bool_ else "t")
        self.block.append(Let(name, _ctype(dtype), expr, deps, op, const))
        self.memo[key] = out = S(name, np.dtype(dtype), const=const, truth=truth)
        return out

    def fn(self, name: str, dtype) -> str:
        return name if np.dtype(dtype) != np.float64 else name[:-1]

    # --- elementwise ------------------------------------------------------------------------

    def unary(self, prim: str, x: S, params) -> S:
        dt = x.dtype
        if prim == "neg":
            return self.let(f"-{x.c}", dt, _deps(x), "add", x.const)
        if prim == "not":
            if dt != np.bool_:
                raise ValueError("export: bitwise not of an integer cannot be written (truth values only)")
            return self.let(f"!{x.c}", dt, _deps(x), "logic", x.const)
        if prim in ("square",):
            return self.binary("mul", x, x)
        if prim == "integer_pow":
            return self.integer_pow(x, int(params["y"]))
        if prim == "rsqrt":
            return self.binary("div", _lit(1, dt), self.unary("sqrt", x, {}))
        if prim == "logistic":
            e = self.unary("exp", self.unary("neg", x, {}), {})
            return self.binary("div", _lit(1, dt), self.binary("add", _lit(1, dt), e))
        if prim == "sign":
            one, zero = c_literal(1, dt), c_literal(0, dt)
            expr = f"({x.c} > {zero} ? {one} : ({x.c} < {zero} ? -{one} : {x.c}))"
            return self.let(expr, dt, _deps(x), "compare", x.const)
        if prim == "is_finite":
            return self.let(f"isfinite({x.c})", np.bool_, _deps(x), "compare", x.const)
        if prim == "round":
            # lax.RoundingMethod: 0 away from zero (roundf), 1 to nearest even (rintf in the default mode)
            call = "roundf" if int(params.get("rounding_method", 0)) == 0 else "rintf"
            return self.let(f"{self.fn(call, dt)}({x.c})", dt, _deps(x), f"call:{call}", x.const)
        call = _UNARY_CALLS[prim]
        if dt.kind != "f":
            if prim == "abs":
                return self.let(f"({x.c} < 0 ? -{x.c} : {x.c})", dt, _deps(x), "compare", x.const)
            raise ValueError(f"export: {prim} of an integer cannot be written (floats only)")
        return self.let(f"{self.fn(call, dt)}({x.c})", dt, _deps(x), f"call:{call}", x.const)

    def integer_pow(self, x: S, y: int) -> S:
        # the same products in the same order as jax's lowering of integer_pow (binary exponentiation)
        if y == 0:
            return _lit(1, x.dtype)
        recip, y = y < 0, abs(y)
        acc = None
        while y > 0:
            if y & 1:
                acc = x if acc is None else self.binary("mul", acc, x)
            y >>= 1
            if y > 0:
                x = self.binary("mul", x, x)
        return self.binary("div", _lit(1, acc.dtype), acc) if recip else acc

    def binary(self, prim: str, a: S, b: S) -> S:
        dt = a.dtype
        const = a.const and b.const
        # exact identities only: x + 0, x - 0, x * 1, x / 1 (and x * 0 = 0 for finite x: forward-mode
        # Jacobians multiply by the zeros of their basis vectors, which would otherwise fill the C)
        if prim in ("add", "add_any") and a.is_lit and a.lit == 0 and dt.kind == "f":
            return b
        if prim in ("add", "add_any", "sub") and b.is_lit and b.lit == 0 and dt.kind == "f":
            return a
        if prim == "mul" and dt.kind == "f":
            for p, q in ((a, b), (b, a)):
                if p.is_lit and p.lit == 1:
                    return q
                if p.is_lit and p.lit == 0:
                    return _lit(0, dt)
        if prim == "div" and b.is_lit and b.lit == 1:
            return a
        if prim in _BINARY_OPS:
            sym, op = _BINARY_OPS[prim]
            if prim == "div" and dt.kind != "f":
                raise ValueError("export: integer division cannot be written (truth values and counters only)")
            return self.let(f"{a.c} {sym} {b.c}", dt, _deps(a, b), op, const)
        if prim in _COMPARE:
            return self.let(f"{a.c} {_COMPARE[prim]} {b.c}", np.bool_, _deps(a, b), "compare", const)
        if prim in _LOGIC or prim == "xor":
            if dt != np.bool_:
                raise ValueError(f"export: bitwise {prim} of integers cannot be written (truth values only)")
            sym = _LOGIC.get(prim, "!=")
            return self.let(f"{a.c} {sym} {b.c}", dt, _deps(a, b), "logic", const)
        if prim in ("max", "min") and dt.kind != "f":
            sym = ">" if prim == "max" else "<"
            return self.let(f"{a.c} {sym} {b.c} ? {a.c} : {b.c}", dt, _deps(a, b), "compare", const)
        if prim == "nextafter":
            return self.let(f"{self.fn('nextafterf', dt)}({a.c}, {b.c})", dt, _deps(a, b), "call:nextafterf", const)
        call = _BINARY_CALLS[prim]
        if dt.kind != "f":
            raise ValueError(f"export: {prim} of integers cannot be written (floats only)")
        return self.let(f"{self.fn(call, dt)}({a.c}, {b.c})", dt, _deps(a, b), f"call:{call}", const)

    def select(self, which: S, cases: list) -> S:
        if which.is_lit:
            return cases[int(np.clip(int(which.lit), 0, len(cases) - 1))]
        if all(c == cases[0] for c in cases[1:]):
            return cases[0]
        dt = cases[0].dtype
        const = which.const and all(c.const for c in cases)
        if len(cases) == 2:
            cond = which.c if which.dtype == np.bool_ else f"{which.c} != 0"
            expr = f"{cond} ? {cases[1].c} : {cases[0].c}"
        else:  # select_n clamps nothing: the index is in range by contract
            expr = cases[-1].c
            for k in range(len(cases) - 2, -1, -1):
                expr = f"{which.c} == {k} ? {cases[k].c} : ({expr})"
        return self.let(expr, dt, _deps(which, *cases), "select", const)

    def convert(self, x: S, new) -> S:
        new = np.dtype(new)
        if new == x.dtype:
            return x
        if x.is_lit:
            return _lit(x.lit, new)
        if new == np.bool_:
            return self.let(f"{x.c} != 0", new, _deps(x), "compare", x.const)
        if x.dtype == np.bool_ and new.kind == "f":
            expr = f"{x.c} ? {c_literal(1, new)} : {c_literal(0, new)}"
            return self.let(expr, new, _deps(x), "select", x.const)
        if x.dtype == np.bool_ and new.kind == "i":
            return S(x.c, new, const=x.const, truth=x)  # 0 or 1 already
        return self.let(f"({_ctype(new)}){x.c}", new, _deps(x), "", x.const)


# --------------------------------------------------------------------------------------------
# the walk
# --------------------------------------------------------------------------------------------


def _array(value) -> np.ndarray:
    a = np.asarray(value)
    out = np.empty(a.shape, dtype=object)
    for idx in np.ndindex(a.shape):
        out[idx] = _lit(a[idx], a.dtype)
    return out


def _is_const_array(arr) -> bool:
    return all(s.is_lit for s in arr.flat)


def _values(arr) -> np.ndarray:
    dt = arr.flat[0].dtype if arr.size else np.float32
    return np.asarray([s.lit for s in arr.flat], dtype=dt).reshape(arr.shape)


class _Walker:
    def __init__(self, emitter: _Emitter):
        self.em = emitter

    def run(self, jaxpr, consts, args) -> list:
        env = {}

        def read(v):
            if isinstance(v, jax.extend.core.Literal):
                return _array(v.val)
            return env[v]

        for var, c in zip(jaxpr.constvars, consts):
            env[var] = _array(c)
        for var, a in zip(jaxpr.invars, args):
            env[var] = a
        for eqn in jaxpr.eqns:
            ins = [read(v) for v in eqn.invars]
            try:
                outs = self.eqn(eqn, ins)
            except ValueError as e:
                if " (at " in str(e):
                    raise
                raise ValueError(f"{e} (at {_where(eqn)})") from None
            for var, o in zip(eqn.outvars, outs):
                env[var] = o
        return [read(v) for v in jaxpr.outvars]

    def eqn(self, eqn, ins) -> list:
        prim, params = eqn.primitive.name, eqn.params
        if prim in _CALLS:
            key = _CALLS[prim] if _CALLS[prim] in params else "call_jaxpr"
            jaxpr, consts = _sub_jaxpr(params[key])
            if prim == "custom_jvp_call" or prim.startswith("custom_vjp"):
                ins = ins[-len(jaxpr.invars) :] if len(ins) > len(jaxpr.invars) else ins
            return self.run(jaxpr, consts, ins)
        if prim == "cond":
            return self.cond(eqn, ins)
        if prim in _IDENTITY:
            return ins
        multiple = eqn.primitive.multiple_results
        if prim not in SUPPORTED:
            raise ValueError(
                f"export: the step uses the primitive '{prim}' (at {_where(eqn)}), which cannot be written as "
                f"straight-line C (loops: unroll them with a Python for); supported: {', '.join(SUPPORTED)}"
            )
        if prim in _MOVE:
            return self.move(eqn, ins)
        if all(_is_const_array(a) for a in ins):
            # constants only: evaluate the primitive itself (XLA's semantics) and keep literals
            out = eqn.primitive.bind(*(jnp.asarray(_values(a)) for a in ins), **params)
            return [_array(o) for o in (out if multiple else [out])]
        if prim in _REDUCE:
            return [self.reduce(_REDUCE[prim], ins[0], params["axes"])]
        if prim == "dot_general":
            return [self.dot(ins[0], ins[1], params["dimension_numbers"], eqn.outvars[0].aval.dtype)]
        shape = eqn.outvars[0].aval.shape
        ins = [np.broadcast_to(a, shape) if a.shape != shape else a for a in ins]
        out = np.empty(shape, dtype=object)
        for idx in np.ndindex(shape):
            xs = [a[idx] for a in ins]
            out[idx] = self.scalar(prim, xs, params)
        return [out]

    def scalar(self, prim, xs, params) -> S:
        em = self.em
        if prim == "select_n":
            return em.select(xs[0], xs[1:])
        if prim == "convert_element_type":
            return em.convert(xs[0], params["new_dtype"])
        if prim == "clamp":
            lo, x, hi = xs
            return em.binary("min", em.binary("max", x, lo), hi)
        if len(xs) == 1:
            return em.unary(prim, xs[0], params)
        return em.binary(prim, xs[0], xs[1])

    def move(self, eqn, ins) -> list:
        """Data movement: run the primitive on element ids to learn where each output element comes from."""
        prim = eqn.primitive.name
        first, last = _MOVE_INDEX_OPERANDS.get(prim, (len(ins), None))
        index_ops = list(range(first, len(ins) if last is None else last))
        pool, args = [], []
        for k, a in enumerate(ins):
            if k in index_ops:
                if not _is_const_array(a):
                    raise ValueError(
                        f"export: {prim} at an index computed in the step cannot be written (constant only)"
                    )
                args.append(jnp.asarray(_values(a)))
                continue
            ids = np.arange(len(pool), len(pool) + a.size, dtype=np.int32).reshape(a.shape)
            pool.extend(a.flat)
            args.append(jnp.asarray(ids))
        with jax.enable_x64(False):
            out = eqn.primitive.bind(*args, **eqn.params)
        outs = out if eqn.primitive.multiple_results else [out]
        result = []
        for o in outs:
            o = np.asarray(o)
            if o.size and (o.min() < 0 or o.max() >= len(pool)):
                raise ValueError(f"export: {prim} reads out of bounds (a fill value) and cannot be written")
            arr = np.empty(o.shape, dtype=object)
            for idx in np.ndindex(o.shape):
                arr[idx] = pool[int(o[idx])]
            result.append(arr)
        return result

    def reduce(self, kind, x, axes) -> np.ndarray:
        axes = tuple(axes)
        keep = [d for d in range(x.ndim) if d not in axes]
        moved = np.transpose(x, keep + list(axes))
        shape = moved.shape[: len(keep)]
        moved = moved.reshape(shape + (-1,))
        out = np.empty(shape, dtype=object)
        for idx in np.ndindex(shape):
            acc = moved[idx][0]
            for s in moved[idx][1:]:
                acc = self.em.binary(kind, acc, s)
            out[idx] = acc
        return out

    def dot(self, a, b, dims, dtype) -> np.ndarray:
        (ca, cb), (ba, bb) = dims
        fa = [d for d in range(a.ndim) if d not in ca and d not in ba]
        fb = [d for d in range(b.ndim) if d not in cb and d not in bb]
        a2 = np.transpose(a, list(ba) + fa + list(ca))
        b2 = np.transpose(b, list(bb) + fb + list(cb))
        nb, nk = len(ba), len(ca)
        bshape = a2.shape[:nb]
        out_shape = bshape + a2.shape[nb : a2.ndim - nk] + b2.shape[nb : b2.ndim - nk]
        a3 = a2.reshape(bshape + (int(np.prod(a2.shape[nb : a2.ndim - nk])), -1))
        b3 = b2.reshape(bshape + (int(np.prod(b2.shape[nb : b2.ndim - nk])), -1))
        out = np.empty(bshape + (a3.shape[-2], b3.shape[-2]), dtype=object)
        for bi in np.ndindex(bshape):
            for i in range(a3.shape[-2]):
                for j in range(b3.shape[-2]):
                    acc = None
                    for k in range(a3.shape[-1]):
                        term = self.em.binary(
                            "mul", self.em.convert(a3[bi][i, k], dtype), self.em.convert(b3[bi][j, k], dtype)
                        )
                        acc = term if acc is None else self.em.binary("add", acc, term)
                    out[bi + (i, j)] = acc if acc is not None else _lit(0, dtype)
        return out.reshape(out_shape)

    def cond(self, eqn, ins) -> list:
        branches = eqn.params["branches"]
        index, ops = ins[0].flat[0], ins[1:]
        if index.is_lit:
            k = int(np.clip(int(index.lit), 0, len(branches) - 1))
            jaxpr, consts = _sub_jaxpr(branches[k])
            return self.run(jaxpr, consts, ops)
        em = self.em
        outer = em.block
        results = []
        for var in eqn.outvars:
            arr = np.empty(var.aval.shape, dtype=object)
            for idx in np.ndindex(var.aval.shape):
                name = em.fresh("c")
                outer.append(Decl(name, _ctype(var.aval.dtype)))
                arr[idx] = S(name, np.dtype(var.aval.dtype))
            results.append(arr)
        blocks = []
        memo = em.memo
        for br in branches:
            em.block, em.memo = [], dict(memo)  # a branch sees the values computed before it, not the other's
            jaxpr, consts = _sub_jaxpr(br)
            outs = self.run(jaxpr, consts, ops)
            for res, o in zip(results, outs):
                for r, s in zip(res.flat, np.broadcast_to(o, res.shape).flat):
                    em.block.append(Assign(r.c, s.c, _deps(s)))
            blocks.append(em.block)
        em.block, em.memo = outer, memo
        names = tuple(r.c for res in results for r in res.flat)
        # if (i) {branch 1} else {branch 0}; more branches nest (the index is clamped, as lax.switch does)
        stmt = blocks[-1]
        for k in range(len(blocks) - 2, -1, -1):
            test = index.truth.c if (index.truth is not None and len(blocks) == 2) else f"{index.c} <= {k}"
            then, other = (stmt, blocks[k]) if index.truth is not None and len(blocks) == 2 else (blocks[k], stmt)
            stmt = [If(test, _deps(index.truth or index), then, other, names)]
        outer.extend(stmt)
        return results


# --------------------------------------------------------------------------------------------
# liveness, counts, text
# --------------------------------------------------------------------------------------------


def _prune(block: list, live: set) -> list:
    """Drop statements whose results nobody reads (backwards); ``live`` is updated with what is read."""
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
            st.then = _prune(st.then, live_then)
            st.other = _prune(st.other, live_else)
            live |= live_then | live_else
            live.update(st.deps)
        kept.append(st)
    return kept[::-1]


def _count(block: list) -> tuple[Counter, Counter]:
    """(cheapest, dearest) operation counts of a block: an ``if`` counts its cheaper and its dearer branch."""
    lo, hi = Counter(), Counter()
    for st in block:
        if isinstance(st, Let) and st.op and not st.const:
            lo[st.op] += 1
            hi[st.op] += 1
        elif isinstance(st, If):
            lo_t, hi_t = _count(st.then)
            lo_e, hi_e = _count(st.other)
            lo.update(min(lo_t, lo_e, key=lambda c: sum(c.values())))
            hi.update(max(hi_t, hi_e, key=lambda c: sum(c.values())))
    return lo, hi


def ops_summary(c: Counter) -> dict:
    """An operation count as JSON: +/- (negations included), *, /, calls by name, compares, selects, logic, total."""
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
    lines = []
    for st in block:
        if isinstance(st, Let):
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


# --------------------------------------------------------------------------------------------
# the step of an observer
# --------------------------------------------------------------------------------------------


def leaf_name(path) -> str:
    """A pytree key path as a C identifier part: ``.rule.f1`` -> ``rule_f1``, ``[0]`` -> ``0``."""
    parts = []
    for k in path:
        for attr in ("name", "key", "idx"):
            if hasattr(k, attr):
                parts.append(str(getattr(k, attr)))
                break
    return "_".join(parts) or "value"


@dataclasses.dataclass
class Leaf:
    """One array leaf of the state, the input, the output or the gains, as C sees it."""

    name: str  # C identifier part (the pytree path joined by '_')
    shape: tuple
    dtype: np.dtype
    value: np.ndarray | None = None  # initial state / gain value

    @property
    def size(self) -> int:
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

    @property
    def input_names(self) -> list:
        return [n for leaf in self.inputs for n in leaf.scalars()]

    @property
    def output_names(self) -> list:
        return [n for leaf in self.outputs for n in leaf.scalars()]


def _leaves(tree, values=True) -> list:
    out = []
    for path, leaf in jax.tree_util.tree_flatten_with_path(tree)[0]:
        a = np.asarray(leaf)
        out.append(Leaf(leaf_name(path), a.shape, a.dtype, a if values else None))
    return out


def gain_macro(leaf: Leaf, i: int | None = None) -> str:
    return "JX_" + leaf.name.upper() + ("" if i is None else f"_{i}")


def generate(observer, state, u, *, input_names=None) -> CStep:
    """``observer.step(state, u)`` as the body of a C function ``jx_step(jx_state *s, const T *u, T *y)``.

    ``state`` and ``u`` give the structure, shapes and dtypes (their values: the initial state, recorded in
    the result); the observer's array leaves become named constants ``JX_<PATH>``.  ``input_names`` names
    the scalars of ``u`` (default: its pytree paths).  Floats must be all float32 or all float64.
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
    floats = {x.dtype for x in gains + st_leaves + in_leaves if x.dtype.kind == "f"}
    if len(floats) > 1:
        raise ValueError(f"export: the step mixes float types {sorted(map(str, floats))}: give one (float32)")
    fdt = floats.pop() if floats else np.dtype(np.float32)

    def step(p, s, x):
        return eqx.combine(p, static).step(s, x)

    closed, out_shape = jax.make_jaxpr(step, return_shape=True)(params, state, u)
    em = _Emitter(fdt)
    args = []
    for g in gains:
        arr = np.empty(g.shape, dtype=object)
        for i, idx in enumerate(np.ndindex(g.shape)):
            arr[idx] = S(gain_macro(g, None if g.shape == () else i), g.dtype, const=True)
        args.append(arr)
    for leaf in st_leaves:
        arr = np.empty(leaf.shape, dtype=object)
        for i, idx in enumerate(np.ndindex(leaf.shape)):
            name = leaf.name if leaf.shape == () else f"{leaf.name}_{i}"
            src = f"s->{leaf.name}" if leaf.shape == () else f"s->{leaf.name}[{i}]"
            em.block.append(Let(name, _ctype(leaf.dtype), src, (), "", False))
            arr[idx] = S(name, leaf.dtype)
        args.append(arr)
    k = 0
    for leaf in in_leaves:
        arr = np.empty(leaf.shape, dtype=object)
        for i, idx in enumerate(np.ndindex(leaf.shape)):
            name = leaf.scalars()[i]
            em.block.append(Let(name, _ctype(leaf.dtype), f"u[{k}]", (), "", False))
            arr[idx] = S(name, leaf.dtype)
            k += 1
        args.append(arr)
    outs = _Walker(em).run(closed.jaxpr, closed.consts, args)
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
            if s_.c != (leaf.name if leaf.shape == () else f"{leaf.name}_{i}"):
                em.block.append(Assign(target, s_.c, _deps(s_)))
    j = 0
    for arr in jax.tree.leaves(y):
        for s_ in arr.flat:
            s_ = em.convert(s_, fdt)
            em.block.append(Assign(f"y[{j}]", s_.c, _deps(s_)))
            j += 1
    block = _prune(em.block, set())
    lo, hi = _count(block)
    has_branch = any(isinstance(st, If) for st in block)
    body = "\n".join(render(block))
    if not any("u[" in st.expr for st in block if isinstance(st, Let)):
        body = "    (void)u;\n" + body
    return CStep(gains, st_leaves, in_leaves, out_leaves, body, ops_summary(lo), ops_summary(hi), has_branch)
