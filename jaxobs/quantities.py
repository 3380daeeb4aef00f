"""The records that name what a study varies and what it measures: :class:`Axis` and :class:`Metric`.

Each axis a scenario family varies is one :class:`Axis` (its name, its CF units, the range it may take and
what it is in words), declared once, in the family's table (:data:`jaxobs.scenarios.GRID_SIGNAL_AXES`,
:data:`jaxobs.scenarios.EMF_SIGNAL_AXES`, :data:`jaxobs.drive.DRIVE_AXES`).  Each metric a study or a tuning
job reports is one :class:`Metric` (its name, CF units, long name, and its exact and smooth forms), declared
once, in :data:`jaxobs.families.METRICS`.  Units are UDUNITS strings, as CF readers parse them (``degree``,
``min-1`` for r/min, ``N m``); :func:`text_unit` spells one for a message or a figure's label.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["Axis", "Metric", "text_unit"]

# a CF unit -> its spelling in a message or a label ("degree" is "deg", "min-1" is "r/min")
_TEXT = {"degree": "deg", "min-1": "r/min", "N m": "N·m"}


def text_unit(units: str) -> str:
    """A unit as a message or a figure's label spells it.

    Args:
        units: A UDUNITS string.

    Returns:
        ``min-1`` -> ``r/min``, ``degree`` -> ``deg``, ``N m`` -> ``N·m``; any other unchanged.
    """
    return _TEXT.get(units, units)


@dataclass(frozen=True)
class Axis:
    """One axis of a scenario family.

    Attributes:
        name: The axis's name.
        units: Its CF units.
        range: The closed range (low, high) its values may take.
        long_name: What it is: the NetCDF coordinate's ``long_name``, a figure's label.
    """

    name: str
    units: str
    range: tuple[float, float]
    long_name: str

    @property
    def attrs(self) -> dict:
        """The CF attributes of its coordinate: ``units`` and ``long_name``."""
        return {"units": self.units, "long_name": self.long_name}

    def check(self, values, where: str = "axes", *, low: float | None = None, high: float | None = None):
        """``values`` as a float list, each finite and inside the range.

        Args:
            values: The values (a list of numbers).
            where: The name errors give the table.
            low: Narrows the range's low end.
            high: Narrows the range's high end.

        Returns:
            The values as a list of floats.

        Raises:
            ValueError: naming ``where`` and the allowed range, for an empty list or a value outside it.
        """
        lo = self.range[0] if low is None else low
        hi = self.range[1] if high is None else high
        vals = [float(v) for v in values]
        bad = [v for v in vals if not (math.isfinite(v) and lo <= v <= hi)]
        if not vals or bad:
            got = f", got {bad[0]:g}" if bad else ", got none"
            raise ValueError(f"{where}.{self.name} must be a non-empty list of numbers in {self.text(lo, hi)}{got}")
        return vals

    def text(self, low: float | None = None, high: float | None = None) -> str:
        """The range with its unit, as a message says it.

        Args:
            low: Narrows the range's low end.
            high: Narrows the range's high end.

        Returns:
            E.g. ``[1, 1e+05] r/min``; a dimensionless axis without a unit.
        """
        lo = self.range[0] if low is None else low
        hi = self.range[1] if high is None else high
        return f"[{lo:g}, {hi:g}]" + ("" if self.units == "1" else f" {text_unit(self.units)}")


@dataclass(frozen=True)
class Metric:
    """One metric and its forms, each a scalar of one run.

    Attributes:
        name: The metric's name.
        units: Its CF units.
        long_name: What it is.
        exact: ``exact(sol, scenario, ctx)``: what a study or a report gives.
        smooth: ``smooth(sol, scenario, ctx)``: what a gradient is taken of (the exact one where that has a
            useful gradient).
        closed_loop: It needs the closed-loop drive (a speed, a reference), not an observer on a signal.
        needs_truth: It needs an observer on a signal that reports its truth (a recording with its encoder:
            :class:`jaxobs.SignalTruth`).
    """

    name: str
    units: str
    long_name: str
    exact: Callable | None = None
    smooth: Callable | None = None
    closed_loop: bool = False
    needs_truth: bool = False

    def __call__(self, sol, scenario, ctx):
        """The form a gradient is taken of: ``smooth``, or ``exact`` where the metric has no smooth form.

        Raises:
            ValueError: the metric has neither form (it is not a function of one run).
        """
        form = self.smooth if self.smooth is not None else self.exact
        if form is None:
            raise ValueError(f"metric {self.name} is not a function of one run (it has no exact or smooth form)")
        return form(sol, scenario, ctx)
