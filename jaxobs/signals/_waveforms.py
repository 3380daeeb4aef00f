"""Test waveforms for signal-level observers, as scan-friendly functions of time.

A :class:`GridSignal` is a PyTree whose leaves (amplitude, frequency, event
time, step sizes, harmonic magnitudes, …) may carry a leading batch axis; it is
called as ``sig(t)`` inside a scan or ``vmap``.  Every disturbance switches on
at ``t_event`` (one rule for all of them, so that a test is "settle, then
disturb"):

    θ(t) = ω₀ t + φ₀ + [t ≥ tₑ] (2π Δf (t − tₑ) + Δφ)
    v(t) = V₀ (1 − [t ≥ tₑ] sag) cos θ
           + [t ≥ tₑ] ( Σₕ Vₕ cos(h θ) + dc + V_sub cos(2π f_sub t) )

``sag`` is the *depth* of the sag (the amplitude falls by ``sag·V₀``).  Paper 001
writes "a 0.75 p.u. voltage sag" (Test 3) and "a 0.5 p.u. voltage sag" (Test B)
without saying whether the figure is the depth or the retained voltage; we read
it as the depth (Test 3 leaves 0.25 p.u.), the harder of the two readings.

Tests 1–3 (model accuracy, 001 Sec. V) and A–E (performance, 001 Sec. VI) are
built by :func:`paper001_test`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any, ClassVar, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.core import Tracer

from .. import papers
from ..core.measurements import DriveInput
from ..core.sampletime import SampleTime, Time, TimeLike, cycles, exact_phase, frac_mul, time_value
from ..core.trig import sincos
from ..core.validate import as_float, check_nonnegative, check_positive, check_real, check_sample_time
from ._base import AbstractSignal


class GridSignal(AbstractSignal):
    """Single-phase test voltage with a settle-then-disturb event (see module doc).

    Every disturbance switches on at ``t_event``.  Each array argument may carry a leading batch axis.

    Args:
        amplitude: V₀ before the event (input units, > 0).
        freq: f₀, Hz (> 0).
        phase: φ₀, rad.
        t_event: tₑ, s (≥ 0).
        freq_step: Δf, Hz (f₀ + Δf > 0).
        phase_jump: Δφ, rad.
        sag: The sag depth, a fraction of V₀ in [0, 0.999].
        dc: The dc step, input units.
        harmonics: ``{order: Vₕ}`` with integer orders ≥ 2 and magnitudes ≥ 0 (input units).
        sub_amplitude: V_sub, input units (≥ 0).
        sub_freq: f_sub, Hz (≥ 0).

    Raises:
        ValueError: A value out of its range, naming the field.
    """

    amplitude: jax.Array  # V₀ before the event (input units, > 0)
    freq: jax.Array  # f₀, Hz (> 0)
    phase: jax.Array  # φ₀, rad
    t_event: jax.Array  # tₑ, s (>= 0)
    freq_step: jax.Array  # Δf, Hz
    phase_jump: jax.Array  # Δφ, rad
    sag: jax.Array  # sag depth, fraction of V₀ in [0, 1)
    dc: jax.Array  # dc step, input units
    harmonics: jax.Array  # Vₕ for each of `orders`, shape (..., len(orders))
    sub_amplitude: jax.Array  # V_sub, input units
    sub_freq: jax.Array  # f_sub, Hz (>= 0)
    orders: tuple[int, ...] = eqx.field(static=True)

    def __init__(
        self,
        amplitude=1.0,
        freq=50.0,
        phase=0.0,
        t_event=0.2,
        *,
        freq_step=0.0,
        phase_jump=0.0,
        sag=0.0,
        dc=0.0,
        harmonics=None,
        sub_amplitude=0.0,
        sub_freq=1.0,
    ):
        own = "GridSignal"
        self.amplitude = check_positive("amplitude", amplitude, own)
        self.freq = check_positive("freq", freq, own)
        self.phase = check_real("phase", phase, owner=own)
        self.t_event = check_nonnegative("t_event", t_event, own)
        self.freq_step = check_real("freq_step", freq_step, owner=own)
        self.phase_jump = check_real("phase_jump", phase_jump, owner=own)
        self.sag = check_real("sag", sag, lower=0.0, lower_open=False, upper=0.999, owner=own)
        self.dc = check_real("dc", dc, owner=own)
        harmonics = dict(harmonics or {})
        for h in harmonics:
            if not (isinstance(h, int) and h >= 2):
                raise ValueError(f"{own}.harmonics keys must be integer orders >= 2, got {h!r}")
        self.orders = tuple(sorted(harmonics))
        mags = [harmonics[h] for h in self.orders]
        self.harmonics = check_nonnegative(
            "harmonics", jnp.asarray(mags, dtype=jnp.result_type(float)) if mags else jnp.zeros((0,)), own
        )
        self.sub_amplitude = check_nonnegative("sub_amplitude", sub_amplitude, own)
        self.sub_freq = check_nonnegative("sub_freq", sub_freq, own)
        # a traced freq or freq_step (vmap over either) is checked by nobody here: the divergence flags see it
        if self.freq.ndim == 0 and not any(isinstance(x, Tracer) for x in (self.freq, self.freq_step)):
            f_after = float(self.freq) + float(jnp.max(jnp.atleast_1d(self.freq_step)))
            if f_after <= 0:
                raise ValueError(f"{own}.freq_step must keep the frequency > 0 Hz, got freq + freq_step = {f_after:g}")

    # OnSignal passes a SampleTime (the sample index) instead of the rounded float t_k
    accepts_sample_time: ClassVar[bool] = True
    has_truth: ClassVar[bool] = True

    def _on(self, t):
        t = time_value(t)
        return (t >= self.t_event).astype(as_float(t).dtype)

    def _cycles(self, t):
        """θ(t)/(2π) without φ₀ and Δφ, in cycles; in float32 (a SampleTime) exact and reduced modulo 1.

        The event term is split as Δf·t − Δf·tₑ so that each product is reduced exactly (jaxobs.core.sampletime).
        """
        c = cycles(self.freq, t) + self._on(t) * (cycles(self.freq_step, t) - frac_mul(self.freq_step, self.t_event))
        return c - jax.lax.stop_gradient(jnp.round(c))

    def theta(self, t: TimeLike) -> Time:
        """True fundamental phase θ(t): unwrapped in float64; in float32 from a :class:`SampleTime`,
        reduced modulo 2π (an unwrapped float32 phase of 3·10⁴ rad is only good to 2 mrad).

        Args:
            t: The time, s, or a :class:`SampleTime`.

        Returns:
            θ(t), rad.
        """
        if exact_phase(t, self.freq):
            return 2 * jnp.pi * self._cycles(t) + self.phase + self._on(t) * self.phase_jump
        t = time_value(t)
        on = self._on(t)
        dt = jnp.maximum(t - self.t_event, 0.0)
        return 2 * jnp.pi * self.freq * t + self.phase + on * (2 * jnp.pi * self.freq_step * dt + self.phase_jump)

    def omega(self, t: TimeLike) -> jax.Array:
        """True fundamental angular frequency.

        Args:
            t: The time, s, or a :class:`SampleTime`.

        Returns:
            ω(t), rad/s.
        """
        return 2 * jnp.pi * (self.freq + self._on(t) * self.freq_step)

    def fundamental_amplitude(self, t: TimeLike) -> jax.Array:
        """True fundamental amplitude: V₀ before the event, (1 − sag)·V₀ from it on.

        Args:
            t: The time, s, or a :class:`SampleTime`.

        Returns:
            The amplitude, input units.
        """
        return self.amplitude * (1.0 - self._on(t) * self.sag)

    @staticmethod
    def _cos_orders(th, orders):
        """{h: cos(h·θ)} for h = 1 and each of ``orders``.

        In float64 from one vectorizable cosine (:func:`jaxobs.core.trig.sincos`) and the Chebyshev recurrence
        cos(hθ) = 2 cos θ cos((h−1)θ) − cos((h−2)θ): XLA's CPU backend calls a scalar library routine for
        each float64 ``cos``, and a Test C signal needs seven a sample, which made them most of a robust FLL
        job's simulation (docs/performance.md).
        The recurrence's error grows with h: 1.1e-14 absolute at h = 13 over 10⁶ angles up to 10³ rad, where
        ``cos(h*th)`` was off by up to 3.6e-12, the product h·θ rounded (tests/test_signals.py).  float32
        takes ``sincos``'s cosine of each multiple (its float32 polynomial: 0.5 ns a value against 4.6 ns for
        XLA's float32 ``cos`` here).
        """
        if jnp.result_type(th) != jnp.float64:
            return {h: sincos(h * th)[1] for h in (1, *orders)}
        c1 = sincos(th)[1]
        cos_h = [jnp.ones_like(c1), c1]
        for _ in range(2, max(orders, default=1) + 1):
            cos_h.append(2 * c1 * cos_h[-1] - cos_h[-2])
        return {h: cos_h[h] for h in (1, *orders)}

    def __call__(self, t):
        on = self._on(t)
        th = self.theta(t)
        cos_h = self._cos_orders(th, self.orders)
        v = self.fundamental_amplitude(t) * cos_h[1]
        for i, h in enumerate(self.orders):
            v = v + on * self.harmonics[..., i] * cos_h[h]
        if exact_phase(t, self.sub_freq):
            sub = sincos(2 * jnp.pi * cycles(self.sub_freq, t))[1]
        else:
            sub = sincos(2 * jnp.pi * self.sub_freq * time_value(t))[1]
        v = v + on * (self.dc + self.sub_amplitude * sub)
        return v


PAPER001_TESTS = tuple(papers.TESTS_001)

_M = TypeVar("_M")


def paper001_test(
    name: str, *, freq: float = 50.0, amplitude: float = 1.0, t_event: float = 0.2, phase: float = 0.0
) -> GridSignal:
    """The test signals of paper 001 (p.u. amplitude, 50 Hz nominal), from :data:`jaxobs.papers.TESTS_001`.

    1: +2 Hz step;  2: +20° phase jump;  3: 0.75 p.u. sag (depth);
    A: 50 → 52 Hz;  B: 0.5 p.u. sag with +60° jump;  C: harmonics 3–13 (THD ≈ 7.7 %);
    D: +0.1 p.u. dc step;  E: 0.1 p.u. 1 Hz sub-harmonic.

    Args:
        name: The test, one of ``"1"``, ``"2"``, ``"3"``, ``"A"`` … ``"E"`` (case-insensitive).
        freq: The nominal frequency, Hz.
        amplitude: The amplitude before the event (input units).
        t_event: The time of the event, s.
        phase: The initial phase, rad.

    Returns:
        The :class:`GridSignal`.

    Raises:
        ValueError: An unknown test name.
    """
    key = str(name).upper()
    if key not in papers.TESTS_001:
        raise ValueError(f"test name must be one of {', '.join(PAPER001_TESTS)}, got {name!r}")
    test = papers.TESTS_001[key]
    # Every test carries the Test C harmonic orders (zero magnitude outside Test C)
    # so that all eight share one static structure and stack into one batch.
    harmonics = {h: 0.0 for h in papers.TEST_C_HARMONICS}
    if "harmonics_scale" in test:
        harmonics = {h: test["harmonics_scale"] * m * amplitude for h, m in papers.TEST_C_HARMONICS.items()}
    kw: dict[str, Any] = dict(amplitude=amplitude, freq=freq, phase=phase, t_event=t_event, harmonics=harmonics)
    for field in ("freq_step", "sag", "sub_freq"):
        if field in test:
            kw[field] = test[field]
    if "phase_jump_deg" in test:
        kw["phase_jump"] = math.radians(test["phase_jump_deg"])
    for field in ("dc", "sub_amplitude"):  # p.u. of the amplitude
        if field in test:
            kw[field] = test[field] * amplitude
    return GridSignal(**kw)


def stack(modules: Iterable[_M]) -> _M:
    """Stack equally-shaped modules (signals, observers, scenarios) along a new leading batch axis.

    Args:
        modules: The modules, of one structure and one shape per leaf.

    Returns:
        One module whose every leaf has the new leading axis.

    Raises:
        ValueError: No modules, or a module holds a time-major batch (a batch already).
    """
    modules = list(modules)
    if not modules:
        raise ValueError("stack needs at least one module")

    def declares(x):  # a node that says its scenario axis is not the leading one (jaxobs.batch_axes)
        return isinstance(x, AbstractSignal) and x.batch_axis != 0

    if any(declares(x) for m in modules for x in jax.tree.leaves(m, is_leaf=declares)):
        raise ValueError(
            "stack: a time-major batch (batch_inner=True) is a batch already; put its recordings side by side "
            "along the inner axis instead (one (n, B) array per field) and build one batch"
        )
    return jax.tree.map(lambda *xs: jnp.stack(xs), *modules)


class EMFSignal(AbstractSignal):
    """A two-axis back EMF for testing flux observers without a drive (000 eq 8).

    e_ab(t) = A0 + A1 e^{j(ω1 t + φ1)}·(−j) … written per axis as
    e_α = A0α + A1 cos(ω1 t + φ1) + Σ_h A_h cos(s_h h ω1 t),
    e_β = A0β + A1 sin(ω1 t + φ1) + Σ_h s_h A_h sin(s_h h ω1 t),
    with s_h = ±1 the sequence of harmonic h.  ``__call__(t)`` returns a
    :class:`~jaxobs.core.measurements.DriveInput` with u = e and i = 0, the voltage being the
    *average* of e over the coming period [t, t + ts] — the same convention as
    the drive, which tells the observer at t_k the voltage it applies over
    [t_k, t_{k+1}].  The true rotor flux (∫e with no dc) is A1/ω1 (sin, −cos)
    of the fundamental.

    Args:
        A1: The fundamental's amplitude (V, > 0).
        omega1: The fundamental's angular frequency ω1, rad/s (> 0).
        phase: φ1, rad.
        dc: The offsets (A0α, A0β), V.
        harmonics: ``{order: A_h}`` with signed nonzero integer orders (+7 positive, −5 negative sequence).
        ts: The observer's sample time, s (:class:`~jaxobs.OnSignal` checks they agree).

    Raises:
        ValueError: A value out of its range, naming the field.
    """

    A1: jax.Array
    omega1: jax.Array
    phase: jax.Array
    dc: jax.Array  # (A0α, A0β)
    harmonics: jax.Array  # amplitudes A_h for `orders`
    orders: tuple[int, ...] = eqx.field(static=True)  # signed: +7 positive, −5 negative sequence
    ts: float = eqx.field(static=True)  # the observer's sample time (OnSignal checks they agree)

    accepts_sample_time: ClassVar[bool] = True
    has_flux_angle: ClassVar[bool] = True  # its truth is the flux angle (the metrics' signal=)

    def __init__(self, A1, omega1, phase=0.0, dc=(0.0, 0.0), harmonics=None, ts=1e-4):
        own = "EMFSignal"
        self.A1 = check_positive("A1", A1, own)
        self.omega1 = check_positive("omega1", omega1, own)
        self.phase = check_real("phase", phase, owner=own)
        self.dc = check_real("dc", jnp.asarray(dc, dtype=jnp.result_type(float)), owner=own)
        if self.dc.shape[-1:] != (2,):
            raise ValueError(f"{own}.dc must be the pair (A0α, A0β), got shape {self.dc.shape}")
        harmonics = dict(harmonics or {})
        for h in harmonics:
            if isinstance(h, bool) or not isinstance(h, int) or h == 0:
                raise ValueError(f"{own}.harmonics keys must be nonzero signed integer orders, got {h!r}")
        self.orders = tuple(sorted(harmonics, key=abs))
        self.harmonics = (
            check_real("harmonics", jnp.asarray([harmonics[h] for h in self.orders], jnp.result_type(float)), owner=own)
            if self.orders
            else jnp.zeros((0,))
        )
        self.ts = check_sample_time("ts", ts, own)

    def _avg_cis(self, w, phi, t):
        # average of (cos, sin)(w τ + phi) over τ ∈ [t, t + ts]
        a1, a0 = w * (t + self.ts) + phi, w * t + phi
        return (jnp.sin(a1) - jnp.sin(a0)) / (w * self.ts), (jnp.cos(a0) - jnp.cos(a1)) / (w * self.ts)

    def _avg_cis_exact(self, c_mid, h, phi):
        # float32, t a SampleTime: the same average written at the period's middle,
        # (sin a1 − sin a0, cos a0 − cos a1) = 2 sin(w ts/2)·(cos a_m, sin a_m), a_m = w (t + ts/2) + phi,
        # with a_m from the exact cycles c_mid of ω1 (t + ts/2) (jaxobs.core.sampletime), h·c_mid reduced modulo 1
        c = h * c_mid
        a_m = 2 * jnp.pi * (c - jax.lax.stop_gradient(jnp.round(c))) + phi
        x = 0.5 * h * self.omega1 * self.ts
        sinc = jnp.sin(x) / x
        return sinc * jnp.cos(a_m), sinc * jnp.sin(a_m)

    def emf(self, t: TimeLike) -> tuple[jax.Array, jax.Array]:
        """The EMF (e_α, e_β) averaged over the coming period [t, t + ts] (the class doc's convention); in float32
        from a :class:`SampleTime`, from the exact phase (jaxobs.core.sampletime).

        Args:
            t: The time, s, or a :class:`SampleTime`.

        Returns:
            ``(e_α, e_β)``, V.
        """
        if isinstance(t, SampleTime) and exact_phase(t, self.omega1):  # isinstance: as exact_phase, for the checker
            mid = SampleTime(t.k, t.ts, t.t0 + 0.5 * self.ts)
            c_mid = cycles(self.omega1, mid, 1 / (2 * math.pi))
            cis = lambda h, phi: self._avg_cis_exact(c_mid, h, phi)  # noqa: E731
        else:
            t = time_value(t)
            cis = lambda h, phi: self._avg_cis(h * self.omega1, phi, t)  # noqa: E731
        ca, sa = cis(1, self.phase)
        ea = self.dc[..., 0] + self.A1 * ca
        eb = self.dc[..., 1] + self.A1 * sa
        for i, h in enumerate(self.orders):
            ch, sh = cis(h, 0.0)  # signed frequency: sequence in the sign
            ea = ea + self.harmonics[..., i] * ch
            eb = eb + self.harmonics[..., i] * sh
        return ea, eb

    def flux_angle(self, t: TimeLike) -> Time:
        """The true rotor-flux angle ω1 t + φ1 − π/2 (ψ lags e by 90°); in float32 from a
        :class:`SampleTime`, reduced modulo 2π and exact (jaxobs.core.sampletime).

        Args:
            t: The time, s, or a :class:`SampleTime`.

        Returns:
            The angle, rad.
        """
        if exact_phase(t, self.omega1):
            c = cycles(self.omega1, t, 1 / (2 * math.pi))
            return 2 * jnp.pi * (c - jax.lax.stop_gradient(jnp.round(c))) + self.phase - jnp.pi / 2
        return self.omega1 * time_value(t) + self.phase - jnp.pi / 2

    def flux_omega(self, t: TimeLike) -> jax.Array:
        """The true rotor-flux angle's rate.

        Args:
            t: The times, s (on the last axis).

        Returns:
            ω1, rad/s, shaped like ``t`` (a batch's ω1 on the leading axes).
        """
        return jnp.broadcast_to(jnp.expand_dims(jnp.asarray(self.omega1), -1), jnp.shape(time_value(t)))

    def __call__(self, t):
        ea, eb = self.emf(t)
        z = jnp.zeros_like(ea)
        return DriveInput(u_a=ea, u_b=eb, i_a=z, i_b=z)
