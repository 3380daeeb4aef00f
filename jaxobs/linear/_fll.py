"""Paper 001 (SOGI-FLL family): small-signal models and closed-form tuning rules.

Closed forms are pure functions that return the same observer modules the
simulator runs, so a closed-form design and a tuned one are compared directly.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp

from .. import papers
from .._validate import as_float, check_positive, check_real
from ..observers.fll import SOGIFLL, SOGIFLLWIF, SOGIFLLWPF
from ._tf import TransferFunction

__all__ = [
    "FLLModel",
    "sogi_fll_model",
    "wpf_model",
    "wif_model",
    "sogi_fll_lambda",
    "wpf_lambda",
    "wif_symmetric_optimum",
    "soifo_lambda",
    "second_order_soifo_lambda",
    "symmetric_optimum_pm",
    "pll_gains",
    "sogi_fll_closed_form",
    "wpf_closed_form",
    "wif_closed_form",
]


# --------------------------------------------------------------------------
# paper 001 small-signal models (θ̂/θ, ω̂/ω and V̂/V)
# --------------------------------------------------------------------------


class FLLModel(eqx.Module):
    amplitude: TransferFunction  # V̂/V
    phase: TransferFunction  # θ̂/θ
    frequency: TransferFunction  # ω̂/ω
    open_loop: TransferFunction  # θ̂/(θ − θ̂), the loop of 001 Fig. 14


def sogi_fll_model(k, lam, omega_n) -> FLLModel:
    """001 eqs (18)–(20)."""
    kw = k * omega_n / 2
    den = jnp.stack([jnp.ones_like(kw), kw, lam / 2])
    zero = jnp.zeros_like(kw)
    return FLLModel(
        amplitude=TransferFunction(jnp.stack([kw]), jnp.stack([jnp.ones_like(kw), kw])),
        phase=TransferFunction(jnp.stack([kw, lam / 2]), den),
        frequency=TransferFunction(jnp.stack([lam / 2]), den),
        # (kωn/2)(s + λ/(kωn)) / s²
        open_loop=TransferFunction(jnp.stack([kw, lam / 2]), jnp.stack([jnp.ones_like(kw), zero, zero])),
    )


def wpf_model(k1, k2, lam, omega_n) -> FLLModel:
    """001 eqs (23)–(25).

    001 notes that Fig. 4 "does not have a standard form"; rearranged, the loop
    whose closed loop is (24) is L = T/(1 − T) = (b1b2 s + d)/(s² (s + b1 + b2)),
    b_i = k_iωn/2, d = k1λωn/4 — the open loop drawn in Fig. 14.
    """
    b1, b2 = k1 * omega_n / 2, k2 * omega_n / 2
    one = jnp.ones_like(b1)
    zero = jnp.zeros_like(b1)
    d = k1 * lam * omega_n / 4
    den = jnp.stack([one, b1 + b2, b1 * b2, d])
    return FLLModel(
        amplitude=TransferFunction(jnp.stack([b1 * b2]), jnp.stack([one, b1 + b2, b1 * b2])),
        phase=TransferFunction(jnp.stack([b1 * b2, d]), den),
        frequency=TransferFunction(jnp.stack([d]), den),
        open_loop=TransferFunction(jnp.stack([b1 * b2, d]), jnp.stack([one, b1 + b2, zero, zero])),
    )


def wif_model(k1, k2, lam, omega_n) -> FLLModel:
    """001 eqs (30)–(32)."""
    a = k1 * k2 * omega_n**2 / 4
    b = k1 * omega_n / 2
    d = k1 * lam * omega_n / 4
    one = jnp.ones_like(a)
    zero = jnp.zeros_like(a)
    den = jnp.stack([one, b, a, d])
    return FLLModel(
        amplitude=TransferFunction(jnp.stack([a]), jnp.stack([one, b, a])),
        phase=TransferFunction(jnp.stack([a, d]), den),
        frequency=TransferFunction(jnp.stack([d]), den),
        # eq (33): (k1k2ωn²/4)(s + λ/(k2ωn)) / (s² (s + k1ωn/2))
        open_loop=TransferFunction(jnp.stack([a, d]), jnp.stack([one, b, zero, zero])),
    )


# --------------------------------------------------------------------------
# closed-form tuning rules of paper 001
# --------------------------------------------------------------------------


def sogi_fll_lambda(k, omega_n, zeta=papers.FLL_ZETA):
    """001 eq (22): λ = k² ωn² / (8 ζ²)  (= k² ωn² / 4 at ζ = 1/√2)."""
    return k**2 * omega_n**2 / (8 * zeta**2)


def wpf_lambda(omega_n, zeta=papers.FLL_ZETA):
    """001 eq (29), with k1 = k2 = √2: λ = 2 (ζ + 1) ωn² / (2ζ + 1)³."""
    return 2 * (zeta + 1) * omega_n**2 / (2 * zeta + 1) ** 3


def wif_symmetric_optimum(b, omega_c, omega_n):
    """001 eq (34): k1 = 2 b ωc / ωn, k2 = 2 ωc / ωn, λ = 2 ωc² / b."""
    return 2 * b * omega_c / omega_n, 2 * omega_c / omega_n, 2 * omega_c**2 / b


def soifo_lambda(k):
    """The SOIFO's FLL gain ``lam`` (dimensionless: 000's FLL is frequency-normalized, λ(ω̂) = lam·ω̂²,
    :mod:`jaxobs.observers.flux`): 001 eq (22) at ζ = 1/√2 with ωn → 1, lam = k²/4, the same damping at
    every speed."""
    return k**2 / 4


def second_order_soifo_lambda(K1, K2):
    """The second-order SOIFO's FLL gain ``lam`` (dimensionless, as :func:`soifo_lambda`): 001's symmetric
    optimum (eq 34) frequency-normalized, in 000's names (the WIF's k1 = K2, k2 = K1) with b = K2/K1:
    lam = K1³/(2 K2)."""
    return K1**3 / (2 * K2)


def pll_gains(bandwidth, zeta=papers.PLL_ZETA):
    """Type-2 PLL on a normalized error: k_p = 2ζω_b, k_i = ω_b² (θ̂/θ = (k_p s + k_i)/(s² + k_p s + k_i))."""
    return 2 * zeta * bandwidth, bandwidth**2


def symmetric_optimum_pm(b):
    """001 eq (39): phase margin of the symmetric optimum, rad."""
    return jnp.arctan((b**2 - 1) / (2 * b))


def sogi_fll_closed_form(k=papers.SOGI_FLL_K, omega_n=papers.FLL_OMEGA_N, zeta=papers.FLL_ZETA, **kw):
    """A :class:`~jaxobs.SOGIFLL` tuned by 001 eq (22) (Table I: k = 1/√2, λ = 12337)."""
    check_positive("k", k, "sogi_fll_closed_form")
    check_positive("zeta", zeta, "sogi_fll_closed_form")
    return SOGIFLL(k=k, lam=sogi_fll_lambda(as_float(k), as_float(omega_n), zeta), omega_n=omega_n, **kw)


def wpf_closed_form(omega_n=papers.FLL_OMEGA_N, zeta=papers.FLL_ZETA, **kw):
    """A :class:`~jaxobs.SOGIFLLWPF` tuned by 001 eq (29) (Table I: k1 = k2 = √2, λ = 23948)."""
    check_positive("zeta", zeta, "wpf_closed_form")
    lam = wpf_lambda(as_float(omega_n), zeta)
    return SOGIFLLWPF(k1=papers.WPF_K1, k2=papers.WPF_K2, lam=lam, omega_n=omega_n, **kw)


def wif_closed_form(omega_c=papers.WIF_OMEGA_C, b=papers.WIF_B, omega_n=papers.FLL_OMEGA_N, **kw):
    """A :class:`~jaxobs.SOGIFLLWIF` tuned by the symmetric optimum, 001 eq (34).

    Defaults are 001's: b = 1 + √2 (ζ = 1/√2, PM = 45°), ωc = 2π·18.8 rad/s
    (Table I: k1 = 1.815, k2 = 0.752, λ = 11559).
    """
    check_real("b", b, lower=1.0, owner="wif_closed_form")
    check_positive("omega_c", omega_c, "wif_closed_form")
    k1, k2, lam = wif_symmetric_optimum(as_float(b), as_float(omega_c), as_float(omega_n))
    return SOGIFLLWIF(k1=k1, k2=k2, lam=lam, omega_n=omega_n, **kw)
