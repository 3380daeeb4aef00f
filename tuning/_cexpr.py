"""A small scalar expression language for emitting float32 C (used by :mod:`tuning.export`).

The C emitters of the observers' cores (:mod:`tuning._cmodels`) build the
vector field and the outputs as expression DAGs with the same operators, in the
same order, as the JAX code they mirror; this module prints them as C99, takes
their derivatives (the Jacobian the Tustin rule's Newton iteration needs),
counts their operations and evaluates them in NumPy (the export's self-check).

Numbers follow JAX's float32 promotion, so that the C computes what the JAX
step computes (to rounding: XLA fuses some multiply-adds and turns divisions by
constants into products):

- a gain (a float32 leaf) is a *named* constant, ``JX_K1``, defined once in
  the header with its float32 value;
- a Python float meeting an expression is a *weak* constant: rounded once to
  float32 where it meets the expression (JAX's weak typing), so ``0.5 * h``
  is computed in double and then rounded, as in ``jaxobs.discretize``;
- an operation on two constants is folded in float32 (NumPy float32
  arithmetic is IEEE single, as XLA's and the C compiler's are).

Structurally equal sub-expressions are the same object (hash-consing inside a
:func:`scope`), so common sub-expressions are found by identity.  Printing
keeps the tree's association exactly (``a - (b - c)`` keeps its parentheses):
float arithmetic is not associative, and the C must add in JAX's order.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterable

import numpy as np

__all__ = [
    "Expr",
    "var",
    "const",
    "named",
    "scope",
    "fmax",
    "sqrt",
    "sin",
    "cos",
    "atan2",
    "gt",
    "lt",
    "eq",
    "select",
    "atan",
    "fabs",
    "fmod",
    "let",
    "deriv",
    "Block",
    "count_ops",
    "evaluate",
    "c_float",
]

_F32 = np.float32

# binary operators: C token and precedence; unary minus and atoms bind tighter
_BIN = {"add": ("+", 1), "sub": ("-", 1), "mul": ("*", 2), "div": ("/", 2)}
_CMP = {"gt": ">", "lt": "<", "eq": "=="}
_FUN = {
    "sqrt": "sqrtf",
    "sin": "sinf",
    "cos": "cosf",
    "atan": "atanf",
    "atan2": "atan2f",
    "fmax": "fmaxf",
    "fabs": "fabsf",
    "fmod": "fmodf",
}
_PREC_NEG, _PREC_ATOM = 3, 4

_table: dict = {}


@contextlib.contextmanager
def scope():
    """A fresh hash-consing table: expressions built inside are shared only with each other."""
    global _table
    saved, _table = _table, {}
    try:
        yield
    finally:
        _table = saved


def c_float(v) -> str:
    """A float32 value as a C literal that reads back to the same float (``%.9g`` is exact for float32)."""
    v = _F32(v)
    if not np.isfinite(v):
        raise ValueError(f"cannot write the non-finite constant {v!r} into C")
    s = f"{float(v):.9g}"
    if not any(ch in s for ch in ".en"):
        s += ".0"
    return s + "f"


class Expr:
    """A node: ``op`` with ``args`` (child nodes) and ``value`` (constant, name or variable)."""

    __slots__ = ("op", "args", "value", "hint", "__weakref__")

    def __new__(cls, op: str, args: tuple = (), value=None):
        key = (op, args, value)
        node = _table.get(key)
        if node is None:
            node = object.__new__(cls)
            node.op, node.args, node.value, node.hint = op, args, value, None
            _table[key] = node
        return node

    # -- constants --------------------------------------------------------------------------
    @property
    def is_const(self) -> bool:
        return self.op in ("const", "named")

    @property
    def number(self) -> np.float32:
        """The float32 value of a constant node."""
        return self.value if self.op == "const" else self.value[1]

    # -- arithmetic -------------------------------------------------------------------------
    def __add__(self, o):
        return _binary("add", self, o)

    def __radd__(self, o):
        return _binary("add", o, self)

    def __sub__(self, o):
        return _binary("sub", self, o)

    def __rsub__(self, o):
        return _binary("sub", o, self)

    def __mul__(self, o):
        return _binary("mul", self, o)

    def __rmul__(self, o):
        return _binary("mul", o, self)

    def __truediv__(self, o):
        return _binary("div", self, o)

    def __rtruediv__(self, o):
        return _binary("div", o, self)

    def __pow__(self, n):
        if n != 2:
            raise ValueError(f"only squares are written as C (x * x, as lax.integer_pow), got power {n!r}")
        return self * self

    def __neg__(self):
        if self.op == "const":
            return const(-self.value)
        if self.op == "neg":
            return self.args[0]
        return Expr("neg", (self,))

    def __pos__(self):
        return self

    def __repr__(self):
        return f"Expr({self.op}, {self.value!r})" if not self.args else f"Expr({self.op}, {len(self.args)} args)"


def var(name: str) -> Expr:
    """A run-time value, printed as ``name`` (e.g. ``x[0]``, ``u[0]``)."""
    return Expr("var", (), name)


def const(v) -> Expr:
    """An anonymous float32 constant (the value is rounded to float32 once)."""
    return Expr("const", (), _F32(v))


def named(cname: str, v) -> Expr:
    """A named float32 constant (a gain), printed as ``cname`` and defined in the header."""
    return Expr("named", (), (cname, _F32(v)))


def _lift(v) -> Expr:
    if isinstance(v, Expr):
        return v
    if isinstance(v, (bool, np.bool_)):
        raise TypeError("booleans are not expressions; use gt/lt/eq and select")
    if isinstance(v, (int, float, np.floating, np.integer)):
        return const(v)  # a weak Python number: rounded to float32 where it meets the expression
    raise TypeError(f"cannot use {type(v).__name__} in a C expression")


def _fold(op, a: np.float32, b: np.float32) -> np.float32:
    with np.errstate(all="ignore"):
        if op == "add":
            return _F32(a + b)
        if op == "sub":
            return _F32(a - b)
        if op == "mul":
            return _F32(a * b)
        return _F32(a / b)


def _binary(op, a, b) -> Expr:
    a, b = _lift(a), _lift(b)
    if a.op == "const" and b.op == "const":
        return const(_fold(op, a.value, b.value))
    return Expr(op, (a, b))


def _zero(e: Expr) -> bool:
    return e.op == "const" and e.value == 0


def _one(e: Expr) -> bool:
    return e.op == "const" and e.value == 1


def _fun(name, *args) -> Expr:
    return Expr(name, tuple(_lift(a) for a in args))


def fmax(a, b) -> Expr:
    """``jnp.maximum`` (C ``fmaxf``)."""
    return _fun("fmax", a, b)


def sqrt(a) -> Expr:
    return _fun("sqrt", a)


def sin(a) -> Expr:
    return _fun("sin", a)


def cos(a) -> Expr:
    return _fun("cos", a)


def atan2(y, x) -> Expr:
    return _fun("atan2", y, x)


def atan(a) -> Expr:
    return _fun("atan", a)


def fabs(a) -> Expr:
    return _fun("fabs", a)


def fmod(a, b) -> Expr:
    """C ``fmodf`` (XLA's ``rem``): the remainder with the sign of ``a``."""
    return _fun("fmod", a, b)


def gt(a, b) -> Expr:
    return _fun("gt", a, b)


def lt(a, b) -> Expr:
    return _fun("lt", a, b)


def eq(a, b) -> Expr:
    return _fun("eq", a, b)


def select(cond: Expr, a, b) -> Expr:
    """``jnp.where(cond, a, b)`` (C ``cond ? a : b``)."""
    a, b = _lift(a), _lift(b)
    if a is b:
        return a
    return Expr("select", (cond, a, b))


def let(name: str, e: Expr) -> Expr:
    """Ask the printer to hold ``e`` in a local named ``name`` (readability only)."""
    if isinstance(e, Expr) and not e.is_const and e.op != "var" and e.hint is None:
        e.hint = name
    return e


# --------------------------------------------------------------------------------------------
# derivatives (the Jacobian of the Tustin rule's Newton iteration)
# --------------------------------------------------------------------------------------------


def _dadd(a, b):
    if _zero(a):
        return b
    if _zero(b):
        return a
    return a + b


def _dsub(a, b):
    if _zero(b):
        return a
    if _zero(a):
        return -b
    return a - b


def _dmul(a, b):
    if _zero(a) or _zero(b):
        return const(0.0)
    if _one(a):
        return b
    if _one(b):
        return a
    if b.op == "const" and b.value == -1:  # x·(−1) = −x exactly
        return -a
    if a.op == "const" and a.value == -1:
        return -b
    return a * b


def _ddiv(a, b):
    if _zero(a):
        return const(0.0)
    return a / b


def deriv(e: Expr, x: Expr, memo: dict | None = None) -> Expr:
    """∂e/∂x for a variable ``x`` (zeros and ones folded; ties of ``fmax`` split ½/½ as JAX's ``maximum``)."""
    memo = {} if memo is None else memo
    key = id(e)
    if key in memo:
        return memo[key][1]
    op, a = e.op, e.args
    if op in ("const", "named"):
        d = const(0.0)
    elif op == "var":
        d = const(1.0) if e is x else const(0.0)
    elif op in ("gt", "lt", "eq"):
        d = const(0.0)
    else:
        da = [deriv(c, x, memo) for c in a]
        if op == "add":
            d = _dadd(da[0], da[1])
        elif op == "sub":
            d = _dsub(da[0], da[1])
        elif op == "neg":
            d = const(0.0) if _zero(da[0]) else -da[0]
        elif op == "mul":
            d = _dadd(_dmul(da[0], a[1]), _dmul(a[0], da[1]))
        elif op == "div":  # d(a/b) = da/b − (a/b)(db/b)
            d = _dsub(_ddiv(da[0], a[1]), _dmul(e, _ddiv(da[1], a[1])))
        elif op == "sqrt":
            d = _ddiv(_dmul(const(0.5), da[0]), e)
        elif op == "sin":
            d = _dmul(cos(a[0]), da[0])
        elif op == "cos":
            d = -_dmul(sin(a[0]), da[0]) if not _zero(da[0]) else const(0.0)
        elif op == "atan":
            d = _ddiv(da[0], 1.0 + a[0] * a[0])
        elif op == "fabs":
            d = select(lt(a[0], 0.0), -da[0], da[0]) if not _zero(da[0]) else const(0.0)
        elif op == "fmod":  # d fmod(a, b)/da = 1 between the jumps
            if not _zero(da[1]):
                raise ValueError("fmod by a varying divisor is not differentiated here")
            d = da[0]
        elif op == "atan2":  # d atan2(y, x) = (x dy − y dx)/(x² + y²)
            num = _dsub(_dmul(a[1], da[0]), _dmul(a[0], da[1]))
            d = _ddiv(num, a[1] * a[1] + a[0] * a[0])
        elif op == "fmax":
            if _zero(da[0]) and _zero(da[1]):
                d = const(0.0)
            else:
                tie = _dmul(const(0.5), _dadd(da[0], da[1]))
                d = select(gt(a[0], a[1]), da[0], select(lt(a[0], a[1]), da[1], tie))
        elif op == "select":
            d = select(a[0], da[1], da[2])
        else:
            raise AssertionError(op)
    memo[key] = (e, d)  # keep e alive so its id is not reused
    return d


# --------------------------------------------------------------------------------------------
# walking, counting, evaluating
# --------------------------------------------------------------------------------------------


def _topo(roots: Iterable[Expr]) -> list[Expr]:
    order, seen = [], set()
    stack = [(r, False) for r in reversed(list(roots))]
    while stack:
        node, done = stack.pop()
        if done:
            order.append(node)
            continue
        if id(node) in seen:
            continue
        seen.add(id(node))
        stack.append((node, True))
        for c in reversed(node.args):
            if id(c) not in seen:
                stack.append((c, False))
    return order


def _runtime(order: list[Expr]) -> set:
    """Ids of the nodes that depend on a variable (the rest are compile-time constants)."""
    live = set()
    for n in order:
        if n.op == "var" or any(id(c) in live for c in n.args):
            live.add(id(n))
    return live


OP_KINDS = ("add", "mul", "div", "call", "compare", "select")


def count_ops(roots: Iterable[Expr]) -> dict:
    """Run-time operations to evaluate ``roots`` once, common sub-expressions counted once.

    Kinds: ``add`` (+, − and negation), ``mul``, ``div``, ``call`` (sqrtf, sinf, cosf, atan2f,
    fmaxf, by name in ``calls``), ``compare`` and ``select`` (?:).  Constant sub-expressions are
    folded at compile time and not counted.
    """
    order = _topo(roots)
    live = _runtime(order)
    n = {k: 0 for k in OP_KINDS}
    calls: dict = {}
    for node in order:
        if id(node) not in live or node.op == "var":
            continue
        op = node.op
        if op in ("add", "sub", "neg"):
            n["add"] += 1
        elif op in ("mul", "div"):
            n[op] += 1
        elif op in _FUN:
            n["call"] += 1
            calls[_FUN[op]] = calls.get(_FUN[op], 0) + 1
        elif op in _CMP:
            n["compare"] += 1
        elif op == "select":
            n["select"] += 1
    n["calls"] = calls
    return n


def evaluate(roots: Iterable[Expr], env: dict, dtype=np.float32) -> list:
    """Values of ``roots`` with variables from ``env`` (name → number), in NumPy ``dtype``."""
    val: dict = {}
    with np.errstate(all="ignore"):
        for node in _topo(roots):
            op, a = node.op, [val[id(c)] for c in node.args]
            if op == "var":
                v = dtype(env[node.value])
            elif op in ("const", "named"):
                v = dtype(node.number)
            elif op == "add":
                v = a[0] + a[1]
            elif op == "sub":
                v = a[0] - a[1]
            elif op == "mul":
                v = a[0] * a[1]
            elif op == "div":
                v = a[0] / a[1]
            elif op == "neg":
                v = -a[0]
            elif op == "sqrt":
                v = np.sqrt(a[0])
            elif op == "sin":
                v = np.sin(a[0])
            elif op == "cos":
                v = np.cos(a[0])
            elif op == "atan2":
                v = np.arctan2(a[0], a[1])
            elif op == "atan":
                v = np.arctan(a[0])
            elif op == "fabs":
                v = np.abs(a[0])
            elif op == "fmod":
                v = np.fmod(a[0], a[1])
            elif op == "fmax":
                v = np.maximum(a[0], a[1])
            elif op == "gt":
                v = a[0] > a[1]
            elif op == "lt":
                v = a[0] < a[1]
            elif op == "eq":
                v = a[0] == a[1]
            elif op == "select":
                v = a[1] if a[0] else a[2]
            else:
                raise AssertionError(op)
            val[id(node)] = v
    return [val[id(r)] for r in roots]


# --------------------------------------------------------------------------------------------
# printing
# --------------------------------------------------------------------------------------------


class Block:
    """Prints assignments ``lhs = expr;`` as C, holding shared sub-expressions in ``const float`` locals.

    A node gets a local when more than one place uses it or when it carries a
    :func:`let` name; everything else is printed inline, parenthesized so that C
    parses exactly the tree that was built.
    """

    def __init__(self, indent: str = "    ", reserved: Iterable[str] = ()):
        self.indent = indent
        self.reserved = set(reserved)  # names already in use (the function's parameters and locals)

    def emit(self, assigns: list[tuple[str, Expr]]) -> str:
        roots = [e for _, e in assigns]
        order = _topo(roots)
        live = _runtime(order)
        uses: dict = {}
        for node in order:
            for c in node.args:
                uses[id(c)] = uses.get(id(c), 0) + 1
        for r in roots:
            uses[id(r)] = uses.get(id(r), 0) + 1
        self.names: dict = {}
        taken = set()
        lines = []
        for node in order:
            if id(node) not in live or node.op == "var":
                continue
            if uses.get(id(node), 0) > 1 or node.hint is not None:
                name = node.hint or f"t{len(taken)}"
                k = 2
                while name in taken or name in self.reserved:
                    name = f"{node.hint}_{k}" if node.hint else f"t{len(taken) + k}"
                    k += 1
                taken.add(name)
                ctype = "int" if node.op in _CMP else "float"
                lines.append(f"{self.indent}const {ctype} {name} = {self.expr(node, top=True)};")
                self.names[id(node)] = name
        for lhs, e in assigns:
            lines.append(f"{self.indent}{lhs} = {self.expr(e)};")
        return "\n".join(lines)

    def expr(self, e: Expr, top: bool = False) -> str:
        return self._p(e, top)[0]

    def _p(self, e: Expr, top: bool = False) -> tuple[str, int]:
        if not top and id(e) in self.names:
            return self.names[id(e)], _PREC_ATOM
        op = e.op
        if op == "var":
            return e.value, _PREC_ATOM
        if op == "named":
            return e.value[0], _PREC_ATOM
        if op == "const":
            s = c_float(e.value)
            return (f"({s})", _PREC_ATOM) if s.startswith("-") else (s, _PREC_ATOM)
        if op in _BIN:
            tok, prec = _BIN[op]
            ls, lp = self._p(e.args[0])
            rs, rp = self._p(e.args[1])
            if lp < prec:
                ls = f"({ls})"
            if rp <= prec:  # same precedence on the right keeps its parentheses: a - (b - c)
                rs = f"({rs})"
            return f"{ls} {tok} {rs}", prec
        if op == "neg":
            s, p = self._p(e.args[0])
            if p < _PREC_ATOM:
                s = f"({s})"
            return f"-{s}", _PREC_NEG
        if op in _FUN:
            return f"{_FUN[op]}({', '.join(self._p(c, False)[0] for c in e.args)})", _PREC_ATOM
        if op in _CMP:
            ls, _ = self._p(e.args[0])
            rs, _ = self._p(e.args[1])
            return f"({ls} {_CMP[op]} {rs})", _PREC_ATOM
        if op == "select":
            c, _ = self._p(e.args[0])
            a, _ = self._p(e.args[1])
            b, _ = self._p(e.args[2])
            return f"({c} ? {a} : {b})", _PREC_ATOM
        raise AssertionError(op)
