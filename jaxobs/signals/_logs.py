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
import re
import stat
import tempfile
import warnings
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ..io.provenance import read_file
from ..io.safetoml import read_toml
from ._logchecks import check_angle_unit, check_balance, check_power, check_sequence, check_speed, check_timing
from ._recordings import DriveRecording, _column

# --------------------------------------------------------------------------------------------------------------
# the layout
# --------------------------------------------------------------------------------------------------------------

UNITS = {
    "current": {"A": 1.0, "mA": 1e-3},
    "voltage": {"V": 1.0, "mV": 1e-3, "kV": 1e3},
    "angle": {"rad": 1.0, "deg": math.pi / 180.0},
    "speed": {"rad/s": 1.0, "r/min": 2.0 * math.pi / 60.0, "Hz": 2.0 * math.pi},
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6},
}
KINDS = ("electrical", "mechanical")
CURRENT_FRAMES = ("alpha_beta", "abc")
VOLTAGE_FRAMES = ("alpha_beta", "abc", "dq")
TIMINGS = ("applied", "reference")
SCALINGS = ("amplitude", "power")
DELIMITERS = {",": ",", ";": ";", "tab": "\t", "\t": "\t", "space": r"\s+", " ": r"\s+"}
DECIMALS = (".", ",")

MAX_LOG_BYTES = 8 * 2**30  # a log file larger than this is refused (10^7 rows of 10 columns is about 1 GiB)
MAX_SIDECAR_BYTES = 64 * 2**10
CHUNK_ROWS = 500_000  # rows parsed at a time: the read's memory is a chunk, whatever the file's length


class RecordingWarning(UserWarning):
    """A defect of a recording that does not make its estimates wrong (an offset, a gain mismatch)."""


def _choice(name, value, allowed):
    if not isinstance(value, str) or value not in allowed:
        raise ValueError(f"RecordingLayout.{name} must be one of {', '.join(map(repr, allowed))}, got {value!r}")
    return value


@dataclasses.dataclass(frozen=True)
class RecordingLayout:
    """What the columns of a drive log hold.  The defaults are the observers' own form, so a file written
    in it needs no declaration.

    Args:
        current_frame: ``"alpha_beta"`` (i_α, i_β) or ``"abc"`` (phase currents; two columns a, b with
            c = −a − b, or three, whose sum is checked).
        voltage_frame: ``"alpha_beta"``, ``"abc"`` (phase-to-neutral voltages, two or three columns) or
            ``"dq"`` (rotor frame: turned to α-β by ``voltage_angle``).
        alpha_beta_scaling: ``"amplitude"`` (the Clarke transform that keeps the phase amplitude: the
            observers' form) or ``"power"`` (√(3/2) times larger), for α-β columns.
        voltage_timing: ``"applied"`` (a row's voltage is the one applied over [t_k, t_k+1]) or
            ``"reference"`` (the controller's reference computed at t_k, applied ``voltage_delay`` periods
            later; the first ``voltage_delay`` rows are then dropped, their applied voltage being unknown).
        voltage_delay: periods from a reference to its application, 1 to 4 (one: computed at t_k and
            loaded into the PWM at t_k+1, the usual single-update timing).
        voltage_angle: the column of the angle a ``"dq"`` voltage is turned by (in the angle's unit and
            kind); default the truth angle column.
        current_unit: the currents' unit, a key of :data:`UNITS`.
        voltage_unit: the voltages' unit, a key of :data:`UNITS`.
        angle_unit: the angle's unit, a key of :data:`UNITS`.
        angle_kind: ``"electrical"`` or ``"mechanical"`` (needs ``pole_pairs``), for the angle.
        speed_unit: the speed's unit, a key of :data:`UNITS`.
        speed_kind: ``"electrical"`` or ``"mechanical"`` (needs ``pole_pairs``), for the speed.
        time_unit: the time column's unit, a key of :data:`UNITS`.
        pole_pairs: the machine's pole pairs, for mechanical angles or speeds.
        delimiter: ``","``, ``";"``, ``"tab"`` or ``"space"``.
        decimal: ``"."`` or ``","`` (a decimal comma needs another delimiter).

    Raises:
        ValueError: a value outside its choices, naming the field.
    """

    current_frame: str = "alpha_beta"
    voltage_frame: str = "alpha_beta"
    alpha_beta_scaling: str = "amplitude"
    voltage_timing: str = "applied"
    voltage_delay: int = 1
    voltage_angle: str | int | None = None
    current_unit: str = "A"
    voltage_unit: str = "V"
    angle_unit: str = "rad"
    angle_kind: str = "electrical"
    speed_unit: str = "rad/s"
    speed_kind: str = "electrical"
    time_unit: str = "s"
    pole_pairs: int | None = None
    delimiter: str = ","
    decimal: str = "."

    def __post_init__(self):
        _choice("current_frame", self.current_frame, CURRENT_FRAMES)
        _choice("voltage_frame", self.voltage_frame, VOLTAGE_FRAMES)
        _choice("alpha_beta_scaling", self.alpha_beta_scaling, SCALINGS)
        _choice("voltage_timing", self.voltage_timing, TIMINGS)
        for q in ("current", "voltage", "angle", "speed", "time"):
            _choice(f"{q}_unit", getattr(self, f"{q}_unit"), tuple(UNITS[q]))
        _choice("angle_kind", self.angle_kind, KINDS)
        _choice("speed_kind", self.speed_kind, KINDS)
        _choice("delimiter", self.delimiter, tuple(DELIMITERS))
        _choice("decimal", self.decimal, DECIMALS)
        d = self.voltage_delay
        if isinstance(d, bool) or not isinstance(d, int) or not 1 <= d <= 4:
            raise ValueError(f"RecordingLayout.voltage_delay must be an integer number of periods in 1..4, got {d!r}")
        p = self.pole_pairs
        if p is not None and (isinstance(p, bool) or not isinstance(p, int) or not 1 <= p <= 100):
            raise ValueError(f"RecordingLayout.pole_pairs must be an integer in 1..100, got {p!r}")
        if p is None and "mechanical" in (self.angle_kind, self.speed_kind):
            which = "angle_kind" if self.angle_kind == "mechanical" else "speed_kind"
            raise ValueError(f"RecordingLayout.{which} = 'mechanical' needs pole_pairs (the machine's pole pairs)")
        if self.decimal == "," and DELIMITERS[self.delimiter] == ",":
            raise ValueError("RecordingLayout.decimal ',' needs another delimiter (';', 'tab' or 'space'), got ','")
        v = self.voltage_angle
        if v is not None and (isinstance(v, bool) or not isinstance(v, (str, int))):
            raise ValueError(f"RecordingLayout.voltage_angle must be a column name or index, got {v!r}")

    @classmethod
    def from_table(cls, table: dict, where: str = "layout") -> RecordingLayout:
        """A layout from a TOML table (a job's ``[scenarios.recording.layout]`` or a sidecar's ``[layout]``).

        Raises:
            ValueError: an unknown key or a bad value, naming ``<where>.<key>``.
        """
        if not isinstance(table, dict):
            raise ValueError(f"{where} must be a table, got {type(table).__name__}")
        known = {f.name for f in dataclasses.fields(cls)}
        for k in table:
            if k not in known:
                raise ValueError(f"{where}.{k}: unknown key; known: {', '.join(sorted(known))}")
        try:
            return cls(**table)
        except ValueError as e:
            raise ValueError(str(e).replace("RecordingLayout.", f"{where}.")) from None

    @classmethod
    def sidecar(cls, csv_path) -> RecordingLayout | None:
        """The layout declared beside a CSV file, in ``<file>.toml`` (``log.csv`` → ``log.csv.toml``, table
        ``[layout]``), or None where there is none.

        Raises:
            ValueError: an unreadable sidecar, or a bad key in it.
        """
        side = Path(str(csv_path) + ".toml")
        if not side.exists():
            return None
        try:  # the size first (a sidecar is a few lines), then TOML read safely: nesting, number lengths, UTF-8
            read_file(side, MAX_SIDECAR_BYTES)
            doc, _ = read_toml(side, "file")
        except ValueError as e:
            raise ValueError(f"recording sidecar {str(side)!r}: {e}") from None
        extra = set(doc) - {"layout"}
        if extra:
            raise ValueError(f"recording sidecar {str(side)!r}: unknown table(s) {sorted(extra)}; only [layout]")
        return cls.from_table(doc.get("layout", {}), where=f"{side.name}: layout")


# --------------------------------------------------------------------------------------------------------------
# streaming CSV reading
# --------------------------------------------------------------------------------------------------------------

_NUM = re.compile(r"\s*[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|nan|inf|infinity)\s*", re.I | re.ASCII)


def _open_regular(path, max_bytes):
    p = os.fspath(path)
    shown = repr(p)
    try:
        st = os.stat(p)
    except OSError as e:
        if not os.path.lexists(p):
            raise FileNotFoundError(f"recording {shown}: no such file") from None
        raise ValueError(f"recording {shown}: cannot read it ({e.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"recording {shown}: not a file (only regular files are read: no FIFO, device or folder)")
    if st.st_size > max_bytes:
        raise ValueError(f"recording {shown}: {st.st_size} bytes, more than the limit of {max_bytes} bytes")
    return p


def _first_lines(path, k=3):
    """The first k non-blank, non-comment lines (line number, text)."""
    out = []
    with open(path, "rb") as f:
        for n, raw in enumerate(f, 1):
            try:
                # a UTF-8 byte-order mark (spreadsheet exports write one) is no part of the first column's name
                ln = raw.decode("utf-8-sig" if n == 1 else "utf-8")
            except UnicodeDecodeError:
                raise ValueError(f"recording {str(path)!r}: line {n}: not UTF-8 text") from None
            if ln.strip() and not ln.lstrip().startswith("#"):
                out.append((n, ln.rstrip("\r\n")))
                if len(out) == k:
                    break
    if not out:
        raise ValueError(f"recording {str(path)!r}: no data rows")
    return out


def _split(line, layout):
    sep = DELIMITERS[layout.delimiter]
    return re.split(sep, line.strip()) if sep == r"\s+" else line.split(sep)


def _is_number(field, decimal):
    f = field.strip()
    if decimal == ",":
        f = f.replace(",", ".")
    return bool(_NUM.fullmatch(f))


def _hint(lines, layout):
    """Why the first data line does not parse: a delimiter or decimal mark other than declared."""
    text = lines[-1][1]
    if layout.delimiter != ";" and text.count(";") >= 1 and len(_split(text, layout)) <= 1 + text.count(";") // 2:
        return "; the file seems to use ';' as its delimiter (declare delimiter = ';')"
    if layout.decimal == "." and re.search(r"\d,\d", text) and DELIMITERS[layout.delimiter] != ",":
        return "; the file seems to use decimal commas (declare decimal = ',')"
    if layout.decimal == "." and re.search(r"\d,\d", text) and ";" in text:
        return "; the file seems to use ';' and decimal commas (declare delimiter = ';', decimal = ',')"
    if "\t" in text and layout.delimiter != "tab":
        return "; the file seems to be tab-separated (declare delimiter = 'tab')"
    return ""


def _header(path, layout):
    lines = _first_lines(path)
    first = _split(lines[0][1], layout)
    if all(_is_number(x, layout.decimal) for x in first):
        return None, lines
    header = [x.strip() for x in first]
    if len(set(header)) != len(header):
        raise ValueError(f"recording {str(path)!r}: the header repeats a column name: {header}")
    if len(lines) > 1:
        row = _split(lines[1][1], layout)
        if len(row) != len(header) or not all(_is_number(x, layout.decimal) for x in row):
            n = lines[1][0]
            why = _hint(lines[:2], layout) or f" (the header has {len(header)} columns, the line {len(row)} fields)"
            raise ValueError(f"recording {str(path)!r}: line {n} holds a field that is not a number{why}")
    return header, lines


def _locate_bad_line(path, layout, width, skip_header):
    """The first data line that is not ``width`` numbers (called only after a failed parse)."""
    with open(path, encoding="utf-8-sig", errors="replace") as f:
        seen_header = not skip_header
        for n, ln in enumerate(f, 1):
            if not ln.strip() or ln.lstrip().startswith("#"):
                continue
            if not seen_header:
                seen_header = True
                continue
            row = _split(ln.rstrip("\r\n"), layout)
            if len(row) != width:
                return f"line {n} has {len(row)} fields, the file {width}"
            if not all(_is_number(x, layout.decimal) for x in row):
                return f"line {n} holds a field that is not a number"
    return "a line could not be read"


def _check_last_line(path):
    """Refuse a file that does not end with a line end: a copy cut short ends inside its last line, and a value cut
    inside a field (``187.84`` read as ``187``) cannot be told from a whole one, so the line is named and the file
    refused rather than read.  Every CSV writer of numpy, pandas, MATLAB and spreadsheets ends its last line."""
    size = os.path.getsize(path)
    if size == 0:
        return
    with open(path, "rb") as f:
        f.seek(size - 1)
        if f.read(1) in (b"\n", b"\r"):
            return
        f.seek(0)
        n = sum(block.count(b"\n") for block in iter(lambda: f.read(1 << 20), b"")) + 1
    raise ValueError(
        f"recording {str(path)!r}: line {n}, the last, has no line end: the file may be cut short inside it (copy "
        "it again; if the line is whole, end it with a line end)"
    )


def _pandas_precision():
    """The float Python's float() reads, so that a log gives the small reader's numbers to the last bit: pandas
    parses so by default from 3.0 on (and warns of the option), before that with float_precision="round_trip"."""
    import pandas as pd

    return {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}


_PRECISION: dict = {}


def _stream_columns(path, layout, header, wanted: list[int], width: int, folder):
    """Parse the file in chunks of :data:`CHUNK_ROWS` rows into one disk-backed float64 column per wanted index.

    Returns (dict index → a column read a block at a time, rows).  Each chunk is written to the columns' files as
    it is parsed, so the process holds one chunk at a time.
    """
    import pandas as pd

    _PRECISION.update(_pandas_precision())
    files = {i: open(os.path.join(folder, f"c{i}.f8"), "wb") for i in wanted}
    rows = 0
    sep = DELIMITERS[layout.delimiter]
    try:
        reader = pd.read_csv(
            path,
            sep=sep,
            decimal=layout.decimal,
            comment="#",
            header=0 if header is not None else None,
            usecols=wanted,
            dtype=np.float64,
            chunksize=CHUNK_ROWS,
            **_PRECISION,
            skip_blank_lines=True,
            engine="c" if sep != r"\s+" else "python",
            names=None,
        )
        for chunk in reader:
            arr = chunk.to_numpy(dtype=np.float64)
            cols = list(chunk.columns)
            for i in wanted:
                pos = cols.index(header[i]) if header is not None else cols.index(i)
                files[i].write(np.ascontiguousarray(arr[:, pos]).tobytes())
            rows += arr.shape[0]
            del arr, chunk
    except (ValueError, pd.errors.ParserError):
        raise ValueError(
            f"recording {str(path)!r}: {_locate_bad_line(path, layout, width, header is not None)}"
        ) from None
    finally:
        for f in files.values():
            f.close()
    out = {}
    for i in wanted:
        fn = os.path.join(folder, f"c{i}.f8")
        out[i] = _Column(fn, rows)
    return out, rows


# --------------------------------------------------------------------------------------------------------------
# the log, converted
# --------------------------------------------------------------------------------------------------------------


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

    u_a: _Column
    u_b: _Column
    i_a: _Column
    i_b: _Column
    theta_e: _Column | None
    omega_e: _Column | None
    ts: float
    t0: float
    path: str
    warnings: list[str]
    _folder: object = dataclasses.field(default=None, repr=False)

    @property
    def n(self) -> int:
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


def _col_index(spec, header, width, path, role):
    return _column(spec, header, width, path, role)


class _Column:
    """A float64 column on disk, read a block at a time (``col[a:b]``, np.fromfile) or whole (``np.asarray(col)``).

    Not a memory map: a mapped window faults in the pages around it (the kernel's read-ahead), which over a
    10^7-row log's 96 check windows kept 264 MiB resident; a read keeps only what it returns.
    """

    def __init__(self, fn, n):
        self.fn, self.n = fn, n

    @property
    def shape(self):
        return (self.n,)

    def __len__(self):
        return self.n

    def __array__(self, dtype=None, copy=None):
        a = self[0 : self.n]
        return a if dtype is None else a.astype(dtype)

    def __getitem__(self, sl: slice | int):
        if not isinstance(sl, slice):
            return float(self[slice(int(sl), int(sl) + 1)][0])
        a, b = max(sl.start or 0, 0), min(self.n if sl.stop is None else sl.stop, self.n)
        with open(self.fn, "rb") as f:
            return np.fromfile(f, dtype=np.float64, count=max(b - a, 0), offset=8 * a)


class _Writer:
    """A float64 column written block after block, then read back as a :class:`_Column`."""

    def __init__(self, folder, name, n):
        self.fn, self.n = os.path.join(folder, name + ".f8"), n
        self.f = open(self.fn, "wb")

    def __setitem__(self, sl, x):
        self.f.write(np.ascontiguousarray(x, dtype=np.float64).tobytes())

    def done(self):
        self.f.close()
        return _Column(self.fn, self.n)


def _out(folder, name, n):
    return _Writer(folder, name, n)


def _blocks(n, size=CHUNK_ROWS):
    for a in range(0, n, size):
        yield slice(a, min(a + size, n))


def read_drive_log(
    path,
    *,
    voltages=("u_a", "u_b"),
    currents=("i_a", "i_b"),
    theta_e="theta_e",
    omega_e=None,
    time_column=None,
    sample_rate=None,
    layout: RecordingLayout | None = None,
    machine=None,
    max_bytes: int | None = None,
    folder=None,
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
    p = _open_regular(path, MAX_LOG_BYTES if max_bytes is None else int(max_bytes))
    if layout is None:
        layout = RecordingLayout.sidecar(p) or RecordingLayout()
    if not isinstance(layout, RecordingLayout):
        raise ValueError(f"read_drive_log: layout must be a RecordingLayout, got {type(layout).__name__}")
    voltages, currents = list(voltages), list(currents)
    if layout.voltage_frame == "dq" and len(voltages) != 2:
        raise ValueError(f"recording {p!r}: voltages in 'dq' are 2 columns (u_d, u_q), got {len(voltages)}")
    for role, cols, frame in (("voltage", voltages, layout.voltage_frame), ("current", currents, layout.current_frame)):
        allowed = (2, 3) if frame == "abc" else (2,)
        if len(cols) not in allowed:
            raise ValueError(
                f"recording {p!r}: {role} columns in {frame!r} are {' or '.join(map(str, allowed))}, got {len(cols)}"
            )
    if (time_column is None) == (sample_rate is None):
        raise ValueError(f"recording {p!r}: give exactly one of time_column and sample_rate")
    if layout.voltage_frame == "dq" and theta_e is None and layout.voltage_angle is None:
        raise ValueError(f"recording {p!r}: voltages in 'dq' need an angle column (theta_e or voltage_angle)")

    header, lines = _header(p, layout)
    width = len(header) if header is not None else len(_split(lines[0][1], layout))
    idx = {}
    for role, cols in (("voltage", voltages), ("current", currents)):
        for k, c in enumerate(cols):
            idx[(role, k)] = _col_index(c, header, width, p, "signal")
    if theta_e is not None:
        idx[("theta", 0)] = _col_index(theta_e, header, width, p, "truth")
    if omega_e is not None:
        if theta_e is None:
            raise ValueError(f"recording {p!r}: omega_e needs theta_e (the encoder angle) beside it")
        idx[("omega", 0)] = _col_index(omega_e, header, width, p, "truth")
    if layout.voltage_angle is not None:
        idx[("vangle", 0)] = _col_index(layout.voltage_angle, header, width, p, "signal")
    elif layout.voltage_frame == "dq":
        idx[("vangle", 0)] = idx[("theta", 0)]
    if time_column is not None:
        idx[("time", 0)] = _col_index(time_column, header, width, p, "time")
    wanted = sorted(set(idx.values()))

    tmp = None
    if folder is not None and not os.path.isdir(folder):
        raise ValueError(
            f"read_drive_log: folder {str(folder)!r} is not an existing folder (give one, or None for a temporary one)"
        )
    if folder is None:
        tmp = tempfile.TemporaryDirectory(prefix="jaxobs-log-")
        folder = tmp.name
    _check_last_line(p)
    raw, rows = _stream_columns(p, layout, header, wanted, width, folder)
    if rows < 2 + (layout.voltage_delay if layout.voltage_timing == "reference" else 0):
        raise ValueError(f"recording {p!r}: {rows} sample(s); too few")
    name = {i: (header[i] if header else str(i)) for i in range(width)}
    for i in wanted:  # finiteness, a chunk at a time
        for sl in _blocks(rows):
            bad = np.flatnonzero(~np.isfinite(raw[i][sl]))
            if bad.size:
                row = sl.start + bad[0] + 1
                raise ValueError(f"recording {p!r}: column {name[i]!r} is not finite at data row {row}")

    # the time base
    if time_column is not None:
        tcol = raw[idx[("time", 0)]]
        scale = UNITS["time"][layout.time_unit]
        first = float(tcol[0])
        dmin, dmax, step = math.inf, -math.inf, None
        for sl in _blocks(rows):
            a = sl.start
            seg = np.asarray(tcol[max(a - 1, 0) : sl.stop])
            dt = np.diff(seg) * scale
            if dt.size and np.any(dt <= 0):
                r = int(np.flatnonzero(dt <= 0)[0]) + max(a - 1, 0)
                raise ValueError(
                    f"recording {p!r}: the time column {name[idx[('time', 0)]]!r} is not strictly increasing "
                    f"(data rows {r + 1}, {r + 2})"
                )
            if dt.size:
                step = float(np.median(dt)) if step is None else step
                dmin, dmax = min(dmin, float(dt.min())), max(dmax, float(dt.max()))
        if max(abs(dmax - step), abs(dmin - step)) > 1e-6 * step:
            raise ValueError(
                f"recording {p!r}: the time column {name[idx[('time', 0)]]!r} is not uniform (intervals {dmin:.6g} "
                f"to {dmax:.6g} {'s' if scale == 1 else '× ' + layout.time_unit}): a long log must be "
                "uniformly sampled (resample it, or use jaxobs.DriveRecording.from_csv for a short one)"
            )
        ts = step
        if ts > 0.01 and layout.time_unit == "s":
            raise ValueError(
                f"recording {p!r}: the time column {name[idx[('time', 0)]]!r} steps by {ts:g} s ({1 / ts:g} Hz), "
                "too slow for a drive's sampling: is it in ms or us? (declare time_unit)"
            )
        t_first = first * scale
    else:
        rate = float(sample_rate)
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError(f"recording {p!r}: sample_rate must be a number of Hz > 0, got {sample_rate!r}")
        ts, t_first = 1.0 / rate, 0.0

    # the conversion, a block at a time, into the output columns
    shift = layout.voltage_delay if layout.voltage_timing == "reference" else 0
    n = rows - shift
    out = {k: _out(folder, k, n) for k in ("u_a", "u_b", "i_a", "i_b")}
    th = _out(folder, "theta_e", n) if theta_e is not None else None
    om = _out(folder, "omega_e", n) if omega_e is not None else None
    a_unit = UNITS["angle"][layout.angle_unit] * (layout.pole_pairs if layout.angle_kind == "mechanical" else 1)
    s_unit = UNITS["speed"][layout.speed_unit] * (layout.pole_pairs if layout.speed_kind == "mechanical" else 1)
    i_unit, v_unit = UNITS["current"][layout.current_unit], UNITS["voltage"][layout.voltage_unit]
    ab_scale = math.sqrt(2.0 / 3.0) if layout.alpha_beta_scaling == "power" else 1.0
    wrapped_jumps = []
    offset = 0.0  # the angle's unwrapping carried across blocks
    prev = None
    sum_sq = amp_sq = 0.0
    for sl in _blocks(n):
        src = slice(sl.start + shift, sl.stop + shift)  # currents, angle and speed at t_k
        vsrc = slice(sl.start, sl.stop)  # the reference computed delay periods before
        cur = [np.asarray(raw[idx[("current", k)]][src]) * i_unit for k in range(len(currents))]
        vol = [np.asarray(raw[idx[("voltage", k)]][vsrc]) * v_unit for k in range(len(voltages))]
        ia, ib = _to_alpha_beta(cur, layout.current_frame, ab_scale)
        if len(cur) == 3:  # three measured phases: their sum is the sensors' error (no neutral current)
            sum_sq += float(np.sum((cur[0] + cur[1] + cur[2]) ** 2))
            amp_sq += float(np.sum(ia * ia + ib * ib))
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
            wrapped_jumps.extend(d[np.abs(d) > math.pi].tolist()[:1000])
            u = np.unwrap(seq) + offset
            if prev is not None:
                u = u[1:]
            th[sl] = u
            prev, offset = x[-1], u[-1] - x[-1]
        if om is not None:
            om[sl] = np.asarray(raw[idx[("omega", 0)]][src]) * s_unit
    out = {k: w.done() for k, w in out.items()}
    th = None if th is None else th.done()
    om = None if om is None else om.done()
    if amp_sq > 0 and math.sqrt(sum_sq / amp_sq) > 0.05:
        raise ValueError(
            f"recording {p!r}: the three current columns {', '.join(name[idx[('current', k)]] for k in range(3))!r} "
            f"do not sum to zero (their sum is {100 * math.sqrt(sum_sq / amp_sq):.3g} % of the current's amplitude)"
        )
    del raw
    warn: list[str] = []
    log = LogData(
        out["u_a"], out["u_b"], out["i_a"], out["i_b"], th, om, ts, t_first + shift * ts, p, warn, _folder=tmp
    )
    cols = {
        "theta": name.get(idx.get(("theta", 0))),
        "omega": name.get(idx.get(("omega", 0))),
        "voltage": ", ".join(name[idx[("voltage", k)]] for k in range(len(voltages))),
        "current": ", ".join(name[idx[("current", k)]] for k in range(len(currents))),
    }
    check_angle_unit(log, layout, cols, wrapped_jumps)
    if log.theta_e is not None:
        check_speed(log, layout, cols)
        check_sequence(log, layout, cols)
        if machine is not None:
            check_power(log, machine, cols)
            check_timing(log, layout, machine, cols)
    check_balance(log, layout, cols, {"current": len(currents), "voltage": len(voltages)})
    for w in warn:
        warnings.warn(RecordingWarning(w), stacklevel=2)
    return log


def _to_alpha_beta(x, frame, ab_scale):
    """α-β (amplitude-invariant) of 2 or 3 phase columns, or of α-β columns scaled."""
    if frame == "alpha_beta":
        return x[0] * ab_scale, x[1] * ab_scale
    if len(x) == 2:  # c = −a − b
        a, b = x
        return a, (a + 2.0 * b) / math.sqrt(3.0)
    a, b, c = x
    return (2.0 * a - b - c) / 3.0, (b - c) / math.sqrt(3.0)
