"""Robustness studies of sensorless drives: drive observers × a grid (or a Sobol/LHS sample) of scenarios.

The one study preset, :func:`jaxobs.studies.study.run_study`, on a :class:`jaxobs.scenarios.families.DriveScenarios`
family, which declares the drive study (:meth:`~jaxobs.scenarios.families.DriveScenarios.study_plan`): its default
metrics and flags (:attr:`~jaxobs.scenarios.families.DriveScenarios.metrics`, ``.flags``: entries of the one metric
table, :data:`jaxobs.metrics.METRICS`, in SI units), its quantiles and its attributes.

    family = DriveScenarios(ipmsm_paper002(), drive)
    ds = run_study({"C-LESO": cleso, "FA-LESO": faleso}, {"speed_rpm": [300, 600], "dRs": [-0.3, 0.3]},
                   family=family, horizon=0.3)
    ds["rms_position_steady"].sel(design="FA-LESO").max()           # rad
    ds["rms_position_steady_q"].sel(design="FA-LESO", quantile=0.99)

Every design is the observer that closes the loop (``Drive(sensorless=True)``)
on every scenario, each scenario started in its steady state (its speed, its
load, the observer settled before t = 0).  The observer is bound to
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
``rms_position_steady`` and ``peak_position_steady`` (|θ̂e − θe|, electrical rad),
``rms_speed_estimate_steady`` (ω̂e/p − ωm, rad/s, p the scenario's), ``speed_noise`` (the
sample-to-sample noise of ω̂e/p: rms of the first difference over √2, rad/s), ``bias_position`` (rad),
``peak_speed_deviation`` (rad/s, after ``t_event``; tables and figures show them in degrees and r/min:
:meth:`jaxobs.metrics.Metric.shown`) and
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
coordinate has ``units`` (UDUNITS strings: ``rad``, ``rad s-1``) and ``long_name``; each gain is
its own variable ``gain_<name>`` (dim ``design``, its own ``units``, NaN where a design has no such gain); the
attributes hold the options, the true machine (``machine_Rs``, ...) and the versions, nothing that changes between two
identical runs.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, cast

from ..drive import Drive, PMSMParams, Sensors
from ..observers import AbstractObserver, gain_fields
from ..runtime.chunkstore import ChunkStore
from ..runtime.progress import ProgressArg
from ..scenarios import AbstractSampler
from ..scenarios.families import DRIVE_STUDY_AXES, DriveScenarios, bind_observer, drive_scenarios
from .study import run_study

if TYPE_CHECKING:
    import xarray as xr
    from jax.sharding import Mesh

__all__ = [
    "DRIVE_STUDY_AXES",
    "DRIVE_STUDY_METRICS",
    "QUANTILES",
    "run_drive_study",
    "drive_scenarios",
    "bind_observer",
    "drive_gains",
]

# the drive study's metrics and quantiles: the drive family's (jaxobs.metrics.METRICS: SI units, long names)
DRIVE_STUDY_METRICS = DriveScenarios.metrics
QUANTILES = DriveScenarios.study_quantiles


def drive_gains(obs: AbstractObserver) -> dict[str, float]:
    """A drive observer's gains: its gain fields (:func:`jaxobs.observers.gain_fields`; what a study binds per
    scenario, ``bound_fields``, is none).

    Args:
        obs: The drive observer.

    Returns:
        gain name -> float.
    """
    return {g: float(getattr(obs, g)) for g in gain_fields(obs)}


def run_drive_study(
    designs: dict[str, Any],
    axes: Mapping[str, Any] | AbstractSampler,
    *,
    family: DriveScenarios | None = None,
    machine: PMSMParams | None = None,
    drive: Drive | None = None,
    sensors: Sensors | None = None,
    t_event: float | None = None,
    seed: int | None = None,
    horizon: float = 0.3,
    steady_from: float | None = None,
    sampling: str | None = None,
    sample: int = 0,
    chunk_size: int = 256,
    progress: ProgressArg = None,
    mesh: Mesh | None = None,
    store: ChunkStore | None = None,
) -> xr.Dataset:
    """Deprecated: ``run_study(designs, axes, family=DriveScenarios(machine, drive, ...))``, the one study preset,
    which this calls with the same Dataset.

    Args:
        designs: name -> drive observer.
        axes: a dict of axis values (:data:`DRIVE_STUDY_AXES`) or a sampler.
        family: the drive's scenarios; None: ``DriveScenarios(machine, drive, t_event=t_event or 0, seed=seed or 0,
            sensors=sensors)``.
        machine, drive, sensors, t_event, seed: without ``family``: what it is built from.
        horizon, steady_from, sampling, sample, chunk_size, progress, mesh, store: as
            :func:`jaxobs.studies.study.run_study` takes them.

    Returns:
        The Dataset (module doc).

    Raises:
        ValueError: ``family`` given with its own keywords, or neither it nor ``machine`` and ``drive``; what
            :func:`~jaxobs.studies.study.run_study` refuses.
    """
    warnings.warn(
        "run_drive_study is deprecated: call jaxobs.studies.study.run_study(designs, axes, "
        "family=DriveScenarios(machine, drive, ...))",
        DeprecationWarning,
        stacklevel=2,
    )
    if family is None:
        if machine is None or drive is None:
            raise ValueError("drive study: give family (a DriveScenarios), or machine and drive")
        t_event = 0.0 if t_event is None else t_event
        family = DriveScenarios(machine, drive, t_event=t_event, seed=0 if seed is None else seed, sensors=sensors)
    elif any(v is not None for v in (machine, drive, sensors, t_event, seed)):
        raise ValueError("drive study: give family or machine, drive, sensors, t_event and seed, not both")
    ds = run_study(  # no return_seconds: the Dataset alone
        designs,
        axes,
        family=family,
        horizon=horizon,
        steady_from=steady_from,
        sampling=sampling,
        sample=sample,
        chunk_size=chunk_size,
        progress=progress,
        mesh=mesh,
        store=store,
    )
    return cast("xr.Dataset", ds)
