"""Sensorless PMSM drive (paper 000): plant, second-order SOIFO + FLL, FOC, as scalar kernels; its numba
batch loop (one scenario per iteration) and its batch-inner form (thread blocks of scenarios; see
:mod:`benchmarks.kernels.fll` for why the batch-inner layout, and :func:`drive_block` for why it does
not vectorize here).
"""

from __future__ import annotations

import numpy as np

from .common import (
    HALF_SQRT3,
    PI,
    SQRT3,
    TINY,
    TWO_PI,
    compiled,
    inlined,
    maximum,
    minimum,
    njit_inner,
    njit_variants,
    numba,
    prange,
    sel,
)

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
# the numba baseline: a loop over the batch, one scenario per iteration
# ---------------------------------------------------------------------------


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


NUMBA_DRIVE = njit_variants(drive_batch)


# ---------------------------------------------------------------------------
# batch-inner: threads over batch blocks (the layout's reasoning: benchmarks.kernels.fll)
# ---------------------------------------------------------------------------


@compiled
def drive_block(X0, O0, S0, W, P, M, OB, C, lo, hi, n, t_s, every, F, out):
    """The drive workload for scenarios lo..hi−1 (one thread's block), batch-inner: ``out[lo:hi]`` = costs.

    The state lives in rows (plant (4, m), observer (9, m), loop state (11, m)); each period runs
    :func:`drive_step` over the block's scenarios, a column loaded into thread-local scratch and stored
    back.  Without a vector math library (numba here has no SVML) the ~40 sines, cosines and arctangents
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
