"""The figure helpers every plotting module shares: a pyplot-free Figure, and its layout and saving."""

from __future__ import annotations

import os
import re
from typing import IO, TYPE_CHECKING, Any, TypeAlias

from ..io.files import atomic_path

if TYPE_CHECKING:
    import xarray as xr
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

# where a figure is written: a file name, a binary file object (written as it is), or None (not written)
FigurePath: TypeAlias = "str | os.PathLike[str] | IO[bytes] | None"


def _subplots(*args: Any, figsize: tuple[float, float], **kwargs: Any) -> tuple[Figure, Any]:
    """``pyplot.subplots`` without pyplot: (figure, axes) on a plain Figure."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(*args, **kwargs)


def _finish(fig: Figure, path: FigurePath, dpi: float = 110) -> Figure:
    """Lay out and save to ``path`` (if given); the figure is returned for notebooks."""
    fig.tight_layout()
    _save(fig, path, dpi)
    return fig


def _save(fig: Figure, path: FigurePath, dpi: float) -> None:
    """``fig`` to ``path`` (if given) through :class:`jaxobs.io.files.atomic_path`: a temp file renamed over it,
    never written through a link; a file object given as ``path`` is written as it is."""
    if path is None:
        return
    if not isinstance(path, (str, os.PathLike)):
        fig.savefig(path, dpi=dpi)
        return
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi)


def _mark_event(ax: Axes, t: float, text: str) -> None:
    """A dotted vertical line at ``t`` named ``text`` (rotated, at the top of ``ax``)."""
    from matplotlib.transforms import blended_transform_factory

    ax.axvline(t, color="0.3", lw=0.8, ls=":")
    if text:
        tr = blended_transform_factory(ax.transData, ax.transAxes)
        ax.text(
            t,
            0.97,
            text,
            transform=tr,
            rotation=90,
            ha="right",
            va="top",
            fontsize=8,
            color="0.15",
            bbox={"fc": "white", "ec": "none", "alpha": 0.85, "pad": 1.0},  # readable over a trace
        )


def _axis_words(ds: xr.Dataset, name: str, short: bool = False) -> str:
    """An axis in words: its ``long_name`` (the Axis record's, :mod:`jaxobs.core.quantities`), or its name where the
    Dataset has none; ``short``: without the closing parenthesis (a title lists several)."""
    words = str(ds[name].attrs.get("long_name") or name)
    return re.sub(r"\s*\([^()]*\)$", "", words) if short else words
