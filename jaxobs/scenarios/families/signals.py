"""The signal families: single-phase grid voltages (:class:`GridSignals`, the FLL family) and two-axis back EMFs
(:class:`EMFSignals`); the design runs on the signal, open loop."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any, ClassVar, Self

import equinox as eqx
import numpy as np
from jaxtyping import PyTree

from ...core.system import AbstractSystem
from ...core.validate import check_seconds
from ...io.provenance import provenance
from ...metrics import METRICS, MetricContext
from ...observers import AbstractObserver
from ...runtime.simulation import OnSignal
from .. import (
    EMF_SIGNAL_AXES,
    GRID_SIGNAL_AXES,
    LHS,
    AbstractSampler,
    Grid,
    Random,
    Recordings,
    Sobol,
    emf_signals,
    grid_signals,
)
from ._base import FLL_FLAGS, FLL_METRICS, AbstractFamily, DriveSetting, StudyPlan, _seed, _t_event

__all__ = ["EMFSignals", "GridSignals", "MAX_FREQ_STEP_FRACTION"]

# The largest frequency step, as a fraction of the nominal frequency: a "50 Hz" grid at 25 Hz or 75 Hz is
# another grid (tune for that nominal), and an FLL's normalized gains are set at its ω_n.  Grid codes ask
# far less (EN 50160: ±1 %; ride-through 47–52 Hz); a study may still sweep well beyond them.
MAX_FREQ_STEP_FRACTION = 0.5


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
    metrics: ClassVar[tuple[str, ...]] = FLL_METRICS
    flags: ClassVar[tuple[str, ...]] = FLL_FLAGS
    # a recording of it: the voltage column; the truth columns (phase rad, ω rad/s, amplitude), how many
    recording_columns: ClassVar[tuple] = (("v",), ("theta", "omega", "amplitude"), (3,))
    study_horizon: ClassVar[float] = 0.4
    study_chunk: ClassVar[int] = 2048

    def __check_init__(self):
        check_seconds("t_event", self.t_event)
        if not (math.isfinite(self.freq) and self.freq > 0):
            raise ValueError(f"freq must be a finite frequency > 0 Hz, got {self.freq!r}")

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
        """The FLL study: the settling time (on the one-period average of f̂, within ``band_hz`` of the final
        frequency), the steady ripple and phase error, ITAE and IAE; a diverged scenario's metrics masked; the
        steady window from three quarters of the way from the event by default.  On a
        :class:`~jaxobs.scenarios.Recordings` sampler the recordings' family builds the runs, and a design settles
        on one period of its own nominal frequency.

        Args:
            designs: name -> FLL.
            sampler: The scenarios' sampler.
            horizon: The runs' length, s (> ``t_event``).
            steady_from: The steady window's start, s; None: ``t_event + 0.75 (horizon − t_event)``.
            band_hz: The settling band, Hz; None: 0.05.

        Returns:
            The :class:`~jaxobs.scenarios.families.StudyPlan`.

        Raises:
            ValueError: ``horizon`` not above ``t_event``, or an axis value the signals refuse (the sampler's
                least and greatest values are built here, before anything runs).
        """
        if not horizon > self.t_event >= 0:
            raise ValueError(f"horizon must exceed t_event >= 0, got t_event={self.t_event}, horizon={horizon}")
        t_event, freq = self.t_event, self.freq
        steady_from = t_event + 0.75 * (horizon - t_event) if steady_from is None else steady_from
        band_hz = 0.05 if band_hz is None else band_hz
        recordings = isinstance(sampler, Recordings)
        fam = self.recorded() if recordings else self

        def n_period(obs: Any) -> int:
            # settle on the one-period average of f̂: one period of the grid's frequency (a recording's: the
            # design's nominal one), in samples
            f = float(obs.omega_n) / (2 * math.pi) if recordings else freq
            return max(1, int(round(1.0 / (f * obs.ts))))

        if isinstance(sampler, (Grid, Random, Sobol, LHS)):
            # the signals are built a chunk at a time (jaxobs.runtime.runner): a bad axis value is refused here,
            # before anything runs, by building the two scenarios of every axis's least and greatest values (each of
            # grid_signals's checks is a bound on one axis, so these two pass only if every point inside does)
            ends = [tuple(float(f(sampler.axes[k])) for k in sampler.names) for f in (np.min, np.max)]
            fam.build(sampler.names, ends)
        what = "recordings on which the design lost lock" if recordings else "scenarios that lost lock"
        flags = tuple(
            replace(METRICS[k], count=f"{what} (diverged ones included)") if k == "lost_lock" else METRICS[k]
            for k in self.flags
        )
        seed = sampler.seed if isinstance(sampler, (Random, Sobol, LHS)) else self.seed
        digests = {"recordings": " ".join(sampler.sha256)} if isinstance(sampler, Recordings) else None
        attrs = dict(
            t_event=t_event,
            horizon=horizon,
            steady_from=steady_from,
            band_hz=band_hz,
            sampling=sampler.sampling,
            **({} if recordings else {"seed": seed}),
            **provenance("jaxobs.studies.study.run_study", digests=digests),
        )
        ctx = MetricContext(t_event=t_event, steady_from=steady_from, band_hz=band_hz)
        return StudyPlan(fam, self.metrics, flags, ctx, "diverged", (), n_period, attrs, "study")

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
