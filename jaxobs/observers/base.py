"""The step-function contract shared by every observer (DESIGN.md).

An observer is an immutable ``equinox.Module`` holding its gains as array
leaves, with pure ``init`` and ``step``:

    state = obs.init()
    state, out = obs.step(state, u)      # u: one input sample (or an input path)

``out`` at sample n is always the estimate *at* t_n, built only from data a
DSP has at t_n:

- signal-level observers (the FLL family) see a sample v(t_n) but not the
  signal over [t_n, t_{n+1}], so ``step`` returns the outputs of the state
  *before* the update (inputs up to n − 1 integrated up to t_n);
- drive observers (flux observers, LESOs) at t_n know the current i_n and
  the voltage applied over the period that just ended, so ``step``
  integrates that period and returns the outputs at t_n.

Either way the observer is strictly causal and its outputs line up with a
continuous-time reference sampled at t_n.
"""

from __future__ import annotations

import abc
from typing import Any, NamedTuple

import equinox as eqx
import jax

from .._discretize import AbstractRule


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


class BankOutput(NamedTuple):
    theta: Any  # the primary observer's θ̂e (what a sensorless controller uses)
    omega: Any  # the primary observer's ω̂e
    each: tuple  # every observer's own outputs, in order


class ObserverBank(eqx.Module):
    """Several observers fed the same measurements; ``primary`` closes the loop when sensorless.

    Lets one drive simulation compare observers on identical data (000's
    per-observer position errors) without them disturbing each other.
    """

    observers: tuple
    primary: int = eqx.field(static=True, default=0)

    def init(self, u0=None):
        return tuple(o.init() for o in self.observers)

    def init_at(self, omega_e):
        return tuple(o.init_at(omega_e) if hasattr(o, "init_at") else o.init() for o in self.observers)

    def seed_speed(self, state, omega_e):
        return tuple(o.seed_speed(s, omega_e) if hasattr(o, "seed_speed") else s for o, s in zip(self.observers, state))

    def step(self, state, u):
        pairs = [o.step(s, u) for o, s in zip(self.observers, state)]
        outs = tuple(p[1] for p in pairs)
        return tuple(p[0] for p in pairs), BankOutput(
            theta=outs[self.primary].theta, omega=outs[self.primary].omega, each=outs
        )
