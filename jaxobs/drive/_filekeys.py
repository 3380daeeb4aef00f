"""A drive file's keys: every table's keys with their types and ranges, and the check that reads a parsed file into
tables of known, in-range values (:mod:`jaxobs.drive.drivefile`)."""

from __future__ import annotations

import math
from typing import Any, NamedTuple

__all__ = ["DRIVE_FILE_KEYS", "PSI_F_KEYS", "TOP_KEYS", "KeySpec", "checked_tables", "key_value", "show"]

PSI_F_KEYS = ("psi_f", "ke_v_per_krpm_ll_rms", "ke_v_per_krpm_ll_peak", "kt_nm_per_a_rms")


class KeySpec(NamedTuple):
    """One key's type and range.

    Attributes:
        kind: "float", "int", "bool", "str" or "pair".
        lo: The least value (None: no range).
        hi: The largest value.
        lo_open: True: ``lo`` itself is refused.
        unit: The unit the messages print.
        required: True: the table must give it.
        choices: A "str" key's allowed values.
    """

    kind: str  # "float", "int", "bool", "str", "pair"
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    unit: str = ""
    required: bool = False
    choices: tuple[str, ...] = ()


_F, _I = "float", "int"
# every key of a drive file: table -> key -> its type and range (DriveFile's docs list them; the check prints them)
DRIVE_FILE_KEYS: dict[str, dict[str, KeySpec]] = {
    "machine": {
        "p": KeySpec(_I, 1, 100, unit="pole pairs", required=True),
        "Rs": KeySpec(_F, 0.0, 1e3, unit="Ω", required=True),
        "Ld": KeySpec(_F, 1e-8, 10.0, unit="H", required=True),
        "Lq": KeySpec(_F, 1e-8, 10.0, unit="H", required=True),
        # the magnet flux: psi_f, or one of the datasheet constants it is converted from (PSI_F_KEYS)
        "psi_f": KeySpec(_F, 1e-6, 100.0, unit="Wb"),
        "ke_v_per_krpm_ll_rms": KeySpec(_F, 1e-3, 1e6, unit="V/krpm"),
        "ke_v_per_krpm_ll_peak": KeySpec(_F, 1e-3, 1e6, unit="V/krpm"),
        "kt_nm_per_a_rms": KeySpec(_F, 1e-6, 1e4, unit="N·m/A"),
        "J": KeySpec(_F, 1e-10, 1e5, unit="kg·m²", required=True),
        "rated_speed_rpm": KeySpec(_F, 1.0, 1e6, unit="r/min", required=True),
        "rated_torque_nm": KeySpec(_F, 1e-6, 1e6, unit="N·m", required=True),
        "rated_current_a": KeySpec(_F, 1e-6, 1e5, unit="A rms", required=True),
        "max_speed_rpm": KeySpec(_F, 1.0, 1e6, unit="r/min"),
        "B": KeySpec(_F, 0.0, 1e3, unit="N·m·s/rad"),
        "a5": KeySpec(_F, 0.0, 1.0, unit="1"),
        "a7": KeySpec(_F, 0.0, 1.0, unit="1"),
        "q_sat_current_a": KeySpec(_F, 1e-6, 1e6, unit="A"),
        "q_sat_n": KeySpec(_F, 1.0, 16.0, unit="1"),
    },
    "inverter": {
        "u_dc": KeySpec(_F, 1.0, 1e5, unit="V", required=True),
        "f_sample_hz": KeySpec(_F, 100.0, 1e6, unit="Hz", required=True),
        "f_pwm_hz": KeySpec(_F, 100.0, 1e6, unit="Hz"),
        "sampling": KeySpec("str", choices=("start", "centre")),
        "compute_delay": KeySpec(_I, 0, 1, unit="periods"),
        "pwm": KeySpec("str", choices=("averaged", "carrier")),
        "device_drop_v": KeySpec(_F, 0.0, 100.0, unit="V"),
        "voltage_limit": KeySpec("str", choices=("circle", "hexagon")),
    },
    "control": {
        "current_bandwidth_hz": KeySpec(_F, 0.01, 1e5, unit="Hz"),
        "speed_bandwidth_hz": KeySpec(_F, 0.001, 1e4, unit="Hz"),
        "speed_estimate_hz": KeySpec(_F, 0.001, 1e4, unit="Hz"),
        "speed_every": KeySpec(_I, 1, 10_000, unit="periods"),
        "overload": KeySpec(_F, 1.0, 10.0, unit="1"),
        "i_max_a": KeySpec(_F, 1e-6, 1e6, unit="A"),
        "id_policy": KeySpec("str", choices=("zero", "mtpa")),
        "field_weakening": KeySpec("bool"),
        "fw_bandwidth_hz": KeySpec(_F, 0.01, 1e4, unit="Hz"),
        "fw_margin": KeySpec(_F, 0.5, 1.0, unit="1"),
        "current_margin": KeySpec("bool"),
        "speed_schedule": KeySpec(_F, 0.0, 1000.0, unit="1"),
        "setpoint_weight": KeySpec(_F, 0.0, 1.0, unit="1"),
        "advance": KeySpec(_F, 0.0, 3.0, unit="periods"),
    },
    "sensors": {
        "i_noise_a": KeySpec(_F, 0.0, 1e3, unit="A"),
        "u_noise_v": KeySpec(_F, 0.0, 1e4, unit="V"),
        "i_offset_a": KeySpec("pair", -1e3, 1e3, unit="A"),
        "u_offset_v": KeySpec("pair", -1e4, 1e4, unit="V"),
        "i_gain_error": KeySpec("pair", -0.5, 0.5, unit="1"),
        "adc_bits": KeySpec(_I, 6, 24, unit="bits"),
        "adc_range_a": KeySpec(_F, 1e-6, 1e6, unit="A"),
        "encoder_lines": KeySpec(_I, 1, 10_000_000, unit="lines/rev"),
    },
    "startup": {
        "current_a": KeySpec(_F, 1e-6, 1e6, unit="A"),
        "switch_rpm": KeySpec(_F, 0.01, 1e6, unit="r/min"),
        "hold_s": KeySpec(_F, 0.0, 60.0, unit="s"),
        "blend_s": KeySpec(_F, 0.0, 10.0, unit="s"),
        "dwell_s": KeySpec(_F, 1e-6, 10.0, unit="s"),
        "angle_tol_rad": KeySpec(_F, 1e-6, 3.14, unit="rad"),
        "speed_tol": KeySpec(_F, 1e-6, 1.0, unit="1"),
    },
    # a dual three-phase machine (jaxobs.drive._dualfile): the xy inductance and the current control's mode
    "dual": {
        "Lls": KeySpec(_F, 1e-8, 10.0, unit="H", required=True),
        "mode": KeySpec("str", choices=("vsd", "individual")),
        "fw_voltage": KeySpec("str", choices=("ab", "set")),
    },
}
TOP_KEYS = ("name", "description")


def _bounds(spec: KeySpec) -> tuple[float, float]:
    """(lo, hi) of a numeric key (every "float", "int" and "pair" key has both)."""
    return (-math.inf if spec.lo is None else spec.lo), (math.inf if spec.hi is None else spec.hi)


def key_value(table: dict[str, Any], tname: str, key: str, spec: KeySpec) -> Any:
    """One key's value, checked against its spec.

    Args:
        table: The table that holds the key.
        tname: The table's name (the messages name ``tname.key``).
        key: The key.
        spec: Its type and range.

    Returns:
        The value: a str, bool, int, float or a pair ``[float, float]``.

    Raises:
        ValueError: One line naming the key and its allowed range or choices.
    """
    field = f"{tname}.{key}"
    v = table[key]
    rng = ""
    if spec.lo is not None:
        rng = f"{'(' if spec.lo_open else '['}{spec.lo:g}, {spec.hi:g}]" + (f" {spec.unit}" if spec.unit else "")
    if spec.kind == "str":
        if v not in spec.choices:
            raise ValueError(f"{field} must be one of {', '.join(map(repr, spec.choices))}, got {show(v)}")
        return v
    if spec.kind == "bool":
        if not isinstance(v, bool):
            raise ValueError(f"{field} must be true or false, got {show(v)}")
        return v
    if spec.kind == "pair":
        if not (isinstance(v, list) and len(v) == 2):
            raise ValueError(f"{field} must be a pair [α, β] of numbers in {rng}, got {show(v)}")
        return [_number(x, f"{field}[{i}]", spec, rng) for i, x in enumerate(v)]
    if spec.kind == "int":
        lo, hi = _bounds(spec)
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            what = "a positive integer" if spec.lo == 1 else "an integer"
            raise ValueError(f"{field} must be {what} in {rng}, got {show(v)}")
        return int(v)
    return _number(v, field, spec, rng)


def _number(v: object, field: str, spec: KeySpec, rng: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"{field} must be a number in {rng}, got {show(v)}")
    x = float(v)
    lo, hi = _bounds(spec)
    ok = math.isfinite(x) and (x > lo if spec.lo_open else x >= lo) and x <= hi
    if not ok:
        raise ValueError(f"{field} must be in {rng}, got {show(v)}")
    return x


def show(v: object) -> str:
    """``repr(v)``, cut to 40 characters (a message quotes a value so).

    Args:
        v: The value.

    Returns:
        Its repr, at most 40 characters.
    """
    r = repr(v)
    return r if len(r) <= 40 else r[:39] + "…"


def checked_tables(raw: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The file's tables, every key known and in range.

    Args:
        raw: The parsed file (``tomllib`` output).

    Returns:
        table -> {key: value}.

    Raises:
        ValueError: One line naming the unknown, missing or out-of-range key.
    """
    for k, v in raw.items():
        if k in TOP_KEYS:
            if not isinstance(v, str) or len(v) > 200:
                raise ValueError(f"{k} must be a string of at most 200 characters, got {show(v)}")
            continue
        if k not in DRIVE_FILE_KEYS:
            raise ValueError(
                f"{k}: unknown table or key; allowed: {', '.join((*TOP_KEYS, *(f'[{t}]' for t in DRIVE_FILE_KEYS)))}"
            )
        if not isinstance(v, dict):
            raise ValueError(f"{k} must be a table ([{k}]), got {type(v).__name__}")
    out: dict[str, dict[str, Any]] = {}
    for tname, keys in DRIVE_FILE_KEYS.items():
        table = raw.get(tname, {})
        for k in table:
            if k not in keys:
                near = ", ".join(keys)
                raise ValueError(f"{tname}.{k}: unknown key; allowed: {near}"[:300])
        for k, spec in keys.items():
            if spec.required and k not in table and (tname in raw or tname != "dual"):  # [dual]: when present
                raise ValueError(f"{tname}.{k}: missing (required)")
        out[tname] = {k: key_value(table, tname, k, keys[k]) for k in table}
    return out
