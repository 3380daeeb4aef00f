"""Discrete-time transfer functions H(z) and Tustin's discretization of a :class:`~jaxobs.linear.TransferFunction`."""

from __future__ import annotations

import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from ..core.validate import as_float
from ._tf import TransferFunction, _real_coefficients

__all__ = ["DiscreteTransferFunction", "tustin"]


class DiscreteTransferFunction(eqx.Module):
    """H(z) = Σ b_k z^(−k) / Σ a_k z^(−k), coefficients in ascending powers of z⁻¹, a₀ = 1.

    Attributes:
        num: b_0, b_1, …
        den: a_0 = 1, a_1, …
        ts: The sample time, s (static).
    """

    num: jax.Array
    den: jax.Array
    ts: float = eqx.field(static=True)

    def to_control(self) -> Any:
        """This H(z) as a discrete ``control.TransferFunction`` (``dt = ts``), in python-control's descending
        powers of z (both polynomials multiplied by zⁿ); complex coefficients are refused."""
        import control

        b, a = _real_coefficients(self, "DiscreteTransferFunction.to_control")
        n = max(b.shape[0], a.shape[0])
        return control.tf(np.pad(b, (0, n - b.shape[0])), np.pad(a, (0, n - a.shape[0])), self.ts)

    def __call__(self, z: ArrayLike) -> jax.Array:
        zi = 1.0 / z
        return jnp.polyval(self.num[::-1], zi) / jnp.polyval(self.den[::-1], zi)

    def freqresp(self, omega: ArrayLike) -> jax.Array:
        """H(e^{jωT_s}).

        Args:
            omega: The angular frequencies, rad/s.

        Returns:
            H(e^{jωT_s}), complex.
        """
        return self(jnp.exp(1j * as_float(omega) * self.ts))

    def filter(self, u: jax.Array) -> jax.Array:
        """Run the difference equation from rest (direct form II transposed).

        Args:
            u: The input samples.

        Returns:
            The output samples.
        """
        n = max(self.num.shape[0], self.den.shape[0]) - 1
        dtype = jnp.result_type(self.num, self.den, u)
        b = jnp.concatenate([self.num, jnp.zeros(n + 1 - self.num.shape[0], self.num.dtype)]).astype(dtype)
        a = jnp.concatenate([self.den, jnp.zeros(n + 1 - self.den.shape[0], self.den.dtype)]).astype(dtype)
        if n == 0:
            return b[0] * u

        def body(state: jax.Array, uk: jax.Array) -> tuple[jax.Array, jax.Array]:
            y = b[0] * uk + state[0]
            shifted = jnp.concatenate([state[1:], jnp.zeros((1,), dtype)])
            return shifted + b[1:] * uk - a[1:] * y, y

        _, y = jax.lax.scan(body, jnp.zeros((n,), dtype), u)
        return y


def tustin(tf: TransferFunction, ts: float, prewarp: float | None = None) -> DiscreteTransferFunction:
    """Bilinear (Tustin) discretization s → c (z − 1)/(z + 1), c = 2/ts.

    Args:
        tf: The :class:`TransferFunction`.
        ts: The sample time, s.
        prewarp: ω_p, rad/s: c = ω_p / tan(ω_p ts / 2) so that the discrete response equals the continuous
            one exactly at ω_p (None: c = 2/ts).

    Returns:
        The :class:`DiscreteTransferFunction`.
    """
    if not (ts > 0 and math.isfinite(ts)):
        raise ValueError(f"tustin ts must be a positive finite sample time, got {ts!r}")
    c = 2.0 / ts if prewarp is None else prewarp / math.tan(prewarp * ts / 2)
    n = max(tf.num.shape[0], tf.den.shape[0]) - 1
    zm1 = jnp.array([1.0, -1.0])  # (z − 1)
    zp1 = jnp.array([1.0, 1.0])  # (z + 1)

    def substitute(coeffs: jax.Array) -> jax.Array:
        # Σ_k c_k s^(m−k) · (z+1)^n  with s = c (z−1)/(z+1):  Σ_k c_k c^(m−k) (z−1)^(m−k) (z+1)^(n−m+k)
        m = coeffs.shape[0] - 1
        out = jnp.zeros((n + 1,), jnp.result_type(coeffs, float))
        for k in range(m + 1):
            p = jnp.ones((1,))
            for _ in range(m - k):
                p = jnp.convolve(p, zm1)
            for _ in range(n - m + k):
                p = jnp.convolve(p, zp1)
            out = out + coeffs[k] * c ** (m - k) * p
        return out  # highest power of z first == ascending powers of z^-1 after dividing by z^n

    num = substitute(tf.num)
    den = substitute(tf.den)
    return DiscreteTransferFunction(num=num / den[0], den=den / den[0], ts=float(ts))
