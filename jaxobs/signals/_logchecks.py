"""The consistency checks of a drive log (:mod:`jaxobs.signals._logs` runs them; its module doc lists them).

Each reads a log in the observers' form (``u_a, u_b, i_a, i_b, theta_e, omega_e, ts, n, path``, arrays that may
be disk-backed) on up to :data:`_WINDOWS` windows of :data:`_WLEN` consecutive samples spread over it, so that a
check's memory does not grow with the log.  An error is a one-line ``ValueError``; a warning is appended to
``log.warnings``.
"""

from __future__ import annotations

import math

import numpy as np

# --------------------------------------------------------------------------------------------------------------

_WINDOWS, _WLEN = 48, 2000


def _windows(n):
    w = min(_WLEN, n)
    starts = np.unique(np.linspace(0, n - w, min(_WINDOWS, max(1, n // w))).astype(int))
    return [slice(int(s), int(s) + w) for s in starts]


def check_angle_unit(log, layout, cols, jumps):
    if not jumps or layout.angle_unit != "rad":
        return
    med = float(np.median(np.abs(np.asarray(jumps))))
    if abs(med - 360.0) < 18.0:
        raise ValueError(
            f"recording {log.path!r}: column {cols['theta']!r} wraps by about 360: it is in degrees (declare "
            "angle_unit = 'deg')"
        )


def check_speed(log, layout, cols):
    if log.omega_e is None:
        return
    num, den = [], []
    for sl in _windows(log.n):
        th = np.asarray(log.theta_e[sl])
        om = np.asarray(log.omega_e[sl])
        t = np.arange(th.size) * log.ts
        slope = np.polyfit(t, th, 1)[0]
        if abs(slope) > 2 * math.pi * 0.5:  # at least half an electrical turn a second
            num.append(float(np.mean(om)))
            den.append(slope)
    if not num:
        return
    r = float(np.median(np.asarray(num) / np.asarray(den)))
    if abs(r - 1.0) <= 0.05:
        return
    p = layout.pole_pairs
    causes = [(-1.0, "a sign (the speed column has the opposite sign to the angle's slope)")]
    causes += [(60 / (2 * math.pi), "r/min (declare speed_unit = 'r/min')")]
    causes += [(180 / math.pi, "degrees per second, or an angle in radians declared as degrees")]
    causes += [(math.pi / 180, "an angle in degrees (declare angle_unit = 'deg')")]
    causes += [(1 / (2 * math.pi), "Hz (declare speed_unit = 'Hz')")]
    for pp in range(2, 13) if p is None else (p,):
        causes += [(1 / pp, f"a mechanical speed (declare speed_kind = 'mechanical'; ratio 1/{pp})")]
        causes += [(pp * 1.0, f"a mechanical angle (declare angle_kind = 'mechanical'; ratio {pp})")]
        rpm = f"mechanical r/min (speed_unit = 'r/min', speed_kind = 'mechanical'; p = {pp})"
        causes += [(60 / (2 * math.pi * pp), rpm)]
    best = min(causes, key=lambda c: abs(math.log(abs(r) / abs(c[0]))) + (0 if np.sign(r) == np.sign(c[0]) else 9))
    why = best[1] if abs(math.log(abs(r) / abs(best[0]))) < 0.05 and np.sign(r) == np.sign(best[0]) else "unknown"
    raise ValueError(
        f"recording {log.path!r}: column {cols['omega']!r} is {r:.4g} times the slope of column {cols['theta']!r} "
        f"(expected 1 in rad/s and rad, electrical): likely {why}"
    )


def _sequence(x, th):
    """P, N, D of x_α + j x_β = P e^{jθ} + N e^{−jθ} + D by least squares."""
    z = x[0] + 1j * x[1]
    e = np.exp(1j * th)
    A = np.stack([e, np.conj(e), np.ones_like(e)], axis=1)
    coef, *_ = np.linalg.lstsq(A, z, rcond=None)
    return coef


def check_sequence(log, layout, cols):
    for role, (xa, xb) in (("voltage", (log.u_a, log.u_b)), ("current", (log.i_a, log.i_b))):
        P = N = 0.0
        scale = 0.0
        for sl in _windows(log.n):
            th = np.asarray(log.theta_e[sl])
            if abs(th[-1] - th[0]) < 2 * math.pi:  # less than an electrical turn: no sequence to see
                continue
            x = (np.asarray(xa[sl]), np.asarray(xb[sl]))
            p_, n_, _ = _sequence(x, th)
            P, N = P + abs(p_), N + abs(n_)
            scale += float(np.sqrt(np.mean(x[0] ** 2 + x[1] ** 2)))
        if P + N == 0 or (P + N) < 1e-9 * max(scale, 1e-300):
            continue
        ratio = N / P if P > 0 else math.inf
        if ratio > 1.0:
            raise ValueError(
                f"recording {log.path!r}: columns {cols[role]!r} turn against the angle column {cols['theta']!r} "
                f"(negative sequence {ratio:.3g} times the positive): a flipped β sign or swapped phases"
            )
        if ratio > 0.15:
            frame = "current_frame" if role == "current" else "voltage_frame"
            raise ValueError(
                f"recording {log.path!r}: columns {cols[role]!r} are not an α-β pair (negative sequence "
                f"{ratio:.3g} times the positive; phase values read as α-β give 0.27): declare {frame} = 'abc'"
            )


def check_power(log, machine, cols):
    pin = pexp = 0.0
    for sl in _windows(log.n):
        th = np.asarray(log.theta_e[sl])
        ua, ub, ia, ib = (np.asarray(a[sl]) for a in (log.u_a, log.u_b, log.i_a, log.i_b))
        w = np.gradient(th, log.ts) if log.omega_e is None else np.asarray(log.omega_e[sl])
        c, s = np.cos(th), np.sin(th)
        i_d, i_q = c * ia + s * ib, -s * ia + c * ib
        te = 1.5 * machine.p * (machine.psi_f * i_q + (machine.Ld - machine.Lq) * i_d * i_q)
        pin += 1.5 * float(np.mean(ua * ia + ub * ib))
        pexp += float(np.mean(1.5 * machine.Rs * (ia**2 + ib**2) + te * w / machine.p))
    if abs(pexp) > 0 and np.sign(pin) != np.sign(pexp) and abs(pin) > 0.2 * abs(pexp):
        raise ValueError(
            f"recording {log.path!r}: the power into the machine from columns {cols['voltage']!r} and "
            f"{cols['current']!r} is {pin / len(_windows(log.n)):.4g} W, the machine's parameters give "
            f"{pexp / len(_windows(log.n)):.4g} W: a voltage or current sign, or the frame, is off"
        )


def check_balance(log, layout, cols):
    """Offsets and gain mismatch between phases: from the α-β fit, the phases' DC and the negative sequence."""
    for role, (xa, xb), frame in (
        ("current", (log.i_a, log.i_b), layout.current_frame),
        ("voltage", (log.u_a, log.u_b), layout.voltage_frame),
    ):
        if frame != "abc" or log.theta_e is None:
            continue
        P = N = D = 0.0
        k = 0
        for sl in _windows(log.n):
            th = np.asarray(log.theta_e[sl])
            if abs(th[-1] - th[0]) < 2 * math.pi:
                continue
            p_, n_, d_ = _sequence((np.asarray(xa[sl]), np.asarray(xb[sl])), th)
            P, N, D, k = P + abs(p_), N + abs(n_), D + abs(d_), k + 1
        if not k or P == 0:
            continue
        if D / P > 0.02:
            log.warnings.append(
                f"recording {log.path!r}: columns {cols[role]!r} carry a DC offset of {100 * D / P:.2g} % of the "
                "amplitude (a sensor offset)"
            )
        if N / P > 0.03 / 2:  # a gain error g on one phase gives a negative sequence of about g/3·... ≥ g/2
            log.warnings.append(
                f"recording {log.path!r}: columns {cols[role]!r} are unbalanced (negative sequence {100 * N / P:.2g} % "
                "of the positive: a gain mismatch between phases)"
            )


def _model_voltage(machine, th, ia, ib, ts):
    """The mean voltage over each period [t_k, t_k+1] that the machine's flux-linkage equation asks for:
    Rs (i_k + i_k+1)/2 + (ψ_k+1 − ψ_k)/ts, ψ = R(θ)(Ld i_d + ψ_f, Lq i_q) (exact but for the trapezoid of ∫i)."""
    c, s = np.cos(th), np.sin(th)
    i_d, i_q = c * ia + s * ib, -s * ia + c * ib
    p_d, p_q = machine.Ld * i_d + machine.psi_f, machine.Lq * i_q
    pa, pb = c * p_d - s * p_q, s * p_d + c * p_q
    ua = machine.Rs * (ia[:-1] + ia[1:]) / 2 + np.diff(pa) / ts
    ub = machine.Rs * (ib[:-1] + ib[1:]) / 2 + np.diff(pb) / ts
    return ua, ub


def check_timing(log, layout, machine, cols):
    """Warn when the voltage columns, as declared, match the machine's model best at another period: later
    (the controller's references logged at t_k declared as applied, or a declared delay too short) or earlier
    (a declared delay too long).  Each bias every estimate by ω_e·ts per period.  On a clean log of 000's SPMSM
    the shift by one period raises the mean squared residual 5e5-fold (2.4e-5 → 12.7 V²); parameter errors and
    dead time raise the unshifted residual, so the warning asks for the shifted one to be under half."""
    shifts = (0, 1, 2, -1)  # periods by which the model is compared later than the voltages
    err = np.zeros(len(shifts))
    for sl in _windows(log.n):
        th = np.asarray(log.theta_e[sl])
        ia, ib, ua, ub = (np.asarray(a[sl]) for a in (log.i_a, log.i_b, log.u_a, log.u_b))
        ma, mb = _model_voltage(machine, th, ia, ib, log.ts)
        n = ma.size - 3
        if n < 10:
            continue
        for j, s in enumerate(shifts):
            a = 1 if s < 0 else 0
            err[j] += np.mean(
                (ua[a : a + n] - ma[a + s : a + s + n]) ** 2 + (ub[a : a + n] - mb[a + s : a + s + n]) ** 2
            )
    best = int(np.argmin(err))
    if best == 0 or not err[best] < 0.5 * err[0]:
        return
    s = shifts[best]
    declared = layout.voltage_delay if layout.voltage_timing == "reference" else 0
    delay = declared + s  # the delay that makes the model match best
    if delay <= 0:
        fix = "declare voltage_timing = 'applied'"
    else:
        fix = f"declare voltage_timing = 'reference', voltage_delay = {delay}"
    where = f"{s} period(s) later" if s > 0 else f"{-s} period(s) earlier"
    log.warnings.append(
        f"recording {log.path!r}: columns {cols['voltage']!r} match the machine's model best {where} than "
        f"declared ({fix}; as declared they bias every estimate by {abs(s)}·ω_e·ts)"
    )
