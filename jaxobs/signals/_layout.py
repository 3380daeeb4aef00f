"""The declared layout of a drive log: what its columns hold (frames, timing, units, kinds), how its text is
delimited, and the warning its checks raise (:mod:`jaxobs.signals._logs` reads a log by it).
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

from ..io.provenance import read_file
from ..io.safetoml import read_toml

ColumnSpec = str | int  # a column of a file, by its header name or 0-based index

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
ZERO_SEQUENCES = ("unknown", "none")  # what two phase voltages may leave out

MAX_SIDECAR_BYTES = 64 * 2**10


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
        voltage_zero_sequence: ``"none"``: the phase voltages carry no zero sequence, so two ``"abc"`` voltage
            columns give the third as −a − b; ``"unknown"`` (the default): two ``"abc"`` voltage columns are refused
            (a min-max or space-vector reference carries a zero sequence, and −a − b would be wrong).
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
    voltage_angle: ColumnSpec | None = None
    current_unit: str = "A"
    voltage_unit: str = "V"
    angle_unit: str = "rad"
    angle_kind: str = "electrical"
    speed_unit: str = "rad/s"
    speed_kind: str = "electrical"
    time_unit: str = "s"
    pole_pairs: int | None = None
    voltage_zero_sequence: str = "unknown"
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
        _choice("voltage_zero_sequence", self.voltage_zero_sequence, ZERO_SEQUENCES)
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

        Args:
            table: The table: field names of :class:`RecordingLayout` to their values.
            where: The table's name in the messages.

        Returns:
            The :class:`RecordingLayout`.

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
    def sidecar(cls, csv_path: str | os.PathLike[str]) -> RecordingLayout | None:
        """The layout declared beside a CSV file, in ``<file>.toml`` (``log.csv`` → ``log.csv.toml``, table
        ``[layout]``), or None where there is none.

        Args:
            csv_path: The CSV file.

        Returns:
            The declared :class:`RecordingLayout`, or None (no sidecar).

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
