"""Paper 001 Table I from the closed-form formulas (float64): the published gains
(:mod:`jaxobs.papers`) are the oracle, the formulas compute them from ζ, b, ωc and ωn."""

import math

import pytest

from jaxobs import linear, papers


def test_table_I_sogi_fll():
    obs = linear.sogi_fll_closed_form()
    assert float(obs.k) == pytest.approx(papers.SOGI_FLL_K)
    assert float(obs.lam) == pytest.approx(papers.SOGI_FLL_LAM, abs=0.5)  # 4 significant digits (12337 ± 0.5)


def test_table_I_wpf():
    obs = linear.wpf_closed_form()
    assert float(obs.k1) == pytest.approx(papers.WPF_K1) and float(obs.k2) == pytest.approx(papers.WPF_K2)
    assert float(obs.lam) == pytest.approx(papers.WPF_LAM, abs=0.5)


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
