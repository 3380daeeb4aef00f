"""The system contract: what ``jaxobs.simulate`` runs and what a user can ``lax.scan``.

A system is an ``equinox.Module`` with a sample time ``ts`` and two pure methods,
``init()`` and ``step(state, k)`` (k the sample index).  Everything else the loop
reads is declared here with a default, so that ``simulate`` asks rather than probes:

- ``t0``: the time of sample 0 (0 s);
- ``unroll``: the loop unrolling the system prefers (1; :mod:`jaxobs.runtime._loop`, point 3);
- ``check_horizon(n)``: refuse a run of n steps the system cannot make (accepts every n);
- ``loop_inputs(ks)``: how the throughput loop feeds the steps at the sample indices ``ks``
  (:class:`LoopInputs`; by default the indices themselves, each step ``step(state, k)``); a system whose
  step splits into the outside world's input at sample k and ``advance(state, x)`` feeds the inputs a
  block at a time (:class:`~jaxobs.OnSignal`);
- ``throughput()``: the system the throughput loop runs in this one's place, with the same numbers to
  rounding (itself; an observer on a time-major recording batch runs as its rows system).

:class:`~jaxobs.OnSignal` and :class:`~jaxobs.drive.ClosedLoop` (and the dual three-phase drive's
:class:`~jaxobs.drive.dual_loop.DualClosedLoop`) are the systems that ship with jaxobs.
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax

__all__ = ["AbstractSystem", "LoopInputs"]


class LoopInputs(NamedTuple):
    """How the throughput loop feeds a system's n steps (:func:`jaxobs.runtime._loop.run_loop`'s arguments).

    Attributes:
        xs: the per-step values, leading axis n (the sample indices, or a time-major batch's rows).
        advance: ``advance(state, x) -> (state, outputs)``, the step on one step's input.
        xs_map: a block of ``xs`` (leading axis the block) to the block's inputs, evaluated a block at a
            time (:mod:`jaxobs.runtime._loop`, point 5), or None: ``advance`` takes ``xs[k]`` itself.
        fill: the peeled start-up's carries to a steady carry at step 0 (:mod:`jaxobs.runtime._loop`, point 6), or None.
        unroll: the loop unrolling (simulate's ``unroll=`` overrides it).
    """

    xs: Any
    advance: Callable[[Any, Any], tuple[Any, Any]]
    xs_map: Callable[[Any], Any] | None = None
    fill: Callable[[Any, Any, Any], Any] | None = None
    unroll: int = 1


class AbstractSystem(eqx.Module):
    """Base of the systems ``jaxobs.simulate`` runs: ``ts``, ``init()``, ``step(state, k)``; the rest has defaults.

    Systems hash by identity.  ``jax.lax.scan(system.step, ...)`` hashes the
    function it is given (a cache key in JAX's tracing), and an equinox bound
    method hashes its module, whose array leaves are unhashable; an identity
    hash makes the user's own scan work (a new system object only means a new
    trace, never a wrong one).
    """

    t0: ClassVar[float] = 0.0  # time of sample 0, s (a system that starts elsewhere has a field)
    unroll: ClassVar[int] = 1  # preferred loop unrolling (jaxobs.runtime._loop point 3)

    @property
    @abc.abstractmethod
    def ts(self) -> float:
        """Sample time, s."""

    @abc.abstractmethod
    def init(self) -> Any:
        """The state at sample 0."""

    @abc.abstractmethod
    def step(self, state: Any, k: jax.Array) -> tuple[Any, Any]:
        """One sample period.

        Args:
            state: The state at k.
            k: The sample index.

        Returns:
            ``(state at k + 1, outputs at t_k)``.
        """

    def check_horizon(self, n: int) -> None:
        """Refuse a run this system cannot make; any by default.

        Args:
            n: The steps from sample 0.

        Raises:
            ValueError: The system cannot run ``n`` steps.
        """

    def loop_inputs(self, ks: jax.Array) -> LoopInputs:
        """How the throughput loop feeds the steps: by default the indices themselves, ``step`` on each.

        Args:
            ks: The sample indices (int32, 0 to n − 1).

        Returns:
            The :class:`LoopInputs`.
        """
        return LoopInputs(ks, self.step, unroll=self.unroll)

    def throughput(self) -> AbstractSystem:
        """The system the throughput loop (``SaveFinal``, ``SaveAll(fast=True)``) runs in this one's place: the
        same outputs to rounding, fed differently (this one by default)."""
        return self

    def __hash__(self) -> int:
        return id(self)
