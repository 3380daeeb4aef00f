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

import csv
import math
import re
from pathlib import Path
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import papers
from ._measurements import DriveInput
from ._time import SampleTime, cycles, exact_phase, frac_mul, time_value
from ._validate import as_float, check_nonnegative, check_positive, check_real, check_sample_time, static_float
from .provenance import read_file

__all__ = [
    "GridSignal",
    "SampledSignal",
    "DriveRecording",
    "EMFSignal",
    "SampleTime",
    "paper001_test",
    "PAPER001_TESTS",
    "stack",
    "read_recording",
    "MAX_CSV_BYTES",
    "RecordingColumnError",
]


class GridSignal(eqx.Module):
    """Single-phase test voltage with a settle-then-disturb event (see module doc)."""

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
        if self.freq.ndim == 0 and not any(isinstance(x, jax.core.Tracer) for x in (self.freq, self.freq_step)):
            f_after = float(self.freq) + float(jnp.max(jnp.atleast_1d(self.freq_step)))
            if f_after <= 0:
                raise ValueError(f"{own}.freq_step must keep the frequency > 0 Hz, got freq + freq_step = {f_after:g}")

    # OnSignal passes a SampleTime (the sample index) instead of the rounded float t_k
    accepts_sample_time: ClassVar[bool] = True

    def _on(self, t):
        t = time_value(t)
        return (t >= self.t_event).astype(as_float(t).dtype)

    def _cycles(self, t):
        """θ(t)/(2π) without φ₀ and Δφ, in cycles; in float32 (a SampleTime) exact and reduced modulo 1.

        The event term is split as Δf·t − Δf·tₑ so that each product is reduced exactly (jaxobs._time).
        """
        c = cycles(self.freq, t) + self._on(t) * (cycles(self.freq_step, t) - frac_mul(self.freq_step, self.t_event))
        return c - jax.lax.stop_gradient(jnp.round(c))

    def theta(self, t):
        """True fundamental phase θ(t), rad: unwrapped in float64; in float32 from a :class:`SampleTime`,
        reduced modulo 2π (an unwrapped float32 phase of 3·10⁴ rad is only good to 2 mrad)."""
        if exact_phase(t, self.freq):
            return 2 * jnp.pi * self._cycles(t) + self.phase + self._on(t) * self.phase_jump
        t = time_value(t)
        on = self._on(t)
        dt = jnp.maximum(t - self.t_event, 0.0)
        return 2 * jnp.pi * self.freq * t + self.phase + on * (2 * jnp.pi * self.freq_step * dt + self.phase_jump)

    def omega(self, t):
        """True fundamental angular frequency ω(t), rad/s."""
        return 2 * jnp.pi * (self.freq + self._on(t) * self.freq_step)

    def fundamental_amplitude(self, t):
        return self.amplitude * (1.0 - self._on(t) * self.sag)

    def __call__(self, t):
        on = self._on(t)
        th = self.theta(t)
        v = self.fundamental_amplitude(t) * jnp.cos(th)
        for i, h in enumerate(self.orders):
            v = v + on * self.harmonics[..., i] * jnp.cos(h * th)
        if exact_phase(t, self.sub_freq):
            sub = jnp.cos(2 * jnp.pi * cycles(self.sub_freq, t))
        else:
            sub = jnp.cos(2 * jnp.pi * self.sub_freq * time_value(t))
        v = v + on * (self.dc + self.sub_amplitude * sub)
        return v


class SampledSignal(eqx.Module):
    """A signal given by its samples u_k = u(t₀ + k·ts): a recording, or a waveform computed once.

    ``sig(t)`` reads the samples back by linear interpolation; a time within
    ``SNAP`` of a sample interval from a sample instant reads that sample
    exactly (the loop's sample times t₀ + ts·k carry rounding errors of a few
    ulps, and a replayed recording should give back the recorded numbers, not
    a blend of neighbours).  Before the first sample and after the last one
    the end sample is held — a traced time cannot raise, so a horizon longer
    than the recording must be checked by the caller (``simulate`` does).

    ``truth`` is the true (θ, ω, fundamental amplitude) at the same instants,
    when known (a synthetic waveform); with it, ``simulate`` fills in
    :class:`~jaxobs._simulate.SignalTruth` and a cost may compare against it.
    Leaves may carry a leading batch axis (``vmap`` over recordings of one
    length).

    This is also how a benchmark feeds *precomputed* inputs: the waveform is
    generated once, outside the timed function, and the loop only reads it,
    a block of steps at a time (``SaveFinal``: :mod:`jaxobs._loop`, point 5).
    """

    samples: jax.Array  # u_k, shape (..., n)
    truth: tuple | None  # (θ_k, ω_k, V_k), each shaped like samples, or None
    ts: float = eqx.field(static=True)  # sample interval, s
    t0: float = eqx.field(static=True)  # time of the first sample, s (static, so a horizon is checked when traced)

    SNAP = 1e-3  # fraction of a sample interval treated as "on" a sample instant

    def __init__(self, samples, ts, t0=0.0, *, truth=None):
        own = "SampledSignal"
        samples = check_real("samples", samples, owner=own)
        if samples.ndim < 1 or samples.shape[-1] < 2:
            raise ValueError(
                f"{own}.samples must hold at least 2 samples along its last axis, got shape {samples.shape}"
            )
        self.samples = samples
        self.ts = check_sample_time("ts", ts, own)
        self.t0 = static_float(check_real("t0", t0, owner=own), t0)
        if truth is not None:
            if len(truth) != 3:
                raise ValueError(
                    f"{own}.truth must be (theta, omega, amplitude) sample arrays, got {len(truth)} arrays"
                )
            truth = tuple(
                check_real(name, a, owner=own)
                for name, a in zip(("truth.theta", "truth.omega", "truth.amplitude"), truth)
            )
            for name, a in zip(("theta", "omega", "amplitude"), truth):
                if a.shape != samples.shape:
                    raise ValueError(
                        f"{own}.truth.{name} must have the shape of samples {samples.shape}, got {a.shape}"
                    )
        self.truth = truth

    @property
    def n(self) -> int:
        return self.samples.shape[-1]

    @property
    def has_truth(self) -> bool:
        return self.truth is not None

    @property
    def t_end(self) -> float:
        """Time of the last sample, s."""
        return self.t0 + self.ts * (self.n - 1)

    def _read(self, arr, t):
        return _read_samples(arr, t, self.t0, self.ts, self.SNAP)

    def __call__(self, t):
        return self._read(self.samples, t)

    def _truth(self, which, t):
        if self.truth is None:
            raise ValueError("SampledSignal was built without truth=(theta, omega, amplitude)")
        return self._read(self.truth[which], t)

    def theta(self, t):
        return self._truth(0, t)

    def omega(self, t):
        return self._truth(1, t)

    def fundamental_amplitude(self, t):
        return self._truth(2, t)

    @classmethod
    def from_csv(
        cls,
        path,
        *,
        columns=None,
        time_column=None,
        sample_rate=None,
        ts=None,
        truth=None,
        max_bytes: int | None = None,
    ) -> SampledSignal:
        """A recorded signal from a CSV file, resampled to the observer's sample time ``ts``.

        The file: one row per sample, comma-separated numbers, an optional header row of column
        names, ``#`` comment lines.  The time base is a ``time_column`` (s, strictly increasing; it
        may be non-uniform) or a ``sample_rate`` (Hz, uniform rows).  Times are taken from the first
        row: sample 0 is t = 0.

        Args:
            columns: the channel(s): a name (from the header) or a 0-based index, or a list of them
                (several channels give a batch, samples shaped (channels, n), for ``vmap``); default:
                the one column that is neither the time nor a truth column.
            time_column / sample_rate: the time base (exactly one of them).
            ts: the observer's sample time, s.  ``None`` keeps the recording's own (uniform) rate.
                Otherwise the recording is read at t_k = k·ts by linear interpolation (point
                sampling, as the DSP's converter would: no anti-alias filter).  A recording sampled
                more slowly than 1/ts (any interval longer than 1.01·ts) is refused: interpolation
                would invent the samples in between.
            truth: ``(theta, omega, amplitude)`` column names or indices: the signal's true phase (rad),
                angular frequency (rad/s) and fundamental amplitude, when the recording carries them
                (a reference instrument, or a synthetic record); the metrics that compare an estimate
                with the truth need them.
            max_bytes: refuse a larger file (default :data:`MAX_CSV_BYTES`).

        Raises:
            ValueError: a missing or unreadable file, a file too large, a row of another width, a
                non-number, a non-finite value, an unknown column, a time column that is not
                strictly increasing, fewer than 2 samples, a rate below 1/ts, or both or neither of
                ``time_column`` and ``sample_rate``.
        """
        single = columns is None or isinstance(columns, (str, int))
        want_truth = () if truth is None else tuple(truth)
        if truth is not None and len(want_truth) != 3:
            raise ValueError(f"from_csv: truth must be 3 columns (theta, omega, amplitude), got {truth!r}")
        rec = read_recording(
            path,
            None if columns is None else ([columns] if single else list(columns)),
            time_column=time_column,
            sample_rate=sample_rate,
            ts=ts,
            extra=want_truth,
            angle=want_truth[:1],
            max_bytes=max_bytes,
        )
        data = rec["columns"]
        samples = data[0] if single else np.stack(data)
        tr = None
        if want_truth:
            tr = tuple(np.broadcast_to(a, samples.shape) for a in rec["extra"])
        return cls(samples, rec["ts"], truth=tr)


def _read_samples(arr, t, t0, ts, snap_tol):
    """Linear interpolation of ``arr[..., k]`` (samples at t0 + k·ts) at time t; within ``snap_tol`` of a
    sample interval from a sample instant, that sample exactly; the end samples held outside."""
    n = arr.shape[-1]
    x = (t - t0) / ts
    k = jnp.round(x)
    d = x - k
    snap = jnp.abs(d) <= snap_tol
    i = jnp.clip(k, 0, n - 1).astype(jnp.int32)
    j = jnp.clip(k + jnp.where(d < 0, -1, 1), 0, n - 1).astype(jnp.int32)
    a_i, a_j = arr[..., i], arr[..., j]
    return jnp.where(snap, a_i, a_i + jnp.abs(d) * (a_j - a_i))


# --------------------------------------------------------------------------------------------
# recordings from CSV files
# --------------------------------------------------------------------------------------------

MAX_CSV_BYTES = 64 * 2**20  # a recording file larger than this is refused (from_csv's max_bytes default)
_RATE_SLACK = 1.01  # a recording's interval may exceed ts by 1 % (clock jitter) before it is "too slow"


# a number as Python's float() reads it, less its leniencies: no "1_0" (read as 10), no surrounding junk;
# nan / inf pass here and are refused by the finiteness check with their column and row
_NUMBER = re.compile(r"\s*[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|nan|inf|infinity)\s*", re.I)
MAX_CSV_FIELD = 1000  # characters in one CSV field (csv.field_size_limit while a recording is read)


def _number(x: str) -> float:
    if len(x) > MAX_CSV_FIELD or not _NUMBER.fullmatch(x):
        raise ValueError(x[:40])
    return float(x)


def _csv_table(path, max_bytes):
    """(header or None, float array (rows, columns)) of a CSV file; ValueError naming the problem."""
    p = Path(path)
    try:  # a regular file only (no FIFO, no device), at most max_bytes (jaxobs.provenance.read_file)
        data = read_file(p, max_bytes)
    except ValueError as e:
        msg = str(e)
        msg = msg.replace("cannot read", "cannot read it:") if msg.startswith("cannot read") else msg
        raise ValueError(f"recording {str(p)!r}: {msg}") from None
    try:
        text = data.decode()
    except UnicodeDecodeError:
        raise ValueError(f"recording {str(p)!r}: not UTF-8 text") from None
    lines = [(n, ln) for n, ln in enumerate(text.splitlines(), 1) if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise ValueError(f"recording {str(p)!r}: no data rows")
    limit = csv.field_size_limit(MAX_CSV_FIELD)  # a field over the limit is a csv.Error, reported below
    try:
        reader = csv.reader((ln for _, ln in lines), strict=True)
        rows = list(reader)
    except csv.Error as e:  # a field too large, an unterminated quote: the line it was read from
        lineno = lines[min(max(reader.line_num, 1), len(lines)) - 1][0]
        raise ValueError(f"recording {str(p)!r}: line {lineno}: not CSV ({str(e)[:80]})") from None
    finally:
        csv.field_size_limit(limit)
    header = None
    try:
        [_number(x) for x in rows[0]]
    except ValueError:
        header = [x.strip() for x in rows[0]]
        rows, lines = rows[1:], lines[1:]
        if len(set(header)) != len(header):
            raise ValueError(f"recording {str(p)!r}: the header repeats a column name: {header}") from None
    width = len(header) if header is not None else len(rows[0]) if rows else 0
    out = np.empty((len(rows), width))
    for r, ((lineno, _), row) in enumerate(zip(lines, rows)):
        if len(row) != width:
            raise ValueError(f"recording {str(p)!r}: line {lineno} has {len(row)} fields, the file {width}")
        try:
            out[r] = [_number(x) for x in row]
        except ValueError:
            raise ValueError(f"recording {str(p)!r}: line {lineno} holds a field that is not a number") from None
    return header, out


class RecordingColumnError(ValueError):
    """A column of a recording that is not there; ``role`` ("time", "signal" or "truth") and ``spec`` (the
    name or index asked for) let a caller name the argument or job field that asked for it."""

    def __init__(self, msg: str, role: str, spec):
        super().__init__(msg)
        self.role, self.spec = role, spec


def _column(spec, header, width, path, role):
    """The index of a column given by name or 0-based index."""
    p = str(path)
    if isinstance(spec, (int, np.integer)) and not isinstance(spec, bool):
        if not 0 <= spec < width:
            msg = f"recording {p!r}: {role} column index {spec} is outside 0..{width - 1}"
            raise RecordingColumnError(msg, role, spec)
        return int(spec)
    if isinstance(spec, str):
        if header is None:
            msg = f"recording {p!r}: {role} column {spec!r} named, but the file has no header row"
            raise RecordingColumnError(msg, role, spec)
        if spec not in header:
            msg = f"recording {p!r}: no {role} column {spec!r}; columns: {', '.join(header)}"
            raise RecordingColumnError(msg, role, spec)
        return header.index(spec)
    raise RecordingColumnError(f"recording {p!r}: a {role} column must be a name or an index, got {spec!r}", role, spec)


def read_recording(
    path,
    columns=None,
    *,
    time_column=None,
    sample_rate=None,
    ts=None,
    extra=(),
    angle=(),
    averaged=(),
    max_bytes=None,
) -> dict:
    """Read channels of a CSV recording and resample them to ``ts`` (the engine of :meth:`SampledSignal.from_csv`
    and :meth:`DriveRecording.from_csv`; their docstrings give the file format and the checks).

    ``columns`` and ``extra`` are lists of column names or indices; ``angle`` names the columns among them
    that are angles (unwrapped before interpolation, rad); ``averaged`` those that hold the average over the
    period that starts at each row (a drive's applied voltage): resampled as the average over [t_k, t_k + ts]
    of the recording held piecewise constant.  Returns ``{"columns": [arrays], "extra": [arrays], "ts": s,
    "rate_hz": the recording's own rate, "duration": s, "names": [column names]}``.
    """
    max_bytes = MAX_CSV_BYTES if max_bytes is None else int(max_bytes)
    header, table = _csv_table(path, max_bytes)
    width = table.shape[1]
    if (time_column is None) == (sample_rate is None):
        raise ValueError(f"recording {str(path)!r}: give exactly one of time_column and sample_rate")
    tcol = None if time_column is None else _column(time_column, header, width, path, "time")
    idx_extra = [_column(c, header, width, path, "truth") for c in extra]
    if columns is None:
        rest = [i for i in range(width) if i != tcol and i not in idx_extra]
        if len(rest) != 1:
            names = [header[i] if header else str(i) for i in rest]
            raise ValueError(f"recording {str(path)!r}: name the channel among {', '.join(names)} (columns=...)")
        columns = rest
    idx = [_column(c, header, width, path, "signal") for c in columns]
    if table.shape[0] < 2:
        raise ValueError(f"recording {str(path)!r}: {table.shape[0]} sample(s); at least 2 are needed")
    for i in sorted({*idx, *idx_extra, *([] if tcol is None else [tcol])}):
        bad = np.flatnonzero(~np.isfinite(table[:, i]))
        if bad.size:
            name = header[i] if header else str(i)
            raise ValueError(f"recording {str(path)!r}: column {name!r} is not finite at data row {bad[0] + 1}")
    if tcol is not None:
        t = table[:, tcol] - table[0, tcol]
        dt = np.diff(t)
        if np.any(dt <= 0):
            r = int(np.flatnonzero(dt <= 0)[0])
            raise ValueError(
                f"recording {str(path)!r}: the time column is not strictly increasing (data rows {r + 1}, {r + 2})"
            )
        step, longest = float(np.median(dt)), float(np.max(dt))
        uniform = float(np.max(np.abs(dt - step))) <= 1e-6 * step
    else:
        rate = float(sample_rate)
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError(f"recording {str(path)!r}: sample_rate must be a number of Hz > 0, got {sample_rate!r}")
        step = longest = 1.0 / rate
        t = step * np.arange(table.shape[0])
        uniform = True
    if ts is None:
        if not uniform:
            raise ValueError(
                f"recording {str(path)!r}: the time column is not uniform (intervals {np.min(dt):.6g} to "
                f"{longest:.6g} s): give ts= to resample it"
            )
        ts = step
    ts = check_sample_time("ts", ts, "recording")
    if longest > _RATE_SLACK * ts:
        raise ValueError(
            f"recording {str(path)!r}: sampled at intervals up to {longest:.6g} s ({1 / longest:.6g} Hz), slower "
            f"than the observer's ts = {ts:g} s ({1 / ts:g} Hz): interpolation would invent the samples between"
        )
    names_of = {i: (header[i] if header else str(i)) for i in range(width)}
    angle_idx = {_column(c, header, width, path, "truth") for c in angle}
    avg_idx = {_column(c, header, width, path, "signal") for c in averaged}
    exact = uniform and abs(step - ts) <= 1e-9 * ts
    n = table.shape[0] if exact else int(math.floor(t[-1] / ts * (1 + 1e-12))) + 1
    if avg_idx and not exact:  # every period [t_k, t_k + ts] must lie inside the record
        n = int(math.floor((t[-1] + step) / ts * (1 + 1e-12)))
    if n < 2:
        raise ValueError(
            f"recording {str(path)!r}: {t[-1]:.6g} s long, fewer than 2 samples of ts = {ts:g} s after resampling"
        )
    tk = ts * np.arange(n)

    def resample(i):
        x = table[:, i]
        if i in angle_idx:
            x = np.unwrap(x)
        if exact:
            return x.copy()
        if i in avg_idx:  # the average over [t_k, t_k + ts] of x held constant over each recorded interval
            edges = np.append(t, t[-1] + step)
            cum = np.concatenate([[0.0], np.cumsum(x * np.diff(edges))])
            return (np.interp(tk + ts, edges, cum) - np.interp(tk, edges, cum)) / ts
        return np.interp(tk, t, x)

    return {
        "columns": [resample(i) for i in idx],
        "extra": [resample(i) for i in idx_extra],
        "ts": ts,
        "rate_hz": 1.0 / step,
        "duration": float(t[-1]),
        "names": [names_of[i] for i in idx],
    }


class DriveRecording(eqx.Module):
    """A recording of a drive's measurements, (u_α, u_β, i_α, i_β) per sample, for a drive observer run open
    loop (``jaxobs.OnSignal(observer, recording)``), with the encoder's electrical angle when known.

    ``recording(t)`` returns the :class:`~jaxobs._measurements.DriveInput` at t_k (the drive observers'
    contract: the voltage applied over [t_k, t_k+1], the current sampled at t_k); its ``ts`` must be the
    observer's (``OnSignal`` checks it; :meth:`from_csv` resamples).  With ``theta_e`` (the encoder's
    electrical angle, rad) the truth is reported: ``theta`` the angle (unwrapped), ``omega`` the electrical
    speed (given, or the angle's centred difference), ``fundamental_amplitude`` the voltage vector's length
    |u_αβ|, so that ``jaxobs.metrics`` and the tuning objectives compare θ̂ with the encoder.
    Leaves may carry a leading batch axis (recordings of one length).
    """

    samples: jax.Array  # (..., 4, n): u_α, u_β (V), i_α, i_β (A)
    theta_e: jax.Array | None  # (..., n) encoder electrical angle, rad (unwrapped), or None
    omega_e: jax.Array | None  # (..., n) electrical speed, rad/s, or None
    ts: float = eqx.field(static=True)
    t0: float = eqx.field(static=True)

    SNAP = SampledSignal.SNAP

    def __init__(self, u_a, u_b, i_a, i_b, ts, *, theta_e=None, omega_e=None, t0=0.0):
        own = "DriveRecording"
        arrs = [check_real(nm, a, owner=own) for nm, a in zip(("u_a", "u_b", "i_a", "i_b"), (u_a, u_b, i_a, i_b))]
        shape = arrs[0].shape
        if len(shape) < 1 or shape[-1] < 2:
            raise ValueError(f"{own}.u_a must hold at least 2 samples along its last axis, got shape {shape}")
        for nm, a in zip(("u_b", "i_a", "i_b"), arrs[1:]):
            if a.shape != shape:
                raise ValueError(f"{own}.{nm} must have the shape of u_a {shape}, got {a.shape}")
        self.samples = jnp.stack(arrs, axis=-2)
        self.ts = check_sample_time("ts", ts, own)
        self.t0 = static_float(check_real("t0", t0, owner=own), t0)
        if theta_e is None and omega_e is not None:
            raise ValueError(f"{own}.omega_e needs theta_e (the encoder angle) beside it")
        if theta_e is not None:
            theta_e = check_real("theta_e", theta_e, owner=own)
            if theta_e.shape != shape:
                raise ValueError(f"{own}.theta_e must have the shape of u_a {shape}, got {theta_e.shape}")
            if omega_e is None:  # the angle's derivative: centred differences (one-sided at the ends)
                omega_e = jnp.gradient(theta_e, self.ts, axis=-1)
            omega_e = check_real("omega_e", omega_e, owner=own)
            if omega_e.shape != shape:
                raise ValueError(f"{own}.omega_e must have the shape of u_a {shape}, got {omega_e.shape}")
        self.theta_e, self.omega_e = theta_e, omega_e

    @property
    def n(self) -> int:
        return self.samples.shape[-1]

    @property
    def t_end(self) -> float:
        """Time of the last sample, s."""
        return self.t0 + self.ts * (self.n - 1)

    @property
    def has_truth(self) -> bool:
        return self.theta_e is not None

    def __call__(self, t):
        x = _read_samples(self.samples, t, self.t0, self.ts, self.SNAP)
        return DriveInput(u_a=x[..., 0], u_b=x[..., 1], i_a=x[..., 2], i_b=x[..., 3])

    def theta(self, t):
        if self.theta_e is None:
            raise ValueError("DriveRecording was built without theta_e (the encoder angle)")
        return _read_samples(self.theta_e, t, self.t0, self.ts, self.SNAP)

    def omega(self, t):
        if self.omega_e is None:
            raise ValueError("DriveRecording was built without theta_e (the encoder angle)")
        return _read_samples(self.omega_e, t, self.t0, self.ts, self.SNAP)

    def fundamental_amplitude(self, t):
        m = self(t)
        return jnp.sqrt(m.u_a * m.u_a + m.u_b * m.u_b)

    COLUMNS = ("u_a", "u_b", "i_a", "i_b")

    @classmethod
    def from_csv(
        cls,
        path,
        *,
        columns=COLUMNS,
        time_column=None,
        sample_rate=None,
        ts=None,
        theta_e=None,
        omega_e=None,
        max_bytes: int | None = None,
    ) -> DriveRecording:
        """A drive recording from a CSV file (the format and the checks of :meth:`SampledSignal.from_csv`).

        ``columns``: the four columns u_α, u_β (V), i_α, i_β (A), names or indices (default the names
        ``u_a, u_b, i_a, i_b``); ``theta_e``: the encoder's electrical angle column (rad, wrapped or not),
        ``omega_e``: an electrical speed column (rad/s; default the angle's derivative).  Resampled to
        ``ts``: the currents and the angle by linear interpolation, the voltages as the average over
        each new period [t_k, t_k + ts] of the recorded voltage held over its own periods (a voltage row
        is what the inverter applied until the next row).
        """
        columns = list(columns)
        if len(columns) != 4:
            raise ValueError(f"DriveRecording.from_csv: columns must be 4 (u_a, u_b, i_a, i_b), got {columns!r}")
        extra = [c for c in (theta_e, omega_e) if c is not None]
        if omega_e is not None and theta_e is None:
            raise ValueError("DriveRecording.from_csv: omega_e needs theta_e (the encoder angle) beside it")
        rec = read_recording(
            path,
            columns,
            time_column=time_column,
            sample_rate=sample_rate,
            ts=ts,
            extra=extra,
            angle=extra[:1],
            averaged=columns[:2],
            max_bytes=max_bytes,
        )
        ex = rec["extra"]
        return cls(
            *rec["columns"],
            rec["ts"],
            theta_e=ex[0] if ex else None,
            omega_e=ex[1] if len(ex) > 1 else None,
        )


PAPER001_TESTS = tuple(papers.TESTS_001)


def paper001_test(name: str, *, freq=50.0, amplitude=1.0, t_event=0.2, phase=0.0) -> GridSignal:
    """The test signals of paper 001 (p.u. amplitude, 50 Hz nominal), from :data:`jaxobs.papers.TESTS_001`.

    1: +2 Hz step;  2: +20° phase jump;  3: 0.75 p.u. sag (depth);
    A: 50 → 52 Hz;  B: 0.5 p.u. sag with +60° jump;  C: harmonics 3–13 (THD ≈ 7.7 %);
    D: +0.1 p.u. dc step;  E: 0.1 p.u. 1 Hz sub-harmonic.
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
    kw = dict(amplitude=amplitude, freq=freq, phase=phase, t_event=t_event, harmonics=harmonics)
    for field in ("freq_step", "sag", "sub_freq"):
        if field in test:
            kw[field] = test[field]
    if "phase_jump_deg" in test:
        kw["phase_jump"] = math.radians(test["phase_jump_deg"])
    for field in ("dc", "sub_amplitude"):  # p.u. of the amplitude
        if field in test:
            kw[field] = test[field] * amplitude
    return GridSignal(**kw)


def stack(modules):
    """Stack equally-shaped modules (signals, observers, scenarios) along a new leading batch axis."""
    modules = list(modules)
    if not modules:
        raise ValueError("stack needs at least one module")
    return jax.tree.map(lambda *xs: jnp.stack(xs), *modules)


class EMFSignal(eqx.Module):
    """A two-axis back EMF for testing flux observers without a drive (000 eq 8).

    e_ab(t) = A0 + A1 e^{j(ω1 t + φ1)}·(−j) … written per axis as
    e_α = A0α + A1 cos(ω1 t + φ1) + Σ_h A_h cos(s_h h ω1 t),
    e_β = A0β + A1 sin(ω1 t + φ1) + Σ_h s_h A_h sin(s_h h ω1 t),
    with s_h = ±1 the sequence of harmonic h.  ``__call__(t)`` returns a
    :class:`~jaxobs._measurements.DriveInput` with u = e and i = 0, the voltage being the
    *average* of e over the coming period [t, t + ts] — the same convention as
    the drive, which tells the observer at t_k the voltage it applies over
    [t_k, t_{k+1}].  The true rotor flux (∫e with no dc) is A1/ω1 (sin, −cos)
    of the fundamental.
    """

    A1: jax.Array
    omega1: jax.Array
    phase: jax.Array
    dc: jax.Array  # (A0α, A0β)
    harmonics: jax.Array  # amplitudes A_h for `orders`
    orders: tuple[int, ...] = eqx.field(static=True)  # signed: +7 positive, −5 negative sequence
    ts: float = eqx.field(static=True)  # the observer's sample time (OnSignal checks they agree)

    accepts_sample_time: ClassVar[bool] = True

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
        # with a_m from the exact cycles c_mid of ω1 (t + ts/2) (jaxobs._time), h·c_mid reduced modulo 1
        c = h * c_mid
        a_m = 2 * jnp.pi * (c - jax.lax.stop_gradient(jnp.round(c))) + phi
        x = 0.5 * h * self.omega1 * self.ts
        sinc = jnp.sin(x) / x
        return sinc * jnp.cos(a_m), sinc * jnp.sin(a_m)

    def emf(self, t):
        if exact_phase(t, self.omega1):
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

    def flux_angle(self, t):
        """The true rotor-flux angle ω1 t + φ1 − π/2, rad (ψ lags e by 90°); in float32 from a
        :class:`SampleTime`, reduced modulo 2π and exact (jaxobs._time)."""
        if exact_phase(t, self.omega1):
            c = cycles(self.omega1, t, 1 / (2 * math.pi))
            return 2 * jnp.pi * (c - jax.lax.stop_gradient(jnp.round(c))) + self.phase - jnp.pi / 2
        return self.omega1 * time_value(t) + self.phase - jnp.pi / 2

    def __call__(self, t):
        ea, eb = self.emf(t)
        z = jnp.zeros_like(ea)
        return DriveInput(u_a=ea, u_b=eb, i_a=z, i_b=z)
