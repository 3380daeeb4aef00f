"""Transfer functions as coefficient arrays (real or complex): their algebra, poles and time responses, and the
generalized Routh test.  Frequency responses and margins are :mod:`jaxobs.linear._margins`'s, discrete-time
transfer functions and Tustin's discretization :mod:`jaxobs.linear._discrete`'s.

Everything here is a JAX function of the coefficients, so responses and poles are differentiable with respect to
gains.

Coefficients are stored highest power first (``jnp.polyval`` order).
python-control cannot represent complex-coefficient filters such as the
FA-LESO (002 eqs 21, 26); these classes can.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
from jax.core import Tracer
from jax.typing import ArrayLike

from ..core.validate import as_float

__all__ = ["TransferFunction", "routh_complex", "is_hurwitz"]

# a polynomial's coefficients, highest power first: an array, or a sequence of numbers or JAX scalars
Coefficients = ArrayLike | Sequence[ArrayLike]
# samples or uniformly spaced times: a JAX or a NumPy array
Samples = jax.Array | np.ndarray


def _trim(c: Coefficients) -> jax.Array:
    return jnp.atleast_1d(jnp.asarray(c))


class TransferFunction(eqx.Module):
    """G(s) = num(s) / den(s), coefficients highest power first, real or complex.

    Args:
        num: The numerator's coefficients, highest power first (leading zeros are trimmed).
        den: The denominator's coefficients, highest power first.
    """

    num: jax.Array
    den: jax.Array

    def __init__(self, num: Coefficients, den: Coefficients) -> None:
        num, den = _trim(num), _trim(den)
        dtype = jnp.result_type(num, den, float)
        self.num = num.astype(dtype)
        self.den = den.astype(dtype)

    # --- evaluation --------------------------------------------------------
    def __call__(self, s: ArrayLike) -> jax.Array:
        return jnp.polyval(self.num, s) / jnp.polyval(self.den, s)

    def freqresp(self, omega: ArrayLike) -> jax.Array:
        """G(jω).

        Args:
            omega: The angular frequencies, rad/s.

        Returns:
            G(jω), complex.
        """
        return self(1j * as_float(omega))

    @property
    def is_complex(self) -> bool:
        """Whether the coefficients are complex."""
        return jnp.iscomplexobj(self.num)

    # --- algebra -----------------------------------------------------------
    def __mul__(self, other: TransferFunction | ArrayLike) -> TransferFunction:
        other = _as_tf(other)
        return TransferFunction(jnp.convolve(self.num, other.num), jnp.convolve(self.den, other.den))

    __rmul__ = __mul__

    def __add__(self, other: TransferFunction | ArrayLike) -> TransferFunction:
        other = _as_tf(other)
        return TransferFunction(
            _polyadd(jnp.convolve(self.num, other.den), jnp.convolve(other.num, self.den)),
            jnp.convolve(self.den, other.den),
        )

    __radd__ = __add__

    def __neg__(self) -> TransferFunction:
        return TransferFunction(-self.num, self.den)

    def __sub__(self, other: TransferFunction | ArrayLike) -> TransferFunction:
        return self + (-_as_tf(other))

    def feedback(self, other: TransferFunction | ArrayLike = 1.0, sign: int = -1) -> TransferFunction:
        """Closed loop G / (1 − sign·G·H) (negative feedback by default).

        Args:
            other: H, a :class:`TransferFunction` or a constant.
            sign: −1 (negative feedback) or +1.

        Returns:
            The closed loop's :class:`TransferFunction`.
        """
        h = _as_tf(other)
        num = jnp.convolve(self.num, h.den)
        den = _polyadd(jnp.convolve(self.den, h.den), -sign * jnp.convolve(self.num, h.num))
        return TransferFunction(num, den)

    # --- poles, zeros, stability ---------------------------------------------
    def poles(self) -> jax.Array:
        """Roots of the denominator (eigenvalues of its companion matrix)."""
        return _roots(self.den)

    def zeros(self) -> jax.Array:
        """Roots of the numerator."""
        return _roots(self.num)

    def is_stable(self) -> jax.Array:
        """All poles strictly in the left half-plane (generalized Routh test, exact in the coefficients)."""
        return is_hurwitz(self.den)

    def dcgain(self) -> jax.Array:
        """G(0)."""
        return self(jnp.asarray(0.0, self.den.dtype))

    # --- python-control ------------------------------------------------------
    def to_control(self) -> Any:
        """This G(s) as a ``control.TransferFunction`` (python-control, the test extra: ``pip install control``).

        python-control holds real coefficients only: a complex-coefficient filter (the FA-LESO's, 002 eq 26;
        the GI-LESO's) is refused.

        Returns:
            The ``control.TransferFunction``.

        Raises:
            ValueError: Complex coefficients.
        """
        import control  # optional: python-control is this bridge's, not the library's, dependency

        num, den = _real_coefficients(self, "TransferFunction.to_control")
        return control.tf(num, den)

    @classmethod
    def from_control(cls, sys: Any) -> TransferFunction:
        """A continuous-time SISO python-control system as a :class:`TransferFunction`.

        Args:
            sys: A ``control.TransferFunction`` (or anything ``control.tf`` accepts).

        Returns:
            The :class:`TransferFunction`.

        Raises:
            ValueError: A discrete system (``dt`` set: use ``DiscreteTransferFunction``) or one that is not SISO.
        """
        import control

        # control.tf always returns a TransferFunction; its inferred type also holds None (the class attribute
        # TransferFunction.s starts as None)
        sys = cast(control.TransferFunction, control.tf(sys))
        if sys.ninputs != 1 or sys.noutputs != 1:
            raise ValueError(f"from_control: a SISO system is needed, got {sys.noutputs}x{sys.ninputs}")
        if sys.dt not in (0, None):
            raise ValueError(f"from_control: a continuous-time system is needed (dt = 0), got dt = {sys.dt!r}")
        return cls(jnp.asarray(sys.num[0][0], float), jnp.asarray(sys.den[0][0], float))

    # --- time responses ----------------------------------------------------
    def state_space(self) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
        """Controllable canonical form (A, B, C, D) of a proper G."""
        den = self.den / self.den[0]
        num = self.num / self.den[0]
        n = den.shape[0] - 1
        if num.shape[0] > n + 1:
            raise ValueError(
                f"TransferFunction must be proper: numerator degree {num.shape[0] - 1} > denominator degree {n}"
            )
        num = jnp.concatenate([jnp.zeros(n + 1 - num.shape[0], num.dtype), num])
        d = num[0]
        b = num[1:] - d * den[1:]
        a = jnp.zeros((n, n), den.dtype).at[0, :].set(-den[1:])
        if n > 1:
            a = a.at[1:, :-1].set(jnp.eye(n - 1, dtype=den.dtype))
        bvec = jnp.zeros((n, 1), den.dtype).at[0, 0].set(1.0)
        return a, bvec, b[None, :], d

    def _zoh(self, dt: float) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
        a, b, c, d = self.state_space()
        n = a.shape[0]
        m = jnp.zeros((n + 1, n + 1), a.dtype).at[:n, :n].set(a).at[:n, n:].set(b)
        em = jsl.expm(m * dt)
        return em[:n, :n], em[:n, n:], c, d

    def lsim_zoh(self, u: jax.Array, dt: float, x0: jax.Array | None = None) -> jax.Array:
        """Response to samples held over each period (exact ZOH discretization, ``lax.scan``).

        Args:
            u: The input samples.
            dt: The period, s.
            x0: The initial state (default zero).

        Returns:
            The output samples.
        """
        ad, bd, c, d = self._zoh(dt)
        x = jnp.zeros((ad.shape[0], 1), ad.dtype) if x0 is None else x0

        def body(x: jax.Array, uk: jax.Array) -> tuple[jax.Array, jax.Array]:
            return ad @ x + bd * uk, (c @ x)[0, 0] + d * uk

        _, y = jax.lax.scan(body, x, u)
        return y

    def step(self, t: Samples) -> jax.Array:
        """Unit-step response (step applied at t[0]).

        Args:
            t: Uniformly spaced times, s.

        Returns:
            The response at ``t``.
        """
        return self.lsim_zoh(jnp.ones_like(t), float(t[1] - t[0]))

    def impulse(self, t: Samples) -> jax.Array:
        """Unit-impulse response C e^{A(t − t0)} B of a strictly proper G.

        Args:
            t: Uniformly spaced times, s.

        Returns:
            The response at ``t``.
        """
        ad, _, c, _ = self._zoh(float(t[1] - t[0]))
        _, b, _, _ = self.state_space()

        def body(x: jax.Array, _: Any) -> tuple[jax.Array, jax.Array]:
            return ad @ x, (c @ x)[0, 0]

        _, y = jax.lax.scan(body, b, None, length=t.shape[0])
        return y

    def sine_response(self, omega: ArrayLike, t: Samples) -> jax.Array:
        """Response to sin(ω (t − t[0])) from rest, exact at the sample times.

        The sine is generated by an oscillator appended to the state, and the
        augmented autonomous system is stepped with its exact matrix exponential.

        Args:
            omega: ω, rad/s.
            t: Uniformly spaced times, s.

        Returns:
            The response at ``t``.
        """
        a, b, c, d = self.state_space()
        n = a.shape[0]
        dt = float(t[1] - t[0])
        w = as_float(omega).astype(a.dtype)
        aug = jnp.zeros((n + 2, n + 2), a.dtype)
        aug = aug.at[:n, :n].set(a).at[:n, n].set(b[:, 0])
        aug = aug.at[n, n + 1].set(w).at[n + 1, n].set(-w)  # z1 = sin, z2 = cos
        ead = jsl.expm(aug * dt)
        x0 = jnp.zeros((n + 2,), a.dtype).at[n + 1].set(1.0)

        def body(x: jax.Array, _: Any) -> tuple[jax.Array, jax.Array]:
            return ead @ x, c[0] @ x[:n] + d * x[n]

        _, y = jax.lax.scan(body, x0, None, length=t.shape[0])
        return y

    def phasor_response(self, omega: ArrayLike, t: Samples) -> jax.Array:
        """Complex response to e^{jω(t − t[0])} switched on at t[0] from rest, exact at the samples.

        For a real G this is the response to cos + j·sin; its distance from the
        steady state G(jω) e^{jωt}, :meth:`phasor_transient`, is a smooth
        envelope (no ripple at ω), which makes settling times continuous in
        the coefficients.

        Args:
            omega: ω, rad/s.
            t: Uniformly spaced times, s.

        Returns:
            The complex response at ``t``.
        """
        a, b, c, d = self.state_space()
        n = a.shape[0]
        dt = float(t[1] - t[0])
        cdt = jnp.result_type(a, 1j)
        w = as_float(omega)
        aug = jnp.zeros((n + 1, n + 1), cdt).at[:n, :n].set(a).at[:n, n].set(b[:, 0]).at[n, n].set(1j * w)
        ead = jsl.expm(aug * dt)
        x0 = jnp.zeros((n + 1,), cdt).at[n].set(1.0)

        def body(x: jax.Array, _: Any) -> tuple[jax.Array, jax.Array]:
            return ead @ x, c[0] @ x[:n] + d * x[n]

        _, y = jax.lax.scan(body, x0, None, length=t.shape[0])
        return y

    def phasor_transient(self, omega: ArrayLike, t: Samples) -> jax.Array:
        """|y(t) − G(jω) e^{jω(t − t[0])}| for the switched-on phasor input: the decaying transient's envelope.

        Args:
            omega: ω, rad/s.
            t: Uniformly spaced times, s.

        Returns:
            The envelope at ``t``.
        """
        y = self.phasor_response(omega, t)
        return jnp.abs(y - self.freqresp(omega) * jnp.exp(1j * as_float(omega) * (t - t[0])))

    def settling_time(self, t: Samples, band: float = 0.02) -> jax.Array:
        """Step-response settling time (exact on the grid).

        Args:
            t: Uniformly spaced times, s.
            band: The band, a fraction of the final value.

        Returns:
            The settling time, s.
        """
        y = jnp.real(self.step(t))
        final = self.dcgain()
        # the first sample from which |y − final| stays within the band (0 if it never leaves it; the record's
        # length if it never settles): jaxobs.metrics.settling_time's arithmetic, here below the metrics
        outside = jnp.abs(y - jnp.real(final)) > band * jnp.abs(final)
        last_out = jnp.max(jnp.where(outside, jnp.arange(y.shape[-1]), -1), axis=-1)
        tt = t - t[0]
        settled_at = jnp.where(last_out < 0, 0.0, tt[jnp.minimum(last_out + 1, y.shape[-1] - 1)])
        return jnp.where(jnp.isfinite(jnp.real(final)) & jnp.isfinite(band * jnp.abs(final)), settled_at, jnp.nan)


def _as_tf(x: TransferFunction | ArrayLike) -> TransferFunction:
    if isinstance(x, TransferFunction):
        return x
    return TransferFunction(jnp.atleast_1d(jnp.asarray(x)), jnp.ones((1,)))


def _polyadd(a: jax.Array, b: jax.Array) -> jax.Array:
    n = max(a.shape[0], b.shape[0])
    dtype = jnp.result_type(a, b)
    a = jnp.concatenate([jnp.zeros(n - a.shape[0], dtype), a.astype(dtype)])
    b = jnp.concatenate([jnp.zeros(n - b.shape[0], dtype), b.astype(dtype)])
    return a + b


def _roots(coeffs: ArrayLike) -> jax.Array:
    # concrete coefficients (a closed form's margins, a report) take NumPy's companion eigenvalues on the host:
    # eagerly, each jnp step compiled an XLA program of its own on a first run; under jit or a gradient the
    # coefficients are traced and the same steps run in jnp
    xp: Any = jnp if isinstance(coeffs, Tracer) else np
    c = xp.asarray(coeffs)
    c = c / c[0]
    n = c.shape[0] - 1
    if n == 0:
        return jnp.zeros((0,), jnp.result_type(c, 1j))
    # the companion matrix: first row −c[1:], then the shifted identity [I_{n−1} | 0]
    comp = xp.concatenate([-c[None, 1:], xp.eye(n - 1, n, dtype=c.dtype)], axis=0)
    roots = xp.linalg.eigvals(comp)
    return roots if xp is jnp else jnp.asarray(roots.astype(np.result_type(c, 1j)))


# --------------------------------------------------------------------------
# the generalized Routh test for complex coefficients (002 Table I, eqs 22-24)
# --------------------------------------------------------------------------


def routh_complex(coeffs: Coefficients) -> jax.Array:
    """Generalized Routh test for p(s) = Σ c_k s^(n−k) with real or complex coefficients.

    Writes p(jω) = j^n (R(ω) + j I(ω)) with real polynomials R (degree n,
    leading coefficient Re c₀) and I, and runs the Euclidean (Sturm) sequence
    f₀ = R, f₁ = −I, f_{k+2} = −rem(f_k, f_{k+1}).  p is Hurwitz (all roots in
    Re s < 0) iff every division lowers the degree by one with a quotient of
    positive leading coefficient, i.e. iff the n + 1 leading coefficients
    ("first column") of f₀ … f_n all have the sign of Re c₀.  This is the
    Frank/Xie generalized Routh array that 002 cites [24] in Sturm form; for
    002's s² + (k₂ − jω̂)s + k₁ the first column is (1, k₂, k₁), whose
    positivity is 002 eq (24): k₁ > 0, k₂ > 0.  For real coefficients it is the
    ordinary Routh test.

    Args:
        coeffs: c₀ … c_n, highest power first, real or complex.

    Returns:
        The first column (a length n+1 real array); stability is ``all(first_column > 0)`` after
        normalizing c₀ to 1.
    """
    c = jnp.atleast_1d(jnp.asarray(coeffs))
    c = c.astype(jnp.result_type(c, 1j))
    c = c / c[0]
    n = c.shape[0] - 1
    # p(jω) = Σ c_k j^(n−k) ω^(n−k);  j^(−n) p(jω) = Σ c_k j^(−k) ω^(n−k)
    jpow = jnp.asarray([(1j) ** (-k) for k in range(n + 1)], dtype=c.dtype)
    q = c * jpow  # coefficients of R + jI in powers of ω, highest first
    f_prev = jnp.real(q)
    f_curr = -jnp.imag(q)[1:]  # degree ≤ n−1 (the ω^n term of I is Im c₀ = 0)
    column = [f_prev[0], f_curr[0]]
    for _ in range(n - 1):
        # divide f_prev (degree m) by f_curr (degree m−1): quotient a ω + b
        a = f_prev[0] / f_curr[0]
        b = (f_prev[1] - a * f_curr[1]) / f_curr[0]
        fc = jnp.concatenate([f_curr, jnp.zeros((1,), f_curr.dtype)])  # ω·f_curr
        fb = jnp.concatenate([jnp.zeros((1,), f_curr.dtype), f_curr])  # f_curr
        rem = f_prev - a * fc - b * fb  # first two entries vanish
        f_prev, f_curr = f_curr, -rem[2:]
        column.append(f_curr[0])
    return jnp.stack(column[: n + 1])


def is_hurwitz(coeffs: Coefficients) -> jax.Array:
    """Whether every root of the (real or complex) polynomial lies in Re s < 0.

    Args:
        coeffs: The coefficients, highest power first.

    Returns:
        A bool array.
    """
    return jnp.all(routh_complex(coeffs) > 0)


def _real_coefficients(tf: Any, where: str) -> tuple[np.ndarray, np.ndarray]:
    if jnp.iscomplexobj(tf.num) or jnp.iscomplexobj(tf.den):
        raise ValueError(
            f"{where}: python-control holds real coefficients only; this transfer function has complex ones "
            "(a complex-coefficient filter such as the FA-LESO's): use jaxobs.linear's own bode/margins/poles"
        )
    return np.asarray(tf.num, float), np.asarray(tf.den, float)
