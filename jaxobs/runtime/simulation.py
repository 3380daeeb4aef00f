"""The one time loop: ``jaxobs.simulate(system, t1)`` runs any *system*.

A system is an ``equinox.Module`` with a sample time ``ts`` and two pure methods::

    state = system.init()
    state, out = system.step(state, k)      # k: the sample index (int32 scalar)

so that a user's own scan gives exactly what ``simulate`` returns::

    _, outs = jax.lax.scan(system.step, system.init(), jnp.arange(n))
    outs == jaxobs.simulate(system, t0 + n * ts).outputs       # tested, element for element

Two systems ship with jaxobs: :class:`OnSignal` (an observer fed a test signal
or a recording, :mod:`jaxobs.runtime.onsignal`) and :class:`jaxobs.drive.ClosedLoop` (the PMSM drive, with an
observer or the encoder).  What else the loop reads of a system is declared by
:class:`~jaxobs.AbstractSystem` with defaults (``t0``, ``unroll``,
``check_horizon``, ``loop_inputs``, ``throughput``).  :class:`OnSignal` feeds its
inputs a block of steps at a time, vectorized (:mod:`jaxobs.runtime._loop`, point 5),
which is what makes long horizons fast on CPU; on a time-major recording batch
its throughput loop runs as :class:`OnRows`, whose inputs are the batch's rows
(point 6).

What to keep and how reverse-mode AD stores the loop are strategy objects,
as diffrax passes ``SaveAt`` and adjoints: :class:`SaveAll` / :class:`SaveFinal`
(each with an optional running cost), each running the loop it needs
(``save.run``), and the checkpoint strategies of :mod:`jaxobs.runtime._loop`
(:class:`AutoCheckpoint` by default).  ``simulate`` is a
``filter_jit``-ed function of PyTrees: ``jax.vmap`` over a batch of systems
(scenarios, gains) and ``jax.grad`` through it apply unchanged.  Gains stay
leaves of the system.

A simulation that diverges is reported by ``sol.ok`` (per scenario under
``vmap``), not raised, unless ``throw=True``.
"""

from __future__ import annotations

import abc
import os
import warnings
from collections.abc import Callable
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..core.system import AbstractSystem, LoopInputs
from ..core.validate import check_sample_time
from ..observers import AbstractObserver
from ._loop import AbstractCheckpoint, AutoCheckpoint, check_unroll, run_loop
from .onsignal import OnRows as OnRows
from .onsignal import OnSignal as OnSignal
from .onsignal import SignalOutput as SignalOutput
from .onsignal import SignalTruth as SignalTruth

__all__ = [
    "simulate",
    "Solution",
    "AbstractSave",
    "SaveAll",
    "SaveFinal",
    "OnSignal",
    "OnRows",
    "SignalTruth",
    "SignalOutput",
    "n_samples",
    "PrecisionWarning",
]


class PrecisionWarning(UserWarning):
    """jaxobs is running in float32 (x64 disabled): see README, "float32 vs float64"."""


_warned_float32 = False


def _warn_float32():
    """Once per process: the library runs in float32 because the caller did not enable x64."""
    global _warned_float32
    if _warned_float32 or jnp.result_type(float) != jnp.float32:
        return
    _warned_float32 = True
    warnings.warn(
        "jaxobs is running in float32 (jax_enable_x64 is off). Signal phases stay exact at any horizon, but "
        "observer states, metrics and gradients carry float32 rounding (README, 'float32 vs float64'). For "
        "float64 call jax.config.update('jax_enable_x64', True) before the first computation. "
        "(Shown once per process.)",
        PrecisionWarning,
        stacklevel=3,
    )


# ---------------------------------------------------------------------------
# the solution
# ---------------------------------------------------------------------------


class Solution(eqx.Module):
    """What :func:`simulate` returns (under ``vmap``, every field gains the batch axis).

    Attributes:
        t: sample times t_k = t0 + k·ts, s, shape (n,) (None with :class:`SaveFinal`).
        outputs: the stacked step outputs, exactly what ``lax.scan(system.step, ...)``
            returns (None with :class:`SaveFinal`).
        final_state: the system state after the last step (pass it as ``state0`` to continue).
        ok: bool, every floating-point output finite over the horizon (with
            :class:`SaveFinal`: the final state and the cost finite — a non-finite
            value never leaves these systems' states again).
        cost: ts·Σ cost(out) when the save strategy has a cost, else None.
    """

    t: jax.Array | None
    outputs: Any
    final_state: Any
    ok: jax.Array
    cost: jax.Array | None = None

    @property
    def final_ok(self) -> jax.Array:
        """bool, the final state finite (:class:`SaveFinal`'s reading of ``ok``, without the cost).  Under
        ``vmap`` one per scenario; on a batched solution outside it, one for the whole batch.  With
        :class:`SaveAll` it is the cheaper flag: ``ok`` reads every output of every step, and a program that
        returns it keeps every output of the loop alive, those nothing else reads included (the tuning
        objective reads it, jaxobs_tuning.objective; docs/performance.md)."""
        return all_finite(self.final_state)


def all_finite(tree: Any) -> jax.Array:
    """True when every floating-point leaf of ``tree`` is finite everywhere.

    Args:
        tree: A PyTree.

    Returns:
        A bool array.
    """
    leaves = [x for x in jax.tree.leaves(tree) if jnp.issubdtype(jnp.result_type(x), jnp.inexact)]
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in leaves])) if leaves else jnp.asarray(True)


def n_samples(t1: float, ts: float, t0: float = 0.0) -> int:
    """Samples in [t0, t1): round((t1 − t0)/ts), checked (finite, at least one).

    Args:
        t1: The end of the horizon, s (a Python number).
        ts: The sample time, s.
        t0: The time of sample 0, s.

    Returns:
        The number of samples.

    Raises:
        ValueError: ``t1`` is not a finite Python number, or the horizon is shorter than one sample or longer
            than 2^31 − 1 samples.
    """
    if not isinstance(t1, (int, float, np.integer, np.floating)) or isinstance(t1, bool):
        raise ValueError(f"simulate: t1 must be a Python number of seconds (static), got {type(t1).__name__}")
    if not np.isfinite(t1):
        raise ValueError(f"simulate: t1 must be finite, got {t1!r}")
    steps = (float(t1) - float(t0)) / ts
    if not steps < 2**31 - 1:
        raise ValueError(f"simulate: t1 − t0 = {t1 - t0:g} s is {steps:.3g} samples of {ts:g} s, more than 2^31 − 1")
    n = int(round(steps))
    if n < 1:
        raise ValueError(
            f"simulate: t1 must exceed t0 by at least one sample time ({ts:g} s), got t0={t0:g}, t1={t1:g}"
        )
    return n


def _available_memory() -> float:
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return float("inf")


def _check_memory(out_shape: Any, n: int) -> None:
    """Refuse a trajectory that cannot fit: n × (bytes of one step's outputs) against the free memory.

    The estimate is per scenario (inside ``vmap`` the batch axis is not seen);
    a batch multiplies it, which the caller's own sizing must allow for.
    """
    per_step = sum(int(np.prod(a.shape)) * np.dtype(a.dtype).itemsize for a in jax.tree.leaves(out_shape))
    need = per_step * n
    avail = _available_memory()
    if need > avail:
        raise ValueError(
            f"simulate: saving every step needs {need / 2**30:.3g} GiB ({n} steps × {per_step} bytes) but "
            f"{avail / 2**30:.3g} GiB are free: shorten t1 or use save=SaveFinal(cost)"
        )


# ---------------------------------------------------------------------------
# what to save: each strategy runs the loop it needs
# ---------------------------------------------------------------------------


class _Carry(NamedTuple):
    state: Any
    acc: jax.Array


class AbstractSave(eqx.Module):
    """What ``simulate`` keeps: every step's outputs, or only the end; optionally a running cost.

    ``cost(out) -> scalar`` is evaluated on every step's output ``out`` (the
    system's output type: :class:`SignalOutput` for :class:`OnSignal`, the
    drive's ``DriveOutput`` for ``ClosedLoop``); ``sol.cost`` is its integral
    ts·Σ cost — the streaming form of an ISE-type objective, whose gradient
    over a long horizon needs no trajectory.

    Each strategy runs its own loop (:meth:`run`), as diffrax's adjoints do: the plain scan of the system's
    step, or the throughput loop (:mod:`jaxobs.runtime._loop`) over the inputs the system declares
    (:meth:`jaxobs.AbstractSystem.loop_inputs`).

    Attributes:
        cost: ``cost(out) -> scalar``, or ``None`` (no running cost; static).
    """

    cost: Callable | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        if self.cost is not None and not callable(self.cost):
            raise ValueError(
                f"{type(self).__name__}.cost must be a callable cost(out) -> scalar or None, got {self.cost!r}"
            )

    @abc.abstractmethod
    def run(
        self, system: AbstractSystem, n: int, *, checkpoint: AbstractCheckpoint, state0: Any, unroll: int | None
    ) -> Solution:
        """Run ``n`` steps of ``system`` from sample 0.

        Args:
            system: The :class:`AbstractSystem`.
            n: The steps.
            checkpoint: How the loop is stored for reverse-mode AD (an :class:`AbstractCheckpoint`).
            state0: The initial state, or None: ``system.init()``.
            unroll: The throughput loop's unrolling (None: the system's).

        Returns:
            The :class:`Solution`.
        """

    def _plain(self, system, n, *, keep, checkpoint, state0) -> Solution:
        """The system's step scanned plainly: a user's own ``lax.scan(system.step, ...)`` gives these numbers."""
        feed = lambda ks: LoopInputs(ks, system.step)  # noqa: E731
        return _solve(self.cost, system, n, feed, fast=False, keep=keep, checkpoint=checkpoint, state0=state0)

    def _throughput(self, system, n, *, keep, checkpoint, state0, unroll) -> Solution:
        """The throughput loop (:mod:`jaxobs.runtime._loop`) over the inputs the system declares: the plain scan's
        numbers to rounding (1e-12 relative)."""
        system = system.throughput()

        def feed(ks):
            inputs = system.loop_inputs(ks)
            return inputs if unroll is None else inputs._replace(unroll=unroll)

        return _solve(self.cost, system, n, feed, fast=True, keep=keep, checkpoint=checkpoint, state0=state0)


class SaveAll(AbstractSave):
    """Keep every step's outputs (``sol.outputs``, leading axis the samples) and the final state.

    ``fast=False`` (the default) scans ``system.step`` plainly: a user's own ``lax.scan`` of it gives the
    same numbers bit for bit.  ``fast=True`` runs the loop made fast (jaxobs.runtime._loop: inputs a block of steps
    at a time, state vectors split, multistep start-ups peeled, unrolled), as :class:`SaveFinal` always
    does: the same outputs to rounding (1e-12 relative), in about half the time where the input is costly
    (a harmonic signal) or under differentiation (the tuning objective runs this way).

    Attributes:
        fast: Whether to run the throughput loop (static).
        cost: ``cost(out) -> scalar``, or ``None`` (:class:`AbstractSave`; static).
    """

    fast: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        super().__check_init__()
        if not isinstance(self.fast, bool):
            raise ValueError(f"SaveAll.fast must be True or False, got {self.fast!r}")

    def run(
        self, system: AbstractSystem, n: int, *, checkpoint: AbstractCheckpoint, state0: Any, unroll: int | None
    ) -> Solution:
        """Run ``n`` steps of ``system`` from sample 0, every output kept.

        Args:
            system: The :class:`AbstractSystem`.
            n: The steps.
            checkpoint: How the loop is stored for reverse-mode AD (an :class:`AbstractCheckpoint`).
            state0: The initial state, or None: ``system.init()``.
            unroll: The throughput loop's unrolling (None: the system's).

        Returns:
            The :class:`Solution`.
        """
        if self.fast:
            return self._throughput(system, n, keep=True, checkpoint=checkpoint, state0=state0, unroll=unroll)
        return self._plain(system, n, keep=True, checkpoint=checkpoint, state0=state0)


class SaveFinal(AbstractSave):
    """Keep only the final state, ``ok`` and the running cost: a long horizon stores no trajectory.  Always the
    throughput loop (:mod:`jaxobs.runtime._loop`).

    Attributes:
        cost: ``cost(out) -> scalar``, or ``None`` (no running cost; static).
    """

    def run(
        self, system: AbstractSystem, n: int, *, checkpoint: AbstractCheckpoint, state0: Any, unroll: int | None
    ) -> Solution:
        """Run ``n`` steps of ``system`` from sample 0 in the throughput loop, keeping only the end.

        Args:
            system: The :class:`AbstractSystem`.
            n: The steps.
            checkpoint: How the loop is stored for reverse-mode AD (an :class:`AbstractCheckpoint`).
            state0: The initial state, or None: ``system.init()``.
            unroll: The throughput loop's unrolling (None: the system's).

        Returns:
            The :class:`Solution` (no ``t``, no ``outputs``).
        """
        return self._throughput(system, n, keep=False, checkpoint=checkpoint, state0=state0, unroll=unroll)


def _solve(cost, system, n: int, feed: Callable, *, fast: bool, keep: bool, checkpoint, state0) -> Solution:
    """The loop of ``n`` steps fed by ``feed(ks)`` (:class:`~jaxobs.core.system.LoopInputs` at the sample indices ks),
    with the running cost; the outputs kept when ``keep``.

    With ``fast`` the loop is made fast (jaxobs.runtime._loop: inputs a block of steps at a time, multistep start-ups
    peeled, state vectors split, unrolled).  Those rewrites change which operations XLA fuses, and XLA's CPU
    backend always contracts a·b + c into a fused multiply-add where it fuses, so the two loops agree to
    rounding (1e-12 relative, tests/test_perf.py), not to the last bit.
    """
    ts, t0 = float(system.ts), float(system.t0)
    dtype = jnp.result_type(float)
    ks = jnp.arange(n, dtype=jnp.int32)
    feed = feed(ks)

    def body(carry, x):
        state, out = feed.advance(carry.state, x)
        acc = carry.acc if cost is None else carry.acc + cost(out)
        return _Carry(state, acc), (out if keep else None)

    # Without state0 the loop builds the initial state itself (carry_fn): a gain that also sets the initial
    # state (an FLL's omega_n) is then one direction of the forward sensitivities, not one per state component.
    def carry_fn():
        state = system.init() if state0 is None else state0
        return _Carry(state, jnp.zeros((), dtype))

    if keep:

        def one_output(first):  # the outputs of step 0 (shapes only)
            x = jax.tree.map(lambda a: a[0], first if feed.xs_map is None else feed.xs_map(first))
            return body(carry_fn(), x)[1]

        _check_memory(jax.eval_shape(one_output, jax.tree.map(lambda a: a[:1], feed.xs)), n)
    final, outputs = run_loop(
        body,
        None,
        feed.xs,
        n,
        unroll=feed.unroll if fast else 1,
        checkpoint=checkpoint,
        xs_map=feed.xs_map,
        split=fast,
        peel=fast,
        carry_fn=carry_fn,
        fill=feed.fill,
    )
    total = None if cost is None else ts * final.acc
    ok = all_finite(outputs) if keep else all_finite(final)
    t = (t0 + ts * ks.astype(dtype)) if keep else None
    return Solution(t=t, outputs=outputs, final_state=final.state, ok=ok, cost=total)


# ---------------------------------------------------------------------------
# the loop
# ---------------------------------------------------------------------------


@eqx.filter_jit
def simulate(
    system: AbstractSystem,
    t1: float,
    *,
    save: AbstractSave = SaveAll(),
    checkpoint: AbstractCheckpoint = AutoCheckpoint(),
    state0: Any = None,
    throw: bool = False,
    unroll: int | None = None,
) -> Solution:
    """Run ``system`` from its first sample (t0, default 0) up to ``t1`` (exclusive), one step per ``system.ts``.

    Args:
        system: a :class:`~jaxobs.AbstractSystem`, with ``ts``, ``init()`` and ``step(state, k)``
            (:class:`OnSignal`, :class:`jaxobs.drive.ClosedLoop`, or your own subclass), starting at its ``t0``.
        t1: end of the horizon, s (static: it fixes the number of steps n = round((t1 − t0)/ts)).
        save: :class:`SaveAll` (default) or :class:`SaveFinal`, each with an optional running cost; it runs
            the loop (``save.run``).
        checkpoint: how reverse-mode AD stores the loop (:class:`~jaxobs.AutoCheckpoint` by default;
            :class:`~jaxobs.NoCheckpoint`, :class:`~jaxobs.StepCheckpoint`,
            :class:`~jaxobs.ChunkCheckpoint`, :class:`~jaxobs.ForwardSensitivity`); results are identical.
        state0: the state to start from (default ``system.init()``), e.g. a previous ``sol.final_state``.
        throw: raise if the run is not ``ok``, instead of only reporting it.
        unroll: loop unrolling of the throughput loop (:class:`SaveFinal`, ``SaveAll(fast=True)``; static;
            default the system's, :meth:`~jaxobs.AbstractSystem.loop_inputs`).

    Returns:
        A :class:`Solution`: ``t``, ``outputs`` (the stacked step outputs), ``final_state``, ``ok``, ``cost``.

    Raises:
        ValueError: a bad horizon (not finite, shorter than one sample, more than 2^31 − 1 steps, outside a
            recording), a trajectory larger than the free memory, or bad strategy objects.
    """
    if not isinstance(system, AbstractSystem):
        hint = " (an observer runs on a signal as jaxobs.OnSignal(observer, signal))"
        raise ValueError(
            f"simulate: system must be a jaxobs.AbstractSystem (ts, init(), step(state, k)), "
            f"got {type(system).__name__}{hint if isinstance(system, AbstractObserver) else ''}"
        )
    if not isinstance(save, AbstractSave):
        raise ValueError(f"simulate: save must be SaveAll(...) or SaveFinal(...), got {save!r}")
    _warn_float32()  # at trace time: the first call of a process always traces
    ts = check_sample_time("ts", system.ts, type(system).__name__)
    n = n_samples(t1, ts, float(system.t0))
    check_unroll(system.unroll if unroll is None else unroll)
    system.check_horizon(n)
    sol = save.run(system, n, checkpoint=checkpoint, state0=state0, unroll=unroll)
    if throw:
        msg = "simulation diverged: non-finite output"
        final_state = eqx.error_if(sol.final_state, ~sol.ok, msg)
        outputs = None if sol.outputs is None else eqx.error_if(sol.outputs, ~sol.ok, msg)
        sol = Solution(t=sol.t, outputs=outputs, final_state=final_state, ok=sol.ok, cost=sol.cost)
    return sol
