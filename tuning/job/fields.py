"""Job-file fields: :class:`JobError` (one line naming the field) and the typed, range-checked getters."""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from typing import Any, Literal, TypeVar, overload

from jaxobs.scenarios.families import AbstractFamily

T = TypeVar("T")


class JobError(ValueError):
    """A problem with a job file; ``str()`` is one line naming the field, at most :data:`MAX_ERROR` characters.

    Args:
        field: The field, as the job file spells its path (``drive.start``).
        message: What is wrong, and the allowed range.
    """

    def __init__(self, field: str, message: str):
        self.field = field
        field = cap(field, 80)
        line = " ".join(f"{field}: {message}".split())  # one line, whatever the message holds
        super().__init__(cap(line, MAX_ERROR))


# characters in a job-file error: a bound on what a hostile file can make the tool print, far above any message
# the library writes (their quoted values are cut by show() and cap() to 40-100 characters), so that no message is
# cut before its remedy
MAX_ERROR = 1000


MAX_STEPS = 10_000_000  # time steps of one simulation (horizon / ts)


MAX_SCENARIOS = 1_000_000  # scenarios of a grid or of `sample`


MAX_INT = 2**63 - 1


MAX_SOLVER_STEPS = 1_000_000


def cap(text: str, n: int) -> str:
    """Text cut to ``n`` characters, its last one an ellipsis where it was longer.

    Args:
        text: The text.
        n: The most characters kept.

    Returns:
        ``text``, or its first ``n - 1`` characters and "…".
    """
    return text if len(text) <= n else text[: n - 1] + "…"


def show(v: object) -> str:
    """A value for an error message: its repr, long ones elided.

    Args:
        v: The value.

    Returns:
        Its repr (a list or table of more than 8 items by its type and length), at most 60 characters.
    """
    if isinstance(v, int) and not isinstance(v, bool) and abs(v) > 10**20:
        return f"an integer of {len(str(abs(v)))} digits"
    try:
        r = repr(v) if not isinstance(v, (list, dict)) or len(v) <= 8 else f"{type(v).__name__} of {len(v)}"
    except (RecursionError, ValueError):
        r = type(v).__name__
    return cap(r, 60)


@overload
def get_field(table: Mapping, key: str, field: str, kind: type[T], default: T, required: bool = False) -> T: ...


@overload
def get_field(
    table: Mapping, key: str, field: str, kind: type[T], default: None = None, *, required: Literal[True]
) -> T: ...


@overload
def get_field(
    table: Mapping, key: str, field: str, kind: type[T], default: None = None, required: bool = False
) -> T | None: ...


def get_field(
    table: Mapping, key: str, field: str, kind: type[Any], default: Any = None, required: bool = False
) -> Any:
    """A key of a TOML table, checked as ``kind``.

    Args:
        table: The table.
        key: The key.
        field: The key's path in errors (``drive.start``).
        kind: ``float`` (a finite number, as a float), ``int`` (within ±(2^63 - 1)), ``bool``, ``str``, ``list``
            (a non-empty list of finite numbers, as floats) or ``dict`` (a table).
        default: The value without the key.
        required: Refuse a missing key.

    Returns:
        The checked value, or ``default``.

    Raises:
        JobError: A missing required key, or a value of another kind, naming ``field``.
    """
    if key not in table:
        if required:
            raise JobError(field, "missing (required)")
        return default
    v = table[key]
    if kind is float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise JobError(field, f"must be a number, got {type(v).__name__} {show(v)}")
        return finite(v, field)
    if kind is int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise JobError(field, f"must be an integer, got {type(v).__name__} {show(v)}")
        if abs(v) > MAX_INT:
            raise JobError(field, f"out of range (|value| <= 2^63 - 1), got {show(v)}")
        return v
    if kind is bool:
        if not isinstance(v, bool):
            raise JobError(field, f"must be true or false, got {show(v)}")
        return v
    if kind is str:
        if not isinstance(v, str):
            raise JobError(field, f"must be a string, got {type(v).__name__} {show(v)}")
        return v
    if kind is list:
        if not isinstance(v, list) or not v:
            raise JobError(field, f"must be a non-empty list of numbers, got {show(v)}")
        if len(v) > MAX_SCENARIOS:
            raise JobError(field, f"too many values ({len(v)} > {MAX_SCENARIOS})")
        for i, x in enumerate(v):
            if isinstance(x, bool) or not isinstance(x, (int, float)):
                raise JobError(f"{field}[{i}]", f"must be a finite number, got {type(x).__name__} {show(x)}")
            finite(x, f"{field}[{i}]")
        return [float(x) for x in v]
    if kind is dict:
        if not isinstance(v, dict):
            raise JobError(field, f"must be a table, got {type(v).__name__}")
        return v
    raise AssertionError(kind)


def finite(v: float, field: str) -> float:
    """A value as a finite float.

    Args:
        v: The value.
        field: The field's name in errors.

    Returns:
        ``v`` as a float.

    Raises:
        JobError: An integer beyond the float range (10^309), or NaN / inf.
    """
    try:
        f = float(v)
    except OverflowError:
        raise JobError(field, f"out of the float range, got {show(v)}") from None
    if not math.isfinite(f):
        raise JobError(field, f"must be finite, got {show(v)}")
    return f


def no_unknown(table: Mapping, allowed: Collection[str], where: str) -> None:
    """Refuse a key of ``table`` not in ``allowed``.

    Args:
        table: The table.
        allowed: Its allowed keys, in the order the error lists them.
        where: The table's name in errors.

    Raises:
        JobError: ``<where>.<key>: unknown key; allowed: ...``.
    """
    for key in table:
        if key not in allowed:
            raise JobError(f"{where}.{cap(str(key), 40)}", f"unknown key; allowed: {', '.join(allowed)}")


def axes_field(
    tab: Mapping, family: type[AbstractFamily], where: str, limits: dict | None = None
) -> dict[str, list[float]]:
    """Axes checked against a scenario family's: known names, each a list of numbers inside its range.

    Args:
        tab: Axis name -> list of numbers.
        family: A scenario family (:mod:`jaxobs.scenarios.families`).
        where: The table's name in errors.
        limits: name -> (low, high), narrowing the ranges (:meth:`~jaxobs.scenarios.families.AbstractFamily.limits`).

    Returns:
        name -> the checked values.

    Raises:
        JobError: naming ``where``, ``where.<axis>`` or ``where.<axis>[i]`` and the allowed range.
    """
    allowed = family.axes
    if not tab:
        raise JobError(where, f"at least one axis is required; allowed: {', '.join(allowed)}")
    axes: dict[str, list[float]] = {}
    for k in tab:
        if k not in allowed:
            raise JobError(f"{where}.{cap(str(k), 40)}", f"unknown axis; allowed: {', '.join(allowed)}")
        v = axes[k] = get_field(tab, k, f"{where}.{k}", list, required=True)
        lo, hi = (limits or {}).get(k, allowed[k].range)
        for i, x in enumerate(v):
            if not lo <= x <= hi:
                raise JobError(f"{where}.{k}[{i}]", f"must be in {allowed[k].text(lo, hi)}, got {x:g}")
    return axes
