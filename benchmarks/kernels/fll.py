"""FLL family (paper 001), AB3 with an RK4 start: the scalar kernels, their numba batch loops (one
scenario per iteration) and the batch-inner kernels (the batch as the inner, SIMD, loop).

Also :func:`triad`, the STREAM triad benchmarks.ceiling measures memory bandwidth with.
"""

from __future__ import annotations

import numpy as np

from .common import TWO_PI, compiled, inlined, maximum, njit_inner, njit_variants, numba, prange, sel

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


NUMBA_FLL = njit_variants(fll_batch)
NUMBA_FLL_PRE = njit_variants(fll_batch_pre)


# ---------------------------------------------------------------------------
# batch-inner kernels: the batch as the inner (SIMD) loop, threads over batch blocks
# ---------------------------------------------------------------------------
#
# How a performance engineer writes these loops.  The kernels above run one scenario at a
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
