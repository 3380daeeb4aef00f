"""The base of the drive's step components: plant, sensors, inverter, controller.

Each is an immutable ``equinox.Module`` with the contract of every dynamic piece,
and one ``init`` convention:

    state = component.init(op)                 # op: the operating point it starts at (None: at rest)
    state, out = component.step(state, inp)    # inp: a NamedTuple of the component's inputs

``op`` is a :class:`~jaxobs.drive.OperatingPoint` (the true machine's steady state: speed, angle,
currents, voltages) or None for a machine at rest at θe = 0; an I-f start-up starts at
``OperatingPoint.at_rest(θe0)``.  What a component needs beyond the operating point is a keyword-only
extra of its own ``init``, documented there (the sensors' noise key, the I-f angle).  A component that
keeps no state (the inverter) returns None.  :class:`jaxobs.drive.ClosedLoop` starts every component this
way, from one operating point.
"""

from __future__ import annotations

import abc
from typing import Any

import equinox as eqx

__all__ = ["AbstractComponent"]


class AbstractComponent(eqx.Module):
    """A drive component: ``init(op=None, *, extras)`` and ``step(state, inp) -> (state, out)``."""

    @abc.abstractmethod
    def init(self, op: Any = None) -> Any:
        """The state at an operating point.

        Args:
            op: An ``OperatingPoint``; None: at rest at θe = 0.

        Returns:
            The component's state.
        """

    @abc.abstractmethod
    def step(self, state: Any, inp: Any) -> tuple[Any, Any]:
        """One control period.

        Args:
            state: The component's state.
            inp: Its input.

        Returns:
            ``(the next state, the outputs)``.
        """
