"""The record that names what a study varies: :class:`Axis`, and the spelling of a unit.

Each axis a scenario family varies is one :class:`Axis` (its name, its CF units, the range it may take and
what it is in words), declared once, in the family's table (:data:`jaxobs.scenarios.GRID_SIGNAL_AXES`,
:data:`jaxobs.scenarios.EMF_SIGNAL_AXES`, :data:`jaxobs.drive.DRIVE_AXES`).  What a study measures is the
metric table's (:data:`jaxobs.metrics.METRICS`, one :class:`jaxobs.metrics.Metric` per quantity).  Units are
UDUNITS strings, as CF readers parse them (``degree``, ``min-1`` for r/min, ``N m``); :func:`text_unit` spells
one for a message or a figure's label.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

__all__ = ["Axis", "text_unit"]

# a CF unit -> its spelling in a message or a label ("degree" is "deg", "min-1" is "r/min")
_TEXT = {"degree": "deg", "min-1": "r/min", "N m": "N·m", "percent": "%"}


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

    def check(
        self, values: Iterable[float], where: str = "axes", *, low: float | None = None, high: float | None = None
    ) -> list[float]:
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
