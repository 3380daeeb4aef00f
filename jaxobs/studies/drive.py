"""Robustness studies of sensorless drives: drive observers × a grid (or a Sobol/LHS sample) of scenarios.

A preset of :func:`jaxobs.studies.study.study` on :class:`jaxobs.scenarios.families.DriveScenarios` with the drive
family's default metrics and flags (:attr:`~jaxobs.scenarios.families.DriveScenarios.metrics`, ``.flags``: entries of
the one
metric table, :data:`jaxobs.metrics.METRICS`, in SI units).

    ds = run_drive_study({"C-LESO": cleso, "FA-LESO": faleso}, {"speed_rpm": [300, 600], "dRs": [-0.3, 0.3]},
                         machine=ipmsm_paper002(), horizon=0.3)
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

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from .. import metrics as M
from ..drive import Drive, PMSMParams, Sensors
from ..io.provenance import provenance
from ..observers import AbstractObserver, gain_fields
from ..runtime.chunkstore import ChunkStore
from ..runtime.progress import ProgressArg
from ..scenarios import AbstractSampler, sampler_of
from ..scenarios.families import DRIVE_STUDY_AXES, DriveScenarios, bind_observer, drive_scenarios
from .study import StudyContext, gain_variables, study

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

# the drive study's metrics: the drive family's defaults (jaxobs.metrics.METRICS: SI units, long names, exact forms)
DRIVE_STUDY_METRICS = DriveScenarios.metrics
QUANTILES = (0.5, 0.95, 0.99, 1.0)


def drive_gains(obs: AbstractObserver) -> dict[str, float]:
    """A drive observer's gains: its gain fields (:func:`jaxobs.observers.gain_fields`; what a study binds per
    scenario, ``bound_fields``, is none).

    Args:
        obs: The drive observer.

    Returns:
        gain name -> float.
    """
    return {g: float(getattr(obs, g)) for g in gain_fields(obs)}


FLAGS = tuple(M.METRICS[k] for k in DriveScenarios.flags)  # the drive family's flags (the metric table's)


def run_drive_study(
    designs: dict[str, Any],
    axes: Mapping[str, Any] | AbstractSampler,
    *,
    family: DriveScenarios | None = None,
    machine: PMSMParams | None = None,
    drive: Drive | None = None,
    sensors: Sensors | None = None,
    horizon: float = 0.3,
    steady_from: float | None = None,
    t_event: float | None = None,
    sampling: str | None = None,
    sample: int = 0,
    seed: int | None = None,
    chunk_size: int = 256,
    progress: ProgressArg = None,
    mesh: Mesh | None = None,
    store: ChunkStore | None = None,
) -> xr.Dataset:
    """Run every design (a drive observer closing the drive's loop) on every scenario; an ``xarray.Dataset``.

    Args:
        designs: name -> drive observer.
        axes: a dict of axis values (:data:`DRIVE_STUDY_AXES`) or a sampler, as
            :func:`jaxobs.scenarios.sampler_of` takes them, the same way as :func:`jaxobs.studies.study.run_study`:
            ``sampling="grid"`` (the default without ``sample``) the Cartesian product of the axes;
            ``"random"``, ``"sobol"``, ``"lhs"``: ``sample`` points drawn inside the axes' [min, max].
        family: the drive's scenarios (:class:`~jaxobs.scenarios.families.DriveScenarios`: the true machine, the
            sensorless drive, the steps' time, the noise seed, the sensors); None: built from ``machine``,
            ``drive``, ``sensors``, ``t_event`` (default 0) and ``seed`` (default 0), the keywords this preset
            first took (kept for the Python API and the docs).
        machine, drive, sensors, t_event: without ``family``: the true machine, the ``Drive`` (sensorless), the
            drive's :class:`~jaxobs.drive.Sensors` (None: ideal; the noise and offset axes set their own) and the
            steps' time, s in [0, horizon).
        horizon, steady_from: the run's length and the steady window's start (default half the horizon), s.
        sampling, sample, seed: how a dict of axes is sampled (``seed`` with ``family``: its own).
        chunk_size: scenarios per compiled call.
        progress: ``True`` a tqdm bar on stderr (each design's compilation named), a callable
            ``progress(done, total)`` called after each chunk, ``None``/``False`` nothing
            (:mod:`jaxobs.runtime.progress`).
        mesh: the devices each chunk is split over (:func:`jaxobs.runtime.runner.run_scenarios`; default
            ``jaxobs.batch_mesh()``, every device, as every preset).
        store: a :class:`jaxobs.runtime.chunkstore.ChunkStore`, as in :func:`jaxobs.studies.study.run_study`: each
            chunk's values go to disk as it finishes, the chunks already there are not run again, and the Dataset is
            laid out from the store (the same Dataset as without one).

    Returns:
        The Dataset (module doc).

    Raises:
        ValueError: no designs, an axis or sampler refused, a drive that is not sensorless, ``family`` given with
            its own keywords, or ``horizon``, ``steady_from`` or ``t_event`` out of range.
    """
    if not designs:
        raise ValueError("drive study: at least one design is required")
    if family is None:
        if machine is None or drive is None:
            raise ValueError("drive study: give family (a DriveScenarios), or machine and drive")
        t_event = 0.0 if t_event is None else t_event
        family = DriveScenarios(machine, drive, t_event=t_event, seed=0 if seed is None else seed, sensors=sensors)
    elif not isinstance(family, DriveScenarios):
        raise ValueError(
            f"drive study: family must be DriveScenarios (jaxobs.scenarios.families), got {type(family).__name__}"
        )
    elif any(v is not None for v in (machine, drive, sensors, t_event, seed)):
        raise ValueError("drive study: give family or machine, drive, sensors, t_event and seed, not both")
    machine, drive, t_event, seed = family.machine, family.drive, family.t_event, family.seed
    if isinstance(axes, dict):
        DriveScenarios.check_axes(axes, "axes")
    sampler = sampler_of(axes, sampling=sampling, sample=sample, seed=seed)
    if not drive.sensorless:
        raise ValueError("drive study: the drive must be sensorless (Drive(..., sensorless=True))")
    if not (horizon > 0 and math.isfinite(horizon)):
        raise ValueError(f"horizon must be a finite number of seconds > 0, got {horizon!r}")
    steady_from = 0.5 * horizon if steady_from is None else float(steady_from)
    if not 0 <= steady_from < horizon:
        raise ValueError(f"steady_from must be in [0, horizon), got {steady_from!r}")
    if not (math.isfinite(t_event) and 0 <= t_event < horizon):
        raise ValueError(f"t_event must be in [0, horizon = {horizon:g}) s, got {t_event!r}")
    attrs = dict(horizon=horizon, steady_from=steady_from, t_event=t_event, sampling=sampler.sampling, seed=seed)
    # the true machine (the assumed one is this, moved by the mismatch axes) and the drive's controller
    attrs.update({f"machine_{f}": float(getattr(machine, f)) for f in ("Rs", "Ld", "Lq", "psi_f", "p", "J")})
    attrs.update(drive_ts=float(drive.ts), drive_settle=float(drive.settle))
    # provenance, and nothing that differs between two identical runs (the run time is not stored)
    attrs.update(provenance("jaxobs.studies.drive.run_drive_study"))
    return study(
        designs,
        family,  # built a chunk at a time (the axes are checked above, so no chunk can refuse its points)
        sampler,
        [M.METRICS[k] for k in DRIVE_STUDY_METRICS],
        horizon=horizon,
        ctx=StudyContext(t_event=t_event, steady_from=steady_from),
        flags=FLAGS,
        mask="lost_lock",
        quantiles=QUANTILES,
        gains=gain_variables({d: designs[d] for d in designs}),  # one variable per gain (jaxobs.studies.study too)
        attrs=attrs,
        chunk_size=chunk_size,
        mesh=mesh,
        progress=progress,
        store=store,
        label="drive study",
    )
