"""Scenarios and batches for the drive.

A :class:`Scenario` is a PyTree: the true machine (``par``), what controller and
observer assume (``est_par``), the speed-reference and load-torque profiles,
sensor errors, the inverter dead time, a PRNG key for the noise, and the
initial state.  A batch is a Scenario whose leaves carry a leading axis;
:func:`scenario_batch` builds one from points of named axes (:data:`DRIVE_AXES`, the one set of
drive-axis names that studies, tuning jobs and :func:`grid` share), :func:`grid` from the Cartesian
product of axes (``speed × mismatch × offset``), returning the axis names and coordinates with it, so a
study's results can be labelled.

Three builders make the scenarios that pass through or sit at zero speed, each one :class:`Scenario` the loop
runs: :func:`reversal` (a speed-reference ramp from +n to −n at a given rate, with or without load),
:func:`low_speed_load_step` (a fraction of rated torque stepped on at a few % of rated speed) and
:func:`standstill_hold` (zero speed held under a load); :func:`stack_scenarios` batches several.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from ..core.quantities import Axis, text_unit
from ..core.validate import as_float, check_nonnegative, check_real, key_part
from .hardware import Sensors
from .machine import RPM, PMSMParams

__all__ = [
    "Profile",
    "ParameterDrift",
    "Scenario",
    "Batch",
    "grid",
    "scenario_batch",
    "DRIVE_AXES",
    "stack_scenarios",
]


class Profile(eqx.Module):
    """A piecewise profile of time: linear between breakpoints (``kind="linear"``) or held (``"step"``).

    Before the first breakpoint the first value holds, after the last the last.

    Args:
        times: The breakpoints, s (1-D, finite, non-decreasing).
        values: The values at the breakpoints (1-D, finite, as long as ``times``).
        kind: ``"linear"`` or ``"step"``.

    Raises:
        ValueError: Arrays of other shapes, non-finite or decreasing times, or an unknown ``kind``.
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
    def constant(cls, value: jax.Array | float) -> Profile:
        """A profile that holds one value.

        Args:
            value: The value.

        Returns:
            The :class:`Profile`.
        """
        return cls([0.0], [value], kind="step")

    def __call__(self, t):
        # "compare_all": a vectorized compare-and-sum over a handful of breakpoints, not searchsorted's
        # nested while loop inside the time loop (docs/performance.md)
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


class ParameterDrift(eqx.Module):
    """The observer's assumed machine as a function of time: each given parameter of ``est_par`` scaled by a
    :class:`Profile` of relative values (1 = as ``est_par`` says), ``Scenario(est_drift=...)``.

    002 Fig. 18 ramps the observer's R̂s and L̂q by ±0.5 p.u. during a run at rated load: the DSP's parameter
    values change, the machine does not.  So the drift moves what the *observer* assumes (rebound each period
    by its one binding, :meth:`jaxobs.observers.AbstractDriveObserver.bind`); the FOC keeps ``est_par``, so that
    the position error is the observer's alone.  The factors are leaves: a drift is differentiable and
    batches like any profile; evaluated inside the step (a few compares), no loop over time.

    Args:
        Rs: R̂s(t)/R̂s, a :class:`Profile` of relative values (> 0), or None (constant).
        Ld: L̂d(t)/L̂d, likewise.
        Lq: L̂q(t)/L̂q, likewise.
        psi_f: ψ̂f(t)/ψ̂f, likewise.

    Raises:
        ValueError: No parameter given, or a profile that is not one of relative values > 0.
    """

    Rs: Profile | None  # R̂s(t)/R̂s, 1
    Ld: Profile | None  # L̂d(t)/L̂d, 1
    Lq: Profile | None  # L̂q(t)/L̂q, 1
    psi_f: Profile | None  # ψ̂f(t)/ψ̂f, 1

    def __init__(self, Rs=None, Ld=None, Lq=None, psi_f=None):
        for name, prof in (("Rs", Rs), ("Ld", Ld), ("Lq", Lq), ("psi_f", psi_f)):
            if prof is not None and not isinstance(prof, Profile):
                raise ValueError(f"ParameterDrift.{name} must be a Profile of relative values or None")
            if prof is not None and not bool(np.all(np.asarray(prof.values) > 0)):
                raise ValueError(f"ParameterDrift.{name} must stay > 0 (a relative factor), got {prof.values}")
        if Rs is None and Ld is None and Lq is None and psi_f is None:
            raise ValueError("ParameterDrift needs at least one of Rs, Ld, Lq, psi_f")
        self.Rs, self.Ld, self.Lq, self.psi_f = Rs, Ld, Lq, psi_f

    @classmethod
    def ramps(
        cls, name: str, times: ArrayLike | Sequence[float], factors: ArrayLike | Sequence[float]
    ) -> ParameterDrift:
        """One parameter ramped linearly through relative factors.

        Args:
            name: ``"Rs"``, ``"Ld"``, ``"Lq"`` or ``"psi_f"``.
            times: The breakpoints, s.
            factors: The relative values at the breakpoints (1 = as ``est_par`` says).

        Returns:
            The :class:`ParameterDrift`.
        """
        if name not in ("Rs", "Ld", "Lq", "psi_f"):
            raise ValueError(f"ParameterDrift.ramps: name must be one of Rs, Ld, Lq, psi_f, got {name!r}")
        return cls(**{name: Profile(times, factors, kind="linear")})

    def at(self, est: PMSMParams, t: jax.Array | float) -> PMSMParams:
        """``est`` with the drifting parameters at time ``t``.

        Args:
            est: The assumed machine.
            t: The time, s.

        Returns:
            The :class:`PMSMParams` at ``t``.
        """
        names = tuple(n for n in ("Rs", "Ld", "Lq", "psi_f") if getattr(self, n) is not None)
        return eqx.tree_at(
            lambda q: tuple(getattr(q, n) for n in names),
            est,
            tuple(getattr(est, n) * getattr(self, n)(t) for n in names),
        )


class Scenario(eqx.Module):
    """One drive scenario: the machine, what the controller and observer assume, the references and disturbances.

    Args:
        par: The machine as it is (:class:`PMSMParams`).
        est_par: The machine as controller and observer assume it (default ``par``; the same pole pairs).
        speed_ref: The mechanical speed reference, rad/s (i_q* in A when the FOC's outer loop is
            ``"current"``), a :class:`Profile` (default 0).
        load: The load torque, N·m, a :class:`Profile` (default 0).
        sensors: The :class:`Sensors` (default ideal).
        dead_time: The inverter's dead time, s (≥ 0).
        seed: The PRNG seed of the noise (an integer), or a PRNG key.
        omega_m0: The initial mechanical speed, rad/s.
        theta_e0: The initial electrical angle, rad.
        est_drift: The observer's assumed machine over time (:class:`ParameterDrift`; None: ``est_par``
            throughout).

    Raises:
        ValueError: A value of the wrong type or out of its range, naming the field.
    """

    par: PMSMParams  # the machine as it is
    est_par: PMSMParams  # the machine as controller and observer assume it
    speed_ref: Profile  # mechanical speed reference, rad/s (i_q* in A when the FOC's outer loop is 'current')
    load: Profile  # load torque, N·m
    sensors: Sensors
    dead_time: jax.Array  # inverter dead time, s
    key: jax.Array  # PRNG key (noise)
    omega_m0: jax.Array  # initial mechanical speed, rad/s
    theta_e0: jax.Array  # initial electrical angle, rad
    est_drift: ParameterDrift | None  # the observer's assumed machine over time (None: est_par throughout)

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
        est_drift=None,
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
        if est_drift is not None and not isinstance(est_drift, ParameterDrift):
            raise ValueError(f"Scenario.est_drift must be a ParameterDrift or None, got {type(est_drift).__name__}")
        self.est_drift = est_drift

    @staticmethod
    def speed_rpm(times: Sequence[float], rpms: Sequence[float], ramp: float = 0.0) -> Profile:
        """Speed reference (r/min in, rad/s stored) changing to ``rpms[i]`` at ``times[i]``.

        002's 300-600-840-600-300 r/min test is a ramp profile.

        Args:
            times: The times of the changes, s.
            rpms: The speeds, r/min.
            ramp: 0: steps; > 0: each change is a linear ramp lasting ``ramp`` seconds.

        Returns:
            The :class:`Profile`, rad/s.
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
    def load_steps(times: ArrayLike | Sequence[float], torques: ArrayLike | Sequence[float]) -> Profile:
        """Load torque stepping to ``torques[i]`` at ``times[i]``.

        Args:
            times: The times of the steps, s.
            torques: The torques, N·m.

        Returns:
            The :class:`Profile`.
        """
        return Profile(times, torques, kind="step")


# CF units of the drive's outputs (DriveOutput's fields) and of the observers' common ones, for to_xarray
_OUTPUT_UNITS = {
    "t": "s",
    "theta_e": "rad",
    "theta_e_hat": "rad",
    "omega_m": "rad s-1",
    "omega_m_hat": "rad s-1",
    "omega_m_ref": "rad s-1",
    "i_d": "A",
    "i_q": "A",
    "i_a": "A",
    "i_b": "A",
    "u_a": "V",
    "u_b": "V",
    "torque": "N m",
    "load": "N m",
    "id_ref": "A",
    "iq_ref": "A",
    "mode": "1",
    "obs_theta": "rad",
    "obs_omega": "rad s-1",
}


class Batch(eqx.Module):
    """A batched Scenario with the names and coordinates of its axes (row-major over ``dims``).

    Attributes:
        scenarios: The batched :class:`Scenario` (leading axis one per scenario).
        dims: The axes' names (static).
        coords: Each axis's values (static).
    """

    scenarios: Scenario
    dims: tuple[str, ...] = eqx.field(static=True)
    coords: tuple[tuple[float, ...], ...] = eqx.field(static=True)

    @property
    def shape(self) -> tuple[int, ...]:
        """The grid's shape, one length per axis."""
        return tuple(len(c) for c in self.coords)

    @property
    def size(self) -> int:
        """The number of scenarios."""
        return int(np.prod(self.shape))

    def to_xarray(self, outputs: Any) -> Any:
        """The results of a ``vmap`` over :attr:`scenarios` as an ``xarray.Dataset`` with the grid's dims.

        Each leaf becomes a variable named by its path (``omega_m``, ``obs_theta``; None leaves are skipped)
        with dims ``dims`` for one value per scenario, ``(*dims, "time")`` for a trace when ``outputs`` has a
        ``t`` field shared by every scenario (the ``time`` coordinate, s), else ``<name>_dim<k>`` axes.  The
        grid's axes are coordinates with their CF units; the drive's outputs carry theirs (rad, rad s-1, A, V,
        N m).

        Args:
            outputs: A PyTree (a :class:`~jaxobs.drive.DriveOutput`, a dict of metrics, ...) whose array
                leaves have the batch as leading axis (:attr:`size` rows, row-major over :attr:`dims`).

        Returns:
            The ``xarray.Dataset``.

        Raises:
            ValueError: A leaf's leading axis is not the batch.
        """
        import xarray as xr

        leaves = jax.tree_util.tree_flatten_with_path(outputs)[0]
        named = {}
        for path, leaf in leaves:
            name = "_".join(str(key_part(k)) for k in path)
            arr = np.asarray(leaf)
            if arr.ndim == 0 or arr.shape[0] != self.size:
                raise ValueError(
                    f"to_xarray: {name or 'outputs'} has shape {arr.shape}; its leading axis must be the batch "
                    f"({self.size} scenarios, dims {self.dims})"
                )
            named[name or "value"] = arr.reshape(*self.shape, *arr.shape[1:])
        coords = {d: (d, list(c), DRIVE_AXES[d].attrs) for d, c in zip(self.dims, self.coords)}
        t = named.get("t")
        if t is not None and t.ndim == len(self.dims) + 1:
            flat = t.reshape(-1, t.shape[-1])
            if np.all(flat == flat[0]):  # one time base (the usual vmap over scenarios): a coordinate
                named.pop("t")
                coords["time"] = ("time", flat[0], {"units": "s", "long_name": "sample time"})
        data = {}
        nd = len(self.dims)
        for name, arr in named.items():
            n_t = len(coords["time"][1]) if "time" in coords else -1
            extra = [("time" if k == 0 and arr.shape[nd] == n_t else f"{name}_dim{k}") for k in range(arr.ndim - nd)]
            attrs = {"units": _OUTPUT_UNITS[name]} if name in _OUTPUT_UNITS else {}
            data[name] = ((*self.dims, *extra), arr, attrs)
        return xr.Dataset(data, coords=coords)


# The one table of drive-scenario axes: one Axis each (CF units, allowed range, what it is).  Studies, tuning
# jobs and D.grid take these names; relative mismatches are of the assumed machine against the true one
# (est = true · (1 + v)), ``dJ`` moves the true inertia (the controller keeps the nominal one).
DRIVE_AXES: dict[str, Axis] = {
    a.name: a
    for a in (
        Axis("speed_rpm", "min-1", (1.0, 1e5), "speed (and its reference before the event)"),
        Axis("load_nm", "N m", (-1e4, 1e4), "load torque before the event"),
        Axis("speed_step_rpm", "min-1", (-1e5, 1e5), "step of the speed reference at t_event"),
        Axis("load_step_nm", "N m", (-1e4, 1e4), "step of the load torque at t_event"),
        Axis("dRs", "1", (-0.95, 10.0), "relative error of the assumed stator resistance Rs"),
        Axis("dL", "1", (-0.95, 10.0), "relative error of both assumed inductances Ld and Lq"),
        Axis("dLd", "1", (-0.95, 10.0), "relative error of the assumed d-axis inductance Ld"),
        Axis("dLq", "1", (-0.95, 10.0), "relative error of the assumed q-axis inductance Lq"),
        Axis("dpsi", "1", (-0.95, 10.0), "relative error of the assumed PM flux linkage"),
        Axis("dJ", "1", (-0.95, 100.0), "relative change of the true inertia (controller: nominal)"),
        Axis(
            "dsat",
            "1",
            (-1.0, 10.0),
            "relative change of the true machine's saturation (its map's a_dd, a_qq, a_dq; the controller and "
            "observers keep the nominal machine: its constants, and the reduced-order flux observer its map); a "
            "machine with a saturation map only",
        ),
        Axis("i_noise", "A", (0.0, 1e3), "current-sensor noise (standard deviation)"),
        Axis("u_noise", "V", (0.0, 1e4), "voltage-sensor noise (standard deviation)"),
        Axis("dead_time", "s", (0.0, 1e-4), "inverter dead time"),
        Axis("u_offset_alpha", "V", (-1e4, 1e4), "voltage-sensor offset, alpha axis"),
        Axis("u_offset_beta", "V", (-1e4, 1e4), "voltage-sensor offset, beta axis"),
        Axis("i_offset_alpha", "A", (-1e3, 1e3), "current-sensor offset, alpha axis"),
        Axis("i_offset_beta", "A", (-1e3, 1e3), "current-sensor offset, beta axis"),
        Axis("seed", "1", (0.0, 2.0**31 - 1), "noise seed (PRNGKey(seed) of the scenario)"),
    )
}


def _two_knots(b: int, t_event: float, before, after) -> Profile:
    """A batch of ``b`` step profiles: ``before`` until ``t_event``, ``after`` from it on."""
    p = Profile([0.0, t_event], [0.0, 0.0], kind="step")
    p = jax.tree.map(lambda x: jnp.broadcast_to(x, (b,) + jnp.shape(x)), p)
    return eqx.tree_at(lambda q: q.values, p, jnp.stack([before, after], axis=1))


def _held(prof: Profile, v) -> Profile:
    """The batched profile ``prof`` held at ``v`` (one value per scenario) at every knot."""
    return eqx.tree_at(lambda q: q.values, prof, jnp.broadcast_to(v[:, None], prof.values.shape))


def scenario_batch(
    base: Scenario,
    names: Sequence[str],
    points: Sequence[Sequence[float]],
    *,
    seed: int | None = None,
    t_event: float = 0.0,
    first: int = 0,
) -> Scenario:
    """``base`` with a leading axis, one scenario per point, built vectorized (no constructor per scenario).

    ``speed_rpm`` holds the speed reference at the value and *starts the machine there* (``omega_m0``: the
    scenario starts steady: no start-up transient nobody asked for); ``load_nm`` holds the load;
    ``speed_step_rpm`` and ``load_step_nm`` make the reference and the load step profiles (the value before,
    plus the step from ``t_event`` s on).
    The mismatch axes set the assumed machine from the true one; a noise axis makes the sensors noisy.
    The noise key: ``PRNGKey(v)`` of a ``seed`` axis, else ``fold_in(PRNGKey(seed), i)`` of scenario i when
    ``seed`` is given, else the base's.

    Args:
        base: The :class:`Scenario` every point modifies.
        names: The axes, of :data:`DRIVE_AXES`.
        points: One tuple of values per scenario, in ``names`` order.
        seed: The seed of the scenarios' noise keys (None: the base's key).
        t_event: The time of the steps, s.
        first: The index of ``points[0]`` among all the scenarios, so a chunk built on its own has the keys
            it has in the whole.

    Returns:
        The batched :class:`Scenario`.

    Raises:
        ValueError: An unknown axis or a value out of range, naming it.
    """
    names = tuple(names)
    if not (math.isfinite(t_event) and t_event >= 0):
        raise ValueError(f"t_event must be a finite number of seconds >= 0, got {t_event!r}")
    for name in names:
        if name not in DRIVE_AXES:
            raise ValueError(f"grid axis {name!r} is unknown; known axes: {', '.join(DRIVE_AXES)}")
    if "dL" in names and ({"dLd", "dLq"} & set(names)):
        raise ValueError("grid axis dL sets both inductances: give dL or dLd/dLq, not both")
    b = len(points)
    cols = {n: np.asarray([p[i] for p in points], dtype=float).reshape(b) for i, n in enumerate(names)}
    for name, c in cols.items():
        (lo, hi), unit = DRIVE_AXES[name].range, text_unit(DRIVE_AXES[name].units)
        if not np.all(np.isfinite(c)) or np.any(c < lo) or np.any(c > hi):
            raise ValueError(f"grid axis {name} must be in [{lo:g}, {hi:g}] {unit}")
    if ({"i_noise", "u_noise"} & set(names)) and not base.sensors.noisy:
        # the noise flag is static (Sensors): a noisy Sensors with the base's offsets, gains and levels
        s0 = base.sensors
        noisy = Sensors(s0.i_offset, s0.u_offset, s0.i_gain - 1.0, i_noise=1.0, u_noise=1.0)
        noisy = eqx.tree_at(lambda s: (s.i_gain, s.i_noise, s.u_noise), noisy, (s0.i_gain, s0.i_noise, s0.u_noise))
        base = eqx.tree_at(lambda s: s.sensors, base, noisy)
    sc = jax.tree.map(lambda x: jnp.broadcast_to(x, (b,) + jnp.shape(x)), base)

    def col(name):
        return jnp.asarray(cols[name])

    if "speed_rpm" in cols:
        speed = col("speed_rpm") * RPM
        sc = eqx.tree_at(lambda s: (s.speed_ref, s.omega_m0), sc, (_held(sc.speed_ref, speed), speed))
    if "speed_step_rpm" in cols:
        w0 = sc.speed_ref.values[:, 0]
        ref = _two_knots(b, t_event, w0, w0 + col("speed_step_rpm") * RPM)
        sc = eqx.tree_at(lambda s: s.speed_ref, sc, ref)
    if "load_nm" in cols:
        sc = eqx.tree_at(lambda s: s.load, sc, _held(sc.load, col("load_nm")))
    if "load_step_nm" in cols:
        l0 = sc.load.values[:, 0]
        sc = eqx.tree_at(lambda s: s.load, sc, _two_knots(b, t_event, l0, l0 + col("load_step_nm")))
    par, est = sc.par, sc.est_par
    for axis, fields in (("dRs", ("Rs",)), ("dL", ("Ld", "Lq")), ("dLd", ("Ld",)), ("dLq", ("Lq",))):
        for f in fields if axis in cols else ():
            est = eqx.tree_at(lambda p, f=f: getattr(p, f), est, getattr(par, f) * (1 + col(axis)))
    if "dpsi" in cols:
        est = eqx.tree_at(lambda p: p.psi_f, est, par.psi_f * (1 + col("dpsi")))
    if "dJ" in cols:  # the true inertia; the controller's stays nominal
        par = eqx.tree_at(lambda p: p.J, par, par.J * (1 + col("dJ")))
    if "dsat" in cols:  # the true machine saturates more (or less: −1 leaves the map's unsaturated part)
        if par.sat is None or not par.sat.state_is_flux:
            raise ValueError('grid axis dsat needs a machine with an algebraic saturation map ([machine.saturation] '
                             'model = "algebraic")')  # fmt: skip
        k = 1 + col("dsat")
        sat = par.sat
        par = eqx.tree_at(
            lambda p: (p.sat.a_dd, p.sat.a_qq, p.sat.a_dq), par, (sat.a_dd * k, sat.a_qq * k, sat.a_dq * k)
        )
    sc = eqx.tree_at(lambda s: (s.par, s.est_par), sc, (par, est))
    sens = sc.sensors
    for name in ("i_noise", "u_noise"):
        if name in cols:
            sens = eqx.tree_at(lambda s, n=name: getattr(s, n), sens, col(name))
    for name, field, idx in (
        ("u_offset_alpha", "u_offset", 0),
        ("u_offset_beta", "u_offset", 1),
        ("i_offset_alpha", "i_offset", 0),
        ("i_offset_beta", "i_offset", 1),
    ):
        if name in cols:
            arr = getattr(sens, field).at[:, idx].set(col(name))
            sens = eqx.tree_at(lambda s, f=field: getattr(s, f), sens, arr)
    sc = eqx.tree_at(lambda s: s.sensors, sc, sens)
    if "dead_time" in cols:
        sc = eqx.tree_at(lambda s: s.dead_time, sc, col("dead_time"))
    if "seed" in cols:
        keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(cols["seed"].astype(np.int64)))
        sc = eqx.tree_at(lambda s: s.key, sc, keys)
    elif seed is not None:
        keys = jax.vmap(lambda i: jax.random.fold_in(jax.random.PRNGKey(seed), i))(first + jnp.arange(b))
        sc = eqx.tree_at(lambda s: s.key, sc, keys)
    return sc


def grid(base: Scenario, *, t_event: float = 0.0, **axes: Sequence[float]) -> Batch:
    """Cartesian product of named axes applied to ``base``: ``grid(s, speed_rpm=[...], dRs=[...])``.

    The batch is flattened row-major (last axis fastest).

    Args:
        base: The :class:`Scenario` every point modifies.
        t_event: The time of the steps, s.
        **axes: Values per axis, of :data:`DRIVE_AXES` (:func:`scenario_batch` says what each sets;
            ``speed_rpm`` also starts each scenario at its speed).

    Returns:
        The :class:`Batch`.

    Raises:
        ValueError: An unknown axis or a value out of range, naming it.
    """
    for name, vals in axes.items():
        if name not in DRIVE_AXES:
            raise ValueError(f"grid axis {name!r} is unknown; known axes: {', '.join(DRIVE_AXES)}")
        if len(vals) < 1:
            raise ValueError(f"grid axis {name!r} needs at least one value")
    names = tuple(axes)
    coords = tuple(tuple(float(v) for v in axes[n]) for n in names)
    stacked = scenario_batch(base, names, list(itertools.product(*coords)), t_event=t_event)
    return Batch(scenarios=stacked, dims=names, coords=coords)


def stack_scenarios(scenarios: Sequence[Scenario]) -> Scenario:
    """Scenarios of one structure stacked into a batch (a leading axis, in order), for one ``vmap``.

    Args:
        scenarios: One or more :class:`Scenario` with the same profiles' breakpoint counts and kinds, the same
            sensors' kind and the same drift (the builders above, on one base, with one count each).

    Returns:
        The batched :class:`Scenario`.

    Raises:
        ValueError: No scenario, or scenarios of different structure.
    """
    scs = list(scenarios)
    if not scs or not all(isinstance(s, Scenario) for s in scs):
        raise ValueError("stack_scenarios.scenarios must be one or more Scenario")
    ref = jax.tree.structure(scs[0])
    shapes = [jnp.shape(x) for x in jax.tree.leaves(scs[0])]
    for i, s in enumerate(scs[1:], 1):
        if jax.tree.structure(s) != ref or [jnp.shape(x) for x in jax.tree.leaves(s)] != shapes:
            raise ValueError(
                f"stack_scenarios.scenarios[{i}] differs in structure from scenarios[0] (profiles' breakpoints, "
                "sensors, drift): build them alike"
            )
    return jax.tree.map(lambda *xs: jnp.stack(xs), *scs)
