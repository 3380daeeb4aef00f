"""Errata of papers 000 and 002: for each, the corrected form is derived here (numerically, from the transfer
function or the polynomial the paper itself states) and the printed form is shown to be wrong.  The list, with
the reasoning, is docs/errata.md.  float64 (conftest)."""

import math

import numpy as np
import pytest

import jaxobs.linear as L
from jaxobs import papers

W = 100 * math.pi  # ω' = ω1 = 100π rad/s, 000 Fig. 5
K = math.sqrt(2)  # 000's k
K1, K2 = papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2  # 000's K1, K2 (Fig. 5, Table V)
HS = [2.0, 3.0, 5.0, 7.0, 11.0, 13.0]  # harmonic orders h = ω_h/ω'


def soifo_h(s, k=K, w=W):
    """000 eq (15): ψ̂/e of the SOIFO."""
    return k * w / (s**2 + k * w * s + w**2)


def sosoifo_h(s, k1=K1, k2=K2, w=W):
    """000 eq (20): ψ̂/e of the second-order SOIFO."""
    return k1 * k2 * w**2 * s / (s**4 + k2 * w * s**3 + (2 + k1 * k2) * w**2 * s**2 + k2 * w**3 * s + w**4)


def wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def test_000_eq28_pole_sign():
    """Eq (28) prints p = (kω' ± ω'√(k²−4))/2: right half-plane poles, against the text ("located in the left
    half-plane").  The roots of s² + kω's + ω'² are p = (−kω' ± ω'√(k²−4))/2."""
    for k in (K, 1.0, 3.0):
        true = np.sort_complex(np.roots([1.0, k * W, W**2]))
        printed = np.sort_complex(
            [(k * W + W * np.sqrt(complex(k * k - 4))) / 2, (k * W - W * np.sqrt(complex(k * k - 4))) / 2]
        )
        corrected = np.sort_complex(
            [(-k * W + W * np.sqrt(complex(k * k - 4))) / 2, (-k * W - W * np.sqrt(complex(k * k - 4))) / 2]
        )
        np.testing.assert_allclose(corrected, true, rtol=1e-12)
        assert np.all(true.real < 0) and np.all(np.real(printed) > 0)  # the printed poles are unstable ones
        np.testing.assert_allclose(np.sort_complex(-np.asarray(printed)), true, rtol=1e-12)  # the sign of kω'


def test_000_eq30_cites_eq17_but_evaluates_eq15():
    """Eq (30) says "combining s = jω' with (17)", but (17) is the second-order SOGI's D1, which is 1 at jω';
    the 1/(jω') it prints is the SOIFO's eq (15)."""
    s = 1j * W
    d1 = K1 * K2 * W**2 * s**2 / (s**4 + K2 * W * s**3 + (2 + K1 * K2) * W**2 * s**2 + K2 * W**3 * s + W**4)
    assert d1 == pytest.approx(1.0, rel=1e-12)
    assert soifo_h(s) == pytest.approx(1 / (1j * W), rel=1e-12)


def test_000_eq19_holds_only_at_the_centre_frequency():
    """Eq (19) (as eq 14 does) evaluates every denominator term of Q1 at s = jω' but K1K2ω'²s², then cancels
    to ω'/s.  Read at s = jω' its algebra is right (Q1(jω') = −j, as an integrator's ω'/s there); the "= ω'/s"
    is not an identity in s.  No slip in our copy beyond that device."""

    def q1(s):
        return K1 * K2 * W**3 * s / (s**4 + K2 * W * s**3 + (2 + K1 * K2) * W**2 * s**2 + K2 * W**3 * s + W**4)

    s = 1j * W
    printed_den = W**4 - 1j * K2 * W**4 + K1 * K2 * W**2 * s**2 - 2 * W**4 + 1j * K2 * W**4 + W**4
    den = s**4 + K2 * W * s**3 + (2 + K1 * K2) * W**2 * s**2 + K2 * W**3 * s + W**4
    assert printed_den == pytest.approx(den, rel=1e-12)
    assert q1(s) == pytest.approx(W / s, rel=1e-12) == pytest.approx(-1j, rel=1e-12)
    assert abs(q1(2j * W) - W / (2j * W)) > 0.1  # not ω'/s elsewhere


def test_000_eq32_theta1_quadrant():
    """Eq (32): θ₁ = arg kω'/(s² + kω's + ω'²) at s = jhω' is −atan2(hk, 1 − h²); the printed
    atan(kω'ω_h/(ω_h² − ω'²)) is π off for every harmonic (h > 1).  γ_h1 of eqs (16)/(33), which is
    θ₁ + π/2 taken the right way, is right as printed (L.soifo_harmonic_phase)."""
    for h in HS:
        s = 1j * h * W
        true = np.angle(soifo_h(s))
        printed = math.atan(K * W * h * W / ((h * W) ** 2 - W**2))
        assert true == pytest.approx(-math.atan2(h * K, 1 - h * h), abs=1e-12)
        assert wrap(printed - true) == pytest.approx(np.pi, abs=1e-9) or wrap(printed - true) == pytest.approx(
            -np.pi, abs=1e-9
        )
        gamma_printed = math.atan((W**2 - (h * W) ** 2) / (K * W * h * W))
        assert float(wrap(true + np.pi / 2 - gamma_printed)) == pytest.approx(0.0, abs=1e-12)
        assert float(L.soifo_harmonic_phase(h, K)) == pytest.approx(gamma_printed, abs=1e-12)


def test_000_gamma_h2_extra_h2_and_quadrant():
    """Eq (21)/(40)'s γ_h2: the harmonic of ψ̂ is |H|·A_h·sin(ω_h t + φ_h + arg H), so γ_h2 = arg H + π/2 with H
    eq (20) at s = jhω'.  The printed arctangent has h²(2+K1K2)ω'²ω_h² in its denominator (an extra h²:
    it is (2+K1K2)ω'²ω_h²) and, being a plain arctangent, misses the quadrant: with the h² removed it is
    still 180° off wherever Re P > 0 (h ≥ 3 here: the 5th, 7th, 11th, 13th of a PMSM); as printed it is off
    by other amounts too."""
    for h in HS:
        wh = h * W
        true = float(wrap(np.angle(sosoifo_h(1j * wh)) + np.pi / 2))
        assert float(wrap(L.sosoifo_harmonic_phase(h, K1, K2) - true)) == pytest.approx(0.0, abs=1e-12)
        num = K2 * W * wh**3 - K2 * W**3 * wh
        printed = math.atan(num / (W**4 - h**2 * (2 + K1 * K2) * W**2 * wh**2 + wh**4))
        no_extra_h2 = math.atan(num / (W**4 - (2 + K1 * K2) * W**2 * wh**2 + wh**4))
        re = 1 - h * h * (2 + K1 * K2) + h**4  # Re P: > 0 from h ≈ 2.6 on (K1K2 = 4.85), every PMSM harmonic
        if re > 0:  # the quadrant: π − arg P is near π there, a plain arctangent gives it −π off
            assert abs(float(wrap(no_extra_h2 - true))) == pytest.approx(np.pi, abs=1e-9)
        else:  # h = 2: Re P < 0, Im P < 0, and the arctangent happens to land in the right quadrant
            assert float(wrap(no_extra_h2 - true)) == pytest.approx(0.0, abs=1e-12)
        assert abs(float(wrap(printed - true))) > 0.05  # the printed form is wrong for every harmonic
        if h >= 3:  # the extra h² changes the angle itself, not only by π
            assert abs(abs(float(wrap(printed - true))) - np.pi) > 1e-3


def test_000_eq39_numerator_drops_h():
    """Eq (39), second line: the numerator at s = jhω' is jhK1K2ω'³ (s = jhω'); the paper prints jK1K2ω'³,
    which is 1/h of the first line.  The third and fourth lines have the h back, and the magnitude of eq (21),
    L.sosoifo_harmonic_factor, equals |H|·ω_h."""
    for h in HS:
        s = 1j * h * W
        den = (h**4 - 1j * h**3 * K2 - h**2 * (2 + K1 * K2) + 1j * h * K2 + 1) * W**4
        line2_printed = 1j * K1 * K2 * W**3 / den
        line2_corrected = 1j * h * K1 * K2 * W**3 / den
        assert line2_corrected == pytest.approx(sosoifo_h(s), rel=1e-12)
        assert line2_printed == pytest.approx(sosoifo_h(s) / h, rel=1e-12)
        re, im = 1 - h * h * (2 + K1 * K2) + h**4, h * K2 - h**3 * K2
        line3 = (im + 1j * re) / (re**2 + im**2) * h * K1 * K2 / W
        assert line3 == pytest.approx(sosoifo_h(s), rel=1e-12)
        assert float(L.sosoifo_harmonic_factor(h, K1, K2)) == pytest.approx(abs(sosoifo_h(s)) * h * W, rel=1e-12)


def test_000_text_after_eq21_drops_a_square():
    """After eq (21) the text's "inversely proportional to √([1−h²(2+K1K2)+h⁴]/(h²K1K2)² + …)" has lost the
    square on the first bracket (eq 21 itself has it); the unsquared form is not the attenuation."""
    for h in (5.0, 7.0):
        a = 1 - h * h * (2 + K1 * K2) + h**4
        b = h * K2 - h**3 * K2
        printed = math.sqrt(a / (h * h * K1 * K2) ** 2 + b**2 / (h * h * K1 * K2) ** 2)
        corrected = math.sqrt(a**2 / (h * h * K1 * K2) ** 2 + b**2 / (h * h * K1 * K2) ** 2)
        assert 1 / corrected == pytest.approx(float(L.sosoifo_harmonic_factor(h, K1, K2)), rel=1e-12)
        assert abs(printed / corrected - 1) > 0.3  # 36 % at h = 5, more above


def _criterion(a1, b1, a2, b2):
    """s² + (a1 + jb1)s + (a2 + jb2) has both roots in the left half-plane iff a1 > 0 and this is > 0
    (the generalized Routh/Hurwitz condition for a complex quadratic; checked against roots below)."""
    return a1 * a1 * a2 + a1 * b1 * b2 - b2 * b2


def test_002_routh_entry_a2_2():
    """002 eq (23): a₂⁽²⁾ = a1·a₂⁽¹⁾ + b₁⁽¹⁾·b2 with a1 = k2, a₂⁽¹⁾ = k1k2 and b2 = 0 is k1·k2², not the printed
    k1·k2 (the printed recurrence does not give its printed result unless k2 = 1).  k1·k2² is the complex
    quadratic's stability condition a1²a2 + a1b1b2 − b2² (checked against the roots of random complex
    quadratics); the printed k1k2 has its sign when k2 > 0, so eq (24)'s conclusion (k1 > 0, k2 > 0) stands.
    jaxobs.linear.routh_complex returns a₂⁽²⁾/a1² = k1 (tests/test_linear.py)."""
    rng = np.random.default_rng(0)
    for _ in range(2000):
        a1, b1, a2, b2 = rng.normal(scale=3.0, size=4)
        stable = bool(np.all(np.roots([1.0, a1 + 1j * b1, a2 + 1j * b2]).real < 0))
        assert stable == (a1 > 0 and _criterion(a1, b1, a2, b2) > 0), (a1, b1, a2, b2)
    we = 2 * math.pi * 50
    for k1, k2 in [(3.0, 7.0), (10.06, 613.7), (2.0, 0.5)]:
        a1, a21, b11, b2 = k2, k1 * k2, -we * k2, 0.0  # eq (23)'s a1, a₂⁽¹⁾, b₁⁽¹⁾, b2
        derived = a1 * a21 + b11 * b2
        assert derived == pytest.approx(k1 * k2**2, rel=1e-12) == pytest.approx(_criterion(k2, -we, k1, 0.0))
        assert derived != pytest.approx(k1 * k2, rel=1e-3)  # the printed entry
        col = np.asarray(L.routh_complex(np.asarray([1.0, k2 - 1j * we, k1])))
        assert col[2] == pytest.approx(derived / k2**2, rel=1e-9)
