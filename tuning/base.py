"""What a solver minimises: the objective's protocol (:class:`AbstractObjective`).

The solvers (:mod:`jaxobs_tuning.solvers`) call only what it declares; :class:`jaxobs_tuning.objective.Objective`
implements it for every job, and a user's own objective subclasses it.
"""

# no ``from __future__ import annotations``: equinox recognizes ``eqx.AbstractVar`` only in an evaluated
# annotation (a string one is an ordinary field)
import abc
from typing import Any

import equinox as eqx
import jax

__all__ = ["AbstractObjective"]


class AbstractObjective(eqx.Module):
    """What a solver minimises (:func:`jaxobs_tuning.solvers.tune`): a value of the free gains' vector θ on a
    scenario batch, its gradient, and how many scenarios diverged or overflowed.

    The batch is an argument of every call, never held: one compiled program serves any batch of one shape
    (the tuning set, the held-out set), and the scenarios are inputs of that program, not constants baked
    into it.  :class:`Objective` is the one the jobs use; a user's own subclasses this (the solvers call only
    what it declares).

    Attributes:
        param: The :class:`~jaxobs_tuning.params.Parametrization` of the free gains (θ ↔ gains).
    """

    param: eqx.AbstractVar[Any]  # a jaxobs_tuning.params.Parametrization

    @abc.abstractmethod
    def value(self, theta: jax.Array, scenarios: Any) -> jax.Array:
        """The objective at ``theta``, differentiable in it (optimistix's minimisers trace it).

        Args:
            theta: The free gains' vector.
            scenarios: The batch (leading axis the scenarios); None for an objective without data.

        Returns:
            The scalar objective.
        """

    @abc.abstractmethod
    def value_grad_diverged_overflowed(self, theta: jax.Array, scenarios: Any) -> tuple[Any, Any, int, int]:
        """The objective, its gradient, and the scenarios that diverged and that overflowed (a finite simulation
        and value, a gradient that is not finite), from one batch evaluation.

        Args:
            theta: The free gains' vector.
            scenarios: The batch; None for an objective without data.

        Returns:
            ``(value, gradient, diverged count, overflowed count)``.
        """

    def plain_value(self, theta: jax.Array, scenarios: Any) -> jax.Array:
        """The objective at ``theta`` without its derivative, traceable: what a gradient-free minimiser
        (Nelder–Mead, :mod:`jaxobs_tuning.minimisers`) minimises.  :meth:`value` unless a subclass has a program
        without the derivative.

        Args:
            theta: The free gains' vector.
            scenarios: The batch; None for an objective without data.

        Returns:
            The scalar objective.
        """
        return self.value(theta, scenarios)

    def plain_value_diverged(self, theta: jax.Array, scenarios: Any) -> tuple[Any, int]:
        """:meth:`plain_value` and the scenarios that diverged, from one batch evaluation (a gradient-free
        solver's record of an iterate).  From :meth:`value_grad_diverged_overflowed` unless a subclass has a
        program without the derivative.

        Args:
            theta: The free gains' vector.
            scenarios: The batch; None for an objective without data.

        Returns:
            ``(value, diverged count)``.
        """
        value, _, diverged, _ = self.value_grad_diverged_overflowed(theta, scenarios)
        return value, diverged

    def value_grad_diverged(self, theta: jax.Array, scenarios: Any) -> tuple[Any, Any, int]:
        """:meth:`value_grad_diverged_overflowed` without the overflow count.

        Args:
            theta: The free gains' vector.
            scenarios: The batch.

        Returns:
            ``(value, gradient, diverged count)``.
        """
        return self.value_grad_diverged_overflowed(theta, scenarios)[:3]
