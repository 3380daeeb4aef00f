"""The figure helpers every plotting module shares: a pyplot-free Figure, and its layout and saving."""

from __future__ import annotations


def _subplots(*args, figsize, **kwargs):
    """``pyplot.subplots`` without pyplot: (figure, axes) on a plain Figure."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(*args, **kwargs)


def _finish(fig, path, dpi=110):
    """Lay out and save to ``path`` (if given); the figure is returned for notebooks."""
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=dpi)
    return fig
