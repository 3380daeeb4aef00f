"""The consistency checks of a drive log (:mod:`jaxobs.signals._logs` runs them; its module doc lists them).

Each reads a log in the observers' form (``u_a, u_b, i_a, i_b, theta_e, omega_e, ts, n, path``, arrays that may
be disk-backed) on up to :data:`_WINDOWS` windows of :data:`_WLEN` consecutive samples spread over it, so that a
check's memory does not grow with the log.  An error is a one-line ``ValueError``; a warning is appended to
``log.warnings``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Protocol

import jax
import numpy as np


class DeclaredLayout(Protocol):
    """What the checks read of a log's declared layout (a :class:`~jaxobs.signals.RecordingLayout` has it)."""

    @property
    def current_frame(self) -> str:
        """``"alpha_beta"`` or ``"abc"``."""
        ...

    @property
    def voltage_frame(self) -> str:
        """``"alpha_beta"``, ``"abc"`` or ``"dq"``."""
        ...

    @property
    def voltage_timing(self) -> str:
        """``"applied"`` or ``"reference"``."""
        ...

    @property
    def voltage_delay(self) -> int:
        """Periods from a reference voltage to its application."""
        ...

    @property
    def angle_unit(self) -> str:
        """The angle's unit."""
        ...

    @property
    def pole_pairs(self) -> int | None:
        """The machine's pole pairs, or None."""
        ...


class LogColumn(Protocol):
    """A column of a log, read a block of rows at a time (a :class:`~jaxobs.signals._logfile.DiskColumn`)."""

    def __getitem__(self, sl: slice, /) -> np.ndarray:
        """The rows ``sl``."""
        ...


class CheckedLog(Protocol):
    """What the checks read of a log in the observers' form (a :class:`~jaxobs.signals._logs.LogData` has it)."""

    @property
    def u_a(self) -> LogColumn:
        """The α voltage applied over [t_k, t_k+1], V."""
        ...

    @property
    def u_b(self) -> LogColumn:
        """The β voltage applied over [t_k, t_k+1], V."""
        ...

    @property
    def i_a(self) -> LogColumn:
        """The α current at t_k, A."""
        ...

    @property
    def i_b(self) -> LogColumn:
        """The β current at t_k, A."""
        ...

    @property
    def theta_e(self) -> LogColumn | None:
        """The unwrapped electrical angle (rad), or None."""
        ...

    @property
    def omega_e(self) -> LogColumn | None:
        """The electrical speed (rad/s), or None."""
        ...

    @property
    def ts(self) -> float:
        """The sample interval, s."""
        ...

    @property
    def n(self) -> int:
        """The number of samples."""
        ...

    @property
    def path(self) -> str:
        """The file read."""
        ...

    @property
    def warnings(self) -> list[str]:
        """The checks' warnings, appended to."""
        ...


class MachineConstants(Protocol):
    """The machine constants the power and timing checks read (a :class:`jaxobs.drive.PMSMParams` has them)."""

    @property
    def p(self) -> int:
        """The pole pairs."""
        ...

    @property
    def Rs(self) -> jax.Array:
        """The stator resistance, Ω."""
        ...

    @property
    def Ld(self) -> jax.Array:
        """The d-axis inductance, H."""
        ...

    @property
    def Lq(self) -> jax.Array:
        """The q-axis inductance, H."""
        ...

    @property
    def psi_f(self) -> jax.Array:
        """The magnet's flux linkage, Wb."""
        ...


# --------------------------------------------------------------------------------------------------------------

_WINDOWS, _WLEN = 48, 2000


def _windows(n, wlen=_WLEN):
    w = min(wlen, n)
    starts = np.unique(np.linspace(0, n - w, min(_WINDOWS, max(1, n // w))).astype(int))
    return [slice(int(s), int(s) + w) for s in starts]


def check_angle_unit(
    log: CheckedLog, layout: DeclaredLayout, cols: Mapping[str, str | None], jumps: Sequence[float]
) -> None:
    """Refuse an angle column declared in radians whose wraps are about 360 apart: it is in degrees.

    Args:
        log: The log.
        layout: Its declared layout (``angle_unit``).
        cols: The columns' names by role (``theta``, ``omega``, ``voltage``, ``current``), for the messages.
        jumps: The angle column's steps larger than π between consecutive samples (its wraps), as converted by the
            declared unit.

    Raises:
        ValueError: The wraps' median is within 18 of 360, naming the column.
    """
    if not jumps or layout.angle_unit != "rad":
        return
    med = float(np.median(np.abs(np.asarray(jumps))))
    if abs(med - 360.0) < 18.0:
        raise ValueError(
            f"recording {log.path!r}: column {cols['theta']!r} wraps by about 360: it is in degrees (declare "
            "angle_unit = 'deg')"
        )


def check_speed(log: CheckedLog, layout: DeclaredLayout, cols: Mapping[str, str | None]) -> None:
    """Refuse a speed column that disagrees with the angle: the mean speed against the slope of the unwrapped angle,
    over the windows that turn at least half an electrical turn a second, more than 5 % from 1; the message names
    the likely cause (a sign, r/min, Hz, degrees, a mechanical speed or angle).

    Args:
        log: The log, with its angle (``theta_e``); nothing is checked without a speed column.
        layout: Its declared layout (``pole_pairs``, or 2 to 12 tried where it has none).
        cols: The columns' names by role (``theta``, ``omega``, ``voltage``, ``current``), for the messages.

    Raises:
        ValueError: The speed disagrees with the angle, naming both columns.
    """
    if log.omega_e is None:
        return
    assert log.theta_e is not None  # run only on a log with an angle (_logs._run_checks)
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


def check_sequence(log: CheckedLog, layout: DeclaredLayout, cols: Mapping[str, str | None]) -> None:
    """Refuse voltage or current columns that are not an α-β pair turning with the angle: over the windows spanning
    an electrical turn, a negative-sequence phasor larger than the positive one (a flipped β sign or swapped
    phases), or above 0.15 of it (phase values read as α-β, or an angle that is not the electrical one).

    Args:
        log: The log, with its angle (``theta_e``).
        layout: Its declared layout (``current_frame``, ``voltage_frame``: the hint).
        cols: The columns' names by role (``theta``, ``omega``, ``voltage``, ``current``), for the messages.

    Raises:
        ValueError: A pair that turns against the angle or is not α-β, naming its columns.
    """
    assert log.theta_e is not None  # run only on a log with an angle (_logs._run_checks)
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
            declared = layout.current_frame if role == "current" else layout.voltage_frame
            angle = (
                f"the angle column {cols['theta']!r} does not turn with them: is it the mechanical angle (declare "
                "angle_kind = 'mechanical' and pole_pairs), or in other units (angle_unit)?"
            )
            if declared != "alpha_beta":  # declared as phases already: the angle is the suspect
                why = f"): {angle}"
            elif 0.2 <= ratio <= 0.35:  # near the 0.27 of phase values read as α-β
                why = f"; phase values read as α-β give 0.27): declare {frame} = 'abc'"
            else:
                why = f"): declare {frame} = 'abc' if they are phase values; else {angle}"
            raise ValueError(
                f"recording {log.path!r}: columns {cols[role]!r} are not an α-β pair (negative sequence "
                f"{ratio:.3g} times the positive{why}"
            )


def check_power(log: CheckedLog, machine: MachineConstants, cols: Mapping[str, str | None]) -> None:
    """Refuse power flowing against the machine: the mean electrical input power 3/2 ⟨u·i⟩ of the opposite sign to
    the machine's 3/2 Rs⟨|i|²⟩ + T_e ω_m from the currents in the angle's frame, and above a fifth of it in size.

    Args:
        log: The log, with its angle (``theta_e``).
        machine: The machine's constants.
        cols: The columns' names by role (``theta``, ``omega``, ``voltage``, ``current``), for the messages.

    Raises:
        ValueError: The power flows against the machine, naming the voltage and current columns.
    """
    assert log.theta_e is not None  # run only on a log with an angle (_logs._run_checks)
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


# samples of a balance window: short, so that the stretches between a log's events hold whole windows (an electrical
# turn at least: 400 samples are one at 25 Hz sampled at 10 kHz; slower turns are skipped)
_BALANCE_WLEN = 400
_STEADY = 0.02  # a window is steady where the mean |x| of its two halves differ by at most this fraction

# The thresholds, as the module doc of jaxobs.signals._logs states them: a DC offset above 2 % of the amplitude on
# one channel, a gain mismatch above 3 % between channels.  On x_α + j x_β = P e^{jθ} + N e^{−jθ} + D:
# - three phase columns (amplitude-invariant Clarke): an offset d·|P| on one phase gives |D| = (2/3) d |P|, a gain
#   error g on one |N| = (g/3) |P| (on phase a, its extra g·i_a enters α alone, with weight 2/3);
# - two phase columns, c = −a − b: the error enters c as well: α = a, β = (a + 2b)/√3, so an offset on a gives
#   δ = d|P| (1 + j/√3), |D| = (2/√3) d |P|, and a gain error |N| = (g/√3) |P| (the same on b);
# - α-β columns: an offset d·|P| on one gives |D| = d |P|, a gain error g on one |N| = (g/2) |P|.
_OFFSET, _GAIN = 0.02, 0.03
# (frame, columns) -> (|D|/|P| per unit offset, |N|/|P| per unit gain error)
_PER_FRAME = {
    ("abc", 3): (2 / 3, 1 / 3),
    ("abc", 2): (2 / math.sqrt(3.0), 1 / math.sqrt(3.0)),
    ("alpha_beta", 2): (1.0, 1 / 2),
}


def _steady_windows(log, xa, xb):
    """The check windows over at least an electrical turn whose amplitude holds: the mean |x| of the two halves
    within :data:`_STEADY` of each other.  A load or speed step inside a window changes the amplitude a constant
    phasor is fitted to, and its residual reads as a sequence or an offset (a rated load step gave a DC offset of
    3.2 % and an unbalance of 1.5 % on a clean log, 0.3 % and 0.16 % on the steady windows)."""
    for sl in _windows(log.n, _BALANCE_WLEN):
        th = np.asarray(log.theta_e[sl])
        if abs(th[-1] - th[0]) < 2 * math.pi:
            continue
        x = (np.asarray(xa[sl]), np.asarray(xb[sl]))
        m = np.hypot(*x)
        h = m.size // 2
        m1, m2 = float(np.mean(m[:h])), float(np.mean(m[h:]))
        if abs(m1 - m2) <= _STEADY * max(m1, m2):
            yield x, th


def check_balance(
    log: CheckedLog, layout: DeclaredLayout, cols: Mapping[str, str | None], counts: Mapping[str, int]
) -> None:
    """Offsets and gain mismatch between channels (phases a, b, c, or α and β), from the α-β fit on the steady
    windows: the DC term and the negative sequence against the thresholds above.

    Args:
        log: The log (its ``warnings`` are appended to); nothing is checked without its angle (``theta_e``).
        layout: Its declared layout (``current_frame``, ``voltage_frame``).
        cols: The columns' names by role (``theta``, ``omega``, ``voltage``, ``current``), for the messages.
        counts: The number of columns read per role (``current``, ``voltage``).
    """
    for role, (xa, xb), frame in (
        ("current", (log.i_a, log.i_b), layout.current_frame),
        ("voltage", (log.u_a, log.u_b), layout.voltage_frame),
    ):
        if (frame, counts[role]) not in _PER_FRAME or log.theta_e is None:
            continue
        P = N = D = 0.0
        for x, th in _steady_windows(log, xa, xb):
            p_, n_, d_ = _sequence(x, th)
            P, N, D = P + abs(p_), N + abs(n_), D + abs(d_)
        if P == 0:
            continue
        per_offset, per_gain = _PER_FRAME[frame, counts[role]]
        offset, gain = D / P / per_offset, N / P / per_gain
        channels = "phases" if frame == "abc" else "channels"
        if offset > _OFFSET:
            log.warnings.append(
                f"recording {log.path!r}: columns {cols[role]!r} carry a DC offset of about {100 * offset:.2g} % of "
                f"the amplitude on one of their {channels} (a sensor offset; warned above {100 * _OFFSET:g} %)"
            )
        if gain > _GAIN:
            log.warnings.append(
                f"recording {log.path!r}: columns {cols[role]!r} are unbalanced: a gain mismatch of about "
                f"{100 * gain:.2g} % between their {channels} (warned above {100 * _GAIN:g} %)"
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


def check_timing(
    log: CheckedLog, layout: DeclaredLayout, machine: MachineConstants, cols: Mapping[str, str | None]
) -> None:
    """Warn when the voltage columns, as declared, match the machine's model best at another period: later
    (the controller's references logged at t_k declared as applied, or a declared delay too short) or earlier
    (a declared delay too long).  Each bias every estimate by ω_e·ts per period.  On a clean log of 000's SPMSM
    the shift by one period raises the mean squared residual 5e5-fold (2.4e-5 → 12.7 V²); parameter errors and
    dead time raise the unshifted residual, so the warning asks for the shifted one to be under half.

    Args:
        log: The log, with its angle (``theta_e``; its ``warnings`` are appended to).
        layout: Its declared layout (``voltage_timing``, ``voltage_delay``: the fix named).
        machine: The machine's constants.
        cols: The columns' names by role (``theta``, ``omega``, ``voltage``, ``current``), for the messages.
    """
    assert log.theta_e is not None  # run only on a log with an angle (_logs._run_checks)
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
