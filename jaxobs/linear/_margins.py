"""Frequency responses and stability margins of transfer functions (:mod:`jaxobs.linear._tf`).

Everything here is a JAX function of the coefficients, so frequency responses, margins and crossovers are
differentiable with respect to gains.  Crossover frequencies are found by ``optimistix.root_find`` (Newton), so
their gradients come by implicit differentiation, not through the iterations.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from ..core.validate import as_float
from ._tf import TransferFunction

__all__ = ["Margins", "margins", "bode"]


def bode(tf: TransferFunction, omega: ArrayLike, *, convention: str = "db-deg") -> tuple[jax.Array, ...]:
    """G(jω) on the grid ``omega`` (rad/s): magnitude (dB) and unwrapped phase (deg) by default.

    Args:
        tf: The :class:`TransferFunction`.
        omega: The grid, rad/s.
        convention: ``"db-deg"``, or ``"control"``: python-control's form (absolute magnitude, unwrapped
            phase in rad, and ω), as ``control.frequency_response``/``bode_plot`` give them.

    Returns:
        ``(magnitude in dB, phase in deg)``, or ``(magnitude, phase in rad, omega)`` with ``"control"``.

    Raises:
        ValueError: An unknown ``convention``.
    """
    if convention not in ("db-deg", "control"):
        raise ValueError(f"bode: convention must be 'db-deg' or 'control', got {convention!r}")
    omega = as_float(omega)
    g = tf.freqresp(omega)
    phase = jnp.unwrap(jnp.angle(g))
    if convention == "control":
        return jnp.abs(g), phase, omega
    return 20 * jnp.log10(jnp.abs(g)), jnp.degrees(phase)


class Margins(eqx.Module):
    """The margins of a loop (:func:`margins`).

    Attributes:
        gain_margin: |1/L(jω₁₈₀)| (inf if the phase never crosses −180°).
        phase_margin: deg, mod(∠L(jω_c), 360) − 180 (inf if |L| never crosses 1).
        omega_gc: The gain crossover, rad/s (nan if none).
        omega_pc: The phase crossover, rad/s (nan if none).
    """

    gain_margin: jax.Array  # |1/L(jω₁₈₀)| (inf if the phase never crosses −180°)
    phase_margin: jax.Array  # deg, mod(∠L(jω_c), 360) − 180 (inf if |L| never crosses 1)
    omega_gc: jax.Array  # gain crossover, rad/s (nan if none)
    omega_pc: jax.Array  # phase crossover, rad/s (nan if none)

    def __repr__(self) -> str:
        """The margins as numbers (``Margins(gain_margin=2.5, phase_margin=45.1 deg, ...)``); batched or traced
        margins print as equinox prints a module (their shapes)."""
        try:
            v = [float(x) for x in (self.gain_margin, self.phase_margin, self.omega_gc, self.omega_pc)]
        except (TypeError, jax.errors.ConcretizationTypeError):  # a batch (not a scalar), or a tracer
            return eqx.tree_pformat(self)
        return (
            f"Margins(gain_margin={v[0]:.6g}, phase_margin={v[1]:.6g} deg, "
            f"omega_gc={v[2]:.6g} rad/s, omega_pc={v[3]:.6g} rad/s)"
        )


def _default_grid(tf: TransferFunction, n: int) -> jax.Array:
    """Log-spaced grid wide enough to hold every crossover.

    Spans two decades beyond the finite, non-zero poles and zeros, and beyond
    where the high- and low-frequency asymptotes (K/s^r above the last corner,
    K'/s^m below the first with m integrators) reach unit gain.
    """
    pol, zer = jnp.abs(tf.poles()), jnp.abs(tf.zeros())
    mags = jnp.concatenate([pol, zer])
    scale = jnp.maximum(jnp.max(mags), 1.0)
    nonzero = mags > 1e-9 * scale
    lo = jnp.min(jnp.where(nonzero, mags, jnp.inf))
    hi = jnp.max(jnp.where(nonzero, mags, 0.0))
    r = tf.den.shape[0] - tf.num.shape[0]  # relative degree (leading coefficients assumed non-zero)
    if r > 0:
        c_hi = jnp.abs(tf.num[0] / tf.den[0]) ** (1.0 / r)
        hi = jnp.maximum(hi, c_hi)
        lo = jnp.minimum(lo, c_hi)
    m = jnp.sum(pol <= 1e-9 * scale)  # integrators
    den_last = tf.den[::-1][jnp.minimum(m, tf.den.shape[0] - 1)]
    c_lo = jnp.abs(tf.num[-1] / den_last) ** (1.0 / jnp.maximum(m, 1))
    c_lo = jnp.where((m > 0) & jnp.isfinite(c_lo) & (c_lo > 0), c_lo, lo)
    lo = jnp.minimum(lo, c_lo)
    hi = jnp.maximum(hi, c_lo)
    lo = jnp.where(jnp.isfinite(lo) & (lo > 0), lo, 1e-3) / 100.0
    hi = jnp.where(jnp.isfinite(hi) & (hi > 0), hi, 1e3) * 100.0
    return jnp.exp(jnp.linspace(jnp.log(lo), jnp.log(hi), n))


def _refine(fn: Callable[[jax.Array, Any], jax.Array], x0: jax.Array, args: Any) -> jax.Array:
    """Newton on x = log ω from each candidate, with gradients by implicit differentiation.  optimistix is imported
    here, where a margin is first traced: with it come lineax and half a second that a program computing no
    margin (``jaxobs drive check``) need not pay."""
    import optimistix as optx

    solver = optx.Newton(rtol=1e-12, atol=1e-12)

    def one(x: jax.Array) -> jax.Array:
        return optx.root_find(fn, solver, x, args, max_steps=64, throw=False).value

    return jax.vmap(one)(x0)


def margins(
    loop: TransferFunction, *, grid_size: int = 4000, max_crossings: int = 8, omega: ArrayLike | None = None
) -> Margins:
    """Gain and phase margins of the unity-feedback loop ``loop`` (real coefficients).

    Conventions follow python-control's ``stability_margins``: every gain
    crossover gives PM = mod(∠L, 360°) − 180° and the one of least |PM| is
    reported; every phase crossover (L(jω) real and negative) gives
    GM = 1/|L| and the one of least |log GM| is reported.  Candidates come from
    sign changes on a log grid, each refined by an optimistix Newton root find in log ω.

    Args:
        loop: The loop L(s) (real coefficients).
        grid_size: The log grid's points.
        max_crossings: The most crossings of each kind refined.
        omega: The grid, rad/s (overrides the log grid).

    Returns:
        The :class:`Margins`.
    """
    w = _default_grid(jax.lax.stop_gradient(loop), grid_size) if omega is None else as_float(omega)
    # The grid only seeds the Newton root finds; the crossovers' derivatives come from
    # implicit differentiation of the root conditions, so the grid (built from the
    # eigenvalues of the companion matrices, whose higher derivatives JAX refuses) is
    # deliberately held constant.  Gradients w.r.t. the coefficients are unaffected.
    w = jax.lax.stop_gradient(w)
    x = jnp.log(w)
    num, den = loop.num, loop.den

    def L(xx: jax.Array, nd: tuple[jax.Array, jax.Array]) -> jax.Array:
        n_, d_ = nd
        s = 1j * jnp.exp(xx)
        return jnp.polyval(n_, s) / jnp.polyval(d_, s)

    def log_mag(xx: jax.Array, nd: tuple[jax.Array, jax.Array]) -> jax.Array:
        return jnp.log(jnp.abs(L(xx, nd)))

    def sin_phase_neg(xx: jax.Array, nd: tuple[jax.Array, jax.Array]) -> jax.Array:
        # zero where L is real; Im(L)/|L| = sin ∠L
        g = L(xx, nd)
        return jnp.imag(g) / jnp.abs(g)

    nd = (num, den)
    g_grid = loop.freqresp(w)

    # --- gain crossovers
    lm = jnp.log(jnp.abs(g_grid))
    gc_idx = jnp.nonzero(jnp.sign(lm[:-1]) != jnp.sign(lm[1:]), size=max_crossings, fill_value=-1)[0]
    gc_valid = gc_idx >= 0
    first = jnp.where(jnp.any(gc_valid), gc_idx[0], 0)
    x0 = jnp.where(gc_valid, x[jnp.maximum(gc_idx, 0)], x[first])
    xgc = _refine(log_mag, x0, nd)
    pm_all = jnp.remainder(jnp.degrees(jnp.angle(L(xgc, nd))), 360.0) - 180.0
    pm_key = jnp.where(gc_valid, jnp.abs(pm_all), jnp.inf)
    i_pm = jnp.argmin(pm_key)
    has_gc = jnp.any(gc_valid)
    pm = jnp.where(has_gc, pm_all[i_pm], jnp.inf)
    w_gc = jnp.where(has_gc, jnp.exp(xgc[i_pm]), jnp.nan)

    # --- phase crossovers (Im L changes sign where Re L < 0)
    sp = jnp.imag(g_grid)
    neg = jnp.real(g_grid) < 0
    pc_mask = (jnp.sign(sp[:-1]) != jnp.sign(sp[1:])) & (neg[:-1] | neg[1:])
    pc_idx = jnp.nonzero(pc_mask, size=max_crossings, fill_value=-1)[0]
    pc_valid = pc_idx >= 0
    firstp = jnp.where(jnp.any(pc_valid), pc_idx[0], 0)
    x0p = jnp.where(pc_valid, x[jnp.maximum(pc_idx, 0)], x[firstp])
    xpc = _refine(sin_phase_neg, x0p, nd)
    gpc = L(xpc, nd)
    pc_valid = pc_valid & (jnp.real(gpc) < 0)
    gm_all = 1.0 / jnp.abs(gpc)
    gm_key = jnp.where(pc_valid, jnp.abs(jnp.log(gm_all)), jnp.inf)
    i_gm = jnp.argmin(gm_key)
    has_pc = jnp.any(pc_valid)
    gm = jnp.where(has_pc, gm_all[i_gm], jnp.inf)
    w_pc = jnp.where(has_pc, jnp.exp(xpc[i_gm]), jnp.nan)
    return Margins(gain_margin=gm, phase_margin=pm, omega_gc=w_gc, omega_pc=w_pc)
