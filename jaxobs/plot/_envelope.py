"""The envelope map: a drive observer's operating envelope over speed × load, one row per metric, one column per
design (:func:`envelope_figure`)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ._figure import FigurePath, _axis_words, _save

if TYPE_CHECKING:
    import xarray as xr
    from matplotlib.figure import Figure

__all__ = ["envelope_figure"]


# the envelope map's panels: variable -> (label, colour map, centred at 0, scale to the shown unit: the file is SI)
_ENVELOPE_PANELS = {
    "margin": ("stability margin (1/s; < 0: unstable)", "RdBu", True, 1.0),
    "peak_position_late": ("peak position error, late window (deg el.)", "viridis", False, 180.0 / math.pi),
    "mean_position_late": ("steady position bias (deg el.)", "PuOr", True, 180.0 / math.pi),
    "ripple_position_late": ("position-error ripple, rms (deg el.)", "viridis", False, 180.0 / math.pi),
}


def _log_edges(x):
    """Cell edges of centres ``x`` on a log axis (geometric midpoints; one centre: ±20 %)."""
    x = np.asarray(x, dtype=float)
    if x.size == 1:
        return np.array([x[0] / 1.2, x[0] * 1.2])
    mid = np.sqrt(x[1:] * x[:-1])
    return np.concatenate([[x[0] ** 2 / mid[0]], mid, [x[-1] ** 2 / mid[-1]]])


def _lin_edges(y):
    y = np.asarray(y, dtype=float)
    if y.size == 1:
        return np.array([y[0] - 0.5, y[0] + 0.5])
    mid = 0.5 * (y[1:] + y[:-1])
    return np.concatenate([[2 * y[0] - mid[0]], mid, [2 * y[-1] - mid[-1]]])


def _outline(ax, mask, xe, ye):
    """The boundary of the cells where ``mask`` (speed × load) is true, drawn along the cells' edges."""
    nx, ny = mask.shape
    for i in range(nx):
        for j in range(ny):
            if not mask[i, j]:
                continue
            if i == 0 or not mask[i - 1, j]:
                ax.plot([xe[i], xe[i]], [ye[j], ye[j + 1]], "k-", lw=1.8)
            if i == nx - 1 or not mask[i + 1, j]:
                ax.plot([xe[i + 1], xe[i + 1]], [ye[j], ye[j + 1]], "k-", lw=1.8)
            if j == 0 or not mask[i, j - 1]:
                ax.plot([xe[i], xe[i + 1]], [ye[j], ye[j]], "k-", lw=1.8)
            if j == ny - 1 or not mask[i, j + 1]:
                ax.plot([xe[i], xe[i + 1]], [ye[j + 1], ye[j + 1]], "k-", lw=1.8)


def _fail_marks(ds, d, extra, h):
    """Where design ``d`` fails (``h`` < 0.5, speed × load), split by the first reason, each with its marker:
    ((mask, "x") not synchronous, (mask, "o") synchronous but not resolved stable, (mask, "+") the rest: peak
    error over the bound).  With a mismatch dim a point fails a test if it fails it at any value."""

    def every(name):
        v = ds[name].sel(design=d).astype(bool)
        return np.asarray((v.all(extra) if extra else v).transpose("speed_rpm", "load_nm").values, dtype=bool)

    fails = h < 0.5
    unsync = fails & ~every("synchronous")
    unstable = fails & ~unsync & ~every("stable")
    return ((unsync, "x"), (unstable, "o"), (fails & ~unsync & ~unstable, "+"))


def envelope_figure(ds: xr.Dataset, path: FigurePath) -> Figure:
    """The envelope map (:func:`jaxobs.analysis.envelope.envelope`): one row per metric, one column per design,
    speed on a log axis against load; every row on ONE colour scale (shared by the designs), the region where
    each design holds outlined in black, and each point where it does not marked by why (x: not synchronous,
    o: not resolved stable, +: peak error over the bound).  With a mismatch dim each cell shows the worst over
    it (lowest margin, largest error, holds only where it holds at every value).  A point that lost lock has no
    steady error: its cells in the error panels are hatched grey, apart from every colour scale.  The marks,
    the outline and the hatching have a legend of their own under the panels, independent of the colour
    bars.

    Args:
        ds: The envelope's Dataset (:func:`jaxobs.analysis.envelope.envelope`).
        path: Where the figure is written (a file name or a binary file object); None: not written.

    Returns:
        The figure.
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch, Rectangle
    from matplotlib.patheffects import withStroke

    halo = [withStroke(linewidth=2.2, foreground="w")]  # a mark stays visible on the darkest cells

    designs = list(ds["design"].values)
    extra = [str(d) for d in ds["holds"].dims if d not in ("design", "speed_rpm", "load_nm")]
    worst = {"margin": "min", "peak_position_late": "max", "ripple_position_late": "max"}

    def reduce(name):
        v = ds[name]
        if name == "mean_position_late":  # the bias of largest magnitude, with its sign
            return v.isel({extra[0]: abs(v).fillna(-1.0).argmax(extra[0])}) if extra else v
        return getattr(v, worst.get(name, "min"))(extra) if extra else v

    sp, ld = ds["speed_rpm"].values, ds["load_nm"].values
    # speeds on a log axis; a map through both directions (a negative speed) on one cell per speed, labelled
    log_x = bool(np.all(sp > 0))
    xs = sp if log_x else np.arange(sp.size, dtype=float)
    xe, ye = (_log_edges(sp) if log_x else _lin_edges(xs)), _lin_edges(ld)
    # at most 8 tick labels an axis (every k-th grid value), so that 3 inches of panel stay legible
    xtick, ytick = slice(None, None, -(-sp.size // 8)), slice(None, None, -(-ld.size // 8))
    rows = list(_ENVELOPE_PANELS)
    from matplotlib.figure import Figure

    # constrained layout: the shared colour bars span a row (tight_layout cannot place them)
    fig = Figure(figsize=(3.0 * len(designs) + 1.6, 2.3 * len(rows) + 0.9), layout="constrained")
    axs = fig.subplots(len(rows), len(designs), squeeze=False)
    holds = reduce("holds") if not extra else ds["holds"].min(extra)
    for r, name in enumerate(rows):
        label, cmap, centred, scale = _ENVELOPE_PANELS[name]
        vals = scale * np.asarray(reduce(name).transpose("design", "speed_rpm", "load_nm").values, dtype=float)
        fin = vals[np.isfinite(vals)]
        if centred:
            lim = float(np.percentile(np.abs(fin), 95)) if fin.size else 1.0
            vmin, vmax = -max(lim, 1e-6), max(lim, 1e-6)
        else:
            vmin = 0.0
            vmax = max(float(np.percentile(fin, 95)) if fin.size else 1.0, 1e-6)
        mesh = None
        for c, d in enumerate(designs):
            ax = axs[r, c]
            # under the cells: a cell without a value (lost lock: no steady error) shows hatched grey, never a
            # colour of the scale (white is 0 on the centred ones)
            ax.add_patch(
                Rectangle((xe[0], ye[0]), xe[-1] - xe[0], ye[-1] - ye[0], facecolor="0.88", edgecolor="0.55",
                          hatch="///", lw=0, zorder=0)
            )  # fmt: skip
            mesh = ax.pcolormesh(xe, ye, vals[c].T, cmap=cmap, vmin=vmin, vmax=vmax, shading="flat", zorder=1)
            h = np.asarray(holds.sel(design=d).transpose("speed_rpm", "load_nm").values, dtype=float)
            _outline(ax, h >= 0.5, xe, ye)
            # each failing point marked by why it fails (the first reason of: not synchronous, not resolved
            # stable, error over the bound): a crossed point whose panels all look benign was a puzzle
            for mask, marker in _fail_marks(ds, d, extra, h):
                bad = np.argwhere(mask)
                ax.plot(xs[bad[:, 0]], ld[bad[:, 1]], marker, color="k", ms=4, mew=0.8, mfc="none", path_effects=halo)
            ax.set_xscale("log" if log_x else "linear")
            ax.set_xlim(xe[0], xe[-1])
            ax.set_ylim(ye[0], ye[-1])
            # ticks at the grid's own speeds and loads: each cell is centred on a point run, and its outer
            # edges (a negative load, a speed above rated) are only the cells' extent, not points run
            ax.set_xticks(xs[xtick], [f"{v:.0f}" if abs(v) >= 100 else f"{v:.3g}" for v in sp[xtick]], minor=False)
            ax.set_xticks([], minor=True)
            ax.set_yticks(ld[ytick], [f"{v:.3g}" for v in ld[ytick]])
            ax.tick_params(labelsize=7)
            if r == 0:
                n_h, n = int(h.sum()), h.size
                ax.set_title(f"{str(d).replace('_', ' ')}\nholds at {n_h}/{n} points", fontsize=9)
            if r == len(rows) - 1:
                ax.set_xlabel("speed (r/min, log)" if log_x else "speed (r/min, one cell each)", fontsize=8)
            if c == 0:
                ax.set_ylabel("load (N·m)", fontsize=8)
        # the scale is the 95th percentile (a lost point would swamp the rest): arrows mark values beyond it
        lo_x, hi_x = bool(fin.size and fin.min() < vmin), bool(fin.size and fin.max() > vmax)
        extend = {(True, True): "both", (True, False): "min", (False, True): "max"}.get((lo_x, hi_x), "neither")
        assert mesh is not None  # an envelope has at least one design
        cb = fig.colorbar(mesh, ax=list(axs[r]), shrink=0.95, pad=0.01, extend=extend)
        cb.set_label(label, fontsize=7)
        cb.ax.tick_params(labelsize=7)
    bound = ds.attrs.get("bound_deg", float("nan"))
    mark: dict[str, Any] = dict(color="k", ls="none", ms=5, mew=0.8, mfc="none")
    handles = [
        Line2D([], [], color="k", lw=1.8, label=f"outline: holds (stable, synchronous, peak error <= {bound:g} deg)"),
        Line2D([], [], marker="x", label="fails: not synchronous (lost lock, off speed or not settled)", **mark),
        Line2D([], [], marker="o", label="fails: not resolved stable", **mark),
        Line2D([], [], marker="+", label="fails: peak error over the bound", **mark),
        Patch(facecolor="0.88", edgecolor="0.55", hatch="///", lw=0, label="no value: lost lock (no steady error)"),
    ]
    fig.legend(handles=handles, loc="outside lower center", ncol=2, fontsize=7, frameon=False)
    title = "operating envelope, sensorless"
    if extra:
        title += f"; worst over {', '.join(_axis_words(ds, a, short=True) for a in extra)}"
    fig.suptitle(title, fontsize=9)
    _save(fig, path, 110)
    return fig
