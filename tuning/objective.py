"""Objectives: a scenario batch × simulation × metric × aggregation over the batch.

Per scenario the value is a weighted sum of metrics of one simulation; over the
batch the values are combined by an aggregation object (:mod:`jaxobs_tuning.aggregations`:
the mean, a smooth worst case (log-sum-exp with a temperature) or the CVaR, the
mean of the worst (1 − α) fraction).

Divergence.  A scenario whose simulation is not finite, or whose value or
gradient is not finite, is given a large finite ``penalty`` and a zero gradient
(the penalty is a constant).  The objective is then never NaN and one bad
scenario cannot poison the gradient of the others.  This is why the gradient
is assembled per scenario (``vmap`` of ``value_and_grad``) and exposed through
a ``jax.custom_jvp``: optax (reverse mode) and optimistix (forward or reverse)
both see the sanitized derivative.

Gradients.  A scenario's gradient is taken in forward mode when the job has at most :data:`FORWARD_MAX`
gains (every preset: 1–3): one tangent per gain pushed through the simulation beside its one primal run,
nothing stored per step; reverse mode through a whole trajectory stores the carry of every step and runs it
again backwards, the slower of the two on these jobs (docs/performance.md).  The two agree to rounding
(tests/test_tuning.py).  With more gains, or with the stability-margin term (its Lyapunov exponents come
from the loop's own tangents, a reverse-mode program), reverse mode.  An observer on a signal is simulated
by the loop made fast (``SaveAll(fast=True)``: its inputs a block at a time, the same outputs as the plain
scan to rounding; faster to evaluate, docs/performance.md), for the solver only: it compiles longer, which
the scoring and the report's figures (run once per design) would pay without gaining; they keep the plain
scan (the same numbers to rounding).  The closed-loop drive keeps the plain scan: it has no block of inputs
to gain, and its unrolled step compiles longer (docs/performance.md).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from jaxobs import OnSignal, SaveAll, simulate
from jaxobs import metrics as M
from jaxobs.analysis.stability import lyapunov
from jaxobs.metrics import Metric, MetricContext
from jaxobs.runtime.runner import run_scenarios
from jaxobs.runtime.sharding import batch_mesh
from jaxobs.scenarios import Given
from jaxobs.scenarios.families import AbstractFamily

from .aggregations import AbstractAggregation, Mean
from .base import AbstractObjective
from .params import Parametrization

if TYPE_CHECKING:
    from jaxobs.drive.loop import ClosedLoop

__all__ = [
    "TERM_METRICS",
    "DRIVE_METRICS",
    "LOST_LOCK",
    "LOST_SYNC_DEG",
    "Term",
    "MetricContext",
    "AbstractObjective",
    "Objective",
]


def _exact_form(name: str) -> Callable[..., Any]:
    """The exact form of the metric ``name`` (every flag has one): ``exact(sol, scenario, ctx)``."""
    exact = M.METRICS[name].exact
    if exact is None:
        raise ValueError(f"metric {name!r} has no exact form")
    return exact


@eqx.filter_jit
def _aggregate(aggregation, values):
    """``aggregation(values)`` as one compiled program (eagerly, each of its jnp operations compiled alone)."""
    return aggregation(values)


@eqx.filter_jit
def _aggregate_and_grad(aggregation, values, grads):
    """The aggregate of the per-scenario ``values`` and its gradient through the per-scenario ``grads``
    (rows): ``(A(v), ∂A/∂v · G)``, one compiled program."""
    a, w = jax.value_and_grad(aggregation)(values)
    return a, w @ grads


# the gradient by forward mode up to this many gains (module doc, "Gradients")
FORWARD_MAX = 8

# --------------------------------------------------------------------------
# per-scenario metrics: the one table's (jaxobs.metrics.METRICS), in their smooth forms where they have one
# --------------------------------------------------------------------------

# A system metric (kind "system", the table's stability_margin) as a term: not a function of one simulation but
# of the closed loop itself, jaxobs.analysis.stability.lyapunov's largest non-neutral exponent (1/s) at the
# scenario (from its steady start; an event at t_event falls inside the settle), differentiable with respect to
# the gains.  The term's value is that exponent, minus the margin, so minimizing it raises the margin; give it a
# small weight (rad against 1/s).  Short runs (compile time and cost: the step's jvp in n_dirs directions): enough
# to rank designs by their slowest mode, not a verdict (the envelope's verification gives that).
MARGIN_KW = {"settle": 0.1, "warmup": 0.05, "window": 0.2, "n_dirs": 2}

# the metrics a term may name (a view of the table: its run and system metrics, not its flags; each called as its
# smooth form): the FLL family's on grid signals, the flux observers' on EMF signals, the drive observers' in the
# closed loop
TERM_METRICS: dict[str, Metric] = {k: m for k, m in M.METRICS.items() if m.kind != "flag"}
# the per-scenario flag :meth:`Objective.per_scenario` adds to the metrics: the estimate ended far from the
# truth (the table's lost_lock: 45° / 10 % on signals, 90° on the drive, over the steady window)
LOST_LOCK = "lost_lock"
# the flags the drive adds (the table's): lost_sync (lost lock anywhere in the scored horizon) and lost_speed
DRIVE_FLAGS = ("lost_sync", "lost_speed")
_OK = " ok"  # the simulation's own flag among a scenario's metrics (a name no metric has)
# metrics that need the closed-loop drive (signal = "drive" jobs)
DRIVE_METRICS = tuple(k for k, m in TERM_METRICS.items() if m.closed_loop)

# Loss of synchronism of a drive observer (the table's lost_sync), a per-scenario flag (never fatal): its simulation
# diverged, or |θ̂e − θe| exceeded this anywhere in the scored horizon [0, horizon) (the settling phase before t = 0
# is not scored, nor a standstill start's I-f phase before its hand-over: jaxobs.metrics.scored_position_error).
LOST_SYNC_DEG = M.LOCK_TOL_DRIVE_DEG


@dataclass(frozen=True)
class Term:
    """One weighted term of the objective: a metric times its weight.

    Attributes:
        metric: A :class:`~jaxobs.metrics.Metric`, or the name of one in :data:`TERM_METRICS`; kept as its name,
            the Metric in :attr:`measure`.  An old name (:data:`jaxobs.metrics.ALIASES`) is read as its new one
            with a :class:`DeprecationWarning`, the weight converted to the new units.
        weight: The weight, per the metric's unit.
        measure: The :class:`~jaxobs.metrics.Metric` itself.
    """

    metric: str | Metric
    weight: float = 1.0
    measure: Metric | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        if isinstance(self.metric, str) and self.metric in M.ALIASES:
            name, scale = M.canonical(self.metric, "Term.metric")
            object.__setattr__(self, "metric", name)
            object.__setattr__(self, "weight", self.weight / scale)  # per the new unit: the same term
        m = self.metric if isinstance(self.metric, Metric) else TERM_METRICS.get(self.metric)
        object.__setattr__(self, "measure", m)
        if isinstance(self.metric, Metric):
            object.__setattr__(self, "metric", self.metric.name)


# --------------------------------------------------------------------------
# the objective
# --------------------------------------------------------------------------


@eqx.filter_jit
def _per_scenario_vg(objective, theta, scenarios):
    """:meth:`Objective._per_scenario_value_and_grad` as one program: the objective's arrays (the component's
    fixed values, a family's machine) and the scenarios are its inputs, its static fields its key."""
    return objective._per_scenario_value_and_grad(theta, scenarios)


@eqx.filter_jit
def _per_scenario_plain(objective, theta, scenarios):
    """:meth:`Objective._per_scenario_plain_value` as one program (as :func:`_per_scenario_vg`)."""
    return objective._per_scenario_plain_value(theta, scenarios)


@eqx.filter_jit
def _response_program(objective, theta, sig):
    return objective._response(theta, sig)


@eqx.filter_custom_jvp
def _value(theta, objective, scenarios):
    """The aggregate at ``theta`` with the sanitized derivative (module doc, "Divergence"): optax and optimistix
    see the gradient assembled per scenario, a diverged scenario's zero included."""
    return objective._aggregate_with_grad(theta, scenarios)[0]


@_value.def_jvp
def _value_jvp(primals, tangents):
    # a function of θ alone: the objective's and the scenarios' tangents (None) do not enter
    (theta, objective, scenarios), (tdot, _, _) = primals, tangents
    v, g = objective._aggregate_with_grad(theta, scenarios)
    return v, jnp.dot(g, tdot)


class Objective(AbstractObjective):
    """value(θ, scenarios), value_and_grad(θ, scenarios) and per-scenario scores of a component on a batch.

    A module: its own values (the component, the family's machine) are arrays of its programs' inputs, and the
    scenario batch is an argument of every call, so the value-and-gradient compiles once per batch shape
    (``eqx.filter_jit``; JAX's persistent cache, :func:`jaxobs.use_compile_cache`, keeps it across processes).

    Args:
        component: The module whose free gains ``param`` sets.
        param: The :class:`~jaxobs_tuning.params.Parametrization` of the free gains.
        horizon: Simulated seconds per scenario.
        terms: The weighted metrics (:class:`Term`) summed per scenario.
        ctx: The metrics' event time, steady window and bands.
        aggregation: How the per-scenario values become one (:class:`~jaxobs_tuning.aggregations.Mean` by
            default).
        penalty: The value of a diverged scenario.
        family: The scenarios' family (:mod:`jaxobs.scenarios.families`), which makes the system the component runs on
            each scenario (bound to it: the machine an observer assumes, its initial speed; closing the
            drive's loop for :class:`~jaxobs.scenarios.families.DriveScenarios`); None: the component runs on each
            scenario, a signal, as it is.

    Raises:
        ValueError: An unknown metric, or an aggregation that is not an aggregation object.
    """

    component: Any
    param: Parametrization = eqx.field(static=True)
    horizon: float = eqx.field(static=True)
    terms: tuple = eqx.field(static=True)
    ctx: MetricContext = eqx.field(static=True)
    aggregation: AbstractAggregation
    penalty: float = eqx.field(static=True)
    family: AbstractFamily | None

    def __init__(
        self,
        component,
        param: Parametrization,
        *,
        horizon: float,
        terms: list[Term],
        ctx: MetricContext,
        aggregation: AbstractAggregation = Mean(),
        penalty: float = 1e3,
        family: AbstractFamily | None = None,
    ):
        for term in terms:
            if term.measure is None:
                raise ValueError(f"objective metric {term.metric!r} is unknown; known: {', '.join(TERM_METRICS)}")
        if not isinstance(aggregation, AbstractAggregation):
            raise ValueError(
                f"Objective.aggregation must be jaxobs_tuning.Mean(), SmoothMax() or CVaR(), got {aggregation!r}"
            )
        self.component = component
        self.param = param
        self.horizon = float(horizon)
        self.terms = tuple(terms)
        self.ctx = ctx
        self.aggregation, self.penalty = aggregation, float(penalty)
        self.family = family

    @property
    def closed_loop(self) -> bool:
        """Whether the component closes the drive's loop (the drive's metrics and flags apply)."""
        return self.family is not None and self.family.closed_loop

    @property
    def _save(self) -> SaveAll:
        """The solver's runs: every step's outputs, an observer on a signal through the loop made fast, the drive
        plainly (module doc); the scoring and the figures run once per design, where compile time counts."""
        return SaveAll(fast=not self.closed_loop)

    def value(self, theta: jax.Array, scenarios: Any) -> jax.Array:
        """The objective at ``theta`` on ``scenarios``, with the sanitized derivative (module doc).

        Args:
            theta: The free gains' vector.
            scenarios: The batch (leading axis the scenarios).

        Returns:
            The scalar objective.
        """
        return _value(theta, self, scenarios)

    # --- single scenario
    def _simulate(self, comp, sig, save=SaveAll()):
        return simulate(self._bound_system(comp, sig), self.horizon, save=save)

    def _exponent(self, comp, sig):
        """A system metric's value (the stability margin): the largest non-neutral Lyapunov exponent (1/s) of the
        loop that ``comp`` (bound to ``sig``) closes, :data:`MARGIN_KW`."""
        loop = cast("ClosedLoop", self._bound_system(comp, sig))  # a drive job: the closed loop
        return lyapunov(loop, **MARGIN_KW).exponent

    def _term(self, term, comp, sol, sig):
        if term.measure.kind == "system":
            return self._exponent(comp, sig)
        return term.measure(sol, sig, self.ctx)

    def _one(self, theta, sig):
        comp = self.param.apply(self.component, theta)
        sol = self._simulate(comp, sig, self._save)
        vals = [term.weight * self._term(term, comp, sol, sig) for term in self.terms]
        # Diverged: the final state not finite (a non-finite value never leaves these systems' states again, as
        # SaveFinal's ok reads it); a non-finite output the metrics read makes the value non-finite, which
        # _per_scenario_value_and_grad counts too.  Not sol.ok, every output over the horizon: asking for it
        # kept every output of the loop alive, those no metric reads included (slower, docs/performance.md).
        # The scores' diverged counts keep sol.ok (_scenario_metrics).
        return sum(vals), sol.final_ok

    def _forward_mode(self, theta) -> bool:
        """The gradient by forward mode (module doc, "Gradients"): up to :data:`FORWARD_MAX` gains and no
        stability-margin term."""
        return theta.size <= FORWARD_MAX and not self._system_terms

    def _per_scenario_value_and_grad(self, theta, scenarios):
        def vg(sig):
            if self._forward_mode(theta):
                one = lambda th: self._one(th, sig)  # noqa: E731
                # one tangent per gain, pushed beside one primal run (vmap over the basis; the primal unbatched)
                (v, ok), (g, _) = jax.vmap(lambda d: jax.jvp(one, (theta,), (d,)), out_axes=((None, None), (0, 0)))(
                    jnp.eye(theta.size, dtype=theta.dtype)
                )
            else:
                (v, ok), g = jax.value_and_grad(self._one, has_aux=True)(theta, sig)
            return v, ok, g

        v, ok, g = jax.vmap(vg)(scenarios)
        g_finite = jnp.all(jnp.isfinite(g), axis=-1)
        good = ok & jnp.isfinite(v) & g_finite
        over = ok & jnp.isfinite(v) & ~g_finite  # a finite run and value, a gradient that overflowed
        v = jnp.where(good, v, self.penalty)
        g = jnp.where(good[:, None], g, 0.0)
        return v, g, good, over

    def _per_scenario_plain_value(self, theta, scenarios):
        """Per scenario the value without its derivative, the penalty where the run or the value is not finite
        (no gradient: one that would not be finite, as an rms of an error exactly 0 has, costs nothing here)."""
        v, ok = jax.vmap(lambda sig: self._one(theta, sig))(scenarios)
        good = ok & jnp.isfinite(v)
        return jnp.where(good, v, self.penalty), good

    def plain_value(self, theta: jax.Array, scenarios: Any) -> jax.Array:
        """The objective at ``theta`` without its derivative (a gradient-free minimiser's; no tangent is pushed).

        Args:
            theta: The free gains' vector.
            scenarios: The batch (leading axis the scenarios).

        Returns:
            The scalar objective.
        """
        return self.aggregation(_per_scenario_plain(self, theta, scenarios)[0])

    def plain_value_diverged(self, theta: jax.Array, scenarios: Any) -> tuple[jax.Array, int]:
        """:meth:`plain_value` and how many scenarios diverged (their run or value not finite).

        Args:
            theta: The free gains' vector.
            scenarios: The batch (leading axis the scenarios).

        Returns:
            ``(value, diverged count)``.
        """
        v, good = _per_scenario_plain(self, theta, scenarios)
        return self.aggregation(v), int(np.sum(~np.asarray(good)))

    def _aggregate_with_grad(self, theta, scenarios):
        v, g, _, _ = _per_scenario_vg(self, theta, scenarios)
        return _aggregate_and_grad(self.aggregation, v, g)

    def value_and_grad(self, theta: jax.Array, scenarios: Any) -> tuple[jax.Array, jax.Array]:
        """The objective at ``theta`` on ``scenarios`` and its gradient (module doc, "Divergence").

        Args:
            theta: The free gains' vector.
            scenarios: The batch (leading axis the scenarios).

        Returns:
            ``(value, gradient)``.
        """
        return self._aggregate_with_grad(theta, scenarios)

    def value_grad_diverged_overflowed(self, theta: jax.Array, scenarios: Any) -> tuple[jax.Array, jax.Array, int, int]:
        """:meth:`value_and_grad`, how many scenarios diverged and how many overflowed: a finite simulation and
        value, a gradient that is not finite (a finite but huge weight; counted with the diverged ones too).
        When the aggregate or its gradient is not finite though every scenario's value is, every scenario counts.

        Args:
            theta: The free gains' vector.
            scenarios: The batch (leading axis the scenarios).

        Returns:
            ``(value, gradient, diverged count, overflowed count)``.
        """
        v, g, good, over = _per_scenario_vg(self, theta, scenarios)
        agg_v, grad = _aggregate_and_grad(self.aggregation, v, g)
        # the counts on the host: each eager jnp reduction here was a program of its own to compile
        good, over = np.asarray(good), np.asarray(over)
        n_over = int(np.sum(over))
        if not (np.isfinite(float(agg_v)) and np.all(np.isfinite(np.asarray(grad)))):
            n_over = int(v.shape[0])
        return agg_v, grad, int(np.sum(~good)), n_over

    def overflowed(self, theta: jax.Array, scenarios: Any, scored_good: ArrayLike) -> int:
        """Scenarios whose simulation and weighted metrics are finite (``scored_good``: :meth:`per_scenario`'s
        mask at ``theta``) but whose tuning value or gradient is not: the objective overflows (a finite but
        huge weight), which the solver counts with the diverged scenarios, though nothing diverged.

        Args:
            theta: The free gains' vector.
            scenarios: The batch ``scored_good`` is of.
            scored_good: :meth:`per_scenario`'s good mask at ``theta``.

        Returns:
            The number of such scenarios.
        """
        _, _, good, _ = _per_scenario_vg(self, theta, scenarios)
        return int(np.sum(np.asarray(scored_good) & ~np.asarray(good)))

    def response(self, theta: jax.Array, sig: Any) -> tuple[jax.Array, jax.Array, jax.Array]:
        """One scenario's run at ``theta`` as the report draws it; one program for every design and scenario.

        Args:
            theta: The free gains' vector.
            sig: One scenario (no leading axis).

        Returns:
            The sample times (s), the observer's frequency estimate ``obs.omega`` (rad/s) and its position error
            θ̂ − θ (rad, :func:`jaxobs.metrics.position_error`).
        """
        return _response_program(self, theta, sig)

    def _response(self, theta, sig):
        sol = self._simulate(self.param.apply(self.component, theta), sig)
        return sol.t, sol.outputs.obs.omega, M.position_error(sol, sig)

    # --- reporting: a design scored on the scenarios by the one study runner (jaxobs.runtime.runner)
    def _bound_system(self, comp, sig):
        """The system one scenario runs: the family's (``comp`` bound to the scenario, on its signal or closing
        the drive's loop), or ``comp`` on the signal as it is."""
        return OnSignal(comp, sig) if self.family is None else self.family.system(comp, sig)

    def _system(self, theta, sig):
        """The system one scenario runs at ``theta`` (what :meth:`_simulate` simulates)."""
        return self._bound_system(self.param.apply(self.component, theta), sig)

    @property
    def _system_terms(self) -> bool:
        """Whether a term is a system metric (of the loop, not of one run: the stability margin)."""
        return any(t.measure.kind == "system" for t in self.terms)

    @property
    def flags(self) -> tuple[str, ...]:
        """The table's flags each scenario reports beside the metrics: :data:`LOST_LOCK`, and on the drive
        :data:`DRIVE_FLAGS`."""
        return (LOST_LOCK, *DRIVE_FLAGS) if self.closed_loop else (LOST_LOCK,)

    def _scenario_metrics(self, sol, sig, _aux):
        mets = {t.metric: t.measure(sol, sig, self.ctx) for t in self.terms if t.measure.kind == "run"}
        # the flags, reported, not tuned on: far from the truth over the steady window (lost_lock); on the drive
        # lost synchronism anywhere in the scored horizon (lost_sync) and a missed speed reference over the steady
        # window (lost_speed: e.g. a standstill start that runs backwards with a locked observer)
        mets.update({k: _exact_form(k)(sol, sig, self.ctx) for k in self.flags})
        return {**mets, _OK: sol.ok}

    def _per_scenario_metrics(self, theta, scenarios):
        given = Given(scenarios)
        # one chunk of every scenario on one device: the jit(vmap) the objective always ran (the runner's program
        # takes these two methods, and with them the objective's arrays, as inputs)
        run = run_scenarios(
            {"design": theta},
            given,
            self._system,
            self._scenario_metrics,
            horizon=self.horizon,
            chunk_size=given.n,
            mesh=batch_mesh(jax.devices()[:1]),
            label="scores",
        )
        assert run.values is not None  # no sink was given: run_scenarios keeps the values
        mets = dict(run.values["design"])
        for t in self.terms:  # system metrics: of the loop, not of the run; one jit(vmap)
            if t.measure.kind == "system":
                mets[t.metric] = np.asarray(self._exponents(theta, scenarios))
        return mets, mets.pop(_OK)

    @eqx.filter_jit
    def _exponents(self, theta, scenarios):
        comp = self.param.apply(self.component, theta)
        return jax.vmap(lambda sig: self._exponent(comp, sig))(scenarios)

    def per_scenario(self, theta: jax.Array, scenarios: Any) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
        """Each scenario's metrics (and its :data:`LOST_LOCK` flag), its weighted total (the penalty where
        diverged) and the good mask — no gradient.

        On the drive the metrics hold the table's ``lost_sync`` too: diverged, or |θ̂e − θe| > :data:`LOST_SYNC_DEG`;
        and ``lost_speed``: diverged, or the drive missed its speed reference (:func:`jaxobs.metrics.lost_speed`).

        Args:
            theta: The free gains' vector.
            scenarios: The batch (leading axis the scenarios).

        Returns:
            ``(metrics, total, good)``: metric name -> per-scenario values, the weighted totals (the penalty
            where diverged), and the good mask.
        """
        mets, ok = self._per_scenario_metrics(theta, scenarios)
        # NumPy from here (the runner's values are NumPy arrays): no gradient flows through the scores, and
        # every eager jnp operation on them was a small XLA program compiled on a first run
        mets = {k: np.asarray(v) for k, v in mets.items()}
        with np.errstate(over="ignore", invalid="ignore"):  # a diverged scenario's inf/NaN: masked just below
            total = sum(term.weight * mets[term.metric] for term in self.terms)
        good = np.asarray(ok) & np.isfinite(total)
        for key in DRIVE_FLAGS:
            if key in mets:
                mets = {**mets, key: mets[key] | ~good}
        return mets, np.where(good, total, self.penalty), good

    def scores(self, theta: jax.Array, scenarios: Any) -> dict:
        """Objective and each metric's mean and worst over ``scenarios``.

        Args:
            theta: The free gains' vector.
            scenarios: The batch (leading axis the scenarios).

        Returns:
            The summary dict (:meth:`summarize`).
        """
        return self.summarize(*self.per_scenario(theta, scenarios))

    def summarize(self, mets: Mapping[str, ArrayLike], total: ArrayLike, good: ArrayLike) -> dict:
        """:meth:`scores` from :meth:`per_scenario`'s output.  Where every scenario diverged the metrics'
        means and worsts are ``None`` (there is nothing to average), and ``"null_reason"`` says why.

        Args:
            mets: metric name -> per-scenario values.
            total: The per-scenario weighted totals.
            good: The good mask.

        Returns:
            The summary dict.
        """
        # on the host, in NumPy, but the aggregation (one jitted program: it is the tuning objective's own)
        mets = {k: np.asarray(v) for k, v in mets.items()}
        total, good = np.asarray(total), np.asarray(good)
        out = {
            "objective": float(_aggregate(self.aggregation, jnp.asarray(total))),
            "diverged": int(np.sum(~good)),
        }
        if LOST_LOCK in mets:  # scenarios whose estimate ends far from the truth, the diverged ones included
            out[LOST_LOCK] = int(np.sum(mets[LOST_LOCK] | ~good))
        for key in DRIVE_FLAGS:  # the drive: lost synchronism, lost speed (diverged ones included)
            if key in mets:
                out[key] = int(np.sum(mets[key]))
        for term in self.terms:
            m = np.where(good, mets[term.metric], np.nan)
            if bool(np.any(good)):
                out[f"{term.metric}_mean"] = float(np.nanmean(m))
                out[f"{term.metric}_worst"] = float(np.nanmax(m))
            else:
                out[f"{term.metric}_mean"] = out[f"{term.metric}_worst"] = None
        out["per_scenario_worst"] = float(np.max(total))
        if not bool(np.any(good)):
            out["null_reason"] = "every scenario diverged: the metrics' means and worsts are undefined"
        return out
