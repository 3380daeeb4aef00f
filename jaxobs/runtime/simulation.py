"""The one time loop: ``jaxobs.simulate(system, t1)`` runs any *system*.

A system is an ``equinox.Module`` with a sample time ``ts`` and two pure methods::

    state = system.init()
    state, out = system.step(state, k)      # k: the sample index (int32 scalar)

so that a user's own scan gives exactly what ``simulate`` returns::

    _, outs = jax.lax.scan(system.step, system.init(), jnp.arange(n))
    outs == jaxobs.simulate(system, t0 + n * ts).outputs       # tested, element for element

Two systems ship with jaxobs: :class:`OnSignal` (an observer fed a test signal
or a recording) and :class:`jaxobs.drive.ClosedLoop` (the PMSM drive, with an
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
import functools
import math
import os
import warnings
from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..core.discretize import Knots, ab3_steady_from_start
from ..core.measurements import DriveInput
from ..core.sampletime import TS_REL_TOL, SampleTime
from ..core.system import AbstractSystem, LoopInputs
from ..core.validate import check_sample_time
from ..observers import AbstractObserver
from ..signals import AbstractSignal, DriveRecording, EMFSignal, FunctionSignal, SampledSignal
from ._loop import AbstractCheckpoint, AutoCheckpoint, check_unroll, run_loop

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
        objective's evaluation 47 → 32 ms, jaxobs_tuning.objective)."""
        return all_finite(self.final_state)


def all_finite(tree) -> jax.Array:
    """True when every floating-point leaf of ``tree`` is finite everywhere.

    Args:
        tree: A PyTree.

    Returns:
        A bool array.
    """
    leaves = [x for x in jax.tree.leaves(tree) if jnp.issubdtype(jnp.result_type(x), jnp.inexact)]
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in leaves])) if leaves else jnp.asarray(True)


def n_samples(t1, ts: float, t0: float = 0.0) -> int:
    """Samples in [t0, t1): round((t1 − t0)/ts), checked (finite, at least one)."""
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


def _check_memory(out_shape, n: int):
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
    def run(self, system: AbstractSystem, n: int, *, checkpoint, state0, unroll: int | None) -> Solution:
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

    def run(self, system, n, *, checkpoint, state0, unroll):
        if self.fast:
            return self._throughput(system, n, keep=True, checkpoint=checkpoint, state0=state0, unroll=unroll)
        return self._plain(system, n, keep=True, checkpoint=checkpoint, state0=state0)


class SaveFinal(AbstractSave):
    """Keep only the final state, ``ok`` and the running cost: a long horizon stores no trajectory.  Always the
    throughput loop (:mod:`jaxobs.runtime._loop`).

    Attributes:
        cost: ``cost(out) -> scalar``, or ``None`` (no running cost; static).
    """

    def run(self, system, n, *, checkpoint, state0, unroll):
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
# an observer on a signal
# ---------------------------------------------------------------------------


class SignalTruth(NamedTuple):
    """What a synthetic signal really is at a sample.

    Attributes:
        theta: The true fundamental phase, rad (unwrapped).
        omega: The true fundamental frequency, rad/s.
        amplitude: The true fundamental amplitude.
    """

    theta: jax.Array  # true fundamental phase, rad (unwrapped)
    omega: jax.Array  # true fundamental frequency, rad/s
    amplitude: jax.Array  # true fundamental amplitude


class SignalOutput(NamedTuple):
    """One step of :class:`OnSignal`: the input sample, the observer's outputs, and the truth.

    Attributes:
        u: The input sample u(t_k) the observer was given.
        obs: The observer's outputs at t_k (its NamedTuple).
        truth: What the signal really is at t_k (a :class:`SignalTruth`; ``None`` if the signal cannot say).
    """

    u: Any  # the input sample u(t_k) the observer was given
    obs: Any  # the observer's outputs at t_k (its NamedTuple)
    truth: SignalTruth | None  # what the signal really is at t_k (None if the signal cannot say)


class OnSignal(AbstractSystem):
    """An observer fed a signal sampled every ``observer.ts``, from ``t0`` on: a system for :func:`simulate`.

    ``step(state, k)`` feeds the observer u(t_k), t_k = t0 + k·ts, held over the
    period (as a DSP does), or, with ``knots=True``, u at t_k, t_k + ts/2 and
    t_k + ts (for comparisons with a continuous-time reference).  The output is
    a :class:`SignalOutput`.

    Args:
        observer: a :class:`~jaxobs.AbstractObserver` (``init(u0)``, ``step``, a sample time ``ts``).
        signal: a :class:`~jaxobs.AbstractSignal` (a :class:`~jaxobs.signals.GridSignal`,
            :class:`~jaxobs.signals.EMFSignal`, :class:`~jaxobs.signals.SampledSignal`...), whose truth is
            reported where it declares one (``has_truth``); or a plain function ``signal(t)`` (wrapped as a
            :class:`~jaxobs.signals.FunctionSignal`: no truth).
        t0: time of sample 0, s.
        knots: give the rule the input at the period's start, middle and end.

    The observer starts from ``observer.init(u(t0))``; to start elsewhere, pass
    ``state0=`` to :func:`simulate`.  On a time-major recording batch on the observer's sample grid the
    throughput loop runs :class:`OnRows` in its place (:meth:`throughput`).
    """

    observer: AbstractObserver
    signal: AbstractSignal
    t0: float = eqx.field(static=True)
    knots: bool = eqx.field(static=True)

    # loop unrolling (jaxobs.runtime._loop point 3): a signal-level step is small.  3, measured against 2, 4, 6 and 8
    # (batch 1024, 2 host devices, 1 s at 10 kHz, M scenario-steps/s, side by side in one run each):
    # SOGI-FLL precomputed f32 u3 299 / u4 285 / u8 229, f64 181 / 168 / 99; WIF precomputed f32 297 / 244 /
    # 156, f64 128 / 125 / 52; WIF input in the loop f64 42 / 40 / 28.  Deeper unrolling lets XLA's CPU
    # fusion chain more steps into kernels that each recompute the AB3 sums of the steps before (16 ran
    # at a fifth of the speed of 4).
    unroll: ClassVar[int] = 3

    def __init__(self, observer, signal, *, t0=0.0, knots=False):
        if not isinstance(observer, AbstractObserver):
            raise ValueError(
                f"OnSignal.observer must be a jaxobs.AbstractObserver (init, step, ts), got {type(observer).__name__}"
            )
        if not isinstance(signal, AbstractSignal):
            if not callable(signal):
                raise ValueError(f"OnSignal.signal must be callable signal(t), got {type(signal).__name__}")
            signal = FunctionSignal(signal)
        check_sample_time("ts", observer.ts, type(observer).__name__)
        if isinstance(t0, bool) or not isinstance(t0, (int, float)) or not np.isfinite(t0):
            raise ValueError(f"OnSignal.t0 must be a finite number of seconds, got {t0!r}")
        if isinstance(signal, (EMFSignal, DriveRecording)) and not math.isclose(
            signal.ts, float(observer.ts), rel_tol=TS_REL_TOL
        ):
            # the voltage is the average over [t_k, t_k + ts] of the signal's ts: it must be the observer's
            fix = " (DriveRecording.from_csv(..., ts=observer.ts) resamples a recording)"
            raise ValueError(
                f"OnSignal: {type(signal).__name__}.ts = {signal.ts:g} s must equal the observer's "
                f"{type(observer).__name__}.ts = {float(observer.ts):g} s"
                + (fix if isinstance(signal, DriveRecording) else "")
            )
        self.observer = observer
        self.signal = signal
        self.t0 = float(t0)
        self.knots = bool(knots)

    @property
    def ts(self) -> float:
        return self.observer.ts

    @property
    def has_truth(self) -> bool:
        """The signal reports its truth (``SignalOutput.truth`` is filled in)."""
        return self.signal.has_truth

    def time(self, k):
        """t_k = t0 + k·ts (in the default float dtype).

        Args:
            k: The sample index.

        Returns:
            t_k, s.
        """
        return self.t0 + self.ts * jnp.asarray(k).astype(jnp.result_type(float))

    def _at(self, k, offset: float = 0.0):
        """The time of sample k (+ a static offset) as the signal takes it: a :class:`SampleTime` (the
        exact index, so that a float32 phase stays accurate at any horizon: jaxobs.core.sampletime) for signals
        that accept one, else the float t_k + offset."""
        if self.signal.accepts_sample_time:
            return SampleTime(jnp.asarray(k, jnp.int32), self.ts, self.t0 + offset)
        return self.time(k) + offset if offset else self.time(k)

    def init(self):
        if self.signal.accepts_sample_time:
            return self.observer.init(self.signal(self._at(0)))
        return self.observer.init(self.signal(jnp.asarray(self.t0, jnp.result_type(float))))

    def input(self, k):
        """What the observer is given at sample k, and the truth there.

        Args:
            k: The sample index.

        Returns:
            ``(u, the rule's input path, truth)``.
        """
        t = self._at(k)
        u = self.signal(t)
        path = (
            Knots(u0=u, um=self.signal(self._at(k, 0.5 * self.ts)), u1=self.signal(self._at(k, self.ts)))
            if self.knots
            else u
        )
        sig = self.signal
        truth = SignalTruth(sig.theta(t), sig.omega(t), sig.fundamental_amplitude(t)) if self.has_truth else None
        return u, path, truth

    def _sample_offset(self) -> int | None:
        """The index of sample 0's time in a recording (:class:`SampledSignal`, :class:`DriveRecording`) on this
        system's sample grid (same interval, t0 on a sample instant), else None."""
        sig = self.signal
        if self.knots or not isinstance(sig, (SampledSignal, DriveRecording)):
            return None
        ts = float(self.ts)
        if abs(sig.ts - ts) > TS_REL_TOL * ts:
            return None
        off = (self.t0 - sig.t0) / ts
        return round(off) if abs(off - round(off)) <= 1e-9 else None

    def input_block(self, kb):
        """``input`` at the consecutive sample indices ``kb`` (leading axis the block), computed together.

        A recording on this system's own sample grid (a :class:`SampledSignal` or :class:`DriveRecording`
        with the observer's interval) is read as one contiguous slice of each sample array: at those
        instants the recording's ``__call__`` snaps to the sample, so the values are the same (in float32 a
        sample time t_k rounded by more than SNAP of an interval reads a blend of neighbours there, the
        exact sample here).  Under ``vmap`` over recordings the slice is a block of B rows, where a
        per-step read (``input`` mapped over the block) gathers one column per step.  Anything else
        is ``input`` mapped over the block.

        Args:
            kb: The consecutive sample indices.

        Returns:
            :meth:`input`'s values with the block as leading axis.
        """
        off = self._sample_offset()
        if off is None:
            return jax.lax.map(self.input, kb)
        size = kb.shape[0]
        start = kb[0] + off

        def read(a):
            return jnp.moveaxis(jax.lax.dynamic_slice_in_dim(a, start, size, axis=-1), -1, 0)

        sig = self.signal
        if isinstance(sig, DriveRecording):
            m = read(sig.samples)  # (block, 4): u_α, u_β, i_α, i_β
            u = DriveInput(u_a=m[:, 0], u_b=m[:, 1], i_a=m[:, 2], i_b=m[:, 3])
            truth = None
            if self.has_truth:  # DriveRecording.theta / omega / fundamental_amplitude at the samples
                amp = jnp.sqrt(u.u_a * u.u_a + u.u_b * u.u_b)
                truth = SignalTruth(read(sig.theta_e), read(sig.omega_e), amp)
            return u, u, truth
        u = read(sig.samples)
        truth = SignalTruth(*(read(a) for a in sig.truth)) if sig.truth is not None else None
        return u, u, truth

    def advance(self, state, x):
        """One step on an input of :meth:`input`: ``step(state, k) == advance(state, input(k))``.

        Args:
            state: The observer's state.
            x: :meth:`input`'s value.

        Returns:
            ``(the next state, the SignalOutput)``.
        """
        u, path, truth = x
        state, out = self.observer.step(state, path)
        return state, SignalOutput(u=u, obs=out, truth=truth)

    def step(self, state, k):
        return self.advance(state, self.input(k))

    def loop_inputs(self, ks) -> LoopInputs:
        """The sample indices, their inputs computed a block at a time (:meth:`input_block`).

        Args:
            ks: The sample indices.

        Returns:
            The :class:`LoopInputs`.
        """
        return LoopInputs(ks, self.advance, xs_map=self.input_block, unroll=self.unroll)

    def check_horizon(self, n: int):
        """The signal must be readable over the horizon (a recording inside its samples, a time-major batch one
        scenario at a time: :meth:`jaxobs.AbstractSignal.check_window`).

        Args:
            n: The steps.

        Raises:
            ValueError: The signal cannot be read over the horizon.
        """
        self.signal.check_window(self.t0, self.t0 + self.ts * (n - 1), "OnSignal.signal")

    def throughput(self) -> AbstractSystem:
        """:class:`OnRows` on a time-major recording batch (its scenario axis inner, ``batch_axis`` 1) on this
        system's sample grid; this system otherwise."""
        if self.signal.batch_axis != 0 and self._sample_offset() is not None:
            return OnRows(self)
        return self


class OnRows(AbstractSystem):
    """An observer on a time-major recording batch, fed the batch's rows: the throughput loop's form of
    :class:`OnSignal` on one (:meth:`OnSignal.throughput`).

    A batch of recordings stored time-major (``SampledSignal(batch_inner=True)``,
    ``DriveRecording(batch_inner=True)``: leaves (n, B), row k every scenario's sample k) is mapped along its
    inner axis (``jaxobs.map_batch``), and its rows are the scan's inputs (:mod:`jaxobs.runtime._loop`, point 6):
    ``lax.scan`` keeps a batched input's batch axis where time-major rows have it, so each step reads one
    contiguous (B,) row.  AB3's start-up is filled into a steady history
    (:func:`jaxobs.core.discretize.ab3_steady_from_start`) instead of peeled, since ``xs[2:]`` would copy the
    horizon.  The numbers are :class:`OnSignal`'s to rounding; ``step`` is its step.

    Args:
        system: the :class:`OnSignal` whose signal is a time-major recording batch on its sample grid.
    """

    system: OnSignal

    # the unroll over the rows (jaxobs.runtime._loop point 6), where a step reads one row and nothing else: 2, measured
    # against 1, 2, 3 and 4 (SOGI-FLL, precomputed, 2 host devices, 1 s at 10 kHz, M scenario-steps/s, one run
    # each): batch 8192 f32 u1 884-893 / u2 1095-1104 / u3 365-390 / u4 1160-1165, f64 u2 646-648 / u4 416-510;
    # batch 1024 f32 u2 773-781 / u4 929-944, f64 u2 485-513 / u4 557-568.  4 is faster in three of the four and
    # loses a third in the fourth; 2 is never far from the best.  An unroll that does not divide the horizon makes
    # lax.scan split off the remainder, a copy of the whole horizon's rows (u3 above): loop_inputs lowers it to
    # the next divisor.
    unroll: ClassVar[int] = 2

    def __init__(self, system: OnSignal):
        if not isinstance(system, OnSignal) or system.signal.batch_axis == 0 or system._sample_offset() is None:
            raise ValueError(
                "OnRows.system must be an OnSignal on a time-major recording batch (batch_inner=True) on its "
                f"sample grid, got {type(system).__name__}"
            )
        self.system = system

    @property
    def ts(self) -> float:
        return self.system.ts

    @property
    def t0(self) -> float:
        return self.system.t0

    def _rows(self):
        """The recording's arrays with time leading: (samples, truth arrays or None)."""
        sig = self.system.signal
        if isinstance(sig, DriveRecording):
            return sig.samples, sig.theta_e, sig.omega_e
        return sig.samples, sig.truth

    def input_rows(self, n: int):
        """The rows of all steps: the recording's arrays' rows ``[off, off + n)``, off the index of sample 0.

        Under ``map_batch`` the loop reads them one contiguous row per step (:mod:`jaxobs.runtime._loop`, point 6): a
        static slice keeps the batch axis inner, and with the horizon the whole recording there is no slice at
        all.

        Args:
            n: The steps.

        Returns:
            The rows (leading axis n; :meth:`row_input` makes a step's input of one).
        """
        off = self.system._sample_offset()
        return jax.tree.map(lambda a: a if (off == 0 and a.shape[0] == n) else a[off : off + n], self._rows())

    def row_input(self, row):
        """``OnSignal.input(k)`` from row k of :meth:`input_rows` (the same values: the recording snaps to its
        samples)."""
        if isinstance(self.system.signal, DriveRecording):
            m, th, om = row
            u = DriveInput(u_a=m[0], u_b=m[1], i_a=m[2], i_b=m[3])
            truth = SignalTruth(th, om, jnp.sqrt(u.u_a * u.u_a + u.u_b * u.u_b)) if th is not None else None
            return u, u, truth
        u, truth = row
        return u, u, (SignalTruth(*truth) if truth is not None else None)

    def init(self):
        # sample 0 read where it lies (a dynamic read would move the batch axis)
        off = self.system._sample_offset()
        return self.system.observer.init(self.row_input(jax.tree.map(lambda a: a[off], self._rows()))[0])

    def step(self, state, k):
        return self.system.step(state, k)

    def check_horizon(self, n: int):
        self.system.check_horizon(n)

    def loop_inputs(self, ks) -> LoopInputs:
        """The rows as the scan's inputs, the start-up filled (:mod:`jaxobs.runtime._loop`, point 6)."""
        n = ks.shape[0]
        unroll = min(self.unroll, n)
        while n % unroll:  # a remainder would be split off the rows: a copy of the horizon
            unroll -= 1
        return LoopInputs(
            self.input_rows(n),
            lambda state, row: self.system.advance(state, self.row_input(row)),
            fill=functools.partial(ab3_steady_from_start, h=float(self.ts)),
            unroll=unroll,
        )


# ---------------------------------------------------------------------------
# the loop
# ---------------------------------------------------------------------------


@eqx.filter_jit
def simulate(
    system,
    t1: float,
    *,
    save: AbstractSave = SaveAll(),
    checkpoint: AbstractCheckpoint = AutoCheckpoint(),
    state0=None,
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
