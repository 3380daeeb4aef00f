"""The jaxpr's primitives as C: :class:`Walker` reads a jaxpr equation by equation into an :class:`Emitter`,
which writes the statements of :mod:`jaxobs_tuning.export.ir`.  What each primitive becomes is in
:mod:`jaxobs_tuning.export.codegen`'s module doc; :data:`SUPPORTED` lists them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, cast

import jax
import jax.extend
import jax.numpy as jnp
import numpy as np
from jax.core import ShapedArray
from numpy.typing import DTypeLike

from .c99 import BINARY_CALLS as _BINARY_CALLS
from .c99 import BINARY_OPS as _BINARY_OPS
from .c99 import COMPARE as _COMPARE
from .c99 import LOGIC as _LOGIC
from .c99 import NUMPY as _NUMPY
from .c99 import UNARY_CALLS as _UNARY_CALLS
from .c99 import round_away as _round_away
from .ir import Assign, Comment, Decl, If, Let, S, c_literal, ctype, deps, lit

__all__ = ["SUPPORTED", "Emitter", "Walker"]

# --------------------------------------------------------------------------------------------
# the primitives
# --------------------------------------------------------------------------------------------

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
            return f"{name.rsplit('/', 1)[-1]}:{f.line_num} ({f.function_name})"
    return "unknown"


def _aval(var: jax.extend.core.Var) -> ShapedArray:
    """A jaxpr variable's shape and dtype: its aval, a ShapedArray in the jaxprs of a step (jax types it
    AbstractValue)."""
    return cast(ShapedArray, var.aval)


def _sub_jaxpr(j):
    """(jaxpr, consts) of a ClosedJaxpr or an open Jaxpr parameter."""
    if isinstance(j, jax.extend.core.ClosedJaxpr):
        return j.jaxpr, list(j.consts)
    return j, []


def _pick(which, *cases):
    """``which ? cases[1] : cases[0]`` (and the chain for select_n's index)."""
    return cases[int(which)]


def _truth_test(name):
    return lambda env: bool(env[name])


def _index_test(name, k):
    return lambda env: int(env[name]) <= k


class Emitter:
    """Writes the C statements (:mod:`jaxobs_tuning.export.ir`) of scalar operations, one SSA local each, common
    subexpressions computed once; a primitive or dtype that C cannot hold raises a ``ValueError``.

    Args:
        dtype: The float dtype of the step (float32 or float64): the ``<math.h>`` functions' names follow it.
    """

    def __init__(self, dtype: DTypeLike):
        self.fdt = np.dtype(dtype)
        self.double = self.fdt == np.float64
        self.n = 0
        self.block: list = []
        self.memo: dict = {}  # (type, expression) -> its scalar: common subexpressions computed once
        self.where = ""  # the Python line of the statements being written (a comment when it changes)

    # --- naming and statements ------------------------------------------------------------

    def fresh(self, prefix: str = "t") -> str:
        """A new local's name.

        Args:
            prefix: ``t`` (a float or int), ``b`` (a truth value) or ``c`` (an ``if``'s output).

        Returns:
            The name.
        """
        self.n += 1
        return f"{prefix}{self.n}"

    def let(
        self,
        expr: str,
        dtype: DTypeLike,
        deps: tuple,
        op: str,
        const: bool,
        truth: S | None = None,
        *,
        fn: Callable[..., Any] | None,
        args: Sequence[S],
    ) -> S:
        """``const T t<n> = expr;`` (or the earlier local with the same expression).

        Args:
            expr: The C expression.
            dtype: Its dtype.
            deps: The names it reads.
            op: What it costs (:class:`~jaxobs_tuning.export.ir.Let`'s ``op``).
            const: Whether it depends on constants and gains only.
            truth: The truth value it converts, if any.
            fn: ``fn(*args)`` computes it on numpy scalars (:func:`jaxobs_tuning.export.ir.evaluate`).
            args: Its operands.

        Returns:
            The local.
        """
        key = (ctype(dtype), expr)
        if key in self.memo:
            return self.memo[key]
        name = self.fresh("b" if np.dtype(dtype) == np.bool_ else "t")
        self.block.append(Let(name, ctype(dtype), expr, deps, op, const, fn, tuple(args)))
        self.memo[key] = out = S(name, np.dtype(dtype), const=const, truth=truth)
        return out

    def fn(self, name: str, dtype: DTypeLike) -> str:
        """A ``<math.h>`` function's name for ``dtype``: the float32 one, or the double one without its "f".

        Args:
            name: The float32 name (``sinf``).
            dtype: The operand's dtype.

        Returns:
            The name.
        """
        return name if np.dtype(dtype) != np.float64 else name[:-1]

    # --- elementwise ------------------------------------------------------------------------

    def unary(self, prim: str, x: S, params: dict) -> S:
        """A one-operand primitive on a scalar.

        Args:
            prim: The primitive's name.
            x: The operand.
            params: The equation's parameters.

        Returns:
            The result.
        """
        dt = x.dtype
        if prim == "neg":
            return self.let(f"-{x.c}", dt, deps(x), "add", x.const, fn=np.negative, args=(x,))
        if prim == "not":
            if dt != np.bool_:
                raise ValueError("export: bitwise not of an integer cannot be written (truth values only)")
            return self.let(f"!{x.c}", dt, deps(x), "logic", x.const, fn=np.logical_not, args=(x,))
        if prim in ("square",):
            return self.binary("mul", x, x)
        if prim == "integer_pow":
            return self.integer_pow(x, int(params["y"]))
        if prim == "rsqrt":
            return self.binary("div", lit(1, dt), self.unary("sqrt", x, {}))
        if prim == "logistic":
            e = self.unary("exp", self.unary("neg", x, {}), {})
            return self.binary("div", lit(1, dt), self.binary("add", lit(1, dt), e))
        if prim == "sign":
            one, zero = c_literal(1, dt), c_literal(0, dt)
            expr = f"({x.c} > {zero} ? {one} : ({x.c} < {zero} ? -{one} : {x.c}))"
            return self.let(expr, dt, deps(x), "compare", x.const, fn=np.sign, args=(x,))
        if prim == "is_finite":
            return self.let(f"isfinite({x.c})", np.bool_, deps(x), "compare", x.const, fn=np.isfinite, args=(x,))
        if prim == "round":
            # lax.RoundingMethod: 0 away from zero (roundf), 1 to nearest even (rintf in the default mode)
            call = "roundf" if int(params.get("rounding_method", 0)) == 0 else "rintf"
            fn = _round_away if call == "roundf" else np.rint
            return self.let(f"{self.fn(call, dt)}({x.c})", dt, deps(x), f"call:{call}", x.const, fn=fn, args=(x,))
        call = _UNARY_CALLS[prim]
        if dt.kind != "f":
            if prim == "abs":
                return self.let(f"({x.c} < 0 ? -{x.c} : {x.c})", dt, deps(x), "compare", x.const, fn=np.abs, args=(x,))
            raise ValueError(f"export: {prim} of an integer cannot be written (floats only)")
        fn = _NUMPY[call]
        return self.let(f"{self.fn(call, dt)}({x.c})", dt, deps(x), f"call:{call}", x.const, fn=fn, args=(x,))

    def integer_pow(self, x: S, y: int) -> S:
        """``x ** y`` for an integer ``y`` by products.

        Args:
            x: The base.
            y: The exponent.

        Returns:
            The result.
        """
        # the same products in the same order as jax's lowering of integer_pow (binary exponentiation)
        if y == 0:
            return lit(1, x.dtype)
        recip, y = y < 0, abs(y)
        acc = None
        while y > 0:
            if y & 1:
                acc = x if acc is None else self.binary("mul", acc, x)
            y >>= 1
            if y > 0:
                x = self.binary("mul", x, x)
        assert acc is not None  # y > 0 sets it on the first pass
        return self.binary("div", lit(1, acc.dtype), acc) if recip else acc

    def binary(self, prim: str, a: S, b: S) -> S:
        """A two-operand primitive on scalars (exact identities folded).

        Args:
            prim: The primitive's name.
            a: The first operand.
            b: The second operand.

        Returns:
            The result.
        """
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
                    return lit(0, dt)
        if prim == "div" and b.is_lit and b.lit == 1:
            return a
        if prim in _BINARY_OPS:
            sym, op = _BINARY_OPS[prim]
            if prim == "div" and dt.kind != "f":
                raise ValueError("export: integer division cannot be written (truth values and counters only)")
            return self.let(f"{a.c} {sym} {b.c}", dt, deps(a, b), op, const, fn=_NUMPY[sym], args=(a, b))
        if prim in _COMPARE:
            sym = _COMPARE[prim]
            return self.let(f"{a.c} {sym} {b.c}", np.bool_, deps(a, b), "compare", const, fn=_NUMPY[sym], args=(a, b))
        if prim in _LOGIC or prim == "xor":
            if dt != np.bool_:
                raise ValueError(f"export: bitwise {prim} of integers cannot be written (truth values only)")
            sym = _LOGIC.get(prim, "!=")
            return self.let(f"{a.c} {sym} {b.c}", dt, deps(a, b), "logic", const, fn=_NUMPY[sym], args=(a, b))
        if prim in ("max", "min") and dt.kind != "f":
            sym, fn = (">", np.maximum) if prim == "max" else ("<", np.minimum)
            return self.let(f"{a.c} {sym} {b.c} ? {a.c} : {b.c}", dt, deps(a, b), "compare", const, fn=fn, args=(a, b))
        if prim == "nextafter":
            expr = f"{self.fn('nextafterf', dt)}({a.c}, {b.c})"
            return self.let(expr, dt, deps(a, b), "call:nextafterf", const, fn=np.nextafter, args=(a, b))
        call = _BINARY_CALLS[prim]
        if dt.kind != "f":
            raise ValueError(f"export: {prim} of integers cannot be written (floats only)")
        expr = f"{self.fn(call, dt)}({a.c}, {b.c})"
        return self.let(expr, dt, deps(a, b), f"call:{call}", const, fn=_NUMPY[call], args=(a, b))

    def select(self, which: S, cases: list) -> S:
        """``select_n``: the case that ``which`` indexes (a truth value or an int).

        Args:
            which: The index.
            cases: The cases.

        Returns:
            The result.
        """
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
        return self.let(expr, dt, deps(which, *cases), "select", const, fn=_pick, args=(which, *cases))

    def convert(self, x: S, new: DTypeLike) -> S:
        """``x`` in another dtype (a C cast, or a truth value's test).

        Args:
            x: The scalar.
            new: The dtype.

        Returns:
            The converted scalar.
        """
        new = np.dtype(new)
        if new == x.dtype:
            return x
        if x.is_lit:
            return lit(x.lit, new)
        if new == np.bool_:
            return self.let(f"{x.c} != 0", new, deps(x), "compare", x.const, fn=lambda v: v != 0, args=(x,))
        if x.dtype == np.bool_ and new.kind == "f":
            expr = f"{x.c} ? {c_literal(1, new)} : {c_literal(0, new)}"
            return self.let(expr, new, deps(x), "select", x.const, fn=new.type, args=(x,))
        if x.dtype == np.bool_ and new.kind == "i":
            return S(x.c, new, const=x.const, truth=x)  # 0 or 1 already
        return self.let(f"({ctype(new)}){x.c}", new, deps(x), "", x.const, fn=new.type, args=(x,))


# --------------------------------------------------------------------------------------------
# the walk
# --------------------------------------------------------------------------------------------


def _array(value) -> np.ndarray:
    a = np.asarray(value)
    out = np.empty(a.shape, dtype=object)
    for idx in np.ndindex(a.shape):
        out[idx] = lit(a[idx], a.dtype)
    return out


def _is_const_array(arr) -> bool:
    return all(s.is_lit for s in arr.flat)


def _values(arr) -> np.ndarray:
    dt = arr.flat[0].dtype if arr.size else np.float32
    return np.asarray([s.lit for s in arr.flat], dtype=dt).reshape(arr.shape)


class Walker:
    """Reads a jaxpr equation by equation into its :class:`Emitter`; arrays are numpy object arrays of ``S``.

    Args:
        emitter: What the statements are written to.
    """

    def __init__(self, emitter: Emitter):
        self.em = emitter

    def run(self, jaxpr: jax.extend.core.Jaxpr, consts: Sequence[Any], args: Sequence[np.ndarray]) -> list:
        """The statements of a jaxpr, inlined.

        Args:
            jaxpr: The (open) jaxpr.
            consts: Its constants' values.
            args: Its inputs, arrays of scalars.

        Returns:
            Its outputs, arrays of scalars.

        Raises:
            ValueError: An equation that cannot be written, naming its line of Python.
        """
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
            if eqn.primitive.name not in _CALLS:
                where = _where(eqn)
                if where not in ("unknown", self.em.where):  # a jitted jnp function's equations: no user line
                    self.em.where = where
                    self.em.block.append(Comment(where))
            try:
                outs = self.eqn(eqn, ins)
            except ValueError as e:
                if " (at " in str(e):
                    raise
                raise ValueError(f"{e} (at {_where(eqn)})") from None
            for var, o in zip(eqn.outvars, outs):
                env[var] = o
        return [read(v) for v in jaxpr.outvars]

    def eqn(self, eqn: jax.extend.core.JaxprEqn, ins: list) -> list:
        """One equation: inlined calls, conditionals, data movement, constants evaluated, elementwise operations.

        Args:
            eqn: The equation.
            ins: Its inputs, arrays of scalars.

        Returns:
            Its outputs, arrays of scalars.
        """
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
            return [self.dot(ins[0], ins[1], params["dimension_numbers"], _aval(eqn.outvars[0]).dtype)]
        shape = _aval(eqn.outvars[0]).shape
        ins = [np.broadcast_to(a, shape) if a.shape != shape else a for a in ins]
        out = np.empty(shape, dtype=object)
        for idx in np.ndindex(shape):
            xs = [a[idx] for a in ins]
            out[idx] = self.scalar(prim, xs, params)
        return [out]

    def scalar(self, prim: str, xs: list, params: dict) -> S:
        """An elementwise primitive on one element of its operands.

        Args:
            prim: The primitive's name.
            xs: The operands' scalars.
            params: The equation's parameters.

        Returns:
            The result.
        """
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

    def move(self, eqn: jax.extend.core.JaxprEqn, ins: list) -> list:
        """Data movement: run the primitive on element ids to learn where each output element comes from.

        Args:
            eqn: The equation.
            ins: Its inputs, arrays of scalars.

        Returns:
            Its outputs, arrays of the same scalars.

        Raises:
            ValueError: An index computed in the step, or a read out of bounds.
        """
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

    def reduce(self, kind: str, x: np.ndarray, axes: Sequence[int]) -> np.ndarray:
        """A reduction (sum, max, min, ...) over ``axes``, left to right.

        Args:
            kind: The binary operation it folds.
            x: The array of scalars.
            axes: The axes reduced.

        Returns:
            The reduced array.
        """
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

    def dot(self, a: np.ndarray, b: np.ndarray, dims: tuple, dtype: DTypeLike) -> np.ndarray:
        """``dot_general``: sums of products, in order.

        Args:
            a: The first operand, an array of scalars.
            b: The second operand.
            dims: ``((contracting a, contracting b), (batch a, batch b))``.
            dtype: The result's dtype.

        Returns:
            The product, an array of scalars.
        """
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
                    out[bi + (i, j)] = acc if acc is not None else lit(0, dtype)
        return out.reshape(out_shape)

    def cond(self, eqn: jax.extend.core.JaxprEqn, ins: list) -> list:
        """``cond`` as ``if``/``else`` (more branches nest); a constant index takes its branch alone.

        Args:
            eqn: The equation.
            ins: Its inputs: the index, then the operands.

        Returns:
            Its outputs, arrays of scalars.
        """
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
            aval = _aval(var)
            arr = np.empty(aval.shape, dtype=object)
            for idx in np.ndindex(aval.shape):
                name = em.fresh("c")
                outer.append(Decl(name, ctype(aval.dtype)))
                arr[idx] = S(name, np.dtype(aval.dtype))
            results.append(arr)
        blocks = []
        memo = em.memo
        for br in branches:
            em.block, em.memo = [], dict(memo)  # a branch sees the values computed before it, not the other's
            jaxpr, consts = _sub_jaxpr(br)
            outs = self.run(jaxpr, consts, ops)
            for res, o in zip(results, outs):
                for r, s in zip(res.flat, np.broadcast_to(o, res.shape).flat):
                    em.block.append(Assign(r.c, s.c, deps(s), s))
            blocks.append(em.block)
        em.block, em.memo = outer, memo
        names = tuple(r.c for res in results for r in res.flat)
        # if (i) {branch 1} else {branch 0}; more branches nest (the index is clamped, as lax.switch does)
        stmt = blocks[-1]
        for k in range(len(blocks) - 2, -1, -1):
            if index.truth is not None and len(blocks) == 2:
                test, then, other = index.truth.c, stmt, blocks[k]
                check = _truth_test(index.truth.c)
            else:
                test, then, other = f"{index.c} <= {k}", blocks[k], stmt
                check = _index_test(index.c, k)
            stmt = [If(test, deps(index.truth or index), then, other, names, check)]
        outer.extend(stmt)
        return results
