"""Studies: designs × a sampler's scenarios of one family → a labelled xarray Dataset.

:func:`study` is the one study: every design on every scenario a sampler (:mod:`jaxobs.scenarios`) picks
from a family (:mod:`jaxobs.families`), run by :func:`jaxobs.runner.run_scenarios`, scored by
:class:`~jaxobs.quantities.Metric` s (their exact forms; :data:`METRICS` is the table) and
:class:`Flag` s, and laid out with the sampler's dims, CF units and the designs' gains.  The FLL study
(:func:`run_study`, below) and the drive study (:func:`jaxobs.drive_study.run_drive_study`) are presets of it.

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
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np

from . import metrics as M
from ._simulate import AbstractSave, SaveAll
from .drive import DriveOutput, DualOutput
from .families import AbstractScenarios, GridSignals, RecordedSignals
from .observers import gain_fields, gain_table
from .provenance import cf_dataset, provenance
from .quantities import Metric
from .runner import run_scenarios
from .scenarios import GRID_SIGNAL_AXES, LHS, AbstractSampler, Grid, Random, Recordings, Sobol

__all__ = ["Flag", "METRICS", "STUDY_AXES", "STUDY_METRICS", "StudyContext", "study", "run_study", "worst_cases"]


@dataclass(frozen=True)
class StudyContext:
    """What the metrics read beside the run: the event ``t_event`` (s), the steady window's start
    ``steady_from`` (s), the settling band ``band_hz`` (Hz), the smooth forms' ``temperature`` (s, or the
    metric's units), ``settling_position``'s band ``band_deg`` (electrical degrees, around the error's own
    final value), ``settling_speed``'s band ``band_rpm`` (r/min, around the reference), the one-period
    average's length ``n_period`` (samples: a design's, the study's ``static``) and the machine's pole pairs
    ``p`` (a drive study's speed estimate)."""

    t_event: float = 0.0
    steady_from: float = 0.0
    band_hz: float = 0.05
    temperature: float = 1e-3
    band_deg: float = 2.0
    band_rpm: float = 5.0
    n_period: int = 1
    p: float = 1.0


def _steady(sol, ctx):
    return sol.t >= ctx.steady_from


def _fll(sol):
    """An FLL run's errors: f̂ (Hz), the true f (Hz), f̂ − f (Hz), the wrapped phase error (rad)."""
    out = sol.outputs
    f_hat = out.obs.omega / (2 * math.pi)
    f_true = out.truth.omega / (2 * math.pi)
    return f_hat, f_true, f_hat - f_true, M.wrap(out.obs.theta - out.truth.theta)


def _freq_err_hz(sol):
    return (sol.outputs.obs.omega - sol.outputs.truth.omega) / (2 * math.pi)


def _phase_err(sol):
    return M.wrap(sol.outputs.obs.theta - sol.outputs.truth.theta)


def _settle_avg(sol, ctx):
    # settle on the one-period average of f̂: harmonics and dc leave a ripple that is not a transient
    f_hat, f_true, _, _ = _fll(sol)
    return M.moving_average(f_hat, ctx.n_period), f_true[-1]


def _drive_err_deg(sol):
    o = sol.outputs
    return jnp.degrees(M.wrap(o.obs.theta - o.theta_e))


def _drive_speed_hat_rpm(sol, ctx):
    return sol.outputs.obs.omega / ctx.p * 30 / math.pi


def scored_position_error(sol, sig, ctx):
    """The position error (rad, :func:`jaxobs.metrics.position_error`) as the metrics score it.  A drive
    started from standstill runs on the I-f angle until its hand-over (the FOC's ``mode`` 0 → 1); the
    observer is not in the loop then and may sit ~90° off while it converges at low speed (measured: the I-f
    phase was 0.12 of a 0.124 ``iae_position``), which is the start-up's doing, not the observer's.  So its
    error counts from the hand-over on (a steady start is in mode 1 from t = 0: unchanged).  Inside the steady
    window it always counts: a drive that has not handed over by then is scored (and flagged lost_sync) on its
    real error, never rewarded with a zero."""
    err = M.position_error(sol, sig)
    if not isinstance(sol.outputs, (DriveOutput, DualOutput)):  # an observer on a signal: no start-up
        return err
    return jnp.where((sol.outputs.mode == 1) | _steady(sol, ctx), err, 0.0)


def _speed_err_rpm(sol, sc):
    """Speed-estimate error of a drive observer, ω̂e/p − ωm, in r/min (mechanical); ``sc`` the drive Scenario."""
    out = sol.outputs
    return (out.obs.omega / sc.par.p - out.omega_m) * 30 / math.pi


def _rpm(omega_m):
    """Mechanical speed, rad/s -> r/min."""
    return omega_m * 30 / math.pi


def _sample_noise(x, mask):
    """rms of the sample-to-sample change over √2: the standard deviation of white noise on ``x``,
    blind to its slow variations (a speed estimate's high-frequency noise)."""
    return M.rms(jnp.diff(x) / math.sqrt(2.0), mask[1:])


# the study metrics, exact forms: the FLL family's on grid signals and recordings, the sensorless drive's
METRICS: dict[str, Metric] = {
    m.name: m
    for m in (
        Metric(
            "settling_freq",
            "s",
            "settling time of the one-period average of the frequency estimate after the event",
            exact=lambda sol, sc, ctx: M.settling_time(sol.t, *_settle_avg(sol, ctx), ctx.band_hz, ctx.t_event),
            # tuning: the frequency estimate itself, a smooth settling time
            smooth=lambda sol, sc, ctx: M.smooth_settling_time(
                sol.t,
                sol.outputs.obs.omega / (2 * math.pi),
                sol.outputs.truth.omega[-1] / (2 * math.pi),
                ctx.band_hz,
                ctx.t_event,
                temperature=ctx.temperature,
            ),
        ),
        Metric(
            "ripple_freq",
            "Hz",
            "steady peak-to-peak frequency error",
            exact=lambda sol, sc, ctx: M.peak_to_peak(_fll(sol)[2], sol.t >= ctx.steady_from),
            smooth=lambda sol, sc, ctx: M.smooth_peak_to_peak(_freq_err_hz(sol), _steady(sol, ctx), 1e-3),
        ),
        Metric(
            "rms_phase",
            "rad",
            "steady rms phase error",
            exact=lambda sol, sc, ctx: M.rms(_fll(sol)[3], sol.t >= ctx.steady_from),
        ),
        Metric(
            "itae_freq",
            "Hz s2",
            "ITAE of the frequency error after the event",
            exact=lambda sol, sc, ctx: M.itae(sol.t, _fll(sol)[2], ctx.t_event),
            # tuning: the same ITAE, the error formed in rad/s and then scaled to Hz (its own rounding)
            smooth=lambda sol, sc, ctx: M.itae(sol.t, _freq_err_hz(sol), ctx.t_event),
        ),
        Metric(
            "iae_phase",
            "rad s",
            "IAE of the phase error after the event",
            exact=lambda sol, sc, ctx: M.iae(sol.t, _fll(sol)[3], ctx.t_event),
        ),
        Metric(
            "pos_err_rms_deg",
            "degree",
            "rms position error in the steady window (electrical)",
            exact=lambda sol, sc, ctx: M.rms(_drive_err_deg(sol), sol.t >= ctx.steady_from),
            closed_loop=True,
        ),
        Metric(
            "pos_err_max_deg",
            "degree",
            "peak position error in the steady window (electrical)",
            exact=lambda sol, sc, ctx: jnp.max(jnp.where(sol.t >= ctx.steady_from, jnp.abs(_drive_err_deg(sol)), 0.0)),
            closed_loop=True,
        ),
        Metric(
            "speed_err_rms_rpm",
            "min-1",
            "rms speed-estimate error in the steady window",
            exact=lambda sol, sc, ctx: M.rms(
                _drive_speed_hat_rpm(sol, ctx) - sol.outputs.omega_m * 30 / math.pi, sol.t >= ctx.steady_from
            ),
            closed_loop=True,
        ),
        Metric(
            "speed_noise_rpm",
            "min-1",
            "speed-estimate noise: rms sample-to-sample change / sqrt(2)",
            exact=lambda sol, sc, ctx: M.rms(
                jnp.diff(_drive_speed_hat_rpm(sol, ctx)) / math.sqrt(2.0), (sol.t >= ctx.steady_from)[1:]
            ),
            # tuning: the scenario's own pole pairs
            smooth=lambda sol, sc, ctx: _sample_noise(
                sol.outputs.obs.omega / sc.par.p * 30 / math.pi, _steady(sol, ctx)
            ),
            closed_loop=True,
        ),
        Metric(
            "pos_bias_deg",
            "degree",
            "|mean position error| in the steady window (electrical): the observer's steady lag",
            exact=lambda sol, sc, ctx: jnp.abs(M.steady_mean(_drive_err_deg(sol), sol.t >= ctx.steady_from)),
            closed_loop=True,
        ),
        Metric(
            "speed_dev_max_rpm",
            "min-1",
            "peak |true speed - reference| after t_event (a load step's dip)",
            exact=lambda sol, sc, ctx: (
                M.peak_deviation(sol.t, sol.outputs.omega_m, sol.outputs.omega_m_ref, ctx.t_event) * 30 / math.pi
            ),
            closed_loop=True,
        ),
        # tuning's metrics (jaxobs_tuning.objective: smooth where the exact one has no useful gradient)
        Metric(
            "iae_freq",
            "Hz s",
            "IAE of the frequency error after the event",
            exact=lambda sol, sc, ctx: M.iae(sol.t, _freq_err_hz(sol), ctx.t_event),
        ),
        Metric(
            "itae_phase",
            "rad s2",
            "ITAE of the phase error after the event",
            exact=lambda sol, sc, ctx: M.itae(sol.t, _phase_err(sol), ctx.t_event),
        ),
        Metric(
            "rms_freq_steady",
            "Hz",
            "steady rms frequency error",
            exact=lambda sol, sc, ctx: M.rms(_freq_err_hz(sol), _steady(sol, ctx)),
        ),
        Metric(
            "rms_phase_steady",
            "rad",
            "steady rms phase error",
            exact=lambda sol, sc, ctx: M.rms(_phase_err(sol), _steady(sol, ctx)),
        ),
        # flux observers on EMF signals, and drive observers
        Metric(
            "iae_position",
            "rad s",
            "IAE of the position error after the event (from the I-f hand-over on)",
            exact=lambda sol, sc, ctx: M.iae(sol.t, scored_position_error(sol, sc, ctx), ctx.t_event),
        ),
        Metric(
            "rms_position_steady",
            "rad",
            "steady rms position error (electrical)",
            exact=lambda sol, sc, ctx: M.rms(M.position_error(sol, sc), _steady(sol, ctx)),
        ),
        Metric(
            "ripple_position",
            "rad",
            "steady peak-to-peak position error (electrical)",
            smooth=lambda sol, sc, ctx: M.smooth_peak_to_peak(M.position_error(sol, sc), _steady(sol, ctx), 1e-4),
        ),
        # drive observers in the closed loop (the scenario is a drive Scenario): settling after a load or speed
        # step at t_event, and the noise the estimates carry.  settling_position settles to a band around the
        # error's own final value (its mean over the steady window), so a steady lag settles; the lag is
        # bias_position
        Metric(
            "settling_position",
            "s",
            "settling time of the position error to its own steady value after the event",
            smooth=lambda sol, sc, ctx: M.smooth_settling_to_steady(
                sol.t,
                scored_position_error(sol, sc, ctx),
                math.radians(ctx.band_deg),
                _steady(sol, ctx),
                ctx.t_event,
                temperature=ctx.temperature,
            ),
            closed_loop=True,
        ),
        Metric(
            "bias_position",
            "rad",
            "|mean position error| in the steady window (electrical)",
            exact=lambda sol, sc, ctx: jnp.abs(M.steady_mean(M.position_error(sol, sc), _steady(sol, ctx))),
        ),
        # the true speed against its reference (r/min): after a speed step its settling, after a load step its
        # recovery time; and the peak deviation after it
        Metric(
            "settling_speed",
            "s",
            "settling time of the speed to its reference after the event",
            smooth=lambda sol, sc, ctx: M.smooth_settling_to_reference(
                sol.t,
                _rpm(sol.outputs.omega_m),
                _rpm(sol.outputs.omega_m_ref),
                ctx.band_rpm,
                ctx.t_event,
                temperature=ctx.temperature,
            ),
            closed_loop=True,
        ),
        Metric(
            "peak_speed_dev",
            "min-1",
            "peak |speed - reference| after the event",
            smooth=lambda sol, sc, ctx: M.smooth_peak_deviation(
                sol.t,
                _rpm(sol.outputs.omega_m),
                _rpm(sol.outputs.omega_m_ref),
                ctx.t_event,
                temperature=ctx.temperature,
            ),
            closed_loop=True,
        ),
        Metric(
            "rms_speed_steady",
            "min-1",
            "steady rms speed-estimate error",
            exact=lambda sol, sc, ctx: M.rms(_speed_err_rpm(sol, sc), _steady(sol, ctx)),
            closed_loop=True,
        ),
        # the speed estimate of an observer run open loop on a signal that carries its truth (a drive log with its
        # encoder, jaxobs.DriveRecording): electrical rad/s, as the recording gives it (its pole pairs are not known)
        Metric(
            "rms_speed_error_steady",
            "rad s-1",
            "steady rms electrical speed-estimate error against the recorded speed",
            exact=lambda sol, sc, ctx: M.rms(sol.outputs.obs.omega - sol.outputs.truth.omega, _steady(sol, ctx)),
            needs_truth=True,
        ),
        Metric(
            "peak_speed_error",
            "rad s-1",
            "peak |electrical speed-estimate error| after the event, against the recorded speed",
            exact=lambda sol, sc, ctx: M.peak_deviation(
                sol.t, sol.outputs.obs.omega, sol.outputs.truth.omega, ctx.t_event
            ),
            # a soft maximum within 0.1·(1 + log n) rad/s of the peak (n: the samples after the event)
            smooth=lambda sol, sc, ctx: M.smooth_peak_deviation(
                sol.t, sol.outputs.obs.omega, sol.outputs.truth.omega, ctx.t_event, temperature=0.1
            ),
            needs_truth=True,
        ),
        # not a function of one run but of the closed loop itself: jaxobs.analysis.stability.lyapunov's largest
        # non-neutral exponent (1/s) at the scenario, which the objective computes
        Metric(
            "stability_margin",
            "s-1",
            "largest non-neutral Lyapunov exponent of the closed loop (minus the stability margin)",
            closed_loop=True,
        ),
    )
}


class Flag(NamedTuple):
    """A per-scenario flag of a study: ``name``, ``long_name``; ``exact(sol, scenario, ctx)`` (a bool; None: the
    ``diverged`` flag itself: the run or a metric not finite); ``diverged``: a diverged scenario counts as
    flagged (``True``), or as not (``False``: the flag is kept only where the run is finite); ``count``: the
    ``long_name`` of ``<name>_count``, the flagged scenarios per design (None: no count); ``dtype``: as stored."""

    name: str
    long_name: str
    exact: Callable | None = None
    diverged: bool = True
    count: str | None = None
    dtype: Any = np.int8


DIVERGED = Flag("diverged", "simulation diverged or a metric is not finite (1: its metrics are NaN)")


def study(
    designs: dict,
    scenarios: AbstractScenarios,
    sampler: AbstractSampler,
    metrics,
    *,
    horizon: float,
    ctx: StudyContext = StudyContext(),
    flags: tuple = (DIVERGED,),
    mask: str | None = "diverged",
    quantiles: tuple = (),
    static: Callable | None = None,
    gains: dict | None = None,
    attrs: dict | None = None,
    save: AbstractSave = SaveAll(),
    chunk_size: int = 2048,
    mesh=None,
    progress=False,
    store=None,
    label: str = "study",
):
    """Every design on every scenario of ``sampler``, drawn from the family ``scenarios``; an ``xarray.Dataset``.

    Args:
        designs: name -> design (an observer), each run on ``scenarios.system(design, scenario)``.
        scenarios: the family (:mod:`jaxobs.families`): its axes label the coordinates, it builds the batches.
        sampler: which points of the axes run, and their layout (:mod:`jaxobs.scenarios`).
        metrics: :class:`~jaxobs.quantities.Metric` s (their ``exact`` forms), one variable each with its units.
        horizon: s, of every run.
        ctx: what the metrics read (:class:`StudyContext`); ``ctx.n_period`` is ``static(design)`` where given.
        flags: the per-scenario flags (:class:`Flag`), stored as variables in this order (``diverged`` among them).
        mask: the flag whose scenarios' metrics are NaN (``diverged``, or ``lost_lock``: no steady error to speak
            of); None: every metric as computed.
        quantiles: quantiles over each design's unmasked scenarios, ``<metric>_q`` (dims design, quantile).
        static: a hashable Python value of a design that the metrics need outside tracing (:class:`StudyContext`'s
            ``n_period``); None: ``ctx`` as given.
        gains: the designs' gain variables (``gain_<name>`` -> (dims, values, attrs)), stored as given.
        attrs: the Dataset's attributes (the options, the provenance).
        save, chunk_size, mesh, progress, store, label: as :func:`jaxobs.runner.run_scenarios` takes them
            (``store``: a :class:`jaxobs.chunkstore.ChunkStore`, the Dataset laid out from it).

    Returns:
        The Dataset: dims ``("design", *sampler dims)``, a variable per metric and flag, ``<flag>_count`` per
        design, the quantiles, the gains; every variable and numeric coordinate with CF ``units`` and ``long_name``,
        the CF-1.8 global attributes (:func:`jaxobs.provenance.cf_dataset`).
    """
    import xarray as xr

    metrics = tuple(metrics)
    names = [m.name for m in metrics]

    def per_scenario(sol, sc, aux):
        c = ctx if aux is None else replace(ctx, n_period=aux)
        vals = {m.name: m.exact(sol, sc, c) for m in metrics}
        finite = sol.ok & jnp.all(jnp.stack([jnp.isfinite(vals[k]) for k in names]))
        for f in flags:
            if f.exact is None:
                vals[f.name] = ~finite
            elif f.diverged:
                vals[f.name] = ~finite | f.exact(sol, sc, c)
            else:
                vals[f.name] = finite & f.exact(sol, sc, c)
        return vals

    run = run_scenarios(
        designs,
        sampler,
        lambda design, sc: scenarios.system(design, sc),
        per_scenario,
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
    values = run.values if store is None else {d: store.load(d) for d in designs}
    dnames = list(designs)
    dims, shape, coords = sampler.layout(lambda name: _axis_meta(scenarios, name))
    dims = ("design", *dims)
    what = "observer design (closing the loop sensorless)" if scenarios.closed_loop else "observer design"
    coords["design"] = ("design", dnames, {"long_name": what})
    if quantiles:
        coords["quantile"] = (
            "quantile",
            np.asarray(quantiles),
            {"units": "1", "long_name": "quantile over the scenarios that kept lock (1: the worst)"},
        )
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
    data.update(gains or {})
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update(scenarios=len(run.points), **(attrs or {}))
    return cf_dataset(ds, f"jaxobs {label}: every design on every scenario, its metrics and flags")


def _axis_meta(scenarios: AbstractScenarios, name: str) -> dict:
    if name == "recording":
        return {"long_name": "recording file (relative to the study file)"}
    if name == "scenario":
        return {"units": "1", "long_name": "scenario given whole (jaxobs.scenarios.Given)"}
    return scenarios.axes[name].attrs


# --------------------------------------------------------------------------
# the FLL study: grid signals (or recordings) with an event, the FLL family's metrics
# --------------------------------------------------------------------------

STUDY_AXES = GRID_SIGNAL_AXES  # the scenarios a study runs: jaxobs.families.GridSignals
STUDY_METRICS = ("settling_freq", "ripple_freq", "rms_phase", "itae_freq", "iae_phase")
LOST_LOCK_LONG_NAME = (
    f"lost lock: diverged, or in the steady window a phase error > {M.LOCK_TOL_DEG:g} deg or a mean frequency "
    f"error > {100 * M.LOCK_FREQ_TOL:g} % (1: lost)"
)


def _fll_settled(sol, sc, ctx):
    return M.settled(sol.t, *_settle_avg(sol, ctx), ctx.band_hz, ctx.t_event)


def _fll_lost_lock(sol, sc, ctx):
    # far from the truth over the steady window: phase error > 45° or mean frequency error > 10 %
    # (jaxobs.metrics, "lost lock")
    out = sol.outputs
    return M.lost_lock(
        out.obs.theta,
        out.truth.theta,
        sol.t >= ctx.steady_from,
        math.radians(M.LOCK_TOL_DEG),
        omega_hat=out.obs.omega,
        omega=out.truth.omega,
        freq_tol=M.LOCK_FREQ_TOL,
    )


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
    """Simulate every FLL design on every scenario; returns an ``xarray.Dataset`` (see module doc):
    :func:`study` on :class:`~jaxobs.families.GridSignals` (or a :class:`~jaxobs.scenarios.Recordings`
    sampler's recorded voltages) with the FLL metrics.

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
    family = RecordedSignals(GridSignals) if recordings else GridSignals(t_event, freq, seed)

    def n_period(obs) -> int:
        # settle on the one-period average of f̂: one period of the grid's frequency (a recording's: the
        # design's nominal one), in samples
        f = float(obs.omega_n) / (2 * math.pi) if recordings else freq
        return max(1, int(round(1.0 / (f * obs.ts))))

    if isinstance(sampler, (Grid, Random, Sobol, LHS)):
        # the signals are built a chunk at a time (jaxobs.runner): a bad axis value is refused here, before
        # anything runs, by building the two scenarios of every axis's least and greatest values (each of
        # grid_signals's checks is a bound on one axis, so these two pass only if every point inside does)
        ends = [tuple(float(f(sampler.axes[k])) for k in sampler.names) for f in (np.min, np.max)]
        family.build(sampler.names, ends)
    gains_present = gain_table(designs)  # each gain's units are its field's (jaxobs.observers.gain)
    # one variable per gain, so each carries its own CF units (a (design, gain_name) array could only say
    # "see gain_units", which no CF reader understands)
    gains = {
        f"gain_{g}": (
            ("design",),
            np.asarray([float(getattr(obs, g)) if g in gain_fields(obs) else np.nan for obs in designs.values()]),
            {"units": gains_present[g].units, "long_name": f"observer gain {g} (NaN: the design has no such gain)"},
        )
        for g in gains_present
    }
    what = "recordings on which the design lost lock" if recordings else "scenarios that lost lock"
    flags = (
        Flag(
            "settled",
            "settled by the horizon (False: settling_freq is censored at horizon - t_event)",
            _fll_settled,
            diverged=False,
            dtype=bool,
        ),
        DIVERGED,
        Flag("lost_lock", LOST_LOCK_LONG_NAME, _fll_lost_lock, count=f"{what} (diverged ones included)"),
    )
    attrs = dict(
        t_event=t_event,
        horizon=horizon,
        steady_from=steady_from,
        band_hz=band_hz,
        sampling=sampler.sampling,
        **({} if recordings else {"seed": sampler.seed if isinstance(sampler, (Random, Sobol, LHS)) else seed}),
        **provenance(
            "jaxobs.study.run_study", digests={"recordings": " ".join(sampler.sha256)} if recordings else None
        ),
    )
    t0 = time.time()
    ds = study(
        designs,
        family,
        sampler,
        [METRICS[k] for k in STUDY_METRICS],
        horizon=horizon,
        ctx=StudyContext(t_event=t_event, steady_from=steady_from, band_hz=band_hz),
        flags=flags,
        static=n_period,
        gains=gains,
        attrs=attrs,
        chunk_size=chunk_size,
        mesh=mesh,
        progress=progress,
        store=store,
    )
    seconds = time.time() - t0
    return (ds, seconds) if return_seconds else ds


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
