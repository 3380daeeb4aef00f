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

from collections.abc import Callable
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp

from ._validate import check_sample_time
from ._loop import run_loop
from .discretize import Knots
from .signals import SampledSignal

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
    cost: jax.Array | None = None  # ts·Σ cost(out, truth) when a running cost was given


def _all_finite(tree) -> jax.Array:
    leaves = [x for x in jax.tree.leaves(tree) if jnp.issubdtype(jnp.result_type(x), jnp.inexact)]
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in leaves])) if leaves else jnp.asarray(True)


def n_samples(t1: float, ts: float, t0: float = 0.0) -> int:
    n = int(round((t1 - t0) / ts))
    if n < 1:
        raise ValueError(f"t1 must exceed t0 by at least one sample time ({ts:g} s), got t0={t0:g}, t1={t1:g}")
    return n


DEFAULT_UNROLL = 8  # loop unrolling of signal-level simulations (jaxobs._loop; measured in benchmarks/)


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
    inputs: Literal["precomputed", "loop"] = "precomputed",
    save: Literal["all", "final"] = "all",
    cost: Callable | None = None,
    checkpoint: str = "auto",
    unroll: int = DEFAULT_UNROLL,
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
        inputs: ``"precomputed"`` evaluates the signal at every sample before the
            loop (n samples of memory); ``"loop"`` evaluates it inside the loop, a
            block of steps at a time (:mod:`jaxobs._loop`, point 5: no n-sample
            input array and, on CPU, as fast or faster — what a long horizon or a
            huge batch wants).  Inputs already sampled (a recording) are a
            :class:`~jaxobs.signals.SampledSignal`.
        save: ``"all"`` returns every sample's outputs; ``"final"`` only the final
            state, ``ok`` and ``cost`` (``t``, ``u``, ``out``, ``truth`` are None), so a
            long horizon keeps no trajectory.
        cost: optional running cost ``cost(out, truth) -> scalar`` evaluated at
            every sample (``truth`` the signal's :class:`SignalTruth` at t_n, or None);
            ``sol.cost`` is its integral ts·Σ cost — the streaming form of an ISE-type
            objective, whose gradient over a long horizon needs no trajectory.
        checkpoint: ``"auto"``, ``"none"``, ``"step"`` or ``"chunk"`` — how reverse-mode
            AD stores the loop (:mod:`jaxobs._loop`); results are identical.
        unroll: loop unrolling (static); results are identical.
    """
    ts = check_sample_time("ts", observer.ts, type(observer).__name__)
    n = n_samples(t1, ts, t0)
    if inputs not in ("precomputed", "loop"):
        raise ValueError(f"inputs must be 'precomputed' or 'loop', got {inputs!r}")
    if save not in ("all", "final"):
        raise ValueError(f"save must be 'all' or 'final', got {save!r}")
    if input_path not in ("hold", "knots"):
        raise ValueError(f"input_path must be 'hold' or 'knots', got {input_path!r}")
    dtype = jnp.result_type(float)
    has_truth = getattr(signal, "has_truth", True) and all(hasattr(signal, a) for a in ("theta", "omega", "fundamental_amplitude"))
    if isinstance(signal, SampledSignal):
        # a recording holds its end sample beyond its last instant (signals.py);
        # a horizon that starts before it or runs past it is a mistake, not a hold
        t_last = t0 + ts * (n - 1)
        tol = SampledSignal.SNAP * signal.ts
        if t0 < signal.t0 - tol or t_last > signal.t_end + tol:
            raise ValueError(
                f"simulate: the horizon [t0, t0 + ts*(n-1)] = [{t0:g}, {t_last:g}] s must lie inside the "
                f"SampledSignal's samples [{signal.t0:g}, {signal.t_end:g}] s"
            )

    def input_at(t):
        u = signal(t)
        if input_path == "hold":
            return u, u
        return u, Knots(u0=u, um=signal(t + 0.5 * ts), u1=signal(t + ts))

    def truth_at(t):
        if not has_truth:
            return None
        return SignalTruth(theta=signal.theta(t), omega=signal.omega(t), amplitude=signal.fundamental_amplitude(t))

    t_all = t0 + ts * jnp.arange(n, dtype=dtype)
    need_truth = cost is not None and has_truth
    if inputs == "precomputed":
        u_all, path_all = input_at(t_all)
        xs, xs_map = (t_all, path_all, None), None
        u_first = u_all[0]
    else:
        # sample indices, mapped to (t, input, truth) a block of steps at a time
        # inside the loop (jaxobs._loop, point 5); t0 + ts*k is computed exactly as above
        def xs_map(k):
            t = t0 + ts * k.astype(dtype)
            return t, input_at(t)[1], (truth_at(t) if need_truth else None)

        xs = jnp.arange(n, dtype=jnp.int32)
        u_first = signal(jnp.asarray(t0, dtype))
    state = observer.init(u_first) if state0 is None else state0

    def body(carry, x):
        st, acc = carry
        t, path, truth = x
        st, out = observer.step(st, path)
        if cost is not None:
            acc = acc + cost(out, truth_at(t) if truth is None else truth)
        ys = out if save == "all" else None
        return (st, acc), ys

    carry0 = (state, jnp.zeros((), dtype))
    (final_state, acc), out = run_loop(body, carry0, xs, n, unroll=unroll, checkpoint=checkpoint, xs_map=xs_map)
    # ok: every output finite; with save="final" the outputs are gone, but a
    # non-finite value never leaves the state of these systems again, so the
    # final state (and the running cost) tell the same.
    ok = _all_finite(out if save == "all" else (final_state, acc))
    if throw:
        final_state = eqx.error_if(final_state, ~ok, "simulation diverged: non-finite observer output")
    total = None if cost is None else ts * acc
    if save == "final":
        return SignalSolution(t=None, u=None, out=None, truth=None, final_state=final_state, ok=ok, cost=total)
    if throw:
        out = eqx.error_if(out, ~ok, "simulation diverged: non-finite observer output")
    u = u_all if inputs == "precomputed" else signal(t_all)
    return SignalSolution(t=t_all, u=u, out=out, truth=truth_at(t_all), final_state=final_state, ok=ok, cost=total)
