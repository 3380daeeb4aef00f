"""Provenance: what made a result, stamped the same way on every study Dataset and tuning result.

One function for the versions (:func:`versions`), one for the NetCDF attributes of a study
(:func:`provenance`), one for a file's digest (:func:`sha256`), and the one reader of every input file
(:func:`read_file`: job TOML, result.json, checkpoints, CSV recordings).  Nothing here changes between two
identical runs (no time, no host name), so identical runs still write identical bytes.
"""

from __future__ import annotations

import hashlib
import os
import platform
import stat
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _pkg_version
from pathlib import Path

import jax
import numpy as np

__all__ = ["PACKAGES", "provenance", "read_file", "sha256", "versions"]

# the packages whose versions a result records (xarray writes the Datasets; equinox holds the designs)
PACKAGES = ("jaxobs", "jax", "jaxlib", "equinox", "numpy", "xarray")


def _version(name: str) -> str:
    if name == "jax":
        return jax.__version__
    if name == "numpy":
        return np.__version__
    try:
        return _pkg_version(name)
    except PackageNotFoundError:  # a source tree without an install
        return "unknown"


def versions() -> dict:
    """``{package: version}`` for :data:`PACKAGES`, the Python version and whether JAX runs in float64 (``x64``)."""
    out = {name: _version(name) for name in PACKAGES}
    out["python"] = platform.python_version()
    out["x64"] = bool(jax.config.jax_enable_x64)
    return out


def read_file(path, max_bytes: int) -> bytes:
    """The bytes of the regular file at ``path``, at most ``max_bytes`` of them; else a one-line ``ValueError``
    (``cannot read 'P' (reason)``, ``'P': not a file``, ``'P': more than the limit of N bytes``) that a
    caller prefixes with the field or argument that named the file.

    A FIFO, a device or a directory is refused before it is opened (``os.stat``), and the file is opened
    with ``O_NONBLOCK`` and checked again on its descriptor (``os.fstat``): a FIFO swapped in between the
    two calls cannot block the process, and ``/dev/zero`` cannot fill its memory."""
    p = os.fspath(path)
    shown = repr(p if len(p) <= 120 else p[:117] + "...")
    try:
        st = os.stat(p)
        if not stat.S_ISREG(st.st_mode):
            raise ValueError(f"{shown}: not a file (only regular files are read: no FIFO, device or folder)")
        if st.st_size > max_bytes:
            raise ValueError(f"{shown}: {st.st_size} bytes, more than the limit of {max_bytes} bytes")
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
        with os.fdopen(fd, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                raise ValueError(f"{shown}: not a file (only regular files are read: no FIFO, device or folder)")
            data = f.read(max_bytes + 1)  # + 1: a file that grew after the stat is still caught
    except OSError as e:
        raise ValueError(f"cannot read {shown} ({e.strerror or type(e).__name__})") from None
    if len(data) > max_bytes:
        raise ValueError(f"{shown}: more than the limit of {max_bytes} bytes")
    return data


def sha256(data: bytes | str | Path) -> str:
    """The hex sha256 of ``data`` (bytes) or of the file at ``data`` (a path)."""
    if not isinstance(data, bytes):
        data = Path(data).read_bytes()
    return hashlib.sha256(data).hexdigest()


def provenance(source: str, *, digests: dict | None = None) -> dict:
    """NetCDF attributes (strings and integers) of a result: ``source`` (the function or command that made it),
    ``<package>_version`` for every package of :func:`versions`, ``python_version``, ``jax_enable_x64`` (1/0),
    and ``<name>_sha256`` for each ``name: hex digest`` of ``digests`` (the files the result was made from)."""
    v = versions()
    attrs = {"source": source, **{f"{k}_version": v[k] for k in (*PACKAGES, "python")}}
    attrs["jax_enable_x64"] = int(v["x64"])
    for name, digest in (digests or {}).items():
        attrs[f"{name}_sha256"] = digest
    return attrs
