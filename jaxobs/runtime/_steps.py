"""The steps of the one time loop: split state vectors, peeled start-ups, inputs a block at a time.

The machinery behind :func:`jaxobs.runtime._loop.run_loop` (its module doc gives the reasons and the
measurements, points 1, 2 and 5).  What a checkpoint strategy decides — how reverse-mode AD stores
the steps — is the strategy's own ``scan`` method (:mod:`jaxobs.runtime._loop`); :func:`run_steps` calls it
for the peeled start-up and for the rest, and :func:`scan_blocks` is the blocked scan the strategies
share.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple, Protocol

import jax
import jax.numpy as jnp

from ..core.discretize import AbstractMultistepState

__all__ = [
    "Loop",
    "run_steps",
    "scan_blocks",
    "block_size",
    "startup_steps",
    "to_steady",
    "to_started",
    "INPUT_BLOCK",
]

# With ``xs_map``, the inputs of this many steps are evaluated together (jaxobs.runtime._loop, point 5).
INPUT_BLOCK = 128

_SPLIT_MAX = 64  # 1-D leaves up to this size are carried as tuples of scalars


class Loop(NamedTuple):
    """One call of :func:`jaxobs.runtime._loop.run_loop`: what every strategy's ``loop`` is given.

    Attributes:
        body: ``body(carry, x) -> (carry, y)``.
        init: ``init(carry)`` builds the initial carry from the loop's carry argument (the carry itself, or —
            with ``run_loop(carry_fn=...)`` — a function of nothing, called inside the strategy's loop:
            jaxobs.runtime._loop, point 4).
        n: The steps.
        unroll: The loop's unrolling.
        split: Whether state vectors are carried split (jaxobs.runtime._loop, point 1).
        xs_map: Maps a block of ``xs`` to the steps' inputs, or ``None``.
        peel: Whether multistep start-ups are peeled (jaxobs.runtime._loop, point 2).
        has_outputs: The body returns per-step outputs (not ``None``).
        fill: The start-up steps' carries ``(c0, c1, c2)`` to a steady carry at step 0 (jaxobs.runtime._loop, point 6),
            or ``None``.
    """

    body: Callable[[Any, Any], tuple[Any, Any]]
    init: Callable[[Any], Any]
    n: int
    unroll: int
    split: bool
    xs_map: Callable[[Any], Any] | None
    peel: bool
    has_outputs: bool
    fill: Callable[[Any, Any, Any], Any] | None = None


class _ReverseStrategy(Protocol):
    """What :func:`run_steps` asks of a reverse-mode strategy (a ``_loop.AbstractReverseCheckpoint``).

    The protocol keeps this module below :mod:`jaxobs.runtime._loop`, which defines the strategies.
    """

    @property
    def startup(self) -> _ReverseStrategy: ...

    def scan(
        self,
        step: Callable[[Any, Any], tuple[Any, Any]],
        carry: Any,
        xs: Any,
        n: int,
        unroll: int,
        xs_map: Callable[[Any], Any] | None = None,
    ) -> tuple[Any, Any]: ...


# ---------------------------------------------------------------------------
# split state vectors (point 1)
# ---------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------
# multistep start-ups peeled (point 2)
# ---------------------------------------------------------------------------


def _has_steady(x):
    return isinstance(x, AbstractMultistepState)


def startup_steps(carry: Any) -> int:
    """How many leading steps must run before every rule state in a carry can go steady.

    Args:
        carry: The loop's carry.

    Returns:
        The steps (0 without multistep states).
    """
    states = [s for s in jax.tree.leaves(carry, is_leaf=_has_steady) if _has_steady(s)]
    return max((s.startup_steps for s in states), default=0)


def to_steady(carry: Any) -> Any:
    """Every multistep rule state in a carry in its steady form (its step without the start-up branch).

    Args:
        carry: The loop's carry, its start-up steps taken.

    Returns:
        The carry with each :class:`jaxobs.core.discretize.AbstractMultistepState` replaced by ``steady()``.
    """
    return jax.tree.map(lambda s: s.steady() if _has_steady(s) else s, carry, is_leaf=_has_steady)


def to_started(carry: Any) -> Any:
    """Undo :func:`to_steady`: the carry a plain scan of the step would end with.

    Args:
        carry: The loop's carry, its multistep states steady.

    Returns:
        The carry with each steady multistep state replaced by ``started()``.
    """
    return jax.tree.map(lambda s: s.started() if _has_steady(s) else s, carry, is_leaf=_has_steady)


def run_steps(loop: Loop, strategy: _ReverseStrategy, carry: Any, xs: Any) -> tuple[Any, Any]:
    """The ``loop.n`` steps from ``carry`` (already built: ``loop.init`` applied), stored for reverse-mode
    AD as ``strategy`` says: its ``scan(step, carry, xs, n, unroll, xs_map)`` runs the steps, and the
    start-up steps peeled off run under ``strategy.startup`` (a few steps: never chunked), not unrolled.

    Args:
        loop: The :class:`Loop`.
        strategy: The reverse-mode strategy (:class:`jaxobs.runtime._loop.AbstractReverseCheckpoint`).
        carry: The initial carry.
        xs: The per-step inputs.

    Returns:
        ``(final carry, stacked per-step outputs or None)``.
    """
    body, n, xs_map = loop.body, loop.n, loop.xs_map
    inner: Callable[[Any, Any], tuple[Any, Any]]
    if loop.split:

        def split_body(c: Any, x: Any) -> tuple[Any, Any]:
            c, y = body(_join(c), x)
            return _split(c), y

        inner, wrap, unwrap = split_body, _split, _join
    else:
        inner, wrap, unwrap = body, (lambda c: c), (lambda c: c)

    def scan(strat, c, xs_part, m, unroll):
        if m == 0:
            return c, None
        return strat.scan(inner, c, xs_part, m, unroll, xs_map)

    p = min(startup_steps(carry), n) if loop.peel else 0
    if p == 2 and n > p and loop.fill is not None and xs is not None and xs_map is None:
        # inputs as scan rows (point 6): the start-up's steps taken on their own, then the steady loop over
        # every row from sample 0, its history filled so that its first steps repeat the start-up's
        cs = [carry]
        for k in range(p):
            cs.append(body(cs[-1], jax.tree.map(lambda a, k=k: a[k], xs))[0])
        steady = loop.fill(*cs)
        if steady is not None:
            c, ys = scan(strategy, wrap(steady), xs, n, loop.unroll)
            return to_started(unwrap(c)), ys
    ys_head = None
    if p:
        head = None if xs is None else jax.tree.map(lambda a: a[:p], xs)
        c, ys_head = scan(strategy.startup, wrap(carry), head, p, 1)
        carry = unwrap(c)
    if loop.peel:
        carry = to_steady(carry)
    rest = None if xs is None else jax.tree.map(lambda a: a[p:], xs)
    c, ys = scan(strategy, wrap(carry), rest, n - p, loop.unroll)
    carry = unwrap(c)
    if loop.peel:
        carry = to_started(carry)
    if ys_head is not None:
        ys = ys_head if ys is None else jax.tree.map(lambda a, b: jnp.concatenate([a, b]), ys_head, ys)
    return carry, ys


# ---------------------------------------------------------------------------
# blocks of steps: inputs a block at a time (point 5), chunks of checkpointed steps
# ---------------------------------------------------------------------------


def scan_blocks(
    step: Callable[[Any, Any], tuple[Any, Any]],
    carry: Any,
    xs: Any,
    n: int,
    size: int,
    unroll: int,
    xs_map: Callable[[Any], Any] | None = None,
    checkpoint_blocks: bool = False,
) -> tuple[Any, Any]:
    """``n`` (>= 1) steps of ``step`` as an outer scan over blocks of ``size`` steps (a divisor of n when
    :func:`block_size` found one; the remainder then runs after, not unrolled).

    With ``xs_map``, each block's steps see ``xs_map(block of xs)``: the inputs of a block are evaluated
    together, vectorized, before its steps run.  ``checkpoint_blocks``: each block under
    ``jax.checkpoint`` (the outer scan stores one carry per block, and the backward pass recomputes each
    block once).

    Args:
        step: ``step(carry, x) -> (carry, out)``.
        carry: The initial carry.
        xs: The per-step inputs.
        n: The steps (≥ 1).
        size: Steps per block.
        unroll: The inner loop's unrolling.
        xs_map: Maps a block of ``xs`` to its steps' inputs, or ``None``.
        checkpoint_blocks: Whether each block runs under ``jax.checkpoint``.

    Returns:
        ``(final carry, stacked outputs)``, as ``lax.scan``.
    """
    xs_map = (lambda x: x) if xs_map is None else xs_map
    q, r = divmod(n, size)

    def block(c, xs_c):
        return jax.lax.scan(step, c, xs_map(xs_c), length=size, unroll=min(unroll, size))

    if checkpoint_blocks:
        block = jax.checkpoint(block, prevent_cse=False)
    if q == 1:
        carry, ys = block(carry, jax.tree.map(lambda a: a[:size], xs))
    else:
        head = jax.tree.map(lambda a: a[: q * size].reshape((q, size) + a.shape[1:]), xs)
        carry, ys = jax.lax.scan(block, carry, head, length=q)
        ys = jax.tree.map(lambda a: a.reshape((q * size,) + a.shape[2:]), ys)
    if r:
        # the remainder, not unrolled (one more copy of the step to compile)
        tail = jax.tree.map(lambda a: a[q * size :], xs)
        carry, ys_t = jax.lax.scan(step, carry, xs_map(tail), length=r)
        ys = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), ys, ys_t)
    return carry, ys


MAX_BLOCK_SEARCH = 1 << 16  # the divisor search of block_size looks at no more than 3·2^15 sizes


def block_size(n: int, target: int, unroll: int) -> int:
    """Steps per block: ``n`` itself when short, else a divisor of ``n`` near ``target``.

    A block size that divides the horizon needs no remainder loop, and one that
    is a multiple of ``unroll`` no remainder inside each block: every extra copy
    of the step costs compile time (a drive step takes seconds to compile).
    Without such a divisor (within a factor 2 of ``target``), ``target``
    rounded to a multiple of ``unroll``; the remainder then runs without unrolling.

    Args:
        n: The steps.
        target: The preferred block size.
        unroll: The loop's unrolling.

    Returns:
        The block size.
    """
    if n <= 2 * target:
        return n
    if target > MAX_BLOCK_SEARCH:  # bounded work whatever n (simulate caps n below 2^31: target < 46 341)
        return max(unroll, target // unroll * unroll)
    best = None
    for d in range(max(1, target // 2), 2 * target + 1):
        if n % d == 0 and d % unroll == 0 and (best is None or abs(d - target) < abs(best - target)):
            best = d
    return max(unroll, target // unroll * unroll) if best is None else best
