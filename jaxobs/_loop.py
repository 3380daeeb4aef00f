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
   - ``"auto"`` (default): ``"chunk"`` above ``CHUNK_ABOVE`` steps, else ``"step"``.
"""

from __future__ import annotations

import math
import os as _os
from collections.abc import Callable
from typing import Any, Literal

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["run_loop", "Checkpoint", "CHUNK_ABOVE", "resolve_checkpoint"]

Checkpoint = Literal["auto", "none", "step", "chunk"]
CHECKPOINTS = ("auto", "none", "step", "chunk")

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
    checkpoint = check_checkpoint(checkpoint)
    if checkpoint == "auto":
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

    if split:

        def inner(c, x):
            c, y = body(_join(c), x)
            if _os.environ.get("JAXOBS_BARRIER") == "1":
                c, y = jax.lax.optimization_barrier((c, y))
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
