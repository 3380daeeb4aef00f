"""An observer on a signal, as a system the loop runs: :class:`OnSignal`, and :class:`OnRows` (its throughput
form on a time-major recording batch), with what each step returns (:class:`SignalOutput`, :class:`SignalTruth`).

``OnSignal(observer, signal).step(state, k)`` feeds the observer the signal's sample k; its
:meth:`~OnSignal.loop_inputs` feed the throughput loop a block of inputs at a time (:mod:`jaxobs.runtime._loop`,
point 5), and on a time-major recording batch the loop runs :class:`OnRows`, whose inputs are the batch's rows
(point 6).  :func:`jaxobs.simulate` runs either.
"""

from __future__ import annotations

import functools
import math
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

__all__ = ["OnSignal", "OnRows", "SignalTruth", "SignalOutput"]


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

    # loop unrolling (jaxobs.runtime._loop point 3): a signal-level step is small; 3, the fastest of 2..8, since
    # deeper unrolling makes XLA's CPU fusion recompute the AB3 sums of the steps before (docs/performance.md)
    unroll: ClassVar[int] = 3

    def __init__(
        self,
        observer: AbstractObserver,
        signal: AbstractSignal | Callable[[Any], Any],
        *,
        t0: float = 0.0,
        knots: bool = False,
    ):
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
        """The sample time, s: the observer's."""
        return self.observer.ts

    @property
    def has_truth(self) -> bool:
        """The signal reports its truth (``SignalOutput.truth`` is filled in)."""
        return self.signal.has_truth

    def time(self, k: jax.typing.ArrayLike) -> jax.Array:
        """t_k = t0 + k·ts (in the default float dtype).

        Args:
            k: The sample index.

        Returns:
            t_k, s.
        """
        return self.t0 + self.ts * jnp.asarray(k).astype(jnp.result_type(float))

    def _at(self, k: jax.typing.ArrayLike, offset: float = 0.0) -> SampleTime | jax.Array:
        """The time of sample k (+ a static offset) as the signal takes it: a :class:`SampleTime` (the
        exact index, so that a float32 phase stays accurate at any horizon: jaxobs.core.sampletime) for signals
        that accept one, else the float t_k + offset."""
        if self.signal.accepts_sample_time:
            return SampleTime(jnp.asarray(k, jnp.int32), self.ts, self.t0 + offset)
        return self.time(k) + offset if offset else self.time(k)

    def init(self) -> Any:
        """The observer's initial state, from the signal at ``t0``.

        Returns:
            ``observer.init(u(t0))``.
        """
        if self.signal.accepts_sample_time:
            return self.observer.init(self.signal(self._at(0)))
        return self.observer.init(self.signal(jnp.asarray(self.t0, jnp.result_type(float))))

    def input(self, k: jax.typing.ArrayLike) -> tuple[Any, Any, SignalTruth | None]:
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

    def input_block(self, kb: jax.Array) -> tuple[Any, Any, SignalTruth | None]:
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
        assert isinstance(sig, SampledSignal)  # _sample_offset is None for any other signal
        u = read(sig.samples)
        truth = SignalTruth(*(read(a) for a in sig.truth)) if sig.truth is not None else None
        return u, u, truth

    def advance(self, state: Any, x: tuple[Any, Any, SignalTruth | None]) -> tuple[Any, SignalOutput]:
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

    def step(self, state: Any, k: jax.typing.ArrayLike) -> tuple[Any, SignalOutput]:
        """One step: the observer fed sample k.

        Args:
            state: The observer's state.
            k: The sample index.

        Returns:
            ``(the next state, the SignalOutput)``.
        """
        return self.advance(state, self.input(k))

    def loop_inputs(self, ks: jax.Array) -> LoopInputs:
        """The sample indices, their inputs computed a block at a time (:meth:`input_block`).

        Args:
            ks: The sample indices.

        Returns:
            The :class:`LoopInputs`.
        """
        return LoopInputs(ks, self.advance, xs_map=self.input_block, unroll=self.unroll)

    def check_horizon(self, n: int) -> None:
        """The signal must be readable over the horizon (a recording inside its samples, a time-major batch one
        scenario at a time: :meth:`jaxobs.AbstractSignal.check_window`).

        Args:
            n: The steps.

        Raises:
            ValueError: The signal cannot be read over the horizon.
        """
        self.signal.check_window(self.t0, self.t0 + self.ts * (n - 1), "OnSignal.signal")

    def throughput(self) -> AbstractSystem:
        """The system the throughput loop runs.

        Returns:
            :class:`OnRows` on a time-major recording batch (its scenario axis inner, ``batch_axis`` 1) on this
            system's sample grid; this system otherwise.
        """
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

    # the unroll over the rows (jaxobs.runtime._loop point 6): 2, never far from the best of 1..4
    # (docs/performance.md).  An unroll that does not divide the horizon makes lax.scan split off the remainder, a
    # copy of the whole horizon's rows: loop_inputs lowers it to the next divisor.
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
        """The sample time, s: the :class:`OnSignal`'s."""
        return self.system.ts

    @property
    def t0(self) -> float:
        """The time of sample 0, s: the :class:`OnSignal`'s."""
        return self.system.t0

    def _offset(self) -> int:
        """The index of sample 0 in the recording (``__init__`` checked that there is one)."""
        off = self.system._sample_offset()
        assert off is not None
        return off

    def _rows(self) -> tuple[Any, ...]:
        """The recording's arrays with time leading: (samples, truth arrays or None)."""
        sig = self.system.signal
        if isinstance(sig, DriveRecording):
            return sig.samples, sig.theta_e, sig.omega_e
        assert isinstance(sig, SampledSignal)  # __init__ checked: a recording on the sample grid
        return sig.samples, sig.truth

    def input_rows(self, n: int) -> tuple[Any, ...]:
        """The rows of all steps: the recording's arrays' rows ``[off, off + n)``, off the index of sample 0.

        Under ``map_batch`` the loop reads them one contiguous row per step (:mod:`jaxobs.runtime._loop`, point 6): a
        static slice keeps the batch axis inner, and with the horizon the whole recording there is no slice at
        all.

        Args:
            n: The steps.

        Returns:
            The rows (leading axis n; :meth:`row_input` makes a step's input of one).
        """
        off = self._offset()
        return jax.tree.map(lambda a: a if (off == 0 and a.shape[0] == n) else a[off : off + n], self._rows())

    def row_input(self, row: tuple[Any, ...]) -> tuple[Any, Any, SignalTruth | None]:
        """``OnSignal.input(k)`` from row k of :meth:`input_rows` (the same values: the recording snaps to its
        samples).

        Args:
            row: Row k of :meth:`input_rows`.

        Returns:
            ``(u, the rule's input path, truth)``, as :meth:`OnSignal.input`.
        """
        if isinstance(self.system.signal, DriveRecording):
            m, th, om = row
            u = DriveInput(u_a=m[0], u_b=m[1], i_a=m[2], i_b=m[3])
            truth = SignalTruth(th, om, jnp.sqrt(u.u_a * u.u_a + u.u_b * u.u_b)) if th is not None else None
            return u, u, truth
        u, truth = row
        return u, u, (SignalTruth(*truth) if truth is not None else None)

    def init(self) -> Any:
        """The observer's initial state, from the recording's sample 0.

        Returns:
            ``observer.init(u(t0))``.
        """
        # sample 0 read where it lies (a dynamic read would move the batch axis)
        off = self._offset()
        return self.system.observer.init(self.row_input(jax.tree.map(lambda a: a[off], self._rows()))[0])

    def step(self, state: Any, k: jax.typing.ArrayLike) -> tuple[Any, SignalOutput]:
        """One step: :meth:`OnSignal.step`.

        Args:
            state: The observer's state.
            k: The sample index.

        Returns:
            ``(the next state, the SignalOutput)``.
        """
        return self.system.step(state, k)

    def check_horizon(self, n: int) -> None:
        """The recording must be readable over the horizon: :meth:`OnSignal.check_horizon`.

        Args:
            n: The steps.
        """
        self.system.check_horizon(n)

    def loop_inputs(self, ks: jax.Array) -> LoopInputs:
        """The rows as the scan's inputs, the start-up filled (:mod:`jaxobs.runtime._loop`, point 6).

        Args:
            ks: The sample indices.

        Returns:
            The :class:`LoopInputs`.
        """
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
