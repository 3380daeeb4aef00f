"""Sine and cosine of one angle together, vectorizable in float64 and float32: the drive's Park transforms
and machine, the grid signals.

``sincos(x)`` returns ``(sin x, cos x)``.  Every rotation in the drive's step (Park and inverse Park
transforms, the BEMF's 6θ harmonic factor) needs both of one angle: computing them once per distinct angle
and passing the pair on keeps the step's transcendental calls to one pair per angle.

Why a sine of our own: XLA's CPU backend calls a scalar library routine per element for float64 ``sin`` and
``cos`` (9–14 ns a value, docs/performance.md "The drive in float64"), and its float32 ones, its own
polynomial, are not vectorized well here either (float32 ``cos`` 3.6 ns a value on 10⁶ values); the
drive's step makes dozens of them and an FLL's grid signal two a sample.  ``sincos`` is written in plain
``jnp`` arithmetic, which XLA vectorizes like any other: fdlibm's algorithm (Sun Microsystems' freely
distributable libm, as in FreeBSD's ``k_sin.c``, ``k_cos.c`` and ``e_rem_pio2.c``) without its branches:

1. Cody–Waite reduction: n = round(x·2/π) and r = x − n·π/2 with π/2 split into four parts P1 + P2 + P3 +
   P4 (fdlibm's ``pio2_1``, ``pio2_2``, ``pio2_3`` of 33 significant bits each and ``pio2_3t``, 152 bits in
   all).  For |n| < 2²⁰ (|x| < 1.6·10⁶) the products n·P1, n·P2, n·P3 are exact and x − n·P1 is exact; the
   two further subtractions carry their rounding errors exactly (TwoSum), so r is held as hi + lo to about
   2⁻¹⁰⁰ absolute, enough for x next to a multiple of π/2, where r is small and all its bits matter.
2. fdlibm's minimax polynomials on [−π/4, π/4] (degree 13 for sin, 14 for cos; |error| < 2⁻⁵⁸ relative)
   with the first-order correction for lo.
3. The quadrant n mod 4 picks ±sin r or ±cos r (selects, no branches).

Accuracy (tests/test_trig.py, against NumPy's libm on 10⁶ points and on the awkward ones: multiples of π/2
and the doubles nearest them, ±0, tiny, up to 10⁵): at most 1 ulp for |x| ≤ 10⁵.  Beyond 2²⁰·π/2 the first
product is no longer exact and the error grows as the argument's own spacing ulp(x) does (the angle
itself is no better known); above 2⁵⁰ rad (a spacing of 1/4 rad) the result is NaN rather than a number
that looks like a sine.  Infinite or NaN in, NaN out, as ``jnp.sin``.

float32 (it works with ``jax_enable_x64`` off, where float64 does not exist) is the same
algorithm in float32 arithmetic: π/2 = Q1 + Q2 + Q3 + Q4, the first three π/2's leading bits cut at 12
significant bits (8, 10 and 11 of them nonzero), so for |n| < 2¹³ (|x| < 1.2·10⁴) n·Q1, n·Q2, n·Q3 are
exact, r is held as hi + lo as above (π/2 known to 8·10⁻²⁰), and Cephes's float32 minimax polynomials
(Moshier's ``sinf.c``: degree 7 for sin, 8 for cos on [−π/4, π/4]) in fdlibm's form with its correction
for lo.  Accuracy (tests/test_trig.py, against NumPy's float64 rounded to float32): at most 1 ulp on 10⁶
random angles in ±10³ rad (and in ±10⁴ and ±4, measured), and 0 ulp on the float32 nearest each multiple
of π/2 up to 10³ and its 16 neighbours either side, where XLA's ``sin`` and ``cos`` are off by 1 ulp.
Beyond 2¹³·π/2 the error grows as ulp(x); above 2²¹ rad (a spacing of 1/4 rad) the result is NaN.  A
float32 subnormal's sine is ±0, not the subnormal: XLA's CPU code flushes float32 subnormals in its
arithmetic, and taking x itself after the division by one below made the float32 and float64 drives
slower (the select was copied into every consumer fusion with all it reads; docs/performance.md).  Its cosine
is several times faster than XLA's ``cos`` (docs/performance.md).
Other dtypes (float16, bfloat16) keep XLA's ``sin`` and ``cos``.

Derivatives: a ``custom_jvp`` that uses ``sincos`` itself (d sin = cos dx, d cos = −sin dx), so every
order of derivative is the same function.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

__all__ = ["sincos"]

# π/2 = P1 + P2 + P3 + P4 (fdlibm e_rem_pio2.c: pio2_1, pio2_2, pio2_3 with 33 significant bits, pio2_3t);
# the rest is 7.4e-49.  Written as hex so the bits are the ones meant.
_P1 = float.fromhex("0x1.921fb54400000p+0")
_P2 = float.fromhex("0x1.0b4611a600000p-34")
_P3 = float.fromhex("0x1.3198a2e000000p-69")
_P4 = float.fromhex("0x1.b839a252049c1p-104")
_TWO_OVER_PI = float.fromhex("0x1.45f306dc9c883p-1")
# fdlibm k_sin.c: sin x ≈ x + S1 x³ + … + S6 x¹³ on [−π/4, π/4]
_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
# fdlibm k_cos.c: cos x ≈ 1 − x²/2 + C1 x⁴ + … + C6 x¹⁴ on [−π/4, π/4]
_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11
_LIMIT = 2.0**50  # rad: beyond it NaN (module doc)

# float32: π/2 = Q1 + Q2 + Q3 + Q4, Q1..Q3 π/2's leading bits cut at 12 significant bits (8, 10 and 11 of
# them nonzero), Q4 the rest rounded to 24 bits; the rest of the rest is 8.3e-20.  Exact in float32.
_Q1 = float.fromhex("0x1.92p+0")
_Q2 = float.fromhex("0x1.fb4p-12")
_Q3 = float.fromhex("0x1.444p-24")
_Q4 = float.fromhex("0x1.68c234p-39")
_TWO_OVER_PI32 = float.fromhex("0x1.45f306p-1")
# Cephes sinf.c (Moshier): sin x ≈ x + T1 x³ + T2 x⁵ + T3 x⁷ and cos x ≈ 1 − x²/2 + D1 x⁴ + D2 x⁶ + D3 x⁸,
# float32 minimax polynomials on [−π/4, π/4]
_T1 = -1.6666654611e-1
_T2 = 8.3321608736e-3
_T3 = -1.9515295891e-4
_D1 = 4.166664568298827e-2
_D2 = -1.388731625493765e-3
_D3 = 2.443315711809948e-5
_LIMIT32 = 2.0**21  # rad: beyond it NaN (module doc)


def sincos(x: ArrayLike) -> tuple[jax.Array, jax.Array]:
    """(sin x, cos x): in float64 and float32 the vectorizable version of the module doc (float64: at most 1 ulp
    from libm's for |x| ≤ 10⁵; float32: see the module doc), in any other dtype XLA's ``sin`` and ``cos``.

    Args:
        x: The angle, rad (any shape).

    Returns:
        ``(sin x, cos x)``.
    """
    x = jnp.asarray(x)
    if x.dtype not in (jnp.float64, jnp.float32):
        return jnp.sin(x), jnp.cos(x)
    return _sincos(x)


def _two_sum(a, b):
    """s + e = a + b exactly, s = fl(a + b) (Knuth's TwoSum: no condition on the magnitudes)."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def _reduce(x, p1, p2, p3, p4, two_over_pi):
    """(n, hi, lo): x = n·π/2 + hi + lo, |hi + lo| ≤ π/4 (a hair more after rounding n), n integral (float).

    π/2 = p1 + p2 + p3 + p4; the products n·p1, n·p2, n·p3 exact in x's precision (float64: |n| < 2²⁰,
    float32: |n| < 2¹³)."""
    n = jnp.round(x * two_over_pi)
    r1 = x - n * p1  # exact (n·p1 exact and cancels x's leading bits, Sterbenz)
    r2, e2 = _two_sum(r1, -(n * p2))
    r3, e3 = _two_sum(r2, -(n * p3))
    lo = (e2 + e3) - n * p4
    hi = r3 + lo
    return n, hi, lo - (hi - r3)  # Fast2Sum: |r3| ≥ |lo|


def _kernel_sin(x, y):
    """sin(x + y) for |x| ≤ π/4, |y| ≤ ulp(x)/2 (fdlibm __kernel_sin with iy = 1)."""
    z = x * x
    v = z * x
    r = _S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))
    return x - ((z * (0.5 * y - v * r) - y) - v * _S1)


def _kernel_cos(x, y):
    """cos(x + y) for |x| ≤ π/4, |y| ≤ ulp(x)/2 (fdlibm __kernel_cos, FreeBSD's 2008 form)."""
    z = x * x
    w = z * z
    r = z * (_C1 + z * (_C2 + z * _C3)) + w * w * (_C4 + z * (_C5 + z * _C6))
    hz = 0.5 * z
    w = 1.0 - hz
    return w + (((1.0 - w) - hz) + (z * r - x * y))


def _kernel_sin32(x, y):
    """sin(x + y) in float32 for |x| ≤ π/4, |y| ≤ ulp(x)/2: fdlibm's form with Cephes's degree-7 polynomial."""
    z = x * x
    v = z * x
    return x - ((z * (0.5 * y - v * (_T2 + z * _T3)) - y) - v * _T1)


def _kernel_cos32(x, y):
    """cos(x + y) in float32 for |x| ≤ π/4, |y| ≤ ulp(x)/2: fdlibm's form with Cephes's degree-8 polynomial."""
    z = x * x
    r = z * (_D1 + z * (_D2 + z * _D3))
    hz = 0.5 * z
    w = 1.0 - hz
    return w + (((1.0 - w) - hz) + (z * r - x * y))


@jax.custom_jvp
def _sincos(x):
    return _sincos_jit(x)


# A jit of its own: traced once per shape, not once per call (a drive step makes 12 calls of ~100 operations
# each; inlined, they tripled the time to trace and lower a drive gradient).  XLA inlines it again.
@jax.jit
def _sincos_jit(x):
    if x.dtype == jnp.float64:
        n, hi, lo = _reduce(x, _P1, _P2, _P3, _P4, _TWO_OVER_PI)
        ks, kc = _kernel_sin(hi, lo), _kernel_cos(hi, lo)
        limit = _LIMIT
    else:  # float32 (sincos sends no other dtype)
        n, hi, lo = _reduce(x, _Q1, _Q2, _Q3, _Q4, _TWO_OVER_PI32)
        ks, kc = _kernel_sin32(hi, lo), _kernel_cos32(hi, lo)
        limit = _LIMIT32
    # quadrant q = n mod 4: sin x = sin r, cos r, −sin r, −cos r; cos x = cos r, −sin r, −cos r, sin r
    q = (n - 4.0 * jnp.floor(n * 0.25)).astype(jnp.int32)
    odd = (q & 1) == 1
    s = jnp.where(odd, kc, ks)
    c = jnp.where(odd, ks, kc)
    s = jnp.where((q & 2) == 2, -s, s)
    c = jnp.where(((q + 1) & 2) == 2, -c, c)
    s = jnp.where(x == 0.0, x, s)  # sin(−0) = −0 (the reduction's additions return +0)
    ok = jnp.abs(x) <= limit
    # Divided by one (1 + 0·x, which XLA does not fold): XLA's fusion counts a division as expensive and
    # does not copy an expensive value into each of its consumers, so sin and cos are computed once per
    # angle in a vectorized loop of their own.  Without it XLA copied the whole polynomial into every
    # fusion that reads it, among them the plant's state-derivative stacks, which its CPU backend emits as
    # scalar loops, one per stacked component: the float64 drive ran slower than with XLA's own sine
    # (docs/performance.md).
    one = 1.0 + 0.0 * x
    return jnp.where(ok, s, jnp.nan) / one, jnp.where(ok, c, jnp.nan) / one


@_sincos.defjvp
def _sincos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    s, c = _sincos(x)
    return (s, c), (c * dx, -s * dx)
