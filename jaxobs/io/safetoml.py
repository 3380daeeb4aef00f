"""TOML files read safely: size, encoding, nesting and number lengths checked before the parser sees them.

The one TOML reader of the project: drive files (:mod:`jaxobs.drive.drivefile`) and, through
``jaxobs_tuning.job.toml``, job files.  Every refusal is a :class:`TomlFieldError`, a ``ValueError`` of one
line that names the field (the file's role, ``what``, when no key is at fault).
"""

from __future__ import annotations

import os
import re
import tomllib
from pathlib import Path
from typing import Any

from .provenance import read_file

__all__ = ["MAX_DEPTH", "MAX_DIGITS", "MAX_FILE_BYTES", "TomlFieldError", "check_nesting", "check_numbers", "read_toml"]

MAX_FILE_BYTES = 1_000_000  # a file larger than this is refused before it is parsed
MAX_DEPTH = 20  # nesting of tables, arrays and dotted keys
MAX_DIGITS = 1000  # digits in one number literal (Python refuses to convert an integer of more than 4300)


class TomlFieldError(ValueError):
    """A refused TOML file; ``str()`` is ``"field: message"`` on one line.

    Args:
        field: The key at fault, or the file's role.
        message: What is wrong.
    """

    def __init__(self, field: str, message: str):
        self.field, self.message = field, message
        super().__init__(" ".join(f"{field}: {message}".split()))


_STRINGS = re.compile(r'"""(?:[^\\]|\\.)*?"""|\'\'\'.*?\'\'\'|"(?:[^"\\\n]|\\.)*"|\'[^\'\n]*\'|#[^\n]*', re.S)


def check_nesting(text: str, what: str = "job file") -> None:
    """Refuse TOML nested deeper than :data:`MAX_DEPTH` (arrays, inline tables, dotted keys) before it is
    parsed: the parser recurses on nesting and builds one table per dotted-key part.

    Args:
        text: The TOML text.
        what: The file's role, as the error names it.

    Raises:
        TomlFieldError: naming ``what``.
    """
    bare = _STRINGS.sub('""', text)
    depth = 0
    for m in re.finditer(r"[\[\]{}]", bare):
        depth += 1 if m.group() in "[{" else -1
        if depth > MAX_DEPTH + 2:  # + 2: a [[table]] header's brackets
            raise TomlFieldError(what, f"nested deeper than {MAX_DEPTH} levels (arrays / inline tables)")
    for n, line in enumerate(bare.splitlines(), 1):
        key = line.split("=", 1)[0] if "=" in line else line
        if key.count(".") > MAX_DEPTH:
            raise TomlFieldError(what, f"line {n}: a dotted key of more than {MAX_DEPTH} parts")


_LONG_NUMBER = re.compile(r"[0-9_]{" + str(MAX_DIGITS + 1) + ",}")
_HEADER = re.compile(r"\s*\[\[?\s*([^\]]+?)\s*\]\]?\s*$")


def check_numbers(text: str, what: str = "job file") -> None:
    """Refuse a number literal of more than :data:`MAX_DIGITS` digits before the parser converts it (the
    parser's own refusal of a too-long integer names no field), naming its field: the key on its line, under
    the table header above it.

    Args:
        text: The TOML text.
        what: The file's role, named where a number lies outside every table and key.

    Raises:
        TomlFieldError: naming the key.
    """
    table = ""
    for n, line in enumerate(_STRINGS.sub('""', text).splitlines(), 1):
        if m := _HEADER.match(line):
            table = m.group(1).replace(" ", "")
        elif m := _LONG_NUMBER.search(line):
            before = line[: m.start()]
            key = before.split("=", 1)[0].strip() if "=" in before else ""  # none: an array's continuation line
            field = ".".join(x for x in (table, key) if x) or what
            digits = len(m.group().replace("_", ""))
            raise TomlFieldError(field or what, f"a number of {digits} digits (at most {MAX_DIGITS}), line {n}")


def _depth(obj) -> int:
    """Nesting depth of parsed TOML (iterative: no recursion on a deep value)."""
    best, stack = 0, [(obj, 0)]
    while stack:
        o, d = stack.pop()
        best = max(best, d)
        if d > MAX_DEPTH + 1:
            break
        if isinstance(o, dict):
            stack.extend((v, d + 1) for v in o.values())
        elif isinstance(o, list):
            stack.extend((v, d + 1) for v in o)
    return best


def read_toml(path: str | os.PathLike[str], what: str = "job file") -> tuple[dict[str, Any], bytes]:
    """A TOML file's table and bytes.

    Args:
        path: the file (a regular file only: no FIFO, device or folder).
        what: the file's role, named by an error that concerns the whole file.

    Returns:
        The parsed table and the file's bytes.

    Raises:
        TomlFieldError: one line: unreadable, larger than :data:`MAX_FILE_BYTES`, not UTF-8, nested deeper
            than :data:`MAX_DEPTH`, a number longer than :data:`MAX_DIGITS` digits, not TOML.
    """
    try:  # a regular file only (no FIFO, no device), at most MAX_FILE_BYTES
        data = read_file(Path(path), MAX_FILE_BYTES)
    except ValueError as e:
        raise TomlFieldError(what, str(e)) from None
    try:
        text = data.decode()
    except UnicodeDecodeError as e:
        raise TomlFieldError(what, f"not UTF-8 text: byte {e.start} is {data[e.start : e.start + 1]!r}") from None
    check_nesting(text, what)
    check_numbers(text, what)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise TomlFieldError(what, f"not valid TOML: {e}") from None
    except RecursionError:
        raise TomlFieldError(what, f"nested deeper than {MAX_DEPTH} levels") from None
    except ValueError as e:  # a conversion the parser's own checks let through: still one line, the file
        raise TomlFieldError(what, f"not valid TOML: {str(e)[:80]}") from None
    if _depth(raw) > MAX_DEPTH:
        raise TomlFieldError(what, f"nested deeper than {MAX_DEPTH} levels")
    return raw, data
