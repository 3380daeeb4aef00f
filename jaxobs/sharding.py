"""Scenario batches sharded over devices (DESIGN.md "Scenarios and batches").

A batch is a PyTree whose leaves carry a leading scenario axis.  Scenarios
never talk to each other, so the batch splits over a one-axis
``jax.sharding.Mesh`` with no communication: place the batch with
:func:`shard_batch`, call the ``jit(vmap(...))``-ed function on it, and XLA
runs each device's share.  Results equal the single-device run (to float64
rounding: tests/test_perf.py runs 4 host devices in a subprocess).

CPU.  XLA runs one device's loop on one thread, so a 2-core machine needs two
*host* devices to use both cores: ``import jaxobs`` sets
``XLA_FLAGS=--xla_force_host_platform_device_count=<cores>`` when JAX has not
been imported yet and the flag is not already set (``JAXOBS_HOST_DEVICES=1``
turns this off, an integer sets the count).  This measured 1.9× on batch-1024
forward simulations (benchmarks/README.md).  Import jaxobs before jax to get it.

Many hosts.  The same code runs over several machines: call
``jax.distributed.initialize()`` on every process first (coordinator address,
process count and id, or let a cluster environment such as SLURM supply them),
then build the mesh from ``jax.devices()`` (every process's devices) and give
:func:`shard_batch` each process's global batch.  Each process must run the same
program; per-scenario results come back sharded, ``jax.device_get`` or
``multihost_utils.process_allgather`` collects them.
"""

from __future__ import annotations

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

__all__ = ["batch_mesh", "shard_batch", "batch_size"]

AXIS = "batch"


def batch_mesh(devices=None) -> Mesh:
    """A one-axis mesh named ``"batch"`` over ``devices`` (default: all of ``jax.devices()``)."""
    devs = jax.devices() if devices is None else list(devices)
    if not devs:
        raise ValueError("batch_mesh needs at least one device")
    return Mesh(np.asarray(devs), (AXIS,))


def batch_size(tree) -> int:
    sizes = {np.shape(x)[0] for x in jax.tree.leaves(tree) if np.ndim(x) >= 1}
    if len(sizes) != 1:
        raise ValueError(f"a batch needs one common leading axis on every array leaf, got sizes {sorted(sizes)}")
    return sizes.pop()


def shard_batch(tree, mesh: Mesh | None = None):
    """Place every array leaf of ``tree`` with its leading (scenario) axis split over ``mesh``.

    A batch that does not divide evenly over the devices (or a mesh of one device)
    is placed on the mesh's first device, whole: padding would change what a
    per-scenario reduction sees.  Scalar leaves are replicated.
    """
    mesh = batch_mesh() if mesh is None else mesh
    n_dev = mesh.devices.size
    b = batch_size(tree)
    if n_dev == 1 or b % n_dev:
        dev = mesh.devices.flat[0]
        return jax.tree.map(lambda x: jax.device_put(x, dev), tree)
    split = NamedSharding(mesh, PartitionSpec(AXIS))
    rep = NamedSharding(mesh, PartitionSpec())
    return jax.tree.map(lambda x: jax.device_put(x, split if np.ndim(x) >= 1 else rep), tree)
