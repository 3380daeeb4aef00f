"""The time loop shared by every simulation: one ``lax.scan`` made fast on CPU and cheap to differentiate.

``run_loop(body, carry, xs, n)`` is ``lax.scan(body, carry, xs, length=n)`` with
six things done to it, none of which changes what it returns beyond
rounding (XLA may fuse the same arithmetic differently; tests/test_perf.py
checks each against the plain scan, to 1e-12 or tighter):

1. **Split state vectors.**  A component's state is a flat array (the rules
   work on flat arrays).  Under ``vmap`` it becomes (batch, n_states)
   and every step ends in ``jnp.stack``.  XLA's CPU loop fusion computes a
   concatenated output element by element, so every expression shared by the
   components of ẋ (the input's cos, the FLL's normalization) was evaluated
   once *per component*, and the stacked layout strides the batch.  The loop
   carries each small 1-D leaf as a tuple of scalars instead and restacks it
   inside the step, where XLA folds the stack/slice pair away; the step's
   outputs become separate fused outputs that share their subexpressions
   (docs/performance.md).
2. **Peel multistep start-ups.**  :class:`~jaxobs.core.discretize.AB3` starts with
   two RK4 steps behind a ``lax.cond`` on its sample count.  A conditional in
   the loop body costs a branch per step and blocks unrolling, so the loop runs
   the start-up steps on their own and then converts every rule state in the
   carry to its *steady* form (``rule_state.steady()``), whose step has no
   branch.
3. **Unroll.**  XLA's CPU while loop pays a fixed cost per iteration (several
   microseconds, the same order as a whole step over 512 scenarios), so the
   body is unrolled ``unroll`` times.
4. **Checkpoint** (only matters under reverse-mode AD), a strategy object that
   runs the loop itself (``strategy.loop(...)``, as diffrax's adjoints own theirs):

   - :class:`NoCheckpoint`: plain scan; the VJP stores every step's residuals
     (a 10 s gradient at batch 1024 needed gigabytes).
   - :class:`StepCheckpoint`: ``jax.checkpoint`` on the step; the VJP stores only the carry
     per step and recomputes the step once.
   - :class:`ChunkCheckpoint`: the horizon is cut into ⌈√n⌉-step chunks; the outer scan
     stores one carry per chunk, each chunk is recomputed once in the backward
     pass with its steps checkpointed, so memory is O(√n) carries.
   - :class:`ForwardSensitivity`: forward sensitivities.  The loop is a ``jax.custom_vjp``
     whose forward pass carries, beside the state, its derivative with respect
     to every *perturbed* input scalar (``symbolic_zeros``: a tuning job's few
     gains; the signal and scenario are not perturbed), so the backward pass
     is one small product and nothing is stored per step: O(1) memory in the
     horizon, and a gradient for about the price of one forward pass per
     tangent's linear part.  Exact (forward- and reverse-mode derivatives of the
     same program agree to rounding; tested).  Needs a loop without per-step
     outputs (``SaveFinal`` with a running cost; asking for it with per-step
     outputs is a ValueError) and at most ``max_scalars`` perturbed scalars;
     with more, its ``fallback`` reverse-mode strategy runs.
   - :class:`AutoCheckpoint` (the default): picks one of the above and hands it
     the loop: forward sensitivities when the loop has no per-step outputs (up to
     ``forward_max`` perturbed scalars), otherwise chunks above ``chunk_above``
     steps and per-step checkpoints below.

   The reverse-mode strategies differ only in how they scan the steps (their
   ``scan`` method); the split carry, the peeled start-up and the blocks of
   inputs are the same for all (:mod:`jaxobs.runtime._steps`).  The forward
   sensitivities' custom VJP is :mod:`jaxobs.runtime._sensitivity`.

   The directions are counted where the system's parameters enter, not at the
   loop's state: ``simulate`` passes the initial state as ``carry_fn``, built
   inside the sensitivity region, so a gain that also sets the initial state
   (an FLL's ω_n sets ω̂(0)) is one direction, not one per state component and
   AB3 history entry it reaches (six for the SOGI-FLL, which went past
   ``NESTED_MAX`` to the slower ``vmap`` form; docs/performance.md).

   With two or three perturbed scalars (a tuning job's gains) the tangents
   are pushed by nested JVPs with the mixed terms removed (:func:`jaxobs.runtime._sensitivity.multi_jvp`),
   each tangent an array of the primal's shape, which XLA fuses into the
   primal's kernels: value_and_grad costs about 2× the forward pass.
5. **Inputs a block at a time** (``xs_map``).  A signal evaluated inside the
   step let XLA's fusion recompute its ``cos`` in every
   kernel that read it — once per state component, per tangent, and across
   unrolled steps.  The loop instead evaluates the inputs of ``INPUT_BLOCK``
   steps at once (a chunk's, under :class:`ChunkCheckpoint`), vectorized, and runs those
   steps over the stored block: a loop boundary is a fusion boundary, so each
   input sample is computed once, and memory stays O(block × batch) rather
   than n samples of precomputed inputs, as fast as precomputed inputs
   (docs/performance.md).  A system may read a block at
   once instead (``OnSignal.input_block``: a recording on the loop's own sample
   grid is one contiguous slice per block, where a per-step read gathered a
   column of the batch per step).

6. **Inputs as scan rows** (``fill``).  A batch of recordings stored time-major
   (``SampledSignal(batch_inner=True)``, ``DriveRecording(batch_inner=True)``: leaves
   (n, B), row k holding every scenario's sample k) enters the loop as the
   scan's ``xs`` themselves, not as sample indices: ``lax.scan`` is the one
   operation whose batching keeps a batched input's batch axis where a time-major
   array has it (axis 1), so each step reads one contiguous (B,) row.  Every
   indexing operation (``dynamic_slice``, ``gather``) and every scan constant or
   carry moves the batch axis to the front instead: a transpose of the whole
   recording.  The peeled start-up (point 2) would need ``xs[2:]``, a copy of the
   whole horizon; instead the loop takes the start-up's two steps on their own,
   then ``fill(c0, c1, c2)`` (:func:`jaxobs.core.discretize.ab3_steady_from_start`)
   gives the carry at sample 0 a steady AB3 history under which the steady step
   repeats the start-up (to the rounding of x), and the steady loop runs every
   row, faster than the hand-written JAX scan of the rows and than the
   scenario-major block read (docs/performance.md).  The unroll over rows is
   ``OnRows.unroll`` (2).

A seventh rewrite was tried and deleted: evaluating the step's jaxpr with every small
state vector held as its elements (a ``SCALARIZE`` switch, off by default), so that
the optimized HLO had no stack and no recomputation of the stacked AB3 combination.
It gave the same numbers but ran *slower* (docs/performance.md),
and a drive step (~1600 equations) could not use it for its compile time.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import numpy as np

from ._sensitivity import sensitivity_loop
from ._steps import INPUT_BLOCK, Loop, block_size, run_steps, scan_blocks

__all__ = [
    "run_loop",
    "AbstractCheckpoint",
    "AbstractReverseCheckpoint",
    "NoCheckpoint",
    "StepCheckpoint",
    "ChunkCheckpoint",
    "ForwardSensitivity",
    "AutoCheckpoint",
]


# ---------------------------------------------------------------------------
# checkpoint strategies: each runs the loop (results are identical; memory and time differ)
# ---------------------------------------------------------------------------


class AbstractCheckpoint(eqx.Module):
    """How reverse-mode AD stores the time loop; every strategy gives the same numbers."""

    @abc.abstractmethod
    def loop(self, loop: Loop, carry: Any, xs: Any) -> tuple[Any, Any]:
        """Run a loop from ``loop.init(carry)`` over ``xs``.

        Args:
            loop: The :class:`jaxobs.runtime._steps.Loop`.
            carry: The initial carry.
            xs: The per-step inputs.

        Returns:
            ``(final carry, stacked per-step outputs or None)``.
        """


class AbstractReverseCheckpoint(AbstractCheckpoint):
    """A reverse-mode strategy: the VJP of the loop it runs stores what its ``scan`` keeps."""

    @property
    @abc.abstractmethod
    def startup(self) -> AbstractReverseCheckpoint:
        """The strategy for the few peeled start-up steps (jaxobs.runtime._loop, point 2): never chunked."""

    @abc.abstractmethod
    def scan(
        self,
        step: Callable[[Any, Any], tuple[Any, Any]],
        carry: Any,
        xs: Any,
        n: int,
        unroll: int,
        xs_map: Callable[[Any], Any] | None = None,
    ) -> tuple[Any, Any]:
        """Scan ``step`` over ``xs``.

        Args:
            step: ``step(carry, x) -> (carry, out)``.
            carry: The initial carry.
            xs: The per-step inputs.
            n: The steps (≥ 1).
            unroll: The loop's unrolling.
            xs_map: With it each step sees ``xs_map`` of a block of ``xs`` (jaxobs.runtime._loop, point 5).

        Returns:
            ``(final carry, stacked outputs)``, as ``lax.scan``.
        """

    def loop(self, loop: Loop, carry: Any, xs: Any) -> tuple[Any, Any]:
        return run_steps(loop, self, loop.init(carry), xs)


class NoCheckpoint(AbstractReverseCheckpoint):
    """Plain ``lax.scan``: the VJP stores every step's residuals (fast for short loops, memory-hungry)."""

    @property
    def startup(self) -> AbstractReverseCheckpoint:
        """The strategy for the peeled start-up steps: this one."""
        return self

    def scan(
        self,
        step: Callable[[Any, Any], tuple[Any, Any]],
        carry: Any,
        xs: Any,
        n: int,
        unroll: int,
        xs_map: Callable[[Any], Any] | None = None,
    ) -> tuple[Any, Any]:
        """Scan ``step`` over ``xs`` (the abstract method's contract).

        Args:
            step: ``step(carry, x) -> (carry, out)``.
            carry: The initial carry.
            xs: The per-step inputs.
            n: The steps (≥ 1).
            unroll: The loop's unrolling.
            xs_map: With it each step sees ``xs_map`` of a block of ``xs`` (jaxobs.runtime._loop, point 5).

        Returns:
            ``(final carry, stacked outputs)``, as ``lax.scan``.
        """
        if xs_map is None:
            return jax.lax.scan(step, carry, xs, length=n, unroll=min(unroll, n))
        return scan_blocks(step, carry, xs, n, block_size(n, INPUT_BLOCK, unroll), unroll, xs_map)


class StepCheckpoint(AbstractReverseCheckpoint):
    """``jax.checkpoint`` on each step: the VJP stores one carry per step and recomputes the step once."""

    @property
    def startup(self) -> AbstractReverseCheckpoint:
        """The strategy for the peeled start-up steps: this one."""
        return self

    def scan(
        self,
        step: Callable[[Any, Any], tuple[Any, Any]],
        carry: Any,
        xs: Any,
        n: int,
        unroll: int,
        xs_map: Callable[[Any], Any] | None = None,
    ) -> tuple[Any, Any]:
        """Scan ``step`` over ``xs`` (the abstract method's contract).

        Args:
            step: ``step(carry, x) -> (carry, out)``.
            carry: The initial carry.
            xs: The per-step inputs.
            n: The steps (≥ 1).
            unroll: The loop's unrolling.
            xs_map: With it each step sees ``xs_map`` of a block of ``xs`` (jaxobs.runtime._loop, point 5).

        Returns:
            ``(final carry, stacked outputs)``, as ``lax.scan``.
        """
        # NoCheckpoint's loop over the checkpointed step
        return NoCheckpoint().scan(jax.checkpoint(step, prevent_cse=False), carry, xs, n, unroll, xs_map)


class ChunkCheckpoint(AbstractReverseCheckpoint):
    """About √n-step chunks: one carry stored per chunk, each chunk recomputed once (O(√n) memory)."""

    @property
    def startup(self) -> AbstractReverseCheckpoint:
        """The strategy for the peeled start-up steps: :class:`StepCheckpoint` (never chunked)."""
        return StepCheckpoint()

    def scan(
        self,
        step: Callable[[Any, Any], tuple[Any, Any]],
        carry: Any,
        xs: Any,
        n: int,
        unroll: int,
        xs_map: Callable[[Any], Any] | None = None,
    ) -> tuple[Any, Any]:
        """Scan ``step`` over ``xs`` (the abstract method's contract).

        Args:
            step: ``step(carry, x) -> (carry, out)``.
            carry: The initial carry.
            xs: The per-step inputs.
            n: The steps (≥ 1).
            unroll: The loop's unrolling.
            xs_map: With it each step sees ``xs_map`` of a block of ``xs`` (jaxobs.runtime._loop, point 5).

        Returns:
            ``(final carry, stacked outputs)``, as ``lax.scan``.
        """
        step = jax.checkpoint(step, prevent_cse=False)
        size = block_size(n, max(1, math.isqrt(n - 1) + 1), unroll)  # about √n steps per chunk
        return scan_blocks(step, carry, xs, n, size, unroll, xs_map, checkpoint_blocks=True)


class ForwardSensitivity(AbstractCheckpoint):
    """Forward sensitivities behind a custom VJP: O(1) memory, for loops without per-step outputs.

    The gradient costs about one forward pass per perturbed scalar's tangent;
    with more than ``max_scalars`` perturbed scalars the ``fallback`` strategy
    (reverse mode) runs instead.

    Attributes:
        max_scalars: The most perturbed scalars served by forward sensitivities (an integer ≥ 1; static).
        fallback: The reverse-mode strategy (:class:`NoCheckpoint`, :class:`StepCheckpoint`,
            :class:`ChunkCheckpoint`) run with more perturbed scalars (static).

    Raises:
        ValueError: ``max_scalars`` or ``fallback`` is out of range; or, when run, the loop has
            per-step outputs (use ``save=SaveFinal(cost)``).
    """

    max_scalars: int = eqx.field(static=True, default=8)
    fallback: AbstractReverseCheckpoint = eqx.field(static=True, default=ChunkCheckpoint())

    def __check_init__(self):
        if isinstance(self.max_scalars, bool) or not isinstance(self.max_scalars, int) or self.max_scalars < 1:
            raise ValueError(f"ForwardSensitivity.max_scalars must be an integer >= 1, got {self.max_scalars!r}")
        if not isinstance(self.fallback, AbstractReverseCheckpoint):
            raise ValueError(
                "ForwardSensitivity.fallback must be a reverse-mode strategy (NoCheckpoint, StepCheckpoint, "
                f"ChunkCheckpoint), got {self.fallback!r}"
            )

    def loop(self, loop: Loop, carry: Any, xs: Any) -> tuple[Any, Any]:
        """Run a loop from ``loop.init(carry)`` over ``xs``.

        Args:
            loop: The :class:`jaxobs.runtime._steps.Loop`.
            carry: The initial carry.
            xs: The per-step inputs.

        Returns:
            ``(final carry, stacked per-step outputs or None)``.

        Raises:
            ValueError: The loop has per-step outputs (use ``save=SaveFinal(cost)``).
        """
        if loop.has_outputs:
            raise ValueError(
                "ForwardSensitivity serves loops without per-step outputs: use save=SaveFinal(cost) "
                "(or another checkpoint strategy with SaveAll)"
            )
        # The loop's closed-over arrays (the system's parameters, with carry_fn the initial state's too)
        # become explicit inputs, so that the custom VJP sees which of them are perturbed.
        conv, consts = jax.closure_convert(lambda c, x: self.fallback.loop(loop, c, x), carry, xs)
        return sensitivity_loop(conv, self.max_scalars, consts, carry, xs)


class AutoCheckpoint(AbstractCheckpoint):
    """The default: forward sensitivities for a loop without per-step outputs and at most ``forward_max``
    perturbed scalars; otherwise chunks above ``chunk_above`` steps and per-step checkpoints below.

    Below ``chunk_above`` per-step checkpointing keeps the carries of every step
    (n × carry), which for 1 s at 10 kHz and batch 1024 is a few tens of MB —
    cheap, and a little faster than chunks.

    Attributes:
        chunk_above: Steps above which :class:`ChunkCheckpoint` replaces :class:`StepCheckpoint`
            (an integer ≥ 0; static).
        forward_max: The most perturbed scalars served by :class:`ForwardSensitivity`
            (an integer ≥ 0, 0: never; static).
    """

    chunk_above: int = eqx.field(static=True, default=20_000)
    forward_max: int = eqx.field(static=True, default=8)

    def __check_init__(self):
        for name, v in (("chunk_above", self.chunk_above), ("forward_max", self.forward_max)):
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"AutoCheckpoint.{name} must be an integer >= 0, got {v!r}")

    def pick(self, loop: Loop) -> AbstractCheckpoint:
        """The strategy a loop runs under.

        Args:
            loop: The :class:`jaxobs.runtime._steps.Loop`.

        Returns:
            The :class:`AbstractCheckpoint`.
        """
        reverse = ChunkCheckpoint() if loop.n > self.chunk_above else StepCheckpoint()
        if loop.has_outputs or self.forward_max == 0:
            return reverse
        return ForwardSensitivity(max_scalars=self.forward_max, fallback=reverse)

    def loop(self, loop: Loop, carry: Any, xs: Any) -> tuple[Any, Any]:
        return self.pick(loop).loop(loop, carry, xs)


def check_checkpoint(checkpoint: object) -> AbstractCheckpoint:
    """Check that ``checkpoint`` is a checkpoint strategy.

    Args:
        checkpoint: The value given as ``checkpoint``.

    Returns:
        ``checkpoint`` itself.

    Raises:
        ValueError: It is not an :class:`AbstractCheckpoint`.
    """
    if not isinstance(checkpoint, AbstractCheckpoint):
        raise ValueError(
            "checkpoint must be a checkpoint strategy (jaxobs.AutoCheckpoint(), NoCheckpoint(), StepCheckpoint(), "
            f"ChunkCheckpoint(), ForwardSensitivity()), got {checkpoint!r}"
        )
    return checkpoint


def check_unroll(unroll: object) -> int:
    """Check that ``unroll`` is an integer ≥ 1.

    Args:
        unroll: The value given as ``unroll``.

    Returns:
        It as a Python ``int``.

    Raises:
        ValueError: It is not an integer ≥ 1 (``bool`` included).
    """
    if isinstance(unroll, bool) or not isinstance(unroll, (int, np.integer)) or unroll < 1:
        raise ValueError(f"unroll must be an integer >= 1, got {unroll!r}")
    return int(unroll)


# ---------------------------------------------------------------------------
# the loop
# ---------------------------------------------------------------------------


def run_loop(
    body: Callable[[Any, Any], tuple[Any, Any]],
    carry: Any,
    xs: Any,
    n: int,
    *,
    unroll: int = 1,
    checkpoint: AbstractCheckpoint = AutoCheckpoint(),
    split: bool = True,
    xs_map: Callable[[Any], Any] | None = None,
    peel: bool = True,
    carry_fn: Callable[[], Any] | None = None,
    fill: Callable[[Any, Any, Any], Any] | None = None,
) -> tuple[Any, Any]:
    """``lax.scan(body, carry, xs, length=n)``, made fast and cheap to differentiate (module doc).

    Args:
        body: ``body(carry, x) -> (carry, y)``; it sees the carry exactly as given (state vectors as arrays).
        carry: The initial carry, or ``None`` with ``carry_fn``.
        xs: The per-step inputs (leading axis ``n``), or ``None``.
        n: The steps.
        unroll: The loop's unrolling (module doc, point 3).
        checkpoint: The strategy that runs the loop (module doc, point 4).
        split: Whether to carry state vectors split (module doc, point 1).
        xs_map: With it the body sees ``xs_map(xs)[k]`` at step k instead of ``xs[k]``, where ``xs_map`` maps
            a block of steps' ``xs`` (leading axis the block) to their inputs (leading axis the block) and is
            evaluated a block at a time (module doc, point 5): the simulations pass sample indices and the
            signal as ``xs_map``.
        peel: Whether to peel multistep start-ups (module doc, point 2).
        carry_fn: Instead of ``carry`` (pass ``None``), a function of no arguments that builds the initial
            carry; it is called inside the forward-sensitivity region, so a parameter that sets the initial
            state (an FLL's ω_n) is one perturbed scalar there, not every state component it reaches (module
            doc, point 4).
        fill: With ``xs`` the per-step inputs themselves (no ``xs_map``), the loop does not slice them for its
            peeled start-up: ``fill(c0, c1, c2)`` turns the carries before and after the start-up's two steps
            into a steady carry at step 0 whose steps repeat them (module doc, point 6;
            :func:`jaxobs.core.discretize.ab3_steady_from_start`), and the steady loop runs every row.

    Returns:
        ``(final carry, stacked per-step outputs or None)``.

    Raises:
        ValueError: Both or neither of ``carry`` and ``carry_fn``, ``xs_map`` without ``xs``, or an invalid
            ``unroll`` or ``checkpoint``.
    """
    unroll = check_unroll(unroll)
    checkpoint = check_checkpoint(checkpoint)
    if (carry is None) == (carry_fn is None):
        raise ValueError("run_loop: give either carry or carry_fn (a function building the initial carry)")
    if xs_map is not None and xs is None:
        raise ValueError("run_loop: xs_map needs xs (the per-step values it maps)")
    # one Python trace of the step: whether the loop has per-step outputs (forward sensitivities need none)
    if xs is None:
        x_one = None
    else:
        first = jax.tree.map(lambda a: a[:1], xs)
        x_one = jax.tree.map(lambda a: a[0], first if xs_map is None else xs_map(first))
    carry_shape = carry if carry_fn is None else jax.eval_shape(carry_fn)  # one of the two is given
    has_outputs = bool(jax.tree.leaves(jax.eval_shape(body, carry_shape, x_one)[1]))
    if carry_fn is not None:
        # the initial carry is built inside the strategy's loop: what it closes over (the system's
        # parameters) becomes the perturbed inputs of the forward sensitivities
        build = carry_fn
        init, carry = (lambda _: build()), ()
    else:
        init = lambda c: c  # noqa: E731
    loop = Loop(body, init, n, unroll, split, xs_map, peel, has_outputs, fill)
    return checkpoint.loop(loop, carry, xs)
