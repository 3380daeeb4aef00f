"""Recorded signals: a sampled signal with its truth (:class:`SampledSignal`), a drive's u/i with the
encoder angle (:class:`DriveRecording`), both read from CSV files checked in full (:func:`read_recording`)."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar, cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..core.measurements import DriveInput
from ..core.sampletime import TS_REL_TOL, Time
from ..core.validate import check_real, check_sample_time, static_float
from ._base import AbstractSignal
from ._logfile import read_table


class _Recording(AbstractSignal):
    """What the two recordings share: samples on a uniform grid t₀ + k·ts, read back by :func:`_read_samples`, and
    the layout of a batch of them: scenario-major (time last), or time-major (``n_time`` set: the recordings' length,
    time first and the scenarios inner; :class:`SampledSignal`'s doc)."""

    samples: eqx.AbstractVar[jax.Array]
    ts: eqx.AbstractVar[float]
    t0: eqx.AbstractVar[float]
    # a time-major batch's n, else None: static, so that a scenario's view of the batch is checked when traced
    # (simulate refuses one mapped along time)
    n_time: eqx.AbstractVar[int | None]
    scenario_ndim: eqx.AbstractClassVar[int]  # the dimensions of one scenario's samples

    SNAP = 1e-3  # fraction of a sample interval treated as "on" a sample instant

    @property
    def batch_inner(self) -> bool:
        """A time-major batch (built with ``batch_inner=True``)."""
        return self.n_time is not None

    @property
    def batch_axis(self) -> int:
        """The axis of the leaves that :func:`jaxobs.map_batch` maps over: 1 for a time-major batch, else 0."""
        return 1 if self.batch_inner else 0

    @property
    def n(self) -> int:
        return self.samples.shape[0] if self.batch_inner else self.samples.shape[-1]

    @property
    def t_end(self) -> float:
        """Time of the last sample, s."""
        return self.t0 + self.ts * (self.n - 1)

    def check_window(self, t0: float, t_last: float, owner: str) -> None:
        """A recording cannot be read outside its samples (it holds its end values, which would be a lie); a
        time-major batch is read one scenario at a time (under map_batch, or a vmap along its inner axis)."""
        if self.batch_inner and self.samples.ndim != self.scenario_ndim:
            raise ValueError(
                f"simulate: {owner} is a time-major batch of {self.samples.shape[1]} recordings "
                f"({type(self).__name__}(batch_inner=True), samples {self.samples.shape}) and simulate runs one: "
                "map it with jaxobs.map_batch(fn, batch) or jax.vmap(fn, in_axes=(jaxobs.batch_axes(batch),))"
            )
        if self.batch_inner and self.samples.shape[0] != self.n_time:
            # jax.vmap's default in_axes=0 maps a time-major batch along time: each "recording" is then one
            # sample of every scenario; the recording's length, kept static, tells
            raise ValueError(
                f"simulate: {owner} is a time-major batch mapped along its time axis (each scenario sees "
                f"{self.samples.shape[0]} values of a recording of {self.n_time} samples; jax.vmap's default "
                "in_axes=0 does that): map it with jaxobs.map_batch(fn, batch) or "
                "jax.vmap(fn, in_axes=(jaxobs.batch_axes(batch),))"
            )
        tol = self.SNAP * self.ts
        if t0 < self.t0 - tol or t_last > self.t_end + tol:
            raise ValueError(
                f"simulate: the horizon [t0, t0 + ts*(n-1)] = [{t0:g}, {t_last:g}] s must lie inside the "
                f"{type(self).__name__}'s samples [{self.t0:g}, {self.t_end:g}] s"
            )

    def _read(self, arr, t):
        if self.batch_inner:  # time first: read it last (one scenario's (n,) or (n, 4) as (n,) or (4, n))
            arr = jnp.moveaxis(arr, 0, -1)
        return _read_samples(arr, t, self.t0, self.ts, self.SNAP)


class SampledSignal(_Recording):
    """A signal given by its samples u_k = u(t₀ + k·ts): a recording, or a waveform computed once.

    ``sig(t)`` reads the samples back by linear interpolation; a time within ``SNAP`` of a sample interval from a sample
    instant reads that sample exactly (the loop's sample times t₀ + ts·k carry rounding errors of a few ulps, and a
    replayed recording should give back the recorded numbers, not a blend of neighbours).  Before the first sample and
    after the last one the end sample is held — a traced time cannot raise, so a horizon longer than the recording must
    be checked by the caller (``simulate`` does).

    ``truth`` is the true (θ, ω, fundamental amplitude) at the same instants, when known (a synthetic waveform); with
    it, ``simulate`` fills in :class:`~jaxobs.runtime.simulation.SignalTruth` and a cost may compare against it. Leaves
    may carry a leading batch axis (``vmap`` over recordings of one length).

    This is also how a benchmark feeds *precomputed* inputs: the waveform is generated once, outside the timed function,
    and the loop only reads it, a block of steps at a time (``SaveFinal``: :mod:`jaxobs.runtime._loop`, point 5).

    A batch of recordings may be stored **time-major** instead (``batch_inner=True``: ``samples`` and each truth array
    shaped ``(n, B)``, row k holding every scenario's sample k, the layout a recorder or a NumPy study writes column per
    channel). :func:`jaxobs.map_batch` then maps the batch along its inner axis, and the throughput loop (``SaveFinal``,
    ``SaveAll(fast=True)``) takes the rows as its scan inputs where they lie: one contiguous ``(B,)`` row per step,
    nothing gathered or transposed (:mod:`jaxobs.runtime._loop`, point 6). A device's share of a time-major batch runs
    whole (``map_batch`` does not tile it). The plain loop (``SaveAll()``) gives the same numbers by reading the samples
    back through ``sig(t)``, which under ``vmap`` moves the batch axis to the front: correct, slower.

    Args:
        samples: u_k, shape ``(..., n)`` (n ≥ 2), or ``(n, B)`` with ``batch_inner=True``.
        ts: The sample interval, s.
        t0: The time of the first sample, s (static, so a horizon is checked when traced).
        truth: ``(θ_k, ω_k, V_k)``, each shaped like ``samples``, or ``None``.
        batch_inner: Whether ``samples`` (and ``truth``) are a time-major batch ``(n, B)``.

    Raises:
        ValueError: A value out of its range or of the wrong shape, naming the field.
    """

    samples: jax.Array  # u_k, shape (..., n)
    truth: tuple | None  # (θ_k, ω_k, V_k), each shaped like samples, or None
    ts: float = eqx.field(static=True)  # sample interval, s
    t0: float = eqx.field(static=True)  # time of the first sample, s (static, so a horizon is checked when traced)
    n_time: int | None = eqx.field(static=True)  # a time-major batch (batch_inner=True): its n; else None
    scenario_ndim: ClassVar[int] = 1  # u_k: (n,)

    def __init__(self, samples, ts, t0=0.0, *, truth=None, batch_inner=False):
        own = "SampledSignal"
        samples = check_real("samples", samples, owner=own)
        if not isinstance(batch_inner, bool):
            raise ValueError(f"{own}.batch_inner must be True or False, got {batch_inner!r}")
        if batch_inner:
            if samples.ndim != 2 or samples.shape[0] < 2 or samples.shape[1] < 1:
                raise ValueError(
                    f"{own}.samples of a time-major batch (batch_inner=True) must be shaped (n, B) with n >= 2 "
                    f"samples and B >= 1 scenarios, got shape {samples.shape}"
                )
        elif samples.ndim < 1 or samples.shape[-1] < 2:
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
        self.n_time = int(samples.shape[0]) if batch_inner else None

    @property
    def has_truth(self) -> bool:
        """Whether the signal was built with its truth (``truth=(theta, omega, amplitude)``)."""
        return self.truth is not None

    def __call__(self, t):
        return self._read(self.samples, t)

    def _truth(self, which, t):
        if self.truth is None:
            raise ValueError("SampledSignal was built without truth=(theta, omega, amplitude)")
        return self._read(self.truth[which], t)

    def theta(self, t: Time) -> jax.Array:
        """θ(t), rad: ``truth``'s phase, read back as the samples are; ValueError without ``truth``.

        Args:
            t: The time, s.
        """
        return self._truth(0, t)

    def omega(self, t: Time) -> jax.Array:
        """ω(t), rad/s: ``truth``'s angular frequency, read back as the samples are; ValueError without ``truth``.

        Args:
            t: The time, s.
        """
        return self._truth(1, t)

    def fundamental_amplitude(self, t: Time) -> jax.Array:
        """The fundamental amplitude at ``t``: ``truth``'s, read back as the samples are; ValueError without ``truth``.

        Args:
            t: The time, s.
        """
        return self._truth(2, t)

    @classmethod
    def from_csv(
        cls,
        path: str | os.PathLike[str],
        *,
        columns: str | int | Sequence[str | int] | None = None,
        time_column: str | int | None = None,
        sample_rate: float | None = None,
        ts: float | None = None,
        truth: Sequence[str | int] | None = None,
        max_bytes: int | None = None,
    ) -> SampledSignal:
        """A recorded signal from a CSV file, resampled to the observer's sample time ``ts``.

        The file: one row per sample, comma-separated numbers, an optional header row of column names, ``#`` comment
        lines.  The time base is a ``time_column`` (s, strictly increasing; it may be non-uniform) or a ``sample_rate``
        (Hz, uniform rows).  Times are taken from the first row: sample 0 is t = 0.

        Args:
            path: the CSV file.
            columns: the channel(s): a name (from the header) or a 0-based index, or a list of them (several channels
                give a batch, samples shaped (channels, n), for ``vmap``); default: the one column that is neither the
                time nor a truth column.
            time_column: the time column (s, strictly increasing); exactly one of it and ``sample_rate``.
            sample_rate: the rows' rate (Hz, uniform rows); exactly one of it and ``time_column``.
            ts: the observer's sample time, s.  ``None`` keeps the recording's own (uniform) rate. Otherwise the
                recording is read at t_k = k·ts by linear interpolation (point sampling, as the DSP's converter would:
                no anti-alias filter).  A recording sampled more slowly than 1/ts (any interval longer than 1.01·ts) is
                refused: interpolation would invent the samples in between.
            truth: ``(theta, omega, amplitude)`` column names or indices: the signal's true phase (rad), angular
                frequency (rad/s) and fundamental amplitude, when the recording carries them (a reference instrument, or
                a synthetic record); the metrics that compare an estimate with the truth need them.
            max_bytes: refuse a larger file (default :data:`MAX_CSV_BYTES`).

        Returns:
            The :class:`SampledSignal`.

        Raises:
            FileNotFoundError: no file at ``path``.
            ValueError: an unreadable file, a file too large, a row of another width, a non-number, a non-finite value,
                an unknown column, a time column that is not strictly increasing, fewer than 2 samples, a rate below
                1/ts, or both or neither of ``time_column`` and ``sample_rate``.
        """
        single = columns is None or isinstance(columns, (str, int))
        want_truth = () if truth is None else tuple(truth)
        if truth is not None and len(want_truth) != 3:
            raise ValueError(f"from_csv: truth must be 3 columns (theta, omega, amplitude), got {truth!r}")
        rec = read_recording(
            path,
            None if columns is None else [columns] if isinstance(columns, (str, int)) else list(columns),
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


class RecordingColumnError(ValueError):
    """A column of a recording that is not there.

    The role and the spec let a caller name the argument or job field that asked for the column.

    Args:
        msg: The message.
        role: ``"time"``, ``"signal"`` or ``"truth"``.
        spec: The column's name or index asked for.
    """

    def __init__(self, msg: str, role: str, spec):
        super().__init__(msg)
        self.role, self.spec = role, spec


def column_index(spec: object, header: list[str] | None, width: int, path: str | os.PathLike[str], role: str) -> int:
    """The index of a column given by name or 0-based index.

    Args:
        spec: The column: its header name, or its 0-based index.
        header: The file's column names, or None (no header row).
        width: The file's number of columns.
        path: The file (for the message).
        role: ``"time"``, ``"signal"`` or ``"truth"`` (for the message and the error's ``role``).

    Returns:
        The column's 0-based index.

    Raises:
        RecordingColumnError: An index out of range, a name not in the header (or no header), or neither.
    """
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


def check_rate(longest: float, ts: float, where: str) -> None:
    """Refuse a record slower than the observer: an interval longer than ``ts`` (by more than clock jitter).

    Args:
        longest: The record's longest interval, s.
        ts: The observer's sample time, s.
        where: The record's name, for the message.

    Raises:
        ValueError: ``longest`` over ``ts`` by more than 1 %: interpolation would invent the samples between.
    """
    if longest > _RATE_SLACK * ts:
        raise ValueError(
            f"{where}: sampled at intervals up to {longest:.6g} s ({1 / longest:.6g} Hz), slower than the observer's "
            f"ts = {ts:g} s ({1 / ts:g} Hz): interpolation would invent the samples between"
        )


def resample_rows(
    t: np.ndarray,
    columns: Mapping[int, np.ndarray],
    ts: float,
    step: float,
    *,
    exact: bool = False,
    angle: set[int] | frozenset[int] = frozenset(),
    averaged: set[int] | frozenset[int] = frozenset(),
    where: str = "recording",
) -> dict[int, np.ndarray]:
    """Recorded rows at times ``t`` resampled to ``ts``: linear interpolation at t_k = k·ts, the ``averaged`` columns
    (a drive's applied voltage) as the average over [t_k, t_k + ts] of the recording held constant over each
    recorded interval, the ``angle`` columns unwrapped first.

    Args:
        t: The rows' times from the first, s (strictly increasing).
        columns: The columns by index, each as long as ``t``.
        ts: The sample time resampled to, s.
        step: The recorded interval (the median, for a non-uniform record), s: the last row's hold.
        exact: The rows are already at ``ts`` (uniform, within the one tolerance): copied, not resampled.
        angle: The indices of angle columns (rad, unwrapped before interpolation).
        averaged: The indices of the columns held over each recorded interval.
        where: The record's name, for the message.

    Returns:
        index -> the resampled column, for every index of ``columns``.

    Raises:
        ValueError: Fewer than 2 samples of ``ts`` after resampling.
    """
    n = len(t) if exact else int(math.floor(t[-1] / ts * (1 + 1e-12))) + 1
    if averaged and not exact:  # every period [t_k, t_k + ts] must lie inside the record
        n = int(math.floor((t[-1] + step) / ts * (1 + 1e-12)))
    if n < 2:
        raise ValueError(f"{where}: {t[-1]:.6g} s long, fewer than 2 samples of ts = {ts:g} s after resampling")
    tk = ts * np.arange(n)

    def resample(i: int) -> np.ndarray:
        x = np.asarray(columns[i])
        if i in angle:
            x = np.unwrap(x)
        if exact:
            return x.copy()
        if i in averaged:  # the average over [t_k, t_k + ts] of x held constant over each recorded interval
            edges = np.append(t, t[-1] + step)
            cum = np.concatenate([[0.0], np.cumsum(x * np.diff(edges))])
            return (np.interp(tk + ts, edges, cum) - np.interp(tk, edges, cum)) / ts
        return np.interp(tk, t, x)

    return {i: resample(i) for i in columns}


def read_recording(
    path: str | os.PathLike[str],
    columns: Sequence[str | int] | None = None,
    *,
    time_column: str | int | None = None,
    sample_rate: float | None = None,
    ts: float | None = None,
    extra: Sequence[str | int] = (),
    angle: Sequence[str | int] = (),
    averaged: Sequence[str | int] = (),
    max_bytes: int | None = None,
) -> dict[str, Any]:
    """Read channels of a CSV recording and resample them to ``ts`` (the engine of :meth:`SampledSignal.from_csv`
    and :meth:`DriveRecording.from_csv`; their docstrings give the file format and the checks).

    Args:
        path: The CSV file.
        columns: A list of column names or indices: the channels.
        time_column: The time column (s, strictly increasing), or ``None`` with ``sample_rate``.
        sample_rate: The rows' rate, Hz (uniform rows), or ``None`` with ``time_column``.
        ts: The sample time to resample to, s (``None``: the recording's own uniform rate).
        extra: A list of further column names or indices (the truth columns).
        angle: The columns among ``columns`` and ``extra`` that are angles (unwrapped before interpolation, rad).
        averaged: The columns that hold the average over the period that starts at each row (a drive's
            applied voltage): resampled as the average over [t_k, t_k + ts] of the recording held piecewise
            constant.
        max_bytes: Refuse a larger file (default :data:`MAX_CSV_BYTES`).

    Returns:
        ``{"columns": [arrays], "extra": [arrays], "ts": s, "rate_hz": the recording's own rate,
        "duration": s, "names": [column names]}``.

    Raises:
        FileNotFoundError: No file at ``path``.
        ValueError: An unreadable or invalid file (as :meth:`SampledSignal.from_csv` lists).
    """
    max_bytes = MAX_CSV_BYTES if max_bytes is None else int(max_bytes)
    header, table = read_table(path, max_bytes)
    width = table.shape[1]
    if (time_column is None) == (sample_rate is None):
        raise ValueError(f"recording {str(path)!r}: give exactly one of time_column and sample_rate")
    tcol = None if time_column is None else column_index(time_column, header, width, path, "time")
    idx_extra = [column_index(c, header, width, path, "truth") for c in extra]
    if columns is None:
        rest = [i for i in range(width) if i != tcol and i not in idx_extra]
        if len(rest) != 1:
            names = [header[i] if header else str(i) for i in rest]
            raise ValueError(f"recording {str(path)!r}: name the channel among {', '.join(names)} (columns=...)")
        columns = rest
    idx = [column_index(c, header, width, path, "signal") for c in columns]
    if table.shape[0] < 2:
        raise ValueError(f"recording {str(path)!r}: {table.shape[0]} sample(s); at least 2 are needed")
    read: set[int] = {*idx, *idx_extra, *([] if tcol is None else [tcol])}
    for i in sorted(read):
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
        assert sample_rate is not None  # exactly one of time_column and sample_rate, checked above
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
    check_rate(longest, ts, f"recording {str(path)!r}")
    names_of = {i: (header[i] if header else str(i)) for i in range(width)}
    angle_idx = {column_index(c, header, width, path, "truth") for c in angle}
    avg_idx = {column_index(c, header, width, path, "signal") for c in averaged}
    exact = uniform and abs(step - ts) <= TS_REL_TOL * ts
    cols = resample_rows(
        t, {i: table[:, i] for i in sorted(read)}, ts, step, exact=exact,
        angle={*angle_idx} & read, averaged={*avg_idx} & read,
        where=f"recording {str(path)!r}",
    )  # fmt: skip

    return {
        "columns": [cols[i] for i in idx],
        "extra": [cols[i] for i in idx_extra],
        "ts": ts,
        "rate_hz": 1.0 / step,
        "duration": float(t[-1]),
        "names": [names_of[i] for i in idx],
    }


class DriveRecording(_Recording):
    """A recording of a drive's measurements, (u_α, u_β, i_α, i_β) per sample, for a drive observer run open loop
    (``jaxobs.OnSignal(observer, recording)``), with the encoder's electrical angle when known.

    ``recording(t)`` returns the :class:`~jaxobs.core.measurements.DriveInput` at t_k (the drive observers' contract:
    the voltage applied over [t_k, t_k+1], the current sampled at t_k); its ``ts`` must be the observer's (``OnSignal``
    checks it; :meth:`from_csv` resamples).  With ``theta_e`` (the encoder's electrical angle, rad) the truth is
    reported: ``theta`` the angle (unwrapped), ``omega`` the electrical speed (given, or the angle's centred
    difference), ``fundamental_amplitude`` the voltage vector's length |u_αβ|, so that ``jaxobs.metrics`` and the tuning
    objectives compare θ̂ with the encoder. Leaves may carry a leading batch axis (recordings of one length).

    Args:
        u_a: u_α, the voltage applied over [t_k, t_k+1], V, shape ``(..., n)``.
        u_b: u_β, V.
        i_a: i_α, the current sampled at t_k, A.
        i_b: i_β, A.
        ts: The sample interval, s.
        theta_e: The encoder's electrical angle, rad (unwrapped or not), or ``None``.
        omega_e: The electrical speed, rad/s, or ``None`` (the angle's centred difference).
        t0: The time of the first sample, s.
        batch_inner: Whether every array is a batch stored time-major, each ``(n, B)``, read by the
            throughput loop a row per step as :class:`SampledSignal`'s time-major batches are.

    Raises:
        ValueError: A value out of its range or of the wrong shape, naming the field.
    """

    samples: jax.Array  # (..., 4, n): u_α, u_β (V), i_α, i_β (A); a time-major batch (n, B, 4)
    theta_e: jax.Array | None  # (..., n) encoder electrical angle, rad (unwrapped), or None; time-major (n, B)
    omega_e: jax.Array | None  # (..., n) electrical speed, rad/s, or None; time-major (n, B)
    ts: float = eqx.field(static=True)
    t0: float = eqx.field(static=True)
    n_time: int | None = eqx.field(static=True)  # a time-major batch (batch_inner=True): its n; else None
    scenario_ndim: ClassVar[int] = 2  # (n, 4) time-major, (4, n) scenario-major

    def __init__(self, u_a, u_b, i_a, i_b, ts, *, theta_e=None, omega_e=None, t0=0.0, batch_inner=False):
        own = "DriveRecording"
        if not isinstance(batch_inner, bool):
            raise ValueError(f"{own}.batch_inner must be True or False, got {batch_inner!r}")
        arrs = [check_real(nm, a, owner=own) for nm, a in zip(("u_a", "u_b", "i_a", "i_b"), (u_a, u_b, i_a, i_b))]
        shape = arrs[0].shape
        if batch_inner and (len(shape) != 2 or shape[0] < 2 or shape[1] < 1):
            raise ValueError(
                f"{own}.u_a of a time-major batch (batch_inner=True) must be shaped (n, B) with n >= 2 samples "
                f"and B >= 1 scenarios, got shape {shape}"
            )
        if not batch_inner and (len(shape) < 1 or shape[-1] < 2):
            raise ValueError(f"{own}.u_a must hold at least 2 samples along its last axis, got shape {shape}")
        for nm, a in zip(("u_b", "i_a", "i_b"), arrs[1:]):
            if a.shape != shape:
                raise ValueError(f"{own}.{nm} must have the shape of u_a {shape}, got {a.shape}")
        # time-major: (n, B, 4), so that one scenario's rows are (n, 4) with the batch at axis 1, where
        # lax.scan keeps a batched input's batch axis (another place would be a transpose of the recording)
        self.samples = jnp.stack(arrs, axis=-1 if batch_inner else -2)
        self.n_time = int(shape[0]) if batch_inner else None
        self.ts = check_sample_time("ts", ts, own)
        self.t0 = static_float(check_real("t0", t0, owner=own), t0)
        if theta_e is None and omega_e is not None:
            raise ValueError(f"{own}.omega_e needs theta_e (the encoder angle) beside it")
        if theta_e is not None:
            theta_e = check_real("theta_e", theta_e, owner=own)
            if theta_e.shape != shape:
                raise ValueError(f"{own}.theta_e must have the shape of u_a {shape}, got {theta_e.shape}")
            if omega_e is None:  # the angle's derivative: centred differences (one-sided at the ends)
                # one axis: one array (the stubs also allow the list of several)
                omega_e = cast(jax.Array, jnp.gradient(theta_e, self.ts, axis=0 if batch_inner else -1))
            omega_e = check_real("omega_e", omega_e, owner=own)
            if omega_e.shape != shape:
                raise ValueError(f"{own}.omega_e must have the shape of u_a {shape}, got {omega_e.shape}")
        self.theta_e, self.omega_e = theta_e, omega_e

    @property
    def has_truth(self) -> bool:
        """Whether the recording holds the encoder's angle (``theta_e``)."""
        return self.theta_e is not None

    def __call__(self, t):
        x = self._read(self.samples, t)
        return DriveInput(u_a=x[..., 0], u_b=x[..., 1], i_a=x[..., 2], i_b=x[..., 3])

    def theta(self, t: Time) -> jax.Array:
        """θ_e(t), rad: the encoder's electrical angle (unwrapped), read back as the samples are; ValueError without it.

        Args:
            t: The time, s.
        """
        if self.theta_e is None:
            raise ValueError("DriveRecording was built without theta_e (the encoder angle)")
        return self._read(self.theta_e, t)

    def omega(self, t: Time) -> jax.Array:
        """ω_e(t), rad/s: the electrical speed (given, or the angle's centred difference); ValueError without the angle.

        Args:
            t: The time, s.
        """
        if self.omega_e is None:
            raise ValueError("DriveRecording was built without theta_e (the encoder angle)")
        return self._read(self.omega_e, t)

    def fundamental_amplitude(self, t: Time) -> jax.Array:
        """|u_αβ|(t), V: the voltage vector's length at ``t``.

        Args:
            t: The time, s.
        """
        m = self(t)
        return jnp.sqrt(m.u_a * m.u_a + m.u_b * m.u_b)

    COLUMNS = ("u_a", "u_b", "i_a", "i_b")

    @classmethod
    def from_csv(
        cls,
        path: str | os.PathLike[str],
        *,
        columns: Sequence[str | int] = COLUMNS,
        time_column: str | int | None = None,
        sample_rate: float | None = None,
        ts: float | None = None,
        theta_e: str | int | None = None,
        omega_e: str | int | None = None,
        max_bytes: int | None = None,
    ) -> DriveRecording:
        """A drive recording from a CSV file (the format and the checks of :meth:`SampledSignal.from_csv`).

        Resampled to ``ts``: the currents and the angle by linear interpolation, the voltages as the average over each
        new period [t_k, t_k + ts] of the recorded voltage held over its own periods (a voltage row is what the
        inverter applied until the next row).

        Args:
            path: The CSV file.
            columns: The four columns u_α, u_β (V), i_α, i_β (A), names or indices (default ``u_a, u_b, i_a, i_b``).
            time_column: The time column (s, strictly increasing); exactly one of it and ``sample_rate``.
            sample_rate: The rows' rate (Hz, uniform rows); exactly one of it and ``time_column``.
            ts: The observer's sample time, s (``None``: the recording's own uniform rate).
            theta_e: The encoder's electrical angle column (rad, wrapped or not), or ``None``.
            omega_e: An electrical speed column (rad/s; default the angle's derivative).
            max_bytes: Refuse a larger file (default :data:`MAX_CSV_BYTES`).

        Returns:
            The :class:`DriveRecording`.

        Raises:
            FileNotFoundError: No file at ``path``.
            ValueError: An unreadable or invalid file (as :meth:`SampledSignal.from_csv` lists).
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
        args = [*rec["columns"], rec["ts"]]
        return cls(
            *args,
            theta_e=ex[0] if ex else None,
            omega_e=ex[1] if len(ex) > 1 else None,
        )
