"""The papers' closed-form tuning rules as plain arithmetic: what each observer's ``closed_form`` evaluates.

They sit beside the observers (below :mod:`jaxobs.linear`, which re-exports them) so that an observer class owns
its closed form without importing the linear analysis above it.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .. import papers

# a rule's inputs and values: Python numbers, or JAX scalars (a design built from traced gains)
Scalar = float | jax.Array

__all__ = [
    "sogi_fll_lambda",
    "wpf_lambda",
    "wif_symmetric_optimum",
    "soifo_lambda",
    "second_order_soifo_lambda",
    "symmetric_optimum_pm",
    "pll_gains",
    "cleso_gains",
]


def sogi_fll_lambda(k: Scalar, omega_n: Scalar, zeta: Scalar = papers.FLL_ZETA) -> Scalar:
    """001 eq (22): λ = k² ωn² / (8 ζ²)  (= k² ωn² / 4 at ζ = 1/√2).

    Args:
        k: SOGI gain.
        omega_n: Nominal frequency ωn, rad/s.
        zeta: Damping ζ.

    Returns:
        λ, rad²/s².
    """
    return k**2 * omega_n**2 / (8 * zeta**2)


def wpf_lambda(omega_n: Scalar, zeta: Scalar = papers.FLL_ZETA) -> Scalar:
    """001 eq (29), with k1 = k2 = √2: λ = 2 (ζ + 1) ωn² / (2ζ + 1)³.

    Args:
        omega_n: Nominal frequency ωn, rad/s.
        zeta: Damping ζ.

    Returns:
        λ, rad²/s².
    """
    return 2 * (zeta + 1) * omega_n**2 / (2 * zeta + 1) ** 3


def wif_symmetric_optimum(b: Scalar, omega_c: Scalar, omega_n: Scalar) -> tuple[Scalar, Scalar, Scalar]:
    """001 eq (34): k1 = 2 b ωc / ωn, k2 = 2 ωc / ωn, λ = 2 ωc² / b.

    Args:
        b: The symmetric optimum's ratio b.
        omega_c: The crossover ωc, rad/s.
        omega_n: Nominal frequency ωn, rad/s.

    Returns:
        ``(k1, k2, λ)``.
    """
    return 2 * b * omega_c / omega_n, 2 * omega_c / omega_n, 2 * omega_c**2 / b


def soifo_lambda(k: Scalar) -> Scalar:
    """The SOIFO's FLL gain ``lam`` (dimensionless: 000's FLL is frequency-normalized, λ(ω̂) = lam·ω̂²,
    :mod:`jaxobs.observers.soifo`): 001 eq (22) at ζ = 1/√2 with ωn → 1, lam = k²/4, the same damping at
    every speed.

    Args:
        k: SOGI gain.

    Returns:
        lam.
    """
    return k**2 / 4


def second_order_soifo_lambda(K1: Scalar, K2: Scalar) -> Scalar:
    """The second-order SOIFO's FLL gain ``lam`` (dimensionless, as :func:`soifo_lambda`): 001's symmetric
    optimum (eq 34) frequency-normalized, in 000's names (the WIF's k1 = K2, k2 = K1) with b = K2/K1:
    lam = K1³/(2 K2).

    Args:
        K1: Second-order SOGI error gain.
        K2: Second-order SOGI damping gain.

    Returns:
        lam.
    """
    return K1**3 / (2 * K2)


def pll_gains(bandwidth: Scalar, zeta: Scalar = papers.PLL_ZETA) -> tuple[Scalar, Scalar]:
    """Type-2 PLL on a normalized error: k_p = 2ζω_b, k_i = ω_b² (θ̂/θ = (k_p s + k_i)/(s² + k_p s + k_i)).

    Args:
        bandwidth: ω_b, rad/s.
        zeta: Damping ζ.

    Returns:
        ``(k_p, k_i)``, 1/s and 1/s².
    """
    return 2 * zeta * bandwidth, bandwidth**2


def symmetric_optimum_pm(b: Scalar) -> jax.Array:
    """001 eq (39): phase margin of the symmetric optimum.

    Args:
        b: The symmetric optimum's ratio b.

    Returns:
        The phase margin, rad.
    """
    return jnp.arctan((b**2 - 1) / (2 * b))


def cleso_gains(omega0: Scalar, mu: Scalar) -> tuple[Scalar, Scalar]:
    """002 eq (16): the C-LESO's gains l1 = 2ω0 − μ, l2 = ω0², both poles at −ω0 (ê/e = ω0²/(s + ω0)², eq 17).

    The one place eq (16) is written: the C-LESO and the GI-LESO (whose L1 is the same, eq 29) run it,
    :func:`jaxobs.linear.cleso_closed_form` and the closed forms' rows report it.

    Args:
        omega0: The bandwidth ω0, rad/s.
        mu: μ = Rs/Lq, 1/s.

    Returns:
        ``(l1, l2)``, 1/s and 1/s².
    """
    return 2 * omega0 - mu, omega0**2
