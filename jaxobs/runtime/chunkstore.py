"""A study's per-scenario results on disk, chunk by chunk: a kill loses at most the chunks being computed.

    store = ChunkStore(out / "study.chunks", fingerprint, resume=True)
    ds = run_study(designs, axes, store=store)    # skips the chunks already on disk, writes the others

The folder holds ``meta.json`` (the study's fingerprint, the number of scenarios, the chunk size, the
device count and the designs) and one HDF5 file per finished chunk, ``<design index>.<chunk index>.h5``
(one dataset per metric, that chunk's real rows only).  Each chunk file is written in a temp folder beside
it, fsync'ed and renamed (:mod:`jaxobs.io.files`): a chunk file that exists is complete, and a kill mid-write
leaves only a temp entry, which the next open removes.

Why one file per chunk and not one growing NetCDF4/HDF5 file: HDF5 updates its metadata in place and has
no journal, so a process killed while writing can leave the whole file unreadable, every finished chunk
with it; a rename is atomic.  Zarr would be one file per chunk too, but is one more dependency for what a
folder of small HDF5 files does (h5py is already here for NetCDF4 through h5netcdf).

The fingerprint (the caller's: for ``jaxobs study``, the study file's and its inputs' sha256 with the
versions that compute it) is checked before any chunk is read: another study's chunks are refused in one
line, and so is a store made with another chunk size or device count (the chunks would not line up, and a
device's share of a chunk may differ in the last bit).  The chunk values are those an uninterrupted run
computes (the same compiled program on the same inputs), so a resumed study's Dataset is identical to one
run in one go.
"""

from __future__ import annotations

import abc
import json
import os
import shutil
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from ..io.files import atomic_path, atomic_write_text, remove_temps

__all__ = ["AbstractChunkSink", "ChunkStore"]

META = "meta.json"


def _partial(name: str) -> bool:
    """A temp entry (the store's folder is written by the store alone): what a kill mid-write leaves."""
    return name.endswith(".tmp")


class AbstractChunkSink(abc.ABC):
    """Where the study runner (:func:`jaxobs.runtime.runner.run_scenarios`) sends each chunk's values instead of memory.

    The runner calls :meth:`start` once, then per design and chunk :meth:`done` (True: skip it) or :meth:`put`.
    :class:`ChunkStore` (a folder of chunk files) and ``jaxobs_tuning.distributed.SharedChunks`` (one process's
    share of a study split over processes) implement it.
    """

    @abc.abstractmethod
    def start(self, *, n: int, chunk: int, devices: int, designs: list) -> None:
        """Open the sink for a run.

        Args:
            n: The scenarios.
            chunk: Scenarios per chunk.
            devices: The devices the run splits each chunk over.
            designs: The designs' names.
        """

    @abc.abstractmethod
    def done(self, design: str, i: int) -> bool:
        """Whether chunk ``i`` of ``design`` is held already (the runner skips it).

        Args:
            design: The design's name.
            i: The chunk's index.

        Returns:
            Whether it is held.
        """

    @abc.abstractmethod
    def put(self, design: str, i: int, values: Mapping[str, ArrayLike]) -> None:
        """Take one chunk's values.

        Args:
            design: The design's name.
            i: The chunk's index.
            values: ``values[name]``, that chunk's real rows (no padding).
        """

    @abc.abstractmethod
    def load(self, design: str) -> dict[str, np.ndarray]:
        """Every scenario's values of a design, in order, after the run (a study lays its Dataset out from them).

        Args:
            design: The design's name.

        Returns:
            ``values[name]``, one row per scenario.
        """


class ChunkStore(AbstractChunkSink):
    """The chunk files of one study run in the folder ``path`` (the runner's sink, :class:`AbstractChunkSink`).

    Args:
        path: The folder.
        fingerprint: The study's fingerprint.
        resume: False starts over (the folder's chunks are removed at :meth:`start`); True keeps the chunks
            of the same study (same ``fingerprint``, scenarios, chunk size, devices, designs) and refuses any
            other store with a ``ValueError`` of one line.
    """

    def __init__(self, path, fingerprint: str, *, resume: bool = False):
        self.path = Path(path)
        self.fingerprint = str(fingerprint)
        self.resume = bool(resume)
        self.designs: list = []
        self.n = 0
        self.chunk = 0
        self.resumed = 0  # chunks found on disk at start (0: a fresh run)
        self.total = 0  # chunks of the whole run, every design

    def _refuse(self, why: str):
        raise ValueError(
            f"--resume: checkpoint {str(self.path)!r} {why}; delete it or run without --resume and with --force"
        )

    def start(self, *, n: int, chunk: int, devices: int, designs: list, metrics: list | None = None) -> None:
        """Open the store for a run.

        Args:
            n: The scenarios.
            chunk: Scenarios per chunk.
            devices: The devices the run splits each chunk over.
            designs: The designs' names.
            metrics: The metrics' names (accepted from the runner; the chunks hold whatever ``put`` gives).

        Raises:
            ValueError: The folder is not a folder of study chunks, or (``resume``) it is corrupt or holds another
                study's.
        """
        meta = {
            "fingerprint": self.fingerprint,
            "scenarios": int(n),
            "chunk": int(chunk),
            "devices": int(devices),
            "designs": [str(d) for d in designs],
        }
        p = self.path
        if p.is_symlink() or (p.exists() and not p.is_dir()):
            raise ValueError(f"{str(p)!r} is not a folder of study chunks: refusing to use it")
        trash = self._trash()
        if self.resume and not p.exists() and (trash / META).is_file():
            # killed after retire() and before study.nc's rename: the chunks are all there, under the trash name
            os.replace(trash, p)
        shutil.rmtree(trash, ignore_errors=True)  # a removal a kill cut short (study.nc written)
        if self.resume and (p / META).exists():
            try:
                if (p / META).stat().st_size > 1 << 20 or not (p / META).is_file():
                    raise ValueError("not a small regular file")
                old = json.loads((p / META).read_text())
                if not isinstance(old, dict):
                    raise ValueError("not a JSON object")
            except (OSError, ValueError) as e:
                self._refuse(f"is corrupt or unreadable ({type(e).__name__}: {str(e)[:80]})")
            if old.get("fingerprint") != self.fingerprint:
                got = str(old.get("fingerprint"))[:12]
                self._refuse(f"belongs to another study (sha256 {got}…, this study {self.fingerprint[:12]}…)")
            for key in ("scenarios", "chunk", "devices", "designs"):
                if old.get(key) != meta[key]:
                    self._refuse(f"was made with {key} = {old.get(key)!r}, this run has {meta[key]!r}")
            remove_temps(p, _partial)  # what a kill left mid-write
        else:
            # a kill while meta.json was written (before any chunk) leaves the folder empty or a temp entry in it
            if self.resume and p.exists() and any(not _partial(f.name) for f in p.iterdir()):
                self._refuse("has no meta.json")
            if p.exists():
                shutil.rmtree(p)
            p.mkdir(parents=True, exist_ok=True)
            atomic_write_text(p / META, json.dumps(meta, indent=1))
        self.designs, self.n, self.chunk = list(meta["designs"]), int(n), int(chunk)
        self.resumed = sum(1 for f in p.iterdir() if f.suffix == ".h5")
        self.total = len(self.designs) * -(-self.n // self.chunk)

    def has_chunks(self) -> bool:
        """Whether a finished chunk is on disk (in the folder, or in the folder :meth:`retire` moved aside):
        something a ``--resume`` continues from."""
        for folder in (self.path, self._trash()):
            try:
                if any(f.suffix == ".h5" for f in folder.iterdir()):
                    return True
            except OSError:
                continue
        return False

    def _file(self, design: str, i: int) -> Path:
        return self.path / f"{self.designs.index(str(design))}.{int(i)}.h5"

    def done(self, design: str, i: int) -> bool:
        """Whether a chunk is on disk (complete: chunk files appear only by a rename).

        Args:
            design: The design's name.
            i: The chunk's index.

        Returns:
            Whether chunk ``i`` of ``design`` is on disk.
        """
        return self._file(design, i).exists()

    def put(self, design: str, i: int, values: Mapping[str, ArrayLike]) -> None:
        """Write one chunk.

        Args:
            design: The design's name.
            i: The chunk's index.
            values: ``values[name]``, that chunk's real rows (no padding).
        """
        import h5py

        with atomic_path(self._file(design, i)) as tmp, h5py.File(tmp, "w", track_order=True) as f:
            for k in sorted(values):
                f.create_dataset(k, data=np.asarray(values[k]))

    def load(self, design: str) -> dict[str, np.ndarray]:
        """Every scenario's values of a design, in order: the chunks concatenated.

        Args:
            design: The design's name.

        Returns:
            name -> one value per scenario.

        Raises:
            ValueError: A chunk is missing, unreadable or does not match the study.
        """
        import h5py

        parts = []
        n_chunks = -(-self.n // self.chunk)
        for i in range(n_chunks):
            f = self._file(design, i)
            rows = min(self.chunk, self.n - i * self.chunk)
            try:
                with h5py.File(f, "r") as h:
                    nodes = {k: h[k] for k in h}
                    part = {k: v[()] for k, v in nodes.items() if isinstance(v, h5py.Dataset)}
            except OSError as e:
                raise ValueError(f"study chunk {str(f)!r} is missing or unreadable ({str(e)[:80]})") from None
            if (
                len(part) != len(nodes)
                or (parts and set(part) != set(parts[0]))
                or any(np.shape(v) != (rows,) for v in part.values())
            ):
                raise ValueError(f"study chunk {str(f)!r} does not match the study (keys or rows)")
            parts.append(part)
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

    def _trash(self) -> Path:
        return self.path.with_name(f".{self.path.name}.removed")

    def retire(self) -> None:
        """Move the folder out of the way in one atomic rename, once the study's results are written to their
        temp file and before that file's rename (then :meth:`remove`).

        The results file and the folder cannot change together, and a kill between the two steps must not leave
        both (a ``--resume`` would be refused for the results, with the chunks left behind) nor neither with the
        chunks lost: killed after this rename and before the results', the next ``--resume`` renames the folder
        back (:meth:`start`) and lays the study out from its chunks.  Killed while :meth:`remove` deletes, the
        hidden leftover is no product and the next :meth:`start` deletes it."""
        if self.path.exists():
            shutil.rmtree(self._trash(), ignore_errors=True)
            os.replace(self.path, self._trash())

    def remove(self) -> None:
        """The folder and its chunks (once the study's results are written; after :meth:`retire` or not)."""
        shutil.rmtree(self.path, ignore_errors=True)
        shutil.rmtree(self._trash(), ignore_errors=True)
