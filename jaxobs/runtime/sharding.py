"""Scenario batches sharded over devices.

A batch is a PyTree whose leaves carry a leading scenario axis.  Scenarios
never talk to each other, so the batch splits over a one-axis
``jax.sharding.Mesh`` with no communication: place the batch with
:func:`shard_batch`, call the ``jit(vmap(...))``-ed function on it, and XLA
runs each device's share.  Results equal the single-device run (to float64
rounding: tests/test_perf.py runs 4 host devices in a subprocess).

CPU.  XLA runs one device's loop on one thread, so a 2-core machine needs two
*host* devices to use both cores.  ``import jaxobs`` changes nothing (no
environment variables, no JAX configuration); call
:func:`use_host_devices` once, before the first JAX computation, to make JAX's
CPU backend expose one device per usable core (the ``jaxobs`` command line
does this first thing)::

    import jaxobs
    jaxobs.use_host_devices()      # or use_host_devices(4); JAXOBS_HOST_DEVICES=1 turns the default off

It sets JAX's public ``jax_num_cpu_devices`` option.  Called after JAX has
started its backends it cannot change the count: it warns once and returns the
current count (the gain: benchmarks/README.md).

Tiles.  ``jit(vmap(simulate))`` steps the whole batch in lock-step: every
time step sweeps every scenario's state (and its block of inputs), so once a
device's share outgrows the CPU caches each step streams it from memory.
:func:`map_batch` runs each device's share ``TILE`` scenarios at a time (a
share of at most ``TILE`` runs as it is, without a one-tile ``lax.map`` around
it, which slowed it: docs/performance.md)
(``shard_map`` over the mesh, ``lax.map(..., batch_size=TILE)`` inside), so a
tile's state stays in cache for the whole horizon (docs/performance.md; a tile
of 512 per device is what a batch of 1024 gives each of two devices).  Results equal the plain ``vmap`` to rounding (the
same per-scenario program; XLA may vectorize a tile's elementwise functions
differently, a last-bit difference).

Many processes.  A study splits over several processes, on one machine or many
(:func:`jaxobs.studies.study.run_study`; tests/test_distributed.py runs 2 local processes
and finds the single-process numbers).  Every process calls
:func:`init_distributed` first (``jax.distributed.initialize``, with the CPU
backend's collectives set to gloo), then runs the same program: ``jax.devices()``
is now every process's devices and :func:`batch_mesh` spans them all.  Each
process holds the whole batch (a study builds it from its axes and seed, the same
everywhere), :func:`global_batch` places only that process's rows on its devices,
``jit`` of :func:`map_batch` runs each device's share, and :func:`gather_batch`
all-gathers the per-scenario results, so every process has them all.  Two
processes on this machine::

    # the same script in two shells (or two background jobs), process ids 0 and 1:
    JAX_PLATFORMS=cpu JAXOBS_HOST_DEVICES=1 python my_study.py 0 &
    JAX_PLATFORMS=cpu JAXOBS_HOST_DEVICES=1 python my_study.py 1
    # my_study.py:  jaxobs.use_host_devices()      # JAXOBS_HOST_DEVICES=1: one device per process
    #               jaxobs.init_distributed("localhost:12345", 2, int(sys.argv[1]))
    #               ds = run_study(...)              # every process returns the whole Dataset

On a GPU cluster under SLURM: one process per GPU
(``srun --nodes=M --ntasks-per-node=G --gpus-per-node=G python my_study.py``,
G GPUs a node) and ``jaxobs.init_distributed()`` with no arguments.  JAX reads
the count (``SLURM_NTASKS``), each process's id (``SLURM_PROCID``) and the
coordinator (the first node, a port from the job id, or ``JAX_COORDINATOR_PORT``)
from SLURM's environment and gives each process the GPU of its node-local id
(``SLURM_LOCALID``) as its one local device; the mesh spans every GPU of the job.
That path is JAX's own and was not run here (no cluster: CPU processes only).
"""

from __future__ import annotations

import math
import numbers
import os
import re
import time
import warnings
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ..signals import AbstractSignal

__all__ = [
    "batch_mesh",
    "shard_batch",
    "batch_size",
    "batch_axes",
    "map_batch",
    "use_host_devices",
    "init_distributed",
    "global_batch",
    "gather_batch",
    "TILE",
]

AXIS = "batch"

ENV = "JAXOBS_HOST_DEVICES"


def _usable_cores() -> int:
    """Cores this process may run on: its CPU affinity where the OS reports it, else ``os.cpu_count()``."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except (AttributeError, OSError):  # not on every platform (macOS, Windows)
        return os.cpu_count() or 1


def _xla_flag_count() -> int | None:
    """The count in an explicit ``--xla_force_host_platform_device_count`` of ``XLA_FLAGS``, if any (read only)."""
    m = re.search(r"--xla_force_host_platform_device_count=(\d+)", os.environ.get("XLA_FLAGS", ""))
    return int(m.group(1)) if m else None


_warned_late = False


def use_host_devices(n: int | None = None) -> int:
    """Make JAX's CPU backend expose ``n`` devices, so a sharded batch uses ``n`` cores.

    Call it before the first JAX computation (importing jax and jaxobs is fine):
    it sets JAX's public option ``jax_num_cpu_devices``, which JAX reads when it
    starts its backends.  If JAX has already started its backends the count can
    no longer change: the first such call warns (``RuntimeWarning``), and every
    such call returns the number of CPU devices JAX has.  Only the CPU backend is
    affected; a GPU backend keeps its devices.

    Args:
        n: The device count, an integer ≥ 1.  Defaults to the usable cores
            (``os.sched_getaffinity``, which honours CPU affinity and cpusets; else
            ``os.cpu_count()``).  With ``n=None`` the environment variable
            ``JAXOBS_HOST_DEVICES``, read at each call, replaces that default: an
            integer n ≥ 1, or ``1`` for off (JAX's configuration is left as it is).
            An explicit ``--xla_force_host_platform_device_count`` in ``XLA_FLAGS``
            also wins over the default (it is read, never written).  An explicit
            ``n`` wins over both.

    Returns:
        The number of CPU devices JAX will have (or has, once its backends started).

    Raises:
        ValueError: ``n`` or ``JAXOBS_HOST_DEVICES`` is not an integer ≥ 1.
    """
    global _warned_late
    if n is None:
        env = os.environ.get(ENV, "").strip()
        if env and not (env.isdigit() and int(env) >= 1):
            raise ValueError(f"{ENV} must be an integer >= 1 (1: off), got {env!r}")
        flag = _xla_flag_count()
        if (env and int(env) == 1) or (
            not env and flag is not None
        ):  # off, or the user's own XLA flag: leave JAX as it is
            return flag or 1
        n = int(env) if env else _usable_cores()
    elif isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"use_host_devices: n must be an integer >= 1, got {n!r}")
    try:
        jax.config.update("jax_num_cpu_devices", n)
    except RuntimeError:  # JAX raises this once its backends are initialized
        count = len(jax.devices("cpu"))
        if not _warned_late and count != n:
            _warned_late = True
            warnings.warn(
                f"jaxobs.use_host_devices({n}): JAX has already started with {count} CPU device(s); "
                "call it before the first JAX computation to change the count",
                RuntimeWarning,
                stacklevel=2,
            )
        return count
    return n


# jax.Device aliases a jaxlib extension class that jax's stubs declare as a variable: the two annotations below
# name it all the same
def batch_mesh(devices: Sequence[jax.Device] | None = None) -> Mesh:  # pyright: ignore[reportInvalidTypeForm]
    """A one-axis mesh named ``"batch"`` over ``devices``.

    Args:
        devices: The devices of the mesh (default: all of ``jax.devices()``).

    Returns:
        A ``jax.sharding.Mesh`` with the one axis ``"batch"``.

    Raises:
        ValueError: ``devices`` is empty.
    """
    devs = jax.devices() if devices is None else list(devices)
    if not devs:
        raise ValueError("batch_mesh needs at least one device")
    return Mesh(np.asarray(devs), (AXIS,))


def _declares_axis(x: Any) -> bool:
    """A node that says which axis of its leaves is the scenario axis: a signal (its declared ``batch_axis``)."""
    return isinstance(x, AbstractSignal)


def batch_axes(tree: Any) -> Any:
    """Which axis of each leaf is the scenario axis.

    Args:
        tree: A batch (a PyTree of arrays and signals).

    Returns:
        ``tree``'s structure down to the nodes that declare a scenario axis, holding that axis (a
        signal's ``batch_axis``: a time-major :class:`~jaxobs.signals.SampledSignal` says 1), and 0
        elsewhere.  A prefix of ``tree``, as ``jax.vmap``'s ``in_axes`` takes it.
    """
    return jax.tree.map(lambda x: x.batch_axis if _declares_axis(x) else 0, tree, is_leaf=_declares_axis)


def _leaf_axes(tree: Any) -> list[tuple[Any, int]]:
    """(leaf, its scenario axis) for every leaf of ``tree``."""
    out = []
    for node, ax in zip(jax.tree.leaves(tree, is_leaf=_declares_axis), jax.tree.leaves(batch_axes(tree)), strict=True):
        out += [(x, ax) for x in jax.tree.leaves(node)] if _declares_axis(node) else [(node, ax)]
    return out


def batch_size(tree: Any) -> int:
    """The number of scenarios in a batch.

    Args:
        tree: A batch; every array leaf's scenario axis (the leading one, or the axis its node
            declares: :func:`batch_axes`) must have the same length.

    Returns:
        That common length.

    Raises:
        ValueError: The array leaves disagree on the length of their scenario axis.
    """
    sizes = {np.shape(x)[ax] for x, ax in _leaf_axes(tree) if np.ndim(x) > ax}
    if len(sizes) != 1:
        raise ValueError(
            "a batch needs one common leading axis (its scenario axis; a time-major node's inner axis) on every "
            f"array leaf, got sizes {sorted(sizes)}"
        )
    return sizes.pop()


def _spec(ax: int) -> PartitionSpec:
    return PartitionSpec(*([None] * ax), AXIS)


def shard_batch(tree: Any, mesh: Mesh | None = None) -> Any:
    """Place every array leaf of ``tree`` with its leading (scenario) axis split over ``mesh``.

    A batch that does not divide evenly over the devices (or a mesh of one device)
    is placed on the mesh's first device, whole: padding would change what a
    per-scenario reduction sees.  Scalar leaves are replicated.

    Args:
        tree: The batch (its scenario axes as :func:`batch_axes` gives them).
        mesh: The mesh to split over (default: :func:`batch_mesh` over all devices).

    Returns:
        ``tree`` with its leaves placed on the mesh's devices.
    """
    mesh = batch_mesh() if mesh is None else mesh
    n_dev = mesh.devices.size
    b = batch_size(tree)
    if n_dev == 1 or b % n_dev:
        dev = mesh.devices.flat[0]
        return jax.tree.map(lambda x: jax.device_put(x, dev), tree)
    rep = NamedSharding(mesh, PartitionSpec())

    def put(node, ax):
        return jax.tree.map(
            lambda x: jax.device_put(x, NamedSharding(mesh, _spec(ax)) if np.ndim(x) > ax else rep), node
        )

    return jax.tree.map(put, tree, batch_axes(tree), is_leaf=_declares_axis)


# Scenarios per tile per device in map_batch: the share of one device in a
# batch of 1024 over two host devices, the size at which the benchmarks'
# per-step working set (state, AB3 history, a 128-step input block) still
# fits the CPU's caches (module doc).
TILE = 512


def _default_tile(devices: Iterable[jax.Device], batch: int) -> int:  # pyright: ignore[reportInvalidTypeForm]
    """``map_batch``'s tile where the caller gives none: :data:`TILE` on CPU devices (cache-sized shares), the
    whole batch on accelerators (a GPU's kernels want every scenario of the share in each step)."""
    return TILE if all(d.platform == "cpu" for d in devices) else max(1, int(batch))


def map_batch(fn: Callable[[Any], Any], tree: Any, *, mesh: Mesh | None = None, tile: int | None = None) -> Any:
    """``vmap(fn)(tree)`` computed per device of ``mesh``, ``tile`` scenarios at a time.

    Call ``map_batch`` inside ``jit``.  The batch is split over the mesh with
    ``shard_map`` (no communication: scenarios are independent), and each
    device runs its share in tiles of ``tile`` scenarios with
    ``lax.map(..., batch_size=tile)`` (the last tile may be short).  A batch that
    does not divide over the devices runs whole on one (as in :func:`shard_batch`).
    Results equal ``vmap(fn)(tree)`` to rounding.

    ``check_vma=False``: the simulation loops start from unvarying constants
    (zero running costs, an observer's initial state) that meet per-device
    values in their carries; every value here is per-device anyway.

    A node of the batch may declare another scenario axis (:func:`batch_axes`: a time-major
    :class:`~jaxobs.signals.SampledSignal`, leaves ``(n, B)``, is mapped along axis 1).  A batch with
    such a node runs each device's share whole, untiled: a tile of a time-major array is a strided
    copy of every row, and the share's loop reads one contiguous row per step anyway.

    Args:
        fn: Maps one scenario (a slice of every leaf's leading axis) to a PyTree.
        tree: The batch; every array leaf has the scenario axis.
        mesh: The mesh to split over (default: :func:`batch_mesh` over all devices).
        tile: Scenarios per tile per device, an integer ≥ 1, or None (the default): :data:`TILE` on CPU
            devices, the whole share on a GPU or TPU.  Tiles keep a CPU core's working set in its caches; an
            accelerator wants every scenario of its share in each step's kernels (docs/performance.md,
            "On a GPU").  A time-major
            batch (:func:`batch_axes` not 0) runs each share whole whatever ``tile`` says.

    Returns:
        ``vmap(fn)(tree)``: ``fn``'s PyTree with a leading scenario axis on every leaf.

    Raises:
        ValueError: ``tile`` is not an integer ≥ 1, or an array leaf lacks the scenario axis.
    """
    if not (tile is None or (isinstance(tile, numbers.Integral) and not isinstance(tile, bool) and tile >= 1)):
        raise ValueError(f"map_batch: tile must be an integer >= 1 or None, got {tile!r}")
    if any(np.ndim(x) <= ax for x, ax in _leaf_axes(tree)):
        raise ValueError("map_batch: every array leaf of the batch needs the leading scenario axis (got a scalar leaf)")
    mesh = batch_mesh() if mesh is None else mesh
    b = batch_size(tree)
    tile = _default_tile(mesh.devices.flat, b) if tile is None else int(tile)
    axes = batch_axes(tree)
    leading = all(ax == 0 for ax in jax.tree.leaves(axes))

    def local(t):
        if not leading:
            return jax.vmap(fn, in_axes=(axes,))(t)
        if batch_size(t) <= tile:
            # one tile: the share's loop runs as it is (module doc: a one-iteration lax.map around it is
            # slower)
            return jax.vmap(fn)(t)
        return jax.lax.map(fn, t, batch_size=tile)

    n_dev = mesh.devices.size
    if n_dev == 1 or b % n_dev:
        return local(tree)
    in_specs = jax.tree.map(_spec, axes)
    return jax.shard_map(local, mesh=mesh, in_specs=(in_specs,), out_specs=PartitionSpec(AXIS), check_vma=False)(tree)


def init_distributed(
    coordinator: str | None = None,
    num_processes: int | None = None,
    process_id: int | None = None,
    *,
    timeout: int = 300,
) -> tuple[int, int]:
    """Join a run of several processes (``jax.distributed.initialize``); call it in every process, first.

    Call it before the first JAX computation (``jax.devices()`` counts), once per process;
    :func:`use_host_devices` may come before it.  Left out (``None``), the first three arguments are
    filled in by JAX from the environment: ``JAX_COORDINATOR_ADDRESS``, or a cluster launcher it
    detects (SLURM's ``srun``, Open MPI's ``mpirun``), which also gives each process its GPU(s) there.

    On the CPU backend the processes' collectives (the gather of a study's results) need an
    implementation: this sets ``jax_cpu_collectives_implementation`` to ``"gloo"`` (TCP, in jaxlib)
    unless it names one already (``"mpi"``); a GPU backend uses NCCL and ignores the option.
    Afterwards ``jax.devices()`` lists every process's devices, ``jax.local_devices()`` this
    process's, and :func:`jaxobs.studies.study.run_study` splits each chunk of scenarios over all of them.

    Args:
        coordinator: Process 0's ``"HOST:PORT"`` (a free port there; every process gives the same).
            A process other than 0 given it first waits (up to ``timeout``) for process 0 to listen
            there, before JAX is touched.
        num_processes: The count N ≥ 1 of processes.
        process_id: This process's index in ``0 … N-1``.
        timeout: Seconds (≥ 1) every process waits for the others to join
            (``initialization_timeout``): a process still missing a peer then is aborted by JAX's C++
            runtime (SIGABRT, exit status 134, a stack dump on stderr; jax 0.10 raises nothing Python
            could catch), so launch all N processes together.

    Returns:
        ``(process_id, num_processes)`` as JAX sees them.

    Raises:
        ValueError: An argument is out of its range.
        ConnectionError: Process 0 never listened at ``coordinator`` within ``timeout``.
        RuntimeError: (from JAX) A second call, or one after JAX's backends started.
    """
    if isinstance(timeout, bool) or not isinstance(timeout, int) or timeout < 1:
        raise ValueError(f"init_distributed: timeout must be an integer >= 1 (seconds), got {timeout!r}")
    if coordinator is not None:
        host, sep, port = coordinator.rpartition(":") if isinstance(coordinator, str) else ("", "", "")
        if not (sep and host and port.isdigit() and 1 <= int(port) <= 65535):
            raise ValueError(
                f"init_distributed: coordinator must be 'HOST:PORT' with a port in 1..65535, got {coordinator!r}"
            )
    for name, v, low in (("num_processes", num_processes, 1), ("process_id", process_id, 0)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < low):
            raise ValueError(f"init_distributed: {name} must be an integer >= {low}, got {v!r}")
    if num_processes is not None and process_id is not None and process_id >= num_processes:
        raise ValueError(
            f"init_distributed: process_id must be in 0..{num_processes - 1} (num_processes={num_processes}), "
            f"got {process_id}"
        )
    deadline = time.monotonic() + timeout  # one budget: the wait for process 0, then JAX's own
    if coordinator is not None and process_id not in (None, 0):
        _wait_for_coordinator(coordinator, timeout, deadline)
    # an option jax.config sets at run time: its stubs lack it
    set_gloo = jax.config.jax_cpu_collectives_implementation is None  # pyright: ignore[reportAttributeAccessIssue]
    if set_gloo:
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    try:
        left = max(1, math.ceil(deadline - time.monotonic()))
        jax.distributed.initialize(coordinator, num_processes, process_id, initialization_timeout=left)
    except ValueError as e:  # JAX's own: a value it could not find in the arguments or the environment
        if set_gloo:  # refused: leave JAX's options as they were
            jax.config.update("jax_cpu_collectives_implementation", None)
        raise ValueError(
            f"init_distributed: {e} (give coordinator, num_processes and process_id, or run it under a "
            "launcher JAX detects: SLURM's srun, Open MPI's mpirun)"
        ) from None
    return jax.process_index(), jax.process_count()


def _wait_for_coordinator(coordinator: str, timeout: int, deadline: float) -> None:
    """A process other than 0 first checks that process 0 listens (TCP, retried for ``timeout`` s).

    Without it a missing process 0 is found only by JAX's C++ runtime, which aborts the process;
    this gives a Python error (``ConnectionError``; the CLI prints it in one line).  A process 0
    whose peers never come cannot be caught this way: JAX aborts it after ``timeout``.

    What listens there must also be a JAX coordinator: another program on the port (process 0 could not
    start then) made JAX's runtime abort this process after ``timeout`` with a C++ stack dump.  The
    coordinator is a gRPC server, so it speaks HTTP/2: given a client's connection preface it answers with
    a SETTINGS frame at once (RFC 9113, 3.4).  A listener that answers anything else, closes, or says
    nothing within 10 s (or what is left of ``timeout``) is refused in one line naming the port."""
    import socket

    host, _, port = coordinator.rpartition(":")
    host = host.strip("[]")  # "[::1]:1234"
    while True:
        try:
            with socket.create_connection((host, int(port)), timeout=min(5.0, timeout)) as s:
                _expect_http2(s, coordinator, max(1.0, min(10.0, deadline - time.monotonic())))
                return
        except _NotCoordinator:
            raise
        except OSError as e:
            if time.monotonic() >= deadline:
                raise ConnectionError(
                    f"init_distributed: no coordinator (process 0) listening at {coordinator} within {timeout} s "
                    f"({e.strerror or e}); start every process of the run together"
                ) from None
            time.sleep(0.25)


# the client's HTTP/2 connection preface (RFC 9113, 3.4), then an empty SETTINGS frame
_HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])


def _expect_http2(s, coordinator: str, wait: float) -> None:
    """Whether the peer of socket ``s`` answers the HTTP/2 preface with a SETTINGS frame (its 9-byte header:
    type 4 at byte 3) within ``wait`` s; raises ``ConnectionError`` (not an ``OSError`` the caller retries
    on) naming the port otherwise."""
    _, _, port = coordinator.rpartition(":")
    head = b""
    try:
        s.settimeout(wait)
        s.sendall(_HTTP2_PREFACE)
        while len(head) < 9:
            got = s.recv(9 - len(head))
            if not got:
                break
            head += got
    except OSError:  # a timeout or a reset: checked below, as a wrong answer
        pass
    if len(head) < 9 or head[3] != 4:
        said = f"answered {head!r}" if head else f"said nothing within {wait:.0f} s, or closed the connection"
        raise _NotCoordinator(
            f"init_distributed: what listens at {coordinator} is not a JAX coordinator (it {said}); another "
            f"program holds port {port}: give the run a free port"
        )


class _NotCoordinator(ConnectionError):
    """Something listens at the coordinator's address but is not JAX's coordinator (never retried)."""


def global_batch(tree: Any, mesh: Mesh | None = None) -> Any:
    """A batch that every process holds in full (the same values) as global arrays split over ``mesh``.

    Each process fills only its own devices' rows (``jax.make_array_from_callback``), so nothing crosses
    between processes.  In one process this is :func:`shard_batch` with the split required.

    Args:
        tree: The batch; every array leaf has the leading (scenario) axis.
        mesh: The mesh (default: every process's devices), whose device count must divide the batch.

    Returns:
        ``tree`` as global arrays.

    Raises:
        ValueError: A leaf lacks the scenario axis, or the batch does not divide over the mesh.
    """
    if any(np.ndim(x) <= ax for x, ax in _leaf_axes(tree)):
        raise ValueError("global_batch: every array leaf of the batch needs the leading scenario axis (got a scalar)")
    mesh = batch_mesh() if mesh is None else mesh
    n_dev = mesh.devices.size
    b = batch_size(tree)
    if b % n_dev:
        raise ValueError(f"global_batch: the batch ({b}) must divide over the mesh's {n_dev} devices (pad it)")

    def put(node, ax):
        split = NamedSharding(mesh, _spec(ax))

        def one(x):
            x = np.asarray(x)
            return jax.make_array_from_callback(x.shape, split, lambda idx: x[idx])

        return jax.tree.map(one, node)

    return jax.tree.map(put, tree, batch_axes(tree), is_leaf=_declares_axis)


def gather_batch(tree: Any) -> Any:
    """Every leaf of ``tree`` as a whole NumPy array, on every process.

    A collective across processes (``multihost_utils.process_allgather``) where a leaf spans several, else a
    plain copy to the host.

    Args:
        tree: Per-scenario results, sharded over any devices.

    Returns:
        ``tree`` with NumPy leaves.
    """
    from jax.experimental import multihost_utils

    def get(x):
        if isinstance(x, jax.Array) and not x.is_fully_addressable:
            return np.asarray(multihost_utils.process_allgather(x, tiled=True))
        return np.asarray(x)

    return jax.tree.map(get, tree)
