"""The names a TOML job gives its strategies, and the objects they stand for: the one table.

A job file says ``objective.aggregate = "cvar"``, ``solver.kind = "adam"``, ``solver.schedule =
"cosine"``; the schema checks the names against these tables and builds the objects with
:func:`aggregation` and :func:`solver`, which is all that ever reads a name.  In Python, pass the
objects themselves (``Objective(..., aggregation=CVaR(0.9))``, ``tune(objective, optax.adam(0.1))``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import optax
import optimistix as optx

from .aggregations import AbstractAggregation, CVaR, Mean, SmoothMax
from .solvers import AbstractSolver, OptaxSolver, OptimistixSolver

__all__ = [
    "AGGREGATIONS",
    "SCHEDULES",
    "OPTAX",
    "MINIMISERS",
    "NM_SIMPLEX",
    "SOLVER_KINDS",
    "aggregation",
    "solver",
    "one_of",
]

# objective.aggregate: name -> the aggregation, from objective.alpha (CVaR) and objective.temperature (smooth max)
AGGREGATIONS: dict[str, Callable] = {
    "mean": lambda alpha, temperature: Mean(),
    "max": lambda alpha, temperature: SmoothMax(temperature),
    "cvar": lambda alpha, temperature: CVaR(alpha),
}

# solver.schedule: name -> the learning rate over the iterations, from solver.learning_rate and solver.steps
SCHEDULES: dict[str, Callable] = {
    "constant": lambda learning_rate, steps: learning_rate,
    "cosine": lambda learning_rate, steps: optax.cosine_decay_schedule(learning_rate, max(steps, 1)),
}

# solver.kind: an optax transformation of a learning rate (or schedule), run by OptaxSolver ...
OPTAX: dict[str, Callable] = {"adam": optax.adam, "adamw": optax.adamw, "sgd": optax.sgd}
# Nelder–Mead's first simplex: θ0 and θ0 + NM_SIMPLEX along each θ axis.  θ is the gains' unconstrained coordinate
# (jaxobs_tuning.params: a logistic of log g between the bounds), so 0.5 moves a gain bounded over two decades by
# a factor of about 1.8 near the middle of its range: a first look past the roughness of a peak objective.
# optimistix's own default (5 % of θ0, plus 2.5e-4) is a finite-difference stencil: at θ0 = 0 (a gain at the
# geometric middle of its bounds) it would probe 2.5e-4, well inside the ripple a limit cycle puts on the peak.
NM_SIMPLEX = 0.5
# ... or an optimistix minimiser of a tolerance (relative and absolute), run by OptimistixSolver.  "nelder_mead" is
# gradient-free: for objectives whose gradient is not their trend (a steady peak through a limit cycle, a max over
# samples: the AD derivative is that of one sample and one period, docs/tuning.md)
MINIMISERS: dict[str, Callable] = {
    "bfgs": lambda tol: optx.BFGS(rtol=tol, atol=tol),
    "nelder_mead": lambda tol: optx.NelderMead(rtol=tol, atol=tol, rdelta=0.0, adelta=NM_SIMPLEX),
}
SOLVER_KINDS = (*OPTAX, *MINIMISERS)
# the [solver] keys only an optax solver reads (a minimiser refuses them)
OPTAX_ONLY = ("learning_rate", "schedule", "patience", "checkpoint_every")


def one_of(names: Iterable[str]) -> str:
    """``a, b, c or d``: the allowed names, for an error message.

    Args:
        names: The names, at least one.

    Returns:
        The names joined.
    """
    names = list(names)
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " or " + names[-1]


def aggregation(name: str, *, alpha: float = 0.9, temperature: float | None = None) -> AbstractAggregation:
    """The aggregation named ``name`` (:data:`AGGREGATIONS`).

    Args:
        name: ``"mean"``, ``"max"`` or ``"cvar"``.
        alpha: :class:`~jaxobs_tuning.aggregations.CVaR`'s α.
        temperature: :class:`~jaxobs_tuning.aggregations.SmoothMax`'s temperature.

    Returns:
        The :class:`~jaxobs_tuning.aggregations.AbstractAggregation`.

    Raises:
        ValueError: An unknown name.
    """
    if name not in AGGREGATIONS:
        raise ValueError(f"objective.aggregate must be {one_of(AGGREGATIONS)}, got {name!r}")
    return AGGREGATIONS[name](alpha, temperature)


def solver(
    kind: str,
    *,
    learning_rate: float = 0.05,
    schedule: str = "constant",
    steps: int = 100,
    patience: int = 25,
    tol: float = 1e-6,
    checkpoint_every: int = 5,
    progress_every: int = 1,
) -> AbstractSolver:
    """The solver named ``kind`` with a job's ``[solver]`` settings; its ``name`` is the kind.

    Args:
        kind: A name of :data:`SOLVER_KINDS`: an optax transformation (:data:`OPTAX`) or an optimistix
            minimiser (:data:`MINIMISERS`).
        learning_rate: The optax solver's learning rate.
        schedule: The learning rate over the iterations (:data:`SCHEDULES`).
        steps: The iteration budget.
        patience: The optax solver's patience (:class:`~jaxobs_tuning.solvers.OptaxSolver`).
        tol: The relative improvement that counts (and a minimiser's tolerance).
        checkpoint_every: Iterations between the optax solver's checkpoints.
        progress_every: Iterations between progress figures.

    Returns:
        The :class:`~jaxobs_tuning.solvers.AbstractSolver`.

    Raises:
        ValueError: An unknown kind or schedule.
    """
    if kind in OPTAX:
        if schedule not in SCHEDULES:
            raise ValueError(f"solver.schedule must be {one_of(SCHEDULES)}, got {schedule!r}")
        return OptaxSolver(
            OPTAX[kind](SCHEDULES[schedule](learning_rate, steps)),
            steps=steps,
            patience=patience,
            tol=tol,
            checkpoint_every=checkpoint_every,
            progress_every=progress_every,
            name=kind,
        )
    if kind in MINIMISERS:
        return OptimistixSolver(MINIMISERS[kind](tol), steps=steps, tol=tol, progress_every=progress_every, name=kind)
    raise ValueError(f"solver.kind must be {one_of(SOLVER_KINDS)}, got {kind!r}")
