"""Shared cores: the generalized integrator, the SOGI, the second-order SOGI and the FLL.

Every SOGI-type observer in jaxobs is built from these pure vector-field
functions; none writes them again.

Generalized integrator (GI) at centre frequency ω'
-------------------------------------------------
With input ``x`` and states (y, q):

    ẏ = ω' (x − q),    q̇ = ω' y        ⇒  Y/X = ω' s / (s² + ω'²),  Q = (ω'/s) Y.

``q`` lags ``y`` by 90° at ω'.  In complex-envelope terms (w = y + jq,
rotating at ω'), ẇ = ω' x + jω' w, so the envelope W of the output obeys
Ẇ ≈ (ω'/2) X̃ once the double-frequency term is averaged out: near its centre
frequency the GI acts on envelopes as an integrator of gain ω'/2.  This is
the fact behind every small-signal model in paper 001.

SOGI (001 eqs 1–2, 6–7; 000 eqs 12–13)
-------------------------------------
GI with input x = k (v − y):

    D(s) = y/v = k ω' s / (s² + k ω' s + ω'²),   Q(s) = q/v = k ω'² / (s² + k ω' s + ω'²).

Second-order SOGI (000 eqs 17–18; Tustin difference equations, eqs 22–25)
-------------------------------------------------------------------------
Two GIs replacing the two integrators of the second-order low-pass
filter K1 K2 / (x² + K2 x + K1 K2).  With 1/s in place of each GI that filter is
``z = (1/s)·K2 (K1 (v − y) − z)``, ``y = (1/s)·z``; with GIs:

    GI_a:  ż_a = ω' (K2 (K1 (v − y) − z_a) − z_b),  ż_b = ω' z_a
    GI_b:  ẏ   = ω' (z_a − q),                      q̇   = ω' y

Substituting g = ω' s / (s² + ω'²) for 1/s and clearing (s² + ω'²)² gives

    y/v = K1 K2 ω'² s² / (s⁴ + K2 ω' s³ + (2 + K1 K2) ω'² s² + K2 ω'³ s + ω'⁴)   (000 eq 17)
    q/v = (ω'/s)·y/v = K1 K2 ω'³ s / (same)                                        (000 eq 18)

On envelopes each GI integrates with gain ω'/2, so the amplitude response is
K1 K2 (ω'/2)² / (s² + K2 (ω'/2) s + K1 K2 (ω'/2)²).  Paper 001 eq (30) writes the
WIF amplitude response as (k1 k2 ωn²/4)/(s² + (k1 ωn/2) s + k1 k2 ωn²/4): the
damping term carries k1, so Golestan's k1 is Xu's K2 and k2 is K1.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike


def gi_vf(
    y: jax.Array | float, q: jax.Array | float, x: ArrayLike, w: jax.Array | float
) -> tuple[ArrayLike, jax.Array | float]:
    """Generalized integrator.

    Args:
        y: The in-phase state.
        q: The quadrature state.
        x: The input.
        w: The centre frequency, rad/s.

    Returns:
        ``(ẏ, q̇)``.
    """
    return w * (x - q), w * y


def sogi_vf(
    y: jax.Array | float, q: jax.Array | float, v: ArrayLike, w: jax.Array | float, k: jax.Array | float
) -> tuple[ArrayLike, jax.Array | float]:
    """SOGI (001 eqs 6–7).

    Args:
        y: The in-phase output v'.
        q: The quadrature output qv'.
        v: The input.
        w: The centre frequency, rad/s.
        k: The SOGI gain.

    Returns:
        ``(ẏ, q̇)``.
    """
    return gi_vf(y, q, k * (v - y), w)


def sogi2_vf(
    za: jax.Array | float,
    zb: jax.Array | float,
    y: jax.Array | float,
    q: jax.Array | float,
    v: ArrayLike,
    w: jax.Array | float,
    k_err: jax.Array | float,
    k_damp: jax.Array | float,
) -> tuple[ArrayLike, jax.Array | float, ArrayLike, jax.Array | float]:
    """Second-order SOGI (000 eqs 17–18): returns (ża, żb, ẏ, q̇).

    ``(y, q)`` are the filtered in-phase and quadrature outputs (v', qv');
    ``(za, zb)`` are the first GI's outputs.  ``za`` is the input of the output
    GI, used by the WIF frequency detector.

    The gains are named by what they do, since the papers name them the other way round: ``k_err``
    multiplies the error v − y (000's K1, 001's k2) and ``k_damp`` the damping term (000's K2, 001's k1):
    the filter is k_err k_damp / (x² + k_damp x + k_err k_damp).

    Args:
        za: The first GI's in-phase output.
        zb: The first GI's quadrature output.
        y: The filtered in-phase output v'.
        q: The filtered quadrature output qv'.
        v: The input.
        w: The centre frequency, rad/s.
        k_err: The gain on the error v − y.
        k_damp: The damping gain.

    Returns:
        ``(ża, żb, ẏ, q̇)``.
    """
    dza, dzb = gi_vf(za, zb, k_damp * (k_err * (v - y) - za), w)
    dy, dq = gi_vf(y, q, za, w)
    return dza, dzb, dy, dq


def sogi2_tustin_coefficients(
    K1: jax.Array | float, K2: jax.Array | float, w: jax.Array | float, ts: jax.Array | float
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Second-order SOGI by Tustin, 000 eqs (22)–(25): (a1…a4, D1 numerator, Q1 numerator), each in
    ascending powers of z⁻¹.

    The difference equations :class:`~jaxobs.SecondOrderSOIFO` runs with ``discretization="paper"``;
    :func:`jaxobs.linear.sogi2_tustin_paper` builds the discrete transfer functions from them.

    Args:
        K1: Second-order SOGI error gain.
        K2: Second-order SOGI damping gain.
        w: ω', rad/s.
        ts: Ts, s.

    Returns:
        ``(a1…a4, D1 numerator, Q1 numerator)``, each in ascending powers of z⁻¹.
    """
    u = 2 * K1 * K2 * w**2 * ts**2
    v = 8 * K2 * w * ts
    ww = 4 * (2 + K1 * K2) * w**2 * ts**2
    x = 2 * K2 * w**3 * ts**3
    y = w**4 * ts**4
    sig = 16 + v + ww + x + y
    b0 = u / sig
    a = jnp.stack([-64 - 2 * v + 2 * x + 4 * y, 96 - 2 * ww + 6 * y, -64 + 2 * v - 2 * x + 4 * y, 16 - v + ww - x + y])
    a = a / sig
    d_num = 2 * b0 * jnp.asarray([1.0, 0.0, -2.0, 0.0, 1.0])
    q_num = b0 * w * ts * jnp.asarray([1.0, 2.0, 0.0, -2.0, -1.0])
    return a, d_num, q_num


def safe_sq_amplitude(y: jax.Array | float, q: jax.Array | float, v_floor: jax.Array | float) -> jax.Array:
    """V̂² = y² + q², floored at ``v_floor²`` so the FLL normalization never divides by 0.

    The floor is exact above it (no bias once V̂ > v_floor).

    Args:
        y: The in-phase output.
        q: The quadrature output.
        v_floor: The floor of V̂.

    Returns:
        The floored V̂².
    """
    return jnp.maximum(y * y + q * q, v_floor * v_floor)


def fll_rate(
    err: ArrayLike,
    q: jax.Array | float,
    y: jax.Array | float,
    lam: jax.Array | float,
    v_floor: jax.Array | float,
) -> jax.Array:
    """Normalized FLL, 001 eq (8): ω̂̇ = −λ · err · q / V̂².

    Args:
        err: The FLL's error.
        q: The quadrature output.
        y: The in-phase output.
        lam: λ, rad²/s².
        v_floor: The floor of V̂.

    Returns:
        ω̂̇, rad/s².
    """
    # numpy's stubs type ndarray / jax.Array as an ndarray; jax's __array_priority__ gives a jax.Array
    return -lam * err * q / safe_sq_amplitude(y, q, v_floor)  # pyright: ignore[reportReturnType] (numpy stubs)


def pll_vf(
    theta_p: jax.Array | float,
    omega_p: jax.Array | float,
    err: jax.Array | float,
    kp: jax.Array | float,
    ki: jax.Array | float,
) -> tuple[jax.Array | float, jax.Array | float]:
    """Type-2 PLL on a normalized phase error ``err`` ≈ sin(θ − θ_p):

        θ̇_p = ω_p + k_p err,    ω̇_p = k_i err.

    Linearized, θ_p/θ = (k_p s + k_i)/(s² + k_p s + k_i); the closed form
    k_p = 2ζω_b, k_i = ω_b² places both poles at natural frequency ω_b with
    damping ζ (:func:`jaxobs.linear.pll_gains`).

    Args:
        theta_p: θ_p, rad.
        omega_p: ω_p, rad/s.
        err: The normalized phase error.
        kp: k_p, 1/s.
        ki: k_i, 1/s².

    Returns:
        ``(θ̇_p, ω̇_p)``.
    """
    return omega_p + kp * err, ki * err


def quadrature_error(
    x_a: jax.Array | float, x_b: jax.Array | float, theta_p: jax.Array | float, floor: jax.Array | float
) -> jax.Array:
    """Normalized quadrature phase detector for a vector (x_a, x_b) = |x|(cos θ, sin θ).

    Args:
        x_a: x_a.
        x_b: x_b.
        theta_p: θ_p, rad.
        floor: The floor of |x|.

    Returns:
        (x_b cos θ_p − x_a sin θ_p)/|x| = sin(θ − θ_p).
    """
    mag = jnp.sqrt(jnp.maximum(x_a * x_a + x_b * x_b, floor * floor))
    return (x_b * jnp.cos(theta_p) - x_a * jnp.sin(theta_p)) / mag
