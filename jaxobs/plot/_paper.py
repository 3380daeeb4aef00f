"""Figures in the papers' layout (``jaxobs.plot.paper_figure``): one column per method, the papers' (a), (b),
(c) ..., and in each column a stack of panels, each an estimated quantity drawn over its actual one or an
error, with its unit; every event marked and named.  The experiments' own modules (``jaxobs.reproduce``)
say what goes in the panels: this module only draws.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from ._figure import FigurePath, _finish, _mark_event, _subplots

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["Series", "Panel", "paper_figure"]


class Series(NamedTuple):
    """One trace of a panel: ``y`` over the figure's time axis.  ``actual``: the measured/true quantity, drawn
    black and dashed under the estimates, as the papers draw the encoder's angle or the grid's frequency."""

    label: str
    y: np.ndarray
    actual: bool = False


class Panel(NamedTuple):
    """A panel: its y label (quantity and unit, e.g. ``"θ̂e, θe (rad)"``) and its traces.  ``zero``: its
    y range includes 0 (an error's panel: a steady error then reads as its distance from zero, not as a
    flat line on a scale of its own rounding)."""

    ylabel: str
    series: tuple
    zero: bool = False


def _letter(i: int) -> str:
    return f"({chr(ord('a') + i)})"


def paper_figure(
    t: ArrayLike,
    columns: Sequence[tuple[str, Sequence[Panel]]],
    title: str,
    path: FigurePath = None,
    events: Sequence[tuple[float, str]] = (),
    t_unit: str = "s",
    shared: Sequence[int] = (),
) -> Figure:
    """Draw ``columns`` side by side over the time axis ``t``, in the papers' layout.

    Each column is headed "(a) name", "(b) name", ...; every column has the same panels, in order, and shares
    its x axis.  The rows not in ``shared`` scale to their own traces, as the papers' errors do (an error of
    0.03 rad on the scale of a lost integrator's ±π would read as zero).

    Args:
        t: The time axis, in ``t_unit``.
        columns: ``[(method name, [Panel, ...]), ...]``.
        title: The figure's title (wrapped to its width).
        path: Where to save the figure (None: not saved).
        events: ``[(time, what)]``: a dotted line in every panel, named in the top one.
        t_unit: The unit of ``t``.
        shared: The indices of the panel rows whose columns share one y scale (the methods' estimates
            compared at a glance).

    Returns:
        The figure.

    Raises:
        ValueError: The columns do not all have the same number of panels.
    """
    t = np.asarray(t)
    ncol = len(columns)
    nrow = max(len(panels) for _, panels in columns)
    if any(len(panels) != nrow for _, panels in columns):
        raise ValueError("paper_figure: every column must have the same panels")
    fig, axes = _subplots(
        nrow, ncol, figsize=(max(3.6 * ncol + 0.8, 6.5), 1.9 * nrow + 0.9), sharex=True, squeeze=False
    )
    for j, (name, panels) in enumerate(columns):
        for i, panel in enumerate(panels):
            ax = axes[i, j]
            for s in panel.series:
                y = np.asarray(s.y)
                if s.actual:
                    ax.plot(t, y, "k--", lw=0.9, label=s.label)
                else:
                    ax.plot(t, y, lw=0.9, label=s.label)
            ax.set_ylabel(panel.ylabel, fontsize=8)
            ax.tick_params(labelsize=7)
            ax.ticklabel_format(axis="y", useOffset=False, style="plain")
            ax.grid(True, alpha=0.3)
            if len(panel.series) > 1:
                ax.legend(fontsize=6, loc="lower right")
            if panel.zero:
                lo, hi = ax.get_ylim()
                lo, hi = min(lo, 0.0), max(hi, 0.0)
                pad = 0.08 * (hi - lo) if hi > lo else 1.0
                ax.set_ylim(lo - pad, hi + pad)
            for te, what in events:
                _mark_event(ax, te, what if i == 0 else "")
        axes[0, j].set_title(f"{_letter(j)} {name}", fontsize=9)
        axes[-1, j].set_xlabel(f"time ({t_unit})", fontsize=8)
    for i in shared:
        lows, highs = zip(*(axes[i, j].get_ylim() for j in range(ncol)), strict=True)
        for j in range(ncol):
            axes[i, j].set_ylim(min(lows), max(highs))
    # wrapped to the figure's width (about 12 characters an inch at 10 pt): a one-column figure's title ran off
    # both edges
    fig.suptitle(textwrap.fill(title, width=int(12 * fig.get_figwidth())), fontsize=10)
    return _finish(fig, path)
