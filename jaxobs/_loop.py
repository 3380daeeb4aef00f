"""The time loop shared by every simulation: one ``lax.scan`` made fast on CPU and cheap to differentiate.

``run_loop(body, carry, xs, n)`` is ``lax.scan(body, carry, xs, length=n)`` with
four things done to it, none of which changes a single number it returns
(tests/test_perf.py checks each against the plain scan):

1. **Split state vectors.**  A component's state is a flat array (the rules
   work on flat arrays, DESIGN.md).  Under ``vmap`` it becomes (batch, n_states)
   and every step ends in ``jnp.stack``.  XLA's CPU loop fusion computes a
   concatenated output element by element, so every expression shared by the
   components of ẋ (the input's cos, the FLL's normalization) was evaluated
   once *per component*, and the stacked layout strides the batch.  The loop
   carries each small 1-D leaf as a tuple of scalars instead and restacks it
   inside the step, where XLA folds the stack/slice pair away; the step's
   outputs become separate fused outputs that share their subexpressions.
   Measured on the SOGI-FLL (forward Euler, batch 1024, float32, 2 devices,
   unroll 8): 48 → 74 M scenario-steps/s.
2. **Peel multistep start-ups.**  :class:`~jaxobs.discretize.AB3` starts with
   two RK4 steps behind a ``lax.cond`` on its sample count.  A conditional in
   the loop body costs a branch per step and blocks unrolling, so the loop runs
   the start-up steps on their own and then converts every rule state in the
   carry to its *steady* form (``rule_state.steady()``), whose step has no
   branch.
3. **Unroll.**  XLA's CPU while loop pays a fixed cost per iteration (several
   microseconds, the same order as a whole step over 512 scenarios), so the
   body is unrolled ``unroll`` times.
4. **Checkpoint** (only matters under reverse-mode AD):

   - ``"none"``: plain scan; the VJP stores every step's residuals
     (a 10 s gradient at batch 1024 needed gigabytes).
   - ``"step"``: ``jax.checkpoint`` on the step; the VJP stores only the carry
     per step and recomputes the step once.
   - ``"chunk"``: the horizon is cut into ⌈√n⌉-step chunks; the outer scan
     stores one carry per chunk, each chunk is recomputed once in the backward
     pass with its steps checkpointed, so memory is O(√n) carries.
   - ``"forward"``: forward sensitivities.  The loop is a ``jax.custom_vjp``
     whose forward pass carries, beside the state, its derivative with respect
     to every *perturbed* input scalar (``symbolic_zeros``: a tuning job's few
     gains; the signal and scenario are not perturbed), so the backward pass
     is one small product and nothing is stored per step: O(1) memory in the
     horizon, and a gradient for about the price of one forward pass per
     tangent's linear part.  Exact (forward- and reverse-mode derivatives of the
     same program agree to rounding; tested).  Needs a loop without per-step
     outputs (``save="final"`` with a running cost) and at most ``FORWARD_MAX``
     perturbed scalars, else the reverse-mode mode below is used.
   - ``"auto"`` (default): ``"forward"`` when it applies, otherwise
     ``"chunk"`` above ``CHUNK_ABOVE`` steps and ``"step"`` below.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Literal

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["run_loop", "Checkpoint", "CHUNK_ABOVE", "resolve_checkpoint"]

Checkpoint = Literal["auto", "none", "step", "chunk", "forward"]
CHECKPOINTS = ("auto", "none", "step", "chunk", "forward")

# "auto"/"forward": reverse-mode requests through a loop with no per-step
# outputs are served by forward sensitivities when at most this many input
# scalars are perturbed (a tuning job's handful of gains).
FORWARD_MAX = 8

# Above this many steps "auto" checkpoints per chunk.  Below it per-step
# checkpointing keeps the carries of every step (n × carry), which for 1 s at
# 10 kHz and batch 1024 is a few tens of MB — cheap, and a little faster.
CHUNK_ABOVE = 20_000

_SPLIT_MAX = 64  # 1-D leaves up to this size are carried as tuples of scalars


class _Split:
    """Marker for a 1-D leaf carried as a tuple of scalars (a PyTree node)."""

    def __init__(self, parts):
        self.parts = tuple(parts)


jax.tree_util.register_pytree_node(_Split, lambda s: (s.parts, None), lambda _, parts: _Split(parts))


def _is_split(x):
    return isinstance(x, _Split)


def _split(tree):
    def one(a):
        if isinstance(a, jax.Array) and a.ndim == 1 and 0 < a.shape[0] <= _SPLIT_MAX:
            return _Split(a[i] for i in range(a.shape[0]))
        return a

    return jax.tree.map(one, tree)


def _join(tree):
    return jax.tree.map(lambda a: jnp.stack(a.parts) if _is_split(a) else a, tree, is_leaf=_is_split)


def _has_steady(x):
    return hasattr(x, "steady") and hasattr(x, "startup_steps")


def startup_steps(carry) -> int:
    """How many leading steps must run before every rule state in ``carry`` can go steady."""
    states = [s for s in jax.tree.leaves(carry, is_leaf=_has_steady) if _has_steady(s)]
    return max((s.startup_steps for s in states), default=0)


def to_steady(carry):
    return jax.tree.map(lambda s: s.steady() if _has_steady(s) else s, carry, is_leaf=_has_steady)


def check_checkpoint(checkpoint) -> str:
    if checkpoint not in CHECKPOINTS:
        raise ValueError(f"checkpoint must be one of {CHECKPOINTS}, got {checkpoint!r}")
    return checkpoint


def resolve_checkpoint(checkpoint: str, n: int) -> str:
    """The reverse-mode storage mode (forward sensitivities are decided at differentiation time)."""
    checkpoint = check_checkpoint(checkpoint)
    if checkpoint in ("auto", "forward"):
        return "chunk" if n > CHUNK_ABOVE else "step"
    return checkpoint


def check_unroll(unroll) -> int:
    if isinstance(unroll, bool) or not isinstance(unroll, (int, np.integer)) or unroll < 1:
        raise ValueError(f"unroll must be an integer >= 1, got {unroll!r}")
    return int(unroll)


def _scan(body, carry, xs, n, unroll, checkpoint):
    """Scan of ``n`` steps (n >= 0) under a resolved checkpoint mode."""
    if n == 0:
        return carry, None
    if checkpoint == "none":
        return jax.lax.scan(body, carry, xs, length=n, unroll=min(unroll, n))
    step = jax.checkpoint(body, prevent_cse=False)
    if checkpoint == "step":
        return jax.lax.scan(step, carry, xs, length=n, unroll=min(unroll, n))
    # "chunk": ⌈√n⌉ steps per chunk, the remainder as a step-checkpointed tail
    size = max(1, math.isqrt(n - 1) + 1)
    q, r = divmod(n, size)

    def chunk(c, xs_c):
        return jax.lax.scan(step, c, xs_c, length=size, unroll=min(unroll, size))

    chunk = jax.checkpoint(chunk, prevent_cse=False)
    head = None if xs is None else jax.tree.map(lambda a: a[: q * size].reshape((q, size) + a.shape[1:]), xs)
    carry, ys = jax.lax.scan(chunk, carry, head, length=q)
    ys = jax.tree.map(lambda a: a.reshape((q * size,) + a.shape[2:]), ys)
    if r:
        tail = None if xs is None else jax.tree.map(lambda a: a[q * size :], xs)
        carry, ys_t = jax.lax.scan(step, carry, tail, length=r, unroll=min(unroll, r))
        ys = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), ys, ys_t)
    return carry, ys


def run_loop(
    body: Callable[[Any, Any], tuple[Any, Any]],
    carry,
    xs,
    n: int,
    *,
    unroll: int = 1,
    checkpoint: str = "auto",
    split: bool = True,
):
    """``lax.scan(body, carry, xs, length=n)``, made fast and cheap to differentiate (module doc).

    ``body(carry, x) -> (carry, y)`` sees the carry exactly as given (state
    vectors as arrays); ``xs`` (or ``None``) has leading axis ``n``.
    """
    unroll = check_unroll(unroll)
    mode = resolve_checkpoint(checkpoint, n)
    if checkpoint in ("auto", "forward") and not _has_outputs(body, carry, xs):
        # forward sensitivities only serve loops without per-step outputs; the others go
        # straight to reverse mode (no custom_vjp around them)
        return _sensitivity_loop(lambda c, x: _run(body, c, x, n, unroll, mode, split), carry, xs)
    return _run(body, carry, xs, n, unroll, mode, split)


def _has_outputs(body, carry, xs) -> bool:
    x0 = None if xs is None else jax.tree.map(lambda a: a[0], xs)
    return bool(jax.tree.leaves(jax.eval_shape(body, carry, x0)[1]))


def _run(body, carry, xs, n, unroll, mode, split):
    if split:

        def inner(c, x):
            c, y = body(_join(c), x)
            return _split(c), y

        wrap, unwrap = _split, _join
    else:
        inner, wrap, unwrap = body, (lambda c: c), (lambda c: c)

    p = min(startup_steps(carry), n)
    ys_head = None
    if p:
        head = None if xs is None else jax.tree.map(lambda a: a[:p], xs)
        c, ys_head = _scan(inner, wrap(carry), head, p, 1, "none" if mode == "none" else "step")
        carry = unwrap(c)
    carry = to_steady(carry)
    rest = None if xs is None else jax.tree.map(lambda a: a[p:], xs)
    c, ys = _scan(inner, wrap(carry), rest, n - p, unroll, mode)
    carry = unwrap(c)
    if ys_head is not None:
        ys = ys_head if ys is None else jax.tree.map(lambda a, b: jnp.concatenate([a, b]), ys_head, ys)
    return carry, ys


# ---------------------------------------------------------------------------
# forward sensitivities behind a custom VJP
# ---------------------------------------------------------------------------


def _is_float(x) -> bool:
    return jnp.issubdtype(jnp.result_type(x), jnp.inexact)


def _is_zero(x) -> bool:
    return isinstance(x, jax.custom_derivatives.SymbolicZero)


def _instantiate(c):
    if not _is_zero(c):
        return c
    aval = c.aval
    if aval.dtype == jax.dtypes.float0:
        return np.zeros(aval.shape, dtype=jax.dtypes.float0)
    return jnp.zeros(aval.shape, aval.dtype)


def _sensitivity_loop(loop, carry, xs):
    """``loop(carry, xs)`` whose reverse-mode derivative is computed by forward sensitivities when that applies."""
    conv, consts = jax.closure_convert(loop, carry, xs)

    @jax.custom_vjp
    def f(consts, carry, xs):
        return conv(carry, xs, *consts)

    def fwd(consts, carry, xs):
        primals = (consts, carry, xs)
        is_p = lambda p: isinstance(p, jax.custom_derivatives.CustomVJPPrimal)  # noqa: E731
        values = jax.tree.map(lambda p: p.value, primals, is_leaf=is_p)
        flags = jax.tree.map(lambda p: bool(p.perturbed), primals, is_leaf=is_p)
        leaves, treedef = jax.tree.flatten(values)
        pert = [i for i, (leaf, fl) in enumerate(zip(leaves, jax.tree.leaves(flags))) if fl and _is_float(leaf)]
        state["pert"] = pert
        n_dirs = sum(int(np.prod(np.shape(leaves[i]))) for i in pert)

        def of_perturbed(*pl):
            full = list(leaves)
            for i, v in zip(pert, pl):
                full[i] = v
            c, cr, x = jax.tree.unflatten(treedef, full)
            return conv(cr, x, *c)

        pvals = [leaves[i] for i in pert]
        if 0 < n_dirs <= FORWARD_MAX:
            # one tangent per perturbed scalar, pushed alongside the primal (which is computed once)
            sizes = [int(np.prod(np.shape(v))) for v in pvals]
            eye = jnp.eye(n_dirs, dtype=jnp.result_type(*pvals))
            basis, off = [], 0
            for v, sz in zip(pvals, sizes):
                basis.append(eye[:, off : off + sz].reshape((n_dirs,) + np.shape(v)).astype(jnp.result_type(v)))
                off += sz
            # the primal does not depend on the tangent: out_axes=None keeps it computed once
            y, jac = jax.vmap(lambda *t: jax.jvp(of_perturbed, tuple(pvals), tuple(t)), out_axes=(None, 0))(*basis)
            state["kind"] = "forward"
            return y, (jac, pvals)
        y, vjp_fn = jax.vjp(of_perturbed, *pvals)
        state["kind"] = "reverse"
        return y, (vjp_fn, pvals)

    def bwd(res, cot):
        obj, pvals = res
        if state["kind"] == "forward":
            # d(loss)/d(input scalar j) = Σ_outputs cot · ∂out/∂input_j
            per_dir = None
            for c, jl in zip(jax.tree.leaves(cot, is_leaf=_is_zero), jax.tree.leaves(obj)):
                if _is_zero(c) or not _is_float(jl) or jnp.result_type(c) == jax.dtypes.float0:
                    continue
                term = jnp.sum(jnp.reshape(c * jl, (jl.shape[0], -1)), axis=1)
                per_dir = term if per_dir is None else per_dir + term
            grads, off = [], 0
            for v in pvals:
                sz = int(np.prod(np.shape(v)))
                g = jnp.zeros(np.shape(v), jnp.result_type(v)) if per_dir is None else per_dir[off : off + sz].reshape(np.shape(v))
                grads.append(g.astype(jnp.result_type(v)))
                off += sz
        else:
            grads = list(obj(jax.tree.map(_instantiate, cot, is_leaf=_is_zero)))
        return _scatter(grads)

    # bwd must return cotangents for (consts, carry, xs); perturbed leaves get theirs, the rest None
    leaves_all, treedef_all = jax.tree.flatten((consts, carry, xs))
    state = {}

    def _scatter(grads):
        pert = state["pert"]
        full = [None] * len(leaves_all)
        for i, g in zip(pert, grads):
            full[i] = g
        return jax.tree.unflatten(treedef_all, full)

    f.defvjp(fwd, bwd, symbolic_zeros=True)
    return f(consts, carry, xs)
