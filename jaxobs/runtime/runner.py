"""The one study runner: every design on every scenario a sampler picks, in chunks, over devices and processes.

    run = run_scenarios(designs, Grid(axes), system_factory, metrics, build=..., horizon=0.4)
    run.values["tuned"]["rms_phase_steady"]       # one value per scenario, in the sampler's order

FLL studies, drive studies (:func:`jaxobs.studies.study.run_study`, each family's) and studies on recordings
are this runner with different samplers (:mod:`jaxobs.scenarios`: ``Grid``, ``Random``, ``Sobol``, ``LHS``,
``Recordings``), builders (the points → a batched scenario PyTree),
system factories (a design and one scenario → a system, :class:`jaxobs.AbstractSystem`) and metrics
(a :class:`jaxobs.Solution` → a dict of per-scenario scalars); each study then lays its values out as
an ``xarray.Dataset`` (:meth:`jaxobs.scenarios.AbstractSampler.layout`).

The scenarios run ``chunk_size`` at a time (the last chunk padded with copies of the last scenario, so one
compilation serves all chunks) in one ``jit``.  A builder declared ``chunked`` (it takes the index of its
first point, ``build(names, points, first=i)``, which seeds scenario i's noise from i) is called chunk by chunk,
so the batched scenarios are held one chunk at a time (memory O(chunk), not O(scenarios)); any other is
called once for all points: a ``vmap`` on one device; split over ``mesh`` (default
:func:`jaxobs.batch_mesh`, every device of every process) with :func:`jaxobs.map_batch` on several, each
chunk padded up to a multiple of the device count.  Several processes (:func:`jaxobs.init_distributed`,
then the same call in each): every process builds every scenario (from the sampler's points, the same
everywhere), places only its own devices' rows (:func:`jaxobs.runtime.sharding.global_batch`) and receives every
scenario's values (:func:`jaxobs.runtime.sharding.gather_batch`).  Designs of one class with the same static
fields (a closed form and a tuned one) share one compilation: their gains are array leaves.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..scenarios import AbstractSampler, Given
from . import sharding
from .chunkstore import AbstractChunkSink
from .programs import kept_jit
from .progress import Progress, ProgressArg
from .simulation import AbstractSave, SaveAll, simulate

__all__ = ["StudyRun", "run_scenarios"]


class _Task(NamedTuple):
    """What a chunk runs (static, hashed): the same factory and metrics (a method of one object, say) compile
    once across calls; a closure made per call compiles per call."""

    system_factory: Callable
    metrics: Callable
    horizon: float
    mesh: Any  # None: one device, a plain vmap
    tile: int
    save: AbstractSave = SaveAll()  # SaveFinal: a long horizon whose metrics read the final state alone


def _chunk(task: _Task, design, batch, aux):
    """Every scenario of ``batch`` (one chunk): ``metrics(simulate(system_factory(design, scenario), horizon),
    scenario, aux)``; one program for designs of one class (the gains are array leaves, ``aux`` is static)."""

    def one(sc):
        return task.metrics(simulate(task.system_factory(design, sc), task.horizon, save=task.save), sc, aux)

    if task.mesh is None:
        return jax.vmap(one)(batch)
    # each device's share in one piece (tile = the share): the same per-device program as one device's
    # vmap, no lax.map around it; scenarios are independent, so nothing is communicated
    return sharding.map_batch(one, batch, mesh=task.mesh, tile=task.tile)


# the chunk's program, kept across processes where jaxobs.use_compile_cache set a folder (jaxobs.kept_jit: its key
# is the task's functions and values, the design's static fields and the arrays' shapes)
_run_chunk = kept_jit(_chunk)


def _pad(x, rows: int):
    """``x`` (a chunk's rows) padded to ``rows`` with copies of its last row: only the last chunk is short, so
    only it is copied (padding every scenario array up front held a second copy of all of them)."""
    if x.shape[0] == rows:
        return x
    xp = np if isinstance(x, np.ndarray) else jnp
    return xp.concatenate([x, xp.repeat(x[-1:], rows - x.shape[0], axis=0)])


class StudyRun(NamedTuple):
    """What :func:`run_scenarios` returns.

    Attributes:
        points: The sampler's points, an (n, axes) float array, one row per scenario, in order
            (:meth:`~jaxobs.scenarios.AbstractSampler.array`).
        values: ``values[design][name]``, a NumPy array with one value per scenario for every name the
            metrics return (None with a ``sink``).
    """

    points: np.ndarray
    values: dict[str, dict[str, np.ndarray]] | None


def run_scenarios(
    designs: dict,
    sampler: AbstractSampler,
    system_factory: Callable[[Any, Any], Any],
    metrics: Callable[[Any, Any, Hashable], dict],
    *,
    horizon: float,
    build: Callable[..., Any] | None = None,
    chunked: bool = False,
    static: Callable[[Any], Hashable] | None = None,
    chunk_size: int = 2048,
    mesh: jax.sharding.Mesh | None = None,
    progress: ProgressArg = False,
    label: str = "study",
    save: AbstractSave = SaveAll(),
    sink: AbstractChunkSink | None = None,
) -> StudyRun:
    """Simulate ``system_factory(design, scenario)`` for ``horizon`` s on every scenario, every design.

    Each chunk's traced program is kept across processes where :func:`jaxobs.use_compile_cache` set a folder
    (:func:`jaxobs.kept_jit`).

    Args:
        designs: name -> design (an observer).
        sampler: The scenarios' points (:class:`~jaxobs.scenarios.AbstractSampler`).
        system_factory: ``system_factory(design, scenario)``, the system one design runs on one scenario.
        metrics: ``metrics(sol, scenario, aux)``: a dict of per-scenario scalars of one run's
            :class:`~jaxobs.Solution` on ``scenario``, ``aux = static(design)``.
        horizon: The simulated time, s (finite, > 0).
        build: ``build(names, points)``: the batched scenario PyTree (leading axis one per point) of a
            sampler's points; a sampler that holds its scenarios (:class:`~jaxobs.scenarios.Given`,
            ``Recordings``) needs none.
        chunked: Whether ``build`` is called per chunk, ``build(names, chunk_points, first=index of the
            chunk's first point)``, the last chunk's points padded with copies of its last (so every chunk has
            one shape); such a builder must check its points as a whole-batch call would (a bad value then
            stops the run at its chunk).  Ignored for a sampler that holds its scenarios.
        static: ``static(design)``, a hashable Python value of the design that the metrics need outside
            tracing (``None`` without ``static``; a new value compiles again).
        chunk_size: Scenarios per chunk (an integer ≥ 1).
        mesh: A one-axis ``"batch"`` mesh (default :func:`jaxobs.batch_mesh`).
        progress: ``True`` a tqdm bar on stderr naming each compilation, a callable ``progress(done, total)``,
            ``False`` nothing.
        label: The run's name in messages.
        save: What each run keeps (:class:`~jaxobs.SaveAll` by default; :class:`~jaxobs.SaveFinal` for a long
            horizon whose system accumulates its own metrics in its state).
        sink: Where each chunk's values go instead of memory (a :class:`jaxobs.runtime.chunkstore.AbstractChunkSink`,
            such as a :class:`jaxobs.runtime.chunkstore.ChunkStore`): ``sink.start(n=, chunk=, devices=, designs=)``
            once, then per design and chunk ``sink.done(design, i)`` (True: on disk already, skipped) or
            ``sink.put(design, i, values)`` with the chunk's real rows.

    Returns:
        The :class:`StudyRun`; its ``values`` is ``None`` with a ``sink`` (read them back from the sink).

    Raises:
        ValueError: No designs, ``chunk_size``, ``horizon`` or ``mesh`` out of range, or a ``sink`` that is not
            an :class:`~jaxobs.runtime.chunkstore.AbstractChunkSink`.
    """
    if not designs:
        raise ValueError(f"{label}: at least one design is required")
    if not (isinstance(chunk_size, int) and chunk_size >= 1):
        raise ValueError(f"chunk_size must be an integer >= 1, got {chunk_size!r}")
    if not (math.isfinite(horizon) and horizon > 0):
        raise ValueError(f"horizon must be a finite number of seconds > 0, got {horizon!r}")
    if mesh is not None and not (isinstance(mesh, jax.sharding.Mesh) and mesh.axis_names == (sharding.AXIS,)):
        raise ValueError(f"mesh must be a one-axis jax.sharding.Mesh named 'batch' (jaxobs.batch_mesh), got {mesh!r}")
    if sink is not None and not isinstance(sink, AbstractChunkSink):
        raise ValueError(
            f"sink must be a jaxobs.runtime.chunkstore.AbstractChunkSink or None, got {type(sink).__name__}"
        )
    # a sampler of points (not one that holds its batch) and a builder declared to take its chunk's first index
    chunk_build = build if bool(chunked) and not isinstance(sampler, Given) else None
    by_chunk = chunk_build is not None
    # the points as one float array (8 bytes a value, not a Python tuple per scenario); a builder gets
    # tuples, of its chunk's points or of all
    points = sampler.array()
    n = points.shape[0]
    scs = None if by_chunk else sampler.scenarios(build, list(map(tuple, points.tolist())))
    mesh = sharding.batch_mesh() if mesh is None else mesh
    n_dev = mesh.devices.size
    # a chunk divides over the devices (padded up to a multiple of their count): every device gets an equal share
    chunk = -(-min(chunk_size, n) // n_dev) * n_dev
    pad = (-n) % chunk
    if n_dev > 1 and scs is not None:
        # every process holds every scenario (built from the sampler's points, identically everywhere) and
        # places only its own devices' rows of each chunk (sharding.global_batch)
        scs = jax.tree.map(np.asarray, scs)
    static = (lambda design: None) if static is None else static
    task = _Task(system_factory, metrics, float(horizon), mesh if n_dev > 1 else None, chunk // n_dev, save)

    def chunk_of(start: int):
        """The chunk at ``start``, ``chunk`` rows (the last padded with copies of its last scenario)."""
        if chunk_build is not None:  # built now and dropped after its chunk: only one chunk's scenarios are ever held
            pts = list(map(tuple, points[start : start + chunk].tolist()))
            batch = chunk_build(sampler.names, pts + [pts[-1]] * (chunk - len(pts)), first=start)
        else:
            batch = jax.tree.map(lambda x: _pad(x[start : start + chunk], chunk), scs)
        if n_dev > 1:
            batch = sharding.global_batch(jax.tree.map(np.asarray, batch), mesh)
        return batch

    if sink is not None:
        sink.start(n=n, chunk=chunk, devices=n_dev, designs=list(designs))
    parts: dict[str, list[dict[str, np.ndarray]]] = {dname: [] for dname in designs}
    compiled = set()
    gains = {}
    for dname, design in designs.items():
        aux = static(design)
        if n_dev > 1:
            # the gains as host values: each process passes its own copy, the same on all, to the global jit
            design = jax.tree.map(lambda x: np.asarray(x) if eqx.is_array(x) else x, design)
        gains[dname] = (design, aux, (type(design), aux))
    with Progress(progress, n * len(designs), label, unit="scenario") as bar:
        # chunks outside, designs inside: a chunk built per chunk serves every design
        for start in range(0, n + pad, chunk):
            rows = min(chunk, n - start)
            batch = None
            for dname, (design, aux, key) in gains.items():
                if sink is not None and sink.done(dname, start // chunk):
                    bar.update(rows)  # computed by an earlier, interrupted run
                    continue
                batch = chunk_of(start) if batch is None else batch
                new = key not in compiled  # the first chunk this run computes
                bar.stage(f"{dname} (compiling, then {chunk} scenarios a chunk)" if new else dname)
                # the per-scenario results, whole, on every process (an all-gather when the mesh spans processes)
                got = sharding.gather_batch(_run_chunk(task, design, batch, aux))
                compiled.add(key)
                if sink is None:
                    parts[dname].append(got)
                else:  # streamed: nothing of it is held once it is on disk
                    sink.put(dname, start // chunk, {k: np.asarray(v)[:rows] for k, v in got.items()})
                bar.update(rows)
    if sink is not None:
        return StudyRun(points, None)
    values = {dname: {k: np.concatenate([p[k] for p in ps])[:n] for k in ps[0]} for dname, ps in parts.items()}
    return StudyRun(points, values)
