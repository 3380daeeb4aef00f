"""Streaming reading of a drive log's delimited text into disk-backed float64 columns: the file checked (a
regular file, within its size, ending with a line end), its header and first rows parsed with a hint where the
declared delimiter or decimal mark is not the file's, then the file parsed a chunk of rows at a time.
"""

from __future__ import annotations

import os
import re
import stat
from collections.abc import Iterator
from typing import overload

import numpy as np
from numpy.typing import DTypeLike

from ._layout import DELIMITERS, RecordingLayout

CHUNK_ROWS = 500_000  # rows parsed at a time: the read's memory is a chunk, whatever the file's length

_NUM = re.compile(r"\s*[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|nan|inf|infinity)\s*", re.I | re.ASCII)


def open_regular(path: str | os.PathLike[str], max_bytes: int) -> str:
    """The path of a log that may be read: a regular file (no FIFO, device or folder) of at most ``max_bytes``.

    Args:
        path: The file.
        max_bytes: The largest size read, bytes.

    Returns:
        The path, as a string.

    Raises:
        FileNotFoundError: No file at ``path``.
        ValueError: A file that cannot be read, is not a regular file, or is larger than ``max_bytes``.
    """
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


def split_fields(line: str, layout: RecordingLayout) -> list[str]:
    """A line's fields, split at the layout's delimiter (runs of blanks for ``"space"``).

    Args:
        line: The line, without its line end.
        layout: The log's :class:`RecordingLayout` (its ``delimiter``).

    Returns:
        The fields, as written (not stripped).
    """
    sep = DELIMITERS[layout.delimiter]
    return re.split(sep, line.strip()) if sep == r"\s+" else line.split(sep)


def _unquote(name: str) -> str:
    """A field without the double quotes around it (``"t"`` → ``t``; ``""`` inside → ``"``)."""
    return name[1:-1].replace('""', '"') if len(name) >= 2 and name[0] == name[-1] == '"' else name


def _is_number(field, decimal):
    f = field.strip()
    if decimal == ",":
        f = f.replace(",", ".")
    return bool(_NUM.fullmatch(f))


def _hint(lines, layout):
    """Why the first data line does not parse: a delimiter or decimal mark other than declared."""
    text = lines[-1][1]
    if layout.delimiter != ";" and text.count(";") >= 1 and len(split_fields(text, layout)) <= 1 + text.count(";") // 2:
        return "; the file seems to use ';' as its delimiter (declare delimiter = ';')"
    if layout.decimal == "." and re.search(r"\d,\d", text) and DELIMITERS[layout.delimiter] != ",":
        return "; the file seems to use decimal commas (declare decimal = ',')"
    if layout.decimal == "." and re.search(r"\d,\d", text) and ";" in text:
        return "; the file seems to use ';' and decimal commas (declare delimiter = ';', decimal = ',')"
    if "\t" in text and layout.delimiter != "tab":
        return "; the file seems to be tab-separated (declare delimiter = 'tab')"
    return ""


def read_header(
    path: str | os.PathLike[str], layout: RecordingLayout
) -> tuple[list[str] | None, list[tuple[int, str]]]:
    """The log's header row, if its first data line is not all numbers, checked against the line after it.

    Args:
        path: The file.
        layout: The log's :class:`RecordingLayout` (its delimiter and decimal mark).

    Returns:
        ``(the column names, or None where there is no header row, the first non-blank, non-comment lines as
        (line number, text))``.

    Raises:
        ValueError: A line that is not UTF-8, no data rows, a header that repeats a column name, or a line after
            the header that is not as many numbers (with a hint where the delimiter or decimal mark seems other
            than declared).
    """
    lines = _first_lines(path)
    first = split_fields(lines[0][1], layout)
    if all(_is_number(x, layout.decimal) for x in first):
        return None, lines
    # a quoted name ("t","u_a": some exporters quote every header field) is read without its quotes, as the
    # columns' parser reads it
    header = [_unquote(x.strip()) for x in first]
    if len(set(header)) != len(header):
        raise ValueError(f"recording {str(path)!r}: the header repeats a column name: {header}")
    if len(lines) > 1:
        row = split_fields(lines[1][1], layout)
        if len(row) != len(header) or not all(_is_number(x, layout.decimal) for x in row):
            n = lines[1][0]
            count = f" (the header has {len(header)} columns, the line {len(row)} fields)"
            why = _hint(lines[:2], layout) or (count if len(row) != len(header) else "")
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
            row = split_fields(ln.rstrip("\r\n"), layout)
            if len(row) != width:
                return f"line {n} has {len(row)} fields, the file {width}"
            if not all(_is_number(x, layout.decimal) for x in row):
                return f"line {n} holds a field that is not a number"
    return _NO_BAD_LINE


_NO_BAD_LINE = "a line could not be read"


def check_field_counts(path: str | os.PathLike[str], layout: RecordingLayout, width: int, block: int = 1 << 22) -> None:
    """Refuse a line of another number of fields than the file's: the columns' parser reads only the columns it is
    asked for and drops a line's extra fields unseen.  The delimiters are counted a block of the file at a time
    (vectorised, one pass), blank and comment lines left out; a delimiter of runs of blanks (``"space"``) is
    counted by the parser, which refuses a line with extra fields there.

    Args:
        path: The file.
        layout: The log's :class:`RecordingLayout` (its delimiter).
        width: The file's number of columns.
        block: The bytes read at a time.

    Raises:
        ValueError: The first line with another number of fields, naming it.
    """
    sep = DELIMITERS[layout.delimiter]
    if len(sep) != 1:
        return
    delim, line0, carry = ord(sep), 1, b""
    with open(path, "rb") as f:
        while True:
            data = f.read(block)
            buf = carry + data
            cut = len(buf) if not data else buf.rfind(b"\n") + 1  # whole lines; at the end, the rest
            buf, carry = buf[:cut], buf[cut:]
            if buf and not buf.endswith(b"\n"):
                buf += b"\n"
            a = np.frombuffer(buf, np.uint8)
            ends = np.flatnonzero(a == 10)
            starts = np.concatenate([[0], ends[:-1] + 1])
            # the delimiters' positions, then how many fall in each line: a few bytes a field, where a running count
            # of every byte (np.cumsum, int64) took 8 bytes a byte of the file, 270 MiB for a block of 16 MiB
            at = np.flatnonzero(a == delim)
            counts = np.searchsorted(at, ends) - np.searchsorted(at, starts)
            for j in np.flatnonzero(counts != width - 1):
                text = buf[starts[j] : ends[j]].decode("utf-8", "replace")
                if text.strip() and not text.lstrip().startswith("#"):
                    n = line0 + int(j)
                    raise ValueError(f"recording {str(path)!r}: line {n} has {counts[j] + 1} fields, the file {width}")
            line0 += len(ends)
            if not data:
                return


def check_last_line(path: str | os.PathLike[str]) -> None:
    """Refuse a file that does not end with a line end: a copy cut short ends inside its last line, and a value cut
    inside a field (``187.84`` read as ``187``) cannot be told from a whole one, so the line is named and the file
    refused rather than read.  Every CSV writer of numpy, pandas, MATLAB and spreadsheets ends its last line.

    Args:
        path: The file (an empty one passes).

    Raises:
        ValueError: The last line has no line end, naming it.
    """
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


def stream_columns(
    path: str | os.PathLike[str],
    layout: RecordingLayout,
    header: list[str] | None,
    wanted: list[int],
    width: int,
    folder: str | os.PathLike[str],
) -> tuple[dict[int, DiskColumn], int]:
    """Parse the file in chunks of :data:`CHUNK_ROWS` rows into one disk-backed float64 column per wanted index.

    Each chunk is written to the columns' files as it is parsed, so the process holds one chunk at a time.

    Args:
        path: The file.
        layout: The log's :class:`RecordingLayout` (its delimiter and decimal mark).
        header: The column names (:func:`read_header`), or None where the file has no header row.
        wanted: The 0-based indices of the columns to keep.
        width: The file's number of columns (for the message naming a bad line).
        folder: Where the columns' files ``c<index>.f8`` are written.

    Returns:
        ``(index → the column, a :class:`DiskColumn`, the number of rows)``.

    Raises:
        ValueError: A line that is not ``width`` numbers, naming it.
    """
    import pandas as pd

    _PRECISION.update(_pandas_precision())
    check_field_counts(path, layout, width)
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
            if np.isnan(arr).any():  # a "nan" written, or a row short of fields (which the parser fills with NaN)
                short = _locate_bad_line(path, layout, width, header is not None)
                if short != _NO_BAD_LINE:
                    raise ValueError(f"recording {str(path)!r}: {short}")
            cols = list(chunk.columns)
            for i in wanted:
                pos = cols.index(header[i]) if header is not None else cols.index(i)
                files[i].write(np.ascontiguousarray(arr[:, pos]).tobytes())
            rows += arr.shape[0]
            del arr, chunk
    except (ValueError, pd.errors.ParserError) as e:
        if str(e).startswith(f"recording {str(path)!r}: "):  # a short row, named above
            raise
        raise ValueError(
            f"recording {str(path)!r}: {_locate_bad_line(path, layout, width, header is not None)}"
        ) from None
    finally:
        for f in files.values():
            f.close()
    out = {}
    for i in wanted:
        fn = os.path.join(folder, f"c{i}.f8")
        out[i] = DiskColumn(fn, rows)
    return out, rows


class DiskColumn:
    """A float64 column on disk, read a block at a time (``col[a:b]``, np.fromfile) or whole (``np.asarray(col)``).

    Not a memory map: a mapped window faults in the pages around it (the kernel's read-ahead), which keeps far more
    resident than the window over a long log's check windows (docs/performance.md); a read keeps only what it
    returns.
    """

    def __init__(self, fn: str, n: int) -> None:
        self.fn, self.n = fn, n

    @property
    def shape(self) -> tuple[int]:
        """``(n,)``: one axis, the rows."""
        return (self.n,)

    def __len__(self) -> int:
        return self.n

    def __array__(self, dtype: DTypeLike | None = None, copy: bool | None = None) -> np.ndarray:
        a = self[0 : self.n]
        return a if dtype is None else a.astype(dtype)

    @overload
    def __getitem__(self, sl: slice) -> np.ndarray: ...

    @overload
    def __getitem__(self, sl: int) -> float: ...

    def __getitem__(self, sl: slice | int) -> np.ndarray | float:
        if not isinstance(sl, slice):
            return float(self[slice(int(sl), int(sl) + 1)][0])
        a, b = max(sl.start or 0, 0), min(self.n if sl.stop is None else sl.stop, self.n)
        with open(self.fn, "rb") as f:
            return np.fromfile(f, dtype=np.float64, count=max(b - a, 0), offset=8 * a)


class ColumnWriter:
    """A float64 column written block after block, then read back as a :class:`DiskColumn`.

    Args:
        folder: Where the column's file ``<name>.f8`` is written.
        name: The column's name.
        n: The column's length, rows.
    """

    def __init__(self, folder: str | os.PathLike[str], name: str, n: int) -> None:
        self.fn, self.n = os.path.join(folder, name + ".f8"), n
        self.f = open(self.fn, "wb")

    def __setitem__(self, sl, x):
        self.f.write(np.ascontiguousarray(x, dtype=np.float64).tobytes())

    def done(self) -> DiskColumn:
        """Close the column's file.

        Returns:
            The column, as a :class:`DiskColumn`.
        """
        self.f.close()
        return DiskColumn(self.fn, self.n)


def row_blocks(n: int, size: int = CHUNK_ROWS) -> Iterator[slice]:
    """The rows 0 … n − 1 in consecutive blocks of ``size`` (the last one shorter).

    Args:
        n: The number of rows.
        size: The rows of a block.

    Yields:
        Each block's slice of rows.
    """
    for a in range(0, n, size):
        yield slice(a, min(a + size, n))


def read_table(
    path: str | os.PathLike[str], max_bytes: int, layout: RecordingLayout | None = None
) -> tuple[list[str] | None, np.ndarray]:
    """A whole delimited-text file as one float64 array, read by the drive logs' reader (the same checks, header
    detection and number parsing: :func:`open_regular`, :func:`check_last_line`, :func:`read_header`,
    :func:`stream_columns`), for a recording small enough to hold in memory.

    Args:
        path: The file.
        max_bytes: The largest size read, bytes.
        layout: Its delimiter and decimal mark (default: ``","`` and ``"."``).

    Returns:
        ``(the column names, or None where there is no header row, the values (rows, columns))``.

    Raises:
        FileNotFoundError: No file at ``path``.
        ValueError: A file that cannot be read, is too large, is cut short, or holds a line that is not as many
            numbers as the file has columns, naming it.
    """
    import tempfile

    layout = RecordingLayout() if layout is None else layout
    p = open_regular(path, max_bytes)
    check_last_line(p)
    header, lines = read_header(p, layout)
    width = len(header) if header is not None else len(split_fields(lines[0][1], layout))
    if header is not None and len(lines) == 1:  # a header and nothing under it
        return header, np.empty((0, width))
    with tempfile.TemporaryDirectory(prefix="jaxobs-csv-") as folder:
        cols, rows = stream_columns(p, layout, header, list(range(width)), width, folder)
        table = np.empty((rows, width))
        for i in range(width):
            table[:, i] = np.asarray(cols[i])
    return header, table
