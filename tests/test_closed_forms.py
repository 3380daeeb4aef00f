"""Paper 001 Table I from the closed-form formulas (float64).

The oracles are independent of the formulas: the loops' characteristic polynomials are written out here from
001's transfer functions (eqs 18-20 and 23-25) and their roots found by numpy, so a wrong λ rule gives the
wrong damping; Table I's published numbers are typed in as they are printed."""

import math

import numpy as np
import pytest

from jaxobs import linear, papers

WN = 2 * math.pi * 50.0  # 001 Sec. VI: the nominal grid frequency


def _damping_of_complex_pair(coeffs) -> float:
    """ζ = −Re p / |p| of the complex pole pair of a real polynomial (exactly one pair, asserted)."""
    pair = [p for p in np.roots(coeffs) if abs(p.imag) > 1e-9 * abs(p)]
    assert len(pair) == 2, np.roots(coeffs)
    return float(-pair[0].real / abs(pair[0]))


@pytest.mark.parametrize("k, zeta", [(1 / math.sqrt(2), 1 / math.sqrt(2)), (1.2, 0.5), (0.5, 0.9)])
def test_sogi_fll_rule_gives_the_damping_asked_for(k, zeta):
    """001 eq (19): ω̂/ω = (λ/2) / (s² + (kωn/2) s + λ/2); eq (22)'s λ places its poles at damping ζ."""
    obs = linear.sogi_fll_closed_form(k=k, zeta=zeta)
    assert _damping_of_complex_pair([1.0, k * WN / 2, float(obs.lam) / 2]) == pytest.approx(zeta, rel=1e-12)


def test_table_I_sogi_fll():
    obs = linear.sogi_fll_closed_form()
    assert round(float(obs.k), 4) == 0.7071  # Table I's k, the rule's input
    # by hand, eq (22) at k = ζ = 1/√2: λ = ωn²/8 = 12337.0055 (Table I prints it to the unit)
    assert float(obs.lam) == pytest.approx(WN**2 / 8, rel=1e-12) and float(obs.lam) == pytest.approx(12337.0, abs=0.5)
    assert float(obs.omega_n) == WN


@pytest.mark.parametrize("zeta", [1 / math.sqrt(2), 0.5, 0.9])
def test_wpf_rule_gives_the_damping_asked_for(zeta):
    """001 eq (24): ω̂/ω = d / (s³ + (b1 + b2) s² + b1b2 s + d), b_i = k_iωn/2, d = k1λωn/4; with Table I's
    k1 = k2 = √2, eq (29)'s λ gives its complex pole pair the damping ζ."""
    obs = linear.wpf_closed_form(zeta=zeta)
    k1, k2, lam = float(obs.k1), float(obs.k2), float(obs.lam)
    b1, b2 = k1 * WN / 2, k2 * WN / 2
    assert _damping_of_complex_pair([1.0, b1 + b2, b1 * b2, k1 * lam * WN / 4]) == pytest.approx(zeta, rel=1e-12)


def test_table_I_wpf():
    obs = linear.wpf_closed_form()
    assert round(float(obs.k1), 3) == round(float(obs.k2), 3) == 1.414  # Table I's k1 = k2, the rule's input
    # by hand: with b1 = b2 = ωn/√2, eq (24)'s denominator s³ + √2ωn s² + ωn²/2 s + √2λωn/4 factors as
    # (s + ωn)(s² + (√2 − 1)ωn s + (3/2 − √2)ωn²), whose pair has ζ = (√2 − 1)/(2√(3/2 − √2)) = 1/√2,
    # when λ = (3√2 − 4)ωn² = 23947.68
    assert float(obs.lam) == pytest.approx((3 * math.sqrt(2) - 4) * WN**2, rel=1e-12)
    assert float(obs.lam) == pytest.approx(23948.0, abs=0.5)
    roots = np.roots([1.0, math.sqrt(2) * WN, WN**2 / 2, math.sqrt(2) * float(obs.lam) * WN / 4])
    assert np.min(np.abs(roots + WN)) < 1e-9 * WN  # the real pole at −ωn


def test_table_I_wif():
    obs = linear.wif_closed_form()
    assert round(float(obs.k1), 3) == papers.WIF_K1
    assert round(float(obs.k2), 3) == papers.WIF_K2
    assert float(obs.lam) == pytest.approx(papers.WIF_LAM, abs=0.5)


def test_symmetric_optimum_pm_at_b_1_plus_sqrt2_is_45_degrees():
    assert math.degrees(float(linear.symmetric_optimum_pm(papers.WIF_B))) == pytest.approx(45.0)


def test_wif_characteristic_polynomial_factors_as_eq_35():
    """With (34), s³ + k1ωn/2 s² + k1k2ωn²/4 s + k1λωn/4 = (s + ωc)(s² + (b−1)ωc s + ωc²)."""
    b, wc, wn = papers.WIF_B, papers.WIF_OMEGA_C, papers.FLL_OMEGA_N
    obs = linear.wif_closed_form(omega_c=wc, b=b, omega_n=wn)
    den = linear.wif_model(obs.k1, obs.k2, obs.lam, obs.omega_n).frequency.den
    expected = [1.0, b * wc, b * wc**2, wc**3]
    for got, want in zip(den.tolist(), expected):
        assert got == pytest.approx(want, rel=1e-12)
