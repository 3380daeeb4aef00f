"""Robustness studies of sensorless drives: drive observers × a grid (or a Sobol/LHS sample) of scenarios.

    ds = run_drive_study({"C-LESO": cleso, "FA-LESO": faleso}, {"speed_rpm": [300, 600], "dRs": [-0.3, 0.3]},
                         machine=ipmsm_paper002(), horizon=0.3)
    ds["pos_err_rms_deg"].sel(design="FA-LESO").max()
    ds["pos_err_rms_deg_q"].sel(design="FA-LESO", quantile=0.99)

Every design is the observer that closes the loop (``Drive(sensorless=True)``)
on every scenario, each scenario started in its steady state (its speed, its
load, the observer settled before t = 0; DESIGN.md).  The observer is bound to
the scenario: its resistance and inductance are the scenario's *assumed*
machine (``est_par``: the mismatch axes move it), its initial speed the
scenario's.  Axes (all optional; a value per scenario):

- ``speed_rpm`` (r/min), ``load_nm`` (N·m): the operating point;
- ``speed_step_rpm`` (r/min), ``load_step_nm`` (N·m): steps of the speed reference and of the load at
  ``t_event`` (s, in [0, horizon); 0 by default: a step at the start);
- ``dRs``, ``dLd``, ``dLq``, ``dpsi``: relative errors of the assumed machine
  (est = true · (1 + v)); ``dJ``: relative change of the true inertia (the
  controller keeps the nominal one);
- ``i_noise`` (A), ``u_noise`` (V): white noise on the current and voltage
  measurements (standard deviation; the key is per scenario from ``seed``);
- ``dead_time`` (s): inverter dead time.

Metrics per scenario, over the steady window [steady_from, horizon):
``pos_err_rms_deg`` and ``pos_err_max_deg`` (|θ̂e − θe|, electrical degrees),
``speed_err_rms_rpm`` (ω̂e/p − ωm, r/min), ``speed_noise_rpm`` (the
sample-to-sample noise of ω̂e/p: rms of the first difference over √2) and
``lost_lock``: the scenario diverged (a non-finite value) or its position error
exceeded 90° (electrical) in the steady window — a per-scenario flag, never fatal, with the
definition the FLL studies and the tuning share (:mod:`jaxobs.metrics`, "lost lock": 90° for a drive,
where the current vector beyond it brakes the machine; ``diverged`` flags the non-finite ones alone);
``lost_speed``: diverged, or the drive missed its speed reference over the steady window
(:func:`jaxobs.metrics.lost_speed`: mean |ωm − ωm*| > 20 % of mean |ωm*|, at least 20 r/min), counted in
``lost_speed_count`` — an observer locked to a rotor that turns the wrong way holds lock but not speed.  The
Dataset has dims ``("design", *axes)`` (a grid) or ``("design", "sample")``
(a sample, the axes as coordinates), quantiles over the scenarios of every
metric (``<metric>_q`` with a ``quantile`` coordinate 0.5, 0.95, 0.99, 1.0;
lost-lock scenarios excluded from them and counted in ``lost_lock_count``).  Every variable and
coordinate has ``units`` (UDUNITS strings: ``degree``; ``min-1`` for r/min) and ``long_name``; each gain is
its own variable ``gain_<name>`` (dim ``design``, its own ``units``, NaN where a design has no such gain); the
attributes hold the options, the true machine (``machine_Rs``, ...) and the versions, nothing that changes between two
identical runs.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from . import metrics as M
from .drive import CF_UNITS, DRIVE_AXES, RPM, ClosedLoop, Drive, PMSMParams, Profile, Scenario, scenario_batch
from .observers import AbstractDriveObserver
from .provenance import provenance
from .runner import run_scenarios
from .scenarios import LHS, Grid, Sobol
from .sharding import batch_mesh

SAMPLERS = {"sobol": Sobol, "lhs": LHS}  # sampling name -> sampler (jaxobs.scenarios)

__all__ = [
    "DRIVE_STUDY_AXES",
    "DRIVE_STUDY_AXIS_NAMES",
    "DRIVE_STUDY_METRICS",
    "DRIVE_GAIN_UNITS",
    "QUANTILES",
    "run_drive_study",
    "drive_scenarios",
    "drive_gains",
]

# axis → (unit, allowed range): the axes of drive studies and drive jobs, a part of the one table of drive
# axes (jaxobs.drive.DRIVE_AXES, same names and ranges).  Not here: dL (dLd and dLq together), the sensor
# offsets and a per-scenario seed (a study's noise keys come from its own seed)
DRIVE_STUDY_AXES = {
    name: (unit, rng)
    for name, (unit, rng, _) in DRIVE_AXES.items()
    if name not in ("dL", "u_offset_alpha", "u_offset_beta", "i_offset_alpha", "i_offset_beta", "seed")
}
DRIVE_STUDY_METRICS = {
    "pos_err_rms_deg": ("deg", "rms position error in the steady window (electrical)"),
    "pos_err_max_deg": ("deg", "peak position error in the steady window (electrical)"),
    "speed_err_rms_rpm": ("r/min", "rms speed-estimate error in the steady window"),
    "speed_noise_rpm": ("r/min", "speed-estimate noise: rms sample-to-sample change / sqrt(2)"),
    "pos_bias_deg": ("deg", "|mean position error| in the steady window (electrical): the observer's steady lag"),
    "speed_dev_max_rpm": ("r/min", "peak |true speed - reference| after t_event (a load step's dip)"),
}
QUANTILES = (0.5, 0.95, 0.99, 1.0)
# axis -> what it is, in words (the NetCDF long_name and the figures' labels)
DRIVE_STUDY_AXIS_NAMES = {name: what for name, (_, _, what) in DRIVE_AXES.items()}
# a drive observer's gains (the tuned ones; the assumed machine and the initial speeds are bound per scenario)
# and their units: the LESOs of 002 (FA-LESO: ê/e = (k2 s + k1)/(s² + (k2 − jω̂e)s + k1)), the normalized PLLs
# (ω̂ = kp·err + ki∫err, err in rad), the flux observers of 000 (k, K1, K2, lam dimensionless: lam is the
# frequency-normalized FLL gain, jaxobs.observers.flux)
DRIVE_GAIN_UNITS = {
    "omega0": "rad s-1",
    "K_r": "s-2",
    "omega_c": "rad s-1",
    "k1": "s-2",
    "k2": "s-1",
    "k": "1",
    "K1": "1",
    "K2": "1",
    "lam": "1",
    "kp_pll": "s-1",
    "ki_pll": "s-2",
}


def _axis_meta(name: str) -> dict:
    unit = DRIVE_STUDY_AXES[name][0]
    return {"units": CF_UNITS.get(unit, unit), "long_name": DRIVE_STUDY_AXIS_NAMES[name]}


def _check_axes(axes: dict):
    if not axes:
        raise ValueError("drive study: at least one axis is required")
    for name, vals in axes.items():
        if name not in DRIVE_STUDY_AXES:
            raise ValueError(f"axes.{name}: unknown drive-study axis; allowed: {', '.join(DRIVE_STUDY_AXES)}")
        unit, (lo, hi) = DRIVE_STUDY_AXES[name]
        arr = np.asarray(vals, dtype=float)
        if arr.ndim != 1 or arr.size < 1 or not np.all(np.isfinite(arr)) or np.any(arr < lo) or np.any(arr > hi):
            raise ValueError(f"axes.{name} must be a non-empty list of numbers in [{lo:g}, {hi:g}] {unit}")


def drive_scenarios(
    machine: PMSMParams, names, combos, *, seed: int = 0, t_event: float = 0.0, first: int = 0
) -> Scenario:
    """A batched Scenario (leading axis len(combos)), one per combination of the named axes' values
    (:func:`jaxobs.drive.scenario_batch` on ``machine``, noise keys from ``seed``; ``first``: the index of
    ``combos[0]`` among all the scenarios, for a chunk built on its own).

    Each starts steady at ``speed_rpm`` (600 r/min without the axis) and ``load_nm``; the speed reference
    and the load step by ``speed_step_rpm`` and ``load_step_nm`` at ``t_event`` (s; both 0 by default: no event).
    """
    if not (math.isfinite(t_event) and t_event >= 0):
        raise ValueError(f"t_event must be a finite number of seconds >= 0, got {t_event!r}")
    two = Profile([0.0, t_event], [600.0 * RPM] * 2, kind="step")  # before / after the event
    zero = Profile([0.0, t_event], [0.0, 0.0], kind="step")
    base = Scenario(machine, speed_ref=two, load=zero, omega_m0=600.0 * RPM)
    return scenario_batch(base, names, combos, seed=seed, t_event=t_event, first=first)


def bind_observer(obs, sc: Scenario):
    """The observer bound to the scenario's assumed machine and initial speed: ``obs.bind(est_par, p̂·ω_m0)``
    (:meth:`jaxobs.observers.AbstractDriveObserver.bind`, the one binding), as studies and drive jobs run it."""
    if not isinstance(obs, AbstractDriveObserver):
        raise ValueError(f"drive study: {type(obs).__name__} is not a drive observer (a LESO or a flux observer)")
    return obs.bind(sc.est_par, sc.est_par.p * sc.omega_m0)


def drive_gains(obs) -> dict:
    """A drive observer's gains (name -> float): its fields named in :data:`DRIVE_GAIN_UNITS`, less what a study
    binds per scenario (``bound_fields``: a flux observer's ``omega0`` is its initial speed, a LESO's its
    bandwidth, a gain)."""
    fields = {f.name for f in dataclasses.fields(obs)} - set(type(obs).bound_fields)
    return {g: float(getattr(obs, g)) for g in DRIVE_GAIN_UNITS if g in fields}


def gain_variables(designs: dict) -> dict:
    """The designs' gains as Dataset variables ``gain_<name>`` over ``design``, each with its own CF units (NaN
    where a design has no such gain): what drive studies and envelopes write."""
    gains = {d: drive_gains(obs) for d, obs in designs.items()}
    return {
        f"gain_{g}": (
            ("design",),
            np.asarray([gains[d].get(g, np.nan) for d in designs], dtype=float),
            {"units": DRIVE_GAIN_UNITS[g], "long_name": f"observer gain {g} (NaN: the design has no such gain)"},
        )
        for g in DRIVE_GAIN_UNITS
        if any(g in gains[d] for d in designs)
    }


def run_drive_study(
    designs: dict,
    axes: dict,
    *,
    machine: PMSMParams,
    drive: Drive,
    horizon: float = 0.3,
    steady_from: float | None = None,
    t_event: float = 0.0,
    sampling: str = "grid",
    sample: int = 0,
    seed: int = 0,
    chunk_size: int = 256,
    progress=None,
    mesh=None,
    store=None,
):
    """Run every design (a drive observer closing ``drive``'s loop) on every scenario; an ``xarray.Dataset``.

    ``sampling="grid"``: the Cartesian product of the axes; ``"sobol"``/``"lhs"``: ``sample``
    points drawn by scipy.stats.qmc inside the axes' [min, max].  ``progress``: ``True`` a tqdm bar
    on stderr (each design's compilation named), a callable ``progress(done, total)`` called after
    each chunk, ``None``/``False`` nothing (:mod:`jaxobs.progress`).  ``mesh``: the devices each chunk is
    split over (:func:`jaxobs.runner.run_scenarios`; default one device, as before the runner was shared).
    ``store``: a :class:`jaxobs.chunkstore.ChunkStore`, as in :func:`jaxobs.study.run_study`: each chunk's
    values go to disk as it finishes, the chunks already there are not run again, and the Dataset is laid
    out from the store (the same Dataset as without one).
    """
    import xarray as xr

    if not designs:
        raise ValueError("drive study: at least one design is required")
    _check_axes(axes)
    if not drive.sensorless:
        raise ValueError("drive study: the drive must be sensorless (Drive(..., sensorless=True))")
    if not (horizon > 0 and math.isfinite(horizon)):
        raise ValueError(f"horizon must be a finite number of seconds > 0, got {horizon!r}")
    steady_from = 0.5 * horizon if steady_from is None else float(steady_from)
    if not 0 <= steady_from < horizon:
        raise ValueError(f"steady_from must be in [0, horizon), got {steady_from!r}")
    if not (math.isfinite(t_event) and 0 <= t_event < horizon):
        raise ValueError(f"t_event must be in [0, horizon = {horizon:g}) s, got {t_event!r}")
    if sampling == "grid":
        sampler = Grid(axes)
    elif sampling in SAMPLERS:
        if not (isinstance(sample, int) and sample >= 1):
            raise ValueError(f"sample must be an integer >= 1 with sampling={sampling!r}, got {sample!r}")
        sampler = SAMPLERS[sampling](axes, sample, seed)
    else:
        raise ValueError(f"sampling must be 'grid', 'sobol' or 'lhs', got {sampling!r}")
    p = machine.p

    def metrics_of(sol, _scenario, _aux):
        o = sol.outputs
        steady = sol.t >= steady_from
        err = jnp.degrees(M.wrap(o.obs.theta - o.theta_e))
        w_hat = o.obs.omega / p * 30 / math.pi
        w_err = w_hat - o.omega_m * 30 / math.pi
        m = {
            "pos_err_rms_deg": M.rms(err, steady),
            "pos_err_max_deg": jnp.max(jnp.where(steady, jnp.abs(err), 0.0)),
            "speed_err_rms_rpm": M.rms(w_err, steady),
            "speed_noise_rpm": M.rms(jnp.diff(w_hat) / math.sqrt(2.0), steady[1:]),
            "pos_bias_deg": jnp.abs(M.steady_mean(err, steady)),
            "speed_dev_max_rpm": M.peak_deviation(sol.t, o.omega_m, o.omega_m_ref, t_event) * 30 / math.pi,
        }
        finite = sol.ok & jnp.all(jnp.stack([jnp.isfinite(v) for v in m.values()]))
        m["lost"] = ~finite | M.lost_lock(o.obs.theta, o.theta_e, steady, math.radians(M.LOCK_TOL_DRIVE_DEG))
        m["diverged"] = ~finite
        m["off"] = ~finite | M.lost_speed(o.omega_m, o.omega_m_ref, steady)  # missed its speed reference
        return m

    run = run_scenarios(
        designs,
        sampler,
        lambda obs, s: ClosedLoop(drive, bind_observer(obs, s), s),
        metrics_of,
        horizon=horizon,
        # built a chunk at a time (the axes are checked above, so no chunk can refuse its points)
        build=lambda names, points, first: drive_scenarios(
            machine, names, points, seed=seed, t_event=t_event, first=first
        ),
        chunk_size=chunk_size,
        mesh=batch_mesh(jax.devices()[:1]) if mesh is None else mesh,
        progress=progress,
        label="drive study",
        sink=store,
    )
    n = len(run.points)
    values = run.values if store is None else {d: store.load(d) for d in designs}
    results = {d: (v, v["lost"], v["diverged"], v["off"]) for d, v in values.items()}
    dnames = list(designs)
    dims, shape, coords = sampler.layout(_axis_meta)
    dims = ("design", *dims)
    coords["design"] = ("design", dnames, {"long_name": "observer design (closing the loop sensorless)"})
    qs = np.asarray(QUANTILES)
    coords["quantile"] = (
        "quantile",
        qs,
        {"units": "1", "long_name": "quantile over the scenarios that kept lock (1: the worst)"},
    )
    data = {}
    for k, (label, long_name) in DRIVE_STUDY_METRICS.items():
        unit = CF_UNITS.get(label, label)  # the label's UDUNITS spelling in the file
        vals = np.stack([np.where(results[d][1], np.nan, results[d][0][k]) for d in dnames])  # (design, n)
        data[k] = (dims, vals.reshape((len(dnames), *shape)), {"units": unit, "long_name": long_name})
        q = np.stack([np.nanquantile(v, qs) if np.isfinite(v).any() else np.full(qs.shape, np.nan) for v in vals])
        data[f"{k}_q"] = (("design", "quantile"), q, {"units": unit, "long_name": f"{long_name}, quantiles"})
    lost = np.stack([results[d][1] for d in dnames])
    data["lost_lock"] = (
        dims,
        lost.reshape((len(dnames), *shape)).astype(np.int8),
        {
            "units": "1",
            "long_name": f"lost lock: diverged, or position error > {M.LOCK_TOL_DRIVE_DEG:g} deg (electrical) "
            "in the steady window (1: lost)",
        },
    )
    data["lost_lock_count"] = (
        ("design",),
        lost.sum(axis=1).astype(np.int64),
        {"units": "1", "long_name": "scenarios that lost lock (diverged ones included)"},
    )
    off = np.stack([results[d][3] for d in dnames])
    data["lost_speed"] = (
        dims,
        off.reshape((len(dnames), *shape)).astype(np.int8),
        {
            "units": "1",
            "long_name": f"lost speed: diverged, or the steady window's mean |speed - reference| > "
            f"{100 * M.SPEED_TOL:g} % of the mean |reference| (at least {M.SPEED_FLOOR_RPM:g} r/min) (1: lost)",
        },
    )
    data["lost_speed_count"] = (
        ("design",),
        off.sum(axis=1).astype(np.int64),
        {"units": "1", "long_name": "scenarios that missed their speed reference (diverged ones included)"},
    )
    div = np.stack([results[d][2] for d in dnames])
    data["diverged"] = (
        dims,
        div.reshape((len(dnames), *shape)).astype(np.int8),
        {"units": "1", "long_name": "simulation diverged or a metric is not finite (1: its metrics are NaN)"},
    )
    data.update(gain_variables({d: designs[d] for d in dnames}))  # one variable per gain (jaxobs.study too)
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update(
        horizon=horizon, steady_from=steady_from, t_event=t_event, scenarios=n, sampling=sampling, seed=seed
    )
    # the true machine (the assumed one is this, moved by the mismatch axes) and the drive's controller
    for f in ("Rs", "Ld", "Lq", "psi_f", "p", "J"):
        ds.attrs[f"machine_{f}"] = float(getattr(machine, f))
    ds.attrs.update(drive_ts=float(drive.ts), drive_settle=float(drive.settle))
    # provenance, and nothing that differs between two identical runs (the run time is not stored)
    ds.attrs.update(provenance("jaxobs.drive_study.run_drive_study"))
    return ds
