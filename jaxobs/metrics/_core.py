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

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..core.numerics import wrap as wrap
from ..drive.dual_loop import DualOutput
from ..drive.loop import DriveOutput
from ..runtime.simulation import SignalOutput, Solution
from ..signals import AbstractSignal

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
    "lost_lock",
    "lost_lock_of",
    "position_error",
    "lost_speed",
    "SPEED_TOL",
    "SPEED_FLOOR_RPM",
    "LOCK_TOL_DEG",
    "LOCK_TOL_DRIVE_DEG",
    "LOCK_FREQ_TOL",
]


def _concrete(*xs) -> bool:
    return not any(isinstance(x, jax.core.Tracer) for x in xs)


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


def moving_average(x, n: int):
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


def window_mask(t, start, stop=None):
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


def settling_time(t, x, final, band, t_event=0.0):
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


def settled(t, x, final, band, t_event=0.0, min_hold=0.0):
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


def peak_to_peak(x, mask):
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


def steady_mean(x, mask):
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


def rms(x, mask):
    return jnp.sqrt(steady_mean(x * x, mask))


# --------------------------------------------------------------------------
# more exact metrics
# --------------------------------------------------------------------------


def overshoot(x, final, initial, mask=None):
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


def iae(t, e, t_event=0.0):
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


def itae(t, e, t_event=0.0):
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


def harmonic_amplitude(t, x, omega, mask=None):
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


def flux_offset(psi_a, psi_b, mask):
    """dc offset of an estimated flux circle, |mean ψ̂_ab| over the masked samples (whole periods).

    Args:
        psi_a: ψ̂α, Wb.
        psi_b: ψ̂β, Wb.
        mask: The window (bool; whole periods).

    Returns:
        The offset, Wb.
    """
    return jnp.sqrt(steady_mean(psi_a, mask) ** 2 + steady_mean(psi_b, mask) ** 2)


def flux_imbalance(psi_a, psi_b, mask):
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


def smooth_max(x, temperature, mask=None, axis=-1):
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


def smooth_abs(x, eps):
    """√(x² + ε²) − ε: |x| as ε → 0, smooth at 0.

    Args:
        x: The values.
        eps: ε, in the units of ``x``.

    Returns:
        The smooth |x|, shaped like ``x``.
    """
    return jnp.sqrt(x * x + eps * eps) - eps


def smooth_settling_time(t, x, final, band, t_event=0.0, temperature=None, sharpness=None):
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


# What "lost lock" means, one definition for simulations, tuning and studies (README, "Lost lock").
# An estimate has lost lock when, over the final (steady) window of the run, it is far from the truth:
# - its angle error |wrap(θ̂ − θ)| exceeds the tolerance at some sample: LOCK_TOL_DEG = 45° for an estimate
#   on a signal (the FLL family on grid signals, flux observers on a back EMF): a locked FLL stays within a
#   few degrees even under 001 Test C's distortion, a slip or a false lock sweeps through every angle;
#   LOCK_TOL_DRIVE_DEG = 90° electrical for a drive observer in the closed loop: beyond 90° the current
#   vector brakes the machine (synchronism is lost), while a drive with a biased estimate (the C-LESO's
#   lag, 23° at 600 r/min; an Lq mismatch) still runs;
# - or, on a signal, its mean frequency error over the window exceeds LOCK_FREQ_TOL = 10 % of the true
#   frequency: there θ̂ comes from filters (θ̂ = atan2(qv', v')), not from integrating ω̂, so a wrong ω̂
#   can sit beside a bounded angle error (a band-pass tuned to 115 rad/s fed 326.7 rad/s).  On the drive
#   θ̂ is the PLL's (or the flux's) own angle, whose bounded error bounds the mean speed error already;
# - or any of them is not finite (a diverged run has lost lock).
LOCK_TOL_DEG = 45.0
LOCK_TOL_DRIVE_DEG = 90.0
LOCK_FREQ_TOL = 0.10


def lost_lock(theta_hat, theta, window_mask, tol_rad=math.pi / 4, *, omega_hat=None, omega=None, freq_tol=None):
    """Whether an estimate has lost lock: |wrap(θ̂ − θ)| > ``tol_rad`` somewhere in the final window
    (and, with ``omega_hat``, ``omega`` and ``freq_tol``, the window's mean |ω̂ − ω| > ``freq_tol`` × mean |ω|).

    ``window_mask`` marks the final (steady) window, e.g. ``window_mask(t, t1 − 0.1)``.  A locked
    estimate stays within a few degrees of the truth there, even under distortion; one that slips
    cycles, locks to the wrong frequency or diverges (NaN counts as far) sweeps through every angle.
    The default tolerance, 45° (π/4 rad, :data:`LOCK_TOL_DEG`), is far above any locked steady error
    of the FLL family and far below a slip (the definition: the comment above).

    Args:
        theta_hat: The estimated angle θ̂, rad.
        theta: The true angle θ, rad.
        window_mask: The final (steady) window (bool).
        tol_rad: The angle tolerance, rad.
        omega_hat: The estimated frequency ω̂, rad/s (for the frequency test).
        omega: The true frequency ω, rad/s (for the frequency test).
        freq_tol: The frequency tolerance, a fraction of the mean |ω|; ``None``: no frequency test.

    Returns:
        A bool per scenario (leading axes); a traced empty window gives True (lock cannot be confirmed).

    Raises:
        ValueError: A concrete empty window, or ``freq_tol`` without ``omega_hat`` and ``omega``.
    """
    count = _window(window_mask, "lost_lock")
    near = jnp.abs(wrap(theta_hat - theta)) <= tol_rad  # False for NaN
    lost = jnp.any(window_mask & ~near, axis=-1) | (count == 0)
    if freq_tol is not None:
        if omega_hat is None or omega is None:
            raise ValueError("lost_lock: freq_tol needs omega_hat and omega")
        n = jnp.maximum(count, 1)
        err = jnp.sum(jnp.where(window_mask, omega_hat - omega, 0.0), axis=-1) / n
        ref = jnp.sum(jnp.where(window_mask, jnp.abs(omega), 0.0), axis=-1) / n
        lost = lost | ~(jnp.abs(err) <= freq_tol * ref)  # NaN: lost
    return lost


# A drive that does not follow its speed reference ("lost speed"), a per-scenario flag beside lost lock: over
# the steady window, the mean |ωm − ωm*| exceeds SPEED_TOL × the mean |ωm*| (at least SPEED_FLOOR_RPM, so a
# near-zero reference is not flagged by noise), or a value is not finite.  It catches what lost lock cannot:
# an observer that tracks a rotor turning the wrong way (a standstill start under a load the I-f start-up
# cannot carry runs backwards with a locked observer: |ωm − ωm*| > 100 % of ωm*), a speed stuck far from
# its reference, and a large speed limit cycle.  20 %: far above a locked drive's speed ripple and
# load-step dips after the steady window begins (≤ 1 % measured on the presets), far below a reversal.
SPEED_TOL = 0.20
SPEED_FLOOR_RPM = 20.0


def lost_speed(omega_m, omega_m_ref, window_mask, rel_tol=SPEED_TOL, floor_rpm=SPEED_FLOOR_RPM):
    """Whether a drive lost its speed: the window's mean |ωm − ωm*| > max(``rel_tol`` × mean |ωm*|,
    ``floor_rpm``), or it is not finite.

    Args:
        omega_m: The mechanical speed ωm, rad/s.
        omega_m_ref: The speed reference ωm*, rad/s.
        window_mask: The steady window (bool).
        rel_tol: The tolerance, a fraction of the mean |ωm*|.
        floor_rpm: The least tolerance, r/min.

    Returns:
        A bool per scenario (leading axes); a traced empty window gives True.

    Raises:
        ValueError: A concrete empty window.
    """
    count = _window(window_mask, "lost_speed")
    n = jnp.maximum(count, 1)
    err = jnp.sum(jnp.where(window_mask, jnp.abs(omega_m - omega_m_ref), 0.0), axis=-1) / n
    ref = jnp.sum(jnp.where(window_mask, jnp.abs(omega_m_ref), 0.0), axis=-1) / n
    tol = jnp.maximum(rel_tol * ref, floor_rpm * math.pi / 30)
    return ~(err <= tol) | (count == 0)  # NaN: lost


def lost_lock_of(sol, steady_from=None, *, signal=None, tol_deg=None, freq_tol=LOCK_FREQ_TOL):
    """The lost-lock flag of a simulation (:func:`jaxobs.simulate` with ``SaveAll``): True where the
    observer's estimate is far from the truth over the final window ``t >= steady_from`` (default: the
    last quarter of the record); the definition and tolerances are :func:`lost_lock`'s (module
    constants :data:`LOCK_TOL_DEG`, :data:`LOCK_TOL_DRIVE_DEG`, :data:`LOCK_FREQ_TOL`).

    - an observer on a signal that reports its truth (``OnSignal`` on a ``GridSignal``): θ̂ against the
      true phase (45°) and ω̂ against the true frequency (10 %);
    - an observer on an ``EMFSignal`` (no truth in the outputs): pass ``signal=`` the EMFSignal; θ̂ against
      its rotor-flux angle ω1 t + φ1 − π/2, ω̂ against ω1;
    - the closed-loop drive (``ClosedLoop`` with an observer): θ̂e against θe (90° electrical).

    Works under ``jit``/``vmap``.  It reads the outputs only: the solution, and ``simulate``, are unchanged.

    Args:
        sol: The :class:`~jaxobs.Solution` (saved with ``SaveAll``).
        steady_from: The start of the final window, s (default: the last quarter of the record).
        signal: The :class:`~jaxobs.signals.EMFSignal` an observer ran on (its flux angle is the truth).
        tol_deg: The angle tolerance, degrees (default :data:`LOCK_TOL_DEG`, or
            :data:`LOCK_TOL_DRIVE_DEG` for a drive).
        freq_tol: The frequency tolerance, a fraction of the true frequency; ``None`` drops the frequency test.

    Returns:
        A bool per scenario.

    Raises:
        ValueError: No trajectory or no observer estimate in ``sol``, or no truth to compare with.
    """
    out = _estimated(sol, "lost_lock_of")
    t = sol.t
    if steady_from is None:
        steady_from = t[..., 0] + 0.75 * (t[..., -1] - t[..., 0])
        mask = t >= jnp.expand_dims(steady_from, -1)
    else:
        mask = t >= steady_from
    obs = out.obs
    if isinstance(out, _DRIVE_OUTPUTS):
        tol = LOCK_TOL_DRIVE_DEG if tol_deg is None else tol_deg
        return lost_lock(obs.theta, out.theta_e, mask, math.radians(tol))
    tol = math.radians(LOCK_TOL_DEG if tol_deg is None else tol_deg)
    theta, omega = _truth(sol, signal, "lost_lock_of")
    if freq_tol is None:
        return lost_lock(obs.theta, theta, mask, tol)
    return lost_lock(obs.theta, theta, mask, tol, omega_hat=obs.omega, omega=omega, freq_tol=freq_tol)


def _estimated(sol, caller):
    """The outputs of a trajectory that hold an observer's estimate: an observer on a signal's
    (:class:`~jaxobs.SignalOutput`) or a closed-loop drive's with an observer; a ValueError otherwise."""
    if not isinstance(sol, Solution) or sol.outputs is None:
        raise ValueError(f"{caller}: needs the trajectory (simulate with save=SaveAll(), the default)")
    out = sol.outputs
    if not isinstance(out, (SignalOutput, *_DRIVE_OUTPUTS)) or out.obs is None:
        raise ValueError(f"{caller}: the outputs hold no observer estimate (obs.theta): nothing to compare")
    return out


def _truth(sol, signal, caller):
    """The true angle (rad) and frequency (rad/s) of an observer on a signal: the outputs' own ``truth`` (a
    ``GridSignal`` or a recording), else ``signal=``'s rotor-flux angle ω1 t + φ1 − π/2 (an ``EMFSignal``:
    ψ lags e by 90°)."""
    truth = sol.outputs.truth
    if truth is not None:
        return truth.theta, truth.omega
    if not (isinstance(signal, AbstractSignal) and signal.has_flux_angle):
        raise ValueError(
            f"{caller}: the signal reports no truth; pass signal= an EMFSignal (its flux angle is the truth)"
        )
    return signal.flux_angle(sol.t), signal.flux_omega(sol.t)


def position_error(sol, signal=None):
    """The observer's position error θ̂ − θ (rad, wrapped to (−π, π]) along a simulation's trajectory.

    The truth is the rotor's electrical angle θe for the closed-loop drives (``ClosedLoop``,
    ``DualClosedLoop``), the outputs' ``truth`` for an observer on a signal that reports one (a
    ``GridSignal``, a recording with its encoder angle), else the rotor-flux angle of ``signal=`` (an
    ``EMFSignal``).  Works under ``jit``/``vmap``.

    Args:
        sol: The :class:`~jaxobs.Solution` (saved with ``SaveAll``).
        signal: The :class:`~jaxobs.signals.EMFSignal` an observer ran on, where the outputs carry no truth.

    Returns:
        θ̂ − θ along the trajectory, rad.

    Raises:
        ValueError: No trajectory or no observer estimate in ``sol``, or no truth to compare with.
    """
    out = _estimated(sol, "position_error")
    if isinstance(out, _DRIVE_OUTPUTS):
        return wrap(out.obs.theta - out.theta_e)
    theta, _ = _truth(sol, signal, "position_error")
    return wrap(out.obs.theta - theta)


def smooth_peak_to_peak(x, mask, temperature):
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


def settling_to_steady(t, x, band, steady_mask, t_event=0.0):
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


def smooth_settling_to_steady(t, x, band, steady_mask, t_event=0.0, temperature=None, sharpness=None):
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


def settling_to_reference(t, x, ref, band, t_event=0.0):
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


def smooth_settling_to_reference(t, x, ref, band, t_event=0.0, temperature=None, sharpness=None):
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


def peak_deviation(t, x, ref, t_event=0.0):
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


def smooth_peak_deviation(t, x, ref, t_event=0.0, temperature=1e-3):
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
