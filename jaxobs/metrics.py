"""Metrics on simulated trajectories.

Exact versions for reports; smooth surrogates (``smooth_*``) with a
temperature for gradients, which converge to the exact ones as the temperature
goes to 0 (tests/test_metrics.py).  Angles are electrical and errors are wrapped to
(−π, π].  Bands, windows and event times are arguments, never constants.
All functions act on the last axis (time) and broadcast over leading axes.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ._math import wrap as wrap

__all__ = [
    "wrap",
    "moving_average",
    "settling_time",
    "window_mask",
    "peak_to_peak",
    "steady_mean",
    "rms",
    "overshoot",
    "iae",
    "itae",
    "harmonic_amplitude",
    "flux_offset",
    "flux_imbalance",
    "smooth_max",
    "smooth_abs",
    "smooth_settling_time",
    "smooth_peak_to_peak",
]


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


# --------------------------------------------------------------------------
# more exact metrics
# --------------------------------------------------------------------------


def overshoot(x, final, initial, mask=None):
    """Peak excursion beyond ``final`` in the direction of the step, as a fraction of |final − initial|."""
    step = final - initial
    beyond = (x - final) * jnp.sign(step)
    if mask is not None:
        beyond = jnp.where(mask, beyond, -jnp.inf)
    return jnp.maximum(jnp.max(beyond, axis=-1), 0.0) / jnp.abs(step)


def iae(t, e, t_event=0.0):
    """∫|e| dt after ``t_event`` (rectangle rule on the sample grid)."""
    dt = t[1] - t[0]
    return jnp.sum(jnp.where(t >= t_event, jnp.abs(e), 0.0), axis=-1) * dt


def itae(t, e, t_event=0.0):
    """∫(t − t_event)|e| dt after ``t_event``."""
    dt = t[1] - t[0]
    return jnp.sum(jnp.where(t >= t_event, (t - t_event) * jnp.abs(e), 0.0), axis=-1) * dt


def harmonic_amplitude(t, x, omega, mask=None):
    """Amplitude of the component of ``x`` at angular frequency ``omega`` (DFT over the masked samples).

    Exact for a sinusoid when the window holds whole periods of every component
    present; ``omega = 0`` gives the mean (the dc offset).
    """
    w = jnp.ones_like(x) if mask is None else mask.astype(x.dtype)
    n = jnp.sum(w, axis=-1)
    c = jnp.sum(w * x * jnp.cos(omega * t), axis=-1) / n
    s = jnp.sum(w * x * jnp.sin(omega * t), axis=-1) / n
    return jnp.where(omega == 0, c, 2 * jnp.sqrt(c * c + s * s))


def flux_offset(psi_a, psi_b, mask):
    """dc offset of an estimated flux circle, |mean ψ̂_ab| over the masked samples (whole periods)."""
    return jnp.sqrt(steady_mean(psi_a, mask) ** 2 + steady_mean(psi_b, mask) ** 2)


def flux_imbalance(psi_a, psi_b, mask):
    """Difference of the α and β flux amplitudes (half peak-to-peak each) over the masked samples."""
    return 0.5 * (peak_to_peak(psi_a, mask) - peak_to_peak(psi_b, mask))


# --------------------------------------------------------------------------
# smooth surrogates for gradients (temperature → 0 recovers the exact metric)
# --------------------------------------------------------------------------


def smooth_max(x, temperature, mask=None, axis=-1):
    """temperature·log Σ exp(x/temperature) − temperature·log n: between max − T log n and max."""
    if mask is not None:
        x = jnp.where(mask, x, -jnp.inf)
    n = jnp.sum(jnp.isfinite(x), axis=axis)
    return temperature * (jax.nn.logsumexp(x / temperature, axis=axis) - jnp.log(n))


def smooth_abs(x, eps):
    """√(x² + ε²) − ε: |x| as ε → 0, smooth at 0."""
    return jnp.sqrt(x * x + eps * eps) - eps


def smooth_settling_time(t, x, final, band, t_event=0.0, temperature=None, sharpness=None):
    """Smooth settling time: a soft maximum over samples of (t − t_event)·σ((|x − final| − band)/sharpness).

    As ``temperature`` (s) and ``sharpness`` (units of x) go to 0 it tends to the
    time of the last sample outside the band, i.e. :func:`settling_time` minus
    one sample.  Defaults: temperature = 2 samples, sharpness = band/20.
    """
    dt = t[1] - t[0]
    temperature = 2 * dt if temperature is None else temperature
    sharpness = band / 20 if sharpness is None else sharpness
    outside = jax.nn.sigmoid((jnp.abs(x - final) - band) / sharpness)
    score = (t - t_event) * outside
    return jnp.maximum(smooth_max(score, temperature, mask=t >= t_event), 0.0)


def smooth_peak_to_peak(x, mask, temperature):
    return smooth_max(x, temperature, mask) + smooth_max(-x, temperature, mask)
