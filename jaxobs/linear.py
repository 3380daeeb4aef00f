"""Linear analysis: transfer functions as coefficient arrays, responses, the papers'
small-signal models and closed-form tuning rules.

Transfer functions hold numerator and denominator coefficients (highest power
first, as ``jnp.polyval``), real or complex, so frequency responses and
anything computed from them are differentiable with respect to gains.

Closed forms are pure functions that return the same observer modules the
simulator runs, so a closed-form design and a tuned one are compared directly.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl

from ._validate import as_float, check_positive, check_real

__all__ = [
    "TransferFunction",
    "sogi_fll_model",
    "wpf_model",
    "wif_model",
    "sogi_fll_lambda",
    "wpf_lambda",
    "wif_symmetric_optimum",
    "symmetric_optimum_pm",
    "sogi_fll_closed_form",
    "wpf_closed_form",
    "wif_closed_form",
]


class TransferFunction(eqx.Module):
    """G(s) = num(s) / den(s), coefficients highest power first."""

    num: jax.Array
    den: jax.Array

    def __init__(self, num, den):
        num = jnp.atleast_1d(jnp.asarray(num))
        den = jnp.atleast_1d(jnp.asarray(den))
        dtype = jnp.result_type(num, den, float)
        self.num = num.astype(dtype)
        self.den = den.astype(dtype)

    def __call__(self, s):
        return jnp.polyval(self.num, s) / jnp.polyval(self.den, s)

    def freqresp(self, omega):
        return self(1j * as_float(omega))

    def state_space(self):
        """Controllable canonical form (A, B, C, D) of a proper G."""
        den = self.den / self.den[0]
        num = self.num / self.den[0]
        n = den.shape[0] - 1
        if num.shape[0] > n + 1:
            raise ValueError(f"TransferFunction must be proper: numerator degree {num.shape[0]-1} > denominator degree {n}")
        num = jnp.concatenate([jnp.zeros(n + 1 - num.shape[0], num.dtype), num])
        d = num[0]
        b = num[1:] - d * den[1:]  # strictly proper part, highest power first
        a = jnp.zeros((n, n), den.dtype).at[0, :].set(-den[1:])
        a = a.at[1:, :-1].set(jnp.eye(n - 1, dtype=den.dtype)) if n > 1 else a
        bvec = jnp.zeros((n, 1), den.dtype).at[0, 0].set(1.0)
        c = b[None, :]
        return a, bvec, c, d

    def _zoh(self, dt: float):
        a, b, c, d = self.state_space()
        n = a.shape[0]
        m = jnp.zeros((n + 1, n + 1), a.dtype).at[:n, :n].set(a).at[:n, n:].set(b)
        em = jsl.expm(m * dt)
        return em[:n, :n], em[:n, n:], c, d

    def lsim_zoh(self, u, dt: float, x0=None):
        """Response to samples ``u`` held over each ``dt`` (exact ZOH discretization)."""
        ad, bd, c, d = self._zoh(dt)
        x = jnp.zeros((ad.shape[0], 1), ad.dtype) if x0 is None else x0

        def body(x, uk):
            y = (c @ x)[0, 0] + d * uk
            return ad @ x + bd * uk, y

        _, y = jax.lax.scan(body, x, u)
        return y

    def step(self, t):
        """Unit-step response at uniformly spaced times ``t`` (exact for a step at t[0])."""
        dt = float(t[1] - t[0])
        return self.lsim_zoh(jnp.ones_like(t), dt)

    def impulse(self, t):
        """Unit-impulse response C e^{At} B of a strictly proper G at uniformly spaced ``t``."""
        dt = float(t[1] - t[0])
        ad, _, c, _ = self._zoh(dt)
        _, b, _, _ = self.state_space()

        def body(x, _):
            return ad @ x, (c @ x)[0, 0]

        _, y = jax.lax.scan(body, b, None, length=t.shape[0])
        return y


# --------------------------------------------------------------------------
# paper 001 small-signal models (θ̂/θ, ω̂/ω and V̂/V)
# --------------------------------------------------------------------------


class FLLModel(eqx.Module):
    amplitude: TransferFunction  # V̂/V
    phase: TransferFunction  # θ̂/θ
    frequency: TransferFunction  # ω̂/ω


def sogi_fll_model(k, lam, omega_n) -> FLLModel:
    """001 eqs (18)–(20)."""
    kw = k * omega_n / 2
    den = jnp.stack([jnp.ones_like(kw), kw, lam / 2])
    return FLLModel(
        amplitude=TransferFunction(jnp.stack([kw]), jnp.stack([jnp.ones_like(kw), kw])),
        phase=TransferFunction(jnp.stack([kw, lam / 2]), den),
        frequency=TransferFunction(jnp.stack([lam / 2]), den),
    )


def wpf_model(k1, k2, lam, omega_n) -> FLLModel:
    """001 eqs (23)–(25)."""
    b1, b2 = k1 * omega_n / 2, k2 * omega_n / 2
    one = jnp.ones_like(b1)
    den = jnp.stack([one, b1 + b2, b1 * b2, k1 * lam * omega_n / 4])
    return FLLModel(
        amplitude=TransferFunction(jnp.stack([b1 * b2]), jnp.stack([one, b1 + b2, b1 * b2])),
        phase=TransferFunction(jnp.stack([b1 * b2, k1 * lam * omega_n / 4]), den),
        frequency=TransferFunction(jnp.stack([k1 * lam * omega_n / 4]), den),
    )


def wif_model(k1, k2, lam, omega_n) -> FLLModel:
    """001 eqs (30)–(32)."""
    a = k1 * k2 * omega_n**2 / 4
    b = k1 * omega_n / 2
    d = k1 * lam * omega_n / 4
    one = jnp.ones_like(a)
    den = jnp.stack([one, b, a, d])
    return FLLModel(
        amplitude=TransferFunction(jnp.stack([a]), jnp.stack([one, b, a])),
        phase=TransferFunction(jnp.stack([a, d]), den),
        frequency=TransferFunction(jnp.stack([d]), den),
    )


# --------------------------------------------------------------------------
# closed-form tuning rules of paper 001
# --------------------------------------------------------------------------


def sogi_fll_lambda(k, omega_n, zeta=1 / math.sqrt(2)):
    """001 eq (22): λ = k² ωn² / (8 ζ²)  (= k² ωn² / 4 at ζ = 1/√2)."""
    return k**2 * omega_n**2 / (8 * zeta**2)


def wpf_lambda(omega_n, zeta=1 / math.sqrt(2)):
    """001 eq (29), with k1 = k2 = √2: λ = 2 (ζ + 1) ωn² / (2ζ + 1)³."""
    return 2 * (zeta + 1) * omega_n**2 / (2 * zeta + 1) ** 3


def wif_symmetric_optimum(b, omega_c, omega_n):
    """001 eq (34): k1 = 2 b ωc / ωn, k2 = 2 ωc / ωn, λ = 2 ωc² / b."""
    return 2 * b * omega_c / omega_n, 2 * omega_c / omega_n, 2 * omega_c**2 / b


def symmetric_optimum_pm(b):
    """001 eq (39): phase margin of the symmetric optimum, rad."""
    return jnp.arctan((b**2 - 1) / (2 * b))


def sogi_fll_closed_form(k=1 / math.sqrt(2), omega_n=100 * math.pi, zeta=1 / math.sqrt(2), **kw):
    """A :class:`~jaxobs.SOGIFLL` tuned by 001 eq (22) (Table I: k = 1/√2, λ = 12337)."""
    from .observers.fll import SOGIFLL

    check_positive("k", k, "sogi_fll_closed_form")
    check_positive("zeta", zeta, "sogi_fll_closed_form")
    return SOGIFLL(k=k, lam=sogi_fll_lambda(as_float(k), as_float(omega_n), zeta), omega_n=omega_n, **kw)


def wpf_closed_form(omega_n=100 * math.pi, zeta=1 / math.sqrt(2), **kw):
    """A :class:`~jaxobs.SOGIFLLWPF` tuned by 001 eq (29) (Table I: k1 = k2 = √2, λ = 23948)."""
    from .observers.fll import SOGIFLLWPF

    check_positive("zeta", zeta, "wpf_closed_form")
    return SOGIFLLWPF(k1=math.sqrt(2), k2=math.sqrt(2), lam=wpf_lambda(as_float(omega_n), zeta), omega_n=omega_n, **kw)


def wif_closed_form(omega_c=2 * math.pi * 18.8, b=1 + math.sqrt(2), omega_n=100 * math.pi, **kw):
    """A :class:`~jaxobs.SOGIFLLWIF` tuned by the symmetric optimum, 001 eq (34).

    Defaults are 001's: b = 1 + √2 (ζ = 1/√2, PM = 45°), ωc = 2π·18.8 rad/s
    (Table I: k1 = 1.815, k2 = 0.752, λ = 11559).
    """
    from .observers.fll import SOGIFLLWIF

    check_real("b", b, lower=1.0, owner="wif_closed_form")
    check_positive("omega_c", omega_c, "wif_closed_form")
    k1, k2, lam = wif_symmetric_optimum(as_float(b), as_float(omega_c), as_float(omega_n))
    return SOGIFLLWIF(k1=k1, k2=k2, lam=lam, omega_n=omega_n, **kw)
