"""A parsed job as data: :class:`Job`, its scenario sets, its drive and its recordings."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from jaxobs.drive import DriveFile, PMSMParams, shipped_drive
from jaxobs.scenarios.families import FAMILIES, AbstractFamily
from jaxobs.signals import RecordingLayout

from ..aggregations import AbstractAggregation
from ..objective import Term
from ..params import GainSpec
from ..solvers import AbstractSolver

# s, of [envelope]'s runs: a slowly growing low-speed oscillation shows within it (docs/stability.md)
DEFAULT_HORIZON = 2.0


@dataclass
class ScenarioSpec:
    """A job's scenario set (``[scenarios]`` or ``[holdout]``).

    Attributes:
        signal: The scenario family's name (:data:`jaxobs.scenarios.families.FAMILIES`).
        t_event: The event's time, s.
        horizon: The simulated time, s.
        steady_from: The steady window's start, s.
        axes: name -> list of values.
        sample: 0: the full grid; n > 0: n random combinations (seeded).
        seed: The seed of the sampling and the noise.
        recording: ``[scenarios.recording]``: recorded signals instead of a grid, or None.
        family: The scenario family ``signal`` names (:data:`jaxobs.scenarios.families.FAMILIES`), set from it.

    Raises:
        ValueError: ``signal`` names no family.
    """

    signal: str
    t_event: float
    horizon: float
    steady_from: float
    axes: dict[str, list[float]]  # name -> list of values
    sample: int  # 0: full grid; n > 0: n random combinations (seeded)
    seed: int
    recording: RecordingSpec | None = None  # [scenarios.recording]: recorded signals instead of a grid

    # the family `signal` names, looked up once (jaxobs.scenarios.families.FAMILIES: the one place the name is
    # read); a recording stands for this family's signals
    family: type[AbstractFamily] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.signal not in FAMILIES:
            raise ValueError(f"ScenarioSpec.signal must be one of {', '.join(FAMILIES)}, got {self.signal!r}")
        self.family = FAMILIES[self.signal]


@dataclass
class Job:
    """A parsed job (:func:`jaxobs_tuning.parse_job`).

    Attributes:
        raw: The job file's tables as read.
        name: The job's name.
        component: The component's registered name.
        seed: The job's seed.
        values: The constructor values.
        gains: The free gains (:class:`~jaxobs_tuning.params.GainSpec`).
        scenarios: The tuning set.
        holdout: The holdout set, or None.
        terms: The objective's terms.
        aggregation: ``objective.aggregate`` (with alpha, temperature; :mod:`jaxobs_tuning.strategies`).
        penalty: The value of a diverged scenario.
        solver: ``[solver]`` (:mod:`jaxobs_tuning.strategies`).
        sha256: Of the job file's bytes (:func:`jaxobs_tuning.load_job`); None for a job built from a dict.
        drive: ``signal = "drive"`` jobs: how the observer sits in the loop.
        envelope: ``[envelope]`` (:class:`EnvelopeSpec`, :mod:`jaxobs_tuning.job.verify`): verified after tuning;
            None: not.
    """

    raw: dict
    name: str
    component: str
    seed: int
    values: dict[str, Any]  # constructor keywords: numbers, flags, None, [observer.speed]'s record
    gains: list[GainSpec]
    scenarios: ScenarioSpec
    holdout: ScenarioSpec | None
    terms: list[Term]
    aggregation: AbstractAggregation  # objective.aggregate (with alpha, temperature), jaxobs_tuning.strategies
    penalty: float
    solver: AbstractSolver  # [solver], jaxobs_tuning.strategies
    sha256: str | None = None  # of the job file's bytes (load_job); None for a job built from a dict
    drive: DriveSpec | None = None  # signal = "drive" jobs: how the observer sits in the loop
    envelope: EnvelopeSpec | None = None  # [envelope]: verified after tuning; None: not


@dataclass(frozen=True)
class DriveSpec:
    """``[drive]`` of a drive job.

    Attributes:
        loop: ``"sensorless"`` (the default: the tuned observer closes the loop, from t = 0 after its settling
            phase, or from ``handover`` s on) or ``"sensored"`` (the encoder closes it and the observer
            estimates beside it).
        handover: The time from which the observer closes the loop, s.
        settle: The observer's unscored settling phase before t = 0, s.
        start: ``"steady"`` (each scenario starts in its operating point) or ``"standstill"`` (from rest, by
            the I-f start-up :meth:`jaxobs.drive.IfStartup.for_machine` of the job's machine, then its
            hand-over).
        machine: The drive's name: a shipped drive file (:data:`jaxobs.drive.SHIPPED_DRIVES`, by default the
            component's: the LESOs run 002's IPMSM, the flux observers 000's SPMSM), or the name of the
            user's drive file.
        speed_schedule: The FOC's speed-loop schedule N (0 off; N > 0: speed-loop bandwidth min(α_s, |ωe*|/N),
            so a flux observer's FLL, whose bandwidth scales with the speed, can close the loop at low speed:
            docs/stability.md).
        file: The user's checked drive file (:class:`jaxobs.drive.DriveFile`: ``[drive] file = ...`` or its
            tables inline), None for a shipped one.
    """

    loop: str = "sensorless"
    handover: float = 0.0
    settle: float = 0.2
    start: str = "steady"
    machine: str = "ipmsm002"  # a key of SHIPPED_DRIVES or a drive file's name; a job's default: its component's
    speed_schedule: float = 0.0  # FOC.speed_schedule (0: off)
    file: DriveFile | None = field(default=None, compare=False)  # None: the shipped `machine`

    @property
    def drive_file(self) -> DriveFile:
        """The checked drive file this drive runs (:class:`jaxobs.drive.DriveFile`)."""
        return shipped_drive(self.machine) if self.file is None else self.file


@dataclass(frozen=True)
class RecordingSpec:
    """``[scenarios.recording]``: one scenario per file, read at the component's ``ts``.

    Attributes:
        files: The files as written in the job file.
        paths: The files resolved against the job file's folder (or the working folder).
        time_column: A column name or index, or None.
        sample_rate: Hz, when there is no time column.
        columns: The signal's columns.
        truth: The truth columns.
        ts: The component's sample time, s.
        sha256: Of each file's bytes, when checked at parse time.
        layout: A :class:`jaxobs.signals.RecordingLayout` (what a drive log's columns hold), or None.
        trim: Whether recordings of different lengths are cut to the shortest (else refused).
        windows: > 0: this many windows of the horizon spread over each drive log, each a scenario.
        machine: A :class:`~jaxobs.drive.PMSMParams` for a drive log's power and timing checks, or None.
        machine_name: The machine as the job names it (a bench machine or a drive file).
        voltages: How many of ``columns`` are a drive log's voltages, its currents following (given as
            ``voltages`` and ``currents``); None: half of them (given as ``columns``).
        startup_periods: Electrical periods of a drive log's start that its scores skip, at the slowest
            recording's starting speed (``jaxobs_tuning.job.recordings.scored_window``); 0 for a grid recording.
        startup_s: Those periods in seconds, when the files were read at parse time; else None.
    """

    files: tuple[str, ...]  # as written in the job file
    paths: tuple[str, ...]  # resolved against the job file's folder (or the working folder)
    time_column: str | int | None  # a column name or index, or None
    sample_rate: float | None  # Hz, when there is no time column
    columns: tuple[str | int, ...]
    truth: tuple[str | int, ...]
    ts: float
    sha256: tuple[str, ...] = ()  # of each file's bytes, when checked at parse time
    layout: RecordingLayout | None = None  # what a drive log's columns hold, or None
    trim: bool = False  # recordings of different lengths cut to the shortest (else refused)
    windows: int = 0  # > 0: this many windows of the horizon spread over each drive log, each a scenario
    machine: PMSMParams | None = None  # for a drive log's power and timing checks, or None
    machine_name: str | None = None  # as the job names it (a bench machine or a drive file)
    voltages: int | None = None  # how many of columns are voltages (the voltages/currents keys); None: half
    startup_periods: float = 0.0  # electrical periods of a drive log's start its scores skip
    startup_s: float | None = None  # the same in seconds, when the files were read at parse time

    def labels(self) -> list[str]:
        """The scenarios' names: each file's name, or ``file@k`` for the k-th window of a drive log."""
        if not self.windows:
            return list(self.files)
        return [f"{f}@{k}" for f in self.files for k in range(self.windows)]


@dataclass(frozen=True)
class EnvelopeSpec:
    """The envelope a drive job claims: speeds (r/min) and loads (N·m) as [lo, hi]; ``horizon`` (s) of the
    verification runs; ``settle``, ``window``: s, of the stability verdict (:func:`jaxobs.analysis.stability.floquet`;
    the window is lengthened to one electrical period of the lowest speed where it is shorter); ``ideal_sensors``:
    the runs measure through ideal sensors, not the drive file's ``[sensors]`` (the default, as ``jaxobs envelope``
    without ``--ideal-sensors``)."""

    speed_rpm: tuple[float, float]
    load_nm: tuple[float, float]
    horizon: float = DEFAULT_HORIZON
    settle: float = 0.2
    window: float = 0.4
    ideal_sensors: bool = False
