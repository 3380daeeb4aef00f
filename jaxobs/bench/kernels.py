"""Baseline implementations of the benchmark workloads: the same steps as jaxobs, written by hand.

One source, two back ends.  :data:`SOURCE` is plain Python written so that
every operation works on scalars *and* on NumPy arrays:

- ``numba``: compiled with ``numba.njit`` per scenario (scalars, small state
  arrays), the loop over the batch either serial or ``parallel=True``
  (``prange`` over scenarios, both cores);
- ``numpy``: the same functions run on arrays of shape (batch,) — a Python loop
  over time, vectorized over the batch.

Both must compute what jaxobs computes, operation for operation, so that the
throughput comparison is of one algorithm: tests/test_bench.py checks them
against :func:`jaxobs.simulate` / :func:`jaxobs.drive.simulate_drive` in float64.
Literals are cast to the working dtype (``F(...)``), so a float32 run stays in
float32 as jaxobs does.
"""

from __future__ import annotations

import math

import numpy as np

SOURCE = r'''
def signal(t, amp, f0, ph, te, fstep, pj, sag, dc, suba, subf):
    # jaxobs.signals.GridSignal.__call__ and .omega (no harmonic orders)
    on = sel(t >= te, F(1.0), F(0.0))
    dt_ = maximum(t - te, F(0.0))
    th = TWO_PI * f0 * t + ph + on * (TWO_PI * fstep * dt_ + pj)
    v = amp * (F(1.0) - on * sag) * cos(th)
    v = v + on * (dc + suba * cos(TWO_PI * subf * t))
    return v, TWO_PI * (f0 + on * fstep)


def f_sogifll(x, u, out, P):
    # jaxobs.SOGIFLL.f: P = (k, lam, v_floor², ·, ·)
    y = x[0]
    q = x[1]
    w = x[2]
    e = u - y
    out[0] = w * (P[0] * e - q)
    out[1] = w * y
    out[2] = -P[1] * e * q / maximum(y * y + q * q, P[2])


def f_wpf(x, u, out, P):
    # jaxobs.SOGIFLLWPF.f: P = (k1, k2, lam, v_floor², ·)
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


def f_wif(x, u, out, P):
    # jaxobs.SOGIFLLWIF.f (fll_error="input"): P = (k1, k2, lam, v_floor², ·)
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


def ab3_step(f, S, x, u, P, i, h, k1, k2, k3, k4, xt, f1, f2):
    """One step of jaxobs.AB3 (RK4 for the first two samples) on x, in place."""
    f(x, u, k1, P)
    if i < 2:  # RK4 start-up (AB3 has no history yet)
        for j in range(S):
            xt[j] = x[j] + HALF_H * k1[j]
        f(xt, u, k2, P)
        for j in range(S):
            xt[j] = x[j] + HALF_H * k2[j]
        f(xt, u, k3, P)
        for j in range(S):
            xt[j] = x[j] + h * k3[j]
        f(xt, u, k4, P)
        for j in range(S):
            x[j] = x[j] + H6 * (k1[j] + F(2.0) * k2[j] + F(2.0) * k3[j] + k4[j])
    else:
        for j in range(S):
            x[j] = x[j] + H12 * (F(23.0) * k1[j] - F(16.0) * f1[j] + F(5.0) * f2[j])
    for j in range(S):
        f2[j] = f1[j]
        f1[j] = k1[j]


def ab3_run(f, S, x, P, sp, n, h, k1, k2, k3, k4, xt, f1, f2):
    """jaxobs.simulate(..., inputs="loop", save="final", cost=(ω̂ − ω)²) with the AB3 rule."""
    acc = x[S - 1] * F(0.0)
    for i in range(n):
        t = F(0.0) + h * F(i)
        u, om = signal(t, sp[0], sp[1], sp[2], sp[3], sp[4], sp[5], sp[6], sp[7], sp[8], sp[9])
        d = x[S - 1] - om
        acc = acc + d * d
        ab3_step(f, S, x, u, P, i, h, k1, k2, k3, k4, xt, f1, f2)
    return h * acc


def ab3_run_pre(f, S, x, P, U, OM, n, h, k1, k2, k3, k4, xt, f1, f2):
    """ab3_run with the input and the true ω precomputed (arrays U, OM of n samples)."""
    acc = x[S - 1] * F(0.0)
    for i in range(n):
        d = x[S - 1] - OM[i]
        acc = acc + d * d
        ab3_step(f, S, x, U[i], P, i, h, k1, k2, k3, k4, xt, f1, f2)
    return h * acc


def obs_f(x, ea, eb, out, O):
    # jaxobs.SecondOrderSOIFO.f: O = (Rs, L, K1, K2, lam, v_floor², omega_min)
    w = x[8]
    K1 = O[2]
    K2 = O[3]
    out[0] = w * (K2 * (K1 * (ea - x[2]) - x[0]) - x[1])
    out[1] = w * x[0]
    out[2] = w * (x[0] - x[3])
    out[3] = w * x[2]
    out[4] = w * (K2 * (K1 * (eb - x[6]) - x[4]) - x[5])
    out[5] = w * x[4]
    out[6] = w * (x[4] - x[7])
    out[7] = w * x[6]
    num = x[0] * x[3] + x[4] * x[7]
    lam = O[4] * w * w
    v2 = maximum(x[2] * x[2] + x[3] * x[3], F(0.0)) + maximum(x[6] * x[6] + x[7] * x[7], F(0.0))
    norm = maximum(maximum(v2, ea * ea + eb * eb), O[5])
    out[8] = -(lam / K1) * num / norm


def plant_f(x, ua, ub, tl, out, M):
    # jaxobs.drive.simulate.plant_field: M = (Rs, Ld, Lq, psi, J, B, p, a5, a7, du)
    i_d = x[0]
    i_q = x[1]
    w_m = x[2]
    th = x[3]
    c = cos(th)
    s = sin(th)
    ia = i_d * c - i_q * s
    ib = i_d * s + i_q * c
    # dead time: −du·sgn(i_x) per phase, back to αβ (amplitude-invariant Clarke)
    ea_ = -M[9] * sign(ia)
    eb_ = -M[9] * sign(F(-0.5) * ia + HALF_S3 * ib)
    ec_ = -M[9] * sign(F(-0.5) * ia - HALF_S3 * ib)
    ua = ua + F(2.0 / 3.0) * (ea_ - F(0.5) * (eb_ + ec_))
    ub = ub + (eb_ - ec_) / S3
    w_e = M[6] * w_m
    u_d = c * ua + s * ub
    u_q = -s * ua + c * ub
    c6 = cos(F(6.0) * th)
    s6 = sin(F(6.0) * th)
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


def wrap(a):
    return PI - mod(PI - a, TWO_PI)


def drive_run(x, o, P, M, O, C, prof, n, ts, k1, k2, k3, k4, xt, ok1, ok2, ok3, ok4, ot):
    """jaxobs.drive.simulate_drive(..., save="final", cost=wrap(θ̂ − θ)²), sensorless, SecondOrderSOIFO.

    x: plant [i_d, i_q, ωm, θe]; o: observer states; P = (u_max, handover, speed_every·ts, t_load_step, load)
    C = FOC gains (kp_d, ki_d, kp_q, ki_q, kp_w, ki_w, i_max, Ld, Lq, psi (estimates), setpoint weight);
    prof = (ω* , u_offset α, u_offset β, i_offset α, i_offset β).
    """
    h = ts / F(2.0)
    acc = x[0] * F(0.0)
    ua = acc
    ub = acc
    int_d = acc
    int_q = acc
    int_w = acc
    iq_hold = acc
    ipa = acc
    ipb = acc
    upa = acc
    upb = acc
    p = M[6]
    for k in range(n):
        t = F(k) * ts
        th = x[3]
        c = cos(th)
        s = sin(th)
        ia = x[0] * c - x[1] * s
        ib = x[0] * s + x[1] * c
        uma = ua + prof[1]
        umb = ub + prof[2]
        ima = ia + prof[3]
        imb = ib + prof[4]
        # --- observer: back EMF over the period that ended, RK4 on the 9 states
        ea = upa - O[0] * F(0.5) * (ima + ipa) - O[1] * (ima - ipa) / ts
        eb = upb - O[0] * F(0.5) * (imb + ipb) - O[1] * (imb - ipb) / ts
        started = sel(k > 0, F(1.0), F(0.0))
        ea = ea * started
        eb = eb * started
        obs_f(o, ea, eb, ok1, O)
        for j in range(9):
            ot[j] = o[j] + HALF_TS * ok1[j]
        obs_f(ot, ea, eb, ok2, O)
        for j in range(9):
            ot[j] = o[j] + HALF_TS * ok2[j]
        obs_f(ot, ea, eb, ok3, O)
        for j in range(9):
            ot[j] = o[j] + ts * ok3[j]
        obs_f(ot, ea, eb, ok4, O)
        for j in range(9):
            o[j] = sel(k > 0, o[j] + TS6 * (ok1[j] + F(2.0) * ok2[j] + F(2.0) * ok3[j] + ok4[j]), o[j])
        ipa = ima
        ipb = imb
        upa = uma
        upb = umb
        wo = maximum(o[8], O[6])
        pa = o[3] / wo
        pb = o[7] / wo
        okp = (pa * pa + pb * pb) > TINY
        th_obs = sel(okp, arctan2(sel(okp, pb, F(0.0)), sel(okp, pa, F(1.0))), F(0.0))
        cross = pa * o[6] - pb * o[2]
        w_obs = sel(cross < F(0.0), -o[8], o[8])
        d = wrap(th_obs - wrap(th))
        acc = acc + d * d
        # --- controller on the observer (after the hand-over time) or the encoder
        use = t >= P[1]
        th_c = sel(use, th_obs, th)
        w_e = sel(use, w_obs, p * x[2])
        w_m = w_e / p
        w_ref = prof[0]
        run_speed = (k % SPEED_EVERY) == 0
        e_w = w_ref - w_m
        unsat = C[4] * (C[10] * w_ref - w_m) + int_w
        iq_sat = minimum(maximum(unsat, -C[6]), C[6])
        windup = (unsat != iq_sat) & (sign(e_w) == sign(unsat))
        int_w = sel(run_speed & (windup == False), int_w + C[5] * e_w * P[2], int_w)
        iq_hold = sel(run_speed, iq_sat, iq_hold)
        cc = cos(th_c)
        sc = sin(th_c)
        i_d = cc * ima + sc * imb
        i_q = -sc * ima + cc * imb
        e_d = F(0.0) - i_d
        e_q = iq_hold - i_q
        u_d = C[0] * e_d + int_d - w_e * C[8] * i_q
        u_q = C[2] * e_q + int_q + w_e * (C[7] * i_d + C[9])
        sq = u_d * u_d + u_q * u_q
        okm = sq > TINY
        mag = sel(okm, sqrt(sel(okm, sq, F(1.0))), F(0.0))
        sat = mag > P[0]
        scale = sel(sat, P[0] / maximum(mag, F(1e-12)), F(1.0))
        int_d = sel(sat, int_d, int_d + C[1] * e_d * ts)
        int_q = sel(sat, int_q, int_q + C[3] * e_q * ts)
        u_d = u_d * scale
        u_q = u_q * scale
        th_out = th_c + F(1.5) * w_e * ts
        co = cos(th_out)
        so = sin(th_out)
        na = co * u_d - so * u_q
        nb = so * u_d + co * u_q
        sq = na * na + nb * nb
        okm = sq > TINY
        mag = sel(okm, sqrt(sel(okm, sq, F(1.0))), F(0.0))
        scale = sel(mag > P[0], P[0] / maximum(mag, F(1e-12)), F(1.0))
        na = na * scale
        nb = nb * scale
        # --- plant over the period under the voltage applied now (computed one period ago)
        tl = sel(t >= P[3], P[4], F(0.0))
        for sub in range(2):
            plant_f(x, ua, ub, tl, k1, M)
            for j in range(4):
                xt[j] = x[j] + HALF_H * k1[j]
            plant_f(xt, ua, ub, tl, k2, M)
            for j in range(4):
                xt[j] = x[j] + HALF_H * k2[j]
            plant_f(xt, ua, ub, tl, k3, M)
            for j in range(4):
                xt[j] = x[j] + h * k3[j]
            plant_f(xt, ua, ub, tl, k4, M)
            for j in range(4):
                x[j] = x[j] + H6 * (k1[j] + F(2.0) * k2[j] + F(2.0) * k3[j] + k4[j])
        x[3] = wrap(x[3])
        ua = na
        ub = nb
    return ts * acc
'''


def _constants(F, h):
    return dict(
        F=F,
        TWO_PI=F(2 * math.pi),
        PI=F(math.pi),
        HALF_H=F(0.5 * h),
        H6=F(h / 6.0),
        H12=F(h / 12.0),
        HALF_S3=F(0.5 * math.sqrt(3.0)),
        S3=F(math.sqrt(3.0)),
        TINY=F(1e-30),
    )


def numpy_namespace(F, h, ts=None, speed_every=10):
    """Globals for running SOURCE on arrays (vectorized over the batch)."""
    ns = dict(
        sel=np.where,
        maximum=np.maximum,
        minimum=np.minimum,
        cos=np.cos,
        sin=np.sin,
        sign=np.sign,
        sqrt=np.sqrt,
        arctan2=np.arctan2,
        mod=np.mod,
        SPEED_EVERY=speed_every,
    )
    ns.update(_constants(F, h))
    if ts is not None:
        ns.update(HALF_TS=F(0.5 * ts), TS6=F(ts / 6.0))
    exec(compile(SOURCE, "<jaxobs.bench.kernels>", "exec"), ns)
    return ns


def numba_namespace(F, h, ts=None, speed_every=10):
    """Globals for running SOURCE per scenario under numba (every function njit-ed)."""
    import numba

    @numba.njit(inline="always")
    def sel(c, a, b):
        return a if c else b

    @numba.njit(inline="always")
    def maximum(a, b):
        return a if a >= b else b  # NaN-free inputs here; same as np.maximum

    @numba.njit(inline="always")
    def minimum(a, b):
        return a if a <= b else b

    ns = dict(
        sel=sel,
        maximum=maximum,
        minimum=minimum,
        cos=np.cos,
        sin=np.sin,
        sign=np.sign,
        sqrt=np.sqrt,
        arctan2=np.arctan2,
        mod=np.mod,
        np=np,
        SPEED_EVERY=speed_every,
    )
    ns.update(_constants(F, h))
    if ts is not None:
        ns.update(HALF_TS=F(0.5 * ts), TS6=F(ts / 6.0))
    exec(compile(SOURCE, "<jaxobs.bench.kernels>", "exec"), ns)
    # _nrt=False: these functions only read and write arrays their caller allocated, so they need
    # no reference counting; with it, every call that passes an array paid an atomic incref/decref
    # pair, which made the step 4× slower (5.5 → 21 M scenario-steps/s, SOGI-FLL, one thread)
    for name in ("signal", "f_sogifll", "f_wpf", "f_wif", "ab3_step", "ab3_run", "ab3_run_pre", "obs_f", "plant_f", "wrap", "drive_run"):
        inline = "always" if name not in ("ab3_run", "ab3_run_pre", "drive_run") else "never"
        ns[name] = numba.njit(inline=inline, _nrt=False)(ns[name])
    return ns
