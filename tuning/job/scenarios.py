"""A job's scenarios as a batched signal: grid points or samples of its axes, built by the library's builders."""

from __future__ import annotations

import math

from jaxobs import drive as D
from jaxobs.drive_study import drive_scenarios
from jaxobs.scenarios import Grid, Random, emf_signals, grid_signals

from .components import W_N
from .recordings import load_recordings
from .spec import ScenarioSpec


def scenario_points(spec: ScenarioSpec):
    """The axes' names and the scenarios' points: the studies' samplers (a grid, or ``sample`` uniform draws)."""
    if not spec.axes:
        return [], [()]
    sampler = Random(spec.axes, spec.sample, spec.seed) if spec.sample else Grid(spec.axes)
    return list(sampler.names), sampler.points()


def _drive_scenarios(names, combos, seed=0, t_event=0.0, machine="ipmsm002"):
    """The machine's bench (:func:`jaxobs.drive.bench_machine`) for every combination; each starts steady at
    its speed, and the speed_step_rpm / load_step_nm axes step the reference and the load at t_event."""
    return drive_scenarios(D.bench_machine(machine), names, combos, seed=seed, t_event=t_event)


def build_scenarios(spec: ScenarioSpec, values: dict, machine: str = "ipmsm002"):
    """A batched signal for every combination of the axes (or ``sample`` random ones); ``machine``: a drive
    job's (:data:`jaxobs.drive.BENCH_MACHINES`)."""
    names, combos = scenario_points(spec)
    if spec.recording is not None:
        return load_recordings(spec.recording, spec.signal), names, combos
    if spec.signal == "drive":
        return _drive_scenarios(names, combos, spec.seed, spec.t_event, machine), names, combos
    if spec.signal == "grid":
        return (
            grid_signals(
                names, combos, spec.t_event, float(values.get("omega_n", W_N)) / (2 * math.pi), seed=spec.seed
            ),
            names,
            combos,
        )
    return emf_signals(names, combos), names, combos  # back EMFs for the flux observers
