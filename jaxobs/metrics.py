"""Metrics on simulated trajectories.

Exact versions for reports.  Angles are electrical and errors are wrapped to
(−π, π].  Bands, windows and event times are arguments, never constants.
All functions act on the last axis (time) and broadcast over leading axes.
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["wrap", "moving_average", "settling_time", "window_mask", "peak_to_peak", "steady_mean", "rms"]


def wrap(angle):
    """Wrap an angle to (−π, π]."""
    return jnp.pi - jnp.mod(jnp.pi - angle, 2 * jnp.pi)


def moving_average(x, n: int):
    """Causal moving average over the last ``n`` samples (fewer at the start)."""
    if int(n) < 1:
        raise ValueError(f"moving_average window n must be >= 1 samples, got {n!r}")
    n = int(n)
    c = jnp.cumsum(x, axis=-1)
    shifted = jnp.concatenate([jnp.zeros_like(c[..., :n]), c[..., :-n]], axis=-1)[..., : x.shape[-1]]
    count = jnp.minimum(jnp.arange(1, x.shape[-1] + 1), n)
    return (c - shifted) / count


def window_mask(t, start, stop=None):
    """Boolean mask of samples with start <= t < stop."""
    m = t >= start
    if stop is not None:
        m = m & (t < stop)
    return m


def settling_time(t, x, final, band, t_event=0.0):
    """Time after ``t_event`` from which |x − final| stays within ``band`` (exact).

    ``final`` and ``band`` are in the units of ``x`` (use band = 0.05·|step|
    for a 5 % band).  Returns 0 if x never leaves the band after the event,
    and ``t[-1] − t_event`` if it has not settled by the end of the record.
    """
    outside = (jnp.abs(x - final) > band) & (t >= t_event)
    idx = jnp.arange(x.shape[-1])
    last_out = jnp.max(jnp.where(outside, idx, -1), axis=-1)
    settled_at = jnp.where(last_out < 0, t_event, t[jnp.minimum(last_out + 1, x.shape[-1] - 1)])
    return settled_at - t_event


def peak_to_peak(x, mask):
    """max − min of ``x`` over the samples where ``mask`` is true."""
    hi = jnp.max(jnp.where(mask, x, -jnp.inf), axis=-1)
    lo = jnp.min(jnp.where(mask, x, jnp.inf), axis=-1)
    return hi - lo


def steady_mean(x, mask):
    return jnp.sum(jnp.where(mask, x, 0.0), axis=-1) / jnp.sum(mask, axis=-1)


def rms(x, mask):
    return jnp.sqrt(steady_mean(x * x, mask))
