"""TOML files read safely: size, encoding and nesting checked before the parser sees them
(:mod:`jaxobs.io.safetoml`), each refusal a :class:`JobError` naming the field."""

from __future__ import annotations

import os

from jaxobs.io import safetoml
from jaxobs.io.safetoml import MAX_DEPTH as MAX_DEPTH
from jaxobs.io.safetoml import MAX_DIGITS as MAX_DIGITS
from jaxobs.io.safetoml import MAX_FILE_BYTES as MAX_FILE_BYTES
from jaxobs.io.safetoml import TomlFieldError

from .fields import JobError


def check_nesting(text: str, what: str = "job file") -> None:
    """:func:`jaxobs.io.safetoml.check_nesting`, refusing with a :class:`JobError`.

    Args:
        text: The TOML text.
        what: The file's kind in errors.

    Raises:
        JobError: Tables or arrays nested deeper than :data:`MAX_DEPTH`.
    """
    try:
        safetoml.check_nesting(text, what)
    except TomlFieldError as e:
        raise JobError(e.field, e.message) from None


def check_numbers(text: str, what: str = "job file") -> None:
    """:func:`jaxobs.io.safetoml.check_numbers`, refusing with a :class:`JobError`.

    Args:
        text: The TOML text.
        what: The file's kind in errors.

    Raises:
        JobError: A number of more than :data:`MAX_DIGITS` digits.
    """
    try:
        safetoml.check_numbers(text, what)
    except TomlFieldError as e:
        raise JobError(e.field, e.message) from None


def read_toml(path: str | os.PathLike, what: str = "job file") -> tuple[dict, bytes]:
    """A TOML file's table and bytes (:func:`jaxobs.io.safetoml.read_toml`).

    Args:
        path: The file.
        what: The file's kind in errors.

    Returns:
        ``(table, bytes)``.

    Raises:
        JobError: One line: unreadable, larger than :data:`MAX_FILE_BYTES`, not UTF-8, nested deeper than
            :data:`MAX_DEPTH`, not TOML.
    """
    try:
        return safetoml.read_toml(path, what)
    except TomlFieldError as e:
        raise JobError(e.field, e.message) from None
