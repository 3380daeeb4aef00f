"""The discretization rules of :mod:`jaxobs.discretize` written as C around ``jx_f`` (used by :mod:`tuning.export`).

Each emitter returns the C of one rule — its state in ``jx_state``, its
initialization, its helper functions and the statements that advance
``s->x`` by one period into ``x1`` — with the rule's constants and its
operation count, computed from the loops it writes (``per_f`` and ``per_jac``
are the counts of one call of ``jx_f`` and ``jx_jac``).  The C follows the
Python line for line, the same float32 operations in the same order (XLA may
still fuse some multiply-adds, so the two agree to rounding, not bit for bit):

- Euler:  x₊ = x + f(x, u)·h                                   (``diffrax.Euler``)
- RK4:    the classic tableau, ``rk4_step``
- AB3:    x₊ = x + h/12 (23 f(x, u) − 16 f₋₁ + 5 f₋₂), RK4 for the first two periods
- Tustin: x₊ = x + h/2 (f(x, u) + f(x₊, u)), ``newton_iters`` Newton iterations from an
          Euler predictor, the Newton matrix I − h/2 ∂f/∂x solved by unpivoted Gauss
          elimination (``solve_small``)

``jx_f(x, e, dx)`` takes the input at the stage's time: ``@E0``, ``@EM`` and ``@E1`` in
``advance`` stand for the input arrays at the start, middle and end of the period (all three
the same array for a held input, ``jaxobs.discretize.Held``; three knots for
``jaxobs.discretize.Knots``, which the LESOs use for the current).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from jaxobs.discretize import AB3, RK4, AbstractRule, Euler, Tustin

from ._cexpr import OP_KINDS


def ops(add=0, mul=0, div=0) -> dict:
    return {**{k: 0 for k in OP_KINDS}, "add": add, "mul": mul, "div": div, "calls": {}}


def ops_sum(*terms) -> dict:
    """Σ count·ops over ``(count, ops)`` pairs."""
    out = ops()
    for n, o in terms:
        for k in OP_KINDS:
            out[k] += n * o[k]
        for name, c in o["calls"].items():
            out["calls"][name] = out["calls"].get(name, 0) + n * c
    return out


def ops_total(o: dict) -> int:
    return sum(o[k] for k in OP_KINDS)


@dataclass
class RuleC:
    name: str
    description: str
    constants: list  # (macro, value as float, meaning)
    state_fields: list = field(default_factory=list)  # C declarations in jx_state
    init: list = field(default_factory=list)  # C statements in jx_init
    functions: str = ""  # static helpers, emitted before jx_step
    locals: list = field(default_factory=list)  # C declarations in jx_step
    advance: str = ""  # statements: s->x, u -> x1 (and the rule's own state)
    ops_steady: dict = field(default_factory=ops)
    ops_startup: dict | None = None  # AB3's start-up steps, if any
    startup_steps: int = 0
    uses_jac: bool = False
    newton_iters: int = 0


_LOOP = "for (i = 0; i < JX_NX; ++i)"

_RK4_FN = f"""/* Classic RK4 over one period (jaxobs.discretize.rk4_step): k1 = f(x, e(0)) given,
 * eh = e(1/2), e1 = e(1). */
static void jx_rk4(const float *x, const float *eh, const float *e1, const float *k1, float *x1)
{{
    float k2[JX_NX], k3[JX_NX], k4[JX_NX], xt[JX_NX];
    int i;
    {_LOOP} xt[i] = x[i] + JX_H_2 * k1[i];
    jx_f(xt, eh, k2);
    {_LOOP} xt[i] = x[i] + JX_H_2 * k2[i];
    jx_f(xt, eh, k3);
    {_LOOP} xt[i] = x[i] + JX_H * k3[i];
    jx_f(xt, e1, k4);
    {_LOOP} x1[i] = x[i] + JX_H_6 * (k1[i] + 2.0f * k2[i] + 2.0f * k3[i] + k4[i]);
}}
"""


def _rk4_ops(nx, per_f):
    """jx_rk4 without its k1: three stage updates (× +) and the weighted sum (3 ×, 4 +) per state."""
    return ops_sum((3, per_f), (3 * nx, ops(add=1, mul=1)), (nx, ops(add=4, mul=3)))


def _h_consts(h, *which):
    table = {
        "JX_H": (h, "h = ts, s"),
        "JX_H_2": (0.5 * h, "h/2"),
        "JX_H_6": (h / 6.0, "h/6 (RK4)"),
        "JX_H_12": (h / 12.0, "h/12 (AB3)"),
    }
    return [(m, *table[m]) for m in which]


def euler(rule: Euler, h: float, nx: int, per_f: dict, per_jac=None) -> RuleC:
    return RuleC(
        "Euler",
        "forward Euler (diffrax.Euler): x+ = x + f(x, u) h",
        _h_consts(h, "JX_H"),
        locals=["float f0[JX_NX];"],
        advance=f"    jx_f(s->x, @E0, f0);\n    {_LOOP} x1[i] = s->x[i] + f0[i] * JX_H;",
        ops_steady=ops_sum((1, per_f), (nx, ops(add=1, mul=1))),
    )


def rk4(rule: RK4, h: float, nx: int, per_f: dict, per_jac=None) -> RuleC:
    return RuleC(
        "RK4",
        "classic fourth-order Runge-Kutta, input held over the period",
        _h_consts(h, "JX_H", "JX_H_2", "JX_H_6"),
        functions=_RK4_FN,
        locals=["float f0[JX_NX];"],
        advance="    jx_f(s->x, @E0, f0);\n    jx_rk4(s->x, @EM, @E1, f0, x1);",
        ops_steady=ops_sum((1, per_f), (1, _rk4_ops(nx, per_f))),
    )


def ab3(rule: AB3, h: float, nx: int, per_f: dict, per_jac=None) -> RuleC:
    advance = f"""    jx_f(s->x, @E0, f0);
    if (s->n < 2) {{  /* start-up: no history yet, RK4 (jaxobs.discretize.AB3) */
        jx_rk4(s->x, @EM, @E1, f0, x1);
        s->n += 1;
    }} else {{  /* 001 Sec. VI: y[n] = y[n-1] + (Ts/12)(23 x[n-1] - 16 x[n-2] + 5 x[n-3]) */
        {_LOOP} x1[i] = s->x[i] + JX_H_12 * (23.0f * f0[i] - 16.0f * s->f1[i] + 5.0f * s->f2[i]);
    }}
    {_LOOP} {{
        s->f2[i] = s->f1[i];
        s->f1[i] = f0[i];
    }}"""
    return RuleC(
        "AB3",
        "third-order Adams-Bashforth (paper 001 Sec. VI), RK4 for the first two periods",
        _h_consts(h, "JX_H", "JX_H_2", "JX_H_6", "JX_H_12"),
        state_fields=[
            "float f1[JX_NX]; /* AB3: f one sample back */",
            "float f2[JX_NX]; /* AB3: f two samples back */",
            "int n;           /* AB3: start-up steps taken (0, 1, 2) */",
        ],
        init=[f"{_LOOP} {{\n        s->f1[i] = 0.0f;\n        s->f2[i] = 0.0f;\n    }}", "s->n = 0;"],
        functions=_RK4_FN,
        locals=["float f0[JX_NX];"],
        advance=advance,
        ops_steady=ops_sum((1, per_f), (nx, ops(add=3, mul=4))),
        ops_startup=ops_sum((1, per_f), (1, _rk4_ops(nx, per_f))),
        startup_steps=2,
    )


_SOLVE_FN = """/* a d = b by Gauss elimination without pivoting, a and b overwritten (jaxobs.discretize.solve_small):
 * the Newton matrix I - (h/2) df/dx is strongly diagonally dominant. */
static void jx_solve(float *a, float *b, float *d)
{
    int i, j, l;
    for (i = 0; i < JX_NX; ++i) {
        const float piv = a[i * JX_NX + i];
        for (j = i + 1; j < JX_NX; ++j) {
            const float m = a[j * JX_NX + i] / piv;
            for (l = 0; l < JX_NX; ++l) a[j * JX_NX + l] = a[j * JX_NX + l] - m * a[i * JX_NX + l];
            b[j] = b[j] - m * b[i];
        }
    }
    for (i = JX_NX - 1; i >= 0; --i) {
        float acc = b[i];
        for (j = i + 1; j < JX_NX; ++j) acc = acc - a[i * JX_NX + j] * d[j];
        d[i] = acc / a[i * JX_NX + i];
    }
}
"""


def _solve_ops(n):
    elim = sum((n - 1 - i) * 1 for i in range(n))  # row pairs
    back = sum(n - 1 - i for i in range(n))
    return ops_sum((elim, ops(div=1)), (elim * (n + 1), ops(add=1, mul=1)), (back, ops(add=1, mul=1)), (n, ops(div=1)))


def tustin(rule: Tustin, h: float, nx: int, per_f: dict, per_jac: dict) -> RuleC:
    if nx > 12:
        raise ValueError(f"export: the Tustin rule is written in C for at most 12 states (solve_small), got {nx}")
    iters = rule.newton_iters
    fn = (
        _SOLVE_FN
        + f"""
/* Implicit trapezoidal rule: x+ = x + h/2 [f(x, e0) + f(x+, e1)], solved by JX_NEWTON_ITERS Newton
 * iterations from the Euler predictor (jaxobs.discretize.Tustin). */
static void jx_tustin(const float *x, const float *e0, const float *e1, float *x1)
{{
    float f0[JX_NX], c[JX_NX], fy[JX_NX], r[JX_NX], d[JX_NX], J[JX_NX * JX_NX], a[JX_NX * JX_NX];
    int i, j, it;
    jx_f(x, e0, f0);
    {_LOOP} {{
        c[i] = x[i] + JX_H_2 * f0[i];
        x1[i] = x[i] + JX_H * f0[i];
    }}
    for (it = 0; it < JX_NEWTON_ITERS; ++it) {{
        jx_jac(x1, e1, J);
        {_LOOP}
            for (j = 0; j < JX_NX; ++j) a[i * JX_NX + j] = (i == j ? 1.0f : 0.0f) - JX_H_2 * J[i * JX_NX + j];
        jx_f(x1, e1, fy);
        {_LOOP} r[i] = x1[i] - c[i] - JX_H_2 * fy[i];
        jx_solve(a, r, d);
        {_LOOP} x1[i] = x1[i] - d[i];
    }}
}}
"""
    )
    per_iter = ops_sum(
        (1, per_jac),
        (nx * nx, ops(add=1, mul=1)),
        (1, per_f),
        (nx, ops(add=2, mul=1)),
        (1, _solve_ops(nx)),
        (nx, ops(add=1)),
    )
    return RuleC(
        "Tustin",
        f"implicit trapezoidal (Tustin), {iters} Newton iteration(s) from an Euler predictor",
        _h_consts(h, "JX_H", "JX_H_2"),
        functions=fn,
        advance="    jx_tustin(s->x, @E0, @E1, x1);",
        ops_steady=ops_sum((1, per_f), (nx, ops(add=2, mul=2)), (iters, per_iter)),
        uses_jac=True,
        newton_iters=iters,
    )


RULES = {Euler: euler, RK4: rk4, AB3: ab3, Tustin: tustin}


def rule_c(rule: AbstractRule, h: float, nx: int, per_f: dict, per_jac: dict | None = None) -> RuleC:
    emit = RULES.get(type(rule))
    if emit is None:
        known = ", ".join(c.__name__ for c in RULES)
        raise ValueError(f"export: rule {type(rule).__name__} has no C version; use one of {known}")
    return emit(rule, h, nx, per_f, per_jac)


def needs_jacobian(rule: AbstractRule) -> bool:
    return isinstance(rule, Tustin)
