"""``[envelope]`` of a drive job and the long-horizon verification after tuning: tuning that cannot
hide a failure.

A design tuned and scored on its grid can run away a little outside it (the noise-tuned SOIFO ran away at 400 r/min,
two thirds of its grid's lowest speed). So a drive job states the envelope it claims (``[envelope] speed_rpm = [lo,
hi]``, ``load_nm = [lo, hi]``; by default the span of its tuning grid) and, after tuning, :func:`verify_designs`
maps initial, closed form and tuned over a coarse grid of that envelope (3 speeds, lo, geometric middle and hi, × 2
loads, lo and hi) with the one envelope map, :func:`jaxobs.analysis.envelope.envelope`: a long run (``[envelope]
horizon``, 2 s by default, stretched to the slowest speed loop's time constants) after a speed-reference pulse up
and one after a pulse down (the worse run counts), so unbiased beside a boundary, through the study runner, batched,
and the simulator's own stability verdict (:func:`jaxobs.analysis.stability.floquet`) at the same points, on the
job's drive (its speed schedule) started steady, nominal machine, measured through the drive file's ``[sensors]``
(its ADC's quantization as noise, its offsets and gain errors; the noise drawn from the job's seed) as ``jaxobs
envelope`` measures by default: a design tuned on noisy scenarios is verified on the same sensors, not on ideal ones
that would hide a noise-driven loss. ``[envelope] ideal_sensors = true`` runs ideal sensors (``jaxobs envelope
--ideal-sensors``); a shipped bench's are ideal (as the job's scenarios run them,
:func:`jaxobs_tuning.job.scenarios.job_family`).

A point *passes* when the design holds synchronism there (the envelope's ``synchronous``: finite, locked,
at speed and settled) and is stable (``stable``: resolved, the exponent below 0 by more than its
resolution; a ``marginal`` point, within it, does not pass: the window could not tell).  A tuned design
that fails a point where the closed form passes is **unsafe** (:func:`unsafe_points`): the job's status
becomes ``"unsafe"`` and ``jaxobs tune`` warns on stderr and exits 4 (:data:`UNSAFE_EXIT`; 3 stays
"diverged", where nothing is tuned at all).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from jaxobs.analysis.envelope import envelope
from jaxobs.drive import PMSMParams, Sensors
from jaxobs.scenarios.families import DriveScenarios

from .drive import job_drive
from .fields import JobError, get_field, no_unknown
from .spec import DEFAULT_HORIZON as DEFAULT_HORIZON
from .spec import DriveSpec, EnvelopeSpec, ScenarioSpec

__all__ = [
    "EnvelopeSpec",
    "parse_envelope",
    "verification_points",
    "verification_sensors",
    "verify_designs",
    "unsafe_points",
    "UNSAFE_EXIT",
]

UNSAFE_EXIT = 4  # jaxobs tune's exit status for status "unsafe" (3 is "diverged": nothing tuned at all)
MIN_HORIZON = 0.5  # s: jaxobs.analysis.envelope.envelope's least; the presets run the default 2 s


def _span(axes: dict, key: str, default: float) -> tuple[float, float]:
    vals = [abs(v) for v in axes.get(key, [default])]
    return (min(vals), max(vals))


def _range(tab: dict, key: str, lo: float, hi: float, unit: str, default: tuple[float, float]) -> tuple[float, float]:
    where = f"envelope.{key}"
    v = get_field(tab, key, where, list, list(default))
    if len(v) != 2 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        raise JobError(where, f"must be [lo, hi] ({unit}), got {v!r}")
    a, b = float(v[0]), float(v[1])
    if not (lo <= a <= b <= hi):
        raise JobError(where, f"must be [lo, hi] with {lo:g} <= lo <= hi <= {hi:g} {unit}, got [{a:g}, {b:g}]")
    return (a, b)


def parse_envelope(raw: dict, scen: ScenarioSpec, drive: DriveSpec | None) -> EnvelopeSpec | None:
    """``[envelope]`` of a job (None without the table).  Only drive jobs on a sensorless loop have one: the
    verification closes the loop through each design.

    Args:
        raw: The parsed job file.
        scen: The job's scenarios (the default envelope: their grid's span).
        drive: The job's ``[drive]``, or None (not a drive job).

    Returns:
        The :class:`EnvelopeSpec`, or None without ``[envelope]``.

    Raises:
        JobError: The table on a job that cannot have one, or a field out of its range, naming it.
    """
    if "envelope" not in raw:
        return None
    if drive is None:
        raise JobError("envelope", f"applies to drive jobs (scenarios.signal = 'drive'), not {scen.signal!r} signals")
    if scen.recording is not None:
        raise JobError("envelope", "applies to drive jobs on simulated scenarios, not on recordings")
    if drive.loop != "sensorless":
        raise JobError("envelope", "applies to sensorless drive jobs (drive.loop = 'sensorless')")
    tab = get_field(raw, "envelope", "envelope", dict)
    assert tab is not None  # the key is there
    no_unknown(tab, ("speed_rpm", "load_nm", "horizon", "settle", "window", "ideal_sensors"), "envelope")
    par = drive.drive_file.machine
    n_max = drive.drive_file.speed_limit_rpm
    speeds = _range(tab, "speed_rpm", 1.0, n_max, "r/min", _span(scen.axes, "speed_rpm", 600.0))
    t_max = 3.0 * float(par.kt) * float(par.i_rated)  # generous: the FOC limits the current to 1.5 i_rated
    loads = _range(tab, "load_nm", 0.0, t_max, "N·m", _span(scen.axes, "load_nm", 0.0))
    horizon = get_field(tab, "horizon", "envelope.horizon", float, 2.0)  # DEFAULT_HORIZON
    if not MIN_HORIZON <= horizon <= 10.0:
        raise JobError("envelope.horizon", f"must be in [{MIN_HORIZON:g}, 10] s, got {horizon:g}")
    settle = get_field(tab, "settle", "envelope.settle", float, 0.2)
    if not 0.0 <= settle <= 5.0:
        raise JobError("envelope.settle", f"must be in [0, 5] s, got {settle:g}")
    window = get_field(tab, "window", "envelope.window", float, 0.4)
    if not 0.01 <= window <= 5.0:
        raise JobError("envelope.window", f"must be in [0.01, 5] s, got {window:g}")
    ideal = get_field(tab, "ideal_sensors", "envelope.ideal_sensors", bool, False)
    return EnvelopeSpec(speeds, loads, horizon, settle, window, ideal)


def verification_points(env: EnvelopeSpec) -> tuple[list[float], list[float]]:
    """The coarse grid the verification runs on: 3 speeds (the ends and their geometric mean; the arithmetic mean
    from zero) × the 2 loads at the ends (fewer where an end repeats).

    Args:
        env: The envelope the job claims.

    Returns:
        ``(speeds, loads)``, r/min and N·m, each sorted.
    """
    lo, hi = env.speed_rpm
    mid = math.sqrt(lo * hi) if lo > 0 else 0.5 * (lo + hi)
    speeds = sorted({float(lo), float(mid), float(hi)})
    loads = sorted({float(v) for v in env.load_nm})
    return speeds, loads


def verification_sensors(env: EnvelopeSpec, drive_spec: DriveSpec) -> tuple[Sensors | None, str]:
    """The sensors the verification measures through: the drive file's ``[sensors]``, unless the job turns them
    off (``[envelope] ideal_sensors = true``) or runs a shipped bench (ideal, as its scenarios are).

    Args:
        env: The envelope the job claims.
        drive_spec: The job's ``[drive]``.

    Returns:
        ``(sensors, words)``: the :class:`~jaxobs.drive.Sensors` (None: ideal) and what they are, for result.json.
    """
    if env.ideal_sensors:
        return None, "ideal (envelope.ideal_sensors)"
    if drive_spec.file is None:
        return None, "ideal (a shipped bench)"
    return drive_spec.drive_file.sensors, "the drive file's [sensors]"


def verify_designs(
    designs: dict, env: EnvelopeSpec, drive_spec: DriveSpec, machine: PMSMParams | None = None, seed: int = 0
) -> dict:
    """Initial, closed form and tuned (``designs``: name -> drive observer) at the envelope's coarse grid over
    ``env.horizon`` seconds, with their stability verdicts (:func:`jaxobs.analysis.envelope.envelope`, the one
    envelope map, on the job's drive started steady, through :func:`verification_sensors`): the
    ``verification`` block of result.json.

    Args:
        designs: name -> drive observer (``initial``, ``closed_form``, ``tuned``).
        env: The envelope the job claims.
        drive_spec: The job's ``[drive]``.
        machine: The true machine (default: its drive file's, where the caller has not read it already).
        seed: The seed of the sensors' noise (the job's seed).

    Returns:
        The verification: the envelope, the horizon, the sensors, the points, each design's verdict at each point
        and the points where the tuned design is unsafe (:func:`unsafe_points`).
    """
    drive_spec = dataclasses.replace(drive_spec, start="steady", handover=0.0)  # operating points, started steady
    drive = job_drive(drive_spec)
    par = drive_spec.drive_file.machine if machine is None else machine
    sensors, sensors_words = verification_sensors(env, drive_spec)
    family = DriveScenarios(par, drive, seed=seed, sensors=sensors)  # as a drive study's scenarios
    speeds, loads = verification_points(env)
    stab = {"settle": env.settle, "window": env.window}
    ds = envelope(designs, family=family, speeds_rpm=speeds, loads_nm=loads, horizon=env.horizon, stability=stab)
    combos = [(s, ld) for s in speeds for ld in loads]
    out = {
        "envelope": {"speed_rpm": list(env.speed_rpm), "load_nm": list(env.load_nm)},
        "horizon_s": float(ds.attrs["horizon"]),  # the job's, stretched to the slowest speed loop (envelope)
        "sensors": sensors_words,
        "speed_schedule": drive_spec.speed_schedule,
        "points": [{"speed_rpm": s, "load_nm": ld} for s, ld in combos],
        "passes_definition": "synchronous (jaxobs.analysis.envelope: finite, locked within 90 deg electrical, at its "
        "speed reference and settled after a 2 % speed-reference pulse up and one down, the worse run, over the late "
        "window) and stable "
        "(jaxobs.analysis.stability.floquet: the largest non-neutral Floquet multiplier over whole electrical "
        "periods, as a rate log|mu|/T, below 0 by more than its resolution, 1/s; within it the point is "
        "'marginal', which does not pass)",
        "designs": {},
    }
    for name in designs:
        rows = []
        for s, ld in combos:
            pt = ds.sel(design=name, speed_rpm=s, load_nm=ld)
            row: dict[str, float | bool | None] = {"speed_rpm": s, "load_nm": ld}
            for k in ("synchronous", "stable", "marginal", "holds", "lost_lock", "lost_speed"):
                row[k] = bool(pt[k])
            row["margin_per_s"] = _num(pt["margin"])
            row["resolution_per_s"] = _num(pt["resolution"])
            for k in ("peak_position_late", "mean_position_late", "ripple_position_late", "peak_speed_deviation_late"):
                row[k] = _num(pt[k])
            row["passes"] = row["synchronous"] and row["stable"]
            rows.append(row)
        n_fail = sum(not r["passes"] for r in rows)
        out["designs"][name] = {"passes_everywhere": n_fail == 0, "failed_points": n_fail, "points": rows}
    out["unsafe_points"] = unsafe_points(out)
    return out


def _num(x: object) -> float | None:
    """A JSON number, or None where it is not finite (a lost point's metrics are NaN)."""
    v = float(np.asarray(x))
    return v if math.isfinite(v) else None


def unsafe_points(ver: dict) -> list[dict]:
    """The points where the tuned design fails (loses synchronism or is not stable) and the closed form passes.

    Args:
        ver: The verification (:func:`verify_designs`).

    Returns:
        ``{"speed_rpm", "load_nm"}`` of each such point; empty without a tuned design or a closed form.
    """
    des = ver["designs"]
    if "tuned" not in des or "closed_form" not in des:
        return []

    return [
        {"speed_rpm": t["speed_rpm"], "load_nm": t["load_nm"]}
        for t, c in zip(des["tuned"]["points"], des["closed_form"]["points"], strict=True)
        if c["passes"] and not t["passes"]
    ]
