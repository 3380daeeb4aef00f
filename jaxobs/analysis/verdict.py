"""One verdict per simulated run, and the slowest (or fastest) reversal a design holds.

:func:`verdict` reads a closed-loop trajectory (the angle error θ̂e − θe, the speed ωm and its reference ωm*)
and names **one** state per run, the first that applies in this order:

============  ====================================================================================================
state         when
============  ====================================================================================================
unstable      a value is not finite (the run diverged), or the speed error's swing grows: its peak-to-peak over
              the second half of the settled window is more than :attr:`VerdictRule.growth` (1.5) times the first
              half's and above the swing tolerance
loses lock    the observer's angle left the rotor's by more than :attr:`VerdictRule.lock_deg` (90° electrical,
              :data:`jaxobs.metrics.LOCK_TOL_DRIVE_DEG`) somewhere from the event on
loses speed   the settled window's mean |ωm − ωm*| exceeds :attr:`VerdictRule.speed_tol` (20 %,
              :data:`jaxobs.metrics.SPEED_TOL`) of its mean |ωm*|, or :attr:`VerdictRule.floor_rpm` where that
              is smaller
bounded       the speed error keeps swinging: its half peak-to-peak over the second half exceeds
limit cycle   :attr:`VerdictRule.cycle_tol` (0.5 %) of the mean |ωm*| (at least :attr:`VerdictRule.cycle_floor_rpm`)
              and has not decayed below :attr:`VerdictRule.decay` (0.8) of the first half's (nor grown past
              ``growth``)
holds         none of the above
============  ====================================================================================================

Two windows, both given by the caller: the **event** window from ``t_event`` (the reference or load starts to
change) to the end, where lock is checked, since an observer that slips through zero speed and locks again
afterwards has lost lock (a reversal checked only after the ramp would call it held); and the **settled**
window from ``t_settled`` (the last change plus the speed loop's settling) to the end, split into two halves,
where the speed is judged.  Why these thresholds:

- 90° for lock: a locked drive observer stays within a few degrees (the lab IPMSM's reduced-order observer peaks
  at 1.4° under a rated load step, ``benchmarks/results/2026-12-02-peer-observer.txt``); a slip sweeps every
  angle.  It is the drive studies' own tolerance.
- 20 % for speed: :func:`jaxobs.metrics.lost_speed`'s (far above a locked drive's ripple, far below a reversal
  or a stall), with a floor of 2 r/min instead of its 20 r/min: the low-speed scenarios run at 15 r/min, where
  a 20 r/min floor would call a stalled rotor held.  2 r/min is above the ideal-sensor drives' settled ripple
  (under 0.1 r/min on the lab IPMSM) and below 20 % of any reference of 10 r/min or more.
- the swing test uses the speed error's peak-to-peak, not its peak, so a steady offset (lost speed, or a small
  one that is held) never reads as a cycle; 0.5 % of the reference flags a sustained oscillation of the
  size the envelope misread as "not stable" on a traction drive (±0.65 %) while a settled drive's ripple with
  ideal sensors is far smaller.  With noisy sensors the noise's own swing must stay below ``cycle_tol`` (raise
  it, or the verdict says "bounded limit cycle" where the noise swings).
- decay 0.8 and growth 1.5 over half the settled window: the window must span several time constants of the
  slowest mode (the speed loop's; the caller's ``t_settled`` and horizon), so a decaying transient's swing
  shrinks far below 0.8 in half of it and a mode growing at σ shows as e^{σT/2}.  A growth or decay slower than
  that over the window is not resolved: the envelope's Floquet margin is the tool for it.

``stable`` (:attr:`Verdict.stable`: holds or a bounded limit cycle) is never true where the run loses speed or
lock: the states are exclusive and those come first.

:func:`held_rate` searches the slowest ramp rate of :func:`jaxobs.drive.reversal` a design holds (or the fastest,
``find="fastest"``) by bisection over rates on a log scale to a stated relative resolution: each probe is one
batched simulation of ``probes`` rates inside the bracket (a (probes + 1)-section), the first one with the
bracket's ends.  The verdict is boolean, so a root finder (``optimistix``) does not fit: it needs a residual
whose sign changes continuously with the rate, and a held/not-held flag has no such residual; the bisection is
written out here.  It assumes one change of verdict over the range and says where the probes disagree with
that (:attr:`RateSearch.monotone`).

The envelope (:mod:`jaxobs.analysis.envelope`) judges each long run by :func:`verdict_from` (the same rule on the
quantities its running sums keep) and, on request, each design's slowest held reversal by :func:`held_rate`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer
from jax.typing import ArrayLike

from .. import SaveAll, Solution, simulate
from .. import metrics as M
from ..drive import RPM, ClosedLoop, Drive, Scenario, reversal, stack_scenarios
from ..observers import AbstractDriveObserver

__all__ = [
    "VERDICTS",
    "HOLDS",
    "LIMIT_CYCLE",
    "LOSES_SPEED",
    "LOSES_LOCK",
    "UNSTABLE",
    "VerdictRule",
    "Verdict",
    "verdict",
    "verdict_of",
    "verdict_from",
    "verdict_names",
    "RateSearch",
    "held_rate",
    "reversal_holds",
]

# The states, by code (Verdict.state); the order of the table in the module doc is the precedence.
VERDICTS = ("holds", "bounded limit cycle", "loses speed", "loses lock", "unstable")
HOLDS, LIMIT_CYCLE, LOSES_SPEED, LOSES_LOCK, UNSTABLE = range(5)


def _rule_value(name: str, x, lo: float, hi: float, lo_open: bool = True) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"VerdictRule.{name} must be a number, got {x!r}") from None
    if not (math.isfinite(v) and (v > lo if lo_open else v >= lo) and v <= hi):
        raise ValueError(
            f"VerdictRule.{name} must be a finite number in {'(' if lo_open else '['}{lo:g}, {hi:g}], got {x!r}"
        )
    return v


class VerdictRule(eqx.Module):
    """The verdict's thresholds (module doc: what each does and why its default).

    Args:
        lock_deg: Lost lock above this |θ̂e − θe| from the event on, degrees electrical (in (0, 180]).
        speed_tol: Lost speed above this mean |ωm − ωm*| over the settled window, a fraction of its mean
            |ωm*| (in (0, 10]).
        floor_rpm: The speed tolerance's floor, r/min (in [0, 1e4]).
        cycle_tol: A swing (half peak-to-peak of ωm − ωm*) above this fraction of the mean |ωm*| is a cycle
            (in (0, 1]).
        cycle_floor_rpm: The swing tolerance's floor, r/min (in [0, 1e4]).
        decay: A swing that fell below this fraction of the first half's has decayed (in (0, 1]).
        growth: A swing above this multiple of the first half's grows (in [1, 1e3]).

    Raises:
        ValueError: A value out of its range, naming the field.
    """

    lock_deg: float = eqx.field(static=True)
    speed_tol: float = eqx.field(static=True)
    floor_rpm: float = eqx.field(static=True)
    cycle_tol: float = eqx.field(static=True)
    cycle_floor_rpm: float = eqx.field(static=True)
    decay: float = eqx.field(static=True)
    growth: float = eqx.field(static=True)

    def __init__(
        self,
        lock_deg=M.LOCK_TOL_DRIVE_DEG,
        speed_tol=M.SPEED_TOL,
        floor_rpm=2.0,
        cycle_tol=0.005,
        cycle_floor_rpm=0.5,
        decay=0.8,
        growth=1.5,
    ):
        self.lock_deg = _rule_value("lock_deg", lock_deg, 0.0, 180.0)
        self.speed_tol = _rule_value("speed_tol", speed_tol, 0.0, 10.0)
        self.floor_rpm = _rule_value("floor_rpm", floor_rpm, 0.0, 1e4, lo_open=False)
        self.cycle_tol = _rule_value("cycle_tol", cycle_tol, 0.0, 1.0)
        self.cycle_floor_rpm = _rule_value("cycle_floor_rpm", cycle_floor_rpm, 0.0, 1e4, lo_open=False)
        self.decay = _rule_value("decay", decay, 0.0, 1.0)
        self.growth = _rule_value("growth", growth, 1.0, 1e3, lo_open=False)


class Verdict(NamedTuple):
    """A run's verdict and the numbers it was read from (each with the runs' leading axes).

    Attributes:
        state: The state's code, an index of :data:`VERDICTS`.
        finite: Every value of the run finite.
        peak_angle_deg: Peak |θ̂e − θe| from the event on, degrees electrical.
        speed_err: Mean |ωm − ωm*| over the settled window, rad/s.
        speed_ref: Mean |ωm*| over the settled window, rad/s.
        swing_first: Half peak-to-peak of ωm − ωm* over the settled window's first half, rad/s.
        swing_second: The same over its second half, rad/s.
    """

    state: jax.Array
    finite: jax.Array
    peak_angle_deg: jax.Array
    speed_err: jax.Array
    speed_ref: jax.Array
    swing_first: jax.Array
    swing_second: jax.Array

    @property
    def holds(self) -> jax.Array:
        """The run holds (state ``holds``)."""
        return self.state == HOLDS

    @property
    def stable(self) -> jax.Array:
        """Holds or a bounded limit cycle: never where the run loses speed or lock, or diverges."""
        return (self.state == HOLDS) | (self.state == LIMIT_CYCLE)


def _masked_max(x, mask):
    return jnp.max(jnp.where(mask, x, -jnp.inf), axis=-1)


def _swing(x, mask):
    """Half the peak-to-peak of ``x`` over ``mask`` (0 where the mask is empty)."""
    hi, lo = _masked_max(x, mask), -_masked_max(-x, mask)
    return jnp.where(jnp.any(mask, axis=-1), 0.5 * (hi - lo), 0.0)


def verdict(
    t: ArrayLike,
    angle_error: ArrayLike,
    omega_m: ArrayLike,
    omega_m_ref: ArrayLike,
    t_event: ArrayLike,
    t_settled: ArrayLike,
    rule: VerdictRule | None = None,
) -> Verdict:
    """The one state of each run (module doc: the states, their order and thresholds).

    Works under ``jit`` and ``vmap``; the time axis is the last, leading axes are runs.

    Args:
        t: The sample times, s (the last axis; broadcast against the others).
        angle_error: θ̂e − θe, rad (wrapped or not: it is wrapped here).
        omega_m: The mechanical speed ωm, rad/s.
        omega_m_ref: Its reference ωm*, rad/s.
        t_event: The start of the event window (lock checked from here), s, per run or one.
        t_settled: The start of the settled window (speed judged from here), s (≥ ``t_event``), per run or one.
        rule: The thresholds (default :class:`VerdictRule`).

    Returns:
        The :class:`Verdict`.

    Raises:
        ValueError: A concrete window (event or settled, or a half of it) that holds no sample, or
            ``t_settled`` before ``t_event``.
    """
    rule = VerdictRule() if rule is None else rule
    t = jnp.asarray(t)
    e = M.wrap(jnp.asarray(angle_error))
    w, wr = jnp.asarray(omega_m), jnp.asarray(omega_m_ref)
    te, ts_ = jnp.expand_dims(jnp.asarray(t_event), -1), jnp.expand_dims(jnp.asarray(t_settled), -1)
    t_end = t[..., -1:]
    mid = 0.5 * (ts_ + t_end)
    ev, settled = t >= te, t >= ts_
    first, second = settled & (t < mid), t >= mid
    if not isinstance(te, Tracer) and not isinstance(ts_, Tracer):
        if np.any(np.asarray(ts_) < np.asarray(te)):
            raise ValueError("verdict: t_settled must be >= t_event")
        for name, m in (("event window", ev), ("settled window's first half", first), ("second half", second)):
            if not isinstance(m, Tracer) and not bool(np.all(np.any(np.asarray(m), axis=-1))):
                raise ValueError(f"verdict: the {name} holds no sample (t_settled too late, or the run too short)")
    dw = w - wr
    finite = jnp.all(jnp.isfinite(e) & jnp.isfinite(w), axis=-1)
    peak = jnp.degrees(_masked_max(jnp.abs(e), ev))
    n = jnp.maximum(jnp.sum(settled, axis=-1), 1)
    err = jnp.sum(jnp.where(settled, jnp.abs(dw), 0.0), axis=-1) / n
    ref = jnp.sum(jnp.where(settled, jnp.abs(wr), 0.0), axis=-1) / n
    return verdict_from(finite, peak, err, ref, _swing(dw, first), _swing(dw, second), rule)


def verdict_from(
    finite: ArrayLike,
    peak_angle_deg: ArrayLike,
    speed_err: ArrayLike,
    speed_ref: ArrayLike,
    swing_first: ArrayLike,
    swing_second: ArrayLike,
    rule: VerdictRule | None = None,
) -> Verdict:
    """The one state of each run from the quantities :func:`verdict` reads off its windows: the same rule (module
    doc) for a run whose trajectory was not kept, only these (the envelope's long runs keep them as running sums,
    :mod:`jaxobs.analysis.envelope_runs`).

    Works under ``jit`` and ``vmap`` and on NumPy arrays; the arguments broadcast against each other.

    Args:
        finite: Every value of the run finite.
        peak_angle_deg: Peak |θ̂e − θe| over the event window, degrees electrical (NaN: lost).
        speed_err: Mean |ωm − ωm*| over the settled window, rad/s.
        speed_ref: Mean |ωm*| over the settled window, rad/s.
        swing_first: Half peak-to-peak of ωm − ωm* over the settled window's first half, rad/s.
        swing_second: The same over its second half, rad/s.
        rule: The thresholds (default :class:`VerdictRule`).

    Returns:
        The :class:`Verdict` (its fields the arguments, broadcast).
    """
    rule = VerdictRule() if rule is None else rule
    finite = jnp.asarray(finite, dtype=bool)
    peak, err, ref = jnp.asarray(peak_angle_deg), jnp.asarray(speed_err), jnp.asarray(speed_ref)
    s1, s2 = jnp.asarray(swing_first), jnp.asarray(swing_second)
    cycle_tol = jnp.maximum(rule.cycle_tol * ref, rule.cycle_floor_rpm * RPM)
    grows = (s2 > cycle_tol) & (s2 > rule.growth * s1)
    lost_lock = ~(peak <= rule.lock_deg)  # NaN: lost
    lost_speed = ~(err <= jnp.maximum(rule.speed_tol * ref, rule.floor_rpm * RPM))
    cycles = (s2 > cycle_tol) & (s2 >= rule.decay * s1)
    state = jnp.select(
        [~finite, lost_lock, grows, lost_speed, cycles],
        [UNSTABLE, LOSES_LOCK, UNSTABLE, LOSES_SPEED, LIMIT_CYCLE],
        HOLDS,
    )
    finite, peak, err, ref, s1, s2 = jnp.broadcast_arrays(finite, peak, err, ref, s1, s2)
    return Verdict(state, finite, peak, err, ref, s1, s2)


def verdict_of(sol: Solution, t_event: ArrayLike, t_settled: ArrayLike, rule: VerdictRule | None = None) -> Verdict:
    """The verdict of a closed-loop drive's run (:class:`jaxobs.drive.ClosedLoop` with an observer, saved with
    :class:`jaxobs.SaveAll`; batched solutions too).

    Args:
        sol: The :class:`~jaxobs.Solution`.
        t_event: The start of the event window, s.
        t_settled: The start of the settled window, s.
        rule: The thresholds (default :class:`VerdictRule`).

    Returns:
        The :class:`Verdict`.

    Raises:
        ValueError: No trajectory or no observer estimate in ``sol``; an empty window.
    """
    e = M.position_error(sol)
    out = sol.outputs
    return verdict(out.t, e, out.omega_m, out.omega_m_ref, t_event, t_settled, rule)


def verdict_names(states: ArrayLike) -> np.ndarray:
    """The states' names (:data:`VERDICTS`) for an array of codes.

    Args:
        states: Codes, as :attr:`Verdict.state`.

    Returns:
        A NumPy array of strings of the same shape.
    """
    return np.asarray(VERDICTS, dtype=object)[np.asarray(states, dtype=int)]


# ---- the slowest (or fastest) held reversal ----------------------------------------------------------------------


class RateSearch(NamedTuple):
    """The result of :func:`held_rate`.

    Attributes:
        rate: The held end of the final bracket, r/min per second (the slowest held rate to within
            ``resolution``, or the fastest with ``find="fastest"``); NaN where no probed rate holds.
        other: The bracket's other end: the nearest probed rate that does not hold (NaN where every probed
            rate holds: ``rate`` is then the range's end, a bound).
        resolution: The bracket's final relative width, rate/other − 1 (or its inverse); NaN without a bracket.
        rates: Every probed rate, r/min per second, in probe order.
        states: Their verdicts (codes of :data:`VERDICTS`).
        probes: The number of batched simulations run.
        monotone: Whether the probes agreed with one change of verdict over the range.
    """

    rate: float
    other: float
    resolution: float
    rates: np.ndarray
    states: np.ndarray
    probes: int
    monotone: bool


def held_rate(
    lo: float,
    hi: float,
    *,
    holds_at: Callable[[np.ndarray], np.ndarray] | None = None,
    resolution: float = 0.1,
    probes: int = 3,
    find: Literal["slowest", "fastest"] = "slowest",
    max_probes: int = 12,
    states_at: Callable[[np.ndarray], np.ndarray] | None = None,
) -> RateSearch:
    """The slowest (or fastest) ramp rate in [``lo``, ``hi``] at which a design holds, by bisection on a log
    scale (module doc: why by hand).

    The first probe runs ``lo``, ``hi`` and ``probes`` rates between; each later probe ``probes`` rates inside
    the bracket, log-spaced, so the bracket shrinks by a factor ``probes + 1`` (in log) per batched run, until
    its relative width is at most ``resolution``.  ``find="slowest"`` assumes slow rates fail and fast ones
    hold (a back-EMF observer lingers near zero speed on a slow ramp); ``"fastest"`` the opposite.

    Args:
        lo: The range's slow end, r/min per second (> 0).
        hi: Its fast end (> ``lo``).
        holds_at: Rates (r/min per second, 1-D) → a bool per rate (one batched simulation); or give
            ``states_at`` instead.
        resolution: The bracket's relative width at which to stop (in (0, 10]).
        probes: Rates per probe inside the bracket (an integer in [1, 64]).
        find: ``"slowest"`` or ``"fastest"``.
        max_probes: At most this many batched simulations (an integer in [1, 100]).
        states_at: Rates → verdict codes (:attr:`Verdict.state`); holds is the code ``HOLDS``.

    Returns:
        The :class:`RateSearch`.

    Raises:
        ValueError: A value out of its range, naming it.
    """
    if find not in ("slowest", "fastest"):
        raise ValueError(f"held_rate.find must be 'slowest' or 'fastest', got {find!r}")
    lo_, hi_ = float(lo), float(hi)
    if not (math.isfinite(lo_) and math.isfinite(hi_) and 0.0 < lo_ < hi_):
        raise ValueError(f"held_rate.lo and hi must be finite with 0 < lo < hi (r/min per s), got {lo!r}, {hi!r}")
    if not (math.isfinite(float(resolution)) and 0.0 < float(resolution) <= 10.0):
        raise ValueError(f"held_rate.resolution must be in (0, 10], got {resolution!r}")
    for name, v, top in (("probes", probes, 64), ("max_probes", max_probes, 100)):
        if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= top:
            raise ValueError(f"held_rate.{name} must be an integer in [1, {top}], got {v!r}")
    if (holds_at is None) == (states_at is None):
        raise ValueError("held_rate: give one of holds_at and states_at")

    def run(rates):
        if states_at is not None:
            s = np.asarray(states_at(rates), dtype=int).reshape(rates.shape)
            return s == HOLDS, s
        assert holds_at is not None  # one of the two is given (checked above)
        h = np.asarray(holds_at(rates), dtype=bool).reshape(rates.shape)
        return h, np.where(h, HOLDS, LOSES_LOCK)

    # work in x = ±log(rate), so the held side is always the high-x side
    sign = 1.0 if find == "slowest" else -1.0
    to_x = lambda r: sign * np.log(r)  # noqa: E731
    to_r = lambda x: np.exp(sign * np.asarray(x))  # noqa: E731
    x_a, x_b = sorted((to_x(lo_), to_x(hi_)))
    seen_r, seen_s, monotone = [], [], True
    xs = np.linspace(x_a, x_b, probes + 2)
    n_probe = 0
    held_x, fail_x = np.nan, np.nan
    while n_probe < max_probes:
        rates = to_r(xs)
        ok, st = run(rates)
        n_probe += 1
        seen_r += list(rates)
        seen_s += list(st)
        xs_all = np.asarray([to_x(r) for r in seen_r])
        ok_all = np.asarray(seen_s) == HOLDS
        order = np.argsort(xs_all)
        xo, oko = xs_all[order], ok_all[order]
        # the held side: the lowest x from which every probed x above holds
        tail = np.flip(np.logical_and.accumulate(np.flip(oko)))
        if not tail.any():
            held_x, fail_x = np.nan, np.nan
            monotone = monotone and not oko.any()
            break
        i = int(np.argmax(tail))
        held_x = xo[i]
        monotone = monotone and not oko[:i].any()
        if i == 0:
            fail_x = np.nan  # every probed rate holds: the range's end is a bound
            break
        fail_x = xo[i - 1]
        if held_x - fail_x <= math.log1p(float(resolution)):
            break
        xs = np.linspace(fail_x, held_x, probes + 2)[1:-1]
    width = float(np.expm1(held_x - fail_x)) if np.isfinite(held_x) and np.isfinite(fail_x) else float("nan")
    return RateSearch(
        rate=float(to_r(held_x)) if np.isfinite(held_x) else float("nan"),
        other=float(to_r(fail_x)) if np.isfinite(fail_x) else float("nan"),
        resolution=width,
        rates=np.asarray(seen_r),
        states=np.asarray(seen_s, dtype=int),
        probes=n_probe,
        monotone=bool(monotone),
    )


def reversal_holds(
    drive: Drive,
    observer: AbstractDriveObserver,
    base: Scenario,
    speed_rpm: float,
    *,
    load_nm: float = 0.0,
    t_start: float = 0.2,
    settle: float = 1.0,
    horizon: float | None = None,
    rule: VerdictRule | None = None,
) -> Callable[[np.ndarray], np.ndarray]:
    """The states of a design's reversals at given rates, each call one batched simulation: the ``states_at`` of
    :func:`held_rate`.

    Each rate's run is :func:`jaxobs.drive.reversal` on ``base`` (±``speed_rpm``, ``load_nm``), the observer
    bound to it; lock is judged from ``t_start``, the speed from the end of each run's ramp plus half of
    ``settle`` to the horizon.  One program is compiled per batch size (and horizon): give ``horizon`` (at least
    the slowest rate's ramp end plus ``settle``) to keep one across the calls of a search.

    Args:
        drive: The sensorless :class:`~jaxobs.drive.Drive`.
        observer: The drive observer (unbound: it is bound to each scenario's assumed machine and start).
        base: The :class:`~jaxobs.drive.Scenario` (machine, assumed machine, sensors) the reversals modify.
        speed_rpm: The reversal's speed, r/min (±).
        load_nm: The load, N·m.
        t_start: The ramp's start, s.
        settle: The time after a ramp's end that its run lasts at least, s (> 0; several speed-loop time
            constants).
        horizon: The runs' length, s (None: the slowest rate's ramp end plus ``settle``, per call).
        rule: The verdict's thresholds.

    Returns:
        A function: rates (r/min per second) → verdict codes.

    Raises:
        ValueError: ``settle`` not a finite number > 0, or (by the function) a rate whose ramp and ``settle`` do
            not fit ``horizon`` (the builders check the rest).
    """
    if not (math.isfinite(float(settle)) and float(settle) > 0.0):
        raise ValueError(f"reversal_holds.settle must be a finite number of seconds > 0, got {settle!r}")

    def states_at(rates):
        rates = np.asarray(rates, dtype=float).reshape(-1)
        scs = stack_scenarios([reversal(base, speed_rpm, r, load_nm=load_nm, t_start=t_start) for r in rates])
        ramp_end = t_start + 2.0 * float(speed_rpm) / rates
        t1 = float(ramp_end.max()) + float(settle) if horizon is None else float(horizon)
        if t1 < float(ramp_end.max()) + float(settle) - 1e-9:
            raise ValueError(
                f"reversal_holds.horizon ({t1:g} s) is shorter than the slowest ramp's end plus settle "
                f"({float(ramp_end.max()) + float(settle):g} s)"
            )
        t_set = jnp.asarray(ramp_end + 0.5 * float(settle))
        return np.asarray(_reversal_states(drive, observer, scs, jnp.asarray(float(t_start)), t_set, rule, t1))

    return states_at


@functools.partial(eqx.filter_jit)
def _reversal_states(drive, observer, scs, t_start, t_set, rule, t1):
    """The verdicts of a batch of reversals (:func:`reversal_holds`): one program per drive and observer class,
    batch size and horizon ``t1`` (the gains, the drive's values and the scenarios are traced)."""

    def one(sc):
        return ClosedLoop(drive, observer.bind(sc.est_par, sc.est_par.p * sc.omega_m0), sc)

    sol = jax.vmap(lambda sc: simulate(one(sc), t1, save=SaveAll()))(scs)
    return verdict_of(sol, t_start, t_set, rule).state
