"""``[drive]`` of a drive job: the loop, the start (steady or the I-f start-up, with what it can carry), the
machine's speed range, and the drive the job runs (:func:`job_drive`, on :func:`jaxobs.drive.bench_drive`)."""

from __future__ import annotations

import dataclasses
import math

from jaxobs import drive as D
from jaxobs.drive import BENCH_MACHINES

from .components import COMPONENTS
from .fields import JobError, get_field, no_unknown, show
from .spec import DriveSpec, ScenarioSpec


def check_standstill(drive: DriveSpec, spec: ScenarioSpec, where: str) -> None:
    """What an I-f start-up can do, checked before any run (``--check`` too): the load it must carry, the
    speed reference it hands over to, and a steady window after its hand-over."""
    par = D.bench_machine(drive.machine)
    s = D.IfStartup.for_machine(par)
    axes = spec.axes
    rpm_sw = float(s.omega_switch) / par.p * 30 / math.pi
    t_ho = D.if_handover_earliest(par)
    if spec.steady_from < t_ho:
        raise JobError(
            f"{where}.steady_from",
            f"must be >= {t_ho:.3g} s with start = 'standstill' (the I-f start-up hands over at {t_ho:.3g} s at "
            f"the earliest), got {spec.steady_from:g}",
        )
    speeds = axes.get("speed_rpm", [600.0])
    steps = axes.get("speed_step_rpm", [0.0])
    low = min(min(abs(v) for v in speeds), min(abs(v + d) for v in speeds for d in steps))
    if low < rpm_sw:
        raise JobError(
            f"{where}.grid.speed_rpm",
            f"must be >= the I-f hand-over speed {rpm_sw:.4g} r/min with start = 'standstill' (with any "
            f"speed_step_rpm), got {low:g}",
        )
    dj = max(axes.get("dJ", [0.0]))
    limit = D.if_load_limit(par, dj)
    load = max(abs(v) for v in axes.get("load_nm", [0.0]))
    if spec.t_event < t_ho:  # a load step during the start-up is carried by it too
        load += max(abs(v) for v in axes.get("load_step_nm", [0.0]))
    if load > limit:
        raise JobError(
            f"{where}.grid.load_nm",
            f"the load during the I-f start-up must be <= {limit:.4g} N·m on {drive.machine} (0.7246 K_t I_f − "
            f"J a_peak − B ω_sw, jaxobs.drive.if_load_limit), got {load:g}",
        )


def parse_start(dt: dict, drive: DriveSpec, scen) -> DriveSpec:
    """``[drive] start``: "steady" or "standstill" (the I-f start-up must fit in the horizon; it hands over
    itself, so ``handover`` stays 0; :func:`check_standstill`).  ``loop = "sensored"`` with a standstill
    start is allowed: the same I-f start-up hands over to the encoder's angle (by the same agreement test),
    and the observer estimates beside it from t = 0, scored from the hand-over on."""
    start = get_field(dt, "start", "drive.start", str, "steady")
    if start not in ("steady", "standstill"):
        raise JobError("drive.start", f"must be 'steady' or 'standstill', got {show(start)}")
    drive = dataclasses.replace(drive, start=start)
    if start == "standstill":
        if drive.handover > 0:
            raise JobError("drive.handover", "must be 0 with start = 'standstill' (the I-f start-up hands over)")
        s = job_drive(drive).startup
        t_if = float(s.omega_switch / s.accel + s.hold + s.dwell)
        if scen.horizon <= t_if:
            raise JobError(
                "drive.start", f"'standstill' needs horizon > {t_if:.3g} s (the I-f start-up), got {scen.horizon:g}"
            )
        if scen.recording is None:  # a recording has no drive to start
            check_standstill(drive, scen, "scenarios")
    return drive


def check_drive_speeds(spec: ScenarioSpec, where: str, machine: str) -> None:
    """A drive job's grid (``where``.grid) through :func:`check_speed_axes`, at --check time."""
    check_speed_axes(spec.axes, f"{where}.grid", machine)


def check_speed_axes(axes: dict, where: str, machine: str) -> None:
    """The one check of drive speeds, for jobs and studies: ``speed_rpm`` and ``speed_rpm + speed_step_rpm``
    (every combination of the axes, so every point a sampler draws inside their ranges too) within ± the
    machine's :func:`jaxobs.drive.drive_speed_limit_rpm`; ``where``: the table holding the axes."""
    speeds, steps = axes.get("speed_rpm"), axes.get("speed_step_rpm", [0.0])
    if not speeds:
        return
    n_max = D.drive_speed_limit_rpm(D.bench_machine(machine))
    rng = f"must be in [1, {n_max:.0f}] r/min on {machine} (its back EMF reaches the inverter's voltage limit there)"
    for i, x in enumerate(speeds):
        if abs(x) > n_max:
            raise JobError(f"{where}.speed_rpm[{i}]", f"{rng}, got {x:g}")
    for j, d in enumerate(steps):
        after = max(speeds) + d if d >= 0 else min(speeds) + d  # the extreme speed after this step
        if abs(after) > n_max:
            raise JobError(
                f"{where}.speed_step_rpm[{j}]",
                f"speed_rpm + speed_step_rpm must be in [-{n_max:.0f}, {n_max:.0f}] r/min on {machine} (its back "
                f"EMF reaches the inverter's voltage limit there), got {after:g}",
            )


def job_drive(spec: DriveSpec | None = None):
    """The drive a ``signal = "drive"`` job runs: FOC on its machine's bench; sensorless by default (``spec``)."""
    spec = DriveSpec() if spec is None else spec
    par = D.bench_machine(spec.machine)
    startup = D.IfStartup.for_machine(par) if spec.start == "standstill" else None  # [drive] start
    return D.bench_drive(
        par,
        sensorless=spec.loop == "sensorless",
        handover=spec.handover,
        settle=spec.settle,
        startup=startup,
        speed_schedule=spec.speed_schedule,
    )


def parse_drive(dt: dict, comp: str, scen: ScenarioSpec) -> DriveSpec:
    """``[drive]`` of a drive job of component ``comp`` (its table ``dt``) on the scenarios ``scen``."""
    info = COMPONENTS[comp]
    no_unknown(dt, ("loop", "handover", "settle", "start", "machine", "speed_schedule"), "drive")
    loop = get_field(dt, "loop", "drive.loop", str, "sensorless")
    if loop not in ("sensorless", "sensored"):
        raise JobError("drive.loop", f"must be 'sensorless' or 'sensored', got {show(loop)}")
    handover = get_field(dt, "handover", "drive.handover", float, 0.0)
    if not 0.0 <= handover < scen.horizon:
        raise JobError("drive.handover", f"must be in [0, horizon = {scen.horizon:g}) s, got {handover:g}")
    settle = get_field(dt, "settle", "drive.settle", float, 0.2)
    if not 0.0 <= settle <= 10.0:
        raise JobError("drive.settle", f"must be in [0, 10] s, got {settle:g}")
    machine = get_field(dt, "machine", "drive.machine", str, info.machines[0])
    if machine not in BENCH_MACHINES:
        raise JobError("drive.machine", f"must be one of {', '.join(BENCH_MACHINES)}, got {show(machine)}")
    if machine not in info.machines:
        raise JobError(
            "drive.machine",
            f"{comp} cannot run on {machine} ({BENCH_MACHINES[machine]}); allowed: {', '.join(info.machines)}",
        )
    # the FOC's speed-loop schedule (FOC.speed_gains): 0 off; N keeps the speed loop N times slower than ωe,
    # the flux observers' low-speed fix (docs/stability.md: N = 6 holds 400 and 200 r/min on 000's SPMSM)
    schedule = get_field(dt, "speed_schedule", "drive.speed_schedule", float, 0.0)
    if not 0.0 <= schedule <= 1000.0:
        raise JobError("drive.speed_schedule", f"must be 0 (off) or a ratio in (0, 1000], got {schedule:g}")
    spec = DriveSpec(loop, handover, settle, machine=machine, speed_schedule=schedule)
    return parse_start(dt, spec, scen)
