"""Provenance: what made a result, stamped the same way on every study Dataset and tuning result.

One function for the versions (:func:`versions`), one for the NetCDF attributes of a study
(:func:`provenance`), one that makes a result Dataset a CF-1.8 file (:func:`cf_dataset`: every NetCDF the
commands write passes through it), one for a file's digest (:func:`sha256`), and the one reader of every
input file (:func:`read_file`: job TOML, result.json, checkpoints, CSV recordings).  Nothing here changes between two
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
from typing import TYPE_CHECKING

import jax
import numpy as np

if TYPE_CHECKING:
    import xarray as xr

__all__ = [
    "CONVENTIONS",
    "PACKAGES",
    "REFERENCES",
    "cf_dataset",
    "cf_missing",
    "by_label",
    "cf_labels",
    "provenance",
    "read_file",
    "sha256",
    "versions",
]

# the packages whose versions a result records (xarray writes the Datasets; equinox holds the designs)
PACKAGES = ("jaxobs", "jax", "jaxlib", "equinox", "numpy", "xarray")


# the CF global attributes every NetCDF of jaxobs carries (cf_dataset)
CONVENTIONS = "CF-1.8"
INSTITUTION = "jaxobs, a differentiable JAX simulator for tuning sensorless motor-drive observers and FLLs"
# the papers jaxobs implements, numbered as the README and jaxobs.papers number them
REFERENCES = (
    "000: W. Xu, Y. Jiang, C. Mu and F. Blaabjerg, Improved Nonlinear Flux Observer-Based Second-Order SOIFO for "
    "PMSM Sensorless Control, IEEE Transactions on Power Electronics, 2018. "
    "001: S. Golestan, J. M. Guerrero, J. C. Vasquez, A. M. Abusorrah and Y. Al-Turki, Modeling, Tuning, and "
    "Performance Comparison of Second-Order-Generalized-Integrator-Based FLLs, IEEE Transactions on Power "
    "Electronics 33(12), 10229-10239, 2018, doi:10.1109/TPEL.2018.2808246. "
    "002: Y. Li, Y. Hu, X. Ma and L. Liu, Sensorless Control of Dual Three-Phase IPMSM Based on Frequency Adaptive "
    "Linear Extended State Observer."
)
# the integer types CF 1.8 allows (section 2.2: byte, short, int; no int64 and no unsigned types)
_CF_INTS = (np.dtype(np.int8), np.dtype(np.int16), np.dtype(np.int32))


def _version(name: str) -> str:
    if name == "jax":
        return jax.__version__
    if name == "numpy":
        return np.__version__
    try:
        return _pkg_version(name)
    except PackageNotFoundError:  # a source tree without an install
        return "unknown"


def versions() -> dict[str, str | bool]:
    """``{package: version}`` for :data:`PACKAGES`, the Python version and whether JAX runs in float64 (``x64``)."""
    out: dict[str, str | bool] = {name: _version(name) for name in PACKAGES}
    out["python"] = platform.python_version()
    out["x64"] = bool(jax.config.read("jax_enable_x64"))
    return out


def read_file(path: str | os.PathLike[str], max_bytes: int) -> bytes:
    """The bytes of the regular file at ``path``, at most ``max_bytes`` of them; else a one-line ``ValueError``
    (``cannot read 'P' (reason)``, ``'P': not a file``, ``'P': more than the limit of N bytes``) that a
    caller prefixes with the field or argument that named the file.

    A FIFO, a device or a directory is refused before it is opened (``os.stat``), and the file is opened
    with ``O_NONBLOCK`` and checked again on its descriptor (``os.fstat``): a FIFO swapped in between the
    two calls cannot block the process, and ``/dev/zero`` cannot fill its memory.

    Args:
        path: The file.
        max_bytes: The most bytes it may hold.

    Returns:
        Its bytes.

    Raises:
        ValueError: Not a regular file, larger than ``max_bytes``, or unreadable (one line).
    """
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


_HASH_BLOCK = 1 << 20  # bytes read at a time by sha256: a log of any size is hashed in flat memory


def sha256(data: bytes | str | Path) -> str:
    """The hex sha256 of bytes, or of the file at a path, read in blocks of 1 MiB.

    Args:
        data: The bytes, or the path of a file.

    Returns:
        The digest as 64 hex characters.
    """
    if isinstance(data, bytes):
        return hashlib.sha256(data).hexdigest()
    h = hashlib.sha256()
    with open(data, "rb") as f:
        for block in iter(lambda: f.read(_HASH_BLOCK), b""):
            h.update(block)
    return h.hexdigest()


def provenance(source: str, *, digests: dict[str, str] | None = None) -> dict[str, str | int]:
    """NetCDF attributes (strings and integers) of a result: ``source`` (the function or command that made it),
    ``<package>_version`` for every package of :func:`versions`, ``python_version``, ``jax_enable_x64`` (1/0),
    and ``<name>_sha256`` for each ``name: hex digest`` of ``digests`` (the files the result was made from).

    Args:
        source: The function or command that made the result.
        digests: ``{name: hex sha256}`` of the files the result was made from.

    Returns:
        The attributes.
    """
    v = versions()
    attrs: dict[str, str | int] = {"source": source, **{f"{k}_version": str(v[k]) for k in (*PACKAGES, "python")}}
    attrs["jax_enable_x64"] = int(v["x64"])
    for name, digest in (digests or {}).items():
        attrs[f"{name}_sha256"] = digest
    return attrs


def cf_dataset(ds: xr.Dataset, title: str) -> xr.Dataset:
    """``ds`` made a CF-1.8 Dataset, in place, and returned: what every NetCDF the commands write passes through.

    - Global attributes: ``Conventions`` (:data:`CONVENTIONS`), ``title``, ``institution``, ``references`` (the
      papers, :data:`REFERENCES`), ``source`` (kept where :func:`provenance` set it: the function that made the
      result) and ``history`` (that function and jaxobs's version, without a time: two identical runs still
      write identical bytes).
    - Integers in a type CF 1.8 allows: ``int64`` and unsigned variables (counts, a scenario index) become
      ``int32``; booleans are left to xarray, which writes them as bytes.
    - No ``_FillValue`` on a coordinate (its encoding says none).

    ``long_name`` and ``units`` are each builder's to set: :func:`cf_missing` lists the variables without them.

    Args:
        ds: an ``xarray.Dataset``, a result of the library (a study, scores, an envelope).
        title: what the file holds, in words.

    Returns:
        ``ds``.

    Raises:
        ValueError: an integer variable holds values outside int32's range (it cannot be narrowed).
    """
    for name in list(ds.variables):
        v = ds[name]
        if v.dtype.kind in "iu" and v.dtype not in _CF_INTS:
            a = np.asarray(v.values)
            info = np.iinfo(np.int32)
            if a.size and (a.min() < info.min or a.max() > info.max):
                raise ValueError(
                    f"{name} must hold integers in [{info.min}, {info.max}] (CF int), got {a.min()}..{a.max()}"
                )
            narrowed = v.astype(np.int32)
            narrowed.attrs = dict(v.attrs)
            if name in ds.coords:
                ds.coords[name] = narrowed
            else:
                ds[name] = narrowed
    for name in ds.coords:
        ds.variables[name].encoding["_FillValue"] = None
    source = str(ds.attrs.get("source", "jaxobs"))
    ds.attrs.update(
        Conventions=CONVENTIONS,
        title=title,
        institution=INSTITUTION,
        source=source,
        references=REFERENCES,
        history=f"made by {source} (jaxobs {_version('jaxobs')}); no time is stored, so identical runs write "
        "identical files",
    )
    return ds


def cf_missing(ds: xr.Dataset) -> list[str]:
    """The variables and coordinates of ``ds`` that lack what CF asks of them here: a ``long_name``, and ``units``
    on every numeric one (a string label, such as a design's name, has no unit); ``[]`` when none does.

    Args:
        ds: An ``xarray.Dataset``.

    Returns:
        One line per lack, ``<name>: no long_name`` or ``<name>: no units``.
    """
    out = []
    for name in ds.variables:
        attrs = ds[name].attrs
        if not attrs.get("long_name"):
            out.append(f"{name}: no long_name")
        if ds[name].dtype.kind in "biuf" and not attrs.get("units"):
            out.append(f"{name}: no units")
    return out


def cf_labels(ds: xr.Dataset) -> xr.Dataset:
    """``ds`` as a NetCDF holds it: each dimension whose coordinate is a list of names (``design``; ``recording``,
    the files of a study or a job on recordings) gets a numeric index as its coordinate (0, 1, ... as int32), and
    the names a label variable ``<dim>_label`` beside it (CF 1.8, 6.1: a string-valued auxiliary coordinate).  A
    string coordinate variable is not ordered, which CF checkers read as one that is not monotonic (compliance-
    checker's check raised on it).  :func:`by_label` reads a file back.

    Args:
        ds: an ``xarray.Dataset`` (a study, scores, an envelope).

    Returns:
        A new Dataset (``ds`` itself where no dimension coordinate is a list of names).
    """
    out = ds
    for dim in list(ds.dims):
        if dim not in ds.coords or ds[dim].dtype.kind not in "OUS":
            continue
        names = ds[dim]
        what = names.attrs.get("long_name", dim)
        out = out.assign_coords(
            {
                dim: (dim, np.arange(names.size, dtype=np.int32), {"units": "1", "long_name": f"{what}: its index"}),
                f"{dim}_label": (dim, [str(n) for n in names.values], {"long_name": f"{what}: its name"}),
            }
        )
        out[dim].encoding["_FillValue"] = None
    return out


def by_label(ds: xr.Dataset) -> xr.Dataset:
    """:func:`cf_labels`'s inverse: ``ds`` read from a NetCDF with the names as the coordinates again
    (``ds.sel(design="tuned")``); ``ds`` itself where it has no ``<dim>_label``.

    Args:
        ds: an ``xarray.Dataset`` read from a NetCDF of jaxobs.

    Returns:
        The Dataset labelled by the names.
    """
    for dim in list(ds.dims):
        label = f"{dim}_label"
        if label not in ds.variables:
            continue
        what = str(ds[label].attrs.get("long_name", dim)).removesuffix(": its name")
        names = [str(n) for n in ds[label].values]
        ds = ds.drop_vars(label).assign_coords({dim: (dim, names, {"long_name": what})})
    return ds
