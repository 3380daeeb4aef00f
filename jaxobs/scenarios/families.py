"""Scenario families: what a study or a tuning job runs a design on, and the one place a design is bound.

A family (:class:`AbstractFamily`) declares its axes (one :class:`~jaxobs.core.quantities.Axis` each), builds
a batch of scenarios from named points (:meth:`~AbstractFamily.build`) and makes the system one design
runs on one scenario (:meth:`~AbstractFamily.system`): an observer on a signal, or an observer closing
the drive's loop, bound to the scenario's assumed machine.

    fam = GridSignals(t_event=0.1, freq=50.0)
    batch = fam.build(("freq_step", "dc"), [(1.0, 0.0), (-1.0, 0.05)])
    sol = jaxobs.simulate(fam.system(fll, jax.tree.map(lambda x: x[0], batch)), 0.4)

The families:

- :class:`GridSignals`: single-phase grid voltages with an event (the FLL family), axes
  :data:`jaxobs.scenarios.GRID_SIGNAL_AXES`;
- :class:`EMFSignals`: two-axis back EMFs (the flux observers without a drive), axes
  :data:`jaxobs.scenarios.EMF_SIGNAL_AXES`;
- :class:`DriveScenarios`: the sensorless drive, each scenario started steady (its speed, its load, the
  observer settled before t = 0), axes :data:`DRIVE_STUDY_AXES` (of :data:`jaxobs.drive.DRIVE_AXES`);
- :class:`RecordedSignals`: recorded signals with their truth columns, given whole (one per file).

Each family is built by its own class: its constructor, or :meth:`~AbstractFamily.from_toml` from its TOML
table (a job's ``[scenarios]``, a study file's ``[study]``: the keys it owns, :attr:`~AbstractFamily.options`,
each checked with a ``ValueError`` naming the field) and what the run gives it (the design's nominal frequency,
the drive it closes).  A tuning job's ``scenarios.signal`` names its family: :data:`FAMILIES` maps the name to
the class, once.  Recordings of a family's signals are :meth:`AbstractFamily.recorded`: a
:class:`RecordedSignals` that holds what the recordings are (their columns, whether a design binds to them), the
files read by :func:`jaxobs.signals.read_recorded`.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar, NamedTuple, Self, cast

import equinox as eqx
from jaxtyping import PyTree

from ..core.quantities import Axis
from ..core.system import AbstractSystem
from ..core.validate import check_seconds
from ..drive import DRIVE_AXES as _ALL_DRIVE_AXES
from ..drive import RPM, ClosedLoop, Drive, PMSMParams, Profile, Scenario, Sensors, scenario_batch
from ..observers import AbstractDriveObserver, AbstractObserver
from ..runtime.simulation import OnSignal
from . import EMF_SIGNAL_AXES, GRID_SIGNAL_AXES, emf_signals, grid_signals

__all__ = [
    "AbstractFamily",
    "DRIVE_STUDY_AXES",
    "DriveScenarios",
    "DriveSetting",
    "EMFSignals",
    "FAMILIES",
    "GridSignals",
    "MAX_FREQ_STEP_FRACTION",
    "RecordedSignals",
    "bind_observer",
    "drive_scenarios",
]

# The largest frequency step, as a fraction of the nominal frequency: a "50 Hz" grid at 25 Hz or 75 Hz is
# another grid (tune for that nominal), and an FLL's normalized gains are set at its ω_n.  Grid codes ask
# far less (EN 50160: ±1 %; ride-through 47–52 Hz); a study may still sweep well beyond them.
MAX_FREQ_STEP_FRACTION = 0.5

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


def _t_event(table: Mapping, where: str, default: float) -> float:
    """``<where>.t_event``: a finite number of seconds >= 0."""
    v = table.get("t_event", default)
    check_seconds(f"{where}.t_event:", v, strict=True)
    return float(v)


def _seed(table: Mapping, where: str) -> int:
    """``<where>.seed``: an integer in [0, 2^32)."""
    v = table.get("seed", 0)
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v < 2**32:
        raise ValueError(f"{where}.seed: must be an integer in [0, 2^32), got {v!r}")
    return int(v)


class AbstractFamily(eqx.Module):
    """A family of scenarios: its axes, its batches, and the system a design runs on one of its scenarios.

    Attributes:
        signal: The name a job file gives it, ``scenarios.signal`` (a class attribute).
        axes: name -> :class:`~jaxobs.core.quantities.Axis` (a class attribute).
        closed_loop: Whether the design closes the drive's loop: the drive's metrics apply (a class attribute).
        bytes_per_step: An estimate of the memory a gradient keeps per scenario and step (a class attribute).
        study_bytes_per_step: The same for a study's run (exact metrics, no gradient: an estimate for the study
            files' memory check, not a measurement; a class attribute).
        drive_observer: Whether the design is a drive observer (bound to a machine and a speed), not an FLL on a
            grid voltage: the position metrics apply, and a recording of these signals binds it (a class
            attribute).
        options: The keys of its TOML table it reads (:meth:`from_toml`; a class attribute).
        metrics: Its default metrics, names in :data:`jaxobs.metrics.METRICS` (what its study reports; a class
            attribute).
        flags: Its default flags, boolean metrics of that table, in the order a study stores them (a class
            attribute).
    """

    signal: eqx.AbstractClassVar[str]
    metrics: eqx.AbstractClassVar[tuple]
    flags: eqx.AbstractClassVar[tuple]
    axes: eqx.AbstractClassVar[dict]
    closed_loop: eqx.AbstractClassVar[bool]
    bytes_per_step: eqx.AbstractClassVar[int]
    study_bytes_per_step: eqx.AbstractClassVar[int]
    drive_observer: eqx.AbstractClassVar[bool]
    options: eqx.AbstractClassVar[tuple]
    # a recording of its signals: the default signal and truth columns, and how many truth columns a recording may
    # give; None: none stands for them
    recording_columns: ClassVar[tuple | None] = None

    @abc.abstractmethod
    def build(self, names: Sequence[str], points: Sequence[Sequence[float]], first: int = 0) -> PyTree:
        """The batched scenarios of ``points``.

        Args:
            names: The axes.
            points: Tuples of values for the axes ``names``.
            first: The index of ``points[0]`` among all the scenarios (a chunk built on its own seeds its
                noise as in the whole).

        Returns:
            The batched scenarios (leading axis one per point).
        """

    @abc.abstractmethod
    def system(self, design: AbstractObserver, scenario: PyTree) -> AbstractSystem:
        """The system ``design`` runs on one ``scenario``.

        Args:
            design: The observer.
            scenario: One scenario of this family.

        Returns:
            The :class:`jaxobs.AbstractSystem`.
        """

    @classmethod
    def from_toml(
        cls,
        table: Mapping[str, Any],
        where: str = "scenarios",
        *,
        freq_n: float = 50.0,
        drive: DriveSetting | None = None,
    ) -> Self:
        """The family from its TOML table and what the run gives it.

        The table is a job's ``[scenarios]`` or a study file's ``[study]``: the family reads its own keys
        (:attr:`options`), each checked here; the table's other keys are its reader's.  What is not in a TOML
        table comes from the run, the same two things for every family, each reading what it needs: the
        design's nominal frequency and the drive the design closes.  A family that no file names (one built
        from another, as the envelope's long runs are) keeps this refusal.

        Args:
            table: The TOML table (a mapping of plain values).
            where: The table's name in errors.
            freq_n: The design's nominal frequency, Hz (a grid's).
            drive: What a closed loop runs (:class:`DriveSetting`), or None.

        Returns:
            The family.

        Raises:
            ValueError: ``<where>.<key>`` out of its range, or a needed run input missing.
        """
        raise ValueError(f"{where}: {cls.__name__} is not built from a TOML table")

    @classmethod
    def recorded(cls) -> RecordedSignals:
        """Recordings of this family's signals: their default columns and whether a design binds to them.

        Returns:
            The :class:`RecordedSignals`.

        Raises:
            ValueError: no recording stands for this family's signals.
        """
        if cls.recording_columns is None:
            raise ValueError(f"{cls.__name__}: no recording stands for its signals")
        cols, truth, counts = cls.recording_columns
        return RecordedSignals(cls.signal, cols, truth, counts, cls.drive_observer)

    @classmethod
    def limits(cls, freq_n: float, ts: float) -> dict:
        """Axes whose allowed range depends on the design.

        Args:
            freq_n: The design's nominal frequency, Hz.
            ts: Its sample time, s.

        Returns:
            name -> (low, high), inside the axis's own range.
        """
        return {}

    @classmethod
    def check_axes(cls, axes: dict, where: str = "axes", limits: dict | None = None) -> dict:
        """``axes`` checked against :attr:`axes` (and ``limits``).

        Args:
            axes: name -> values.
            where: The name errors give the table.
            limits: name -> (low, high), narrowing the axes' ranges.

        Returns:
            name -> the checked values.

        Raises:
            ValueError: naming ``where.<axis>`` for an unknown axis, an empty list or a value out of range.
        """
        if not axes:
            raise ValueError(f"{where}: at least one axis is required; allowed: {', '.join(cls.axes)}")
        out = {}
        for name, vals in axes.items():
            if name not in cls.axes:
                raise ValueError(f"{where}.{name}: unknown axis; allowed: {', '.join(cls.axes)}")
            lo, hi = (limits or {}).get(name, (None, None))
            out[name] = cls.axes[name].check(vals, where, low=lo, high=hi)
        return out


class DriveSetting(NamedTuple):
    """What a closed loop runs, beside its scenarios: the true machine, the drive and its sensors (a drive file's,
    :meth:`jaxobs.drive.DriveFile.drive_for`; a shipped bench's sensors are ideal).

    Attributes:
        machine: The true machine (:class:`~jaxobs.drive.PMSMParams`).
        drive: The :class:`~jaxobs.drive.Drive`.
        sensors: The drive's :class:`~jaxobs.drive.Sensors`, or None: ideal.
    """

    machine: PMSMParams
    drive: Drive
    sensors: Sensors | None = None


class GridSignals(AbstractFamily):
    """Single-phase grid voltages (:func:`jaxobs.scenarios.grid_signals`); the design runs on the signal.

    Attributes:
        t_event: The event's time, s.
        freq: The nominal frequency, Hz.
        seed: The seed of the white noise, drawn per scenario.
    """

    t_event: float = eqx.field(static=True)
    freq: float = eqx.field(static=True)
    seed: int = eqx.field(static=True, default=0)

    signal: ClassVar[str] = "grid"
    axes: ClassVar[dict] = GRID_SIGNAL_AXES
    closed_loop: ClassVar[bool] = False
    bytes_per_step: ClassVar[int] = 512
    study_bytes_per_step: ClassVar[int] = 256
    drive_observer: ClassVar[bool] = False
    options: ClassVar[tuple] = ("t_event", "seed")
    metrics: ClassVar[tuple[str, ...]] = ("settling_freq", "ripple_freq", "rms_phase_steady", "itae_freq", "iae_phase")
    flags: ClassVar[tuple[str, ...]] = ("settled", "diverged", "lost_lock")
    # a recording of it: the voltage column; the truth columns (phase rad, ω rad/s, amplitude), how many
    recording_columns: ClassVar[tuple] = (("v",), ("theta", "omega", "amplitude"), (3,))

    def __check_init__(self):
        check_seconds("t_event", self.t_event)
        if not (math.isfinite(self.freq) and self.freq > 0):
            raise ValueError(f"freq must be a finite frequency > 0 Hz, got {self.freq!r}")

    @classmethod
    def from_toml(
        cls,
        table: Mapping[str, Any],
        where: str = "scenarios",
        *,
        freq_n: float = 50.0,
        drive: DriveSetting | None = None,
    ) -> Self:
        """``t_event`` (s, >= 0; default 0.1) and ``seed`` (default 0) from ``table``; the grid's nominal
        frequency is the design's ``freq_n``; ``drive`` does not apply (an FLL closes no loop).

        Args:
            table: The TOML table.
            where: Its name in errors.
            freq_n: The design's nominal frequency, Hz.
            drive: Must be None.

        Returns:
            The :class:`GridSignals`.

        Raises:
            ValueError: ``<where>.t_event`` or ``<where>.seed`` out of range, ``freq_n`` not > 0, or a drive.
        """
        if drive is not None:
            raise ValueError(f"{where}: grid signals run an FLL on a grid voltage: no drive applies")
        if not (math.isfinite(freq_n) and freq_n > 0):
            raise ValueError(f"{where}: the design's nominal frequency must be > 0 Hz, got {freq_n!r}")
        return cls(_t_event(table, where, 0.1), float(freq_n), _seed(table, where))

    def build(self, names: Sequence[str], points: Sequence[Sequence[float]], first: int = 0) -> PyTree:
        """The batched scenarios of ``points`` (:meth:`AbstractFamily.build`).

        Args:
            names: The axes.
            points: Tuples of values for the axes ``names``.
            first: The index of ``points[0]`` among all the scenarios.

        Returns:
            The batched :class:`~jaxobs.scenarios.NoisyGridSignal` (leading axis one per point).
        """
        return grid_signals(names, points, self.t_event, self.freq, seed=self.seed, first=first)

    def system(self, design: AbstractObserver, scenario: PyTree) -> AbstractSystem:
        """The system ``design`` runs on one ``scenario`` (:meth:`AbstractFamily.system`).

        Args:
            design: The observer.
            scenario: One scenario of this family.

        Returns:
            The :class:`~jaxobs.OnSignal` of the observer on the grid voltage.
        """
        return OnSignal(design, scenario)

    @classmethod
    def limits(cls, freq_n: float, ts: float) -> dict:
        """``freq_step`` (Hz): at most :data:`MAX_FREQ_STEP_FRACTION` of ``freq_n`` either way, and below the
        sampling limit (the frequency after the step stays under 1/(4 ts)).

        Args:
            freq_n: The grid's nominal frequency, Hz.
            ts: The sample time, s.

        Returns:
            ``{"freq_step": (low, high)}``.
        """
        lo, hi = cls.axes["freq_step"].range
        step = MAX_FREQ_STEP_FRACTION * freq_n
        return {"freq_step": (max(lo, -step), min(hi, step, 0.25 / ts - freq_n))}


class EMFSignals(AbstractFamily):
    """Two-axis back EMFs (:func:`jaxobs.scenarios.emf_signals`): 100 V at 50 Hz, proportional to speed; the
    design (a flux observer) runs on the signal."""

    signal: ClassVar[str] = "emf"
    axes: ClassVar[dict] = EMF_SIGNAL_AXES
    closed_loop: ClassVar[bool] = False
    bytes_per_step: ClassVar[int] = 512
    study_bytes_per_step: ClassVar[int] = 256
    drive_observer: ClassVar[bool] = True
    options: ClassVar[tuple] = ()  # the back EMFs have no event, no noise and a fixed nominal
    metrics: ClassVar[tuple[str, ...]] = ("iae_position", "rms_position_steady", "bias_position")
    flags: ClassVar[tuple[str, ...]] = ("diverged", "lost_lock")
    # a recording of a drive: u and i; the truth columns (encoder angle rad [, speed rad/s]), how many
    recording_columns: ClassVar[tuple] = (("u_a", "u_b", "i_a", "i_b"), ("theta_e", "omega_e"), (1, 2))

    @classmethod
    def from_toml(
        cls,
        table: Mapping[str, Any],
        where: str = "scenarios",
        *,
        freq_n: float = 50.0,
        drive: DriveSetting | None = None,
    ) -> Self:
        """The back EMFs read no key of ``table`` (their reader checks its own) and no run input.

        Args:
            table: The TOML table.
            where: Its name in errors.
            freq_n: Not read (the EMFs' 50 Hz is the axes' base).
            drive: Must be None.

        Returns:
            The :class:`EMFSignals`.

        Raises:
            ValueError: a drive (the design runs on the signal, open loop).
        """
        if drive is not None:
            raise ValueError(f"{where}: back-EMF signals run the observer open loop: no drive applies")
        return cls()

    def build(self, names: Sequence[str], points: Sequence[Sequence[float]], first: int = 0) -> PyTree:
        """The batched scenarios of ``points`` (:meth:`AbstractFamily.build`).

        Args:
            names: The axes.
            points: Tuples of values for the axes ``names``.
            first: The index of ``points[0]`` among all the scenarios.

        Returns:
            The batched :class:`~jaxobs.EMFSignal` (leading axis one per point).
        """
        return emf_signals(names, points)

    def system(self, design: AbstractObserver, scenario: PyTree) -> AbstractSystem:
        """The system ``design`` runs on one ``scenario`` (:meth:`AbstractFamily.system`).

        Args:
            design: The observer.
            scenario: One scenario of this family.

        Returns:
            The :class:`~jaxobs.OnSignal` of the observer on the back EMF.
        """
        return OnSignal(design, scenario)

    @classmethod
    def limits(cls, freq_n: float, ts: float) -> dict:
        """``speed_hz`` below the sampling limit 1/(4 ts).

        Args:
            freq_n: The design's nominal frequency, Hz.
            ts: The sample time, s.

        Returns:
            ``{"speed_hz": (low, high)}``.
        """
        lo, hi = cls.axes["speed_hz"].range
        return {"speed_hz": (lo, min(hi, 0.25 / ts))}


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


class RecordedSignals(AbstractFamily):
    """Recorded signals with their truth columns, given whole (a sampler that holds them:
    :class:`jaxobs.scenarios.Recordings`); made by the family they stand for (:meth:`AbstractFamily.recorded`).

    The files are read by :func:`jaxobs.signals.read_recorded`; the family holds what they are.

    Attributes:
        source: The name of the family the recordings stand for (:data:`FAMILIES`; a label, never compared).
        columns: The signal columns a recording has by default: a grid voltage's, or a drive's u and i.
        truth: The truth columns by default: the phase, frequency and amplitude (grid), or the encoder's angle and
            speed.
        truth_counts: How many truth columns a recording may give.
        binds: Whether the design is bound to the recording (a drive observer on u and i: bound to the recorded
            speed at t = 0, run open loop), not run on it as is (an FLL on a grid voltage).
    """

    source: str = eqx.field(static=True)
    columns: tuple = eqx.field(static=True)
    truth: tuple = eqx.field(static=True)
    truth_counts: tuple = eqx.field(static=True)
    binds: bool = eqx.field(static=True)

    signal: ClassVar[str] = "recording"
    axes: ClassVar[dict] = {}
    closed_loop: ClassVar[bool] = False
    bytes_per_step: ClassVar[int] = 512
    study_bytes_per_step: ClassVar[int] = 256
    drive_observer: ClassVar[bool] = False  # the instance's binds says which observer runs on it
    options: ClassVar[tuple] = ()
    # the one study on recordings is the FLL study's (jaxobs.studies.study.run_study on a Recordings sampler)
    metrics: ClassVar[tuple[str, ...]] = GridSignals.metrics
    flags: ClassVar[tuple[str, ...]] = GridSignals.flags

    @classmethod
    def from_toml(
        cls,
        table: Mapping[str, Any],
        where: str = "scenarios",
        *,
        freq_n: float = 50.0,
        drive: DriveSetting | None = None,
    ) -> Self:
        """Recordings are made by the family they stand for (:meth:`AbstractFamily.recorded`), their files
        described by the recording table's reader (``jaxobs_tuning.job.recordings``).

        Args:
            table: The TOML table.
            where: Its name in errors.
            freq_n: Unused.
            drive: Unused.

        Returns:
            Nothing: it raises.

        Raises:
            ValueError: always: name the family the recordings stand for.
        """
        raise ValueError(f"{where}.recording: recordings stand for a family's signals: use <Family>.recorded()")

    def build(self, names: Sequence[str], points: Sequence[Sequence[float]], first: int = 0) -> PyTree:
        """Refused: recorded signals are given whole (:class:`jaxobs.scenarios.Recordings`).

        Args:
            names: The axes.
            points: Tuples of values for the axes ``names``.
            first: The index of ``points[0]`` among all the scenarios.

        Returns:
            Nothing: it raises.

        Raises:
            ValueError: always.
        """
        raise ValueError("recorded signals are given whole (jaxobs.scenarios.Recordings): they are not built")

    def system(self, design: AbstractObserver, scenario: PyTree) -> AbstractSystem:
        """The system ``design`` runs on one ``scenario`` (:meth:`AbstractFamily.system`).

        Args:
            design: The observer.
            scenario: One scenario of this family.

        Returns:
            The :class:`~jaxobs.OnSignal` of the observer on the recording (bound to its speed at t = 0 where it binds).
        """
        # a drive observer starts from the recorded speed at t = 0 (the encoder's); est_par None keeps its own
        # Rs and L (a recording gives the speed, not the machine)
        if not self.binds:
            return OnSignal(design, scenario)
        bound = cast(AbstractDriveObserver, design).bind(None, scenario.omega_e[..., 0])  # binds: a drive observer
        return OnSignal(cast(AbstractObserver, bound), scenario)


# the base's first name, kept for code written against it: a family is not a batch of scenarios (docs/architecture.md,
# "Scenario, family, sampler")
AbstractScenarios = AbstractFamily

# a job file's ``scenarios.signal`` -> its family (the one place the name is read)
FAMILIES: dict[str, type[AbstractFamily]] = {f.signal: f for f in (GridSignals, EMFSignals, DriveScenarios)}
