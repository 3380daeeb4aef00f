"""Provenance: what made a result, stamped the same way on every study Dataset and tuning result.

One function for the versions (:func:`versions`), one for the NetCDF attributes of a study
(:func:`provenance`), one for a file's digest (:func:`sha256`).  Nothing here changes between two
identical runs (no time, no host name), so identical runs still write identical bytes.
"""

from __future__ import annotations

import hashlib
import platform
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _pkg_version
from pathlib import Path

import jax
import numpy as np

__all__ = ["PACKAGES", "provenance", "sha256", "versions"]

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
