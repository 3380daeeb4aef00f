"""The drive family: the sensorless drive, each scenario started steady (:class:`DriveScenarios`), its
scenarios (:func:`drive_scenarios`) and the one binding of an observer to a scenario (:func:`bind_observer`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar, Self, cast

import equinox as eqx
from jaxtyping import PyTree

from ...core.quantities import Axis
from ...core.validate import check_seconds
from ...drive import DRIVE_AXES as _ALL_DRIVE_AXES
from ...drive import RPM, ClosedLoop, Drive, PMSMParams, Profile, Scenario, Sensors, scenario_batch
from ...io.provenance import provenance
from ...metrics import METRICS, MetricContext
from ...observers import AbstractDriveObserver, AbstractObserver
from .. import LHS, AbstractSampler, Grid, Random, Sobol
from ._base import AbstractFamily, DriveSetting, StudyPlan, _seed, _t_event
from .signals import EMFSignals

__all__ = ["DRIVE_STUDY_AXES", "DriveScenarios", "bind_observer", "drive_scenarios"]


# the drive axes a study or a job varies: all of DRIVE_AXES but dL (dLd and dLq together), the sensor
# offsets and a per-scenario seed (a study's noise keys come from its own seed)
DRIVE_STUDY_AXES: dict[str, Axis] = {
    name: a
    for name, a in _ALL_DRIVE_AXES.items()
    if name not in ("dL", "u_offset_alpha", "u_offset_beta", "i_offset_alpha", "i_offset_beta", "seed")
}


def bind_observer(obs: AbstractObserver, sc: Scenario) -> AbstractDriveObserver:
    """The observer bound to the scenario's assumed machine and initial speed: ``obs.bind(est_par, p̂·ω_m0)``
    (:meth:`jaxobs.observers.AbstractDriveObserver.bind`, the one binding).

    Args:
        obs: A drive observer.
        sc: The :class:`~jaxobs.drive.Scenario`.

    Returns:
        The bound observer.

    Raises:
        ValueError: ``obs`` is not a drive observer.
    """
    if not isinstance(obs, AbstractDriveObserver):
        raise ValueError(f"drive study: {type(obs).__name__} is not a drive observer (a LESO or a flux observer)")
    # bind returns the observer bound (AbstractDriveObserver.bind declares no return type)
    return cast(AbstractDriveObserver, obs.bind(sc.est_par, sc.est_par.p * sc.omega_m0))


def drive_scenarios(
    machine: PMSMParams,
    names: Sequence[str],
    combos: Sequence[Sequence[float]],
    *,
    seed: int = 0,
    t_event: float = 0.0,
    first: int = 0,
    sensors: Sensors | None = None,
) -> Scenario:
    """A batched Scenario (leading axis len(combos)), one per combination of the named axes' values
    (:func:`jaxobs.drive.scenario_batch` on ``machine``).

    Each starts steady at ``speed_rpm`` (600 r/min without the axis) and ``load_nm``; the speed reference
    and the load step by ``speed_step_rpm`` and ``load_step_nm`` at ``t_event`` (both 0 by default: no event).

    Args:
        machine: The true machine.
        names: The axes, of :data:`jaxobs.drive.DRIVE_AXES`.
        combos: One tuple of values per scenario, in ``names`` order.
        seed: The seed of the noise keys.
        t_event: The time of the steps, s (≥ 0).
        first: The index of ``combos[0]`` among all the scenarios, for a chunk built on its own.
        sensors: The drive's :class:`~jaxobs.drive.Sensors`, or None: ideal; the noise and offset axes set
            their own.

    Returns:
        The batched :class:`~jaxobs.drive.Scenario`.

    Raises:
        ValueError: ``t_event`` is negative or not finite, or an axis or value is refused by ``scenario_batch``.
    """
    check_seconds("t_event", t_event)
    two = Profile([0.0, t_event], [600.0 * RPM] * 2, kind="step")  # before / after the event
    zero = Profile([0.0, t_event], [0.0, 0.0], kind="step")
    base = Scenario(machine, speed_ref=two, load=zero, omega_m0=600.0 * RPM, sensors=sensors)
    return scenario_batch(base, names, combos, seed=seed, t_event=t_event, first=first)


class DriveScenarios(AbstractFamily):
    """The sensorless drive on ``machine``: each scenario (:func:`drive_scenarios`) starts steady.

    The design closes ``drive``'s loop, bound to the scenario's assumed machine and speed
    (:func:`bind_observer`).

    Attributes:
        machine: The true machine.
        drive: The :class:`~jaxobs.drive.Drive`.
        t_event: The time the speed reference and the load step, s.
        seed: The seed of the noise keys.
        sensors: A drive file's sensors (None: ideal), the noise axes' base.
    """

    machine: PMSMParams
    drive: Drive
    t_event: float = eqx.field(static=True, default=0.0)
    seed: int = eqx.field(static=True, default=0)
    sensors: Sensors | None = None  # a drive file's sensors (None: ideal), the noise axes' base

    signal: ClassVar[str] = "drive"
    axes: ClassVar[dict] = DRIVE_STUDY_AXES
    closed_loop: ClassVar[bool] = True
    bytes_per_step: ClassVar[int] = 2048
    study_bytes_per_step: ClassVar[int] = 1024
    drive_observer: ClassVar[bool] = True
    options: ClassVar[tuple] = ("t_event", "seed")
    metrics: ClassVar[tuple[str, ...]] = (
        "rms_position_steady",
        "peak_position_steady",
        "rms_speed_estimate_steady",
        "speed_noise",
        "bias_position",
        "peak_speed_deviation",
    )
    flags: ClassVar[tuple[str, ...]] = ("lost_lock", "lost_speed", "diverged")
    recording_columns: ClassVar[tuple] = EMFSignals.recording_columns
    study_quantiles: ClassVar[tuple[float, ...]] = (0.5, 0.95, 0.99, 1.0)  # a study's, over the scenarios

    @classmethod
    def from_toml(
        cls,
        table: Mapping[str, Any],
        where: str = "scenarios",
        *,
        freq_n: float = 50.0,
        drive: DriveSetting | None = None,
    ) -> Self:
        """``t_event`` (s, >= 0; default 0: no event) and ``seed`` (default 0) from ``table``; the machine, the
        drive and its sensors from ``drive`` (required: the design closes its loop).

        Args:
            table: The TOML table.
            where: Its name in errors.
            freq_n: Not read (the drive's speed is an axis).
            drive: The :class:`DriveSetting` the scenarios run.

        Returns:
            The :class:`DriveScenarios`.

        Raises:
            ValueError: ``<where>.t_event`` or ``<where>.seed`` out of range, or no drive.
        """
        if not isinstance(drive, DriveSetting):
            raise ValueError(f"{where}: drive scenarios need the drive they close (a DriveSetting), got {drive!r}")
        return cls(
            drive.machine,
            drive.drive,
            t_event=_t_event(table, where, 0.0),
            seed=_seed(table, where),
            sensors=drive.sensors,
        )

    def build(self, names: Sequence[str], points: Sequence[Sequence[float]], first: int = 0) -> PyTree:
        """The batched scenarios of ``points`` (:meth:`AbstractFamily.build`).

        Args:
            names: The axes.
            points: Tuples of values for the axes ``names``.
            first: The index of ``points[0]`` among all the scenarios.

        Returns:
            The batched :class:`~jaxobs.drive.Scenario` (leading axis one per point).
        """
        return drive_scenarios(
            self.machine, names, points, seed=self.seed, t_event=self.t_event, first=first, sensors=self.sensors
        )

    def system(self, design: AbstractObserver, scenario: PyTree) -> ClosedLoop:
        """The system ``design`` runs on one ``scenario`` (:meth:`AbstractFamily.system`).

        Args:
            design: The observer.
            scenario: One scenario of this family.

        Returns:
            The :class:`~jaxobs.drive.ClosedLoop` with the observer bound to the scenario's assumed machine.
        """
        return ClosedLoop(self.drive, bind_observer(design, scenario), scenario)

    def draw_seed(self) -> int:
        return self.seed

    def study_plan(
        self,
        designs: Mapping[str, AbstractObserver],
        sampler: AbstractSampler,
        *,
        horizon: float,
        steady_from: float | None = None,
        band_hz: float | None = None,
    ) -> StudyPlan:
        """The drive study: position, speed-estimate and speed-deviation metrics over the steady window (from half
        the horizon by default), their quantiles :attr:`study_quantiles`, a lost-lock scenario's metrics masked and
        counted; the attributes hold the true machine and the drive's timing (:mod:`jaxobs.studies.drive`).

        Args:
            designs: name -> drive observer.
            sampler: The scenarios' sampler.
            horizon: The runs' length, s (finite, > 0, above ``t_event``).
            steady_from: The steady window's start, s in [0, horizon); None: ``horizon / 2``.
            band_hz: Must be None (a drive's metrics have no settling band).

        Returns:
            The :class:`~jaxobs.scenarios.families.StudyPlan`.

        Raises:
            ValueError: a drive that is not sensorless, an axis refused, ``band_hz`` given, or ``horizon``,
                ``steady_from`` or ``t_event`` out of range.
        """
        if band_hz is not None:
            raise ValueError("band_hz applies to a study of grid signals (an FLL's settling band), not to a drive")
        if isinstance(sampler, (Grid, Random, Sobol, LHS)):
            self.check_axes(dict(sampler.axes), "axes")
        if not self.drive.sensorless:
            raise ValueError("drive study: the drive must be sensorless (Drive(..., sensorless=True))")
        if not (horizon > 0 and math.isfinite(horizon)):
            raise ValueError(f"horizon must be a finite number of seconds > 0, got {horizon!r}")
        steady_from = 0.5 * horizon if steady_from is None else float(steady_from)
        if not 0 <= steady_from < horizon:
            raise ValueError(f"steady_from must be in [0, horizon), got {steady_from!r}")
        if not (math.isfinite(self.t_event) and 0 <= self.t_event < horizon):
            raise ValueError(f"t_event must be in [0, horizon = {horizon:g}) s, got {self.t_event!r}")
        m, drive = self.machine, self.drive
        attrs: dict[str, Any] = dict(
            horizon=horizon, steady_from=steady_from, t_event=self.t_event, sampling=sampler.sampling, seed=self.seed
        )
        # the true machine (the assumed one is this, moved by the mismatch axes) and the drive's controller
        attrs.update({f"machine_{f}": float(getattr(m, f)) for f in ("Rs", "Ld", "Lq", "psi_f", "p", "J")})
        attrs.update(drive_ts=float(drive.ts), drive_settle=float(drive.settle))
        # provenance, and nothing that differs between two identical runs (the run time is not stored)
        attrs.update(provenance("jaxobs.studies.study.run_study"))
        flags = tuple(METRICS[k] for k in self.flags)
        ctx = MetricContext(t_event=self.t_event, steady_from=steady_from)
        return StudyPlan(self, self.metrics, flags, ctx, "lost_lock", self.study_quantiles, None, attrs, "drive study")
