"""Paper 001 (SOGI-FLL family): small-signal models and closed-form tuning rules.

Closed forms are pure functions that return the same observer modules the
simulator runs, so a closed-form design and a tuned one are compared directly.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax.numpy as jnp
from jax.typing import ArrayLike

from ..observers import (
    pll_gains,
    second_order_soifo_lambda,
    sogi_fll_lambda,
    soifo_lambda,
    symmetric_optimum_pm,
    wif_symmetric_optimum,
    wpf_lambda,
)
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
    """The small-signal model of an FLL (001).

    Attributes:
        amplitude: V̂/V.
        phase: θ̂/θ.
        frequency: ω̂/ω.
        open_loop: θ̂/(θ − θ̂), the loop of 001 Fig. 14.
    """

    amplitude: TransferFunction  # V̂/V
    phase: TransferFunction  # θ̂/θ
    frequency: TransferFunction  # ω̂/ω
    open_loop: TransferFunction  # θ̂/(θ − θ̂), the loop of 001 Fig. 14


def sogi_fll_model(k: ArrayLike, lam: ArrayLike, omega_n: ArrayLike) -> FLLModel:
    """The SOGI-FLL's small-signal model, 001 eqs (18)–(20).

    Args:
        k: SOGI gain.
        lam: FLL gain λ, rad²/s².
        omega_n: Nominal frequency ωn, rad/s.

    Returns:
        The :class:`FLLModel`.
    """
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


def wpf_model(k1: ArrayLike, k2: ArrayLike, lam: ArrayLike, omega_n: ArrayLike) -> FLLModel:
    """001 eqs (23)–(25).

    001 notes that Fig. 4 "does not have a standard form"; rearranged, the loop
    whose closed loop is (24) is L = T/(1 − T) = (b1b2 s + d)/(s² (s + b1 + b2)),
    b_i = k_iωn/2, d = k1λωn/4 — the open loop drawn in Fig. 14.

    Args:
        k1: Prefilter SOGI gain.
        k2: SOGI gain of the SOGI-FLL.
        lam: FLL gain λ, rad²/s².
        omega_n: Nominal frequency ωn, rad/s.

    Returns:
        The :class:`FLLModel`.
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


def wif_model(k1: ArrayLike, k2: ArrayLike, lam: ArrayLike, omega_n: ArrayLike) -> FLLModel:
    """The SOGI-FLL-WIF's small-signal model, 001 eqs (30)–(32).

    Args:
        k1: In-loop filter damping gain.
        k2: In-loop filter gain.
        lam: FLL gain λ, rad²/s².
        omega_n: Nominal frequency ωn, rad/s.

    Returns:
        The :class:`FLLModel`.
    """
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
# closed-form tuning rules: the observers' own (jaxobs.observers), by their function names
# --------------------------------------------------------------------------


def sogi_fll_closed_form(**kw: Any) -> SOGIFLL:
    """:meth:`SOGIFLL.closed_form <jaxobs.SOGIFLL.closed_form_design>` itself: 001 eq (22) (Table I: k = 1/√2,
    λ = 12337); the rule, its defaults and its rows are the class's.

    Args:
        **kw: :meth:`SOGIFLL.closed_form_design`'s arguments (``k``, ``omega_n``, ``zeta``, constructor keywords).

    Returns:
        The :class:`~jaxobs.SOGIFLL`.
    """
    return SOGIFLL.closed_form(**kw)


def wpf_closed_form(**kw: Any) -> SOGIFLLWPF:
    """:meth:`SOGIFLLWPF.closed_form <jaxobs.SOGIFLLWPF.closed_form_design>` itself: 001 eq (29) (Table I:
    k1 = k2 = √2, λ = 23948); the rule, its defaults and its rows are the class's.

    Args:
        **kw: :meth:`SOGIFLLWPF.closed_form_design`'s arguments (``omega_n``, ``zeta``, constructor keywords).

    Returns:
        The :class:`~jaxobs.SOGIFLLWPF`.
    """
    return SOGIFLLWPF.closed_form(**kw)


def wif_closed_form(**kw: Any) -> SOGIFLLWIF:
    """:meth:`SOGIFLLWIF.closed_form <jaxobs.SOGIFLLWIF.closed_form_design>` itself: the symmetric optimum,
    001 eq (34) (b = 1 + √2, ωc = 2π·18.8 rad/s; Table I: k1 = 1.815, k2 = 0.752, λ = 11559); the rule, its
    defaults and its rows are the class's.

    Args:
        **kw: :meth:`SOGIFLLWIF.closed_form_design`'s arguments (``omega_c``, ``b``, ``omega_n``, constructor
            keywords).

    Returns:
        The :class:`~jaxobs.SOGIFLLWIF`.
    """
    return SOGIFLLWIF.closed_form(**kw)
