"""A drive file's operating points run in closed loop, sensored: does the derived controller hold them?

``jaxobs drive check FILE --simulate`` asks this of two points (:func:`check_points` chooses them,
:func:`run_points` runs them):

- **rated**: the rated speed with the rated torque as load;
- **top**: the highest speed the check claims, the speed limit or 1.5 × the base speed where that is lower
  (DECISION: 1.5 × base speed is the field-weakening range a drive engineer first checks — a constant-power
  range of 1.5 : 1 is what an industrial drive's nameplate promises; the mechanical limit of a traction machine
  lies far beyond it and its torque there is a few % of rated), loaded at :data:`TOP_MARGIN` (95 %) of the
  steady torque the capability curve allows there (:func:`jaxobs.drive.weakening.capability_curve`): 5 % left
  to the speed loop to regulate with.

Each starts in its steady state (the loop's steady start: :meth:`jaxobs.drive.ClosedLoop.init`) with the FOC
closing on the encoder's true angle (``Drive(sensorless=False)``), and runs :func:`horizon` seconds:
max(:data:`HORIZON_MIN_S`, 10/α_s), ten time constants of the speed loop.  A point is **held** when its mean
speed over the last quarter of the run lies within :data:`HOLD_TOL` (2 %) of its reference.  Per point the run
also reports the largest |i| (the true current, every sample) over i_max and the largest |u| (the applied
voltage) over u_dc/√3.  Both points run in one ``jit(vmap)`` (a batch of two scenarios): one compilation.

The voltage is u_dc/√3, the circle inscribed in the space-vector hexagon, whatever the file's
``inverter.voltage_limit``: the FOC limits its own command to it (``FOC.u_max`` is ``Inverter.u_max``), so a
``"hexagon"`` plant never receives a vector beyond the circle from this controller and its corners (up to
2 u_dc/3) are never used; the capability (fw_margin × u_dc/√3) and the points' |u|/u_max are the same numbers
under either plant.  DECISION: the linear range, because a steady sinusoidal current through overmodulation
carries the hexagon's 5th and 7th harmonics, which the check's steady model does not have.

:func:`peak_ratios` runs any batch of scenarios on the same drive (standstill starts, speed and load steps) and
reports the largest |i|/i_max, |i*|/i_max and |u|/u_max over every sample (``tests/test_current_limit.py``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..drive import RPM, ClosedLoop, Drive, DriveFile, Profile, Scenario
from ..runtime import simulate

__all__ = [
    "HOLD_TOL",
    "HORIZON_MIN_S",
    "TOP_MARGIN",
    "PointResult",
    "check_points",
    "horizon",
    "peak_ratios",
    "point_verdict",
    "run_points",
]

HOLD_TOL = 0.02  # held: mean speed over the last quarter within 2 % of the reference
TOP_MARGIN = 0.95  # the top point's load: 95 % of the capability there (5 % left to the speed loop)
HORIZON_MIN_S = 0.2  # the shortest run, s
TOP_BASE_PU = 1.5  # the top point: 1.5 × base speed, or the speed limit where lower
NEAR = 1e-3  # a limit is reached within 0.1 % of it


class PointResult(NamedTuple):
    """One operating point's run.

    Attributes:
        name: ``"rated"`` or ``"top"``.
        speed_rpm: The reference, r/min.
        load_nm: The load torque, N·m.
        mean_rpm: The mean speed over the last quarter of the run, r/min.
        held: Whether that mean lies within :data:`HOLD_TOL` of the reference.
        i_ratio: max |i| / i_max over every sample (the true current).
        u_ratio: max |u| / (u_dc/√3) over every sample (the applied voltage).
    """

    name: str
    speed_rpm: float
    load_nm: float
    mean_rpm: float
    held: bool
    i_ratio: float
    u_ratio: float


def horizon(f: DriveFile) -> float:
    """The run's length: max(:data:`HORIZON_MIN_S`, 10/α_s), s (ten of the speed loop's time constants).

    Args:
        f: The drive file.

    Returns:
        The horizon, s.
    """
    return max(HORIZON_MIN_S, 10.0 / float(f.derived["alpha_s"].value))


def check_points(f: DriveFile) -> tuple[tuple[str, float, float], ...]:
    """The two points (module doc): ``(name, speed r/min, load N·m)`` for the rated point and the top speed.

    Args:
        f: The drive file.

    Returns:
        The points.
    """
    m, d = f.machine, f.derived
    top = min(f.speed_limit_rpm, TOP_BASE_PU * float(d["base_speed_rpm"].value))
    t_top = TOP_MARGIN * float(f.capability([top])["torque"][0])
    t_top = t_top if math.isfinite(t_top) and t_top > 0.0 else 0.0  # no torque there: held at no load
    return (("rated", float(m.n_rated), float(m.T_rated)), ("top", float(top), t_top))


@eqx.filter_jit
def _runs(drive: Drive, scs: Scenario, t1: float, i_max: float, u_max: float):
    """The batch of scenarios in one program: (mean speed of the last quarter, max |i|/i_max, max |u|/u_max)."""

    def one(sc):
        out = simulate(ClosedLoop(drive, None, sc), t1).outputs
        rpm = out.speed_rpm
        n = rpm.shape[0]
        mean = jnp.mean(rpm[n - n // 4 :])
        i_r = jnp.max(jnp.hypot(out.i_d, out.i_q)) / i_max
        u_r = jnp.max(jnp.hypot(out.u_a, out.u_b)) / u_max
        return mean, i_r, u_r

    return jax.vmap(one)(scs)


@eqx.filter_jit
def _peaks(drive: Drive, scs: Scenario, t1: float, i_max: float, u_max: float):
    """The batch's (max |i|/i_max, max |i*|/i_max, max |u|/u_max, the least i_d*, the last speed)."""

    def one(sc):
        out = simulate(ClosedLoop(drive, None, sc), t1).outputs
        i_r = jnp.max(jnp.hypot(out.i_d, out.i_q)) / i_max
        ref_r = jnp.max(jnp.hypot(out.id_ref, out.iq_ref)) / i_max
        u_r = jnp.max(jnp.hypot(out.u_a, out.u_b)) / u_max
        return i_r, ref_r, u_r, jnp.min(out.id_ref), out.speed_rpm[-1]

    return jax.vmap(one)(scs)


def peak_ratios(f: DriveFile, scenarios: list[Scenario], t1: float) -> dict[str, np.ndarray]:
    """Run ``scenarios`` on the file's drive, sensored, in one ``jit(vmap)`` (their profiles of equal knots), and
    report each one's peaks over every sample.

    Args:
        f: The drive file (a single three-phase machine's).
        scenarios: The scenarios (each on ``f.machine``).
        t1: The horizon, s.

    Returns:
        ``i_ratio`` (max |i|/i_max, the true current), ``ref_ratio`` (max |i*|/i_max), ``u_ratio``
        (max |u|/(u_dc/√3), the applied voltage), ``id_ref_min`` (the least i_d*, A) and ``last_rpm`` (the speed
        at the last sample, r/min), one entry per scenario.

    Raises:
        ValueError: A ``[dual]`` file, or no scenario.
    """
    if f.dual is not None or not scenarios:
        raise ValueError("peak_ratios: scenarios must be a non-empty list on a single three-phase drive file")
    drive = f.drive_for(sensorless=False)
    assert isinstance(drive, Drive)
    batch = jax.tree.map(lambda *x: jnp.stack(x), *scenarios)
    i_max, u_max = float(f.derived["i_max"].value), float(f.derived["u_max"].value)
    vals = (np.asarray(v) for v in _peaks(drive, batch, float(t1), i_max, u_max))
    return dict(zip(("i_ratio", "ref_ratio", "u_ratio", "id_ref_min", "last_rpm"), vals))


def run_points(f: DriveFile, points: tuple[tuple[str, float, float], ...] | None = None) -> list[PointResult]:
    """Run ``points`` (default :func:`check_points`) sensored from their steady states, all in one
    ``jit(vmap)`` (module doc).

    Args:
        f: The drive file (a single three-phase machine's).
        points: ``(name, speed r/min, load N·m)`` each.

    Returns:
        One :class:`PointResult` per point.

    Raises:
        ValueError: A ``[dual]`` file (the sensored point runs are the single machine's).
    """
    if f.dual is not None:
        raise ValueError("--simulate: a [dual] file's points are not run (single three-phase drives only)")
    pts = check_points(f) if points is None else points
    drive = f.drive_for(sensorless=False)
    assert isinstance(drive, Drive)
    m = f.machine
    scs = [
        Scenario(m, speed_ref=Profile.constant(n * RPM), omega_m0=n * RPM, load=Profile.constant(t)) for _, n, t in pts
    ]
    batch = jax.tree.map(lambda *x: jnp.stack(x), *scs)
    i_max, u_max = float(f.derived["i_max"].value), float(f.derived["u_max"].value)
    mean, i_r, u_r = (np.asarray(v) for v in _runs(drive, batch, horizon(f), i_max, u_max))
    return [
        PointResult(name, n, t, float(mean[k]), bool(abs(mean[k] - n) <= HOLD_TOL * n), float(i_r[k]), float(u_r[k]))
        for k, (name, n, t) in enumerate(pts)
    ]


def point_verdict(r: PointResult) -> tuple[str, str | None]:
    """A point's one-word-or-so verdict and, where it fails, the warning naming the key to change.

    Held with |i| ≤ i_max: ``"held"`` (``", at the voltage limit"`` added where |u| reached u_dc/√3: the current
    loop had no room left).  Not held, or above i_max: the key whose limit was reached — ``inverter.u_dc`` where
    |u| reached u_dc/√3, ``control.i_max_a`` where |i| reached i_max, else ``control.speed_bandwidth_hz`` (neither
    limit: the loops themselves) — and the rating or speed to lower instead.

    Args:
        r: The point's run.

    Returns:
        ``(verdict, warning or None)``.
    """
    at_u = r.u_ratio >= 1 - NEAR
    over = r.i_ratio > 1 + NEAR
    if r.held and not over:
        return "held" + (", at the voltage limit" if at_u else ""), None
    verdict = ("NOT held" if not r.held else "held") + (", current above i_max" if over else "")
    if at_u:
        key = "inverter.u_dc (the voltage ran out)"
    elif r.i_ratio >= 1 - NEAR:
        key = "control.i_max_a (the current limit bound)"
    else:
        key = "control.speed_bandwidth_hz (neither limit bound: the loops)"
    lower = "machine.rated_torque_nm" if r.name == "rated" else "machine.max_speed_rpm"
    what = "not held" if not r.held else "held only above i_max"
    return verdict, (
        f"{r.name} point ({r.speed_rpm:.5g} r/min, {r.load_nm:.4g} N·m) {what}: raise {key}, or lower {lower}"
    )
