"""``jaxobs study`` over several processes: joining the run, refusing what cannot be split, one writer.

Process 0 alone checks, locks and writes ``--out`` and tells the others by a broadcast whether it can before
anyone computes; every process checks that all were given the same study (sha256) before computing."""

from __future__ import annotations

import argparse
import contextlib
import errno
import hashlib
import json
import os
import socket
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import jaxobs
from jaxobs.runtime.chunkstore import AbstractChunkSink, ChunkStore

from .job import JobError, read_toml
from .outdir import OutDir
from .study_file import KINDS, WHAT

if TYPE_CHECKING:
    import numpy as np
    from jax.typing import ArrayLike


def distributed_asked(args: argparse.Namespace) -> bool:
    """Whether ``study`` was given any of the distributed run's options.

    Args:
        args: The parsed command line.

    Returns:
        Whether any of --coordinator, --num-processes, --process-id, --timeout, --distributed was given.
    """
    given = (args.coordinator, args.num_processes, args.process_id, args.timeout)
    return args.distributed or any(v is not None for v in given)


def refuse_unsplittable(path: Path) -> None:
    """Drive and recording studies run in one process: refused from the raw TOML, before JAX starts.

    A file that does not parse passes here; :func:`jaxobs_tuning.study_file.load_study` reports it after joining
    (every process reads the same file, so every process stops with the same one-line error).

    Args:
        path: The study file.

    Raises:
        ValueError: A drive or recording study.
    """

    try:
        raw, _ = read_toml(path, WHAT)
    except JobError:
        return
    st = raw.get("study")
    st = st if isinstance(st, dict) else {}
    name = st.get("kind")
    name = name if isinstance(name, str) else "fll"  # an unknown kind: load_study's error
    family = KINDS.get(name, KINDS["fll"])[0]
    kind = "drive" if family.closed_loop else "recording" if "recording" in st else None
    if kind is not None:
        raise ValueError(
            f"{path}: only FLL studies on a scenario grid or sample are split over processes; "
            f"run this {kind} study without --coordinator/--num-processes/--process-id/--distributed"
        )


def join_distributed(args: argparse.Namespace) -> tuple[int, int]:
    """``study --coordinator/--num-processes/--process-id/--distributed``: join the run
    (jaxobs.init_distributed); (process id, process count).  Without ``--distributed`` all three are
    required; with it, what is not given comes from the environment (JAX_COORDINATOR_ADDRESS, SLURM, Open MPI).

    Args:
        args: The parsed command line.

    Returns:
        ``(process id, process count)``.

    Raises:
        ValueError: Options missing or inconsistent.
    """
    given = (args.coordinator, args.num_processes, args.process_id)
    if not args.distributed:
        missing = [f for f, v in zip(("--coordinator", "--num-processes", "--process-id"), given) if v is None]
        if len(missing) == 3:  # --timeout alone
            raise ValueError(
                "--timeout applies to a distributed run: give --coordinator, --num-processes and --process-id, "
                "or --distributed"
            )
        if missing:
            raise ValueError(
                f"a distributed study needs --coordinator, --num-processes and --process-id (missing: "
                f"{', '.join(missing)}), or --distributed to take them from the environment"
            )
    if None not in given[1:] and args.process_id >= args.num_processes:
        n = args.num_processes
        raise ValueError(f"--process-id must be in 0..{n - 1} (--num-processes {n}), got {args.process_id}")
    timeout = 300 if args.timeout is None else args.timeout
    if not args.quiet and args.process_id == 0 and (args.num_processes or 0) > 1:
        # process 0 left alone is aborted by JAX's runtime (a C++ stack dump): say so first.  The others
        # check that process 0 listens before JAX starts and end with one line if it does not.
        print(
            f"jaxobs: process 0 waits up to {timeout} s (--timeout) for the other {args.num_processes - 1} "
            "process(es); if they do not come, JAX aborts it (exit 134)",
            file=sys.stderr,
        )
    if args.process_id == 0 and args.coordinator is not None:
        _check_port_free(args.coordinator)
    try:
        return jaxobs.init_distributed(*given, timeout=timeout)
    except RuntimeError as e:
        # JAX's own, raised before it waits for anyone: this process started JAX already (main() called
        # from Python after a JAX computation, or a second join) or its coordinator service did not start
        jax_says = " ".join(str(e).split())[:160].rstrip(".")
        raise ValueError(
            f"--coordinator/--num-processes/--process-id: this process cannot join the distributed run "
            f"({jax_says}); run each process as a fresh `jaxobs study` command"
        ) from None
    except ValueError as e:  # what JAX could not find: name the CLI's options and variables, not the function's
        jax_says = str(e.__context__ or e).rstrip(".")  # init_distributed raises from JAX's own ValueError
        raise ValueError(
            f"--distributed: the environment does not give the run ({jax_says}): set JAX_COORDINATOR_ADDRESS "
            "(with --num-processes and --process-id), launch under SLURM's srun or Open MPI's mpirun, "
            "or give --coordinator, --num-processes and --process-id"
        ) from None


def _check_port_free(coordinator: str) -> None:
    """Process 0 serves the coordinator on every interface at the port: a port in use made JAX fail with
    "Failed to start RPC server" and a traceback.  Bound once here (and released) to say so in one line."""
    port = int(coordinator.rpartition(":")[2])
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind(("", port))
        except OSError as e:
            if e.errno == errno.EADDRINUSE:
                raise ValueError(
                    f"--coordinator {coordinator}: port {port} is in use on this machine: pick a free port"
                ) from None
            if e.errno in (errno.EACCES, errno.EPERM):  # JAX failed on it with an internal error
                low = _unprivileged_port_start()
                raise ValueError(
                    f"--coordinator {coordinator}: port {port} is privileged here (this user may serve "
                    f"{low}..65535 only): pick a free port in {low}..65535"
                ) from None


def _unprivileged_port_start() -> int:
    """The lowest port a user without CAP_NET_BIND_SERVICE may bind (Linux's sysctl; 1024 elsewhere)."""
    try:
        return int(Path("/proc/sys/net/ipv4/ip_unprivileged_port_start").read_text())
    except (OSError, ValueError):
        return 1024


@contextlib.contextmanager
def _stdout_to_stderr():
    """File descriptor 1 points at stderr inside (what native code prints there goes to stderr)."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


class _ShareComputed(Exception):
    """Raised by :meth:`SharedChunks.load` in a process other than 0: its share is computed and nothing is left
    for it to do (process 0 lays the study out from its store and writes it)."""


class SharedChunks(AbstractChunkSink):
    """The runner's sink (:func:`jaxobs.runtime.runner.run_scenarios`) in each process of a study split over processes.

    Every process must skip the same chunks (a chunk is computed by all of them together, in collectives), but
    only process 0 holds the study's :class:`jaxobs.runtime.chunkstore.ChunkStore` (``store``; ``None`` elsewhere): at
    :meth:`start` it opens it (checking an earlier run's chunks) and broadcasts which chunks are on disk, or
    that it cannot use them, so that every process stops with one line instead of waiting in a collective.
    Process 0 writes each chunk and lays the study out from the store; the others hold nothing, and their
    :meth:`load`, reached once every collective is done, ends their run (:class:`_ShareComputed`).

    Args:
        store: Process 0's :class:`jaxobs.runtime.chunkstore.ChunkStore`; ``None`` elsewhere.
        pid: This process's index.
    """

    def __init__(self, store: ChunkStore | None, pid: int):
        self.store, self.pid = store, pid
        self.mask: np.ndarray | None = None  # (design, chunk): the chunks done, once started
        self.designs: list = []

    def start(self, *, n: int, chunk: int, devices: int, designs: list) -> None:
        """Open process 0's store and share which chunks are done with every process.

        Args:
            n: The scenarios.
            chunk: Scenarios per chunk.
            devices: The devices a chunk is split over.
            designs: The designs' names.

        Raises:
            ValueError: Process 0 cannot use its store (in every process).
        """
        import numpy as np
        from jax.experimental import multihost_utils

        self.designs = [str(d) for d in designs]
        mask = np.zeros((len(designs), -(-int(n) // int(chunk))), np.int32)
        failure = None
        if self.store is not None:
            try:
                self.store.start(n=n, chunk=chunk, devices=devices, designs=designs)
                mask[:] = [[self.store.done(d, i) for i in range(mask.shape[1])] for d in designs]
            except ValueError as e:
                failure = e
        with _stdout_to_stderr():
            flat = np.append(mask.ravel(), np.int32(failure is not None))
            got = np.asarray(multihost_utils.broadcast_one_to_all(flat))
        if failure is not None:
            raise failure
        if got[-1]:
            raise ValueError("process 0 cannot use its study.chunks (its error says why); nothing computed")
        self.mask = got[:-1].reshape(mask.shape)

    def done(self, design: str, i: int) -> bool:
        """Whether chunk ``i`` of ``design`` is on disk (the same answer in every process).

        Args:
            design: The design's name.
            i: The chunk's index.

        Returns:
            Whether it is done.

        Raises:
            RuntimeError: Called before :meth:`start`.
        """
        if self.mask is None:
            raise RuntimeError("SharedChunks.done: called before start")
        return bool(self.mask[self.designs.index(str(design)), i])

    def put(self, design: str, i: int, values: Mapping[str, ArrayLike]) -> None:
        """Keep a computed chunk (process 0 only; the others hold nothing).

        Args:
            design: The design's name.
            i: The chunk's index.
            values: Its values by metric.
        """
        if self.store is not None:
            self.store.put(design, i, values)

    def load(self, design: str) -> dict[str, np.ndarray]:
        """A design's values from process 0's store; in the others, the end of their run (``_ShareComputed``).

        Args:
            design: The design's name.

        Returns:
            Its values by metric.
        """
        if self.store is None:
            raise _ShareComputed
        return self.store.load(design)

    @property
    def resumed(self) -> int:
        """The chunks an earlier run had left on disk (0 outside process 0)."""
        return 0 if self.store is None else self.store.resumed

    @property
    def total(self) -> int:
        """The study's chunks (0 outside process 0)."""
        return 0 if self.store is None else self.store.total

    def retire(self) -> None:
        """Retire process 0's store (:meth:`jaxobs.runtime.chunkstore.ChunkStore.retire`)."""
        if self.store is not None:
            self.store.retire()

    def remove(self) -> None:
        """Remove process 0's store (:meth:`jaxobs.runtime.chunkstore.ChunkStore.remove`)."""
        if self.store is not None:
            self.store.remove()


def distributed_study(
    name: str,
    designs: dict,
    axes: dict,
    opts: dict,
    out: Path,
    args: argparse.Namespace,
    rank: tuple[int, int],
    write: Callable[..., int],
    outdir: OutDir,
    store: ChunkStore | None,
) -> int:
    """One process of a study split over processes: every process computes its share of every chunk
    (jaxobs.studies.study.run_study), process 0 alone checks and locks ``--out`` (``outdir``, an
    :class:`~jaxobs_tuning.outdir.OutDir`) and writes it (and shows progress) by
    ``write(name, designs, axes, opts, out, quiet, store=)``, the single-process study of the command line.
    A kill loses at most the chunks being computed, and ``--resume`` (every process given it) continues from
    process 0's chunks.

    Args:
        name: The study's name.
        designs: name -> design.
        axes: name -> values.
        opts: The study's other options.
        out: The output (``--out``).
        args: The command line's arguments.
        rank: ``(process index, process count)``.
        write: ``write(name, designs, axes, opts, out, quiet, store=)``, the single-process study of the
            command line.
        outdir: The :class:`~jaxobs_tuning.outdir.OutDir` process 0 checks and locks.
        store: Process 0's :class:`jaxobs.runtime.chunkstore.ChunkStore` (unused in the others), shared as
            :class:`SharedChunks`.

    Returns:
        The exit status.
    """
    import numpy as np
    from jax.experimental import multihost_utils

    from jaxobs.studies.study import run_study

    pid, count = rank
    with contextlib.ExitStack() as stack:
        failure = None
        if pid == 0:
            try:
                stack.enter_context(outdir)
                args.log_dir = out
            except Exception as e:  # told to the others first, so that none of them waits for it in a collective
                failure = e
        # every process learns whether process 0 can write, and whether all were given the same study (file and
        # result files, by sha256), before any of them computes: different files would give different chunk
        # shapes, on which the collectives abort the processes.  The first collective connects the CPU
        # collectives, whose gloo prints a line on the C++ stdout: to stderr, stdout is results.
        prov = {k: v for k, v in (opts.get("provenance") or {}).items() if k != "study_file"}
        digest = hashlib.sha256(json.dumps(prov, sort_keys=True, default=str).encode()).digest()
        # with the process count each was given: one given --num-processes 3 joined a 2-process run, exit 0
        claimed = count if args.num_processes is None else args.num_processes
        mine = np.concatenate([np.frombuffer(digest[:16], dtype=np.int32), np.asarray([claimed], dtype=np.int32)])
        with _stdout_to_stderr():
            ok = int(multihost_utils.broadcast_one_to_all(np.int32(failure is None)))
            gathered = np.asarray(multihost_utils.process_allgather(mine))
        digests, counts = gathered[:, :-1], gathered[:, -1]
        if failure is not None:
            raise failure
        if not ok:
            raise ValueError("process 0 cannot use its --out (its error says why); nothing computed")
        wrong = [i for i, c in enumerate(counts) if c != count]
        if wrong:
            raise ValueError(
                f"--num-processes: process(es) {', '.join(map(str, wrong))} were given "
                f"{', '.join(str(int(counts[i])) for i in wrong)}, the run has {count} processes; nothing computed"
            )
        differ = [i for i, d in enumerate(digests) if not np.array_equal(d, digests[0])]
        if differ:
            raise ValueError(
                f"the processes were given different study files (or result files): process(es) "
                f"{', '.join(map(str, differ))} differ from process 0; give every process the same; nothing computed"
            )
        if pid == 0:
            return write(name, designs, axes, opts, out, args.quiet, store=SharedChunks(store, 0))
        kw = {k: v for k, v in opts.items() if k not in ("kind", "provenance", "recording")}
        try:
            run_study(designs, axes, progress=False, store=SharedChunks(None, pid), **kw)
        except _ShareComputed:  # the normal end of a process other than 0: its chunks are computed and shared;
            pass  # laying out and writing the study is process 0's (SharedChunks.load raises it)
        print(f"study {name}: process {pid} of {count} computed its share; process 0 writes the results")
        return 0
