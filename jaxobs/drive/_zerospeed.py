"""Scenarios through and at zero speed: a speed reversal, a low-speed load step, a standstill hold
(:mod:`jaxobs.drive.scenario`'s :class:`Scenario` made from a base one)."""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp

from ..core.validate import as_float
from .machine import RPM
from .scenario import Profile, Scenario

__all__ = ["low_speed_load_step", "reversal", "standstill_hold"]


def _finite_in(owner: str, name: str, x, lo: float, hi: float, *, lo_open: bool = False, nonzero: bool = False):
    """``x`` as a Python float, checked finite and in [lo, hi] ((lo, hi] with ``lo_open``; ≠ 0 with ``nonzero``)."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}.{name} must be a number, got {x!r}") from None
    ok = math.isfinite(v) and (v > lo if lo_open else v >= lo) and v <= hi and not (nonzero and v == 0.0)
    if not ok:
        left = "(" if lo_open else "["
        extra = ", not 0" if nonzero else ""
        raise ValueError(f"{owner}.{name} must be a finite number in {left}{lo:g}, {hi:g}]{extra}, got {x!r}")
    return v


def _base_scenario(owner: str, base) -> Scenario:
    if not isinstance(base, Scenario):
        raise ValueError(f"{owner}.base must be a Scenario, got {type(base).__name__}")
    if jnp.ndim(base.omega_m0) != 0:
        raise ValueError(
            f"{owner}.base must be one scenario, not a batch (omega_m0 has shape {jnp.shape(base.omega_m0)})"
        )
    return base


def reversal(
    base: Scenario, speed_rpm: float, rate_rpm_s: float, *, load_nm: float = 0.0, t_start: float = 0.2
) -> Scenario:
    """A speed reversal: steady at +``speed_rpm`` until ``t_start``, the reference ramped to −``speed_rpm`` at
    ``rate_rpm_s``, then held; the load held at ``load_nm`` throughout (an active load: it brakes one direction
    and drives the other, as a hoist's does).

    The ramp lasts 2·``speed_rpm``/``rate_rpm_s`` s and ends at ``speed_ref.times[-1]``; a ±750 r/min reversal
    in 1 s is ``reversal(base, 750, 1500)``.  The machine starts steady at +``speed_rpm`` under the load.

    Args:
        base: The :class:`Scenario` whose machine, assumed machine, sensors and noise key are kept.
        speed_rpm: The speed before the reversal, r/min (in (0, 1e5]; after it, −``speed_rpm``).
        rate_rpm_s: The reference's ramp rate, r/min per second (in (0, 1e7]).
        load_nm: The load torque, N·m (in [−1e4, 1e4]).
        t_start: The start of the ramp, s (in [0, 1e4]).

    Returns:
        The :class:`Scenario`.

    Raises:
        ValueError: A value out of its range, naming the field.
    """
    base = _base_scenario("reversal", base)
    n = _finite_in("reversal", "speed_rpm", speed_rpm, 0.0, 1e5, lo_open=True)
    rate = _finite_in("reversal", "rate_rpm_s", rate_rpm_s, 0.0, 1e7, lo_open=True)
    load = _finite_in("reversal", "load_nm", load_nm, -1e4, 1e4)
    t0 = _finite_in("reversal", "t_start", t_start, 0.0, 1e4)
    t1 = t0 + 2.0 * n / rate
    ref = Profile([0.0, t0, t1], [n * RPM, n * RPM, -n * RPM], kind="linear")
    return eqx.tree_at(
        lambda s: (s.speed_ref, s.load, s.omega_m0),
        base,
        (ref, Profile.constant(load), as_float(n * RPM)),
    )


def low_speed_load_step(base: Scenario, speed_pu: float, load_pu: float, *, t_event: float = 0.2) -> Scenario:
    """A load step at low speed: steady at ``speed_pu`` × rated speed without load, then ``load_pu`` × rated
    torque stepped on at ``t_event`` (the machine's ``n_rated`` and ``T_rated``, :class:`PMSMParams`).

    Args:
        base: The :class:`Scenario` whose machine, assumed machine, sensors and noise key are kept.
        speed_pu: The speed, a fraction of rated speed (in [−1, 1], not 0: :func:`standstill_hold` holds zero).
        load_pu: The load step, a fraction of rated torque (in [−3, 3]).
        t_event: The time of the step, s (in [0, 1e4]).

    Returns:
        The :class:`Scenario`.

    Raises:
        ValueError: A value out of its range, naming the field.
    """
    base = _base_scenario("low_speed_load_step", base)
    v = _finite_in("low_speed_load_step", "speed_pu", speed_pu, -1.0, 1.0, nonzero=True)
    lp = _finite_in("low_speed_load_step", "load_pu", load_pu, -3.0, 3.0)
    te = _finite_in("low_speed_load_step", "t_event", t_event, 0.0, 1e4)
    w = v * float(base.par.n_rated) * RPM
    step = Profile([0.0, te], [0.0, lp * float(base.par.T_rated)], kind="step")
    return eqx.tree_at(lambda s: (s.speed_ref, s.load, s.omega_m0), base, (Profile.constant(w), step, as_float(w)))


def standstill_hold(base: Scenario, load_pu: float, *, t_event: float = 0.2) -> Scenario:
    """Zero speed held under load: the reference 0, the machine at rest, ``load_pu`` × rated torque stepped on
    at ``t_event`` (0: loaded from the start, the steady start balancing it).

    Args:
        base: The :class:`Scenario` whose machine, assumed machine, sensors and noise key are kept.
        load_pu: The load, a fraction of rated torque (in [−3, 3]).
        t_event: The time of the step, s (in [0, 1e4]).

    Returns:
        The :class:`Scenario`.

    Raises:
        ValueError: A value out of its range, naming the field.
    """
    base = _base_scenario("standstill_hold", base)
    lp = _finite_in("standstill_hold", "load_pu", load_pu, -3.0, 3.0)
    te = _finite_in("standstill_hold", "t_event", t_event, 0.0, 1e4)
    step = Profile([0.0, te], [0.0, lp * float(base.par.T_rated)], kind="step")
    return eqx.tree_at(lambda s: (s.speed_ref, s.load, s.omega_m0), base, (Profile.constant(0.0), step, as_float(0.0)))
