"""The step-function contract shared by every observer (DESIGN.md).

An observer is an immutable ``equinox.Module`` holding its gains as array
leaves, with pure ``init`` and ``step``:

    state = obs.init()
    state, out = obs.step(state, u)      # u: one input sample (or an input path)

``step`` returns the outputs computed from the state *before* the update, so
``out`` at sample n is the estimate at t_n built from inputs up to n − 1: the
observer is strictly causal, as on a DSP, and its outputs line up with a
continuous-time reference sampled at t_n.
"""

from __future__ import annotations

import abc
from typing import Any

import equinox as eqx
import jax

from ..discretize import AbstractRule


def check_rule(rule, owner: str) -> AbstractRule:
    """A component's ``rule`` must be a discretization rule object."""
    if not isinstance(rule, AbstractRule):
        raise ValueError(
            f"{owner}.rule must be a discretization rule (jaxobs.Euler(), Tustin(), AB3(), RK4()), got {rule!r}"
        )
    return rule


class ObserverState(eqx.Module):
    """State of a state-vector observer: the flat state and the rule's own state."""

    x: jax.Array  # shape (n_states,)
    rule: Any  # rule state (multistep history) or None


class AbstractObserver(eqx.Module):
    """Observer whose dynamics are a vector field ``f(x, u)`` on a flat state ``x``.

    Subclasses define ``f``, ``output`` and ``initial_state``; the rule given at
    construction integrates ``f`` over each sample period ``ts``.
    """

    ts: eqx.AbstractVar[float]
    rule: eqx.AbstractVar[AbstractRule]

    @abc.abstractmethod
    def f(self, x: jax.Array, u) -> jax.Array:
        """Continuous-time vector field dx/dt for input value ``u``."""

    @abc.abstractmethod
    def output(self, x: jax.Array) -> Any:
        """Named outputs (a NamedTuple) computed from the state ``x``."""

    @abc.abstractmethod
    def initial_state(self) -> jax.Array:
        """The flat state at t = 0."""

    def init(self, u0=None) -> ObserverState:
        x0 = self.initial_state()
        return ObserverState(x=x0, rule=self.rule.init(self.f, x0, u0))

    def step(self, state: ObserverState, u) -> tuple[ObserverState, Any]:
        out = self.output(state.x)
        x1, rule_state = self.rule.step(self.f, state.x, u, self.ts, state.rule)
        return ObserverState(x=x1, rule=rule_state), out

    def vector_field(self, t, x, signal):
        """``f(t, x, args)`` for ``diffrax.ODETerm``: ``args`` is a signal, called at t."""
        return self.f(x, signal(t))
