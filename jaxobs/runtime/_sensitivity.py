"""Forward sensitivities behind a custom VJP: the loop of :class:`jaxobs.ForwardSensitivity`.

The loop is a ``jax.custom_vjp`` whose forward pass carries, beside the state, its derivative with
respect to every *perturbed* input scalar (``symbolic_zeros``: a tuning job's few gains; the signal
and scenario are not perturbed), so the backward pass is one small product and nothing is stored per
step (jaxobs.runtime._loop, point 4, gives the measurements).

Forward and backward share nothing mutable: what the backward pass needs to know about the forward
one (which inputs were perturbed, and whether the tangents were pushed forward or a reverse-mode VJP
was taken instead) travels in the residuals, as the static fields of :class:`_Forward` /
:class:`_Reverse` (part of the residuals' tree structure), and the loop itself is a non-differentiable
argument of the custom VJP.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["sensitivity_loop", "multi_jvp", "NESTED_MAX"]

# Up to this many perturbed scalars the tangents are pushed by nested JVPs
# (each its own array; see multi_jvp), above it by vmap over the directions.
# Tracing the nested form costs 2**d copies of the loop before dead-code
# elimination, so it stays small.
NESTED_MAX = 3


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


class _Forward(eqx.Module):
    """Residuals of the forward-sensitivity pass: ∂(outputs)/∂(each perturbed scalar)."""

    jac: Any  # the loop's outputs, each leaf with the directions as its leading axis
    pvals: list  # the perturbed inputs' values
    pert: tuple[int, ...] = eqx.field(static=True)  # their positions among the flattened (consts, carry, xs)
    n_leaves: int = eqx.field(static=True)  # how many leaves (consts, carry, xs) has
    treedef: Any = eqx.field(static=True)  # and its structure


class _Reverse(eqx.Module):
    """Residuals when there were too many (or no) perturbed scalars: reverse mode's VJP of the loop."""

    vjp_fn: Any
    pvals: list
    pert: tuple[int, ...] = eqx.field(static=True)
    n_leaves: int = eqx.field(static=True)
    treedef: Any = eqx.field(static=True)


def sensitivity_loop(
    conv: Callable[..., tuple[Any, Any]], max_scalars: int, consts: Sequence[Any], carry: Any, xs: Any
) -> tuple[Any, Any]:
    """A closure-converted loop whose reverse-mode derivative is computed by forward sensitivities.

    Args:
        conv: ``conv(carry, xs, *consts)``, the closure-converted loop.
        max_scalars: The most perturbed input scalars served by forward sensitivities (else reverse mode
            through ``conv``).
        consts: The loop's closed-over arrays.
        carry: The initial carry.
        xs: The per-step inputs.

    Returns:
        ``conv(carry, xs, *consts)``.
    """
    return _loop(conv, max_scalars, consts, carry, xs)


@functools.partial(jax.custom_vjp, nondiff_argnums=(0, 1))
def _loop(conv, max_scalars, consts, carry, xs):
    return conv(carry, xs, *consts)


def _loop_fwd(conv, max_scalars, consts, carry, xs):
    primals = (consts, carry, xs)
    is_p = lambda p: isinstance(p, jax.custom_derivatives.CustomVJPPrimal)  # noqa: E731
    values = jax.tree.map(lambda p: p.value, primals, is_leaf=is_p)
    flags = jax.tree.map(lambda p: bool(p.perturbed), primals, is_leaf=is_p)
    leaves, treedef = jax.tree.flatten(values)
    pert = tuple(i for i, (leaf, fl) in enumerate(zip(leaves, jax.tree.leaves(flags))) if fl and _is_float(leaf))
    n_dirs = sum(int(np.prod(np.shape(leaves[i]))) for i in pert)

    def of_perturbed(*pl):
        full = list(leaves)
        for i, v in zip(pert, pl):
            full[i] = v
        c, cr, x = jax.tree.unflatten(treedef, full)
        return conv(cr, x, *c)

    pvals = [leaves[i] for i in pert]
    if 0 < n_dirs <= max_scalars:
        # one tangent per perturbed scalar, pushed alongside the primal (which is computed once)
        sizes = [int(np.prod(np.shape(v))) for v in pvals]
        eye = jnp.eye(n_dirs, dtype=jnp.result_type(*pvals))
        basis, off = [], 0
        for v, sz in zip(pvals, sizes):
            basis.append(eye[:, off : off + sz].reshape((n_dirs,) + np.shape(v)).astype(jnp.result_type(v)))
            off += sz
        y, jac = multi_jvp(of_perturbed, tuple(pvals), basis)
        return y, _Forward(jac, pvals, pert, len(leaves), treedef)
    y, vjp_fn = jax.vjp(of_perturbed, *pvals)
    return y, _Reverse(vjp_fn, pvals, pert, len(leaves), treedef)


def _loop_bwd(conv, max_scalars, res, cot):
    if isinstance(res, _Forward):
        # d(loss)/d(input scalar j) = Σ_outputs cot · ∂out/∂input_j
        per_dir = None
        for c, jl in zip(jax.tree.leaves(cot, is_leaf=_is_zero), jax.tree.leaves(res.jac)):
            if _is_zero(c) or not _is_float(jl) or jnp.result_type(c) == jax.dtypes.float0:
                continue
            term = jnp.sum(jnp.reshape(c * jl, (jl.shape[0], -1)), axis=1)
            per_dir = term if per_dir is None else per_dir + term
        grads, off = [], 0
        for v in res.pvals:
            sz = int(np.prod(np.shape(v)))
            g = (
                jnp.zeros(np.shape(v), jnp.result_type(v))
                if per_dir is None
                else per_dir[off : off + sz].reshape(np.shape(v))
            )
            grads.append(g.astype(jnp.result_type(v)))
            off += sz
    else:
        grads = list(res.vjp_fn(jax.tree.map(_instantiate, cot, is_leaf=_is_zero)))
    # cotangents for (consts, carry, xs): the perturbed leaves get theirs, the rest None
    full = [None] * res.n_leaves
    for i, g in zip(res.pert, grads):
        full[i] = g
    return jax.tree.unflatten(res.treedef, full)


_loop.defvjp(_loop_fwd, _loop_bwd, symbolic_zeros=True)


def multi_jvp(fun: Callable[..., Any], primals: tuple[Any, ...], basis: Sequence[jax.Array]) -> tuple[Any, Any]:
    """``fun(*primals)`` and its JVPs along each direction of ``basis``, in one pass.

    Up to ``NESTED_MAX`` directions, by nested ``jax.jvp`` — the tangent along
    direction k is the k-th level's tangent of the primal — with every mixed
    higher-order term removed by dead-code elimination before anything is
    evaluated.  Each tangent is then its own array of the primal's shape, so
    XLA fuses the tangent arithmetic into the primal's kernels.  ``vmap`` over
    the directions gives the same numbers but (batch, directions)-shaped
    tangents beside (batch,)-shaped primals, which XLA's CPU fusion keeps in
    separate kernels, slower than the nested form (docs/performance.md).

    Args:
        fun: The function.
        primals: Its arguments.
        basis: One array per primal, its leading axis the directions.

    Returns:
        ``(y, jac)``, each leaf of ``jac`` with the directions as its leading axis.
    """
    n_dirs = int(np.shape(basis[0])[0])
    if 1 <= n_dirs <= NESTED_MAX:
        F = fun
        for d in range(n_dirs):
            e = tuple(b[d] for b in basis)
            F = (lambda F, e: lambda *p: jax.jvp(F, p, e))(F, e)

        def first_order(out):
            """(y, [t_1 .. t_d]) of the nested output: level j's output is (out_{j-1}, tangent of out_{j-1})."""
            y = out
            for _ in range(n_dirs):
                y = y[0]
            tans = []
            for k in range(1, n_dirs + 1):
                o = out
                for _ in range(n_dirs - k):
                    o = o[0]  # the primal part of the outer levels
                o = o[1]  # level k's tangent
                for _ in range(k - 1):
                    o = o[0]  # of the primal part of the inner levels
                tans.append(o)
            return y, tans

        # Only the first-order terms leave this jit: JAX's dead-code elimination
        # at lowering (its scan rule drops loop-carried values nothing reads)
        # removes every mixed higher-order tangent before XLA sees the loop.
        y, tans = jax.jit(lambda *p: first_order(F(*p)))(*primals)
        return y, jax.tree.map(lambda *t: jnp.stack(t), *tans)
    # the primal does not depend on the tangent: out_axes=None keeps it computed once
    return jax.vmap(lambda *t: jax.jvp(fun, primals, t), out_axes=(None, 0))(*basis)
