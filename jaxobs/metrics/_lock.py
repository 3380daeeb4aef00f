"""Lost lock and lost speed, the per-scenario flags of a run, and the position error of a simulation: an estimate
against its truth (the rotor's electrical angle for the closed-loop drives, the signal's own truth or an
``EMFSignal``'s flux angle for an observer on a signal).  The conventions of :mod:`jaxobs.metrics._core` hold
(concrete empty windows raise, traced ones flag).
"""

from __future__ import annotations

import math
from typing import cast

import jax
import jax.numpy as jnp

from ..core.numerics import Real, wrap
from ..drive.scenario import Scenario
from ..runtime.simulation import SignalOutput, Solution
from ..signals import AbstractSignal
from ._core import _DRIVE_OUTPUTS, _window

__all__ = [
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


def lost_lock(
    theta_hat: Real,
    theta: Real,
    window_mask: jax.Array,
    tol_rad: float = math.pi / 4,
    *,
    omega_hat: Real | None = None,
    omega: Real | None = None,
    freq_tol: float | None = None,
) -> jax.Array:
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
# load-step dips after the steady window begins (docs/performance.md), far below a reversal.
SPEED_TOL = 0.20
SPEED_FLOOR_RPM = 20.0


def lost_speed(
    omega_m: Real,
    omega_m_ref: Real,
    window_mask: jax.Array,
    rel_tol: float = SPEED_TOL,
    floor_rpm: float = SPEED_FLOOR_RPM,
) -> jax.Array:
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


def lost_lock_of(
    sol: Solution,
    steady_from: Real | None = None,
    *,
    signal: AbstractSignal | Scenario | None = None,
    tol_deg: float | None = None,
    freq_tol: float | None = LOCK_FREQ_TOL,
) -> jax.Array:
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
        signal: The scenario the run was simulated on; read only where the outputs carry no truth, and then
            it must be an :class:`~jaxobs.signals.EMFSignal` (its flux angle is the truth).
        tol_deg: The angle tolerance, degrees (default :data:`LOCK_TOL_DEG`, or
            :data:`LOCK_TOL_DRIVE_DEG` for a drive).
        freq_tol: The frequency tolerance, a fraction of the true frequency; ``None`` drops the frequency test.

    Returns:
        A bool per scenario.

    Raises:
        ValueError: No trajectory or no observer estimate in ``sol``, or no truth to compare with.
    """
    out = _estimated(sol, "lost_lock_of")
    t = cast(jax.Array, sol.t)  # saved with the outputs, which _estimated found
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


def position_error(sol: Solution, signal: AbstractSignal | Scenario | None = None) -> jax.Array:
    """The observer's position error θ̂ − θ (rad, wrapped to (−π, π]) along a simulation's trajectory.

    The truth is the rotor's electrical angle θe for the closed-loop drives (``ClosedLoop``,
    ``DualClosedLoop``), the outputs' ``truth`` for an observer on a signal that reports one (a
    ``GridSignal``, a recording with its encoder angle), else the rotor-flux angle of ``signal=`` (an
    ``EMFSignal``).  Works under ``jit``/``vmap``.

    Args:
        sol: The :class:`~jaxobs.Solution` (saved with ``SaveAll``).
        signal: The scenario the run was simulated on; read only where the outputs carry no truth, and then
            it must be an :class:`~jaxobs.signals.EMFSignal` (its flux angle is the truth).

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
