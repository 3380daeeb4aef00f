"""Metrics on simulated trajectories.

Exact versions for reports; smooth surrogates (``smooth_*``) with a
temperature for gradients, which converge to the exact ones as the temperature
goes to 0 (tests/test_metrics.py).  Angles are electrical and errors are wrapped to
(−π, π].  Bands, windows and event times are arguments, never constants.
All functions act on the last axis (time) and broadcast over leading axes.

Bad windows and bands.  A window (``mask``, or the samples from ``t_event`` on)
that selects no sample has no metric: with a *concrete* mask (eager calls,
reports) the function raises a ``ValueError``; with a *traced* one (inside
``jit``/``vmap``/``grad``, where nothing can be raised) it returns NaN — the
documented flag, which ``sol.ok``-style checks and ``jnp.isfinite`` catch (a
tuning objective replaces it by its penalty).  Likewise ``settling_time`` and
``smooth_settling_time`` reject a non-finite or negative ``band`` (and a
non-finite ``final``) with a ``ValueError`` when concrete and return NaN when
traced.  A settling time that never settles is capped at the end of the record;
:func:`settled` says which values are censored.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer
from jax.typing import ArrayLike

from ..core.numerics import Real
from ..core.numerics import wrap as wrap
from ..drive.dual_loop import DualOutput
from ..drive.loop import DriveOutput

# The outputs whose truth is the rotor's electrical angle θe (the closed-loop drives: their field theta_e), against
# those whose truth is a signal's (SignalOutput's field truth, or the flux angle of an EMFSignal passed beside).
# Each declares the observer's estimate as its field obs (None without an observer).
_DRIVE_OUTPUTS = (DriveOutput, DualOutput)

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
    "settling_to_steady",
    "smooth_settling_to_steady",
    "settling_to_reference",
    "smooth_settling_to_reference",
    "peak_deviation",
    "smooth_peak_deviation",
    "settled",
]


def _concrete(*xs) -> bool:
    return not any(isinstance(x, Tracer) for x in xs)


def _window(mask, name: str):
    """The number of samples in the window; raises if a concrete window is empty (module doc)."""
    count = jnp.sum(jnp.asarray(mask), axis=-1)
    if _concrete(mask) and np.any(np.asarray(count) == 0):
        raise ValueError(f"{name}: the window (mask) selects no samples; a metric of an empty window is undefined")
    return count


def _after(t, t_event, name: str):
    """Mask t >= t_event; raises if a concrete ``t_event`` is after the last sample."""
    m = t >= t_event
    if _concrete(m) and not np.all(np.any(np.asarray(m), axis=-1)):
        raise ValueError(f"{name}: t_event = {t_event!r} is after the last sample: the window after it is empty")
    return m


def _check_band(name: str, final, band):
    """NaN flag (traced) or ValueError (concrete) for a non-finite or negative band, or a non-finite final."""
    if _concrete(band) and not np.all(np.isfinite(np.asarray(band)) & (np.asarray(band) >= 0)):
        raise ValueError(f"{name}: band must be finite and >= 0 (units of x), got {band!r}")
    if _concrete(final) and not np.all(np.isfinite(np.asarray(final))):
        raise ValueError(f"{name}: final must be finite, got {final!r}")
    return ~(jnp.isfinite(band) & (band >= 0) & jnp.isfinite(final))


def _nan_where(bad, x):
    return jnp.where(bad, jnp.nan, x)


def moving_average(x: jax.Array, n: int) -> jax.Array:
    """Causal moving average over the last ``n`` samples (fewer at the start).

    Args:
        x: The samples, along the last axis.
        n: The window, samples (≥ 1).

    Returns:
        The moving average, shaped like ``x``.

    Raises:
        ValueError: ``n`` < 1.
    """
    if int(n) < 1:
        raise ValueError(f"moving_average window n must be >= 1 samples, got {n!r}")
    n = int(n)
    c = jnp.cumsum(x, axis=-1)
    shifted = jnp.concatenate([jnp.zeros_like(c[..., :n]), c[..., :-n]], axis=-1)[..., : x.shape[-1]]
    count = jnp.minimum(jnp.arange(1, x.shape[-1] + 1), n)
    return (c - shifted) / count


def window_mask(t: jax.Array, start: Real, stop: Real | None = None) -> jax.Array:
    """Boolean mask of samples with start <= t < stop.

    Args:
        t: The sample times, s.
        start: The window's start, s (included).
        stop: The window's end, s (excluded); ``None``: to the end.

    Returns:
        The mask, shaped like ``t``.
    """
    m = t >= start
    if stop is not None:
        m = m & (t < stop)
    return m


def settling_time(t: jax.Array, x: jax.Array, final: Real, band: Real, t_event: Real = 0.0) -> jax.Array:
    """Time after ``t_event`` from which |x − final| stays within ``band`` (exact).

    Args:
        t: The sample times, s.
        x: The signal (samples along the last axis).
        final: The final value, in the units of ``x`` (finite).
        band: The band's half-width, in the units of ``x`` (≥ 0; use band = 0.05·|step| for a 5 % band).
        t_event: The event's time, s.

    Returns:
        The settling time, s: 0 if x never leaves the band after the event, and ``t[-1] − t_event`` if it
        has not settled by the end of the record — a censored value, which :func:`settled` tells apart.
        NaN for a traced bad ``band`` or ``final``.

    Raises:
        ValueError: A concrete non-finite or negative ``band``, a non-finite ``final``, or ``t_event``
            after the last sample.
    """
    bad = _check_band("settling_time", final, band)
    after = _after(t, t_event, "settling_time")
    outside = (jnp.abs(x - final) > band) & after
    idx = jnp.arange(x.shape[-1])
    last_out = jnp.max(jnp.where(outside, idx, -1), axis=-1)
    settled_at = jnp.where(last_out < 0, t_event, t[jnp.minimum(last_out + 1, x.shape[-1] - 1)])
    return _nan_where(bad | ~jnp.any(after, axis=-1), settled_at - t_event)


def settled(
    t: jax.Array,
    x: jax.Array,
    final: Real,
    band: Real,
    t_event: Real = 0.0,
    min_hold: Real = 0.0,
) -> jax.Array:
    """Whether x has settled by the end of the record: after ``t_event`` it enters
    |x − final| <= ``band`` and stays there, ending inside the band for at least ``min_hold`` s.

    False marks :func:`settling_time` values that are censored at the horizon (the
    signal was still outside the band at the last sample, or settled less than
    ``min_hold`` before the end).

    Args:
        t: The sample times, s.
        x: The signal (samples along the last axis).
        final: The final value, in the units of ``x``.
        band: The band's half-width, in the units of ``x`` (≥ 0).
        t_event: The event's time, s.
        min_hold: The least time inside the band at the end, s.

    Returns:
        A bool per scenario (a traced bad band or empty window gives False).

    Raises:
        ValueError: As :func:`settling_time`, for concrete arguments.
    """
    bad = _check_band("settled", final, band)
    after = _after(t, t_event, "settled")
    outside = (jnp.abs(x - final) > band) & after
    idx = jnp.arange(x.shape[-1])
    last_out = jnp.max(jnp.where(outside, idx, -1), axis=-1)
    n = x.shape[-1]
    inside_at_end = last_out < n - 1
    settled_at = jnp.where(last_out < 0, t_event, t[jnp.minimum(last_out + 1, n - 1)])
    hold = t[..., -1] - settled_at
    return inside_at_end & (hold >= min_hold) & ~bad & jnp.any(after, axis=-1)


def peak_to_peak(x: Real, mask: ArrayLike) -> jax.Array:
    """max − min of ``x`` over the samples where ``mask`` is true.

    Args:
        x: The signal (samples along the last axis).
        mask: The window (bool, shaped like ``x``).

    Returns:
        The peak-to-peak value, in the units of ``x`` (NaN for a traced empty window).

    Raises:
        ValueError: A concrete empty window.
    """
    count = _window(mask, "peak_to_peak")
    hi = jnp.max(jnp.where(mask, x, -jnp.inf), axis=-1)
    lo = jnp.min(jnp.where(mask, x, jnp.inf), axis=-1)
    return _nan_where(count == 0, hi - lo)


def steady_mean(x: Real, mask: ArrayLike) -> jax.Array:
    """Mean of ``x`` over the samples where ``mask`` is true.

    Args:
        x: The signal (samples along the last axis).
        mask: The window (bool, shaped like ``x``).

    Returns:
        The mean, in the units of ``x`` (NaN for a traced empty window).

    Raises:
        ValueError: A concrete empty window.
    """
    count = _window(mask, "steady_mean")
    return jnp.sum(jnp.where(mask, x, 0.0), axis=-1) / jnp.where(count == 0, jnp.nan, count)


def rms(x: jax.Array, mask: ArrayLike) -> jax.Array:
    """Root mean square of ``x`` over the samples where ``mask`` is true.

    Args:
        x: The signal (samples along the last axis).
        mask: The window (bool, shaped like ``x``).

    Returns:
        The rms value, in the units of ``x`` (NaN for a traced empty window).

    Raises:
        ValueError: A concrete empty window.
    """
    return jnp.sqrt(steady_mean(x * x, mask))


# --------------------------------------------------------------------------
# more exact metrics
# --------------------------------------------------------------------------


def overshoot(x: Real, final: Real, initial: Real, mask: ArrayLike | None = None) -> jax.Array:
    """Peak excursion beyond ``final`` in the direction of the step, as a fraction of |final − initial|.

    Args:
        x: The signal (samples along the last axis).
        final: The value after the step.
        initial: The value before the step.
        mask: The window to look in (bool, shaped like ``x``); ``None``: every sample.

    Returns:
        The overshoot, ≥ 0 (a fraction; NaN for a traced empty window).

    Raises:
        ValueError: A concrete empty window.
    """
    step = final - initial
    beyond = (x - final) * jnp.sign(step)
    if mask is not None:
        empty = _window(mask, "overshoot") == 0
        beyond = jnp.where(mask, beyond, -jnp.inf)
        return _nan_where(empty, jnp.maximum(jnp.max(beyond, axis=-1), 0.0) / jnp.abs(step))
    return jnp.maximum(jnp.max(beyond, axis=-1), 0.0) / jnp.abs(step)


def iae(t: jax.Array, e: Real, t_event: Real = 0.0) -> jax.Array:
    """∫|e| dt after ``t_event`` (rectangle rule on the sample grid).

    Args:
        t: The sample times, s (uniform).
        e: The error (samples along the last axis).
        t_event: The event's time, s.

    Returns:
        The integral, in the units of ``e`` times s.

    Raises:
        ValueError: ``t_event`` after the last sample (concrete).
    """
    dt = t[1] - t[0]
    after = _after(t, t_event, "iae")
    return _nan_where(~jnp.any(after, axis=-1), jnp.sum(jnp.where(after, jnp.abs(e), 0.0), axis=-1) * dt)


def itae(t: jax.Array, e: Real, t_event: Real = 0.0) -> jax.Array:
    """∫(t − t_event)|e| dt after ``t_event`` (rectangle rule on the sample grid).

    Args:
        t: The sample times, s (uniform).
        e: The error (samples along the last axis).
        t_event: The event's time, s.

    Returns:
        The integral, in the units of ``e`` times s².

    Raises:
        ValueError: ``t_event`` after the last sample (concrete).
    """
    dt = t[1] - t[0]
    after = _after(t, t_event, "itae")
    val = jnp.sum(jnp.where(after, (t - t_event) * jnp.abs(e), 0.0), axis=-1) * dt
    return _nan_where(~jnp.any(after, axis=-1), val)


def harmonic_amplitude(
    t: Real, x: jax.Array | np.ndarray, omega: Real, mask: jax.Array | np.ndarray | None = None
) -> jax.Array:
    """Amplitude of the component of ``x`` at angular frequency ``omega`` (DFT over the masked samples).

    Exact for a sinusoid when the window holds whole periods of every component
    present; ``omega = 0`` gives the mean (the dc offset).

    Args:
        t: The sample times, s.
        x: The signal (samples along the last axis).
        omega: The angular frequency, rad/s.
        mask: The window (bool, shaped like ``x``); ``None``: every sample.

    Returns:
        The amplitude, in the units of ``x``.

    Raises:
        ValueError: A concrete empty window.
    """
    if mask is not None:
        _window(mask, "harmonic_amplitude")
    w = jnp.ones_like(x) if mask is None else mask.astype(x.dtype)
    n = jnp.sum(w, axis=-1)
    n = jnp.where(n == 0, jnp.nan, n)
    c = jnp.sum(w * x * jnp.cos(omega * t), axis=-1) / n
    s = jnp.sum(w * x * jnp.sin(omega * t), axis=-1) / n
    return jnp.where(omega == 0, c, 2 * jnp.sqrt(c * c + s * s))


def flux_offset(psi_a: Real, psi_b: Real, mask: ArrayLike) -> jax.Array:
    """dc offset of an estimated flux circle, |mean ψ̂_ab| over the masked samples (whole periods).

    Args:
        psi_a: ψ̂α, Wb.
        psi_b: ψ̂β, Wb.
        mask: The window (bool; whole periods).

    Returns:
        The offset, Wb.
    """
    return jnp.sqrt(steady_mean(psi_a, mask) ** 2 + steady_mean(psi_b, mask) ** 2)


def flux_imbalance(psi_a: Real, psi_b: Real, mask: ArrayLike) -> jax.Array:
    """Difference of the α and β flux amplitudes (half peak-to-peak each) over the masked samples.

    Args:
        psi_a: ψ̂α, Wb.
        psi_b: ψ̂β, Wb.
        mask: The window (bool).

    Returns:
        The α amplitude minus the β amplitude, Wb.
    """
    return 0.5 * (peak_to_peak(psi_a, mask) - peak_to_peak(psi_b, mask))


# --------------------------------------------------------------------------
# smooth surrogates for gradients (temperature → 0 recovers the exact metric)
# --------------------------------------------------------------------------


def smooth_max(x: Real, temperature: Real, mask: ArrayLike | None = None, axis: int = -1) -> jax.Array:
    """temperature·log Σ exp(x/temperature) − temperature·log n: between max − T log n and max.

    Args:
        x: The values.
        temperature: T, in the units of ``x`` (> 0); T → 0 recovers the maximum.
        mask: The samples to take (bool, shaped like ``x``); ``None``: every one.
        axis: The axis reduced.

    Returns:
        The soft maximum (NaN where no sample is taken).

    Raises:
        ValueError: A concrete empty mask.
    """
    if mask is not None:
        _window(jnp.moveaxis(jnp.asarray(mask), axis, -1) if _concrete(mask) else mask, "smooth_max")
        x = jnp.where(mask, x, -jnp.inf)
    n = jnp.sum(jnp.isfinite(x), axis=axis)
    val = temperature * (jax.nn.logsumexp(x / temperature, axis=axis) - jnp.log(n))
    return _nan_where(n == 0, val)


def smooth_abs(x: Real, eps: Real) -> jax.Array:
    """√(x² + ε²) − ε: |x| as ε → 0, smooth at 0.

    Args:
        x: The values.
        eps: ε, in the units of ``x``.

    Returns:
        The smooth |x|, shaped like ``x``.
    """
    return jnp.sqrt(x * x + eps * eps) - eps


def smooth_settling_time(
    t: jax.Array,
    x: Real,
    final: Real,
    band: Real,
    t_event: Real = 0.0,
    temperature: Real | None = None,
    sharpness: Real | None = None,
) -> jax.Array:
    """Smooth settling time: a soft maximum over samples of (t − t_event)·σ((|x − final| − band)/sharpness).

    As ``temperature`` and ``sharpness`` go to 0 it tends to the
    time of the last sample outside the band, i.e. :func:`settling_time` minus
    one sample.

    Args:
        t: The sample times, s.
        x: The signal (samples along the last axis).
        final: The final value, in the units of ``x``.
        band: The band's half-width, in the units of ``x`` (≥ 0).
        t_event: The event's time, s.
        temperature: The soft maximum's temperature, s (default 2 samples).
        sharpness: The sigmoid's width, in the units of ``x`` (default band/20).

    Returns:
        The smooth settling time, s (NaN for a traced bad band).

    Raises:
        ValueError: As :func:`settling_time`, for concrete arguments.
    """
    bad = _check_band("smooth_settling_time", final, band)
    after = _after(t, t_event, "smooth_settling_time")
    dt = t[1] - t[0]
    temperature = 2 * dt if temperature is None else temperature
    sharpness = band / 20 if sharpness is None else sharpness
    outside = jax.nn.sigmoid((jnp.abs(x - final) - band) / sharpness)
    score = (t - t_event) * outside
    return _nan_where(bad, jnp.maximum(smooth_max(score, temperature, mask=after), 0.0))


def smooth_peak_to_peak(x: jax.Array, mask: ArrayLike, temperature: Real) -> jax.Array:
    """Smooth max − min of ``x`` over the samples where ``mask`` is true: :func:`smooth_max` of ``x`` and of ``−x``.

    Args:
        x: The signal (samples along the last axis).
        mask: The window (bool, shaped like ``x``).
        temperature: The soft maxima's temperature, in the units of ``x`` (> 0).

    Returns:
        The smooth peak-to-peak value, in the units of ``x`` (NaN for a traced empty window).

    Raises:
        ValueError: A concrete empty window.
    """
    return smooth_max(x, temperature, mask) + smooth_max(-x, temperature, mask)


# --------------------------------------------------------------------------
# drive metrics that measure what their names say: a settling to the signal's own final value,
# the true speed against its reference, the peak deviation after a load step
# --------------------------------------------------------------------------


def _own_final(x, steady_mask, name):
    """The signal's own final value, its mean over ``steady_mask``, and whether it is unusable (not finite)."""
    _window(steady_mask, name)  # a concrete empty window raises, naming the caller (module doc)
    final = steady_mean(x, steady_mask)
    bad = ~jnp.isfinite(final)
    return jnp.where(bad, 0.0, final), bad


def settling_to_steady(
    t: jax.Array, x: jax.Array, band: Real, steady_mask: ArrayLike, t_event: Real = 0.0
) -> jax.Array:
    """Time after ``t_event`` from which x stays within ``band`` of its *own* final value (exact).

    The final value is the mean of x over ``steady_mask`` (the steady window), so a signal that settles
    to a bias settles: an observer's steady angle lag (the C-LESO's 11–37° on the IPMSM bench) is not a
    failure to settle.  Report the bias apart, ``steady_mean(x, steady_mask)``.

    Args:
        t: The sample times, s.
        x: The signal (samples along the last axis).
        band: The band's half-width, in the units of ``x``.
        steady_mask: The steady window (bool).
        t_event: The event's time, s.

    Returns:
        The settling time, s; censored at ``t[-1] − t_event`` as :func:`settling_time`; NaN where x is not
        finite in the window.

    Raises:
        ValueError: A concrete empty window, or as :func:`settling_time`.
    """
    final, bad = _own_final(x, steady_mask, "settling_to_steady")
    return _nan_where(bad, settling_time(t, x, final, band, t_event))


def smooth_settling_to_steady(
    t: jax.Array,
    x: jax.Array,
    band: Real,
    steady_mask: ArrayLike,
    t_event: Real = 0.0,
    temperature: Real | None = None,
    sharpness: Real | None = None,
) -> jax.Array:
    """:func:`settling_to_steady` through :func:`smooth_settling_time` (the final value is a smooth mean too).

    Args:
        t: The sample times, s.
        x: The signal (samples along the last axis).
        band: The band's half-width, in the units of ``x``.
        steady_mask: The steady window (bool).
        t_event: The event's time, s.
        temperature: The soft maximum's temperature, s (default 2 samples).
        sharpness: The sigmoid's width, in the units of ``x`` (default band/20).

    Returns:
        The smooth settling time, s (NaN where x is not finite in the window).
    """
    final, bad = _own_final(x, steady_mask, "smooth_settling_to_steady")
    return _nan_where(bad, smooth_settling_time(t, x, final, band, t_event, temperature, sharpness))


def settling_to_reference(t: jax.Array, x: jax.Array, ref: Real, band: Real, t_event: Real = 0.0) -> jax.Array:
    """Time after ``t_event`` from which |x − ref| stays within ``band`` (exact).

    A quantity against its reference, e.g. the drive's true speed ωm against ωm* after a speed step.  After
    a load step it is the *recovery time*: from the step until the speed is back within the band for good.

    Args:
        t: The sample times, s.
        x: The signal (samples along the last axis).
        ref: The reference, a signal or a constant in the units of ``x``.
        band: The band's half-width, in the units of ``x``.
        t_event: The event's time, s.

    Returns:
        The settling time, s; censored at ``t[-1] − t_event`` as :func:`settling_time`.
    """
    return settling_time(t, x - ref, 0.0, band, t_event)


def smooth_settling_to_reference(
    t: jax.Array,
    x: jax.Array,
    ref: Real,
    band: Real,
    t_event: Real = 0.0,
    temperature: Real | None = None,
    sharpness: Real | None = None,
) -> jax.Array:
    """:func:`settling_to_reference` through :func:`smooth_settling_time`.

    Args:
        t: The sample times, s.
        x: The signal (samples along the last axis).
        ref: The reference, a signal or a constant in the units of ``x``.
        band: The band's half-width, in the units of ``x``.
        t_event: The event's time, s.
        temperature: The soft maximum's temperature, s (default 2 samples).
        sharpness: The sigmoid's width, in the units of ``x`` (default band/20).

    Returns:
        The smooth settling time, s.
    """
    return smooth_settling_time(t, x - ref, 0.0, band, t_event, temperature, sharpness)


def peak_deviation(t: jax.Array, x: Real, ref: Real, t_event: Real = 0.0) -> jax.Array:
    """max |x − ref| after ``t_event`` (exact): the speed dip (or rise) after a load step.

    Args:
        t: The sample times, s.
        x: The signal (samples along the last axis).
        ref: The reference, a signal or a constant in the units of ``x``.
        t_event: The event's time, s.

    Returns:
        The peak deviation, in the units of ``x``.

    Raises:
        ValueError: ``t_event`` after the last sample (concrete).
    """
    after = _after(t, t_event, "peak_deviation")
    dev = jnp.max(jnp.where(after, jnp.abs(x - ref), -jnp.inf), axis=-1)
    return _nan_where(~jnp.any(after, axis=-1), dev)


def smooth_peak_deviation(t: jax.Array, x: Real, ref: Real, t_event: Real = 0.0, temperature: Real = 1e-3) -> jax.Array:
    """:func:`peak_deviation` as a soft maximum of a smooth |x − ref| (ε = ``temperature``).

    Within ``temperature``·(1 + log n) below the exact peak, n the samples after the event.

    Args:
        t: The sample times, s.
        x: The signal (samples along the last axis).
        ref: The reference, a signal or a constant in the units of ``x``.
        t_event: The event's time, s.
        temperature: The soft maximum's temperature and the smooth |·|'s ε, in the units of ``x``.

    Returns:
        The smooth peak deviation, in the units of ``x``.
    """
    after = _after(t, t_event, "smooth_peak_deviation")
    return smooth_max(smooth_abs(x - ref, temperature), temperature, mask=after)
