"""Baselines of the benchmark workloads: the same steps as jaxobs, written by hand in plain Python.

One source, two back ends, no generated code:

- **NumPy**: every kernel below is a plain Python function whose operations
  work on scalars *and* on NumPy arrays.  Called from Python on arrays of shape
  (batch,) — states (S, batch) — it is the NumPy baseline: a Python loop over
  time, each step vectorized over the batch.
- **numba**: :func:`numba.extending.register_jitable` lets ``numba.njit`` code
  call the same functions, compiled per scenario on scalars (the small kernels
  inlined into their caller, the time loops compiled as functions of their
  own).  The numba baselines are the batch loops at the end, compiled twice by
  :func:`njit_variants`: serial, and ``parallel=True`` (a ``prange`` over
  scenarios, every core).

Where NumPy and numba spell an operation differently the kernels call a
helper (:func:`sel`, :func:`maximum`, :func:`minimum`): ``np.where`` /
``np.maximum`` / ``np.minimum`` from Python, a scalar select through
:func:`numba.extending.overload` under numba.

Both must compute what jaxobs computes, operation for operation, so that the
throughput comparison is of one algorithm: tests/test_bench.py checks them
against :func:`jaxobs.simulate` (of :class:`jaxobs.OnSignal` and :class:`jaxobs.drive.ClosedLoop`) in float64.
Literals are cast to the working dtype ``F`` (``np.float32`` or ``np.float64``,
passed in: numba compiles one version per dtype), so a float32 run stays in
float32 as jaxobs does; the rule's step fractions (h/2, h/6, h/12) are rounded
to ``F`` once, from the float64 step.

numba is optional (the ``bench`` extra): without it this module still imports,
the kernels run as plain Python and :func:`njit_variants` returns ``{}``.

Speed, with public numba API only.  The earlier version (source strings run
through ``exec``) turned numba's reference counting off with the private
``_nrt=False`` option.  Instead: the time loops (:func:`ab3_run`,
:func:`drive_run`) own their state arrays and keep the integrator's update in
their own body, so no array is handed to a function with branches once per
step (each such call cost an atomic incref/decref pair per array: the
SOGI-FLL ran 2–4× slower); the FLL state size comes from a tuple's length,
so the loops over it unroll.  Measured side by side with the exec'd version
(FLLs and drive, float32 and float64): serial 0–6 % slower, ``parallel=True``
the same within this 2-core machine's noise.
"""

from __future__ import annotations

import math

import numpy as np

try:
    import numba
    from numba.extending import overload, register_jitable
except ImportError:  # numba is the optional `bench` extra
    numba = None

prange = range if numba is None else numba.prange

TWO_PI = 2.0 * math.pi
PI = math.pi
SQRT3 = math.sqrt(3.0)
HALF_SQRT3 = 0.5 * math.sqrt(3.0)
TINY = 1e-30

# The kernels' observers, numbered for the numba batch loops (a branch per scenario, not per step).
SOGI_FLL, SOGI_FLL_WPF, SOGI_FLL_WIF = 0, 1, 2
# The grid signal's parameters, in the order of :func:`signal`'s ``sp`` (jaxobs.GridSignal's field names).
SIGNAL_PARAMS = (
    "amplitude",
    "freq",
    "phase",
    "t_event",
    "freq_step",
    "phase_jump",
    "sag",
    "dc",
    "sub_amplitude",
    "sub_freq",
)


def _jitable(inline: str):
    """Register a plain function for numba callers (``inline``: "always" or "never"); it stays plain Python."""

    def register(fn):
        if numba is not None:
            register_jitable(inline=inline)(fn)
        return fn

    return register


inlined = _jitable("always")  # compiled into the numba caller
compiled = _jitable("never")  # a numba function of its own (the per-scenario time loops)


def njit_variants(fn) -> dict:
    """``{False: njit(fn), True: njit(fn, parallel=True)}``: serial, and a ``prange`` over every core."""
    if numba is None:
        return {}
    return {False: numba.njit(fn), True: numba.njit(parallel=True)(fn)}


# ---------------------------------------------------------------------------
# helpers: NumPy from Python, scalar selects under numba
# ---------------------------------------------------------------------------


def sel(c, a, b):
    """``a`` where ``c``, else ``b``."""
    return np.where(c, a, b)


def maximum(a, b):
    return np.maximum(a, b)


def minimum(a, b):
    return np.minimum(a, b)


if numba is not None:

    @overload(sel, inline="always")
    def _sel_scalar(c, a, b):
        # an if statement: `a if c else b` inlined here trips numba's IR checks (NumbaIRAssumptionWarning)
        def impl(c, a, b):
            if c:
                return a
            return b

        return impl

    @overload(maximum, inline="always")
    def _maximum_scalar(a, b):
        return lambda a, b: max(a, b)  # NaN-free inputs here; same as np.maximum

    @overload(minimum, inline="always")
    def _minimum_scalar(a, b):
        return lambda a, b: min(a, b)


# ---------------------------------------------------------------------------
# FLL family (paper 001), AB3 with an RK4 start
# ---------------------------------------------------------------------------


@inlined
def signal(t, sp, F):
    """jaxobs.signals.GridSignal.__call__ and .omega (no harmonic orders); ``sp`` in SIGNAL_PARAMS order."""
    amp, f0, ph, te, fstep, pj, sag, dc, suba, subf = sp
    on = sel(t >= te, F(1.0), F(0.0))
    dt_ = maximum(t - te, F(0.0))
    th = F(TWO_PI) * f0 * t + ph + on * (F(TWO_PI) * fstep * dt_ + pj)
    v = amp * (F(1.0) - on * sag) * np.cos(th)
    v = v + on * (dc + suba * np.cos(F(TWO_PI) * subf * t))
    return v, F(TWO_PI) * (f0 + on * fstep)


@inlined
def f_sogifll(x, u, out, P):
    """jaxobs.SOGIFLL.f: P = (k, lam, v_floor², ·, ·)."""
    y = x[0]
    q = x[1]
    w = x[2]
    e = u - y
    out[0] = w * (P[0] * e - q)
    out[1] = w * y
    out[2] = -P[1] * e * q / maximum(y * y + q * q, P[2])


@inlined
def f_wpf(x, u, out, P):
    """jaxobs.SOGIFLLWPF.f: P = (k1, k2, lam, v_floor², ·)."""
    p = x[0]
    qp = x[1]
    y = x[2]
    q = x[3]
    w = x[4]
    out[0] = w * (P[0] * (u - p) - qp)
    out[1] = w * p
    out[2] = w * (P[1] * (p - y) - q)
    out[3] = w * y
    out[4] = -P[2] * (p - y) * q / maximum(y * y + q * q, P[3])


@inlined
def f_wif(x, u, out, P):
    """jaxobs.SOGIFLLWIF.f (fll_error="input"): P = (k1, k2, lam, v_floor², ·)."""
    za = x[0]
    zb = x[1]
    y = x[2]
    q = x[3]
    w = x[4]
    out[0] = w * (P[0] * (P[1] * (u - y) - za) - zb)
    out[1] = w * za
    out[2] = w * (za - q)
    out[3] = w * y
    out[4] = -(P[2] / P[1]) * za * q / maximum(y * y + q * q, P[3])


@inlined
def rule_steps(h, F):
    """(h, h/2, h/6, h/12) in the working dtype, each rounded once from the float64 step ``h``."""
    return F(h), F(0.5 * h), F(h / 6.0), F(h / 12.0)


@inlined
def signal_input(src, i, t, F):
    """The input and the true ω at step i, time t, computed: ``src`` = the signal's parameters (SIGNAL_PARAMS)."""
    return signal(t, src, F)


@inlined
def sampled_input(src, i, t, F):
    """The input and the true ω at step i, read back: ``src`` = (U, OM), arrays of n samples."""
    return src[0][i], src[1][i]


@compiled
def ab3_run(f, inp, x0, P, src, n, h, F):
    """jaxobs.simulate(..., save="final", cost=(ω̂ − ω)²) with the AB3 rule (RK4 for the first two steps).

    ``f`` is one of the field functions above with gains ``P``; ``inp(src, i, t, F)`` gives the input
    and the true ω of step i (:func:`signal_input` or :func:`sampled_input`); ``x0`` the initial state
    as a tuple; ``n`` steps of ``h`` (float64); ``F`` the working dtype.

    The state size is ``len(x0)``, part of a tuple's type under numba: the loops over the state have a
    constant trip count and unroll (with the size read off an array's shape the WIF ran 27 % slower).
    """
    h, half_h, h6, h12 = rule_steps(h, F)
    x = np.array(x0)
    k1 = np.zeros_like(x)
    k2 = np.zeros_like(x)
    k3 = np.zeros_like(x)
    k4 = np.zeros_like(x)
    xt = np.zeros_like(x)
    f1 = np.zeros_like(x)
    f2 = np.zeros_like(x)
    S = len(x0)
    acc = x[S - 1] * F(0.0)
    for i in range(n):
        t = F(0.0) + h * F(i)
        u, om = inp(src, i, t, F)
        d = x[S - 1] - om
        acc = acc + d * d
        f(x, u, k1, P)
        if i < 2:  # RK4 start-up (AB3 has no history yet)
            for j in range(S):
                xt[j] = x[j] + half_h * k1[j]
            f(xt, u, k2, P)
            for j in range(S):
                xt[j] = x[j] + half_h * k2[j]
            f(xt, u, k3, P)
            for j in range(S):
                xt[j] = x[j] + h * k3[j]
            f(xt, u, k4, P)
            for j in range(S):
                x[j] = x[j] + h6 * (k1[j] + F(2.0) * k2[j] + F(2.0) * k3[j] + k4[j])
        else:
            for j in range(S):
                x[j] = x[j] + h12 * (F(23.0) * k1[j] - F(16.0) * f1[j] + F(5.0) * f2[j])
        for j in range(S):
            f2[j] = f1[j]
            f1[j] = k1[j]
    return h * acc


# ---------------------------------------------------------------------------
# sensorless PMSM drive (paper 000): plant, second-order SOIFO + FLL, FOC
# ---------------------------------------------------------------------------


@inlined
def obs_f(x, ea, eb, out, OB, F):
    """jaxobs.SecondOrderSOIFO.f: OB = (Rs, L, K1, K2, lam, v_floor², omega_min)."""
    w = x[8]
    K1 = OB[2]
    K2 = OB[3]
    out[0] = w * (K2 * (K1 * (ea - x[2]) - x[0]) - x[1])
    out[1] = w * x[0]
    out[2] = w * (x[0] - x[3])
    out[3] = w * x[2]
    out[4] = w * (K2 * (K1 * (eb - x[6]) - x[4]) - x[5])
    out[5] = w * x[4]
    out[6] = w * (x[4] - x[7])
    out[7] = w * x[6]
    num = x[0] * x[3] + x[4] * x[7]
    lam = OB[4] * w * w
    v2 = maximum(x[2] * x[2] + x[3] * x[3], F(0.0)) + maximum(x[6] * x[6] + x[7] * x[7], F(0.0))
    norm = maximum(maximum(v2, ea * ea + eb * eb), OB[5])
    out[8] = -(lam / K1) * num / norm


@inlined
def plant_f(x, ua, ub, tl, out, M, F):
    """jaxobs.drive.simulate.plant_field: M = (Rs, Ld, Lq, psi, J, B, p, a5, a7, du)."""
    i_d = x[0]
    i_q = x[1]
    w_m = x[2]
    th = x[3]
    c = np.cos(th)
    s = np.sin(th)
    ia = i_d * c - i_q * s
    ib = i_d * s + i_q * c
    # dead time: −du·sgn(i_x) per phase, back to αβ (amplitude-invariant Clarke)
    ea_ = -M[9] * np.sign(ia)
    eb_ = -M[9] * np.sign(F(-0.5) * ia + F(HALF_SQRT3) * ib)
    ec_ = -M[9] * np.sign(F(-0.5) * ia - F(HALF_SQRT3) * ib)
    ua = ua + F(2.0 / 3.0) * (ea_ - F(0.5) * (eb_ + ec_))
    ub = ub + (eb_ - ec_) / F(SQRT3)
    w_e = M[6] * w_m
    u_d = c * ua + s * ub
    u_q = -s * ua + c * ub
    c6 = np.cos(F(6.0) * th)
    s6 = np.sin(F(6.0) * th)
    re = F(1.0) + (M[7] + M[8]) * c6
    im = (M[8] - M[7]) * s6
    k = w_e * M[3]
    e_d = -k * im
    e_q = k * re
    out[0] = (u_d - M[0] * i_d + w_e * M[2] * i_q - e_d) / M[1]
    out[1] = (u_q - M[0] * i_q - w_e * M[1] * i_d - e_q) / M[2]
    pm = M[3] * (re * i_q - im * i_d)
    te = F(1.5) * M[6] * (pm + (M[1] - M[2]) * i_d * i_q)
    out[2] = (te - tl - M[5] * w_m) / M[4]
    out[3] = w_e


@inlined
def wrap(a, F):
    """jaxobs.metrics.wrap: the angle in (−π, π]."""
    return F(PI) - np.mod(F(PI) - a, F(TWO_PI))


@inlined
def drive_step(k, x, o, sv, P, M, OB, C, prof, tsc, every, F, scratch):
    """One control period of :func:`drive_run` (the loop's body): ``x``, ``o`` stepped in place; returns
    (the new loop state ``sv``, this step's running cost).  ``sv`` = (u_α, u_β, int_d, int_q, int_w,
    i_q held, i_prev α, β, u_prev α, β, observer started) as ``s0`` of :func:`drive_run`; ``tsc`` the
    period's step fractions (:func:`drive_steps`), ``scratch`` = the RK4 stages (k1..k4, xt; ok1..ok4, ot)."""
    ts, h, half_h, h6, half_ts, ts6 = tsc
    k1, k2, k3, k4, xt, ok1, ok2, ok3, ok4, ot = scratch
    ua, ub, int_d, int_q, int_w, iq_hold, ipa, ipb, upa, upb, started0 = sv
    p = M[6]
    t = F(k) * ts
    th = x[3]
    c = np.cos(th)
    s = np.sin(th)
    ia = x[0] * c - x[1] * s
    ib = x[0] * s + x[1] * c
    uma = ua + prof[1]
    umb = ub + prof[2]
    ima = ia + prof[3]
    imb = ib + prof[4]
    # --- observer: back EMF over the period that ended, RK4 on the 9 states
    ea = upa - OB[0] * F(0.5) * (ima + ipa) - OB[1] * (ima - ipa) / ts
    eb = upb - OB[0] * F(0.5) * (imb + ipb) - OB[1] * (imb - ipb) / ts
    go = (k > 0) | (started0 > F(0.5))
    started = sel(go, F(1.0), F(0.0))
    ea = ea * started
    eb = eb * started
    obs_f(o, ea, eb, ok1, OB, F)
    for j in range(9):
        ot[j] = o[j] + half_ts * ok1[j]
    obs_f(ot, ea, eb, ok2, OB, F)
    for j in range(9):
        ot[j] = o[j] + half_ts * ok2[j]
    obs_f(ot, ea, eb, ok3, OB, F)
    for j in range(9):
        ot[j] = o[j] + ts * ok3[j]
    obs_f(ot, ea, eb, ok4, OB, F)
    for j in range(9):
        o[j] = sel(go, o[j] + ts6 * (ok1[j] + F(2.0) * ok2[j] + F(2.0) * ok3[j] + ok4[j]), o[j])
    ipa = ima
    ipb = imb
    upa = uma
    upb = umb
    wo = maximum(o[8], OB[6])
    pa = o[3] / wo
    pb = o[7] / wo
    okp = (pa * pa + pb * pb) > F(TINY)
    th_obs = sel(okp, np.arctan2(sel(okp, pb, F(0.0)), sel(okp, pa, F(1.0))), F(0.0))
    cross = pa * o[6] - pb * o[2]
    w_obs = sel(cross < F(0.0), -o[8], o[8])
    d = wrap(th_obs - wrap(th, F), F)
    cost = d * d
    # --- controller on the observer (after the hand-over time) or the encoder
    use = t >= P[1]
    th_c = sel(use, th_obs, th)
    w_e = sel(use, w_obs, p * x[2])
    w_m = w_e / p
    w_ref = prof[0]
    run_speed = (k % every) == 0
    e_w = w_ref - w_m
    unsat = C[4] * (C[10] * w_ref - w_m) + int_w
    iq_sat = minimum(maximum(unsat, -C[6]), C[6])
    windup = (unsat != iq_sat) & (np.sign(e_w) == np.sign(unsat))
    int_w = sel(run_speed & np.logical_not(windup), int_w + C[5] * e_w * P[2], int_w)
    iq_hold = sel(run_speed, iq_sat, iq_hold)
    cc = np.cos(th_c)
    sc = np.sin(th_c)
    i_d = cc * ima + sc * imb
    i_q = -sc * ima + cc * imb
    e_d = F(0.0) - i_d
    e_q = iq_hold - i_q
    u_d = C[0] * e_d + int_d - w_e * C[8] * i_q
    u_q = C[2] * e_q + int_q + w_e * (C[7] * i_d + C[9])
    sq = u_d * u_d + u_q * u_q
    okm = sq > F(TINY)
    mag = sel(okm, np.sqrt(sel(okm, sq, F(1.0))), F(0.0))
    sat = mag > P[0]
    scale = sel(sat, P[0] / maximum(mag, F(1e-12)), F(1.0))
    int_d = sel(sat, int_d, int_d + C[1] * e_d * ts)
    int_q = sel(sat, int_q, int_q + C[3] * e_q * ts)
    u_d = u_d * scale
    u_q = u_q * scale
    th_out = th_c + F(1.5) * w_e * ts
    co = np.cos(th_out)
    so = np.sin(th_out)
    na = co * u_d - so * u_q
    nb = so * u_d + co * u_q
    sq = na * na + nb * nb
    okm = sq > F(TINY)
    mag = sel(okm, np.sqrt(sel(okm, sq, F(1.0))), F(0.0))
    scale = sel(mag > P[0], P[0] / maximum(mag, F(1e-12)), F(1.0))
    na = na * scale
    nb = nb * scale
    # --- plant over the period under the voltage applied now (computed one period ago)
    tl = sel(t >= P[3], P[4], F(0.0))
    for _ in range(2):
        plant_f(x, ua, ub, tl, k1, M, F)
        for j in range(4):
            xt[j] = x[j] + half_h * k1[j]
        plant_f(xt, ua, ub, tl, k2, M, F)
        for j in range(4):
            xt[j] = x[j] + half_h * k2[j]
        plant_f(xt, ua, ub, tl, k3, M, F)
        for j in range(4):
            xt[j] = x[j] + h * k3[j]
        plant_f(xt, ua, ub, tl, k4, M, F)
        for j in range(4):
            x[j] = x[j] + h6 * (k1[j] + F(2.0) * k2[j] + F(2.0) * k3[j] + k4[j])
    x[3] = wrap(x[3], F)
    ua = na
    ub = nb
    return (ua, ub, int_d, int_q, int_w, iq_hold, ipa, ipb, upa, upb, started0), cost


@inlined
def drive_steps(t_s, F):
    """(ts, h, h/2, h/6, ts/2, ts/6) of the drive loop in the working dtype: h = ts/2 the plant's substep."""
    ts = F(t_s)
    return ts, ts / F(2.0), F(0.5 * (t_s / 2.0)), F((t_s / 2.0) / 6.0), F(0.5 * t_s), F(t_s / 6.0)


@compiled
def drive_run(x, o, s0, P, M, OB, C, prof, n, t_s, every, F):
    """jaxobs.simulate(ClosedLoop(...), save=SaveFinal(cost=wrap(θ̂ − θ)²)), sensorless, SecondOrderSOIFO.

    x: plant [i_d, i_q, ωm, θe]; o: observer states; both stepped in place; OB: observer parameters (obs_f).
    s0 = (u_α, u_β, int_d, int_q, int_w, i_q held, i_prev α, β, u_prev α, β, observer started): the rest of
    the loop's initial state (jaxobs's steady start, ClosedLoop.init, computes it).
    P = (u_max, handover, speed_every·ts, t_load_step, load);
    C = FOC gains (kp_d, ki_d, kp_q, ki_q, kp_w, ki_w, i_max, Ld, Lq, psi (estimates), setpoint weight);
    prof = (ω*, u_offset α, u_offset β, i_offset α, i_offset β); ``t_s`` the control period (float64),
    the plant takes two RK4 substeps per period; the speed loop runs every ``every`` periods.
    """
    tsc = drive_steps(t_s, F)
    ts = tsc[0]
    k1 = np.zeros_like(x)
    k2 = np.zeros_like(x)
    k3 = np.zeros_like(x)
    k4 = np.zeros_like(x)
    xt = np.zeros_like(x)
    ok1 = np.zeros_like(o)
    ok2 = np.zeros_like(o)
    ok3 = np.zeros_like(o)
    ok4 = np.zeros_like(o)
    ot = np.zeros_like(o)
    scratch = (k1, k2, k3, k4, xt, ok1, ok2, ok3, ok4, ot)
    acc = x[0] * F(0.0)
    sv = (s0[0], s0[1], s0[2], s0[3], s0[4], s0[5], s0[6], s0[7], s0[8], s0[9], s0[10])
    for k in range(n):
        sv, cost = drive_step(k, x, o, sv, P, M, OB, C, prof, tsc, every, F, scratch)
        acc = acc + cost
    return ts * acc


# ---------------------------------------------------------------------------
# the numba baselines: loops over the batch, one scenario per iteration
# ---------------------------------------------------------------------------


def fll_batch(kind, x0, P, SP, n, h, F):
    """Per-scenario costs of the FLL workload, the signal generated in the loop (``SP``: (batch, 10) parameters)."""
    out = np.empty(SP.shape[0], SP.dtype)
    for b in prange(SP.shape[0]):
        sp = (SP[b, 0], SP[b, 1], SP[b, 2], SP[b, 3], SP[b, 4], SP[b, 5], SP[b, 6], SP[b, 7], SP[b, 8], SP[b, 9])
        if kind == SOGI_FLL:
            out[b] = ab3_run(f_sogifll, signal_input, x0, P, sp, n, h, F)
        elif kind == SOGI_FLL_WPF:
            out[b] = ab3_run(f_wpf, signal_input, x0, P, sp, n, h, F)
        else:
            out[b] = ab3_run(f_wif, signal_input, x0, P, sp, n, h, F)
    return out


def fll_batch_pre(kind, x0, P, U, OM, n, h, F):
    """fll_batch reading the precomputed input and true ω, ``U`` and ``OM`` (batch, n)."""
    out = np.empty(U.shape[0], U.dtype)
    for b in prange(U.shape[0]):
        if kind == SOGI_FLL:
            out[b] = ab3_run(f_sogifll, sampled_input, x0, P, (U[b], OM[b]), n, h, F)
        elif kind == SOGI_FLL_WPF:
            out[b] = ab3_run(f_wpf, sampled_input, x0, P, (U[b], OM[b]), n, h, F)
        else:
            out[b] = ab3_run(f_wif, sampled_input, x0, P, (U[b], OM[b]), n, h, F)
    return out


def drive_batch(X0, O0, S0, W, P, M, OB, C, n, ts, every, F):
    """Per-scenario costs of the drive workload: initial plant X0 (batch, 4), observer O0 (batch, 9) and loop
    state S0 (batch, 11) as jaxobs's steady start gives them, speed reference ``W`` (batch,) rad/s."""
    out = np.empty(W.shape[0], W.dtype)
    for b in prange(W.shape[0]):
        x = X0[b].copy()
        o = O0[b].copy()
        s0 = S0[b]
        z = F(0.0)
        s0t = (s0[0], s0[1], s0[2], s0[3], s0[4], s0[5], s0[6], s0[7], s0[8], s0[9], s0[10])
        out[b] = drive_run(x, o, s0t, P, M, OB, C, (W[b], z, z, z, z), n, ts, every, F)
    return out


NUMBA_FLL = njit_variants(fll_batch)
NUMBA_FLL_PRE = njit_variants(fll_batch_pre)
NUMBA_DRIVE = njit_variants(drive_batch)


# ---------------------------------------------------------------------------
# batch-inner kernels: the batch as the inner (SIMD) loop, threads over batch blocks
# ---------------------------------------------------------------------------
#
# How a performance engineer writes these loops (issue 21).  The kernels above run one scenario at a
# time (the time loop inside, scalars): every step is a dependent chain of a few dozen operations, and
# nothing vectorizes.  Here the time loop is the outer one and the batch the inner one, over
# time-major inputs (n, B) and a state kept as one row of B values per component, so each step is a
# loop over independent scenarios that LLVM vectorizes (AVX-512 on this machine).  ``prange`` hands each
# thread one contiguous block of scenarios for the whole horizon (its state rows stay in its caches);
# nothing is allocated per scenario or per step.  Same arithmetic as the scalar kernels, operation for
# operation (tests/test_bench_inner.py: equal to jaxobs to 1e-10 in float64).
#
# ``fastmath`` is off: with it (reassociation, contraction) the SOGI-FLL still agreed to 1e-10 but was
# no faster here (measured, float32 and float64, B = 1024), so the kernels keep IEEE semantics.


CHUNK = 64  # scenarios per chunk of the batch-inner FLL kernels (ab3_block)


@inlined
def ab3_col(x, f1, f2, b, fj, h12, F):
    """AB3 update of one state component's row ``x`` at column b with its new derivative ``fj``; the
    component's history rows ``f1``, ``f2`` shift."""
    x[b] = x[b] + h12 * (F(23.0) * fj - F(16.0) * f1[b] + F(5.0) * f2[b])
    f2[b] = f1[b]
    f1[b] = fj


@inlined
def rows3(X):
    return (X[0], X[1], X[2])


@inlined
def rows5(X):
    return (X[0], X[1], X[2], X[3], X[4])


@inlined
def steps_sogifll(Xr, F1r, F2r, acc, rows, col, t, P, h12, F):
    """One AB3 step of f_sogifll for every column of the block: the SIMD loop over the batch.

    ``Xr``, ``F1r``, ``F2r``: tuples of 1-D rows (state, history), one per component, unpacked before the
    loop (indexed through the tuple inside it, each row's data pointer was reloaded every iteration: 3×
    slower); ``acc`` the running costs; ``col(rows, b, t, F)`` the input and true ω of column b.
    """
    y_, q_, w_ = Xr
    y1, q1, w1 = F1r
    y2, q2, w2 = F2r
    for b in range(acc.shape[0]):
        u, om = col(rows, b, t, F)
        y = y_[b]
        q = q_[b]
        w = w_[b]
        d = w - om
        acc[b] = acc[b] + d * d
        e = u - y
        ab3_col(y_, y1, y2, b, w * (P[0] * e - q), h12, F)
        ab3_col(q_, q1, q2, b, w * y, h12, F)
        ab3_col(w_, w1, w2, b, -P[1] * e * q / maximum(y * y + q * q, P[2]), h12, F)


@inlined
def steps_wpf(Xr, F1r, F2r, acc, rows, col, t, P, h12, F):
    """One AB3 step of f_wpf for every column of the block (as :func:`steps_sogifll`)."""
    p_, qp_, y_, q_, w_ = Xr
    p1, qp1, y1, q1, w1 = F1r
    p2, qp2, y2, q2, w2 = F2r
    for b in range(acc.shape[0]):
        u, om = col(rows, b, t, F)
        p = p_[b]
        qp = qp_[b]
        y = y_[b]
        q = q_[b]
        w = w_[b]
        d = w - om
        acc[b] = acc[b] + d * d
        ab3_col(p_, p1, p2, b, w * (P[0] * (u - p) - qp), h12, F)
        ab3_col(qp_, qp1, qp2, b, w * p, h12, F)
        ab3_col(y_, y1, y2, b, w * (P[1] * (p - y) - q), h12, F)
        ab3_col(q_, q1, q2, b, w * y, h12, F)
        ab3_col(w_, w1, w2, b, -P[2] * (p - y) * q / maximum(y * y + q * q, P[3]), h12, F)


@inlined
def steps_wif(Xr, F1r, F2r, acc, rows, col, t, P, h12, F):
    """One AB3 step of f_wif for every column of the block (as :func:`steps_sogifll`)."""
    za_, zb_, y_, q_, w_ = Xr
    za1, zb1, y1, q1, w1 = F1r
    za2, zb2, y2, q2, w2 = F2r
    for b in range(acc.shape[0]):
        u, om = col(rows, b, t, F)
        za = za_[b]
        zb = zb_[b]
        y = y_[b]
        q = q_[b]
        w = w_[b]
        d = w - om
        acc[b] = acc[b] + d * d
        ab3_col(za_, za1, za2, b, w * (P[0] * (P[1] * (u - y) - za) - zb), h12, F)
        ab3_col(zb_, zb1, zb2, b, w * za, h12, F)
        ab3_col(y_, y1, y2, b, w * (za - q), h12, F)
        ab3_col(q_, q1, q2, b, w * y, h12, F)
        ab3_col(w_, w1, w2, b, -(P[2] / P[1]) * za * q / maximum(y * y + q * q, P[3]), h12, F)


@inlined
def signal_rows(src, i, lo, hi):
    """The signal's parameters of scenarios lo..hi−1: ``src`` = (SP,), SP (10, B)."""
    return src[0][:, lo:hi]


@inlined
def signal_col(rows, b, t, F):
    """The input and true ω of column b, computed from its parameters (``rows`` from :func:`signal_rows`)."""
    sp = (rows[0, b], rows[1, b], rows[2, b], rows[3, b], rows[4, b])
    sp = sp + (rows[5, b], rows[6, b], rows[7, b], rows[8, b], rows[9, b])
    return signal(t, sp, F)


@inlined
def sampled_rows(src, i, lo, hi):
    """Row i of the time-major input and true ω (``src`` = (U, OM), (n, B)), scenarios lo..hi−1."""
    return (src[0][i, lo:hi], src[1][i, lo:hi])


@inlined
def cached_rows(src, i, lo, hi):
    """:func:`sampled_rows` of a short table read round and round (row i mod its length): the inputs stay in
    cache, so the loop measures the FLL's arithmetic alone (benchmarks.ceiling)."""
    r = i % src[0].shape[0]
    return (src[0][r, lo:hi], src[1][r, lo:hi])


@inlined
def sampled_col(rows, b, t, F):
    return rows[0][b], rows[1][b]


@inlined
def ab3_block(f, steps, views, rows_of, col, x0, P, src, lo, hi, n, h, F, out):
    """The FLL workload for scenarios lo..hi−1 (one thread's block), batch-inner: ``out[lo:hi]`` = costs.

    The state is (S, m) rows (m = hi − lo), the AB3 history two more; the first two steps are RK4 on
    ``f`` (jaxobs's start-up, as in :func:`ab3_run`), then ``steps`` (plain AB3 over the block, written
    out per component; ``views`` splits the (S, m) arrays into rows).  ``rows_of(src, i, lo, hi)`` gives
    step i's inputs of the block, ``col(rows, b, t, F)`` the input and true ω of column b.
    """
    h, half_h, h6, h12 = rule_steps(h, F)
    S = len(x0)
    m = hi - lo
    X = np.empty((S, m), F)
    F1 = np.zeros((S, m), F)
    F2 = np.zeros((S, m), F)
    x = np.empty(S, F)
    k1 = np.empty(S, F)
    k2 = np.empty(S, F)
    k3 = np.empty(S, F)
    k4 = np.empty(S, F)
    xt = np.empty(S, F)
    acc = np.zeros(m, F)
    for j in range(S):
        for b in range(m):
            X[j, b] = x0[j]
    for i in range(min(n, 2)):  # RK4 start-up, per scenario (two steps: not worth vectorizing)
        t = F(0.0) + h * F(i)
        rows = rows_of(src, i, lo, hi)
        for b in range(m):
            u, om = col(rows, b, t, F)
            d = X[S - 1, b] - om
            acc[b] = acc[b] + d * d
            for j in range(S):
                x[j] = X[j, b]
            f(x, u, k1, P)
            for j in range(S):
                xt[j] = x[j] + half_h * k1[j]
            f(xt, u, k2, P)
            for j in range(S):
                xt[j] = x[j] + half_h * k2[j]
            f(xt, u, k3, P)
            for j in range(S):
                xt[j] = x[j] + h * k3[j]
            f(xt, u, k4, P)
            for j in range(S):
                X[j, b] = x[j] + h6 * (k1[j] + F(2.0) * k2[j] + F(2.0) * k3[j] + k4[j])
                F2[j, b] = F1[j, b]
                F1[j, b] = k1[j]
    # The steady loop runs on chunks of CHUNK scenarios, each chunk's rows CHUNK apart in one array: the rows'
    # distances are constants, so LLVM vectorizes without a runtime overlap check per pair of rows (with
    # the 5-state FLLs' 18 rows of m scenarios it gave up and ran scalar).
    nch = (m + CHUNK - 1) // CHUNK
    XC = np.zeros((nch, S, CHUNK), F)
    F1C = np.zeros((nch, S, CHUNK), F)
    F2C = np.zeros((nch, S, CHUNK), F)
    AC = np.zeros((nch, CHUNK), F)
    for b in range(m):
        c, l = b // CHUNK, b % CHUNK
        AC[c, l] = acc[b]
        for j in range(S):
            XC[c, j, l] = X[j, b]
            F1C[c, j, l] = F1[j, b]
            F2C[c, j, l] = F2[j, b]
    for i in range(2, n):
        t = F(0.0) + h * F(i)
        for c in range(nch):
            c0 = lo + c * CHUNK
            c1 = min(c0 + CHUNK, hi)
            rows = rows_of(src, i, c0, c1)
            if c1 - c0 == CHUNK:
                steps(views(XC[c]), views(F1C[c]), views(F2C[c]), AC[c], rows, col, t, P, h12, F)
            else:
                steps(views(XC[c]), views(F1C[c]), views(F2C[c]), AC[c, : c1 - c0], rows, col, t, P, h12, F)
    for b in range(m):
        out[lo + b] = h * AC[b // CHUNK, b % CHUNK]


def fll_inner(kind, x0, P, SP, n, h, F):
    """Per-scenario costs, batch-inner, the signal generated in the loop: ``SP`` (10, B) parameters."""
    B = SP.shape[1]
    out = np.empty(B, SP.dtype)
    nblk = min(numba.get_num_threads(), B) if numba is not None else 1
    for blk in prange(nblk):
        lo = blk * B // nblk
        hi = (blk + 1) * B // nblk
        if kind == SOGI_FLL:
            ab3_block(f_sogifll, steps_sogifll, rows3, signal_rows, signal_col, x0, P, (SP,), lo, hi, n, h, F, out)
        elif kind == SOGI_FLL_WPF:
            ab3_block(f_wpf, steps_wpf, rows5, signal_rows, signal_col, x0, P, (SP,), lo, hi, n, h, F, out)
        else:
            ab3_block(f_wif, steps_wif, rows5, signal_rows, signal_col, x0, P, (SP,), lo, hi, n, h, F, out)
    return out


def fll_inner_pre(kind, x0, P, U, OM, n, h, F):
    """fll_inner reading the precomputed input and true ω as time-major rows ``U``, ``OM`` (n, B)."""
    B = U.shape[1]
    out = np.empty(B, U.dtype)
    nblk = min(numba.get_num_threads(), B) if numba is not None else 1
    for blk in prange(nblk):
        lo = blk * B // nblk
        hi = (blk + 1) * B // nblk
        if kind == SOGI_FLL:
            ab3_block(f_sogifll, steps_sogifll, rows3, sampled_rows, sampled_col, x0, P, (U, OM), lo, hi, n, h, F, out)
        elif kind == SOGI_FLL_WPF:
            ab3_block(f_wpf, steps_wpf, rows5, sampled_rows, sampled_col, x0, P, (U, OM), lo, hi, n, h, F, out)
        else:
            ab3_block(f_wif, steps_wif, rows5, sampled_rows, sampled_col, x0, P, (U, OM), lo, hi, n, h, F, out)
    return out


def njit_inner(fn) -> dict:
    """``{True: njit(fn, parallel=True, error_model="numpy")}``: the batch-inner kernels run on every core.

    ``error_model="numpy"``: a float division by zero gives inf/nan as in NumPy and JAX instead of raising
    (numba's default, Python's semantics, checks every divisor: a branch in the batch loop that stops
    LLVM from vectorizing it).  The divisors here are floored (v_floor², ω_min), never zero.
    """
    if numba is None:
        return {}
    return {True: numba.njit(parallel=True, error_model="numpy")(fn)}


def fll_inner_cached(kind, x0, P, U, OM, n, h, F):
    """fll_inner_pre over ``n`` steps reading a short time-major table ``U``, ``OM`` (r, B) round and round."""
    B = U.shape[1]
    out = np.empty(B, U.dtype)
    nblk = min(numba.get_num_threads(), B) if numba is not None else 1
    for blk in prange(nblk):
        lo = blk * B // nblk
        hi = (blk + 1) * B // nblk
        if kind == SOGI_FLL:
            ab3_block(f_sogifll, steps_sogifll, rows3, cached_rows, sampled_col, x0, P, (U, OM), lo, hi, n, h, F, out)
        elif kind == SOGI_FLL_WPF:
            ab3_block(f_wpf, steps_wpf, rows5, cached_rows, sampled_col, x0, P, (U, OM), lo, hi, n, h, F, out)
        else:
            ab3_block(f_wif, steps_wif, rows5, cached_rows, sampled_col, x0, P, (U, OM), lo, hi, n, h, F, out)
    return out


def triad(a, b, c, s):
    """The STREAM triad a = b + s·c over every thread (benchmarks.ceiling: memory bandwidth)."""
    n = a.shape[0]
    nblk = numba.get_num_threads() if numba is not None else 1
    for blk in prange(nblk):
        for i in range(blk * n // nblk, (blk + 1) * n // nblk):
            a[i] = b[i] + s * c[i]


NUMBA_FLL_INNER = njit_inner(fll_inner)
NUMBA_FLL_INNER_CACHED = njit_inner(fll_inner_cached)
NUMBA_TRIAD = njit_inner(triad)
NUMBA_FLL_INNER_PRE = njit_inner(fll_inner_pre)


@compiled
def drive_block(X0, O0, S0, W, P, M, OB, C, lo, hi, n, t_s, every, F, out):
    """The drive workload for scenarios lo..hi−1 (one thread's block), batch-inner: ``out[lo:hi]`` = costs.

    The state lives in rows (plant (4, m), observer (9, m), loop state (11, m)); each period runs
    :func:`drive_step` over the block's scenarios, a column loaded into thread-local scratch and stored
    back.  Without a vector math library (numba here has no SVML) the ~16 sines, cosines and arctangents
    per period stay scalar calls, so this loop does not vectorize: it is the batch-inner form of the
    scalar kernel, measured beside it.
    """
    tsc = drive_steps(t_s, F)
    m = hi - lo
    XS = np.empty((4, m), F)
    OS = np.empty((9, m), F)
    SS = np.empty((11, m), F)
    acc = np.zeros(m, F)
    for b in range(m):
        for j in range(4):
            XS[j, b] = X0[lo + b, j]
        for j in range(9):
            OS[j, b] = O0[lo + b, j]
        for j in range(11):
            SS[j, b] = S0[lo + b, j]
    x = np.empty(4, F)
    o = np.empty(9, F)
    scratch = (np.empty(4, F), np.empty(4, F), np.empty(4, F), np.empty(4, F), np.empty(4, F))
    scratch = scratch + (np.empty(9, F), np.empty(9, F), np.empty(9, F), np.empty(9, F), np.empty(9, F))
    z = F(0.0)
    for k in range(n):
        for b in range(m):
            for j in range(4):
                x[j] = XS[j, b]
            for j in range(9):
                o[j] = OS[j, b]
            sv = (SS[0, b], SS[1, b], SS[2, b], SS[3, b], SS[4, b], SS[5, b])
            sv = sv + (SS[6, b], SS[7, b], SS[8, b], SS[9, b], SS[10, b])
            sv, cost = drive_step(k, x, o, sv, P, M, OB, C, (W[lo + b], z, z, z, z), tsc, every, F, scratch)
            acc[b] = acc[b] + cost
            for j in range(4):
                XS[j, b] = x[j]
            for j in range(9):
                OS[j, b] = o[j]
            for j in range(11):
                SS[j, b] = sv[j]
    for b in range(m):
        out[lo + b] = tsc[0] * acc[b]


def drive_inner(X0, O0, S0, W, P, M, OB, C, n, ts, every, F):
    """Per-scenario costs of the drive workload, batch-inner over thread blocks (arguments as :func:`drive_batch`)."""
    B = W.shape[0]
    out = np.empty(B, W.dtype)
    nblk = min(numba.get_num_threads(), B) if numba is not None else 1
    for blk in prange(nblk):
        drive_block(X0, O0, S0, W, P, M, OB, C, blk * B // nblk, (blk + 1) * B // nblk, n, ts, every, F, out)
    return out


NUMBA_DRIVE_INNER = njit_inner(drive_inner)
