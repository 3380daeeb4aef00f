"""What :class:`jaxobs_tuning.solvers.OptimistixSolver` reads off an optimistix minimiser: whether it needs the
objective's derivative, the sentence its outcome gives, and how many objective evaluations a run made.

Nelder–Mead (``optx.NelderMead``, a job's ``solver.kind = "nelder_mead"``) uses objective values only.  Its solver
then minimises :meth:`jaxobs_tuning.base.AbstractObjective.plain_value`, the objective without its derivative: no
tangent is pushed through the runs, and a scenario whose value is finite but whose derivative is not (an rms of an
error that is exactly 0) keeps its value instead of the penalty a gradient method's divergence rule gives it.
"""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp
import optimistix as optx

__all__ = ["gradient_free", "minimiser_reason", "evaluations", "best_iterate"]


def gradient_free(minimiser: optx.AbstractMinimiser) -> bool:
    """Whether ``minimiser`` uses objective values only (Nelder–Mead).

    Args:
        minimiser: The optimistix minimiser.

    Returns:
        True for :class:`optimistix.NelderMead`.
    """
    return isinstance(minimiser, optx.NelderMead)


def best_iterate(minimiser: optx.AbstractMinimiser, y: Any, state: Any) -> Any:
    """The iterate a step leaves: ``y`` as the minimiser returns it, or for Nelder–Mead the best vertex of its
    simplex.  Decision: optimistix's ``NelderMead.step`` returns a vertex of the simplex it started the step with,
    picked by the index of the new simplex's best (measured: on the PM-SyRM job it returned vertices worse than
    the start, objective 0.176 against 0.124), so the best vertex is read from the state, where the simplex and its
    values agree; a vertex the step just found is then recorded at that step, not one step later.

    Args:
        minimiser: The optimistix minimiser.
        y: The iterate its step returned.
        state: Its state after the step.

    Returns:
        The iterate to record.
    """
    if not isinstance(minimiser, optx.NelderMead):
        return y
    return state.simplex[jnp.argmin(state.f_simplex)]


def minimiser_reason(result: Any, name: str) -> tuple[bool, str]:
    """(finished by its own test, a sentence) for an optimistix RESULTS value of the minimiser ``name``.

    Args:
        result: The ``optimistix.RESULTS`` value.
        name: The minimiser's class name.

    Returns:
        ``(finished, sentence)``.
    """
    R = optx.RESULTS
    if result == R.successful:
        return True, f"converged: {name}'s relative change of θ and of the objective fell below tol"
    if result == R.nonlinear_max_steps_reached:
        return False, f"budget: {name} took its solver.steps"
    if result == R.nonlinear_divergence:
        return False, f"{name} diverged"
    if result == R.nonfinite:
        return False, f"{name} met a non-finite objective or gradient"
    return False, f"{name} stopped: {R[result] or 'unknown reason'}"


def evaluations(minimiser: optx.AbstractMinimiser, state: Any, dim: int) -> int | None:
    """The objective evaluations of a Nelder–Mead run, from its state: d + 1 for the first simplex and for each
    shrink, 2 for every other step (optimistix evaluates the reflection and the vertex it then picks); the
    solver's own scoring of each accepted iterate is not counted.

    Args:
        minimiser: The optimistix minimiser.
        state: Its state after the run.
        dim: The number of free gains d.

    Returns:
        The count; None for another minimiser (its evaluations are its steps').
    """
    if not isinstance(minimiser, optx.NelderMead):
        return None
    return (dim + 1) * (1 + int(state.stats.n_shrink)) + 2 * max(int(state.step) - 1, 0)
