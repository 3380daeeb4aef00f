"""Output folders that stay where they are put: sanitised default names, no symlinks followed, one writer
at a time (a lock file), no silent overwrite, every file written to a temp file and renamed.

- Without ``--out`` a job or study writes to ``./out/<name>``, its ``name`` reduced to ``[A-Za-z0-9._-]``
  (no path separators, no ``..``, no absolute path).
- An ``--out`` that is a symlink, or a file to be written there that is a symlink, is refused.
- ``<out>/.jaxobs.lock`` is held with ``fcntl.flock`` for the run's life and names ``pid host``; a second
  process on the same folder refuses with one line.  The kernel releases the lock of a process that dies, so
  a lock file left behind by a kill is not "stale" in any way that needs a takeover: the next run simply
  locks it.  (The former takeover, "read the pid, see it is dead, unlink, re-create", let two of six
  concurrent starters hold the lock at once in 11 of 100 trials.)  A holder removes the file while it still
  holds the lock; a starter that locked a file which is no longer the one at the path starts again.  A lock
  that cannot be written (a full disk) is removed again, and the error names the file.
- A lock file with another name (a hard link planted at ``.jaxobs.lock``) is unlinked, never written.
- Existing results (``result.json``, ``study.nc``, a checkpoint) are not overwritten without ``--force``.
- Every file is written by :mod:`jaxobs.io.files` (a temp entry beside it, renamed over it: a symlink or hard
  link at its name is replaced, never written through); the temp entries a killed run left are removed once
  the folder is locked and its checks pass, whether the run resumes, is forced or starts afresh.
"""

from __future__ import annotations

import errno
import fcntl
import os
import re
import socket
from pathlib import Path

from jaxobs.io.files import atomic_path, atomic_write_bytes, atomic_write_text, remove_temps

__all__ = ["OutError", "safe_name", "OutDir", "atomic_write_bytes", "atomic_write_text", "atomic_path"]

LOCK = ".jaxobs.lock"


class OutError(ValueError):
    """An output folder that cannot be used; ``str()`` is one line (exit status 2)."""


def safe_name(name: str, default: str = "job") -> str:
    """A name as one folder name: characters outside ``[A-Za-z0-9._-]`` become ``_``, leading dots go.

    Args:
        name: The name.
        default: The folder name where nothing but ``_`` would remain.

    Returns:
        The folder name (at most 100 characters).
    """
    s = re.sub(r"[^A-Za-z0-9._-]", "_", str(name))[:100].lstrip(".")
    return s if s.strip("_") else default


def _read_holder(fd: int) -> str:
    """Who holds a lock, from its file ("process PID on HOST"); the holder may not have written it yet."""
    try:
        pid, host = os.pread(fd, 300, 0).decode().split()
        return f"process {int(pid)} on {host}"
    except (OSError, ValueError, UnicodeDecodeError):
        return "another process"


class OutDir:
    """The results folder of one run: checked, locked, released (a context manager).

    Args:
        path: The folder.
        products: The files a run writes there.
        force: Whether existing products may be replaced.
        hints: product name -> what to say instead of "use --force" when it exists (a checkpoint names
            ``--resume`` first: --force would discard the work it holds).
    """

    def __init__(self, path: Path, products=(), force: bool = False, hints: dict | None = None):
        self.path = Path(path)
        self.products = tuple(products)
        self.force = force
        self.hints = dict(hints or {})
        self._fd = None  # the lock file, flock'ed, while the folder is ours

    def check(self) -> None:
        """What :meth:`__enter__` would refuse, without creating, locking or writing anything (``--check``):
        a symlink, not a folder, not writable (the nearest existing folder above a new one), a product that
        exists (without ``force``) or is a symlink.  An :class:`OutError` naming ``--out``; a lock held by a
        running process is not checked (it may be gone by the real run)."""
        p = self.path
        self._check_folder()
        if not p.exists():
            parent = next((a for a in p.absolute().parents if a.exists()), None)
            if parent is None or not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
                raise OutError(f"--out {str(p)!r} cannot be created: {str(parent)!r} is not a writable folder")
            return
        if not os.access(p, os.W_OK | os.X_OK):
            raise OutError(f"--out {str(p)!r} is not writable")
        self._check_products()

    def _check_folder(self):
        p = self.path
        if p.is_symlink():
            raise OutError(f"--out {str(p)!r} is a symlink: refusing to follow it")
        if p.exists() and not p.is_dir():
            raise OutError(f"--out {str(p)!r} exists and is not a folder")

    def _check_products(self):
        p = self.path
        for name in (*self.products, LOCK):
            f = p / name
            if f.is_symlink():
                raise OutError(f"{str(f)!r} is a symlink: refusing to write through it")
        if not self.force:
            for name in self.products:
                if (p / name).exists():
                    hint = self.hints.get(name, "use --force to overwrite it")
                    raise OutError(f"{str(p / name)!r} exists: {hint}")

    def __enter__(self):
        p = self.path
        self._check_folder()
        p.mkdir(parents=True, exist_ok=True)
        if not os.access(p, os.W_OK | os.X_OK):
            raise OutError(f"--out {str(p)!r} is not writable")
        self._lock()
        try:
            self._check_products()
            remove_temps(p)  # a killed run's temp files and folders (jaxobs.io.files)
        except BaseException:
            self.release()
            raise
        return self

    def _lock(self):
        lock = self.path / LOCK
        flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
        for _ in range(100):
            try:
                fd = os.open(lock, flags, 0o644)
            except PermissionError:
                raise OutError(f"--out {str(self.path)!r} is not writable") from None
            except OSError as e:
                if e.errno == errno.ELOOP:
                    raise OutError(f"{str(lock)!r} is a symlink: refusing to write through it") from None
                raise OutError(f"cannot create the lock {str(lock)!r}: {e.strerror or e}") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _read_holder(fd)
                os.close(fd)
                raise OutError(f"{str(self.path)!r} is in use by {holder} (lock {str(lock)!r})") from None
            try:  # ours, unless its holder removed it between our open and our flock: then start again
                same = os.path.samestat(os.stat(lock, follow_symlinks=False), os.fstat(fd))
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            if os.fstat(fd).st_nlink != 1:  # a hard link to a file elsewhere: unlink the name, never write it
                lock.unlink(missing_ok=True)
                os.close(fd)
                continue
            try:
                os.ftruncate(fd, 0)
                data = f"{os.getpid()} {socket.gethostname()}\n".encode()
                if os.pwrite(fd, data, 0) != len(data):
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            except OSError as e:  # a full disk: leave no lock behind, and name the file
                lock.unlink(missing_ok=True)
                os.close(fd)
                raise OutError(f"cannot write the lock {str(lock)!r}: {e.strerror or e}") from None
            self._fd = fd
            return
        raise OutError(f"{str(self.path)!r}: could not take the lock {str(lock)!r}")

    def release(self) -> None:
        """Give the lock back (its file removed first); nothing if it is not held."""
        if self._fd is not None:
            (self.path / LOCK).unlink(missing_ok=True)  # while still holding it: see the module doc
            os.close(self._fd)
            self._fd = None

    def __exit__(self, *exc):
        self.release()
        return False
