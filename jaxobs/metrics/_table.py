"""The one metric table: every quantity a study, a tuning job or an envelope reports, one entry each.

Each entry is a :class:`Metric`: its name, its CF units (SI: ``rad``, ``rad s-1``, ``s``, ``Hz``, ``1``), its long
name, and its exact and smooth forms of one run.  Three kinds (:attr:`Metric.kind`):

- ``"run"``: a scalar of one run (``exact(sol, scenario, ctx)``; ``smooth`` where a gradient needs another form);
- ``"flag"``: a boolean of one run (lost lock, lost speed, settled, diverged), stored as a 0/1 variable; a flag says
  how a diverged run counts (:attr:`Metric.diverged`) and what its per-design count is called (:attr:`Metric.count`);
- ``"system"``: not a function of one run but of the closed loop itself (the stability margin: the objective computes
  it from the loop's Lyapunov exponents, :mod:`jaxobs.analysis.stability`).

Display units (degrees, r/min, percent) are a presentation transform (:meth:`Metric.shown`,
:attr:`Metric.display`), applied where a table or a figure is shown; the values stored and compared are SI.

Old names (the drive study's ``pos_err_rms_deg``, the FLL study's ``rms_phase``, ...) are read on input through
:func:`canonical` (one line of :class:`DeprecationWarning`, and the factor that converts an old value or weight) and
never written: :data:`ALIASES` is the one table of them.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal, NamedTuple, TypeVar

import jax
import jax.numpy as jnp
import numpy as np

from ..drive.scenario import Scenario
from ..runtime.simulation import Solution
from ..signals import AbstractSignal
from . import _core as M
from . import _lock as L
from ._core import _DRIVE_OUTPUTS

if TYPE_CHECKING:
    import xarray as xr

__all__ = [
    "ALIASES",
    "DISPLAY",
    "DIVERGED",
    "METRICS",
    "Alias",
    "Metric",
    "MetricContext",
    "MetricNameWarning",
    "canonical",
    "scored_position_error",
]

_RPM = 30.0 / math.pi  # rad/s -> r/min (mechanical)

# what a display transform scales (Metric.shown): a number, an array, an xarray variable
_Values = TypeVar("_Values", float, np.ndarray, jax.Array, "xr.DataArray")

# a display transform: (SI units, display units) -> factor (display = factor × SI)
DISPLAY: dict[tuple[str, str], float] = {
    ("rad", "degree"): 180.0 / math.pi,
    ("rad s-1", "min-1"): _RPM,
    ("1", "percent"): 100.0,
}


@dataclass(frozen=True)
class MetricContext:
    """What the metrics read beside the run.

    Attributes:
        t_event: The event's time, s.
        steady_from: The steady window's start, s.
        band_hz: ``settling_freq``'s band, Hz.
        temperature: The smooth forms' temperature (s, or the metric's units; ``peak_speed_deviation`` reads it
            in r/min, as ``band_rpm``).
        band_deg: ``settling_position``'s band, electrical degrees, around the error's own final value.
        band_rpm: ``settling_speed``'s band, r/min, around the reference.
        n_period: The one-period average's length, samples (a design's: the FLL study's ``static``).
    """

    t_event: float = 0.0
    steady_from: float = 0.0
    band_hz: float = 0.05
    temperature: float = 1e-3
    band_deg: float = 2.0
    band_rpm: float = 5.0
    n_period: int = 1


@dataclass(frozen=True)
class Metric:
    """One quantity of the metric table (module doc).

    Attributes:
        name: The metric's name.
        units: Its CF units (SI).
        long_name: What it is.
        exact: ``exact(sol, scenario, ctx)``: what a study or a report gives (a flag: a bool; None for the
            ``diverged`` flag, which the study forms from the run and the other metrics).
        smooth: ``smooth(sol, scenario, ctx)``: what a gradient is taken of (the exact one where that has a
            useful gradient).
        kind: ``"run"``, ``"flag"`` or ``"system"`` (module doc).
        closed_loop: It needs the closed-loop drive (a speed, a reference), not an observer on a signal.
        needs_truth: It needs an observer on a signal that reports its truth (a recording with its encoder).
        display: The units a table or a figure shows it in (:data:`DISPLAY`); None: its own.
        diverged: A flag: a diverged run counts as flagged (True), or as not (False: kept only where finite).
        count: A flag: the ``long_name`` of ``<name>_count``, the flagged scenarios per design (None: no count).
        dtype: A flag: its stored type.
    """

    name: str
    units: str
    long_name: str
    exact: Callable | None = None
    smooth: Callable | None = None
    kind: Literal["run", "flag", "system"] = "run"
    closed_loop: bool = False
    needs_truth: bool = False
    display: str | None = None
    diverged: bool = True
    count: str | None = None
    dtype: Any = np.int8

    def __post_init__(self):
        if self.kind not in ("run", "flag", "system"):
            raise ValueError(f"Metric.kind must be 'run', 'flag' or 'system', got {self.kind!r}")
        if self.display is not None and (self.units, self.display) not in DISPLAY:
            raise ValueError(f"Metric {self.name}: no display transform from {self.units!r} to {self.display!r}")

    def __call__(self, sol, scenario, ctx):
        """The form a gradient is taken of: ``smooth``, or ``exact`` where the metric has no smooth form.

        Raises:
            ValueError: the metric has neither form (it is not a function of one run).
        """
        form = self.smooth if self.smooth is not None else self.exact
        if form is None:
            raise ValueError(f"metric {self.name} is not a function of one run (it has no exact or smooth form)")
        return form(sol, scenario, ctx)

    @property
    def display_units(self) -> str:
        """The units it is shown in: :attr:`display`, or its own."""
        return self.units if self.display is None else self.display

    def shown(self, values: _Values) -> _Values:
        """``values`` (in :attr:`units`) in :attr:`display_units`: the presentation transform.

        Args:
            values: A number, an array or an ``xarray.DataArray`` in the metric's SI units.

        Returns:
            The values times the display factor (unchanged where the metric has no display units).
        """
        return values if self.display is None else values * DISPLAY[(self.units, self.display)]


# --------------------------------------------------------------------------
# the forms' pieces
# --------------------------------------------------------------------------


def _steady(sol, ctx):
    return sol.t >= ctx.steady_from


def _fll(sol):
    """An FLL run's errors: f̂ (Hz), the true f (Hz), f̂ − f (Hz), the wrapped phase error (rad)."""
    out = sol.outputs
    f_hat = out.obs.omega / (2 * math.pi)
    f_true = out.truth.omega / (2 * math.pi)
    return f_hat, f_true, f_hat - f_true, M.wrap(out.obs.theta - out.truth.theta)


def _freq_err_hz(sol):
    return (sol.outputs.obs.omega - sol.outputs.truth.omega) / (2 * math.pi)


def _phase_err(sol):
    return M.wrap(sol.outputs.obs.theta - sol.outputs.truth.theta)


def _settle_avg(sol, ctx):
    # settle on the one-period average of f̂: harmonics and dc leave a ripple that is not a transient
    f_hat, f_true, _, _ = _fll(sol)
    return M.moving_average(f_hat, ctx.n_period), f_true[-1]


def _speed_hat(sol, sc):
    """A drive observer's mechanical speed estimate ω̂e/p, rad/s; p the drive scenario's own (``sc.par.p``: the
    one source of the pole pairs)."""
    return sol.outputs.obs.omega / sc.par.p


def scored_position_error(sol: Solution, sig: AbstractSignal | Scenario, ctx: MetricContext) -> jax.Array:
    """The position error (rad, :func:`jaxobs.metrics.position_error`) as the metrics score it.  A drive
    started from standstill runs on the I-f angle until its hand-over (the FOC's ``mode`` 0 → 1); the
    observer is not in the loop then and may sit ~90° off while it converges at low speed (most of the
    ``iae_position`` of such a start, docs/performance.md), which is the start-up's doing, not the observer's.  So its
    error counts from the hand-over on (a steady start is in mode 1 from t = 0: unchanged).  Inside the steady
    window it always counts: a drive that has not handed over by then is scored (and flagged lost_sync) on its
    real error, never rewarded with a zero.

    Args:
        sol: The run (its outputs hold an observer's estimate).
        sig: Its scenario (the signal, or the drive scenario).
        ctx: The :class:`MetricContext`.

    Returns:
        The position error along the run, rad (zero before a standstill start's hand-over).
    """
    err = L.position_error(sol, sig)
    if not isinstance(sol.outputs, _DRIVE_OUTPUTS):  # an observer on a signal: no start-up
        return err
    return jnp.where((sol.outputs.mode == 1) | _steady(sol, ctx), err, 0.0)


def _lost_sync(sol, sc, ctx):
    # lost lock (jaxobs.metrics.lost_lock, 90° electrical) over the whole scored horizon, not the steady window:
    # a tuning job has events (speed and load steps), and a pole slip during one is a loss of synchronism even if
    # the observer locks again afterwards.  The scored error is already wrapped (wrap of it against 0 is itself)
    err = scored_position_error(sol, sc, ctx)
    every = jnp.ones(err.shape, dtype=bool)
    return L.lost_lock(err, jnp.zeros_like(err), every, math.radians(L.LOCK_TOL_DRIVE_DEG))


def _entries(*ms: Metric) -> dict[str, Metric]:
    out: dict[str, Metric] = {}
    for m in ms:
        if m.name in out:
            raise ValueError(f"metric {m.name} is declared twice")
        out[m.name] = m
    return out


_LOCK = (
    f"lost lock: diverged, or in the steady window a phase error > {L.LOCK_TOL_DEG:g} deg or a mean frequency error "
    f"> {100 * L.LOCK_FREQ_TOL:g} % (an estimate on a signal), a position error > {L.LOCK_TOL_DRIVE_DEG:g} deg "
    "electrical (a drive observer) (1: lost)"
)

METRICS: dict[str, Metric] = _entries(
    # the FLL family on grid signals (and recordings)
    Metric(
        "settling_freq",
        "s",
        "settling time of the one-period average of the frequency estimate after the event",
        exact=lambda sol, sc, ctx: M.settling_time(sol.t, *_settle_avg(sol, ctx), ctx.band_hz, ctx.t_event),
        # tuning: the frequency estimate itself, a smooth settling time
        smooth=lambda sol, sc, ctx: M.smooth_settling_time(
            sol.t,
            sol.outputs.obs.omega / (2 * math.pi),
            sol.outputs.truth.omega[-1] / (2 * math.pi),
            ctx.band_hz,
            ctx.t_event,
            temperature=ctx.temperature,
        ),
    ),
    Metric(
        "ripple_freq",
        "Hz",
        "steady peak-to-peak frequency error",
        exact=lambda sol, sc, ctx: M.peak_to_peak(_fll(sol)[2], _steady(sol, ctx)),
        smooth=lambda sol, sc, ctx: M.smooth_peak_to_peak(_freq_err_hz(sol), _steady(sol, ctx), 1e-3),
    ),
    Metric(
        "rms_phase_steady",
        "rad",
        "steady rms phase error",
        exact=lambda sol, sc, ctx: M.rms(_fll(sol)[3], _steady(sol, ctx)),
        display="degree",
    ),
    Metric(
        "itae_freq",
        "Hz s2",
        "ITAE of the frequency error after the event",
        exact=lambda sol, sc, ctx: M.itae(sol.t, _fll(sol)[2], ctx.t_event),
        # tuning: the same ITAE, the error formed in rad/s and then scaled to Hz (its own rounding)
        smooth=lambda sol, sc, ctx: M.itae(sol.t, _freq_err_hz(sol), ctx.t_event),
    ),
    Metric(
        "iae_phase",
        "rad s",
        "IAE of the phase error after the event",
        exact=lambda sol, sc, ctx: M.iae(sol.t, _fll(sol)[3], ctx.t_event),
    ),
    Metric(
        "iae_freq",
        "Hz s",
        "IAE of the frequency error after the event",
        exact=lambda sol, sc, ctx: M.iae(sol.t, _freq_err_hz(sol), ctx.t_event),
    ),
    Metric(
        "itae_phase",
        "rad s2",
        "ITAE of the phase error after the event",
        exact=lambda sol, sc, ctx: M.itae(sol.t, _phase_err(sol), ctx.t_event),
    ),
    Metric(
        "rms_freq_steady",
        "Hz",
        "steady rms frequency error",
        exact=lambda sol, sc, ctx: M.rms(_freq_err_hz(sol), _steady(sol, ctx)),
    ),
    # flux observers on EMF signals, and drive observers (electrical angles)
    Metric(
        "iae_position",
        "rad s",
        "IAE of the position error after the event (from the I-f hand-over on)",
        exact=lambda sol, sc, ctx: M.iae(sol.t, scored_position_error(sol, sc, ctx), ctx.t_event),
    ),
    Metric(
        "rms_position_steady",
        "rad",
        "steady rms position error (electrical)",
        exact=lambda sol, sc, ctx: M.rms(L.position_error(sol, sc), _steady(sol, ctx)),
        display="degree",
    ),
    Metric(
        "peak_position_steady",
        "rad",
        "steady peak |position error| (electrical)",
        exact=lambda sol, sc, ctx: jnp.max(jnp.where(_steady(sol, ctx), jnp.abs(L.position_error(sol, sc)), 0.0)),
        display="degree",
    ),
    Metric(
        "ripple_position",
        "rad",
        "steady peak-to-peak position error (electrical)",
        smooth=lambda sol, sc, ctx: M.smooth_peak_to_peak(L.position_error(sol, sc), _steady(sol, ctx), 1e-4),
        display="degree",
    ),
    Metric(
        "bias_position",
        "rad",
        "|mean position error| in the steady window (electrical): the observer's steady lag",
        exact=lambda sol, sc, ctx: jnp.abs(M.steady_mean(L.position_error(sol, sc), _steady(sol, ctx))),
        display="degree",
    ),
    # drive observers in the closed loop (the scenario is a drive Scenario): settling after a load or speed step at
    # t_event, and the noise the estimates carry.  settling_position settles to a band around the error's own final
    # value (its mean over the steady window), so a steady lag settles; the lag is bias_position
    Metric(
        "settling_position",
        "s",
        "settling time of the position error to its own steady value after the event",
        smooth=lambda sol, sc, ctx: M.smooth_settling_to_steady(
            sol.t,
            scored_position_error(sol, sc, ctx),
            math.radians(ctx.band_deg),
            _steady(sol, ctx),
            ctx.t_event,
            temperature=ctx.temperature,
        ),
        closed_loop=True,
    ),
    # the true speed against its reference: after a speed step its settling, after a load step its recovery time;
    # and the peak deviation after it
    Metric(
        "settling_speed",
        "s",
        "settling time of the speed to its reference after the event",
        smooth=lambda sol, sc, ctx: M.smooth_settling_to_reference(
            sol.t,
            sol.outputs.omega_m * 30 / math.pi,  # r/min, as band_rpm
            sol.outputs.omega_m_ref * 30 / math.pi,
            ctx.band_rpm,
            ctx.t_event,
            temperature=ctx.temperature,
        ),
        closed_loop=True,
    ),
    Metric(
        "peak_speed_deviation",
        "rad s-1",
        "peak |speed - reference| after the event (mechanical; a load step's dip)",
        exact=lambda sol, sc, ctx: M.peak_deviation(sol.t, sol.outputs.omega_m, sol.outputs.omega_m_ref, ctx.t_event),
        # the soft maximum's temperature is read in r/min (as band_rpm): π/30 of it in rad/s.  A soft maximum scales
        # with its input and temperature together, so this is the r/min form's value × π/30
        smooth=lambda sol, sc, ctx: M.smooth_peak_deviation(
            sol.t, sol.outputs.omega_m, sol.outputs.omega_m_ref, ctx.t_event, temperature=ctx.temperature / _RPM
        ),
        closed_loop=True,
        display="min-1",
    ),
    Metric(
        "rms_speed_estimate_steady",
        "rad s-1",
        "steady rms speed-estimate error (mechanical: the estimate over the pole pairs against the true speed)",
        exact=lambda sol, sc, ctx: M.rms(_speed_hat(sol, sc) - sol.outputs.omega_m, _steady(sol, ctx)),
        closed_loop=True,
        display="min-1",
    ),
    Metric(
        "speed_noise",
        "rad s-1",
        "speed-estimate noise (mechanical): rms sample-to-sample change / sqrt(2) in the steady window",
        # the standard deviation of white noise on the estimate, blind to its slow variations
        exact=lambda sol, sc, ctx: M.rms(jnp.diff(_speed_hat(sol, sc)) / math.sqrt(2.0), _steady(sol, ctx)[1:]),
        closed_loop=True,
        display="min-1",
    ),
    # the speed estimate of an observer run open loop on a signal that carries its truth (a drive log with its
    # encoder, jaxobs.DriveRecording): electrical rad/s, as the recording gives it (its pole pairs are not known)
    Metric(
        "rms_speed_error_steady",
        "rad s-1",
        "steady rms electrical speed-estimate error against the recorded speed",
        exact=lambda sol, sc, ctx: M.rms(sol.outputs.obs.omega - sol.outputs.truth.omega, _steady(sol, ctx)),
        needs_truth=True,
    ),
    Metric(
        "peak_speed_error",
        "rad s-1",
        "peak |electrical speed-estimate error| after the event, against the recorded speed",
        exact=lambda sol, sc, ctx: M.peak_deviation(sol.t, sol.outputs.obs.omega, sol.outputs.truth.omega, ctx.t_event),
        # a soft maximum within 0.1·(1 + log n) rad/s of the peak (n: the samples after the event)
        smooth=lambda sol, sc, ctx: M.smooth_peak_deviation(
            sol.t, sol.outputs.obs.omega, sol.outputs.truth.omega, ctx.t_event, temperature=0.1
        ),
        needs_truth=True,
    ),
    # a system metric: jaxobs.analysis.stability.lyapunov's largest non-neutral exponent (1/s) of the closed loop at
    # the scenario, which the objective computes
    Metric(
        "stability_margin",
        "s-1",
        "largest non-neutral Lyapunov exponent of the closed loop (minus the stability margin)",
        kind="system",
        closed_loop=True,
    ),
    # flags: booleans of one run
    Metric(
        "diverged",
        "1",
        "simulation diverged or a metric is not finite (1: its metrics are NaN)",
        kind="flag",
    ),
    Metric(
        "settled",
        "1",
        "settled by the horizon (False: settling_freq is censored at horizon - t_event)",
        exact=lambda sol, sc, ctx: M.settled(sol.t, *_settle_avg(sol, ctx), ctx.band_hz, ctx.t_event),
        kind="flag",
        diverged=False,
        dtype=bool,
    ),
    Metric(
        "lost_lock",
        "1",
        _LOCK,
        # the one definition (jaxobs.metrics.lost_lock_of: 45° / 10 % on signals, 90° on the drive), over the
        # steady window
        exact=lambda sol, sc, ctx: L.lost_lock_of(sol, ctx.steady_from, signal=sc),
        kind="flag",
        count="scenarios that lost lock (diverged ones included)",
    ),
    Metric(
        "lost_speed",
        "1",
        f"lost speed: diverged, or the steady window's mean |speed - reference| > {100 * L.SPEED_TOL:g} % of the "
        f"mean |reference| (at least {L.SPEED_FLOOR_RPM:g} r/min) (1: lost)",
        exact=lambda sol, sc, ctx: L.lost_speed(sol.outputs.omega_m, sol.outputs.omega_m_ref, _steady(sol, ctx)),
        kind="flag",
        closed_loop=True,
        count="scenarios that missed their speed reference (diverged ones included)",
    ),
    Metric(
        "lost_sync",
        "1",
        f"lost synchronism: diverged, or |position error| > {L.LOCK_TOL_DRIVE_DEG:g} deg anywhere in the scored "
        "horizon (1: lost)",
        exact=_lost_sync,
        kind="flag",
        closed_loop=True,
    ),
)

DIVERGED = METRICS["diverged"]


class MetricNameWarning(DeprecationWarning):
    """An old metric name read on input (:func:`canonical`): one line; the command line prints it as its own
    warning."""


class Alias(NamedTuple):
    """An old metric name read on input: the name it is now and ``scale``, the new value per old one (a weight
    per old unit is ``weight / scale`` per new unit)."""

    new: str
    scale: float


# old name -> its entry now (module doc): read on input with a deprecation note, never written
ALIASES: dict[str, Alias] = {
    "rms_phase": Alias("rms_phase_steady", 1.0),
    "pos_err_rms_deg": Alias("rms_position_steady", math.pi / 180.0),
    "pos_err_max_deg": Alias("peak_position_steady", math.pi / 180.0),
    "pos_bias_deg": Alias("bias_position", math.pi / 180.0),
    "speed_err_rms_rpm": Alias("rms_speed_estimate_steady", 1.0 / _RPM),
    "rms_speed_steady": Alias("rms_speed_estimate_steady", 1.0 / _RPM),
    "speed_noise_rpm": Alias("speed_noise", 1.0 / _RPM),
    "speed_dev_max_rpm": Alias("peak_speed_deviation", 1.0 / _RPM),
    "peak_speed_dev": Alias("peak_speed_deviation", 1.0 / _RPM),
}


def canonical(name: str, where: str = "metric") -> tuple[str, float]:
    """The metric table's name for ``name`` read on input, and the factor from its old units to the table's.

    An old name (:data:`ALIASES`) gives one line of :class:`MetricNameWarning` (a :class:`DeprecationWarning`) naming
    ``where``; any other name is
    returned as it is with factor 1 (the caller refuses an unknown one, with its own allowed list).

    Args:
        name: A metric name as an input file or a caller gave it.
        where: What the warning names (the field, e.g. ``objective.terms[0].metric``).

    Returns:
        ``(name, scale)``: the new value is ``scale`` × the old one.
    """
    alias = ALIASES.get(name)
    if alias is None:
        return name, 1.0
    conv = "" if alias.scale == 1.0 else f", its values × {alias.scale:.6g} (SI units)"
    warnings.warn(f"{where}: {name!r} is an old metric name, read as {alias.new!r}{conv}", MetricNameWarning, 2)
    return alias.new, alias.scale
