"""The simulation entry point for signal-level observers.

``simulate(observer, signal, t1)`` scans the observer's pure ``step`` over the
signal sampled every ``observer.ts`` and returns named fields.  It is a
``filter_jit``-ed function of PyTrees, so ``jax.vmap`` over a batch of signals
or of observers (gains), and ``jax.grad`` through it, apply unchanged::

    sol = jaxobs.simulate(obs, sig, 0.5)
    sols = jax.vmap(lambda s: jaxobs.simulate(obs, s, 0.5))(batched_signal)

A simulation that diverges is reported by ``sol.ok`` (per scenario under
``vmap``), not raised, unless ``throw=True``.
"""

from __future__ import annotations

from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp

from ._validate import check_sample_time
from .discretize import Knots

__all__ = ["SignalSolution", "simulate", "n_samples"]


class SignalTruth(eqx.Module):
    theta: jax.Array  # true fundamental phase, rad (unwrapped), shape (n,)
    omega: jax.Array  # true fundamental frequency, rad/s, shape (n,)
    amplitude: jax.Array  # true fundamental amplitude, shape (n,)


class SignalSolution(eqx.Module):
    t: jax.Array  # sample times t_n, shape (n,)
    u: jax.Array  # input samples u(t_n), shape (n,)
    out: Any  # observer outputs (NamedTuple of arrays of shape (n,)), estimate at t_n
    truth: SignalTruth | None  # what the signal really is, when it can say
    final_state: Any  # observer state after the last sample (to continue a run)
    ok: jax.Array  # bool: every output finite over the horizon


def n_samples(t1: float, ts: float, t0: float = 0.0) -> int:
    n = int(round((t1 - t0) / ts))
    if n < 1:
        raise ValueError(f"t1 must exceed t0 by at least one sample time ({ts:g} s), got t0={t0:g}, t1={t1:g}")
    return n


@eqx.filter_jit
def simulate(
    observer,
    signal,
    t1: float,
    *,
    t0: float = 0.0,
    input_path: Literal["hold", "knots"] = "hold",
    state0=None,
    throw: bool = False,
) -> SignalSolution:
    """Scan ``observer`` over ``signal`` from ``t0`` to ``t1`` (exclusive), one sample per ``observer.ts``.

    Args:
        observer: any module with ``init``/``step`` and a sample time ``ts``.
        signal: callable ``signal(t)`` (e.g. a :class:`~jaxobs.signals.GridSignal`).
        t1, t0: horizon in seconds (static: they fix the scan length).
        input_path: ``"hold"`` feeds the sample u(t_n) held over the period, as a
            DSP does; ``"knots"`` gives the rule u at t_n, t_n + ts/2 and t_n + ts,
            for comparisons with a continuous-time reference.
        state0: initial observer state (default ``observer.init()``).
        throw: raise if any output is non-finite, instead of reporting ``ok``.
    """
    ts = check_sample_time("ts", observer.ts, type(observer).__name__)
    n = n_samples(t1, ts, t0)
    dtype = jnp.result_type(float)
    t = t0 + ts * jnp.arange(n, dtype=dtype)
    u = signal(t)
    if input_path == "hold":
        xs = u
    elif input_path == "knots":
        xs = Knots(u0=u, um=signal(t + 0.5 * ts), u1=signal(t + ts))
    else:
        raise ValueError(f"input_path must be 'hold' or 'knots', got {input_path!r}")
    state = observer.init(u[0]) if state0 is None else state0

    def body(carry, x):
        return observer.step(carry, x)

    final_state, out = jax.lax.scan(body, state, xs)
    leaves = jax.tree.leaves(out)
    ok = jnp.all(jnp.stack([jnp.all(jnp.isfinite(leaf)) for leaf in leaves]))
    if throw:
        out = eqx.error_if(out, ~ok, "simulation diverged: non-finite observer output")
    truth = None
    if all(hasattr(signal, a) for a in ("theta", "omega", "fundamental_amplitude")):
        truth = SignalTruth(theta=signal.theta(t), omega=signal.omega(t), amplitude=signal.fundamental_amplitude(t))
    return SignalSolution(t=t, u=u, out=out, truth=truth, final_state=final_state, ok=ok)
