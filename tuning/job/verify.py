"""``[envelope]`` of a drive job and the long-horizon verification after tuning (issue 26: tuning that cannot
hide a failure).

A design tuned and scored on its grid can run away a little outside it (the noise-tuned SOIFO ran away at
400 r/min, two thirds of its grid's lowest speed).  So a drive job states the envelope it claims
(``[envelope] speed_rpm = [lo, hi]``, ``load_nm = [lo, hi]``; by default the span of its tuning grid) and,
after tuning, :func:`verify_designs` runs initial, closed form and tuned at a coarse grid of that envelope
(3 speeds, lo, geometric middle and hi, × 2 loads, lo and hi) over a long horizon (``[envelope] horizon``,
2 s by default) through the study runner (:func:`jaxobs.drive_study.run_drive_study`, batched), and gives
the simulator's own stability verdict at the same points (:func:`jaxobs.drive.stability.lyapunov`, one ``jit(vmap)``
per design class).  Each point is steady (no event), nominal machine, the job's drive (its speed schedule)
started steady.

A point *holds* when the simulation neither diverged, nor lost synchronism (|position error| > 90° in the
steady window), nor missed its speed reference (lost_speed), and is *stable* when the Lyapunov verdict is.
A tuned design that fails a point where the closed form passes is **unsafe** (:func:`unsafe_points`): the
job's status becomes ``"unsafe"`` and ``jaxobs tune`` warns and exits 4.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import numpy as np

from jaxobs import drive as D
from jaxobs.drive.stability import lyapunov
from jaxobs.drive_study import bind_observer, drive_scenarios, run_drive_study

from .drive import job_drive
from .fields import JobError, get_field, no_unknown
from .spec import DriveSpec, ScenarioSpec

__all__ = ["EnvelopeSpec", "parse_envelope", "verify_designs", "unsafe_points", "UNSAFE_EXIT"]

UNSAFE_EXIT = 4  # jaxobs tune's exit status for status "unsafe" (3 is "diverged": nothing tuned at all)
MIN_HORIZON = 0.05  # s; tests run short, the presets the default 2 s
DEFAULT_HORIZON = 2.0  # s: a slowly growing low-speed oscillation shows within it (docs/stability.md)


@dataclasses.dataclass(frozen=True)
class EnvelopeSpec:
    """The envelope a drive job claims: speeds (r/min) and loads (N·m) as [lo, hi]; ``horizon`` (s) of the
    verification runs; ``stability``: also the Lyapunov verdict (``lyapunov`` ``settle``/``window``, s)."""

    speed_rpm: tuple
    load_nm: tuple
    horizon: float = DEFAULT_HORIZON
    stability: bool = True
    settle: float = 0.2
    window: float = 0.4

    def points(self):
        """The coarse verification grid: (speeds, loads), 3 × 2 (fewer where lo == hi)."""
        lo, hi = self.speed_rpm
        mid = math.sqrt(lo * hi) if lo > 0 else 0.5 * (lo + hi)
        speeds = sorted({float(lo), float(mid), float(hi)})
        loads = sorted({float(v) for v in self.load_nm})
        return speeds, loads


def _span(axes: dict, key: str, default: float) -> tuple:
    vals = [abs(v) for v in axes.get(key, [default])]
    return (min(vals), max(vals))


def _range(tab: dict, key: str, lo: float, hi: float, unit: str, default: tuple) -> tuple:
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
    verification closes the loop through each design."""
    if "envelope" not in raw:
        return None
    if drive is None:
        raise JobError("envelope", f"applies to drive jobs (scenarios.signal = 'drive'), not {scen.signal!r} signals")
    if scen.recording is not None:
        raise JobError("envelope", "applies to drive jobs on simulated scenarios, not on recordings")
    if drive.loop != "sensorless":
        raise JobError("envelope", "applies to sensorless drive jobs (drive.loop = 'sensorless')")
    tab = get_field(raw, "envelope", "envelope", dict)
    no_unknown(tab, ("speed_rpm", "load_nm", "horizon", "stability", "settle", "window"), "envelope")
    par = D.bench_machine(drive.machine)
    n_max = D.drive_speed_limit_rpm(par)
    speeds = _range(tab, "speed_rpm", 1.0, n_max, "r/min", _span(scen.axes, "speed_rpm", 600.0))
    t_max = 3.0 * float(par.kt) * float(par.i_rated)  # generous: the FOC limits the current to 1.5 i_rated
    loads = _range(tab, "load_nm", 0.0, t_max, "N·m", _span(scen.axes, "load_nm", 0.0))
    horizon = get_field(tab, "horizon", "envelope.horizon", float, 2.0)  # DEFAULT_HORIZON
    if not MIN_HORIZON <= horizon <= 10.0:
        raise JobError("envelope.horizon", f"must be in [{MIN_HORIZON:g}, 10] s, got {horizon:g}")
    stability = get_field(tab, "stability", "envelope.stability", bool, True)
    settle = get_field(tab, "settle", "envelope.settle", float, 0.2)
    if not 0.0 <= settle <= 5.0:
        raise JobError("envelope.settle", f"must be in [0, 5] s, got {settle:g}")
    window = get_field(tab, "window", "envelope.window", float, 0.4)
    if not 0.01 <= window <= 5.0:
        raise JobError("envelope.window", f"must be in [0.01, 5] s, got {window:g}")
    return EnvelopeSpec(speeds, loads, horizon, stability, settle, window)


@eqx.filter_jit
def _stability(drive, obs, scenarios, settle, window):
    """:func:`jaxobs.drive.stability.lyapunov` at every scenario for one design; the design is an argument (its gains
    array leaves), so initial, closed form and tuned of one class share one compilation."""

    def one(sc):
        return lyapunov(D.ClosedLoop(drive, bind_observer(obs, sc), sc), settle=settle, warmup=0.1, window=window)

    return jax.vmap(one)(scenarios)


def verify_designs(designs: dict, env: EnvelopeSpec, drive_spec: DriveSpec) -> dict:
    """Initial, closed form and tuned (``designs``: name -> drive observer) at the envelope's coarse grid over
    ``env.horizon`` seconds, and their stability verdicts: the ``verification`` block of result.json."""
    drive_spec = dataclasses.replace(drive_spec, start="steady", handover=0.0)  # operating points, started steady
    drive = job_drive(drive_spec)
    par = D.bench_machine(drive_spec.machine)
    speeds, loads = env.points()
    axes = {"speed_rpm": speeds, "load_nm": loads}
    # the steady window: the last quarter of the horizon (at least 10 samples)
    steady_from = max(0.75 * env.horizon, env.horizon - 0.5)
    ds = run_drive_study(designs, axes, machine=par, drive=drive, horizon=env.horizon, steady_from=steady_from)
    combos = [(s, ld) for s in speeds for ld in loads]
    scen = drive_scenarios(par, ("speed_rpm", "load_nm"), combos) if env.stability else None
    out = {
        "envelope": {"speed_rpm": list(env.speed_rpm), "load_nm": list(env.load_nm)},
        "horizon_s": env.horizon,
        "steady_from_s": steady_from,
        "speed_schedule": drive_spec.speed_schedule,
        "points": [{"speed_rpm": s, "load_nm": ld} for s, ld in combos],
        "holds_definition": "not diverged, |position error| <= 90 deg (electrical) in the steady window, and the "
        "steady window's mean |speed - reference| within 20 % (lost_speed)",
        "stable_definition": "jaxobs.drive.stability.lyapunov: the largest non-neutral Lyapunov exponent < 0 "
        "(margin > 0, 1/s) and the orbit held its speed",
        "designs": {},
    }
    for name, obs in designs.items():
        sel = ds.sel(design=name)
        stab = _stability(drive, obs, scen, env.settle, env.window) if env.stability else None
        rows = []
        for i, (s, ld) in enumerate(combos):
            pt = sel.sel(speed_rpm=s, load_nm=ld)
            lost_lock, lost_speed = bool(pt["lost_lock"]), bool(pt["lost_speed"])
            row = {
                "speed_rpm": s,
                "load_nm": ld,
                "holds": not (lost_lock or lost_speed or bool(pt["diverged"])),
                "lost_lock": lost_lock,
                "lost_speed": lost_speed,
                "diverged": bool(pt["diverged"]),
                "pos_err_max_deg": _num(pt["pos_err_max_deg"]),
                "pos_err_rms_deg": _num(pt["pos_err_rms_deg"]),
                "pos_bias_deg": _num(pt["pos_bias_deg"]),
                "speed_err_rms_rpm": _num(pt["speed_err_rms_rpm"]),
            }
            if stab is not None:
                row["stable"] = bool(np.asarray(stab.stable)[i])
                row["exponent_per_s"] = _num(np.asarray(stab.exponent)[i])
                row["margin_per_s"] = _num(np.asarray(stab.margin)[i])
            rows.append(row)
        ok = [r["holds"] and r.get("stable", True) for r in rows]
        out["designs"][name] = {"holds_everywhere": all(ok), "failed_points": int(len(ok) - sum(ok)), "points": rows}
    out["unsafe_points"] = unsafe_points(out)
    return out


def _num(x):
    """A JSON number, or None where it is not finite (a lost point's metrics are NaN)."""
    v = float(np.asarray(x))
    return v if math.isfinite(v) else None


def unsafe_points(ver: dict) -> list:
    """The points where the tuned design fails (does not hold, or is not stable) and the closed form passes."""
    des = ver["designs"]
    if "tuned" not in des or "closed_form" not in des:
        return []

    def ok(r):
        return r["holds"] and r.get("stable", True)

    return [
        {"speed_rpm": t["speed_rpm"], "load_nm": t["load_nm"]}
        for t, c in zip(des["tuned"]["points"], des["closed_form"]["points"], strict=True)
        if ok(c) and not ok(t)
    ]
