"""The signal contract: what :class:`~jaxobs.OnSignal`, the metrics and the batch functions ask of a signal.

A signal is an ``equinox.Module`` called as ``signal(t)`` inside a scan or ``vmap``.  It declares, with
defaults, what the rest of jaxobs reads from it instead of probing for it:

- ``accepts_sample_time``: it takes a :class:`~jaxobs.SampleTime` (the exact sample index) in place of the
  float t_k, so that a float32 phase stays exact at any horizon (``jaxobs.core.sampletime``);
- ``has_truth``: ``theta``, ``omega`` and ``fundamental_amplitude`` report what the signal really is;
- ``has_flux_angle``: ``flux_angle(t)`` and ``flux_omega(t)`` are the rotor-flux angle and its rate that a flux
  observer's estimate is compared with (an EMF's truth);
- ``batch_axis``: the axis of its leaves that a batch of it maps over (:func:`jaxobs.batch_axes`);
- ``check_window(t0, t_last, owner)``: refuse a simulation's horizon the signal cannot be read over (a
  recording's), naming the signal as ``owner`` (e.g. ``"OnSignal.signal"``).

A plain function of time is wrapped as a :class:`FunctionSignal` (no truth, no sample time).
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import ClassVar

import equinox as eqx
import jax

from ..core.sampletime import TimeLike

__all__ = ["AbstractSignal", "FunctionSignal"]


class AbstractSignal(eqx.Module):
    """Base of the signals: ``signal(t)``, and the declarations the loop, the metrics and the batch functions read.

    A subclass overrides what differs from the defaults: no sample time, no truth, no flux angle, the scenario
    axis leading, every horizon readable.

    Attributes:
        accepts_sample_time: Whether ``signal(t)`` takes a :class:`~jaxobs.SampleTime` (which
            :class:`~jaxobs.OnSignal` then passes instead of the rounded float t_k).
        has_truth: Whether the signal reports its true phase, frequency and amplitude (a recording's
            depends on its data: a property there).
        has_flux_angle: Whether the signal reports a true rotor-flux angle (the metrics' ``signal=``).
        batch_axis: The scenario axis of the signal's leaves in a batch (a time-major recording batch's
            is 1: a property there).
    """

    accepts_sample_time: ClassVar[bool] = False
    has_truth: ClassVar[bool] = False  # a recording's depends on its data: a property there
    has_flux_angle: ClassVar[bool] = False
    batch_axis: ClassVar[int] = 0  # a time-major recording batch's is 1: a property there

    @abc.abstractmethod
    def __call__(self, t):
        """The signal at time ``t`` (s, or a :class:`~jaxobs.SampleTime` where ``accepts_sample_time``)."""

    def theta(self, t: TimeLike) -> jax.Array:
        """True fundamental phase (where ``has_truth``).

        Args:
            t: The time, s.

        Returns:
            θ(t), rad.

        Raises:
            ValueError: The signal reports no truth.
        """
        raise ValueError(f"{type(self).__name__} reports no truth (theta)")

    def omega(self, t: TimeLike) -> jax.Array:
        """True fundamental angular frequency (where ``has_truth``).

        Args:
            t: The time, s.

        Returns:
            ω(t), rad/s.

        Raises:
            ValueError: The signal reports no truth.
        """
        raise ValueError(f"{type(self).__name__} reports no truth (omega)")

    def fundamental_amplitude(self, t: TimeLike) -> jax.Array:
        """True fundamental amplitude (where ``has_truth``).

        Args:
            t: The time, s.

        Returns:
            The amplitude, in the signal's units.

        Raises:
            ValueError: The signal reports no truth.
        """
        raise ValueError(f"{type(self).__name__} reports no truth (fundamental_amplitude)")

    def flux_angle(self, t: TimeLike) -> jax.Array:
        """The true rotor-flux angle (where ``has_flux_angle``).

        Args:
            t: The time, s.

        Returns:
            The angle, rad.

        Raises:
            ValueError: The signal has no flux angle.
        """
        raise ValueError(f"{type(self).__name__} has no flux angle")

    def flux_omega(self, t: TimeLike) -> jax.Array:
        """The true rotor-flux angle's rate (where ``has_flux_angle``).

        Args:
            t: The times, s.

        Returns:
            The rate, rad/s, shaped like ``t``.

        Raises:
            ValueError: The signal has no flux angle.
        """
        raise ValueError(f"{type(self).__name__} has no flux angle")

    def check_window(self, t0: float, t_last: float, owner: str) -> None:
        """Refuse a simulation that reads the signal where it cannot be read; every horizon is readable by default.

        Args:
            t0: The first time read, s.
            t_last: The last time read (t0, t0 + ts, ..., t_last), s.
            owner: The name the error gives the signal.

        Raises:
            ValueError: The signal cannot be read over [t0, t_last].
        """


class FunctionSignal(AbstractSignal):
    """A plain function of time as a signal: no truth, a float time.

    Attributes:
        fn: The function ``fn(t)``, t in s.
    """

    fn: Callable

    def __call__(self, t):
        return self.fn(t)
