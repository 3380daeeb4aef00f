"""Transfer functions as coefficient arrays (real or complex), and what is computed from them.

Everything here is a JAX function of the coefficients, so frequency
responses, margins, crossovers and poles are differentiable with respect to
gains.  Crossover frequencies are found by ``optimistix.root_find`` (Newton),
so their gradients come by implicit differentiation, not through the
iterations.

Coefficients are stored highest power first (``jnp.polyval`` order).
python-control cannot represent complex-coefficient filters such as the
FA-LESO (002 eqs 21, 26); these classes can.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
import optimistix as optx

from ..core.validate import as_float

__all__ = [
    "TransferFunction",
    "DiscreteTransferFunction",
    "Margins",
    "margins",
    "routh_complex",
    "is_hurwitz",
    "tustin",
    "bode",
]


def _trim(c):
    return jnp.atleast_1d(jnp.asarray(c))


class TransferFunction(eqx.Module):
    """G(s) = num(s) / den(s), coefficients highest power first, real or complex.

    Args:
        num: The numerator's coefficients, highest power first (leading zeros are trimmed).
        den: The denominator's coefficients, highest power first.
    """

    num: jax.Array
    den: jax.Array

    def __init__(self, num, den):
        num, den = _trim(num), _trim(den)
        dtype = jnp.result_type(num, den, float)
        self.num = num.astype(dtype)
        self.den = den.astype(dtype)

    # --- evaluation --------------------------------------------------------
    def __call__(self, s):
        return jnp.polyval(self.num, s) / jnp.polyval(self.den, s)

    def freqresp(self, omega):
        """G(jω).

        Args:
            omega: The angular frequencies, rad/s.

        Returns:
            G(jω), complex.
        """
        return self(1j * as_float(omega))

    @property
    def is_complex(self) -> bool:
        return jnp.iscomplexobj(self.num)

    # --- algebra -----------------------------------------------------------
    def __mul__(self, other):
        other = _as_tf(other)
        return TransferFunction(jnp.convolve(self.num, other.num), jnp.convolve(self.den, other.den))

    __rmul__ = __mul__

    def __add__(self, other):
        other = _as_tf(other)
        return TransferFunction(
            _polyadd(jnp.convolve(self.num, other.den), jnp.convolve(other.num, self.den)),
            jnp.convolve(self.den, other.den),
        )

    __radd__ = __add__

    def __neg__(self):
        return TransferFunction(-self.num, self.den)

    def __sub__(self, other):
        return self + (-_as_tf(other))

    def feedback(self, other=1.0, sign: int = -1):
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
    def poles(self):
        """Roots of the denominator (eigenvalues of its companion matrix)."""
        return _roots(self.den)

    def zeros(self):
        return _roots(self.num)

    def is_stable(self):
        """All poles strictly in the left half-plane (generalized Routh test, exact in the coefficients)."""
        return is_hurwitz(self.den)

    def dcgain(self):
        return self(jnp.asarray(0.0, self.den.dtype))

    # --- python-control ------------------------------------------------------
    def to_control(self):
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
    def from_control(cls, sys) -> TransferFunction:
        """A continuous-time SISO python-control system as a :class:`TransferFunction`.

        Args:
            sys: A ``control.TransferFunction`` (or anything ``control.tf`` accepts).

        Returns:
            The :class:`TransferFunction`.

        Raises:
            ValueError: A discrete system (``dt`` set: use ``DiscreteTransferFunction``) or one that is not SISO.
        """
        import control

        sys = control.tf(sys)
        if sys.ninputs != 1 or sys.noutputs != 1:
            raise ValueError(f"from_control: a SISO system is needed, got {sys.noutputs}x{sys.ninputs}")
        if sys.dt not in (0, None):
            raise ValueError(f"from_control: a continuous-time system is needed (dt = 0), got dt = {sys.dt!r}")
        return cls(jnp.asarray(sys.num[0][0], float), jnp.asarray(sys.den[0][0], float))

    # --- time responses ----------------------------------------------------
    def state_space(self):
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

    def _zoh(self, dt: float):
        a, b, c, d = self.state_space()
        n = a.shape[0]
        m = jnp.zeros((n + 1, n + 1), a.dtype).at[:n, :n].set(a).at[:n, n:].set(b)
        em = jsl.expm(m * dt)
        return em[:n, :n], em[:n, n:], c, d

    def lsim_zoh(self, u, dt: float, x0=None):
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

        def body(x, uk):
            return ad @ x + bd * uk, (c @ x)[0, 0] + d * uk

        _, y = jax.lax.scan(body, x, u)
        return y

    def step(self, t):
        """Unit-step response (step applied at t[0]).

        Args:
            t: Uniformly spaced times, s.

        Returns:
            The response at ``t``.
        """
        return self.lsim_zoh(jnp.ones_like(t), float(t[1] - t[0]))

    def impulse(self, t):
        """Unit-impulse response C e^{A(t − t0)} B of a strictly proper G.

        Args:
            t: Uniformly spaced times, s.

        Returns:
            The response at ``t``.
        """
        ad, _, c, _ = self._zoh(float(t[1] - t[0]))
        _, b, _, _ = self.state_space()

        def body(x, _):
            return ad @ x, (c @ x)[0, 0]

        _, y = jax.lax.scan(body, b, None, length=t.shape[0])
        return y

    def sine_response(self, omega, t):
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

        def body(x, _):
            return ead @ x, c[0] @ x[:n] + d * x[n]

        _, y = jax.lax.scan(body, x0, None, length=t.shape[0])
        return y

    def phasor_response(self, omega, t):
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

        def body(x, _):
            return ead @ x, c[0] @ x[:n] + d * x[n]

        _, y = jax.lax.scan(body, x0, None, length=t.shape[0])
        return y

    def phasor_transient(self, omega, t):
        """|y(t) − G(jω) e^{jω(t − t[0])}| for the switched-on phasor input: the decaying transient's envelope.

        Args:
            omega: ω, rad/s.
            t: Uniformly spaced times, s.

        Returns:
            The envelope at ``t``.
        """
        y = self.phasor_response(omega, t)
        return jnp.abs(y - self.freqresp(omega) * jnp.exp(1j * as_float(omega) * (t - t[0])))

    def settling_time(self, t, band=0.02):
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


def _as_tf(x) -> TransferFunction:
    if isinstance(x, TransferFunction):
        return x
    return TransferFunction(jnp.atleast_1d(jnp.asarray(x)), jnp.ones((1,)))


def _polyadd(a, b):
    n = max(a.shape[0], b.shape[0])
    dtype = jnp.result_type(a, b)
    a = jnp.concatenate([jnp.zeros(n - a.shape[0], dtype), a.astype(dtype)])
    b = jnp.concatenate([jnp.zeros(n - b.shape[0], dtype), b.astype(dtype)])
    return a + b


def _roots(c):
    # concrete coefficients (a closed form's margins, a report) take NumPy's companion eigenvalues on the host:
    # eagerly, each jnp step compiled an XLA program of its own on a first run; under jit or a gradient the
    # coefficients are traced and the same steps run in jnp
    xp = jnp if isinstance(c, jax.core.Tracer) else np
    c = xp.asarray(c)
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


def routh_complex(coeffs):
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


def is_hurwitz(coeffs):
    """Whether every root of the (real or complex) polynomial lies in Re s < 0.

    Args:
        coeffs: The coefficients, highest power first.

    Returns:
        A bool array.
    """
    return jnp.all(routh_complex(coeffs) > 0)


# --------------------------------------------------------------------------
# frequency response, margins
# --------------------------------------------------------------------------


def bode(tf: TransferFunction, omega, *, convention: str = "db-deg"):
    """G(jω) on the grid ``omega`` (rad/s): magnitude (dB) and unwrapped phase (deg) by default.

    Args:
        tf: The :class:`TransferFunction`.
        omega: The grid, rad/s.
        convention: ``"db-deg"``, or ``"control"``: python-control's form (absolute magnitude, unwrapped
            phase in rad, and ω), as ``control.frequency_response``/``bode_plot`` give them.

    Returns:
        ``(magnitude in dB, phase in deg)``, or ``(magnitude, phase in rad, omega)`` with ``"control"``.

    Raises:
        ValueError: An unknown ``convention``.
    """
    if convention not in ("db-deg", "control"):
        raise ValueError(f"bode: convention must be 'db-deg' or 'control', got {convention!r}")
    omega = as_float(omega)
    g = tf.freqresp(omega)
    phase = jnp.unwrap(jnp.angle(g))
    if convention == "control":
        return jnp.abs(g), phase, omega
    return 20 * jnp.log10(jnp.abs(g)), jnp.degrees(phase)


class Margins(eqx.Module):
    """The margins of a loop (:func:`margins`).

    Attributes:
        gain_margin: |1/L(jω₁₈₀)| (inf if the phase never crosses −180°).
        phase_margin: deg, mod(∠L(jω_c), 360) − 180 (inf if |L| never crosses 1).
        omega_gc: The gain crossover, rad/s (nan if none).
        omega_pc: The phase crossover, rad/s (nan if none).
    """

    gain_margin: jax.Array  # |1/L(jω₁₈₀)| (inf if the phase never crosses −180°)
    phase_margin: jax.Array  # deg, mod(∠L(jω_c), 360) − 180 (inf if |L| never crosses 1)
    omega_gc: jax.Array  # gain crossover, rad/s (nan if none)
    omega_pc: jax.Array  # phase crossover, rad/s (nan if none)

    def __repr__(self) -> str:
        """The margins as numbers (``Margins(gain_margin=2.5, phase_margin=45.1 deg, ...)``); batched or traced
        margins print as equinox prints a module (their shapes)."""
        try:
            v = [float(x) for x in (self.gain_margin, self.phase_margin, self.omega_gc, self.omega_pc)]
        except (TypeError, jax.errors.ConcretizationTypeError):  # a batch (not a scalar), or a tracer
            return eqx.tree_pformat(self)
        return (
            f"Margins(gain_margin={v[0]:.6g}, phase_margin={v[1]:.6g} deg, "
            f"omega_gc={v[2]:.6g} rad/s, omega_pc={v[3]:.6g} rad/s)"
        )


def _default_grid(tf: TransferFunction, n: int):
    """Log-spaced grid wide enough to hold every crossover.

    Spans two decades beyond the finite, non-zero poles and zeros, and beyond
    where the high- and low-frequency asymptotes (K/s^r above the last corner,
    K'/s^m below the first with m integrators) reach unit gain.
    """
    pol, zer = jnp.abs(tf.poles()), jnp.abs(tf.zeros())
    mags = jnp.concatenate([pol, zer])
    scale = jnp.maximum(jnp.max(mags), 1.0)
    nonzero = mags > 1e-9 * scale
    lo = jnp.min(jnp.where(nonzero, mags, jnp.inf))
    hi = jnp.max(jnp.where(nonzero, mags, 0.0))
    r = tf.den.shape[0] - tf.num.shape[0]  # relative degree (leading coefficients assumed non-zero)
    if r > 0:
        c_hi = jnp.abs(tf.num[0] / tf.den[0]) ** (1.0 / r)
        hi = jnp.maximum(hi, c_hi)
        lo = jnp.minimum(lo, c_hi)
    m = jnp.sum(pol <= 1e-9 * scale)  # integrators
    den_last = tf.den[::-1][jnp.minimum(m, tf.den.shape[0] - 1)]
    c_lo = jnp.abs(tf.num[-1] / den_last) ** (1.0 / jnp.maximum(m, 1))
    c_lo = jnp.where((m > 0) & jnp.isfinite(c_lo) & (c_lo > 0), c_lo, lo)
    lo = jnp.minimum(lo, c_lo)
    hi = jnp.maximum(hi, c_lo)
    lo = jnp.where(jnp.isfinite(lo) & (lo > 0), lo, 1e-3) / 100.0
    hi = jnp.where(jnp.isfinite(hi) & (hi > 0), hi, 1e3) * 100.0
    return jnp.exp(jnp.linspace(jnp.log(lo), jnp.log(hi), n))


def _refine(fn, x0, args):
    """Newton on x = log ω from each candidate, with gradients by implicit differentiation."""
    solver = optx.Newton(rtol=1e-12, atol=1e-12)

    def one(x):
        return optx.root_find(fn, solver, x, args, max_steps=64, throw=False).value

    return jax.vmap(one)(x0)


def margins(loop: TransferFunction, *, grid_size: int = 4000, max_crossings: int = 8, omega=None) -> Margins:
    """Gain and phase margins of the unity-feedback loop ``loop`` (real coefficients).

    Conventions follow python-control's ``stability_margins``: every gain
    crossover gives PM = mod(∠L, 360°) − 180° and the one of least |PM| is
    reported; every phase crossover (L(jω) real and negative) gives
    GM = 1/|L| and the one of least |log GM| is reported.  Candidates come from
    sign changes on a log grid, each refined by an optimistix Newton root find in log ω.

    Args:
        loop: The loop L(s) (real coefficients).
        grid_size: The log grid's points.
        max_crossings: The most crossings of each kind refined.
        omega: The grid, rad/s (overrides the log grid).

    Returns:
        The :class:`Margins`.
    """
    w = _default_grid(jax.lax.stop_gradient(loop), grid_size) if omega is None else as_float(omega)
    # The grid only seeds the Newton root finds; the crossovers' derivatives come from
    # implicit differentiation of the root conditions, so the grid (built from the
    # eigenvalues of the companion matrices, whose higher derivatives JAX refuses) is
    # deliberately held constant.  Gradients w.r.t. the coefficients are unaffected.
    w = jax.lax.stop_gradient(w)
    x = jnp.log(w)
    num, den = loop.num, loop.den

    def L(xx, nd):
        n_, d_ = nd
        s = 1j * jnp.exp(xx)
        return jnp.polyval(n_, s) / jnp.polyval(d_, s)

    def log_mag(xx, nd):
        return jnp.log(jnp.abs(L(xx, nd)))

    def sin_phase_neg(xx, nd):
        # zero where L is real; Im(L)/|L| = sin ∠L
        g = L(xx, nd)
        return jnp.imag(g) / jnp.abs(g)

    nd = (num, den)
    g_grid = loop.freqresp(w)

    # --- gain crossovers
    lm = jnp.log(jnp.abs(g_grid))
    gc_idx = jnp.nonzero(jnp.sign(lm[:-1]) != jnp.sign(lm[1:]), size=max_crossings, fill_value=-1)[0]
    gc_valid = gc_idx >= 0
    first = jnp.where(jnp.any(gc_valid), gc_idx[0], 0)
    x0 = jnp.where(gc_valid, x[jnp.maximum(gc_idx, 0)], x[first])
    xgc = _refine(log_mag, x0, nd)
    pm_all = jnp.remainder(jnp.degrees(jnp.angle(L(xgc, nd))), 360.0) - 180.0
    pm_key = jnp.where(gc_valid, jnp.abs(pm_all), jnp.inf)
    i_pm = jnp.argmin(pm_key)
    has_gc = jnp.any(gc_valid)
    pm = jnp.where(has_gc, pm_all[i_pm], jnp.inf)
    w_gc = jnp.where(has_gc, jnp.exp(xgc[i_pm]), jnp.nan)

    # --- phase crossovers (Im L changes sign where Re L < 0)
    sp = jnp.imag(g_grid)
    neg = jnp.real(g_grid) < 0
    pc_mask = (jnp.sign(sp[:-1]) != jnp.sign(sp[1:])) & (neg[:-1] | neg[1:])
    pc_idx = jnp.nonzero(pc_mask, size=max_crossings, fill_value=-1)[0]
    pc_valid = pc_idx >= 0
    firstp = jnp.where(jnp.any(pc_valid), pc_idx[0], 0)
    x0p = jnp.where(pc_valid, x[jnp.maximum(pc_idx, 0)], x[firstp])
    xpc = _refine(sin_phase_neg, x0p, nd)
    gpc = L(xpc, nd)
    pc_valid = pc_valid & (jnp.real(gpc) < 0)
    gm_all = 1.0 / jnp.abs(gpc)
    gm_key = jnp.where(pc_valid, jnp.abs(jnp.log(gm_all)), jnp.inf)
    i_gm = jnp.argmin(gm_key)
    has_pc = jnp.any(pc_valid)
    gm = jnp.where(has_pc, gm_all[i_gm], jnp.inf)
    w_pc = jnp.where(has_pc, jnp.exp(xpc[i_gm]), jnp.nan)
    return Margins(gain_margin=gm, phase_margin=pm, omega_gc=w_gc, omega_pc=w_pc)


# --------------------------------------------------------------------------
# discretization of transfer functions
# --------------------------------------------------------------------------


def _real_coefficients(tf, where):
    if jnp.iscomplexobj(tf.num) or jnp.iscomplexobj(tf.den):
        raise ValueError(
            f"{where}: python-control holds real coefficients only; this transfer function has complex ones "
            "(a complex-coefficient filter such as the FA-LESO's): use jaxobs.linear's own bode/margins/poles"
        )
    import numpy as np

    return np.asarray(tf.num, float), np.asarray(tf.den, float)


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

    def to_control(self):
        """This H(z) as a discrete ``control.TransferFunction`` (``dt = ts``), in python-control's descending
        powers of z (both polynomials multiplied by zⁿ); complex coefficients are refused."""
        import control
        import numpy as np

        b, a = _real_coefficients(self, "DiscreteTransferFunction.to_control")
        n = max(b.shape[0], a.shape[0])
        return control.tf(np.pad(b, (0, n - b.shape[0])), np.pad(a, (0, n - a.shape[0])), self.ts)

    def __call__(self, z):
        zi = 1.0 / z
        return jnp.polyval(self.num[::-1], zi) / jnp.polyval(self.den[::-1], zi)

    def freqresp(self, omega):
        return self(jnp.exp(1j * as_float(omega) * self.ts))

    def filter(self, u):
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

        def body(state, uk):
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

    def substitute(coeffs):
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
