"""Small-signal models of papers 000 (flux observers) and 002 (back-EMF LESOs).

Paper 000 (Xu et al., TPEL 2018): transfer functions from back EMF e_r to the
estimated rotor flux ψ̂_r (Table III and eqs 15, 20), their dc and harmonic
gains (eqs 16, 21, 29, 36) and the second-order SOGI's Tustin transfer functions
(eqs 22–25, from the coefficients the observer runs, :func:`jaxobs.observers.sogi2_tustin_coefficients`).

Paper 002 (Li et al.): transfer functions from the true to the estimated
equivalent BEMF ê/e (Table II, eqs 15–17, 21/26, 29–30), the C-LESO closed
form (16), and the position errors caused by Rs and Lq mismatch (41)–(43).

Misprints found in the papers, and what we use instead (the full list, each derived and tested:
docs/errata.md, tests/test_errata.py):

- 000 Table III writes the second-order SOIFO's s³ coefficient as K2 ω'³; the
  body's eq (20) has K2 ω' (dimensionally the only possibility: every term of
  the quartic must scale as ω'⁴).  We use eq (20).
- 000 eqs (24)–(25): the coefficients b0, a1…a4 and both numerators agree
  with a generic Tustin substitution to rounding (tests/test_linear.py), so
  no misprint survives there in our copy.
- 000 Sec. III-B, item 4: "magnitude … decays at rates of −20 and −60 dB/decade
  at lower and higher frequencies".  Below ω' the second-order SOIFO's gain
  *rises* at +20 dB/decade (H ∝ s); it is the attenuation of low frequencies
  that grows at 20 dB/decade.  Above ω' it falls at −60 dB/decade as stated.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from ..core.numerics import Real
from ..core.validate import as_float, check_positive, check_real
from ..observers import cleso_gains, sogi2_tustin_coefficients
from ._discrete import DiscreteTransferFunction
from ._tf import TransferFunction, is_hurwitz

__all__ = [
    "integrator_flux_tf",
    "lpf_flux_tf",
    "soifo_tf",
    "sosoifo_tf",
    "sogi2_tf",
    "flux_dc_gain",
    "soifo_harmonic_factor",
    "sosoifo_harmonic_factor",
    "soifo_harmonic_phase",
    "sosoifo_harmonic_phase",
    "lpf_compensation",
    "sogi2_tustin_paper",
    "cleso_tf",
    "leso_tf",
    "gileso_tf",
    "faleso_tf",
    "CLESOGains",
    "cleso_closed_form",
    "faleso_is_stable",
    "faleso_pll_loop",
    "faleso_speed_loop_poles",
    "position_error_rs",
    "position_error_lq",
]

# --------------------------------------------------------------------------
# paper 000: flux observers, ψ̂/e
# --------------------------------------------------------------------------


def integrator_flux_tf() -> TransferFunction:
    """Pure integrator 1/s (000 eq 6).

    Returns:
        The :class:`TransferFunction`.
    """
    return TransferFunction([1.0], [1.0, 0.0])


def lpf_flux_tf(omega_c: ArrayLike) -> TransferFunction:
    """Low-pass filter 1/(s + ωc) (000, Sec. II).

    Args:
        omega_c: ωc, rad/s.

    Returns:
        The :class:`TransferFunction`.
    """
    return TransferFunction([1.0], jnp.stack([jnp.ones_like(as_float(omega_c)), as_float(omega_c)]))


def soifo_tf(k: ArrayLike, omega: ArrayLike) -> TransferFunction:
    """SOIFO (000 eq 15): (1/ω') Q(s) = k ω' / (s² + k ω' s + ω'²).

    Args:
        k: SOGI gain.
        omega: ω', rad/s.

    Returns:
        The :class:`TransferFunction`.
    """
    k, w = as_float(k), as_float(omega)
    return TransferFunction(jnp.stack([k * w]), jnp.stack([jnp.ones_like(w), k * w, w * w]))


def _sogi2_den(K1, K2, w):
    return jnp.stack([jnp.ones_like(w), K2 * w, (2 + K1 * K2) * w**2, K2 * w**3, w**4])


def sosoifo_tf(K1: ArrayLike, K2: ArrayLike, omega: ArrayLike) -> TransferFunction:
    """Second-order SOIFO (000 eq 20): K1K2ω'² s / (s⁴ + K2ω's³ + (2+K1K2)ω'²s² + K2ω'³s + ω'⁴).

    Args:
        K1: Second-order SOGI error gain.
        K2: Second-order SOGI damping gain.
        omega: ω', rad/s.

    Returns:
        The :class:`TransferFunction`.
    """
    K1, K2, w = as_float(K1), as_float(K2), as_float(omega)
    return TransferFunction(jnp.stack([K1 * K2 * w**2, jnp.zeros_like(w)]), _sogi2_den(K1, K2, w))


def sogi2_tf(K1: ArrayLike, K2: ArrayLike, omega: ArrayLike) -> tuple[TransferFunction, TransferFunction]:
    """Second-order SOGI outputs (000 eqs 17–18).

    Args:
        K1: Second-order SOGI error gain.
        K2: Second-order SOGI damping gain.
        omega: ω', rad/s.

    Returns:
        ``(D1, Q1) = (v'/v, qv'/v)``, :class:`TransferFunction` s.
    """
    K1, K2, w = as_float(K1), as_float(K2), as_float(omega)
    z = jnp.zeros_like(w)
    d1 = TransferFunction(jnp.stack([K1 * K2 * w**2, z, z]), _sogi2_den(K1, K2, w))
    q1 = TransferFunction(jnp.stack([K1 * K2 * w**3, z]), _sogi2_den(K1, K2, w))
    return d1, q1


def flux_dc_gain(tf: TransferFunction) -> jax.Array:
    """Final value of ψ̂ for a unit dc back EMF: lim_{s→0} s·H(s)·(1/s) = H(0) (000 eqs 29, 36).

    Infinite for the pure integrator (the ramp A₀t of eq 10).

    Args:
        tf: The flux estimator's :class:`TransferFunction` H.

    Returns:
        H(0).
    """
    return tf.dcgain()


def soifo_harmonic_factor(h: ArrayLike, k: Real) -> jax.Array:
    """000 eq (16): amplitude of the h-th harmonic relative to a pure integrator, 1/√((1−h²)²/(k²h²) + 1).

    Args:
        h: The harmonic order.
        k: SOGI gain.

    Returns:
        The factor.
    """
    h = as_float(h)
    return 1.0 / jnp.sqrt((1 - h**2) ** 2 / (k**2 * h**2) + 1)


def sosoifo_harmonic_factor(h: ArrayLike, K1: Real, K2: Real) -> jax.Array:
    """000 eq (21): 1/√([1 − h²(2+K1K2) + h⁴]²/(h²K1K2)² + (hK2 − h³K2)²/(h²K1K2)²).

    The amplitude of the h-th harmonic relative to a pure integrator.

    Args:
        h: The harmonic order.
        K1: Second-order SOGI error gain.
        K2: Second-order SOGI damping gain.

    Returns:
        The factor.
    """
    h = as_float(h)
    a = (1 - h**2 * (2 + K1 * K2) + h**4) / (h**2 * K1 * K2)
    b = (h * K2 - h**3 * K2) / (h**2 * K1 * K2)
    return 1.0 / jnp.sqrt(a**2 + b**2)


def soifo_harmonic_phase(h: ArrayLike, k: Real) -> jax.Array:
    """000 eq (16)'s γ_h1, rad: the h-th harmonic of ψ̂ is (factor)·(A_h/ω_h)·sin(ω_h t + φ_h − π/2 + γ_h1).

    γ_h1 = arg H(jhω') + π/2 with H = kω'/(s² + kω's + ω'²), i.e. atan((1 − h²)/(kh)), as printed (the
    printed arctangent is in the right quadrant because kh > 0).  Eq (32)'s θ₁, the phase of H itself, is
    printed as atan(kω'ω_h/(ω_h² − ω'²)), which is π off for h > 1 (errata: docs/errata.md).

    Args:
        h: The harmonic order.
        k: SOGI gain.

    Returns:
        γ_h1, rad.
    """
    h = as_float(h)
    return jnp.arctan2(1 - h**2, k * h)


def sosoifo_harmonic_phase(h: ArrayLike, K1: Real, K2: Real) -> jax.Array:
    """000 eq (21)'s γ_h2, corrected, rad: the h-th harmonic is (factor)·(A_h/ω_h)·sin(ω_h t + φ_h − π/2 + γ_h2).

    H(jhω') = jhK1K2 / (ω' P) with P = [1 − h²(2+K1K2) + h⁴] + j K2 h(1 − h²)  (000 eq 39), so
    γ_h2 = arg H + π/2 = π − arg P.  The paper prints γ_h2 = atan((K2ω'ω_h³ − K2ω'³ω_h) /
    (ω'⁴ − h²(2+K1K2)ω'²ω_h² + ω_h⁴)): its denominator has an extra h² (the middle term is
    (2+K1K2)ω'²ω_h², i.e. h²(2+K1K2)ω'⁴), and a plain arctangent cannot give π − arg P, which lies near π
    for h > 1: the printed angle is 180° off there (errata: docs/errata.md; tests/test_errata.py).

    Args:
        h: The harmonic order.
        K1: Second-order SOGI error gain.
        K2: Second-order SOGI damping gain.

    Returns:
        γ_h2, rad.
    """
    h = as_float(h)
    re = 1 - h**2 * (2 + K1 * K2) + h**4
    im = K2 * h * (1 - h**2)
    return jnp.pi - jnp.arctan2(im, re)


def lpf_compensation(omega_1: ArrayLike, omega_c: ArrayLike) -> tuple[jax.Array, jax.Array]:
    """Gain and rotation that turn the LPF's output at ω1 into the integrator's (000 eq 11).

    The LPF passes the fundamental as A₁/√(ω₁² + ωc²) at −0.5π + θ₁ with
    θ₁ = atan(ωc/ω₁), instead of the integrator's A₁/ω₁ at −0.5π.  Needs ω₁, hence a speed estimate.

    Args:
        omega_1: ω₁, rad/s.
        omega_c: ωc, rad/s.

    Returns:
        ``(gain, phase)`` with gain·e^{j·phase}·H_LPF(jω₁) = 1/(jω₁), i.e.
        gain = √(ω₁² + ωc²)/ω₁ and phase = −θ₁ (rad).
    """
    w1, wc = as_float(omega_1), as_float(omega_c)
    h = 1.0 / (1j * w1 + wc)
    target = 1.0 / (1j * w1)
    ratio = target / h
    return jnp.abs(ratio), jnp.angle(ratio)


def sogi2_tustin_paper(
    K1: ArrayLike, K2: ArrayLike, omega: ArrayLike, ts: float
) -> tuple[DiscreteTransferFunction, DiscreteTransferFunction]:
    """000 eqs (22)–(25): the Tustin coefficients of the second-order SOGI, as printed.

    u = 2K1K2ω'²Ts², v = 8K2ω'Ts, w = 4(2+K1K2)ω'²Ts², x = 2K2ω'³Ts³, y = ω'⁴Ts⁴;
    b0 = u/Σ, a1 = (−64 − 2v + 2x + 4y)/Σ, a2 = (96 − 2w + 6y)/Σ,
    a3 = (−64 + 2v − 2x + 4y)/Σ, a4 = (16 − v + w − x + y)/Σ with Σ = 16 + v + w + x + y;
    Q1(z) = b0 ω'Ts (1 + 2z⁻¹ − 2z⁻³ − z⁻⁴)/A(z),  D1(z) = 2b0 (1 − 2z⁻² + z⁻⁴)/A(z).

    Args:
        K1: Second-order SOGI error gain.
        K2: Second-order SOGI damping gain.
        omega: ω', rad/s.
        ts: Ts, s.

    Returns:
        ``(D1, Q1)`` as :class:`DiscreteTransferFunction` s.
    """
    a, d_num, q_num = sogi2_tustin_coefficients(as_float(K1), as_float(K2), as_float(omega), ts)
    a = jnp.concatenate([jnp.ones((1,), a.dtype), a])
    return DiscreteTransferFunction(d_num, a, ts=float(ts)), DiscreteTransferFunction(q_num, a, ts=float(ts))


# --------------------------------------------------------------------------
# paper 002: back-EMF LESOs, ê/e
# --------------------------------------------------------------------------


def leso_tf(l1: ArrayLike, l2: ArrayLike, mu: ArrayLike) -> TransferFunction:
    """LESO with constant gains (002 eq 15): l2 / (s² + (μ + l1) s + l2).

    Args:
        l1: The first gain, 1/s.
        l2: The second gain, 1/s².
        mu: μ = Rs/Lq, 1/s.

    Returns:
        The :class:`TransferFunction`.
    """
    l1, l2, mu = as_float(l1), as_float(l2), as_float(mu)
    return TransferFunction(jnp.stack([l2]), jnp.stack([jnp.ones_like(l2), mu + l1, l2]))


def cleso_tf(omega0: ArrayLike) -> TransferFunction:
    """C-LESO with the gains of (16) (002 eq 17): ω0² / (s + ω0)².

    Args:
        omega0: The bandwidth ω0, rad/s.

    Returns:
        The :class:`TransferFunction`.
    """
    w = as_float(omega0)
    return TransferFunction(jnp.stack([w * w]), jnp.stack([jnp.ones_like(w), 2 * w, w * w]))


def gileso_tf(omega0: ArrayLike, K_r: ArrayLike, omega_c: ArrayLike, omega_e: ArrayLike) -> TransferFunction:
    """GI-LESO (002 eqs 29–30): (G + ω0²)/(s² + 2ω0 s + G + ω0²), G = 2K_r ωc s/(s² + 2ωc s + ω̂e²).

    Args:
        omega0: The bandwidth ω0, rad/s.
        K_r: Generalized integrator gain, 1/s².
        omega_c: Generalized integrator damping ωc, rad/s.
        omega_e: ω̂e, rad/s.

    Returns:
        The :class:`TransferFunction`.
    """
    w0, kr, wc, we = (as_float(a) for a in (omega0, K_r, omega_c, omega_e))
    one = jnp.ones_like(w0)
    gi_den = jnp.stack([one, 2 * wc, we * we])  # s² + 2ωc s + ω̂²
    # numerator: 2Kr ωc s + ω0² (s² + 2ωc s + ω̂²)
    num = jnp.stack([w0**2, 2 * kr * wc + 2 * wc * w0**2, w0**2 * we**2])
    den = jnp.convolve(jnp.stack([one, 2 * w0, 0 * one]), gi_den) + jnp.concatenate([jnp.zeros(2), num])
    return TransferFunction(num, den)


def faleso_tf(k1: ArrayLike, k2: ArrayLike, omega_e: ArrayLike) -> TransferFunction:
    """FA-LESO, a complex-coefficient filter (002 eqs 21, 26): (k2 s + k1)/(s² + (k2 − jω̂e) s + k1).

    Acts on the complex vector e_α + j e_β: positive-sequence components are at
    +ω, the 5th harmonic (negative sequence) at −5ω̂e, the 7th at +7ω̂e.

    Args:
        k1: FA-LESO integral gain, 1/s².
        k2: FA-LESO proportional gain, 1/s.
        omega_e: ω̂e, rad/s.

    Returns:
        The complex-coefficient :class:`TransferFunction`.
    """
    k1, k2, we = as_float(k1), as_float(k2), as_float(omega_e)
    one = jnp.ones_like(k1)
    return TransferFunction(jnp.stack([k2, k1]).astype(complex), jnp.stack([one + 0j, k2 - 1j * we, k1 + 0j]))


def faleso_is_stable(k1: ArrayLike, k2: ArrayLike, omega_e: ArrayLike) -> jax.Array:
    """Generalized Routh test on 002 eq (22) (stable iff k1 > 0 and k2 > 0, eq 24).

    Args:
        k1: FA-LESO integral gain, 1/s².
        k2: FA-LESO proportional gain, 1/s.
        omega_e: ω̂e, rad/s.

    Returns:
        Whether the FA-LESO is stable.
    """
    return is_hurwitz(faleso_tf(k1, k2, omega_e).den)


class CLESOGains(eqx.Module):
    """Constant LESO gains (002 eq 16) with the μ = Rs/Lq they were designed for.

    Attributes:
        l1: 2ω0 − μ, 1/s.
        l2: ω0², 1/s².
        omega0: The bandwidth ω0, rad/s.
    """

    l1: jax.Array
    l2: jax.Array
    omega0: jax.Array


def cleso_closed_form(omega0: ArrayLike, Rs: ArrayLike, Lq: ArrayLike) -> CLESOGains:
    """002 eq (16): l1 = 2ω0 − μ, l2 = ω0², μ = Rs/Lq; both poles at −ω0 (:func:`jaxobs.observers.cleso_gains`,
    which the C-LESO runs; its design's rows are :meth:`jaxobs.CLESO.closed_form_design`'s).

    Args:
        omega0: The bandwidth ω0, rad/s (> 0).
        Rs: The stator resistance, Ω (≥ 0).
        Lq: The q-axis inductance, H (> 0).

    Returns:
        :class:`CLESOGains`.

    Raises:
        ValueError: A value out of its range.
    """
    w0 = check_positive("omega0", omega0, "cleso_closed_form")
    rs = check_real("Rs", Rs, lower=0.0, lower_open=False, owner="cleso_closed_form")
    lq = check_positive("Lq", Lq, "cleso_closed_form")
    l1, l2 = cleso_gains(w0, rs / lq)  # the one writing of eq (16), jaxobs.observers._rules
    return CLESOGains(l1=jnp.asarray(l1), l2=jnp.asarray(l2), omega0=w0)


def faleso_speed_loop_poles(
    k1: Real,
    k2: Real,
    omega_e: ArrayLike,
    kp: Real,
    ki: Real,
    kp_w: Real,
    ki_w: Real,
    *,
    p: Real,
    psi_f: Real,
    Ld: Real,
    Lq: Real,
    J: Real,
    i_d: Real = 0.0,
    i_q: Real = 0.0,
    adaptation: bool = False,
) -> jax.Array:
    """Poles (rad/s) of a sensorless drive's speed loop closed through the FA-LESO and its PLL, linearized at
    the operating point ω_e (rad/s), (i_d, i_q) (A) with the estimate unbiased (the FA-LESO's, δ0 = 0).

    The loop (ideal current control; I-P speed loop on the PLL's integrator ω̂, as :class:`jaxobs.drive.FOC`):

    - the PLL sees the rotor angle θ through the FA-LESO's envelope response H_φ (:func:`faleso_pll_loop`):
      θ̂ = C H_φ θ/(1 + C), C = (k_p s + k_i)/s², and ω̂ = (k_i/s)(H_φ θ − θ̂);
    - the speed loop (k_pω, k_iω, on the mechanical ω̂/p) sets i_q* = −(k_pω + k_iω/s) ω̂/p;
    - the controller's frame is δ = θ̂ − θ ahead of the rotor's, so the rotor carries
      i_q,rotor ≈ i_q* + i_d δ and i_d,rotor ≈ i_d − i_q δ: the torque T = 1.5p(ψf i_q + (Ld − Lq) i_d i_q)
      moves by K_q i_q* + K_δ δ with K_q = 1.5p(ψf + (Ld − Lq) i_d), K_δ = 1.5p(ψf i_d + (Ld − Lq)(i_d² − i_q²));
    - J s² θ = p T.

    K_δ is the path field weakening opens: with i_d < 0 a lagging estimate (δ < 0) *adds* torque, which
    accelerates the rotor, which makes the PLL lag more (its acceleration error).  With H_φ = N/D,
    P = s² + k_p s + k_i and Q = k_p s + k_i, H_φ − θ̂/θ = N s²/(D P) and θ̂/θ − 1 = (Q N − P D)/(P D), so
    eliminating θ̂ and ω̂ (times p P D) leaves J s² P D + K_q k_i (k_pω s + k_iω) N − p K_δ (Q N − P D) = 0.
    Its roots include the FA-LESO's slow, lightly damped mode near ±jω_e, which the phase hardly excites (a
    near pole–zero cancellation in H_φ); the speed loop's own modes have |Im| well below ω_e.

    ``adaptation`` (static) adds the FA-LESO's frequency adaptation, the PLL's ω̂ fed back into the LESO, which
    the loop above leaves out (the FA-LESO at a frozen ω̂ = ω_e).  It does not vanish: G_FA(jω̂; ω̂) = 1 for every
    ω̂, but the carrier is at the rotor's ω_e, and ∂G_FA(jω_e; ω̂)/∂ω̂ = j/k2 (≈), an angle shift of δω̂/k2.  In
    error form (ε = x̂1 − i, z = ∫ε, matched machine) ε̇ = (jω̂ − k2)ε − k1 z + e/L̂q and ê = L̂q(k2 ε + k1 z),
    so δω̂ forces ε̇ by j δω̂ ε0, ε0 = jω_e e/(L̂q(k1 + jω_e k2)) the carrier's steady ε: an equivalent BEMF
    c δω̂ e with c = −ω_e/(k1 + jω_e k2), reaching ê through G_FA.  Its angle part is
    H_ω = (cH − c̄H̄)/(2j) = N_ω/D (H the envelope response, as for H_φ), so the PLL detects H_φ θ + H_ω ω̂, and
    P D becomes R = P D − k_i s N_ω: J s² R + K_q k_i (k_pω s + k_iω) N − p K_δ (Q N − R) = 0.  Checked against
    the simulated dual drive (docs/papers.md, "the ringing after the I-f hand-over"): with the speed loop run every
    period and a 1.5 kHz current loop, the simulated pair is 10.93 Hz, σ = 1.33 /s, this 11.05 Hz, 1.01 /s; with
    the simulated FA-LESO's ω̂ frozen at ω_e 9.83 Hz, 4.70 /s, and without ``adaptation`` 9.95 Hz, 4.23 /s.

    Args:
        k1: FA-LESO integral gain, 1/s².
        k2: FA-LESO proportional gain, 1/s.
        omega_e: The operating point's ω_e, rad/s.
        kp: The PLL's proportional gain k_p, 1/s.
        ki: The PLL's integral gain k_i, 1/s².
        kp_w: The speed loop's k_pω.
        ki_w: The speed loop's k_iω.
        p: Pole pairs.
        psi_f: ψf, Wb.
        Ld: Ld, H.
        Lq: Lq, H.
        J: Inertia, kg·m².
        i_d: The operating point's i_d, A.
        i_q: The operating point's i_q, A.
        adaptation: Whether to include the frequency adaptation (static).

    Returns:
        The poles, rad/s.
    """
    g = faleso_tf(k1, k2, omega_e)
    jw = 1j * as_float(omega_e)
    hh = TransferFunction(_poly_shift(g.num, jw), _poly_shift(g.den, jw))
    n_c, d_c = hh.num, hh.den
    # H_φ = (H + H̄)/2 = (N D̄ + N̄ D)/(2 D D̄): real polynomials
    nn = jnp.real(jnp.polymul(n_c, jnp.conj(d_c)) + jnp.polymul(jnp.conj(n_c), d_c)) / 2
    dd = jnp.real(jnp.polymul(d_c, jnp.conj(d_c)))
    kq = 1.5 * p * (psi_f + (Ld - Lq) * i_d)
    kd = 1.5 * p * (psi_f * i_d + (Ld - Lq) * (i_d * i_d - i_q * i_q))
    one, zero = jnp.ones_like(as_float(kp)), jnp.zeros_like(as_float(kp))
    pp = jnp.stack([one, kp * one, ki * one])
    qq = jnp.stack([kp * one, ki * one])
    rr = jnp.polymul(pp, dd)  # P D
    if adaptation:  # R = P D − k_i s N_ω (docstring)
        c = -as_float(omega_e) / (k1 + jw * k2)
        n_w = jnp.real((c * jnp.polymul(n_c, jnp.conj(d_c)) - jnp.conj(c) * jnp.polymul(jnp.conj(n_c), d_c)) / 2j)
        rr = jnp.polysub(rr, ki * jnp.polymul(jnp.stack([one, zero]), n_w))
    t1 = J * jnp.polymul(jnp.stack([one, zero, zero]), rr)  # J s² R (R = P D without adaptation)
    t2 = kq * ki * jnp.polymul(jnp.stack([kp_w * one, ki_w * one]), nn)  # K_q k_i (k_pω s + k_iω) N
    t3 = -p * kd * jnp.polysub(jnp.polymul(qq, nn), rr)  # −p K_δ (Q N − R)
    poly = jnp.polyadd(jnp.polyadd(t1, t2), t3)
    return jnp.roots(poly, strip_zeros=False)


def position_error_rs(delta_rs: Real, i_d: Real, i_q: Real, e_ex: Real) -> jax.Array:
    """002 eq (42): Δθ = atan(−ΔRs î_d / (E_ex − ΔRs î_q)), rad.

    Args:
        delta_rs: ΔRs, Ω.
        i_d: î_d, A.
        i_q: î_q, A.
        e_ex: E_ex, V.

    Returns:
        Δθ, rad.
    """
    return jnp.arctan2(-delta_rs * i_d, e_ex - delta_rs * i_q)


def position_error_lq(delta_lq: Real, i_d: Real, i_q: Real, e_ex: Real, omega_e: Real) -> jax.Array:
    """002 eq (43): Δθ = atan(ΔLq î_q / (E_ex/ω̂e − ΔLq î_d)), rad.

    Args:
        delta_lq: ΔLq, H.
        i_d: î_d, A.
        i_q: î_q, A.
        e_ex: E_ex, V.
        omega_e: ω̂e, rad/s.

    Returns:
        Δθ, rad.
    """
    return jnp.arctan2(delta_lq * i_q, e_ex / omega_e - delta_lq * i_d)


def _poly_shift(c, a):
    """Coefficients (highest first) of p(s + a) for p with coefficients ``c``."""
    n = c.shape[0] - 1
    out = jnp.zeros((n + 1,), jnp.result_type(c, a))
    for k in range(n + 1):
        p = jnp.ones((1,), out.dtype)
        for _ in range(n - k):
            p = jnp.convolve(p, jnp.stack([jnp.ones_like(a), a]).astype(out.dtype))
        out = out.at[k:].add(c[k] * p)
    return out


def faleso_pll_loop(k1: ArrayLike, k2: ArrayLike, omega_e: ArrayLike, kp: ArrayLike, ki: ArrayLike) -> TransferFunction:
    """The PLL's open loop through the FA-LESO, linearized at ω̂e = ωe (real coefficients).

    A small phase modulation δ of the BEMF reaches the FA-LESO's output through its
    envelope response H(s) = G_FA(s + jωe) (complex); the angle the PLL detects is
    filtered by H_φ(s) = (H(s) + H̄(s))/2, H̄ with conjugated coefficients.  The type-2 PLL
    closes L(s) = H_φ(s)(k_p s + k_i)/s².  The frequency-adaptation path (ω̂ fed back to the
    FA-LESO) is left out: the FA-LESO at a frozen ω̂ = ω_e.  It does not vanish to first order
    (G_FA(jω̂) = 1 for every ω̂, but the carrier is at ω_e: an angle shift of about δω̂/k2;
    :func:`faleso_speed_loop_poles` with ``adaptation=True`` has it).

    Args:
        k1: FA-LESO integral gain, 1/s².
        k2: FA-LESO proportional gain, 1/s.
        omega_e: ωe, rad/s.
        kp: The PLL's proportional gain, 1/s.
        ki: The PLL's integral gain, 1/s².

    Returns:
        The open loop L(s), a :class:`TransferFunction`.
    """
    g = faleso_tf(k1, k2, omega_e)
    jw = 1j * as_float(omega_e)
    h = TransferFunction(_poly_shift(g.num, jw), _poly_shift(g.den, jw))
    hbar = TransferFunction(jnp.conj(h.num), jnp.conj(h.den))
    hphi = 0.5 * (h + hbar)
    hphi = TransferFunction(jnp.real(hphi.num), jnp.real(hphi.den))
    pll = TransferFunction(jnp.stack([kp, ki]), jnp.stack([jnp.ones_like(kp), jnp.zeros_like(kp), jnp.zeros_like(kp)]))
    return hphi * pll
