"""Studies: designs × a sampler's scenarios of one family → a labelled xarray Dataset.

:func:`study` is the one study: every design on every scenario a sampler (:mod:`jaxobs.scenarios`) picks
from a family (:mod:`jaxobs.scenarios.families`), run by :func:`jaxobs.runtime.runner.run_scenarios`, scored by
:class:`~jaxobs.metrics.Metric` s of the one metric table (:data:`jaxobs.metrics.METRICS`: their exact forms,
the flags among them: boolean metrics), and laid out with the sampler's dims, CF units and the designs' gains.
:func:`run_study` is its one preset: the family declares its study (its metrics, flags, mask, quantiles, metric
context and attributes: :meth:`jaxobs.scenarios.families.AbstractFamily.study_plan`), the FLL study of grid
signals below, the drive study of :class:`~jaxobs.scenarios.families.DriveScenarios` (:mod:`jaxobs.studies.drive`).

The FLL study:

    ds = run_study({"closed form": fll_a, "tuned": fll_b}, axes={"freq_step": [...], "dc": [...]})
    ds["settling_freq"].sel(design="tuned").max()
    ds.to_netcdf("study.nc", engine="h5netcdf")  # NetCDF4

Every design is simulated on every scenario of the Cartesian grid (or on
``sample`` random points drawn from the axes' ranges) in one ``jit(vmap)``
call per chunk of ``chunk_size`` scenarios (the last chunk is padded, so one
compilation serves all), with progress over chunks when asked (``progress=True``: a tqdm bar on
stderr that names each design's compilation; a callable: ``progress(done, total)``).  The result has one
variable per metric, dims ``("design", *axes)`` (or ``("design", "sample")``
with the axes as coordinates along ``sample``), and a ``diverged`` flag: a
diverging scenario is reported, never fatal.  Every variable and coordinate
carries CF-style ``units`` and ``long_name``; ``lost_lock`` flags the scenarios
whose estimate is far from the truth over the steady window (phase error > 45° or
mean frequency error > 10 %, or diverged: :mod:`jaxobs.metrics`, "lost lock"),
``lost_lock_count`` counts them per design; ``settled`` flags the settling
times that are censored at the horizon (False: not settled by the end of the
run); each gain is its own variable ``gain_<name>`` (``gain_k``, ``gain_lam``, ...), dim ``design``, with
its own ``units`` (NaN where a design has no such gain); the attributes hold the study's options and
the versions that made it, nothing that changes between two identical runs
(the wall time is the second value of ``run_study(..., return_seconds=True)``).

Devices and processes.  Each chunk is split over ``mesh`` (default :func:`jaxobs.batch_mesh`: every
device JAX has, of every process), padded up to a multiple of its device count; each device runs its
share as one ``vmap`` (:func:`jaxobs.map_batch`, no communication).  One device is the plain ``jit(vmap)``.
Several host devices in one process (:func:`jaxobs.use_host_devices`) use every core.  Several
processes (:func:`jaxobs.init_distributed` in each, then the same ``run_study`` call in each): every
process builds every scenario (the grid, or the draws from ``seed``: the same everywhere), places its own
devices' rows of each chunk (:func:`jaxobs.runtime.sharding.global_batch`), and receives every scenario's
metrics (an all-gather, :func:`jaxobs.runtime.sharding.gather_batch`), so every process returns the whole
Dataset.  The numbers equal a one-device run's to rounding: a device's share is a smaller ``vmap``,
which XLA may vectorize differently in the last bit (tests/test_distributed.py: 2 processes).

The scenarios come from a sampler (:mod:`jaxobs.scenarios`): a dict of axes is a ``Grid`` (or, with
``sample``, a ``Random`` sample); ``Sobol``, ``LHS`` and ``Recordings`` (recorded signals with their truth
columns: dims ``("design", "recording")``) are passed as ``axes`` themselves.  The loop over chunks, devices
and processes is the one study runner, :func:`jaxobs.runtime.runner.run_scenarios`, which drive studies share.

Sampled scenarios are single-phase grid signals (the FLL family) built by
:func:`jaxobs.scenarios.grid_signals`: axes are ``freq_step`` (Hz),
``phase_jump_deg``, ``sag``, ``dc``, ``harmonics_scale`` (× Test C's spectrum),
``sub_amplitude`` (1 Hz), ``phase_deg`` (initial phase) and ``noise`` (white noise
standard deviation, p.u., with a per-scenario seed).
Metrics (exact versions): ``settling_freq`` (s after the event for the
one-period average of f̂ to stay within ``band_hz`` of the final frequency), ``ripple_freq`` (steady p-p, Hz),
``rms_phase_steady`` (steady rms phase error, rad), ``itae_freq`` and ``iae_phase`` (the family's default
metrics, :attr:`jaxobs.scenarios.families.GridSignals.metrics`).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Hashable, Iterable, Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import jax.numpy as jnp
import numpy as np

from .. import metrics as M
from ..io.files import atomic_path
from ..io.provenance import cf_dataset, cf_labels
from ..observers import gain_fields, gain_table
from ..runtime.chunkstore import AbstractChunkSink, ChunkStore
from ..runtime.progress import ProgressArg
from ..runtime.runner import run_scenarios
from ..runtime.simulation import AbstractSave, SaveAll
from ..scenarios import GRID_SIGNAL_AXES, AbstractSampler, sampler_of
from ..scenarios.families import AbstractFamily, GridSignals

if TYPE_CHECKING:
    import xarray as xr
    from jax.sharding import Mesh

__all__ = [
    "STUDY_AXES",
    "STUDY_METRICS",
    "StudyContext",
    "study",
    "run_study",
    "worst_cases",
    "write_study",
    "gain_variables",
]


# what the metrics read beside the run (the metric table's: jaxobs.metrics.MetricContext)
StudyContext = M.MetricContext


def study(
    designs: dict[str, Any],
    scenarios: AbstractFamily,
    sampler: AbstractSampler,
    metrics: Iterable[M.Metric],
    *,
    horizon: float,
    ctx: StudyContext = StudyContext(),
    flags: tuple[M.Metric, ...] = (M.DIVERGED,),
    mask: str | None = "diverged",
    quantiles: tuple[float, ...] = (),
    static: Callable[[Any], Hashable] | None = None,
    gains: dict[str, Any] | None = None,
    attrs: dict[str, Any] | None = None,
    save: AbstractSave = SaveAll(),
    chunk_size: int = 2048,
    mesh: Mesh | None = None,
    progress: ProgressArg = False,
    store: AbstractChunkSink | None = None,
    label: str = "study",
) -> xr.Dataset:
    """Every design on every scenario of ``sampler``, drawn from the family ``scenarios``; an ``xarray.Dataset``.

    Args:
        designs: name -> design (an observer), each run on ``scenarios.system(design, scenario)``.
        scenarios: the family (:mod:`jaxobs.scenarios.families`): its axes label the coordinates, it builds the batches.
        sampler: which points of the axes run, and their layout (:mod:`jaxobs.scenarios`).
        metrics: the metric table's entries (:data:`jaxobs.metrics.METRICS`; their ``exact`` forms), one variable
            each with its SI units.
        horizon: s, of every run.
        ctx: what the metrics read (:class:`StudyContext`); ``ctx.n_period`` is ``static(design)`` where given.
        flags: the per-scenario flags (the table's boolean metrics, ``kind="flag"``), stored as variables in this
            order (``diverged`` among them).
        mask: the flag whose scenarios' metrics are NaN (``diverged``, or ``lost_lock``: no steady error to speak
            of); None: every metric as computed.
        quantiles: quantiles over each design's unmasked scenarios, ``<metric>_q`` (dims design, quantile).
        static: a hashable Python value of a design that the metrics need outside tracing (:class:`StudyContext`'s
            ``n_period``); None: ``ctx`` as given.
        gains: the designs' gain variables (``gain_<name>`` -> (dims, values, attrs)), stored as given.
        attrs: the Dataset's attributes (the options, the provenance).
        save, chunk_size, mesh, progress, store, label: as :func:`jaxobs.runtime.runner.run_scenarios` takes them
            (``store``: a :class:`jaxobs.runtime.chunkstore.ChunkStore`, the Dataset laid out from it).

    Returns:
        The Dataset: dims ``("design", *sampler dims)``, a variable per metric and flag, ``<flag>_count`` per
        design, the quantiles, the gains; every variable and numeric coordinate with CF ``units`` and ``long_name``,
        the CF-1.8 global attributes (:func:`jaxobs.io.provenance.cf_dataset`).
    """
    import xarray as xr

    metrics = tuple(metrics)
    run = run_scenarios(
        designs,
        sampler,
        lambda design, sc: scenarios.system(design, sc),
        _scorer(metrics, flags, ctx),
        horizon=horizon,
        build=scenarios.build,
        chunked=True,
        static=static,
        chunk_size=chunk_size,
        mesh=mesh,
        progress=progress,
        label=label,
        save=save,
        sink=store,
    )
    values = {d: store.load(d) for d in designs} if store is not None else run.values
    assert values is not None  # run_scenarios keeps the values where no store took them
    dnames = list(designs)
    dims, shape, coords = sampler.layout(lambda name: _axis_meta(scenarios, sampler, name))
    dims = ("design", *dims)
    what = "observer design (closing the loop sensorless)" if scenarios.closed_loop else "observer design"
    coords["design"] = ("design", dnames, {"long_name": what})
    if quantiles:
        coords["quantile"] = (
            "quantile",
            np.asarray(quantiles),
            {"units": "1", "long_name": "quantile over the scenarios that kept lock (1: the worst)"},
        )
    data = _metric_variables(metrics, values, dnames, dims, shape, mask, quantiles)
    data.update(_flag_variables(flags, values, dnames, dims, shape))
    data.update(gains or {})
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update(scenarios=len(run.points), **(attrs or {}))
    return cf_dataset(ds, f"jaxobs {label}: every design on every scenario, its metrics and flags")


def _scorer(
    metrics: tuple[M.Metric, ...], flags: tuple[M.Metric, ...], ctx: StudyContext
) -> Callable[[Any, Any, Hashable], dict[str, Any]]:
    """The per-scenario values of one run: every metric's exact form, then every flag (a flag without an exact
    form is "not finite": the run not ok or a metric not finite)."""
    names = [m.name for m in metrics]
    forms: list[tuple[str, Callable[..., Any]]] = []
    for m in metrics:
        if m.exact is None:
            raise ValueError(f"study: the metric {m.name!r} has no exact form")
        forms.append((m.name, m.exact))

    def per_scenario(sol: Any, sc: Any, aux: Hashable) -> dict[str, Any]:
        c = ctx if aux is None else replace(ctx, n_period=aux)
        vals = {name: exact(sol, sc, c) for name, exact in forms}
        finite = sol.ok & jnp.all(jnp.stack([jnp.isfinite(vals[k]) for k in names]))
        for f in flags:
            if f.exact is None:
                vals[f.name] = ~finite
            elif f.diverged:
                vals[f.name] = ~finite | f.exact(sol, sc, c)
            else:
                vals[f.name] = finite & f.exact(sol, sc, c)
        return vals

    return per_scenario


def _metric_variables(
    metrics: tuple[M.Metric, ...],
    values: dict[str, dict[str, np.ndarray]],
    dnames: list[str],
    dims: tuple[str, ...],
    shape: tuple[int, ...],
    mask: str | None,
    quantiles: tuple[float, ...],
) -> dict[str, tuple]:
    """A variable per metric (NaN where ``mask`` flags the scenario), and its quantiles over each design's
    scenarios where asked."""
    data = {}
    for m in metrics:
        vals = np.stack(
            [
                values[d][m.name] if mask is None else np.where(values[d][mask], np.nan, values[d][m.name])
                for d in dnames
            ]
        )  # (design, n)
        data[m.name] = (dims, vals.reshape((len(dnames), *shape)), {"units": m.units, "long_name": m.long_name})
        if quantiles:
            qs = np.asarray(quantiles)
            q = np.stack([np.nanquantile(v, qs) if np.isfinite(v).any() else np.full(qs.shape, np.nan) for v in vals])
            data[f"{m.name}_q"] = (
                ("design", "quantile"),
                q,
                {"units": m.units, "long_name": f"{m.long_name}, quantiles"},
            )
    return data


def _flag_variables(
    flags: tuple[M.Metric, ...],
    values: dict[str, dict[str, np.ndarray]],
    dnames: list[str],
    dims: tuple[str, ...],
    shape: tuple[int, ...],
) -> dict[str, tuple]:
    """A variable per flag, and its count per design where the flag declares one."""
    data = {}
    for f in flags:
        flag = np.stack([np.asarray(values[d][f.name]) for d in dnames])
        data[f.name] = (
            dims,
            flag.reshape((len(dnames), *shape)).astype(f.dtype),
            {"units": "1", "long_name": f.long_name},
        )
        if f.count is not None:
            data[f"{f.name}_count"] = (
                ("design",),
                flag.reshape(len(dnames), -1).sum(axis=1).astype(np.int32),  # CF 1.8 has no int64
                {"units": "1", "long_name": f.count},
            )
    return data


def gain_variables(designs: dict) -> dict:
    """The designs' gains as Dataset variables ``gain_<name>`` over ``design``: one variable per gain, so each
    carries its own CF units (a (design, gain_name) array could only say "see gain_units", which no CF reader
    understands); NaN where a design has no such gain.  What every preset and the envelope write.

    Args:
        designs: name -> observer.

    Returns:
        ``gain_<name>`` -> (dims, values, attrs), each gain's units its field's (:func:`jaxobs.observers.gain`).

    Raises:
        ValueError: two designs give one gain name different units (:func:`jaxobs.observers.gain_table`).
    """
    table = gain_table(designs)
    # the gain fields alone: what a study binds per scenario (bound_fields) is none
    gains = {d: {g: float(getattr(obs, g)) for g in gain_fields(obs)} for d, obs in designs.items()}
    return {
        f"gain_{g}": (
            ("design",),
            np.asarray([gains[d].get(g, np.nan) for d in designs], dtype=float),
            {"units": info.units, "long_name": f"observer gain {g} (NaN: the design has no such gain)"},
        )
        for g, info in table.items()
    }


def _axis_meta(scenarios: AbstractFamily, sampler: AbstractSampler, name: str) -> dict:
    # a family's axis, or a dim the sampler has of its own (a Given batch's, the recordings')
    return scenarios.axes[name].attrs if name in scenarios.axes else dict(sampler.dim_attrs)


# --------------------------------------------------------------------------
# the FLL study: grid signals (or recordings) with an event, the FLL family's metrics
# --------------------------------------------------------------------------

STUDY_AXES = GRID_SIGNAL_AXES  # the scenarios a study runs: jaxobs.scenarios.families.GridSignals
# the FLL family's default metrics and flags (jaxobs.scenarios.families.GridSignals declares them)
STUDY_METRICS = GridSignals.metrics


def run_study(
    designs: dict[str, Any],
    axes: Mapping[str, Any] | AbstractSampler,
    *,
    family: AbstractFamily | None = None,
    t_event: float | None = None,
    horizon: float | None = None,
    steady_from: float | None = None,
    band_hz: float | None = None,
    sampling: str | None = None,
    sample: int = 0,
    seed: int | None = None,
    chunk_size: int | None = None,
    progress: ProgressArg = False,
    return_seconds: bool = False,
    mesh: Mesh | None = None,
    store: AbstractChunkSink | None = None,
) -> xr.Dataset | tuple[xr.Dataset, float]:
    """The one study preset: every design on every scenario of ``axes``, drawn from ``family``, scored as the
    family's study scores it (:meth:`~jaxobs.scenarios.families.AbstractFamily.study_plan`): :func:`study` with the
    family's metrics, flags, mask, quantiles and attributes.

    The FLL study (:class:`~jaxobs.scenarios.families.GridSignals`, or a :class:`~jaxobs.scenarios.Recordings`
    sampler's recorded voltages) is the module doc's; the drive study
    (:class:`~jaxobs.scenarios.families.DriveScenarios`) is :mod:`jaxobs.studies.drive`'s.

    Args:
        designs: name -> design (FLLs for grid signals, drive observers for a drive).
        axes: a dict of axis values, or a sampler itself (``Grid``, ``Random``, ``Sobol``, ``LHS``, or
            ``Recordings``: recorded signals with truth columns, dims ``(design, recording)``), as
            :func:`jaxobs.scenarios.sampler_of` takes them (with ``sampling``, ``sample`` and the family's seed).
        family: the scenarios' family (:mod:`jaxobs.scenarios.families`: ``GridSignals`` with its event, nominal
            frequency and seed; ``DriveScenarios`` with its machine, drive, sensors, event and seed); None: grid
            signals built from ``t_event`` (default 0.1 s), ``seed`` (default 0) and the first design's nominal
            frequency.
        t_event, seed: without ``family``: the grid signals' event time, s, and noise seed.
        horizon: the runs' length, s; None: the family's ``study_horizon`` (0.4 s grid signals, 0.3 s a drive).
        steady_from: the steady window's start, s; None: the family's rule (grid signals: three quarters of the
            way from ``t_event``; a drive: half the horizon).
        band_hz: the FLL's settling band, Hz (default 0.05; grid signals only).
        sampling, sample: how a dict of axes is sampled (:func:`jaxobs.scenarios.sampler_of`).
        chunk_size: scenarios per compiled call; None: the family's ``study_chunk`` (2048 grid signals, 256 a
            drive).
        progress: ``True``: a tqdm bar on stderr (each design's compilation named); a callable
            ``progress(done, total)``; False/None: nothing.
        return_seconds: also return the wall time of the runs (kept out of the Dataset, so two identical
            studies write identical files).
        mesh: the devices each chunk is split over, a one-axis ``"batch"`` mesh (default
            ``jaxobs.batch_mesh()``, every device of every process;
            ``jaxobs.batch_mesh(jax.devices()[:1])`` keeps to one device).
        store: a :class:`jaxobs.runtime.chunkstore.ChunkStore`: each chunk's values go to disk as it finishes, chunks
            already there (an interrupted run's, ``resume=True``) are not run again, and the Dataset is laid
            out from the store: the same Dataset as without one.

    Returns:
        The Dataset, or ``(dataset, seconds)`` with ``return_seconds``.

    Raises:
        ValueError: no designs, an axis or sampler refused, ``family`` given with ``t_event`` or ``seed``, a
            family without a study, or ``horizon``, ``t_event``, ``steady_from``, ``band_hz`` or ``chunk_size``
            out of range.
    """
    if not designs:
        raise ValueError("run_study needs at least one design")
    if family is None:
        first = next(iter(designs.values()))
        freq = float(first.omega_n) / (2 * math.pi)
        family = GridSignals(0.1 if t_event is None else t_event, freq, 0 if seed is None else seed)
    elif not isinstance(family, AbstractFamily):
        raise ValueError(f"run_study: family must be a scenario family (jaxobs.scenarios.families), got {family!r}")
    elif t_event is not None or seed is not None:
        raise ValueError("run_study: give family or t_event and seed, not both (the family holds its own)")
    sampler = sampler_of(axes, sampling=sampling, sample=sample, seed=family.draw_seed())
    horizon = family.study_horizon if horizon is None else horizon
    chunk_size = family.study_chunk if chunk_size is None else chunk_size
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    plan = family.study_plan(designs, sampler, horizon=horizon, steady_from=steady_from, band_hz=band_hz)
    t0 = time.time()
    ds = study(
        designs,
        plan.family,  # built a chunk at a time (the plan checked the axes: no chunk can refuse its points)
        sampler,
        [M.METRICS[k] for k in plan.metrics],
        horizon=horizon,
        ctx=plan.ctx,
        flags=plan.flags,
        mask=plan.mask,
        quantiles=plan.quantiles,
        static=plan.static,
        gains=gain_variables(designs),
        attrs=plan.attrs,
        chunk_size=chunk_size,
        mesh=mesh,
        progress=progress,
        store=store,
        label=plan.label,
    )
    seconds = time.time() - t0
    return (ds, seconds) if return_seconds else ds


def worst_cases(ds: xr.Dataset, metric: str, k: int = 5) -> list[dict[str, Any]]:
    """The ``k`` worst scenarios per design for ``metric``: dicts with the design, the value, the coordinates
    and the flags ``diverged`` and ``lost_lock``.

    Diverged scenarios (no finite metric) are the worst of all: they come first, with ``value`` None and
    ``diverged`` True, never dropped; then the finite values, largest first.

    Args:
        ds: A study's Dataset.
        metric: The metric's name (an old name is read as its canonical one).
        k: Scenarios per design.

    Returns:
        One dict per scenario, the designs in order: ``design``, ``metric``, ``value`` (None where not finite),
        the coordinates, ``diverged`` and (where the study has it) ``lost_lock``.
    """
    metric = M.canonical(metric, "worst_cases(metric)")[0]
    out = []
    has_div = "diverged" in ds
    has_lost = "lost_lock" in ds
    for d in ds["design"].values:
        sel = ds.sel(design=d)
        df = sel[metric].to_dataframe(name="value").reset_index()
        df["diverged"] = sel["diverged"].values.reshape(-1).astype(bool) if has_div else df["value"].isna()
        df["diverged"] |= df["value"].isna()
        if has_lost:
            df["lost_lock"] = sel["lost_lock"].values.reshape(-1).astype(bool) | df["diverged"]
        # diverged first (in scenario order), then the finite values, largest first
        df["_rank"] = np.where(df["diverged"], np.inf, df["value"].fillna(-np.inf))
        df = df.sort_values("_rank", ascending=False, kind="stable").head(k).drop(columns="_rank")
        for rec in df.to_dict("records"):
            item = {}
            for key, v in rec.items():
                if key in ("diverged", "lost_lock"):
                    item[key] = bool(v)
                elif isinstance(v, (int, float, np.floating, np.integer)) and not isinstance(v, (bool, np.bool_)):
                    item[key] = float(v) if math.isfinite(float(v)) else None
                else:
                    item[key] = str(v)
            item.update(design=str(d), metric=metric)
            out.append(item)
    return out


def write_study(ds: xr.Dataset, path: str | os.PathLike[str], store: ChunkStore | None = None) -> None:
    """The one study writer: ``ds`` as NetCDF4 at ``path`` (h5netcdf), its name coordinates as numeric indexes
    with label variables (:func:`jaxobs.io.provenance.cf_labels`), written beside it and renamed over it
    (:func:`jaxobs.io.files.atomic_path`), so a ``path`` that exists is a whole study.

    Args:
        ds: A study's Dataset (:func:`study`, a preset's).
        path: The file (``study.nc``).
        store: The :class:`jaxobs.runtime.chunkstore.ChunkStore` the study ran into, or None: retired before the rename
            (never both on disk: a ``--resume`` would be refused, its chunks left) and removed after it
            (the results are in ``path``: nothing is left to resume).
    """
    with atomic_path(path) as tmp:
        cf_labels(ds).to_netcdf(tmp, engine="h5netcdf")  # a numeric design index, the names its label
        if store is not None:
            store.retire()
    if store is not None:
        store.remove()
