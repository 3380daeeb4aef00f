"""Sample times kept exact, and signal phases that stay accurate in float32 over long horizons.

Why.  A signal's phase is 2π·f·t from the absolute time t.  In float32 (the default unless the caller
enables x64) t_k = t0 + k·ts at t = 100 s carries an error of up to ½ ulp(100) = 3.8 µs, and the
product 2π·f·t ≈ 31 416 rad another ½ ulp(31 416) = 1 mrad: the input and the truth jitter by
~1e-3 rad, which is larger than the steady errors being measured (the WIF's rms phase error under
Test C is ~5e-3 rad; its ripple is set by the same jitter).  Forming the time or the phase in
float64 inside the trace is not possible (x64 off means no float64 at all), and numpy outside the
trace cannot see the traced frequency.

How.  :class:`SampleTime` carries the sample *index* k (int32, exact) with the static ts and t0
(Python floats, exact to 53 bits), and :func:`cycles` forms frac(rate·scale·(t0 + k·ts)) — the
phase in cycles, reduced modulo 1 — from pieces that are each *exact* in float32:

- rate (traced float32, 24 significant bits) is split by bit masking into two halves of ≤ 12
  significant bits (masking cannot be rounded, re-associated or contracted into an FMA by XLA);
- A = scale·ts (static float64) is split into four float32 pieces of ≤ 12 bits (48 bits in all:
  relative error 2^-48, 4e-8 cycles after 2³¹ samples of 50 Hz at 10 kHz);
- a product of two ≤ 12-bit pieces has ≤ 24 bits: it is exact; it is split again into halves;
- k is split into 12-bit chunks k = k0 + k1·2¹² + k2·2²⁴ (exact as float32), and a half times a
  chunk (≤ 24 bits) times a power of two is again exact;
- x − round(x) of an exact x is exact.

So every term's fractional part is exact; only their sum is rounded, and it is reduced modulo 1
after every addition so it stays in [−½, ½] where a float32 step is 3e-8 cycles: the phase of any
sample, at any horizon below 2³¹ samples, is accurate to ~1e-6 rad.  The same goes for the static
t0 (its pieces times the rate's halves) and for a product of two traced numbers (:func:`frac_mul`,
for Δf·t_e).

Gradients.  The masking has no derivative; the exact value is computed from ``stop_gradient``
inputs and the naive product's tangent is added back, ``exact + (x − stop_gradient(x))``, whose
value is ``exact`` bit for bit and whose derivative is the naive product's (d/d rate = scale·t).

In float64 (x64 on) none of this runs: the signals keep their plain formulas, bit for bit as
before (a float64 phase at 100 s is accurate to 4e-12 rad).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

__all__ = ["SampleTime", "time_value", "exact_phase", "cycles", "frac_mul"]

_MASK = np.uint32(0xFFFFF000)  # sign, exponent and the top 11 stored mantissa bits: 12 significant bits


# The one tolerance on a sample interval, relative, from a log's reader to the run: a recording whose interval is
# within it of the observer's is on the observer's grid and its samples are taken as they are, by index (a log's
# time stamps printed to 12 digits give ts = 9.99999999997669e-05 for 1e-4).  Over the longest simulation a job
# allows (10^7 samples) such a difference moves the last sample by 1e-2 of a period at most.
TS_REL_TOL = 1e-9

Time = jax.Array | np.ndarray | float  # a float time, s (any shape)


class SampleTime(eqx.Module):
    """The time of sample ``k``, t = t0 + k·ts, kept as the integer k and the static ts and t0.

    Signals that know it (:class:`~jaxobs.signals.GridSignal`, :class:`~jaxobs.signals.EMFSignal`,
    :class:`~jaxobs.scenarios.NoisyGridSignal`) form their phase from it exactly in float32 (module doc);
    :class:`~jaxobs.OnSignal` passes one to such signals instead of the rounded float t_k.

    Attributes:
        k: The sample index (int32, any shape).
        ts: The sample period (s, static).
        t0: The time of sample 0 (s, static).
    """

    k: jax.Array  # the sample index (int32, any shape)
    ts: float = eqx.field(static=True)  # s
    t0: float = eqx.field(static=True)  # s

    def value(self) -> jax.Array:
        """t0 + k·ts in the default float dtype (rounded: for comparisons and tangents, not for phases).

        Returns:
            The time, s.
        """
        return self.t0 + self.ts * jnp.asarray(self.k).astype(jnp.result_type(float))


TimeLike = Time | SampleTime  # a float time, or a SampleTime (sample k of a static period)


def time_value(t: TimeLike) -> Time:
    """The float time of ``t``.

    Args:
        t: A float array, or a :class:`SampleTime`.

    Returns:
        ``t`` itself, or the :class:`SampleTime`'s rounded value.
    """
    return t.value() if isinstance(t, SampleTime) else t


def exact_phase(t: TimeLike, *leaves: ArrayLike) -> bool:
    """Whether to form phases by :func:`cycles`: ``t`` is a SampleTime and the arithmetic is float32.

    Args:
        t: A float time, or a :class:`SampleTime`.
        *leaves: The other operands, whose dtypes join ``t``'s.

    Returns:
        Whether phases are formed by :func:`cycles`.
    """
    if not isinstance(t, SampleTime):
        return False
    return jnp.result_type(t.value(), *leaves) == jnp.float32


def _split(x):
    """x (float32) = hi + lo exactly, each with ≤ 12 significant bits."""
    hi = jax.lax.bitcast_convert_type(jax.lax.bitcast_convert_type(x, jnp.uint32) & _MASK, jnp.float32)
    return hi, x - hi  # x − hi is the low 12 mantissa bits: exact


def _static_pieces(c: float, n: int = 4) -> list[float]:
    """A Python float as n float32 numbers of ≤ 12 significant bits (c to 12·n bits)."""
    out, r = [], float(c)
    for _ in range(n):
        p = float((np.asarray(r, np.float32).view(np.uint32) & _MASK).view(np.float32))
        if p == 0.0:
            break
        out.append(p)
        r -= p  # exact in float64: p is r's leading bits
    return out


def _frac(x):
    return x - jnp.round(x)


class _Sum:
    """A running sum of fractional parts, kept in [−½, ½] (modulo 1) after every addition."""

    def __init__(self) -> None:
        self.s: jax.Array | None = None

    def add(self, x):
        self.s = _frac(x) if self.s is None else _frac(self.s + _frac(x))


def _cycles_exact(rate, a_pieces, b_pieces, k):
    acc = _Sum()
    r_halves = _split(rate)
    kk = jnp.asarray(k, jnp.int32)
    chunks = [c.astype(jnp.float32) for c in (kk & 0xFFF, (kk >> 12) & 0xFFF, kk >> 24)]  # k = Σ c_m 2^(12m)
    for r in r_halves:
        for a in a_pieces:
            for p in _split(r * jnp.float32(a)):  # r·a: ≤ 24 bits, exact
                for m, km in enumerate(chunks):
                    acc.add((p * jnp.float32(2.0 ** (12 * m))) * km)  # ≤ 24 bits times 2^(12m): exact
        for b in b_pieces:
            acc.add(r * jnp.float32(b))
    return acc.s if acc.s is not None else jnp.zeros_like(rate)


def cycles(rate: Time, t: TimeLike, scale: float = 1.0) -> Time:
    """rate·scale·t in cycles: reduced to [−½, ½] and exact (module doc) when ``t`` is a float32
    :class:`SampleTime`; else the plain product (float64, or a float time).

    Args:
        rate: A frequency in Hz (scale 1) or rad/s (scale 1/(2π)).
        t: A float time, or a :class:`SampleTime`.
        scale: The rate's scale to Hz (static).

    Returns:
        rate·scale·t, cycles.
    """
    tv = time_value(t)
    naive = rate * (scale * tv)
    if not isinstance(t, SampleTime) or not exact_phase(t, rate):
        return naive
    rate = jnp.asarray(rate, jnp.float32)
    a = _static_pieces(scale * t.ts)
    b = _static_pieces(scale * t.t0) if t.t0 != 0.0 else []
    k = jnp.broadcast_to(jnp.asarray(t.k), jnp.broadcast_shapes(jnp.shape(t.k), jnp.shape(rate)))
    exact = _cycles_exact(jax.lax.stop_gradient(jnp.broadcast_to(rate, k.shape)), a, b, k)
    return exact + (naive - jax.lax.stop_gradient(naive))


def frac_mul(x: jax.Array, y: jax.Array) -> jax.Array:
    """x·y modulo 1 in [−½, ½], exact before the last rounding, for float32 x, y (straight-through tangent).

    Args:
        x: A float32 factor.
        y: A float32 factor.

    Returns:
        x·y modulo 1, in [−½, ½].
    """
    naive = x * y
    xs, ys = jax.lax.stop_gradient(x), jax.lax.stop_gradient(y)
    acc = _Sum()
    for a in _split(xs):
        for b in _split(ys):
            acc.add(a * b)  # ≤ 24 bits: exact
    assert acc.s is not None  # four products added
    return acc.s + (naive - jax.lax.stop_gradient(naive))


TWO_PI = 2 * math.pi
