"""Scenarios and batches for the drive.

A :class:`Scenario` is a PyTree: the true machine (``par``), what controller and
observer assume (``est_par``), the speed-reference and load-torque profiles,
sensor errors, the inverter dead time, a PRNG key for the noise, and the
initial state.  A batch is a Scenario whose leaves carry a leading axis;
:func:`grid` builds one from named axes (``speed × mismatch × offset``) and
returns the axis names and coordinates with it, so a study's results can be
labelled.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._validate import as_float, check_nonnegative, check_real
from .hardware import Sensors
from .machine import RPM, PMSMParams

__all__ = ["Profile", "Scenario", "Batch", "grid", "GRID_AXES"]


class Profile(eqx.Module):
    """A piecewise profile of time: linear between breakpoints (``kind="linear"``) or held (``"step"``).

    Before the first breakpoint the first value holds, after the last the last.
    """

    times: jax.Array  # s, non-decreasing
    values: jax.Array
    kind: Literal["linear", "step"] = eqx.field(static=True)

    def __init__(self, times, values, kind="linear"):
        t = np.asarray(times, dtype=float)
        v = np.asarray(values, dtype=float)
        if t.ndim != 1 or t.shape != v.shape or t.size < 1:
            raise ValueError(
                f"Profile.times and values must be 1-D of equal non-zero length, got {t.shape} and {v.shape}"
            )
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
            raise ValueError("Profile.times and values must be finite")
        if np.any(np.diff(t) < 0):
            raise ValueError("Profile.times must be non-decreasing")
        if kind not in ("linear", "step"):
            raise ValueError(f"Profile.kind must be 'linear' or 'step', got {kind!r}")
        self.times = as_float(t)
        self.values = as_float(v)
        self.kind = kind

    @classmethod
    def constant(cls, value):
        return cls([0.0], [value], kind="step")

    def __call__(self, t):
        # Profiles have a handful of breakpoints and are evaluated inside the
        # time loop: "compare_all" is a vectorized compare-and-sum, while the
        # default searchsorted (also inside jnp.interp) is a nested while loop,
        # which made the whole drive step 3-20x slower (benchmarks/).
        n = self.times.shape[-1]
        idx = jnp.searchsorted(self.times, t, side="right", method="compare_all") - 1
        i0 = jnp.clip(idx, 0, n - 1)
        if self.kind == "step":
            return self.values[i0]
        i1 = jnp.clip(idx + 1, 0, n - 1)
        t0, t1 = self.times[i0], self.times[i1]
        v0, v1 = self.values[i0], self.values[i1]
        span = t1 - t0
        frac = jnp.where(span > 0, (t - t0) / jnp.where(span > 0, span, 1.0), 0.0)
        frac = jnp.clip(frac, 0.0, 1.0)
        return jnp.where(idx < 0, self.values[0], v0 + frac * (v1 - v0))


class Scenario(eqx.Module):
    par: PMSMParams  # the machine as it is
    est_par: PMSMParams  # the machine as controller and observer assume it
    speed_ref: Profile  # mechanical speed reference, rad/s (i_q* in A when the FOC's outer loop is 'current')
    load: Profile  # load torque, N·m
    sensors: Sensors
    dead_time: jax.Array  # inverter dead time, s
    key: jax.Array  # PRNG key (noise)
    omega_m0: jax.Array  # initial mechanical speed, rad/s
    theta_e0: jax.Array  # initial electrical angle, rad

    def __init__(
        self,
        par,
        est_par=None,
        speed_ref=None,
        load=None,
        sensors=None,
        dead_time=0.0,
        seed=0,
        omega_m0=0.0,
        theta_e0=0.0,
    ):
        if not isinstance(par, PMSMParams):
            raise ValueError(f"Scenario.par must be a PMSMParams, got {type(par).__name__}")
        self.par = par
        self.est_par = par if est_par is None else est_par
        if self.est_par.p != par.p:
            raise ValueError(f"Scenario.est_par.p must equal par.p ({par.p}), got {self.est_par.p}")
        self.speed_ref = Profile.constant(0.0) if speed_ref is None else speed_ref
        self.load = Profile.constant(0.0) if load is None else load
        self.sensors = Sensors() if sensors is None else sensors
        self.dead_time = check_nonnegative("dead_time", dead_time, "Scenario")
        self.key = jax.random.PRNGKey(seed) if not isinstance(seed, jax.Array) else seed
        self.omega_m0 = check_real("omega_m0", omega_m0, owner="Scenario")
        self.theta_e0 = check_real("theta_e0", theta_e0, owner="Scenario")

    @staticmethod
    def speed_rpm(times, rpms, ramp=0.0):
        """Speed reference (r/min in, rad/s stored) changing to ``rpms[i]`` at ``times[i]``.

        ``ramp = 0``: steps.  ``ramp > 0``: each change is a linear ramp lasting ``ramp`` seconds
        (002's 300-600-840-600-300 r/min test is a ramp profile).
        """
        if len(times) != len(rpms) or not times:
            raise ValueError("speed_rpm needs equally many (>= 1) times and speeds")
        if ramp < 0:
            raise ValueError(f"speed_rpm ramp must be >= 0 s, got {ramp}")
        if ramp == 0:
            return Profile(times, [r * RPM for r in rpms], kind="step")
        tt, vv = [float(times[0])], [rpms[0] * RPM]
        for ti, ri in zip(times[1:], rpms[1:]):
            tt += [float(ti), float(ti) + ramp]
            vv += [vv[-1], ri * RPM]
        return Profile(tt, vv, kind="linear")

    @staticmethod
    def load_steps(times, torques):
        """Load torque (N·m) stepping to ``torques[i]`` at ``times[i]``."""
        return Profile(times, torques, kind="step")


class Batch(eqx.Module):
    """A batched Scenario with the names and coordinates of its axes (row-major over ``dims``)."""

    scenarios: Scenario
    dims: tuple[str, ...] = eqx.field(static=True)
    coords: tuple[tuple[float, ...], ...] = eqx.field(static=True)

    @property
    def shape(self):
        return tuple(len(c) for c in self.coords)

    @property
    def size(self):
        return int(np.prod(self.shape))


def _set_speed(s: Scenario, v):
    return eqx.tree_at(lambda x: x.speed_ref, s, Profile.constant(v * RPM))


def _set_load(s: Scenario, v):
    return eqx.tree_at(lambda x: x.load, s, Profile.constant(v))


def _set_est(field):
    def f(s: Scenario, v):
        return eqx.tree_at(lambda x: getattr(x.est_par, field), s, getattr(s.par, field) * (1 + v))

    return f


def _set_est_L(s: Scenario, v):
    return eqx.tree_at(lambda x: (x.est_par.Ld, x.est_par.Lq), s, (s.par.Ld * (1 + v), s.par.Lq * (1 + v)))


def _set_sensor(field, idx):
    def f(s: Scenario, v):
        arr = getattr(s.sensors, field).at[idx].set(v)
        return eqx.tree_at(lambda x: getattr(x.sensors, field), s, arr)

    return f


def _set_seed(s: Scenario, v):
    return eqx.tree_at(lambda x: x.key, s, jax.random.PRNGKey(int(v)))


GRID_AXES: dict[str, Callable] = {
    "speed_rpm": _set_speed,  # constant speed reference, r/min
    "load_nm": _set_load,  # constant load torque, N·m
    "dRs": _set_est("Rs"),  # est_par.Rs = par.Rs (1 + v)
    "dL": _set_est_L,  # est_par.Ld, Lq = par (1 + v)
    "dLq": _set_est("Lq"),
    "dpsi": _set_est("psi_f"),
    "u_offset_alpha": _set_sensor("u_offset", 0),
    "u_offset_beta": _set_sensor("u_offset", 1),
    "i_offset_alpha": _set_sensor("i_offset", 0),
    "i_offset_beta": _set_sensor("i_offset", 1),
    "dead_time": lambda s, v: eqx.tree_at(lambda x: x.dead_time, s, as_float(v)),
    "seed": _set_seed,
}


def grid(base: Scenario, **axes: Sequence[float]) -> Batch:
    """Cartesian product of named axes applied to ``base``: ``grid(s, speed_rpm=[...], dRs=[...])``.

    Known axes: ``GRID_AXES``.  The batch is flattened row-major (last axis fastest).
    """
    for name, vals in axes.items():
        if name not in GRID_AXES:
            raise ValueError(f"grid axis {name!r} is unknown; known axes: {', '.join(GRID_AXES)}")
        if len(vals) < 1:
            raise ValueError(f"grid axis {name!r} needs at least one value")
    names = tuple(axes)
    coords = tuple(tuple(float(v) for v in axes[n]) for n in names)
    items = []
    for combo in itertools.product(*coords):
        s = base
        for name, v in zip(names, combo):
            s = GRID_AXES[name](s, v)
        items.append(s)
    stacked = jax.tree.map(lambda *xs: jnp.stack(xs), *items)
    return Batch(scenarios=stacked, dims=names, coords=coords)
