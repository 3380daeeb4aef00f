"""Output folders that stay where they are put: sanitised default names, no symlinks followed, one writer
at a time (a lock file), no silent overwrite, every file written to a temp file and renamed.

- Without ``--out`` a job or study writes to ``./out/<name>``, its ``name`` reduced to ``[A-Za-z0-9._-]``
  (no path separators, no ``..``, no absolute path).
- An ``--out`` that is a symlink, or a file to be written there that is a symlink, is refused.
- ``<out>/.jaxobs.lock`` is created with ``O_EXCL`` and holds ``pid host``; a second process on the same
  folder refuses with one line.  A stale lock (its process is gone, same host) is taken over; a lock from
  another host, or one that cannot be read, must be removed by hand (the message says which file).
- Existing results (``result.json``, ``study.nc``, a checkpoint) are not overwritten without ``--force``.
"""

from __future__ import annotations

import os
import re
import secrets
import socket
from pathlib import Path

__all__ = ["OutError", "safe_name", "OutDir", "atomic_write_bytes", "atomic_write_text", "atomic_path"]

LOCK = ".jaxobs.lock"


class OutError(ValueError):
    """An output folder that cannot be used; ``str()`` is one line (exit status 2)."""


def safe_name(name: str, default: str = "job") -> str:
    """``name`` as one folder name: characters outside ``[A-Za-z0-9._-]`` become ``_``, leading dots go."""
    s = re.sub(r"[^A-Za-z0-9._-]", "_", str(name))[:100].lstrip(".")
    return s if s.strip("_") else default


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


class OutDir:
    """The results folder of one run: checked, locked, released (a context manager)."""

    def __init__(self, path: Path, products=(), force: bool = False, hints: dict | None = None):
        """``hints``: product name -> what to say instead of "use --force" when it exists (a checkpoint names
        ``--resume`` first: --force would discard the work it holds)."""
        self.path = Path(path)
        self.products = tuple(products)
        self.force = force
        self.hints = dict(hints or {})
        self._locked = False

    def __enter__(self):
        p = self.path
        if p.is_symlink():
            raise OutError(f"--out {str(p)!r} is a symlink: refusing to follow it")
        if p.exists() and not p.is_dir():
            raise OutError(f"--out {str(p)!r} exists and is not a folder")
        p.mkdir(parents=True, exist_ok=True)
        if not os.access(p, os.W_OK | os.X_OK):
            raise OutError(f"--out {str(p)!r} is not writable")
        self._lock()
        try:
            for name in (*self.products, LOCK):
                f = p / name
                if f.is_symlink():
                    raise OutError(f"{str(f)!r} is a symlink: refusing to write through it")
            if not self.force:
                for name in self.products:
                    if (p / name).exists():
                        hint = self.hints.get(name, "use --force to overwrite it")
                        raise OutError(f"{str(p / name)!r} exists: {hint}")
        except BaseException:
            self.release()
            raise
        return self

    def _lock(self):
        lock = self.path / LOCK
        for _ in range(2):
            try:
                fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY | getattr(os, "O_NOFOLLOW", 0), 0o644)
            except FileExistsError:
                try:
                    pid, host = lock.read_text().split()
                    pid = int(pid)
                except (OSError, ValueError):
                    msg = f"{str(self.path)!r} is locked by {str(lock)!r} (unreadable): remove it by hand"
                    raise OutError(msg) from None
                if host == socket.gethostname() and not _pid_alive(pid):
                    lock.unlink(missing_ok=True)  # stale: its process is gone
                    continue
                msg = f"{str(self.path)!r} is in use by process {pid} on {host} (lock {str(lock)!r})"
                raise OutError(msg) from None
            except PermissionError:
                raise OutError(f"--out {str(self.path)!r} is not writable") from None
            with os.fdopen(fd, "w") as f:
                f.write(f"{os.getpid()} {socket.gethostname()}\n")
            self._locked = True
            return
        raise OutError(f"{str(self.path)!r}: could not take the lock {str(lock)!r}")

    def release(self):
        if self._locked:
            (self.path / LOCK).unlink(missing_ok=True)
            self._locked = False

    def __exit__(self, *exc):
        self.release()
        return False


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """``data`` to a temp file beside ``path``, flushed, then renamed over it (a symlink there is replaced,
    never followed).  The file gets the mode a plain ``open(path, "w")`` would give it (0o666 less the
    umask): the temp file is created with ``os.open(..., 0o666)`` and ``O_EXCL``, not ``tempfile.mkstemp``
    (which always makes 0600 files), so no umask has to be read (``os.umask`` can only be read by setting it,
    which races with other threads)."""
    path = Path(path)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_BINARY", 0)
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
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, text.encode())


class atomic_path:
    """``with atomic_path(p) as tmp: write(tmp)``: ``tmp`` is renamed to ``p`` when the block succeeds."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.tmp = self.path.with_name(f".{self.path.stem}.{os.getpid()}.tmp{self.path.suffix}")

    def __enter__(self) -> Path:
        return self.tmp

    def __exit__(self, et, ev, tb):
        if et is None:
            os.replace(self.tmp, self.path)
        else:
            self.tmp.unlink(missing_ok=True)
        return False
