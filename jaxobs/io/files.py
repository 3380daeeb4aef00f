"""The one writer of every file jaxobs and its command line write: whole or absent, never through a link.

- :func:`atomic_write_bytes` (and :func:`atomic_write_text`): the bytes to a temp file beside the target
  (random name, ``O_CREAT | O_EXCL | O_NOFOLLOW``), flushed and fsync'ed, renamed over the target, the
  folder fsync'ed.
- :class:`atomic_path`: for writers that open a path themselves (matplotlib's ``savefig``, xarray's
  ``to_netcdf``, h5py): they write into a fresh folder ``tempfile.mkdtemp`` makes beside the target (random
  name, ``O_EXCL``, mode 0700, so no name in it can be guessed or planted by anyone else); the file is
  fsync'ed (opened ``O_NOFOLLOW``), renamed over the target and the folder fsync'ed.

A rename replaces the directory entry: a symlink or a hard link planted at the target's name is replaced, and
the file it points to is left as it was.  A kill leaves at most a temp entry ``.<name>.<random>.tmp`` (a
file, or a folder); :func:`remove_temps` removes them, and the command line calls it on every run's output
folder once it holds the folder's lock.
"""

from __future__ import annotations

import os
import re
import secrets
import shutil
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import Literal

__all__ = ["atomic_write_bytes", "atomic_write_text", "atomic_path", "remove_temps", "is_temp"]

# .<name>.<12 hex digits>.tmp (atomic_write_bytes), .<name>.<8 of [a-z0-9_]>.tmp (mkdtemp, mkstemp)
_TEMP = re.compile(r"\..+\.([0-9a-f]{12}|[a-z0-9_]{8})\.tmp")


def is_temp(name: str) -> bool:
    """Whether a name is a temp entry this module (or ``tempfile`` with its prefix and suffix) makes.

    Args:
        name: A file or folder name.

    Returns:
        Whether it is such a temp entry.
    """
    return _TEMP.fullmatch(name) is not None


def _fsync_folder(folder: Path) -> None:
    """The folder's entries to disk, so that a rename survives a crash (no-op where folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_bytes(
    path: str | os.PathLike[str], data: bytes, replace: Callable[[str, Path], None] = os.replace
) -> None:
    """``data`` to a temp file beside ``path``, fsync'ed, then renamed over it (a symlink or hard link there is
    replaced, never written through).

    The file gets the mode a plain ``open(path, "w")`` would give it (0o666 less the umask): the temp file is
    created with ``os.open(..., 0o666)`` and ``O_EXCL``, not ``tempfile.mkstemp`` (which always makes 0600
    files), so no umask has to be read (``os.umask`` can only be read by setting it, which races with other
    threads).

    Args:
        path: the file to write.
        data: its whole content.
        replace: the rename that publishes the file (``os.replace``; tests interpose a kill there).

    Raises:
        OSError: the folder cannot be written (the temp file is removed again).
    """
    path = Path(path)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_BINARY", 0)
    flags |= getattr(os, "O_CLOEXEC", 0)
    for _ in range(100):
        tmp = str(path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp")
        try:
            fd = os.open(tmp, flags, 0o666)
            break
        except FileExistsError:
            continue
    else:
        raise FileExistsError(f"no free temp file name beside {str(path)!r}")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    _fsync_folder(path.parent)


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write text (UTF-8) to a file through :func:`atomic_write_bytes`.

    Args:
        path: The file.
        text: The text.
    """
    atomic_write_bytes(path, text.encode())


class atomic_path:
    """``with atomic_path(p) as tmp: write(tmp)``: ``tmp`` is renamed to ``p`` when the block succeeds.

    ``tmp`` has ``p``'s name (a writer that picks its format by the suffix sees it) in a fresh folder
    ``.<name>.<random>.tmp`` beside ``p`` (module doc).  The folder goes on every exit path; the file keeps
    the mode its writer gave it (0o666 less the umask).  A block that raises, or writes no regular file at
    ``tmp`` (an ``OSError`` then), leaves ``p`` as it was.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self._dir: Path | None = None

    def __enter__(self) -> Path:
        self._dir = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.", suffix=".tmp", dir=self.path.parent))
        return self._dir / self.path.name

    def __exit__(
        self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None
    ) -> Literal[False]:
        assert self._dir is not None, "atomic_path: __exit__ before __enter__"
        try:
            if et is None:
                tmp = self._dir / self.path.name
                fd = os.open(tmp, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
                try:
                    if not stat.S_ISREG(os.fstat(fd).st_mode):
                        raise OSError(f"{str(tmp)!r} is not a regular file")
                    os.fsync(fd)
                finally:
                    os.close(fd)
                os.replace(tmp, self.path)
                _fsync_folder(self.path.parent)
        finally:
            shutil.rmtree(self._dir, ignore_errors=True)
        return False


def remove_temps(folder: str | os.PathLike[str], match: Callable[[str], bool] = is_temp) -> list[str]:
    """Remove the temp entries a killed writer left in ``folder`` (files, and folders with what they hold; a
    symlink is removed itself, never followed).  The caller must be the folder's only writer (the command
    line holds its lock).

    Args:
        folder: the folder to clean; a missing one has nothing to remove.
        match: which names are temp entries (:func:`is_temp`; a folder only its owner writes may take every
            name ending in ``.tmp``).

    Returns:
        The names removed.
    """
    folder = Path(folder)
    removed = []
    try:
        entries = list(os.scandir(folder))
    except (FileNotFoundError, NotADirectoryError):
        return removed
    for e in entries:
        if not match(e.name):
            continue
        try:
            if e.is_dir(follow_symlinks=False):
                shutil.rmtree(e.path)
            else:
                os.unlink(e.path)
            removed.append(e.name)
        except FileNotFoundError:
            pass
    return removed
