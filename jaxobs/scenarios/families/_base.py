"""The base of the scenario families (:class:`AbstractFamily`), what a closed loop runs beside its scenarios
(:class:`DriveSetting`), what a family's study runs (:class:`StudyPlan`) and the recorded signals that stand
for a family's (:class:`RecordedSignals`); the package's doc says what a family is."""

from __future__ import annotations

import abc
from collections.abc import Callable, Hashable, Mapping, Sequence
from typing import Any, ClassVar, NamedTuple, Self, cast

import equinox as eqx
from jaxtyping import PyTree

from ...core.system import AbstractSystem
from ...core.validate import check_seconds
from ...drive import Drive, PMSMParams, Sensors
from ...metrics import Metric, MetricContext
from ...observers import AbstractDriveObserver, AbstractObserver
from ...runtime.simulation import OnSignal
from .. import AbstractSampler

__all__ = ["AbstractFamily", "DriveSetting", "RecordedSignals", "StudyPlan"]


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


# the FLL family's default metrics and flags (GridSignals'), which its recordings share
FLL_METRICS = ("settling_freq", "ripple_freq", "rms_phase_steady", "itae_freq", "iae_phase")
FLL_FLAGS = ("settled", "diverged", "lost_lock")


class StudyPlan(NamedTuple):
    """What a family's study runs beside its designs and sampler (:meth:`AbstractFamily.study_plan`), read by
    the one study preset, :func:`jaxobs.studies.study.run_study`.

    Attributes:
        family: The family that builds the batches and the systems (a recordings sampler's: the recorded family).
        metrics: The metrics' names in :data:`jaxobs.metrics.METRICS`, one variable each.
        flags: The flags (the table's boolean metrics), in the order the Dataset stores them.
        ctx: What the metrics read (:class:`jaxobs.metrics.MetricContext`).
        mask: The flag whose scenarios' metrics are NaN, or None.
        quantiles: The quantiles over each design's unmasked scenarios (none: no ``<metric>_q``).
        static: A design's hashable value the metrics need outside tracing (the FLL's settling window), or None.
        attrs: The Dataset's attributes: the options, the provenance.
        label: The study's name in progress bars and the Dataset's title.
    """

    family: AbstractFamily
    metrics: tuple[str, ...]
    flags: tuple[Metric, ...]
    ctx: MetricContext
    mask: str | None
    quantiles: tuple[float, ...]
    static: Callable[[Any], Hashable] | None
    attrs: dict[str, Any]
    label: str


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
    # its study's defaults (jaxobs.studies.study.run_study): the runs' length, s, and the scenarios per compiled
    # call (a drive's scenario keeps about 8x an FLL's state: 256 of them fill what 2048 FLL runs do)
    study_horizon: ClassVar[float] = 0.3
    study_chunk: ClassVar[int] = 256

    def draw_seed(self) -> int:
        """The seed a study draws its random points with: the family's own noise seed, or 0.

        Returns:
            The seed, an integer in [0, 2^32).
        """
        return 0

    def study_plan(
        self,
        designs: Mapping[str, AbstractObserver],
        sampler: AbstractSampler,
        *,
        horizon: float,
        steady_from: float | None = None,
        band_hz: float | None = None,
    ) -> StudyPlan:
        """What a study of this family runs: its metrics, flags, metric context, mask, quantiles and attributes
        (the one study preset, :func:`jaxobs.studies.study.run_study`, reads it).

        Args:
            designs: name -> design.
            sampler: The scenarios' sampler (:mod:`jaxobs.scenarios`).
            horizon: The runs' length, s.
            steady_from: The steady window's start, s; None: the family's rule.
            band_hz: The settling band of a frequency estimate, Hz, where the family's metrics have one; None: its
                default.

        Returns:
            The :class:`StudyPlan`.

        Raises:
            ValueError: the family has no study (the base's refusal), or an option out of its range.
        """
        raise ValueError(
            f"{type(self).__name__}: no study runs on this family (studies run GridSignals, their recordings, and "
            "DriveScenarios)"
        )

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
    metrics: ClassVar[tuple[str, ...]] = FLL_METRICS
    flags: ClassVar[tuple[str, ...]] = FLL_FLAGS

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
