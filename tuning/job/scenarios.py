"""A job's scenarios: its family (:mod:`jaxobs.scenarios.families`, named by ``scenarios.signal``) and the batch it
builds from grid points or samples of its axes."""

from __future__ import annotations

import math
from typing import cast

import equinox as eqx

from jaxobs.drive import Drive
from jaxobs.scenarios import Grid, Random
from jaxobs.scenarios.families import AbstractFamily, DriveSetting, RecordedSignals

from .components import W_N
from .recordings import load_recordings
from .spec import DriveSpec, ScenarioSpec


def scenario_points(spec: ScenarioSpec) -> tuple[list[str], list[tuple]]:
    """The axes' names and the scenarios' points: the studies' samplers (a grid, or ``sample`` uniform draws).

    Args:
        spec: The scenario set.

    Returns:
        ``(names, points)``.
    """
    if not spec.axes:
        return [], [()]
    sampler = Random(spec.axes, spec.sample, spec.seed) if spec.sample else Grid(spec.axes)
    return list(sampler.names), sampler.points()


def job_family(
    spec: ScenarioSpec, values: dict, drive: Drive | None = None, drive_spec: DriveSpec | None = None
) -> AbstractFamily:
    """The family of a job's scenario set.

    Args:
        spec: The scenario set.
        values: The component's constructor values (``values["omega_n"]``: the nominal frequency).
        drive: The :class:`~jaxobs.drive.Drive` the family's scenarios run.
        drive_spec: The job's ``[drive]``, whose drive file gives the machine and sensors (None: the shipped
            ``ipmsm002``).

    Returns:
        Its recordings (:meth:`~jaxobs.scenarios.families.AbstractFamily.recorded`), or the family ``spec.signal``
        names,
        built by its own :meth:`~jaxobs.scenarios.families.AbstractFamily.from_toml` from the job's event and seed, the
        component's nominal frequency and, where there is one, the drive.
    """
    if spec.recording is not None:
        return spec.family.recorded()
    freq = float(values.get("omega_n", W_N)) / (2 * math.pi)
    setting = None
    if drive is not None:  # the job's drive (jaxobs_tuning.job.run: the family closes its loop)
        df = DriveSpec().drive_file if drive_spec is None else drive_spec.drive_file
        sensors = None if drive_spec is None or drive_spec.file is None else df.sensors  # shipped: ideal sensors
        setting = DriveSetting(df.machine, drive, sensors)
    table = {"t_event": spec.t_event, "seed": spec.seed}  # [scenarios], as checked (jaxobs_tuning.job.schema)
    return spec.family.from_toml(table, "scenarios", freq_n=freq, drive=setting)


def build_scenarios(spec: ScenarioSpec, family: AbstractFamily) -> tuple[eqx.Module, list[str], list[tuple]]:
    """The batched scenarios of every combination of the axes (or ``sample`` random ones), or the job's recordings.

    Args:
        spec: The scenario set.
        family: The family that builds them (:func:`job_family`).

    Returns:
        ``(scenarios, names, points)``.
    """
    names, combos = scenario_points(spec)
    if spec.recording is not None and isinstance(family, RecordedSignals):
        return load_recordings(spec.recording, family, spec.horizon), names, combos
    # AbstractFamily.build has no return annotation (its body a docstring: inferred None); it returns the batch
    return cast(eqx.Module, family.build(names, combos)), names, combos
