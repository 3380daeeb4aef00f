"""Strategy objects of tuning: aggregations (the method that aggregates), solvers (the method that runs) and
the one table from a job's names to them."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import optax
import optimistix as optx
import pytest

from jaxobs_tuning import (
    AbstractObjective,
    CVaR,
    Mean,
    Objective,
    OptaxSolver,
    OptimistixSolver,
    SmoothMax,
    strategies,
    tune,
)
from jaxobs_tuning.solvers import as_solver


def test_aggregations_on_a_hand_made_batch():
    v = jnp.asarray([1.0, 2.0, 3.0, 10.0])
    assert float(Mean()(v)) == 4.0
    assert float(CVaR(0.75)(v)) == 10.0  # the worst ⌈0.25·4⌉ = 1
    assert float(CVaR(0.5)(v)) == 6.5  # the worst 2
    assert float(CVaR(0.0)(v)) == 4.0  # all of them: the mean
    # log-sum-exp: between the max and max + T log B, tight as T → 0; its gradient weights the worst
    for t in (1.0, 0.1, 1e-3):
        s = float(SmoothMax(t)(v))
        assert 10.0 <= s <= 10.0 + t * np.log(4) + 1e-12
    g = jax.grad(SmoothMax(0.1))(v)
    assert float(g[-1]) == pytest.approx(1.0, abs=1e-12) and float(jnp.sum(g)) == pytest.approx(1.0)
    # no temperature: 1 % of the mean magnitude (0.04 here)
    assert float(SmoothMax()(v)) == pytest.approx(float(SmoothMax(0.04)(v)), rel=1e-12)


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: CVaR(1.0), "CVaR.alpha"),
        (lambda: CVaR(-0.1), "CVaR.alpha"),
        (lambda: SmoothMax(0.0), "SmoothMax.temperature"),
        (lambda: SmoothMax(float("inf")), "SmoothMax.temperature"),
        (lambda: strategies.aggregation("worst"), "objective.aggregate must be mean, max or cvar"),
        (lambda: strategies.solver("lbfgs"), "solver.kind must be adam, adamw, sgd, bfgs or nelder_mead"),
        (lambda: strategies.solver("adam", schedule="linear"), "solver.schedule must be constant or cosine"),
        (lambda: as_solver("adam"), "optimizer must be an optax GradientTransformation"),
        (lambda: OptaxSolver(optax.adam(0.1), steps=0), "OptaxSolver.steps"),
        (lambda: OptaxSolver(optax.adam(0.1), patience=True), "OptaxSolver.patience"),
        (lambda: OptimistixSolver(optx.BFGS(rtol=1e-6, atol=1e-6), tol=-1.0), "OptimistixSolver.tol"),
        (lambda: Objective(None, None, horizon=1.0, terms=[], ctx=None, aggregation="mean"), "aggregation"),
        (lambda: tune(object(), optax.sgd(0.1)), "objective must be a jaxobs_tuning.AbstractObjective"),
    ],
)
def test_bad_strategies_are_refused_naming_the_field(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_the_table_builds_the_objects_a_job_names():
    assert strategies.aggregation("mean") == Mean()
    assert strategies.aggregation("max", temperature=0.5) == SmoothMax(0.5)
    assert strategies.aggregation("cvar", alpha=0.8, temperature=0.5) == CVaR(0.8)
    adam = strategies.solver("adam", learning_rate=0.1, steps=7, patience=3)
    assert isinstance(adam, OptaxSolver) and (adam.name, adam.steps, adam.patience) == ("adam", 7, 3)
    bfgs = strategies.solver("bfgs", tol=1e-5)
    assert isinstance(bfgs, OptimistixSolver) and isinstance(bfgs.minimiser, optx.BFGS)
    assert bfgs.minimiser.rtol == bfgs.minimiser.atol == 1e-5 and bfgs.name == "bfgs"
    nm = strategies.solver("nelder_mead", tol=1e-5, steps=9)
    assert isinstance(nm, OptimistixSolver) and isinstance(nm.minimiser, optx.NelderMead) and nm.steps == 9
    assert (nm.minimiser.adelta, nm.minimiser.rdelta) == (strategies.NM_SIMPLEX, 0.0)
    # the cosine schedule decays the learning rate over the solver's steps
    sched = strategies.SCHEDULES["cosine"](0.1, 10)
    assert float(sched(0)) == pytest.approx(0.1) and float(sched(10)) == pytest.approx(0.0, abs=1e-12)


class _Quadratic(AbstractObjective):
    """(θ − 1)², never diverged; no simulation."""

    class param:
        @staticmethod
        def values(theta):
            return {"g": float(theta[0])}

        @staticmethod
        def to_theta(values):
            return jnp.asarray([values["g"]])

        @staticmethod
        def theta0():
            return jnp.zeros(1)

    def value_grad_diverged_overflowed(self, theta, scenarios):
        return jnp.sum((theta - 1.0) ** 2), 2 * (theta - 1.0), 0, 0

    def value(self, theta, scenarios):
        return jnp.sum((theta - 1.0) ** 2)


def test_tune_takes_an_optax_transformation_or_an_optimistix_minimiser_directly():
    # plain gradient descent at rate 0.1 contracts θ − 1 by 0.8 per step: 100 steps (the default budget)
    res = tune(_Quadratic(), optax.sgd(0.1))
    assert res.status == "budget" and res.iterations == 100
    assert float(res.theta[0]) == pytest.approx(1.0 - 0.8**100, abs=1e-12)
    assert len(res.history) == 101  # every iterate and the last update
    res = tune(_Quadratic(), optx.BFGS(rtol=1e-8, atol=1e-8), jnp.asarray([3.0]))
    assert res.status == "converged" and "BFGS" in res.reason
    assert float(res.theta[0]) == pytest.approx(1.0, abs=1e-6)


class _Rough(_Quadratic):
    """(θ − 1)² with a ripple 0.05 sin(200 θ) on it: its gradient at θ = 0 (≈ 8) points away from the trend's (−2)
    and a gradient method stops in the ripple next to its start, as an Adam or BFGS step on a steady peak through a
    limit cycle does (docs/tuning.md)."""

    def value_grad_diverged_overflowed(self, theta, scenarios):
        v, g = jax.value_and_grad(self.value)(theta, scenarios)
        return v, g, 0, 0

    def value(self, theta, scenarios):
        return jnp.sum((theta - 1.0) ** 2 + 0.05 * jnp.sin(200.0 * theta))


def test_nelder_mead_finds_the_trend_of_a_rough_objective_where_bfgs_stops_in_its_ripple():
    """The job's "nelder_mead" (a simplex of θ0 and θ0 + NM_SIMPLEX) reaches the trend's minimum at θ = 1 within
    the ripple's scale, each recorded iterate better than the one before; BFGS from the same start stays within a
    ripple period of θ0; the run reports its objective evaluations (2 per step, d + 1 for the first simplex and a
    shrink)."""
    nm = strategies.solver("nelder_mead", tol=1e-9, steps=40)
    res = tune(_Rough(), nm, jnp.zeros(1), quiet=True)
    assert abs(float(res.theta[0]) - 1.0) < 0.1, res.theta
    assert res.value < float(_Rough().value(jnp.zeros(1), None)) - 0.5
    # each recorded iterate is the simplex's best vertex (tuning/minimisers.py best_iterate): never worse
    values = [h["value"] for h in res.history]
    assert all(b < a for a, b in zip(values, values[1:], strict=False)), values
    evals = res.timing["evaluations"]
    assert 2 * res.iterations <= evals <= 4 * res.iterations + 2 and f"({evals} objective evaluations)" in res.reason
    res_bfgs = tune(_Rough(), strategies.solver("bfgs", tol=1e-9, steps=40), jnp.zeros(1), quiet=True)
    assert abs(float(res_bfgs.theta[0])) < 2 * math.pi / 200, res_bfgs.theta
    assert "evaluations" not in res_bfgs.timing
