"""Drive logs as an engineer records them: a declared layout, a streaming reader, and consistency checks.

A drive observer is run open loop on the measurements its own controller would have given it: the
α-β currents sampled at t_k (amplitude-invariant Clarke transform), and the α-β voltage *applied* over
[t_k, t_k+1], in SI units, with the encoder's *electrical* angle and speed as the truth
(:class:`jaxobs.DriveRecording`).  A log written by a controller rarely holds exactly that:

- its currents are phase currents (two or three of a, b, c), or α-β power-invariant;
- its voltages are the controller's references computed at t_k, which the PWM applies one period
  later (or later still), possibly in the rotor frame (d-q) with the angle the controller used;
- its angle is in degrees or mechanical, its speed in r/min or mechanical rad/s, its time in ms;
- it is a semicolon-separated file with decimal commas, and it is long (minutes at 10 kHz).

:class:`RecordingLayout` declares all of this (in Python, in a job's ``[scenarios.recording]``, or in a
sidecar ``<file>.toml`` beside the CSV); :func:`read_drive_log` reads the file in chunks of rows into
disk-backed columns (the memory a read takes does not grow with the file: ``LogData``), converts it to the
observers' form, and runs the checks below; :meth:`LogData.recording` cuts a window of it into a
:class:`jaxobs.DriveRecording`.

Each check is a one-line ``ValueError`` (a mistake that makes every estimate wrong) or a
:class:`RecordingWarning` (a defect worth knowing), naming the column:

- **speed against angle**: the mean speed column over windows against the slope of the unwrapped angle;
  a ratio near π/180, p, 60/(2π) or their combinations names the unit that was meant (degrees,
  mechanical, r/min), a ratio near −1 a sign;
- **angle unit**: a wrapped angle column whose wraps are 360 apart is in degrees;
- **phase sequence**: each of the voltage and current vectors is fitted, over windows, as a positive- and a
  negative-sequence phasor of the truth angle, x_α + j x_β = P e^{jθ} + N e^{−jθ} + D.  A correct α-β pair
  has |N| ≪ |P|; a flipped β or swapped phases has |N| > |P|; phase currents read as α-β give
  |N|/|P| ≈ 0.27 (an ellipse), so anything above 0.15 is refused;
- **power direction** (with the machine's parameters): the mean electrical input power 3/2 ⟨u·i⟩ against
  the machine's 3/2 Rs⟨|i|²⟩ + T_e ω_m from the measured currents in the truth angle's frame; opposite signs
  are refused (a voltage or current sign, or the wrong frame);
- **voltage timing** (with the machine's parameters): the voltage columns against the mean voltage over each
  period that the machine's flux-linkage equation asks for, shifted by 0, 1 or 2 periods; a best match one or
  two periods late is a warning that the references were logged as applied voltages;
- **balance** (abc and α-β inputs, on the windows whose amplitude holds, away from load and speed steps): a DC
  offset above 2 % of the amplitude on one phase or channel, or a gain mismatch between them above 3 %, is a
  warning; three phases that do not sum to zero (5 % of the amplitude) an error.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
import warnings
from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from ..core.validate import check_sample_time
from ._layout import UNITS, ColumnSpec, RecordingLayout, RecordingWarning
from ._logchecks import (
    MachineConstants,
    check_angle_unit,
    check_balance,
    check_power,
    check_sequence,
    check_speed,
    check_timing,
)
from ._logfile import (
    ColumnWriter,
    DiskColumn,
    check_last_line,
    open_regular,
    read_header,
    row_blocks,
    split_fields,
    stream_columns,
)
from ._recordings import DriveRecording, check_rate, column_index, resample_rows

MAX_LOG_BYTES = 8 * 2**30  # a log file larger than this is refused (10^7 rows of 10 columns is about 1 GiB)


@dataclasses.dataclass
class LogData:
    """A drive log in the observers' form, held in disk-backed columns (the file's length costs disk, not
    memory).

    Attributes:
        u_a: The α voltage applied over [t_k, t_k+1], V.
        u_b: The β voltage applied over [t_k, t_k+1], V.
        i_a: The α current at t_k (A, amplitude-invariant).
        i_b: The β current at t_k (A, amplitude-invariant).
        theta_e: The unwrapped electrical angle (rad), or None.
        omega_e: The electrical speed (rad/s), or None.
        ts: The sample interval, s.
        t0: The time of the first kept row (s: rows dropped by a reference voltage's delay shift it).
        path: The file read.
        warnings: The checks' warnings.
    """

    u_a: DiskColumn
    u_b: DiskColumn
    i_a: DiskColumn
    i_b: DiskColumn
    theta_e: DiskColumn | None
    omega_e: DiskColumn | None
    ts: float
    t0: float
    path: str
    warnings: list[str]
    _folder: object = dataclasses.field(default=None, repr=False)

    @property
    def n(self) -> int:
        """The number of samples (rows kept)."""
        return int(self.u_a.shape[0])

    def recording(self, start: int = 0, n: int | None = None) -> DriveRecording:
        """Rows ``start`` … ``start + n − 1`` as a :class:`jaxobs.DriveRecording` (the whole log by default).

        Args:
            start: The first row.
            n: The rows (default: to the end).

        Returns:
            The :class:`jaxobs.DriveRecording`.

        Raises:
            ValueError: a window outside the log.
        """
        n = self.n - start if n is None else int(n)
        if not (0 <= start and n >= 2 and start + n <= self.n):
            raise ValueError(f"LogData.recording: rows {start}..{start + n - 1} are outside the log's 0..{self.n - 1}")
        sl = slice(start, start + n)

        def get(a):
            return None if a is None else jnp.asarray(np.array(a[sl]))

        return DriveRecording(
            get(self.u_a), get(self.u_b), get(self.i_a), get(self.i_b), self.ts,
            theta_e=get(self.theta_e), omega_e=get(self.omega_e),
        )  # fmt: skip

    def resampled(self, ts: float) -> DriveRecording:
        """The whole log, in the observers' form (its layout's conversions made), resampled to ``ts``: a log
        recorded faster than the observer runs.  The voltages become averages over each new period (each row's
        voltage is applied over its interval), the currents, angle and speed are interpolated
        (:func:`jaxobs.signals._recordings.resample_rows`, as ``DriveRecording.from_csv`` resamples).

        Args:
            ts: The observer's sample time, s.

        Returns:
            The :class:`jaxobs.DriveRecording` at ``ts``.

        Raises:
            ValueError: A log slower than ``ts`` (interpolation would invent the samples between), or fewer than 2
                samples of ``ts``.
        """
        ts = check_sample_time("ts", ts, "LogData.resampled")
        check_rate(self.ts, ts, f"recording {self.path!r}")
        named = {"u_a": self.u_a, "u_b": self.u_b, "i_a": self.i_a, "i_b": self.i_b}
        named.update({k: c for k, c in (("theta_e", self.theta_e), ("omega_e", self.omega_e)) if c is not None})
        keys = list(named)
        t = self.ts * np.arange(self.n)
        cols = resample_rows(
            t, {i: np.asarray(named[k]) for i, k in enumerate(keys)}, ts, self.ts,
            averaged={0, 1}, where=f"recording {self.path!r}",
        )  # fmt: skip
        out = {k: jnp.asarray(cols[i]) for i, k in enumerate(keys)}
        return DriveRecording(
            out["u_a"], out["u_b"], out["i_a"], out["i_b"], ts, theta_e=out.get("theta_e"), omega_e=out.get("omega_e")
        )


def read_drive_log(
    path: str | os.PathLike[str],
    *,
    voltages: Sequence[ColumnSpec] = ("u_a", "u_b"),
    currents: Sequence[ColumnSpec] = ("i_a", "i_b"),
    theta_e: ColumnSpec | None = "theta_e",
    omega_e: ColumnSpec | None = None,
    time_column: ColumnSpec | None = None,
    sample_rate: float | None = None,
    layout: RecordingLayout | None = None,
    machine: MachineConstants | None = None,
    max_bytes: int | None = None,
    folder: str | os.PathLike[str] | None = None,
) -> LogData:
    """Read a drive log of any length into the observers' form, checking it as it goes.

    Args:
        path: the CSV file (one row per sample, ``#`` comment lines, an optional header row).
        voltages: 2 or 3 voltage columns (names or 0-based indices), in ``layout.voltage_frame``.
        currents: 2 or 3 current columns, in ``layout.current_frame``.
        theta_e: the encoder angle column (``layout.angle_unit``/``angle_kind``), or None.
        omega_e: a speed column (``layout.speed_unit``/``speed_kind``), or None (the angle's derivative).
        time_column: a time column (``layout.time_unit``), or None with ``sample_rate``.
        sample_rate: the rows' rate, Hz (uniform rows), or None with ``time_column``.
        layout: what the columns hold; default the sidecar ``<path>.toml`` if there is one, else the
            observers' own form.
        machine: a :class:`jaxobs.drive.PMSMParams` for the power-direction check (skipped without it).
        max_bytes: refuse a larger file (default :data:`MAX_LOG_BYTES`).
        folder: where the disk-backed columns are kept (default a temporary folder removed with the
            returned ``LogData``).

    Returns:
        The log as :class:`LogData`, at the file's own (uniform) rate.

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: one line naming the column or line: an unreadable or oversized file, a delimiter or
            decimal mark other than declared (with a hint), a non-number or non-finite value, a time column that
            is not strictly increasing or not uniform, a speed that disagrees with the angle (with the unit
            meant), a phase sequence opposite to the angle or not α-β, power flowing against the machine.
    """
    p = open_regular(path, MAX_LOG_BYTES if max_bytes is None else int(max_bytes))
    if layout is None:
        layout = RecordingLayout.sidecar(p) or RecordingLayout()
    if not isinstance(layout, RecordingLayout):
        raise ValueError(f"read_drive_log: layout must be a RecordingLayout, got {type(layout).__name__}")
    voltages, currents = list(voltages), list(currents)
    _check_columns_asked(p, layout, voltages, currents, theta_e, time_column, sample_rate)
    header, lines = read_header(p, layout)
    width = len(header) if header is not None else len(split_fields(lines[0][1], layout))
    idx = _column_indices(p, layout, header, width, voltages, currents, theta_e, omega_e, time_column)
    wanted = sorted(set(idx.values()))
    folder, tmp = _columns_folder(folder)
    check_last_line(p)
    raw, rows = stream_columns(p, layout, header, wanted, width, folder)
    shift = layout.voltage_delay if layout.voltage_timing == "reference" else 0
    if rows < 2 + shift:
        raise ValueError(f"recording {p!r}: {rows} sample(s); too few")
    name = {i: (header[i] if header else str(i)) for i in range(width)}
    _check_finite(p, raw, wanted, rows, name)
    if time_column is not None:
        ts, t_first = _time_base_of_column(p, raw[idx[("time", 0)]], rows, name[idx[("time", 0)]], layout)
    else:
        assert sample_rate is not None  # _check_columns_asked: exactly one of time_column and sample_rate
        ts, t_first = _time_base_of_rate(p, sample_rate)
    conv = _Conversion(raw, idx, layout, folder, rows - shift, shift)
    conv.run(len(currents), len(voltages), theta_e is not None, omega_e is not None)
    conv.check_phase_sum(p, name)
    del raw
    warn: list[str] = []
    log = LogData(*conv.columns(), ts, t_first + shift * ts, p, warn, _folder=tmp)
    cols = {
        "theta": name[idx[("theta", 0)]] if ("theta", 0) in idx else None,
        "omega": name[idx[("omega", 0)]] if ("omega", 0) in idx else None,
        "voltage": ", ".join(name[idx[("voltage", k)]] for k in range(len(voltages))),
        "current": ", ".join(name[idx[("current", k)]] for k in range(len(currents))),
    }
    _run_checks(log, layout, machine, cols, conv.wrapped_jumps, len(currents), len(voltages))
    for w in warn:
        warnings.warn(RecordingWarning(w), stacklevel=2)
    return log


def _check_columns_asked(
    p: str,
    layout: RecordingLayout,
    voltages: list[ColumnSpec],
    currents: list[ColumnSpec],
    theta_e: ColumnSpec | None,
    time_column: ColumnSpec | None,
    sample_rate: float | None,
) -> None:
    """Refuse column counts the layout's frames do not take, both or neither of a time column and a rate, and d-q
    voltages without an angle to turn them by."""
    if layout.voltage_frame == "dq" and len(voltages) != 2:
        raise ValueError(f"recording {p!r}: voltages in 'dq' are 2 columns (u_d, u_q), got {len(voltages)}")
    for role, cols, frame in (("voltage", voltages, layout.voltage_frame), ("current", currents, layout.current_frame)):
        allowed = (2, 3) if frame == "abc" else (2,)
        if len(cols) not in allowed:
            raise ValueError(
                f"recording {p!r}: {role} columns in {frame!r} are {' or '.join(map(str, allowed))}, got {len(cols)}"
            )
    if layout.voltage_frame == "abc" and len(voltages) == 2 and layout.voltage_zero_sequence != "none":
        raise ValueError(
            f"recording {p!r}: two phase voltages give the third as −a − b only where they carry no zero sequence "
            "(a min-max or space-vector reference carries one): give the third column, or declare "
            "voltage_zero_sequence = 'none'"
        )
    if (time_column is None) == (sample_rate is None):
        raise ValueError(f"recording {p!r}: give exactly one of time_column and sample_rate")
    if layout.voltage_frame == "dq" and theta_e is None and layout.voltage_angle is None:
        raise ValueError(f"recording {p!r}: voltages in 'dq' need an angle column (theta_e or voltage_angle)")


def _column_indices(
    p: str,
    layout: RecordingLayout,
    header: list[str] | None,
    width: int,
    voltages: list[ColumnSpec],
    currents: list[ColumnSpec],
    theta_e: ColumnSpec | None,
    omega_e: ColumnSpec | None,
    time_column: ColumnSpec | None,
) -> dict[tuple[str, int], int]:
    """The file's column index of each (role, k) asked for: ``voltage``/``current`` k, ``theta``, ``omega``,
    ``vangle`` (the angle d-q voltages are turned by) and ``time``, each with k = 0."""
    idx: dict[tuple[str, int], int] = {}
    for role, cols in (("voltage", voltages), ("current", currents)):
        for k, c in enumerate(cols):
            idx[(role, k)] = column_index(c, header, width, p, "signal")
    if theta_e is not None:
        idx[("theta", 0)] = column_index(theta_e, header, width, p, "truth")
    if omega_e is not None:
        if theta_e is None:
            raise ValueError(f"recording {p!r}: omega_e needs theta_e (the encoder angle) beside it")
        idx[("omega", 0)] = column_index(omega_e, header, width, p, "truth")
    if layout.voltage_angle is not None:
        idx[("vangle", 0)] = column_index(layout.voltage_angle, header, width, p, "signal")
    elif layout.voltage_frame == "dq":
        idx[("vangle", 0)] = idx[("theta", 0)]
    if time_column is not None:
        idx[("time", 0)] = column_index(time_column, header, width, p, "time")
    return idx


def _columns_folder(
    folder: str | os.PathLike[str] | None,
) -> tuple[str | os.PathLike[str], tempfile.TemporaryDirectory[str] | None]:
    """(the folder the disk-backed columns go to, the temporary folder to remove with the log, or None)."""
    if folder is not None and not os.path.isdir(folder):
        raise ValueError(
            f"read_drive_log: folder {str(folder)!r} is not an existing folder (give one, or None for a temporary one)"
        )
    if folder is not None:
        return folder, None
    tmp = tempfile.TemporaryDirectory(prefix="jaxobs-log-")
    return tmp.name, tmp


def _check_finite(p: str, raw: dict[int, DiskColumn], wanted: list[int], rows: int, name: dict[int, str]) -> None:
    """Refuse the first non-finite value of the columns read, a chunk at a time."""
    for i in wanted:
        for sl in row_blocks(rows):
            bad = np.flatnonzero(~np.isfinite(raw[i][sl]))
            if bad.size:
                row = sl.start + bad[0] + 1
                raise ValueError(f"recording {p!r}: column {name[i]!r} is not finite at data row {row}")


def _time_base_of_column(
    p: str, tcol: DiskColumn, rows: int, tname: str, layout: RecordingLayout
) -> tuple[float, float]:
    """(sample interval, time of the first row), both in s, of a time column that must be strictly increasing,
    uniform and fast enough for a drive."""
    scale = UNITS["time"][layout.time_unit]
    first = float(tcol[0])
    dmin, dmax, step = math.inf, -math.inf, None
    for sl in row_blocks(rows):
        a = sl.start
        seg = np.asarray(tcol[max(a - 1, 0) : sl.stop])
        dt = np.diff(seg) * scale
        if dt.size and np.any(dt <= 0):
            r = int(np.flatnonzero(dt <= 0)[0]) + max(a - 1, 0)
            raise ValueError(
                f"recording {p!r}: the time column {tname!r} is not strictly increasing (data rows {r + 1}, {r + 2})"
            )
        if dt.size:
            step = float(np.median(dt)) if step is None else step
            dmin, dmax = min(dmin, float(dt.min())), max(dmax, float(dt.max()))
    assert step is not None  # rows >= 2: the first block has an interval
    if max(abs(dmax - step), abs(dmin - step)) > 1e-6 * step:
        raise ValueError(
            f"recording {p!r}: the time column {tname!r} is not uniform (intervals {dmin:.6g} "
            f"to {dmax:.6g} {'s' if scale == 1 else '× ' + layout.time_unit}): a long log must be "
            "uniformly sampled (resample it, or use jaxobs.DriveRecording.from_csv for a short one)"
        )
    ts = step
    if ts > 0.01 and layout.time_unit == "s":
        raise ValueError(
            f"recording {p!r}: the time column {tname!r} steps by {ts:g} s ({1 / ts:g} Hz), "
            "too slow for a drive's sampling: is it in ms or us? (declare time_unit)"
        )
    return ts, first * scale


def _time_base_of_rate(p: str, sample_rate: float) -> tuple[float, float]:
    """(sample interval, time of the first row = 0), both in s, of rows at ``sample_rate`` Hz."""
    rate = float(sample_rate)
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"recording {p!r}: sample_rate must be a number of Hz > 0, got {sample_rate!r}")
    return 1.0 / rate, 0.0


def _per_kind(kind: str, pole_pairs: int | None) -> int:
    """The factor from a ``kind`` angle or speed to the electrical one: the pole pairs for a mechanical one."""
    if kind != "mechanical":
        return 1
    assert pole_pairs is not None  # RecordingLayout refuses a mechanical kind without pole pairs
    return pole_pairs


class _Conversion:
    """The log's columns converted, a block at a time, into the observers' form (α-β amplitude-invariant, SI,
    electrical, the angle unwrapped across blocks, the voltage applied at t_k), written to disk-backed columns."""

    def __init__(
        self,
        raw: dict[int, DiskColumn],
        idx: dict[tuple[str, int], int],
        layout: RecordingLayout,
        folder: str | os.PathLike[str],
        n: int,
        shift: int,
    ) -> None:
        self.raw, self.idx, self.layout, self.folder, self.n, self.shift = raw, idx, layout, folder, n, shift
        self.wrapped_jumps: list[float] = []
        self.sum_sq = self.amp_sq = 0.0  # the three phase currents' summed squares, and the current's
        self.out: dict[str, DiskColumn] = {}
        self.th: DiskColumn | None = None
        self.om: DiskColumn | None = None

    def run(self, n_currents: int, n_voltages: int, has_theta: bool, has_omega: bool) -> None:
        """Convert every block of rows."""
        raw, idx, layout, folder, n, shift = self.raw, self.idx, self.layout, self.folder, self.n, self.shift
        out = {k: ColumnWriter(folder, k, n) for k in ("u_a", "u_b", "i_a", "i_b")}
        th = ColumnWriter(folder, "theta_e", n) if has_theta else None
        om = ColumnWriter(folder, "omega_e", n) if has_omega else None
        a_unit = UNITS["angle"][layout.angle_unit] * _per_kind(layout.angle_kind, layout.pole_pairs)
        s_unit = UNITS["speed"][layout.speed_unit] * _per_kind(layout.speed_kind, layout.pole_pairs)
        i_unit, v_unit = UNITS["current"][layout.current_unit], UNITS["voltage"][layout.voltage_unit]
        ab_scale = math.sqrt(2.0 / 3.0) if layout.alpha_beta_scaling == "power" else 1.0
        offset = 0.0  # the angle's unwrapping carried across blocks
        prev = None
        for sl in row_blocks(n):
            src = slice(sl.start + shift, sl.stop + shift)  # currents, angle and speed at t_k
            vsrc = slice(sl.start, sl.stop)  # the reference computed delay periods before
            cur = [np.asarray(raw[idx[("current", k)]][src]) * i_unit for k in range(n_currents)]
            vol = [np.asarray(raw[idx[("voltage", k)]][vsrc]) * v_unit for k in range(n_voltages)]
            ia, ib = _to_alpha_beta(cur, layout.current_frame, ab_scale)
            if len(cur) == 3:  # three measured phases: their sum is the sensors' error (no neutral current)
                self.sum_sq += float(np.sum((cur[0] + cur[1] + cur[2]) ** 2))
                self.amp_sq += float(np.sum(ia * ia + ib * ib))
            if layout.voltage_frame == "dq":
                ang = np.asarray(raw[idx[("vangle", 0)]][vsrc]) * a_unit
                c, s = np.cos(ang), np.sin(ang)
                ua, ub = vol[0] * c - vol[1] * s, vol[0] * s + vol[1] * c
            else:
                ua, ub = _to_alpha_beta(vol, layout.voltage_frame, ab_scale)
            out["i_a"][sl], out["i_b"][sl], out["u_a"][sl], out["u_b"][sl] = ia, ib, ua, ub
            if th is not None:
                x = np.asarray(raw[idx[("theta", 0)]][src]) * a_unit
                seq = x if prev is None else np.concatenate([[prev], x])
                d = np.diff(seq)
                self.wrapped_jumps.extend(d[np.abs(d) > math.pi].tolist()[:1000])
                u = np.unwrap(seq) + offset
                if prev is not None:
                    u = u[1:]
                th[sl] = u
                prev, offset = x[-1], u[-1] - x[-1]
            if om is not None:
                om[sl] = np.asarray(raw[idx[("omega", 0)]][src]) * s_unit
        self.out = {k: w.done() for k, w in out.items()}
        self.th = None if th is None else th.done()
        self.om = None if om is None else om.done()

    def check_phase_sum(self, p: str, name: dict[int, str]) -> None:
        """Refuse three phase currents that do not sum to zero (5 % of the current's amplitude)."""
        if self.amp_sq > 0 and math.sqrt(self.sum_sq / self.amp_sq) > 0.05:
            names = ", ".join(name[self.idx[("current", k)]] for k in range(3))
            raise ValueError(
                f"recording {p!r}: the three current columns {names!r} do not sum to zero (their sum is "
                f"{100 * math.sqrt(self.sum_sq / self.amp_sq):.3g} % of the current's amplitude)"
            )

    def columns(self) -> tuple[DiskColumn, DiskColumn, DiskColumn, DiskColumn, DiskColumn | None, DiskColumn | None]:
        """(u_a, u_b, i_a, i_b, theta_e or None, omega_e or None)."""
        o = self.out
        return o["u_a"], o["u_b"], o["i_a"], o["i_b"], self.th, self.om


def _run_checks(
    log: LogData,
    layout: RecordingLayout,
    machine: MachineConstants | None,
    cols: dict[str, str | None],
    wrapped_jumps: list[float],
    n_currents: int,
    n_voltages: int,
) -> None:
    """The log's consistency checks (the module doc lists them): errors raised, warnings appended to the log's."""
    check_angle_unit(log, layout, cols, wrapped_jumps)
    if log.theta_e is not None:
        check_speed(log, layout, cols)
        check_sequence(log, layout, cols)
        if machine is not None:
            check_power(log, machine, cols)
            check_timing(log, layout, machine, cols)
    check_balance(log, layout, cols, {"current": n_currents, "voltage": n_voltages})


def _to_alpha_beta(x, frame, ab_scale):
    """α-β (amplitude-invariant) of 2 or 3 phase columns, or of α-β columns scaled."""
    if frame == "alpha_beta":
        return x[0] * ab_scale, x[1] * ab_scale
    if len(x) == 2:  # c = −a − b
        a, b = x
        return a, (a + 2.0 * b) / math.sqrt(3.0)
    a, b, c = x
    return (2.0 * a - b - c) / 3.0, (b - c) / math.sqrt(3.0)
