"""The system contract: what ``jaxobs.simulate`` runs and what a user can ``lax.scan`` (DESIGN.md).

A system is an ``equinox.Module`` with a sample time ``ts`` and two pure methods,
``init()`` and ``step(state, k)`` (k the sample index).  It may split its step
into ``input(k)`` (the outside world at sample k) and ``advance(state, x)``,
``step(state, k) == advance(state, input(k))``, which lets the loop evaluate
inputs a block of steps at a time.  :class:`~jaxobs.OnSignal` and
:class:`~jaxobs.drive.ClosedLoop` (and the dual three-phase drive's :class:`~jaxobs.drive.dual_loop.DualClosedLoop`)
are the systems that ship with jaxobs.
"""

from __future__ import annotations

import abc
from typing import Any

import equinox as eqx

__all__ = ["AbstractSystem"]


class AbstractSystem(eqx.Module):
    """Base of the systems ``jaxobs.simulate`` runs: ``ts``, ``init()``, ``step(state, k)``.

    Systems hash by identity.  ``jax.lax.scan(system.step, ...)`` hashes the
    function it is given (a cache key in JAX's tracing), and an equinox bound
    method hashes its module, whose array leaves are unhashable; an identity
    hash makes the user's own scan work (a new system object only means a new
    trace, never a wrong one).
    """

    unroll: eqx.AbstractClassVar[int]  # preferred loop unrolling (jaxobs._loop point 3)

    @property
    @abc.abstractmethod
    def ts(self) -> float:
        """Sample time, s."""

    @abc.abstractmethod
    def init(self) -> Any:
        """The state at sample 0."""

    @abc.abstractmethod
    def step(self, state, k) -> tuple[Any, Any]:
        """One sample period: (state at k + 1, outputs at t_k)."""

    def __hash__(self) -> int:
        return id(self)
