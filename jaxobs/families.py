"""Scenario families: what a study or a tuning job runs a design on, and the one place a design is bound.

A family (:class:`AbstractScenarios`) declares its axes (one :class:`~jaxobs.quantities.Axis` each), builds
a batch of scenarios from named points (:meth:`~AbstractScenarios.build`) and makes the system one design
runs on one scenario (:meth:`~AbstractScenarios.system`): an observer on a signal, or an observer closing
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

A tuning job's ``scenarios.signal`` names its family: :data:`FAMILIES` maps the name to the class, once.
"""

from __future__ import annotations

import abc
import math
from typing import ClassVar

import equinox as eqx

from ._simulate import OnSignal
from .drive import DRIVE_AXES as _ALL_DRIVE_AXES
from .drive import RPM, ClosedLoop, Drive, PMSMParams, Profile, Scenario, Sensors, scenario_batch
from .observers import AbstractDriveObserver
from .quantities import Axis
from .scenarios import EMF_SIGNAL_AXES, GRID_SIGNAL_AXES, emf_signals, grid_signals
from .signals import DriveRecording, RecordingLayout, SampledSignal, read_drive_log

__all__ = [
    "AbstractScenarios",
    "DRIVE_STUDY_AXES",
    "DriveScenarios",
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


def bind_observer(obs, sc: Scenario):
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
    return obs.bind(sc.est_par, sc.est_par.p * sc.omega_m0)


def drive_scenarios(
    machine: PMSMParams,
    names,
    combos,
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
    if not (math.isfinite(t_event) and t_event >= 0):
        raise ValueError(f"t_event must be a finite number of seconds >= 0, got {t_event!r}")
    two = Profile([0.0, t_event], [600.0 * RPM] * 2, kind="step")  # before / after the event
    zero = Profile([0.0, t_event], [0.0, 0.0], kind="step")
    base = Scenario(machine, speed_ref=two, load=zero, omega_m0=600.0 * RPM, sensors=sensors)
    return scenario_batch(base, names, combos, seed=seed, t_event=t_event, first=first)


class AbstractScenarios(eqx.Module):
    """A family of scenarios: its axes, its batches, and the system a design runs on one of its scenarios.

    Attributes:
        signal: The name a job file gives it, ``scenarios.signal`` (a class attribute).
        axes: name -> :class:`~jaxobs.quantities.Axis` (a class attribute).
        closed_loop: Whether the design closes the drive's loop: the drive's metrics apply (a class attribute).
        bytes_per_step: An estimate of the memory a gradient keeps per scenario and step (a class attribute).
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

    @abc.abstractmethod
    def build(self, names, points, first: int = 0):
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
    def system(self, design, scenario):
        """The system ``design`` runs on one ``scenario``.

        Args:
            design: The observer.
            scenario: One scenario of this family.

        Returns:
            The :class:`jaxobs.AbstractSystem`.
        """

    @classmethod
    def of(cls, *, t_event: float = 0.0, seed: int = 0, freq: float = 50.0, machine=None, drive=None, sensors=None):
        """The family with these options, each family taking the ones it has.

        Args:
            t_event: The event's time, s.
            seed: The seed of the noise keys.
            freq: A grid's nominal frequency, Hz.
            machine: The drive's true machine.
            drive: The :class:`~jaxobs.drive.Drive`.
            sensors: The drive's: a drive file's :class:`~jaxobs.drive.Sensors`, or None: ideal.

        Returns:
            The family.
        """
        return cls()

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


class GridSignals(AbstractScenarios):
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
    metrics: ClassVar[tuple[str, ...]] = ("settling_freq", "ripple_freq", "rms_phase_steady", "itae_freq", "iae_phase")
    flags: ClassVar[tuple[str, ...]] = ("settled", "diverged", "lost_lock")
    # a recording of it: the voltage column; the truth columns (phase rad, ω rad/s, amplitude), how many
    recording_columns: ClassVar[tuple] = (("v",), ("theta", "omega", "amplitude"))
    truth_counts: ClassVar[tuple] = (3,)

    @classmethod
    def of(cls, *, t_event: float = 0.0, seed: int = 0, freq: float = 50.0, machine=None, drive=None, sensors=None):
        return cls(t_event, freq, seed)

    def build(self, names, points, first: int = 0):
        return grid_signals(names, points, self.t_event, self.freq, seed=self.seed, first=first)

    def system(self, design, scenario):
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


class EMFSignals(AbstractScenarios):
    """Two-axis back EMFs (:func:`jaxobs.scenarios.emf_signals`): 100 V at 50 Hz, proportional to speed; the
    design (a flux observer) runs on the signal."""

    signal: ClassVar[str] = "emf"
    axes: ClassVar[dict] = EMF_SIGNAL_AXES
    closed_loop: ClassVar[bool] = False
    bytes_per_step: ClassVar[int] = 512
    metrics: ClassVar[tuple[str, ...]] = ("iae_position", "rms_position_steady", "bias_position")
    flags: ClassVar[tuple[str, ...]] = ("diverged", "lost_lock")
    # a recording of a drive: u and i; the truth columns (encoder angle rad [, speed rad/s]), how many
    recording_columns: ClassVar[tuple] = (("u_a", "u_b", "i_a", "i_b"), ("theta_e", "omega_e"))
    truth_counts: ClassVar[tuple] = (1, 2)

    def build(self, names, points, first: int = 0):
        return emf_signals(names, points)

    def system(self, design, scenario):
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


class DriveScenarios(AbstractScenarios):
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
    truth_counts: ClassVar[tuple] = EMFSignals.truth_counts

    @classmethod
    def of(cls, *, t_event: float = 0.0, seed: int = 0, freq: float = 50.0, machine=None, drive=None, sensors=None):
        return cls(machine, drive, t_event=t_event, seed=seed, sensors=sensors)

    def build(self, names, points, first: int = 0):
        return drive_scenarios(
            self.machine, names, points, seed=self.seed, t_event=self.t_event, first=first, sensors=self.sensors
        )

    def system(self, design, scenario):
        return ClosedLoop(self.drive, bind_observer(design, scenario), scenario)


class RecordedSignals(AbstractScenarios):
    """Recorded signals with their truth columns, given whole (a sampler that holds them:
    :class:`jaxobs.scenarios.Recordings`).

    Attributes:
        kind: The family the recordings stand for: a grid voltage (:class:`GridSignals`: the design runs on
            the recorded voltage) or a drive's u and i (:class:`EMFSignals`, :class:`DriveScenarios`: a drive
            observer, bound to the recorded speed at t = 0, runs open loop on them).
    """

    kind: type = eqx.field(static=True)

    signal: ClassVar[str] = "recording"
    axes: ClassVar[dict] = {}
    closed_loop: ClassVar[bool] = False
    bytes_per_step: ClassVar[int] = 512
    # the one study on recordings is the FLL study's (jaxobs.study.run_study on a Recordings sampler)
    metrics: ClassVar[tuple[str, ...]] = GridSignals.metrics
    flags: ClassVar[tuple[str, ...]] = GridSignals.flags

    @property
    def binds(self) -> bool:
        """Whether the design is bound to the recording (a drive observer on u and i), not run on it as is."""
        return self.kind is not GridSignals

    def build(self, names, points, first: int = 0):
        raise ValueError("recorded signals are given whole (jaxobs.scenarios.Recordings): they are not built")

    def system(self, design, scenario):
        # a drive observer starts from the recorded speed at t = 0 (the encoder's); est_par None keeps its own
        # Rs and L (a recording gives the speed, not the machine)
        return OnSignal(design.bind(None, scenario.omega_e[..., 0]) if self.binds else design, scenario)

    def read(self, path: str, columns, truth, *, layout=None, machine=None, windows=None, **kw):
        """One recording file as scenarios.

        Args:
            path: the CSV file.
            columns: a grid voltage's column (``columns[0]``), or the voltage then the current columns, two each
                (u_α, u_β, i_α, i_β, or in ``layout``'s frames) or three each (``abc``).
            truth: the phase, frequency and amplitude columns (grid), or the encoder's angle and speed.
            layout: what a drive log's columns hold (:class:`jaxobs.signals.RecordingLayout`; default the
                sidecar ``<path>.toml``, else the observers' own form).
            machine: a :class:`~jaxobs.drive.PMSMParams` for the log's power and timing checks, or None.
            windows: ``(count, n)``: ``count`` windows of ``n`` samples spread evenly over a drive log, each a
                scenario starting at its own speed; None: the whole file.
            **kw: the time base (``time_column``, ``sample_rate``, ``ts``) and ``max_bytes``.

        Returns:
            A :class:`~jaxobs.SampledSignal` (a grid voltage), a :class:`~jaxobs.DriveRecording` (u and i), or a
            list of ``count`` of them (``windows``).

        Raises:
            ValueError: what :func:`jaxobs.signals.read_drive_log` or ``from_csv`` refuses, in one line; a
                declared layout on a log sampled at another rate than ``ts``.
        """
        if not self.binds:
            return SampledSignal.from_csv(path, columns=columns[0], truth=truth, **kw)
        ts = kw.get("ts")
        log = read_drive_log(
            path,
            voltages=columns[: len(columns) // 2],  # 2 + 2 columns, or 3 + 3 (abc)
            currents=columns[len(columns) // 2 :],
            theta_e=truth[0],
            omega_e=truth[1] if len(truth) > 1 else None,
            time_column=kw.get("time_column"),
            sample_rate=kw.get("sample_rate"),
            layout=layout,
            machine=machine,
            max_bytes=kw.get("max_bytes"),
        )
        if ts is None or abs(log.ts - ts) <= 1e-9 * ts:
            if windows is None:
                return log.recording()
            count, n = windows
            if log.n < n:
                raise ValueError(f"recording {str(path)!r}: {log.n} samples, fewer than a window's {n}")
            starts = [round(i * (log.n - n) / max(count - 1, 1)) for i in range(count)]
            return [log.recording(a, n) for a in starts]
        # another rate: resampled by the small reader (the checks above have run on the file as it is)
        if (layout is not None and layout != RecordingLayout()) or windows is not None:
            raise ValueError(
                f"recording {str(path)!r}: sampled at {1 / log.ts:.6g} Hz, not at the observer's {1 / ts:.6g} Hz: a "
                "declared layout or windows read the log at its own rate (resample it, or set ts)"
            )
        return DriveRecording.from_csv(path, columns=columns, **dict(zip(("theta_e", "omega_e"), truth)), **kw)


# a job file's ``scenarios.signal`` -> its family (the one place the name is read)
FAMILIES: dict[str, type[AbstractScenarios]] = {f.signal: f for f in (GridSignals, EMFSignals, DriveScenarios)}
