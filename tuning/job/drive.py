"""``[drive]`` of a drive job: the drive file (a shipped one by name, the user's by ``file``, or its tables
inline), the loop, the start (steady or the I-f start-up, with what it can carry), the drive's speed range, and
the drive the job runs (:func:`job_drive`, :meth:`jaxobs.drive.DriveFile.drive_for`)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Literal, overload

from jaxobs import drive as D
from jaxobs.drive import SHIPPED_DRIVES, Drive, DriveFile, drive_from_table, read_drive, shipped_drive

from .components import COMPONENTS
from .fields import JobError, get_field, no_unknown, show
from .spec import DriveSpec, ScenarioSpec


def check_standstill(drive: DriveSpec, spec: ScenarioSpec, where: str) -> None:
    """What an I-f start-up can do, checked before any run (``--check`` too): the load it must carry, the
    speed reference it hands over to, and a steady window after its hand-over.

    Args:
        drive: The job's ``[drive]`` (``start = "standstill"``).
        spec: A scenario set of the job.
        where: The set's table in errors.

    Raises:
        JobError: A steady window that starts before the hand-over, a speed below the hand-over speed or a
            load the start-up cannot carry, naming the field.
    """
    df = drive.drive_file
    par, s = df.machine, df.startup
    axes = spec.axes
    rpm_sw = float(s.omega_switch) / par.p * 30 / math.pi
    t_ho = D.if_handover_earliest(par, s)
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
    limit = D.if_load_limit(par, dj, s)
    load = max(abs(v) for v in axes.get("load_nm", [0.0]))
    if spec.t_event < t_ho:  # a load step during the start-up is carried by it too
        load += max(abs(v) for v in axes.get("load_step_nm", [0.0]))
    if load > limit:
        raise JobError(
            f"{where}.grid.load_nm",
            f"the load during the I-f start-up must be <= {limit:.4g} N·m on {drive.machine} (0.7246 K_t I_f − "
            f"J a_peak − B ω_sw, jaxobs.drive.if_load_limit), got {load:g}",
        )


def parse_start(dt: dict, drive: DriveSpec, scen: ScenarioSpec) -> DriveSpec:
    """``[drive] start``: "steady" or "standstill" (the I-f start-up must fit in the horizon; it hands over
    itself, so ``handover`` stays 0; :func:`check_standstill`).  ``loop = "sensored"`` with a standstill
    start is allowed: the same I-f start-up hands over to the encoder's angle (by the same agreement test),
    and the observer estimates beside it from t = 0, scored from the hand-over on.

    Args:
        dt: The ``[drive]`` table.
        drive: The drive parsed so far.
        scen: The job's scenarios.

    Returns:
        ``drive`` with its start.

    Raises:
        JobError: An unknown start, a hand-over or a horizon that a standstill start cannot have, naming the
            field.
    """
    start = get_field(dt, "start", "drive.start", str, "steady")
    if start not in ("steady", "standstill"):
        raise JobError("drive.start", f"must be 'steady' or 'standstill', got {show(start)}")
    drive = dataclasses.replace(drive, start=start)
    if start == "standstill":
        if drive.handover > 0:
            raise JobError("drive.handover", "must be 0 with start = 'standstill' (the I-f start-up hands over)")
        job_drive(drive)  # the drive it runs: a dual three-phase drive file is refused here
        s = drive.drive_file.startup  # the start-up a standstill drive runs (DriveFile.drive_for)
        t_if = float(s.omega_switch / s.accel + s.hold + s.dwell)
        if scen.horizon <= t_if:
            raise JobError(
                "drive.start", f"'standstill' needs horizon > {t_if:.3g} s (the I-f start-up), got {scen.horizon:g}"
            )
        if scen.recording is None:  # a recording has no drive to start
            check_standstill(drive, scen, "scenarios")
    return drive


def check_drive_speeds(spec: ScenarioSpec, where: str, drive: DriveSpec) -> None:
    """A drive job's grid through :func:`check_speed_axes`, at --check time.

    Args:
        spec: The scenario set.
        where: The table holding it (its ``.grid`` is checked).
        drive: The job's ``[drive]``.

    Raises:
        JobError: A speed out of range, naming the field.
    """
    check_speed_axes(spec.axes, f"{where}.grid", drive.machine, drive.drive_file)


def check_speed_axes(axes: dict, where: str, machine: str, file: DriveFile | None = None) -> None:
    """The one check of drive speeds, for jobs and studies.

    ``speed_rpm`` and ``speed_rpm + speed_step_rpm`` (every combination of the axes, so every point a sampler
    draws inside their ranges too) must lie within ± the drive file's speed limit
    (:attr:`jaxobs.drive.DriveFile.speed_limit_rpm`, the one rule :func:`jaxobs.drive.speed_limit` that
    ``jaxobs drive check`` prints and ``envelope`` uses: the no-load voltage bound, with field weakening where
    on, within the mechanical limit ``[machine] max_speed_rpm``).

    Args:
        axes: name -> values.
        where: The table holding the axes.
        machine: The drive's name.
        file: Its drive file (None: the shipped ``machine``).

    Raises:
        JobError: A speed out of range, naming the field.
    """
    speeds, steps = axes.get("speed_rpm"), axes.get("speed_step_rpm", [0.0])
    if not speeds:
        return
    file = shipped_drive(machine) if file is None else file
    n_max = file.speed_limit_rpm
    why = f"speed_limit_rpm, drive check: {file.derived['speed_limit_rpm'].rule}"
    rng = f"must be in [1, {n_max:.0f}] r/min on {machine} ({why})"
    for i, x in enumerate(speeds):
        if abs(x) > n_max:
            raise JobError(f"{where}.speed_rpm[{i}]", f"{rng}, got {x:g}")
    for j, d in enumerate(steps):
        after = max(speeds) + d if d >= 0 else min(speeds) + d  # the extreme speed after this step
        if abs(after) > n_max:
            raise JobError(
                f"{where}.speed_step_rpm[{j}]",
                f"speed_rpm + speed_step_rpm must be in [-{n_max:.0f}, {n_max:.0f}] r/min on {machine} ({why}), "
                f"got {after:g}",
            )


def check_three_phase(spec: DriveSpec) -> None:
    """Refuse a dual three-phase drive file where a command runs three-phase drives only.

    Args:
        spec: The job's ``[drive]``.

    Raises:
        JobError: ``spec``'s drive file has a ``[dual]`` table.
    """
    if spec.drive_file.dual is not None:
        raise JobError(
            "drive",
            f"{spec.machine!r} is a dual three-phase drive ([dual]): `jaxobs envelope` and `jaxobs drive check` "
            "take it; tune and study run three-phase drives only",
        )


@overload
def job_drive(spec: DriveSpec | None = None, *, dual: Literal[False] = False) -> Drive: ...


@overload
def job_drive(spec: DriveSpec | None = None, *, dual: bool) -> Drive | D.DualDrive: ...


def job_drive(spec: DriveSpec | None = None, *, dual: bool = False) -> Drive | D.DualDrive:
    """The drive a ``signal = "drive"`` job runs: its drive file's (:meth:`jaxobs.drive.DriveFile.drive_for`).

    Args:
        spec: The job's ``[drive]`` (default: ``DriveSpec()``, sensorless).
        dual: The command maps a dual three-phase drive (``jaxobs envelope``); the others refuse a ``[dual]``
            drive file.

    Returns:
        The :class:`~jaxobs.drive.Drive` (a :class:`~jaxobs.drive.DualDrive` where ``dual`` allows it).

    Raises:
        JobError: a ``[dual]`` drive file where ``dual`` is False.
    """
    spec = DriveSpec() if spec is None else spec
    if not dual:
        check_three_phase(spec)
    return spec.drive_file.drive_for(
        sensorless=spec.loop == "sensorless",
        handover=spec.handover,
        settle=spec.settle,
        standstill=spec.start == "standstill",
        speed_schedule=spec.speed_schedule,
    )


DRIVE_TABLES = ("machine", "inverter", "control", "sensors", "startup", "dual")  # a drive file's tables, inline
_DRIVE_KEYS = ("loop", "handover", "settle", "start", "machine", "file", "speed_schedule", *DRIVE_TABLES[1:])
_INLINE_TOP = ("name", "description")  # an inline drive's label and description (a drive file's top-level keys)


def drive_source(dt: dict, default: str, base: Path | None, where: str = "drive") -> tuple[str, DriveFile | None]:
    """The drive file a ``[drive]`` table names.

    ``machine = "<shipped name>"`` (:data:`jaxobs.drive.SHIPPED_DRIVES`), ``file = "<path.toml>"``, or a drive
    file's tables inline (``[drive.machine]``, ``[drive.inverter]``, ...).

    Args:
        dt: The ``[drive]`` table.
        default: The shipped name without any.
        base: The job's or study's folder, against which a relative ``file`` is read (None: the working
            folder).
        where: The table's name in errors.

    Returns:
        ``(name, file)``: the drive's name, and its checked :class:`~jaxobs.drive.DriveFile` (None: shipped).

    Raises:
        JobError: naming the field: an unknown shipped name, an unreadable or refused file (its one line).
    """
    inline = {k: dt[k] for k in DRIVE_TABLES if isinstance(dt.get(k), dict)}
    named = isinstance(dt.get("machine"), str)
    if "file" in dt and (named or inline):
        raise JobError(f"{where}.file", "give a drive file, a shipped machine or the tables inline, one of them")
    if inline and named:
        raise JobError(f"{where}.machine", "a shipped machine's name or the drive file's tables inline, not both")
    if "file" in dt:
        name = get_field(dt, "file", f"{where}.file", str)
        assert name is not None  # the key is there
        path = Path(name) if Path(name).is_absolute() or base is None else Path(base) / name
        try:
            f = read_drive(path)
        except OSError as e:
            raise JobError(f"{where}.file", f"{name!r}: cannot be read ({e.strerror or e})") from None
        except ValueError as e:
            raise JobError(f"{where}.file", f"{name!r}: {e}") from None
        return f.name, f
    for k in _INLINE_TOP:
        if k in dt and not inline:
            raise JobError(f"{where}.{k}", "applies to a drive given inline ([drive.machine], [drive.inverter], ...)")
    if inline:
        if "machine" not in inline:
            raise JobError(f"{where}.machine", "missing: inline drive tables need [drive.machine] (the drive file's)")
        try:
            f = drive_from_table({**inline, **{k: dt[k] for k in _INLINE_TOP if k in dt}}, "inline")
        except ValueError as e:
            raise JobError(where, str(e)) from None
        return f.name, f
    machine = get_field(dt, "machine", f"{where}.machine", str, default)
    if machine not in SHIPPED_DRIVES:
        raise JobError(
            f"{where}.machine",
            f"must be one of {', '.join(SHIPPED_DRIVES)} (shipped drive files), or give file = 'my_drive.toml', "
            f"got {show(machine)}",
        )
    return machine, None


def inline_drive(dt: dict, file: DriveFile) -> dict:
    """``[drive]`` with its drive file's tables inline instead of ``file = ...`` (and its name and description):
    what a result keeps, so that it reads the same drive wherever it is moved.

    Args:
        dt: The ``[drive]`` table.
        file: Its drive file.

    Returns:
        The table with the drive inline.
    """
    out = {k: v for k, v in dt.items() if k != "file"}
    return {**out, "name": file.name, "description": file.description, **file.table}


def parse_drive(dt: dict, comp: str, scen: ScenarioSpec, base: Path | None = None) -> DriveSpec:
    """``[drive]`` of a drive job.

    Args:
        dt: The ``[drive]`` table.
        comp: The component's registered name.
        scen: The job's scenarios.
        base: The job file's folder (a relative ``file``).

    Returns:
        The :class:`DriveSpec`.

    Raises:
        JobError: A field out of its range, naming it.
    """
    info = COMPONENTS[comp]
    no_unknown(dt, (*_DRIVE_KEYS, *_INLINE_TOP), "drive")
    loop = get_field(dt, "loop", "drive.loop", str, "sensorless")
    if loop not in ("sensorless", "sensored"):
        raise JobError("drive.loop", f"must be 'sensorless' or 'sensored', got {show(loop)}")
    handover = get_field(dt, "handover", "drive.handover", float, 0.0)
    if not 0.0 <= handover < scen.horizon:
        raise JobError("drive.handover", f"must be in [0, horizon = {scen.horizon:g}) s, got {handover:g}")
    settle = get_field(dt, "settle", "drive.settle", float, 0.2)
    if not 0.0 <= settle <= 10.0:
        raise JobError("drive.settle", f"must be in [0, 10] s, got {settle:g}")
    machine, file = drive_source(dt, info.machines[0], base)
    if file is None and machine not in info.machines:
        raise JobError(
            "drive.machine",
            f"{comp} cannot run on {machine} ({shipped_drive(machine).description}); allowed: "
            f"{', '.join(info.machines)}",
        )
    if file is not None:
        why = info.entry.refusal(file.machine)
        if why is not None:
            raise JobError("drive.file" if "file" in dt else "drive.machine", why)
    # the FOC's speed-loop schedule (FOC.speed_gains): 0 off; N keeps the speed loop N times slower than ωe,
    # the flux observers' low-speed fix (docs/stability.md);
    # without the key, the drive file's ([control] speed_schedule)
    file_schedule = float((shipped_drive(machine) if file is None else file).foc_kw["speed_schedule"])
    schedule = get_field(dt, "speed_schedule", "drive.speed_schedule", float, file_schedule)
    if not 0.0 <= schedule <= 1000.0:
        raise JobError("drive.speed_schedule", f"must be 0 (off) or a ratio in (0, 1000], got {schedule:g}")
    spec = DriveSpec(loop, handover, settle, machine=machine, speed_schedule=schedule, file=file)
    return parse_start(dt, spec, scen)
