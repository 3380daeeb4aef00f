"""Batch robustness studies: designs × a named grid of scenarios → an xarray Dataset.

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
devices' rows of each chunk (:func:`jaxobs.sharding.global_batch`), and receives every scenario's
metrics (an all-gather, :func:`jaxobs.sharding.gather_batch`), so every process returns the whole
Dataset.  The numbers equal a one-device run's to rounding: a device's share is a smaller ``vmap``,
which XLA may vectorize differently in the last bit (tests/test_distributed.py: 2 processes).

The scenarios come from a sampler (:mod:`jaxobs.scenarios`): a dict of axes is a ``Grid`` (or, with
``sample``, a ``Random`` sample); ``Sobol``, ``LHS`` and ``Recordings`` (recorded signals with their truth
columns: dims ``("design", "recording")``) are passed as ``axes`` themselves.  The loop over chunks, devices
and processes is the one study runner, :func:`jaxobs.runner.run_scenarios`, which drive studies share.

Sampled scenarios are single-phase grid signals (the FLL family) built by
:func:`jaxobs.scenarios.grid_signals`: axes are ``freq_step`` (Hz),
``phase_jump_deg``, ``sag``, ``dc``, ``harmonics_scale`` (× Test C's spectrum),
``sub_amplitude`` (1 Hz), ``phase_deg`` (initial phase) and ``noise`` (white noise
standard deviation, p.u., with a per-scenario seed).
Metrics (exact versions): ``settling_freq`` (s after the event for the
one-period average of f̂ to stay within ``band_hz`` of the final frequency), ``ripple_freq`` (steady p-p, Hz),
``rms_phase`` (steady rms phase error, rad), ``itae_freq`` and ``iae_phase``.
"""

from __future__ import annotations

import math
import time

import jax.numpy as jnp
import numpy as np

from . import metrics as M
from ._simulate import OnSignal
from .provenance import provenance
from .runner import run_scenarios
from .scenarios import GRID_SIGNAL_AXES, LHS, AbstractSampler, Grid, Random, Recordings, Sobol, grid_signals

__all__ = ["STUDY_AXES", "STUDY_METRICS", "study_metrics", "run_study", "worst_cases"]

STUDY_AXES = GRID_SIGNAL_AXES  # the scenarios a study runs: jaxobs.scenarios.grid_signals
STUDY_METRICS = ("settling_freq", "ripple_freq", "rms_phase", "itae_freq", "iae_phase")
# CF-style (units, long_name) of every metric, axis and flag of a study Dataset
METRIC_META = {
    "settling_freq": ("s", "settling time of the one-period average of the frequency estimate after the event"),
    "ripple_freq": ("Hz", "steady peak-to-peak frequency error"),
    "rms_phase": ("rad", "steady rms phase error"),
    "itae_freq": ("Hz s2", "ITAE of the frequency error after the event"),
    "iae_phase": ("rad s", "IAE of the phase error after the event"),
}
AXIS_META = {
    "freq_step": ("Hz", "frequency step at the event"),
    "phase_jump_deg": ("degree", "phase jump at the event"),
    "sag": ("1", "voltage sag depth at the event (p.u.)"),
    "dc": ("1", "dc offset (p.u. of the fundamental)"),
    "harmonics_scale": ("1", "harmonic distortion (multiple of 001 Test C's spectrum)"),
    "sub_amplitude": ("1", "1 Hz subharmonic amplitude (p.u.)"),
    "phase_deg": ("degree", "initial phase"),
    "noise": ("1", "white measurement noise standard deviation (p.u.)"),
}
LOST_LOCK_LONG_NAME = (
    f"lost lock: diverged, or in the steady window a phase error > {M.LOCK_TOL_DEG:g} deg or a mean frequency "
    f"error > {100 * M.LOCK_FREQ_TOL:g} % (1: lost)"
)
GAIN_NAMES = ("k", "k1", "k2", "lam")
GAIN_UNITS = {"k": "1", "k1": "1", "k2": "1", "lam": "rad2 s-2"}  # jaxobs.observers.fll: λ in rad²/s²


def study_metrics(sol, t_event: float, steady_from: float, band_hz: float, n_period: int) -> dict:
    """An FLL run's metrics (:data:`STUDY_METRICS`, exact versions), ``settled`` and ``lost_lock``: scalars of one
    :class:`~jaxobs.Solution` on a signal with an event at ``t_event`` s, steady from ``steady_from`` s, settling
    to ``band_hz`` on the ``n_period``-sample average of the frequency estimate."""
    t = sol.t
    out = sol.outputs
    f_hat = out.obs.omega / (2 * math.pi)
    f_true = out.truth.omega / (2 * math.pi)
    ferr = f_hat - f_true
    perr = M.wrap(out.obs.theta - out.truth.theta)
    steady = t >= steady_from
    # settle on the one-period average of f̂: harmonics and dc leave a ripple that is not a transient
    f_avg = M.moving_average(f_hat, n_period)
    return {
        "settling_freq": M.settling_time(t, f_avg, f_true[-1], band_hz, t_event),
        "settled": M.settled(t, f_avg, f_true[-1], band_hz, t_event),
        "ripple_freq": M.peak_to_peak(ferr, steady),
        "rms_phase": M.rms(perr, steady),
        "itae_freq": M.itae(t, ferr, t_event),
        "iae_phase": M.iae(t, perr, t_event),
        # far from the truth over the steady window: phase error > 45° or mean frequency error > 10 %
        # (jaxobs.metrics, "lost lock")
        "lost_lock": M.lost_lock(
            out.obs.theta,
            out.truth.theta,
            steady,
            math.radians(M.LOCK_TOL_DEG),
            omega_hat=out.obs.omega,
            omega=out.truth.omega,
            freq_tol=M.LOCK_FREQ_TOL,
        ),
    }


def run_study(
    designs: dict,
    axes,
    *,
    t_event=0.1,
    horizon=0.4,
    steady_from=None,
    band_hz=0.05,
    sample=0,
    seed=0,
    chunk_size=2048,
    progress=False,
    return_seconds=False,
    mesh=None,
    store=None,
):
    """Simulate every design on every scenario; returns an ``xarray.Dataset`` (see module doc).

    ``axes``: a dict of axis values (a :class:`~jaxobs.scenarios.Grid`, or with ``sample > 0`` a
    :class:`~jaxobs.scenarios.Random` sample of that size seeded by ``seed``), or a sampler itself
    (``Grid``, ``Random``, ``Sobol``, ``LHS``, or ``Recordings``: recorded signals with truth columns,
    dims ``(design, recording)``).  With ``return_seconds=True`` returns ``(dataset, seconds)``, the wall
    time of the runs (kept out of the Dataset, so two identical studies write identical files).  ``mesh``:
    the devices each chunk is split over, a one-axis ``"batch"`` mesh (default ``jaxobs.batch_mesh()``,
    every device of every process; ``jaxobs.batch_mesh(jax.devices()[:1])`` keeps to one device).
    ``store``: a :class:`jaxobs.chunkstore.ChunkStore`: each chunk's values go to disk as it finishes (none
    held during the run), chunks already there (an interrupted run's, ``resume=True``) are not run again, and
    the Dataset is laid out from the store: the same Dataset as without one.
    """
    import xarray as xr

    if not designs:
        raise ValueError("run_study needs at least one design")
    if isinstance(axes, dict):
        for name in axes:  # names and values are checked by grid_signals
            if len(axes[name]) < 1:
                raise ValueError(f"study axis {name!r} needs at least one value")
        sampler = Random(axes, sample, seed) if sample else Grid(axes)
    elif isinstance(axes, AbstractSampler):
        sampler = axes
    else:
        raise ValueError(f"axes must be a dict of axis values or a sampler (jaxobs.scenarios), got {axes!r}")
    if not horizon > t_event >= 0:
        raise ValueError(f"horizon must exceed t_event >= 0, got t_event={t_event}, horizon={horizon}")
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    steady_from = t_event + 0.75 * (horizon - t_event) if steady_from is None else steady_from
    recordings = isinstance(sampler, Recordings)
    freq = float(next(iter(designs.values())).omega_n) / (2 * math.pi)

    def n_period(obs) -> int:
        # settle on the one-period average of f̂: one period of the grid's frequency (a recording's: the
        # design's nominal one), in samples
        f = float(obs.omega_n) / (2 * math.pi) if recordings else freq
        return max(1, int(round(1.0 / (f * obs.ts))))

    def metrics(sol, _signal, n_per):
        m = study_metrics(sol, t_event, steady_from, band_hz, n_per)
        m["ok"] = sol.ok & jnp.all(jnp.stack([jnp.isfinite(m[k]) for k in STUDY_METRICS]))
        return m

    if isinstance(sampler, (Grid, Random, Sobol, LHS)):
        # the signals are built a chunk at a time (jaxobs.runner): a bad axis value is refused here, before
        # anything runs, by building the two scenarios of every axis's least and greatest values (each of
        # grid_signals's checks is a bound on one axis, so these two pass only if every point inside does)
        ends = [tuple(float(f(sampler.axes[k])) for k in sampler.names) for f in (np.min, np.max)]
        grid_signals(sampler.names, ends, t_event, freq)
    t0 = time.time()
    run = run_scenarios(
        designs,
        sampler,
        OnSignal,
        metrics,
        horizon=horizon,
        build=lambda names, points, first: grid_signals(names, points, t_event, freq, seed=seed, first=first),
        static=n_period,
        chunk_size=chunk_size,
        mesh=mesh,
        progress=progress,
        label="study",
        sink=store,
    )
    n = len(run.points)
    values = run.values if store is None else {d: store.load(d) for d in designs}
    results = {d: (v, v["ok"]) for d, v in values.items()}
    dnames = list(designs)
    dims, shape, coords = sampler.layout(_axis_meta)
    dims = ("design", *dims)
    coords["design"] = ("design", dnames, {"long_name": "observer design"})
    gains_present = [g for g in GAIN_NAMES if any(hasattr(o, g) for o in designs.values())]
    data = {}
    for k in STUDY_METRICS:
        arr = np.stack([np.where(results[d][1], results[d][0][k], np.nan).reshape(shape) for d in dnames])
        data[k] = (dims, arr, _meta(*METRIC_META[k]))
    data["settled"] = (
        dims,
        np.stack([(results[d][0]["settled"] & results[d][1]).reshape(shape) for d in dnames]),
        _meta("1", "settled by the horizon (False: settling_freq is censored at horizon - t_event)"),
    )
    data["diverged"] = (
        dims,
        np.stack([(~results[d][1]).astype(np.int8).reshape(shape) for d in dnames]),
        _meta("1", "simulation diverged or a metric is not finite (1: its metrics are NaN)"),
    )
    lost = np.stack([(results[d][0]["lost_lock"] | ~results[d][1]).reshape(shape) for d in dnames])
    data["lost_lock"] = (
        dims,
        lost.astype(np.int8),
        _meta("1", LOST_LOCK_LONG_NAME),
    )
    what = "recordings on which the design lost lock" if recordings else "scenarios that lost lock"
    data["lost_lock_count"] = (
        ("design",),
        lost.reshape(len(dnames), -1).sum(axis=1).astype(np.int64),
        _meta("1", f"{what} (diverged ones included)"),
    )
    # one variable per gain, so each carries its own CF units (a (design, gain_name) array could only say
    # "see gain_units", which no CF reader understands)
    for g in gains_present:
        data[f"gain_{g}"] = (
            ("design",),
            np.asarray([float(getattr(obs, g)) if hasattr(obs, g) else np.nan for obs in designs.values()]),
            _meta(GAIN_UNITS[g], f"observer gain {g} (NaN: the design has no such gain)"),
        )
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update(
        t_event=t_event,
        horizon=horizon,
        steady_from=steady_from,
        band_hz=band_hz,
        scenarios=n,
        sampling=sampler.sampling,
        **({} if recordings else {"seed": getattr(sampler, "seed", seed)}),
        **provenance(
            "jaxobs.study.run_study", digests={"recordings": " ".join(sampler.sha256)} if recordings else None
        ),
    )
    seconds = time.time() - t0
    return (ds, seconds) if return_seconds else ds


def _meta(units: str, long_name: str) -> dict:
    return {"units": units, "long_name": long_name}


def _axis_meta(name: str) -> dict:
    if name == "recording":
        return {"long_name": "recording file (relative to the study file)"}
    if name == "scenario":
        return _meta("1", "scenario given whole (jaxobs.scenarios.Given)")
    return _meta(*AXIS_META[name])


def worst_cases(ds, metric: str, k: int = 5):
    """The ``k`` worst scenarios per design for ``metric``: dicts with the design, the value, the coordinates
    and the flags ``diverged`` and ``lost_lock``.

    Diverged scenarios (no finite metric) are the worst of all: they come first, with ``value`` None and
    ``diverged`` True, never dropped; then the finite values, largest first.
    """
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
