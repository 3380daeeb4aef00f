"""matplotlib figures (imported lazily: the library itself never needs a display).

Figures are made with :class:`matplotlib.figure.Figure`, not ``pyplot``: drawing one
neither selects a backend nor registers a window, so a script writes its files on a
machine without a display and a notebook keeps its own (inline) backend; a figure
returned with ``path=None`` displays in Jupyter as the value of a cell.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from jax.typing import ArrayLike

from .. import metrics, papers
from ..core.quantities import text_unit
from ..metrics import METRICS as _METRICS
from ._bode import bode_figure as bode_figure
from ._bode import paper_bode_figures as paper_bode_figures
from ._bode import resonance_grid as resonance_grid
from ._envelope import envelope_figure as envelope_figure
from ._figure import FigurePath, _axis_words, _finish, _mark_event, _save, _subplots
from ._paper import Panel as Panel
from ._paper import Series as Series
from ._paper import paper_figure as paper_figure

if TYPE_CHECKING:
    import xarray as xr
    from matplotlib.figure import Figure

    from ..drive import DriveOutput, DualOutput
    from ..runtime.simulation import Solution


class Trace(Protocol):
    """A run as the figures read it: :class:`jaxobs.Solution`, or a reproduction's kept run of the same fields."""

    @property
    def t(self) -> Any:
        """The sample times, s."""
        ...

    @property
    def outputs(self) -> Any:
        """The outputs, a PyTree with time leading."""
        ...


def fll_event_text(test: str) -> str:
    """What happens at the event of paper 001's Test ``test``, in words (papers.TESTS_001).

    Args:
        test: The test's letter (``"A"`` … ``"E"``).

    Returns:
        The event in words (``"event"`` for a test without one).
    """
    spec = papers.TESTS_001.get(test, {})
    words = {
        "freq_step": lambda v: f"frequency step {v:+g} Hz",
        "phase_jump_deg": lambda v: f"{v:+g}° jump",
        "sag": lambda v: f"sag {v:g} p.u.",
        "harmonics_scale": lambda v: "harmonics on",
        "dc": lambda v: f"dc {v:g} p.u. on",
        "sub_amplitude": lambda v: f"{v:g} p.u. subharmonic on",
    }
    return " + ".join(words[k](v) for k, v in spec.items() if k in words) or "event"


def drive_events(t: ArrayLike, out: DriveOutput | DualOutput, t_from: float = 0.0) -> list[tuple[float, str]]:
    """The events of a drive run, from its outputs: each load-torque change (applied, removed, stepped), each
    start of a speed-reference ramp or step (and its target), and the I-f start-up's hand-over to the observer.

    Args:
        t: The sample times, s.
        out: The run's stacked outputs (``load``, ``omega_m_ref``, ``mode``).
        t_from: Events before this time, s, are left out.

    Returns:
        ``[(time s, what)]``, in time order.
    """
    t = np.asarray(t)
    events = []
    load = np.asarray(out.load)
    tol = 1e-6 * max(1.0, float(np.nanmax(np.abs(load)))) if load.size else 1.0
    for k in np.flatnonzero(np.abs(np.diff(load)) > tol):
        a, b = float(load[k]), float(load[k + 1])
        what = "load removed" if abs(b) <= tol else "load applied" if abs(a) <= tol else "load step"
        events.append((t[k + 1], f"{what}: {a:.3g} → {b:.3g} N·m"))
    ref = np.asarray(out.omega_m_ref) * 30 / math.pi
    moving = np.abs(np.diff(ref)) > 1e-6 * max(1.0, float(np.nanmax(np.abs(ref))))
    starts = np.flatnonzero(moving & ~np.concatenate([[False], moving[:-1]]))
    for k in starts:
        end = k + 1
        while end < len(moving) and moving[end]:
            end += 1
        kind = "step" if end == k + 1 else "ramp"
        events.append((t[k + 1] if kind == "step" else t[k], f"speed ref. {kind} to {ref[end]:.4g} r/min"))
    mode = np.asarray(out.mode)  # a drive's outputs (DriveOutput, DualOutput) always have it
    for k in np.flatnonzero((mode[:-1] == 0) & (mode[1:] == 1)):
        events.append((t[k + 1], "I-f hand-over to the observer"))
    return sorted((float(te), w) for te, w in events if te >= t_from)


def fll_demo_figure(
    traces: Mapping[str, Solution], tests: Sequence[str], t_event: float, path: FigurePath = None
) -> Figure:
    """Frequency estimate and phase error of each FLL for each test (rows = tests).

    Args:
        traces: FLL name -> its :class:`~jaxobs.Solution` over the tests (one row per test,
            :func:`jaxobs.studies.demo.fll_demo`).
        tests: The tests' letters, in the rows' order.
        t_event: The events' time, s.
        path: Where the figure is written (a file name or a binary file object); None: not written.

    Returns:
        The figure.
    """
    fig, axes = _subplots(len(tests), 2, figsize=(11, 2.2 * len(tests)), sharex=False, squeeze=False)
    for name, sol in traces.items():
        t = np.asarray(sol.t)[0]
        f_hat = np.asarray(sol.outputs.obs.omega) / (2 * math.pi)
        err = np.degrees(np.asarray(metrics.wrap(sol.outputs.obs.theta - sol.outputs.truth.theta)))
        for i, test in enumerate(tests):
            span = 0.3 if test in ("A", "B") else 1.2
            m = (t >= t_event - 0.05) & (t <= t_event + span)
            axes[i, 0].plot(1e3 * (t[m] - t_event), f_hat[i][m], lw=1, label=name)
            axes[i, 1].plot(1e3 * (t[m] - t_event), err[i][m], lw=1, label=name)
    for i, test in enumerate(tests):
        axes[i, 0].set_ylabel(f"Test {test}\n$\\hat{{\\mathrm{{f}}}}$ (Hz)")  # mathtext: U+0302 drifts off the f
        axes[i, 1].set_ylabel("θ̂ − θ (deg)")
        what = fll_event_text(test)
        for ax in axes[i]:
            ax.grid(True, alpha=0.3)
            _mark_event(ax, 0.0, what)
    axes[-1, 0].set_xlabel("time after event (ms)")
    axes[-1, 1].set_xlabel("time after event (ms)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Paper 001 Tests A–E, Table I gains (simulated, 10 kHz, AB3)")
    return _finish(fig, path)


def flux_circles_figure(
    sol: Trace, names: Sequence[str], title: str, path: FigurePath = None, last: float = 0.1
) -> Figure:
    """Estimated rotor-flux circles (ψ̂β vs ψ̂α) of each observer over the last ``last`` seconds.

    Args:
        sol: A drive run with an observer bank (``outputs.obs.each``: one output per observer).
        names: The observers' names, in the bank's order.
        title: The figure's title.
        path: Where the figure is written (a file name or a binary file object); None: not written.
        last: The time drawn, s, up to the end of the run.

    Returns:
        The figure.
    """
    t = np.asarray(sol.t)
    m = t >= t[-1] - last
    fig, axes = _subplots(1, len(names), figsize=(3.2 * len(names), 3.4), squeeze=False)
    for ax, name, o in zip(axes[0], names, sol.outputs.obs.each):
        pa, pb = np.asarray(o.psi_a)[m], np.asarray(o.psi_b)[m]
        ax.plot(pa, pb, lw=0.8)
        ax.set_aspect("equal", adjustable="datalim")
        ax.axhline(0, color="k", lw=0.4)
        ax.axvline(0, color="k", lw=0.4)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("ψ̂α (Wb)")
        ax.grid(True, alpha=0.3)
    axes[0, 0].set_ylabel("ψ̂β (Wb)")
    fig.suptitle(title, fontsize=10)
    return _finish(fig, path)


def _clipped_range(peaks: dict, spans: dict | None = None, ratio: float = 3.0, lost: float = 30.0, swept=120.0):
    """The observers that have lost track and would flatten the others, left out of the y-range (at least one
    observer stays in): each whose error sweeps ``swept`` degrees or more peak to peak (``spans``, deg: a pure
    integrator's circle through the origin saws ±90°, whatever the others' errors, as the LPF's 38° lead beside
    it in 000's speed ramp, which stays in range: it has not lost track); where none sweeps, from the largest
    peak |error| (deg) down, each peak above ``lost`` degrees and more than ``ratio`` times the next one.
    Returns (clipped names, the largest peak kept)."""
    order = sorted(peaks, key=lambda n: peaks[n], reverse=True)
    clipped = [n for n in order[:-1] if spans is not None and spans[n] >= swept]
    if not clipped:
        for hi, lo in zip(order, order[1:]):
            if not (peaks[hi] > lost and peaks[hi] > ratio * peaks[lo]):
                break
            clipped.append(hi)
    return clipped, max(peaks[n] for n in order if n not in clipped)


def position_error_figure(
    sol: Solution, names: Sequence[str], title: str, path: FigurePath = None, t_from: float = 0.0
) -> Figure:
    """Wrapped position error θ̂e − θe (deg) of each observer, with the speed on a second axis.

    The y-range shows the observers compared: an observer that has lost track (a pure integrator's
    drift sweeps ±180°), its error dwarfing the others', is drawn clipped, its peak given in the legend.

    Args:
        sol: A drive run with an observer bank (``outputs.obs.each``: one output per observer).
        names: The observers' names, in the bank's order.
        title: The figure's title.
        path: Where the figure is written (a file name or a binary file object); None: not written.
        t_from: The first time drawn, s; the run's events from then on are marked.

    Returns:
        The figure.
    """
    t = np.asarray(sol.t)
    m = t >= t_from
    fig, (ax_s, ax_e) = _subplots(2, 1, figsize=(9, 5.5), sharex=True)
    ax_s.plot(t[m], np.asarray(sol.outputs.speed_rpm)[m], label="speed", lw=1)
    ax_s.plot(t[m], np.asarray(sol.outputs.omega_m_ref)[m] * 30 / math.pi, "k--", lw=0.8, label="reference")
    ax_s.set_ylabel("speed (r/min)")
    ax_s.ticklabel_format(axis="y", useOffset=False, style="plain")
    speeds = np.concatenate(
        [np.asarray(sol.outputs.speed_rpm)[m], np.asarray(sol.outputs.omega_m_ref)[m] * 30 / math.pi]
    )
    if speeds.size and np.isfinite(speeds).all():  # at least ±5 r/min: a steady speed reads as flat, not as noise
        mid, half = 0.5 * (speeds.max() + speeds.min()), 0.5 * (speeds.max() - speeds.min())
        half = max(1.1 * half, 5.0)
        ax_s.set_ylim(mid - half, mid + half)
    ax_s.legend(fontsize=8)
    errs = {
        name: np.degrees(np.asarray(metrics.wrap(o.theta - sol.outputs.theta_e))[m])
        for name, o in zip(names, sol.outputs.obs.each)
    }
    peaks = {n: float(np.nanmax(np.abs(e))) if e.size and np.isfinite(e).any() else 0.0 for n, e in errs.items()}
    spans = {n: float(np.ptp(e[np.isfinite(e)])) if np.isfinite(e).any() else 0.0 for n, e in errs.items()}
    clipped, top = _clipped_range(peaks, spans) if len(peaks) > 1 else ([], max(peaks.values(), default=1.0))
    for name, err in errs.items():
        if name in clipped:  # drawn faint and behind: its sawtooth would still cross the others' range
            label = f"{name} (clipped: peaks ±{peaks[name]:.0f}°)"
            ax_e.plot(t[m], err, lw=0.5, alpha=0.35, zorder=1, label=label)
        else:
            ax_e.plot(t[m], err, lw=0.8, zorder=2, label=name)
    lim = min(1.15 * top, 185.0) if top > 0 else 1.0
    ax_e.set_ylim(-lim, lim)
    ax_e.set_ylabel("θ̂e − θe (deg)")
    ax_e.set_xlabel("time (s)")
    ax_e.legend(fontsize=8, ncol=2)
    for ax in (ax_s, ax_e):
        ax.grid(True, alpha=0.3)
    for te, what in drive_events(t, sol.outputs, t_from):  # every event marked, named above
        _mark_event(ax_s, te, what)
        _mark_event(ax_e, te, "")
    fig.suptitle(title, fontsize=10)
    return _finish(fig, path)


# plotted metrics: (scale to the shown unit, shown unit, short name); a Dataset's own attrs name the rest
_STUDY_PLOT = {
    "settling_freq": (1.0, "s", "settling time"),
    "ripple_freq": (1.0, "Hz p-p", "steady frequency ripple"),
    "rms_phase_steady": (180.0 / math.pi, "deg", "steady rms phase error"),
}
# axes' units when the Dataset has none (a study written before the units were added)
_AXIS_UNITS = {
    "freq_step": "Hz",
    "phase_jump_deg": "deg",
    "sag": "p.u.",
    "dc": "p.u.",
    "harmonics_scale": "× Test C",
    "sub_amplitude": "p.u.",
    "phase_deg": "deg",
    "noise": "p.u.",
}


def _axis_label(ds, name: str) -> str:
    """An axis's label: its long name and its unit (none for a dimensionless one, whose long name says p.u.)."""
    units = ds[name].attrs.get("units")
    unit = text_unit(units) if units else _AXIS_UNITS.get(name, "")
    words = _axis_words(ds, name)
    return f"{words} ({unit})" if unit and unit != "1" else words


def _shared_norm(vals):
    """One colour scale for every panel of a comparison: log where the positive values span more than a
    decade (designs that differ by decades stay apart), else linear; (norm, is_log)."""
    from matplotlib.colors import LogNorm, Normalize

    v = np.asarray(vals, dtype=float)
    v = v[np.isfinite(v)]
    if not v.size:
        return Normalize(0.0, 1.0), False
    lo, hi = float(v.min()), float(v.max())
    if lo > 0 and hi / lo > 10.0:
        return LogNorm(lo, hi), True
    return Normalize(lo, hi if hi > lo else lo + 1.0), False


def _log_ticks(lo: float, hi: float) -> list:
    """Labelled values of a log colour bar over [lo, hi] (> 0): 1-2-5 per decade (1 per decade beyond three
    decades), and each end itself, rounded inwards to two digits, where no tick lies within 0.1 decade of
    it.  Matplotlib's own labelled only whole decades (and, with minor labels, 0.07 0.08 0.09 0.1 crowded at
    one end): a bar from 0.013 to 0.09 had no label at all below its top."""
    subs = (1, 2, 5) if math.log10(hi / lo) <= 3 else (1,)
    ticks = [
        m * 10.0**k
        for k in range(math.floor(math.log10(lo)), math.ceil(math.log10(hi)) + 1)
        for m in subs
        if lo <= m * 10.0**k <= hi
    ]
    for end, rnd in ((lo, math.ceil), (hi, math.floor)):
        if not ticks or min(abs(math.log10(end / v)) for v in ticks) > 0.1:
            step = 10.0 ** (math.floor(math.log10(end)) - 1)
            ticks.append(float(f"{rnd(end / step) * step:.2g}"))
    return sorted(ticks)


def _study_heatmap(ds, da, unit, short, axes, designs):
    a0, a1 = axes[0], axes[1]
    others = [d for d in axes if d not in (a0, a1)]
    rows = [("mean", da.mean(dim=others) if others else da)]
    if others:  # the worst case over the hidden axes beside the mean
        rows.append(("worst (max)", da.max(dim=others)))
    norm, is_log = _shared_norm(np.concatenate([np.asarray(r).ravel() for _, r in rows]))
    nx, ny = len(ds[a0]), len(ds[a1])
    w = max(3.6, 0.55 * nx + 1.0)  # room for a value in each cell at 9 pt
    fig, axs = _subplots(
        len(rows),
        len(designs),
        figsize=(w * len(designs) + 1.4, 0.42 * ny * len(rows) + 1.6 * len(rows) + 0.6),
        squeeze=False,
    )
    im = None
    for r, (how, red) in enumerate(rows):
        for c, d in enumerate(designs):
            ax = axs[r, c]
            arr = np.asarray(red.sel(design=d).transpose(a1, a0), dtype=float)
            im = ax.imshow(arr, origin="lower", aspect="auto", norm=norm, cmap="viridis")
            for (j, i), v in np.ndenumerate(arr):  # the value itself: colours alone hide 0.15 vs 0.115
                if np.isfinite(v):
                    light = norm(v) < 0.55  # white on the dark end of viridis
                    ax.text(i, j, f"{v:.2g}", ha="center", va="center", fontsize=9, color="w" if light else "k")
            ax.set_xticks(range(nx), [f"{v:g}" for v in ds[a0].values], fontsize=9)
            ax.set_yticks(range(ny), [f"{v:g}" for v in ds[a1].values], fontsize=9)
            if r == len(rows) - 1:
                ax.set_xlabel(_axis_label(ds, a0), fontsize=10)
            if c == 0:  # the axis alone: the row (mean, worst) is each panel's title
                ax.set_ylabel(_axis_label(ds, a1), fontsize=10, wrap=True)
            ax.set_title(f"{d}: {how}", fontsize=10)
    left = min(0.2, 1.0 / fig.get_figwidth())  # 1 in for the axis's label and its ticks
    fig.subplots_adjust(left=left, right=0.88, top=0.84, bottom=0.12, wspace=0.22, hspace=0.4)
    cax = fig.add_axes((0.9, 0.12, 0.012, 0.74))  # beside the panels, never over one
    assert im is not None  # a study has at least one design
    cb = fig.colorbar(im, cax=cax, label=f"{short} ({unit})" + (", log scale" if is_log else ""))
    if is_log:  # plain numbers (0.2, 0.5, 1), not 2×10⁻¹, on 1-2-5 ticks and both ends (_log_ticks)
        from matplotlib.ticker import FixedLocator, FormatStrFormatter, NullFormatter

        lo, hi = norm.vmin, norm.vmax
        assert lo is not None and hi is not None  # a LogNorm made from the values' range
        cb.ax.yaxis.set_major_locator(FixedLocator(_log_ticks(lo, hi)))
        cb.ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        cb.ax.yaxis.set_minor_formatter(NullFormatter())
    cb.ax.tick_params(which="both", labelsize=9)
    cb.ax.yaxis.label.set_fontsize(10)
    over = ", ".join(_axis_words(ds, a, short=True) for a in others)
    how = f"mean and worst case over the {over}" if others else "every scenario"
    fig.suptitle(f"{short} ({unit}): {how}\none colour scale for every panel", fontsize=11)
    return fig


def study_figures(ds: xr.Dataset, out_dir: str | os.PathLike[str]) -> list[Path]:
    """Heat-maps and distributions per metric, written as PNG files.

    Heat-maps (a grid of at least two axes): the first two axes, one column per design; the top row is the
    mean over the other axes and, when there are others, the bottom row their worst case (the max), so a
    bad corner the mean hides shows.  One colour scale per metric shared by every panel (log where the
    values span more than a decade), one labelled colour bar, each cell's value written in it; labels
    ≥ 9 pt.  The rms phase error is shown in degrees.  Histograms: one set of bins per metric; settling
    times that are censored at the horizon (``settled`` False) are counted in the legend.

    Args:
        ds: An FLL study's Dataset (:func:`jaxobs.studies.study.run_study`).
        out_dir: The folder the files are written to (``heatmap_<metric>.png``, ``distribution_<metric>.png``).

    Returns:
        The paths written.
    """
    out = Path(out_dir)
    paths = []
    axes = [d for d in ds[next(iter(_STUDY_PLOT))].dims if d != "design"]
    designs = list(ds["design"].values)
    for metric, (scale, unit, short) in _STUDY_PLOT.items():
        da = ds[metric] * scale
        finite = np.asarray(da)[np.isfinite(np.asarray(da))]
        if len(axes) >= 2 and "sample" not in axes:
            p = out / f"heatmap_{metric}.png"
            _save(_study_heatmap(ds, da, unit, short, axes, designs), p, 100)  # no tight_layout: the bar
            paths.append(p)
        fig, ax = _subplots(figsize=(6, 3.4))
        bins = np.histogram_bin_edges(finite, bins=30) if finite.size else 30
        for d in designs:
            vals = np.asarray(da.sel(design=d)).ravel()
            vals = vals[np.isfinite(vals)]
            label = str(d)
            if metric == "settling_freq" and "settled" in ds:
                unsettled = int((~np.asarray(ds["settled"].sel(design=d), dtype=bool)).sum())
                label += f" ({unsettled} not settled: counted at the horizon)" if unsettled else ""
            ax.hist(vals, bins=bins, histtype="step", lw=1.6, label=label)  # outlines: no mixed colours
        ax.set_xlabel(f"{short} ({unit})")
        ax.set_ylabel("scenarios")
        ax.set_title(f"{short} over {int(ds.attrs.get('scenarios', finite.size))} scenarios per design", fontsize=10)
        ax.tick_params(labelsize=9)
        ax.legend(fontsize=9)
        p = out / f"distribution_{metric}.png"
        _finish(fig, p, dpi=100)
        paths.append(p)
    return paths


# the drive study's axes and metrics in words (with their units) for the figures' labels
_DRIVE_AXIS_LABELS = {
    "speed_rpm": "speed (r/min)",
    "load_nm": "load torque (N·m)",
    "speed_step_rpm": "speed-reference step (r/min)",
    "load_step_nm": "load step (N·m)",
    "dRs": "error of assumed Rs (R̂s/Rs − 1)",
    "dLd": "error of assumed Ld (L̂d/Ld − 1)",
    "dLq": "error of assumed Lq (L̂q/Lq − 1)",
    "dpsi": "error of assumed PM flux (ψ̂/ψ − 1)",
    "dJ": "inertia change (J/J_nominal − 1)",
    "i_noise": "current noise, std (A)",
    "u_noise": "voltage noise, std (V)",
    "dead_time": "dead time (µs)",
}
_DRIVE_AXIS_SCALE = {"dead_time": 1e6}
# in their display units (jaxobs.metrics.Metric.shown: the study stores SI)
_DRIVE_METRIC_LABELS = {
    "rms_position_steady": "rms position error (deg el.)",
    "peak_position_steady": "peak position error (deg el.)",
    "rms_speed_estimate_steady": "rms speed-estimate error (r/min)",
    "speed_noise": "speed-estimate noise (r/min)",
    "bias_position": "steady position lag |mean| (deg el.)",
    "peak_speed_deviation": "peak speed deviation after the event (r/min)",
}


def _drive_axis_label(ds, name: str) -> str:
    if name in _DRIVE_AXIS_LABELS:
        return _DRIVE_AXIS_LABELS[name]
    unit = ds[name].attrs.get("units", "")
    return f"{name} ({unit})" if unit and unit != "1" else name


def _vs_axis(ds, metric: str, design, axis: str, bins: int = 8):
    """(x, median, 95 % quantile) of ``metric`` of one design against one swept axis, over every other
    axis (a grid) or in bins of equal count of the axis's values (a sample); lost-lock scenarios (NaN) left out."""
    da = ds[metric].sel(design=design)
    if "sample" not in ds.dims:
        other = [d for d in da.dims if d != axis]
        flat = np.asarray(da.transpose(axis, *other)).reshape(da.sizes[axis], -1)
        x = np.asarray(ds[axis].values, dtype=float)
    else:
        xs, vs = np.asarray(ds[axis].values, dtype=float), np.asarray(da.values, dtype=float)
        edges = np.unique(np.quantile(xs, np.linspace(0, 1, bins + 1)))
        idx = np.clip(np.searchsorted(edges, xs, side="right") - 1, 0, max(len(edges) - 2, 0))
        groups = [vs[idx == i] for i in range(max(len(edges) - 1, 1))]
        x = np.asarray([xs[idx == i].mean() if (idx == i).any() else np.nan for i in range(len(groups))])
        width = max(len(g) for g in groups)
        flat = np.full((len(groups), width), np.nan)
        for i, g in enumerate(groups):
            flat[i, : len(g)] = g
    with np.errstate(all="ignore"):
        ok = np.isfinite(flat).any(axis=1)
        med, q95 = np.full(len(x), np.nan), np.full(len(x), np.nan)
        med[ok] = np.nanquantile(flat[ok], 0.5, axis=1)
        q95[ok] = np.nanquantile(flat[ok], 0.95, axis=1)
    return x, med, q95


def drive_study_figure(ds: xr.Dataset, path: FigurePath) -> Figure:
    """The drive study on one page, one row per metric (one y-scale per row, shared by every design):
    the empirical CDF over the scenarios (lost-lock counts in the legend), then the metric's median (solid)
    and 95 % quantile (dashed) against each swept axis, over the other axes (a grid) or in bins of the
    axis (a Sobol/LHS sample).  Axes and metrics are labelled in words with their units.

    Args:
        ds: A drive study's Dataset (:func:`jaxobs.studies.study.run_study` on a ``DriveScenarios`` family, with
            quantiles).
        path: Where the figure is written (a file name or a binary file object); None: not written.

    Returns:
        The figure.
    """
    names = [str(v) for v in ds.data_vars]
    metrics = [v[: -len("_q")] for v in names if v.endswith("_q")]  # the metrics with quantiles
    ds = ds.assign({m: _METRICS[m].shown(ds[m]) for m in metrics if m in _METRICS})  # SI -> display units
    axes = [str(k) for k in ds[metrics[0]].dims if k not in ("design", "sample")]
    if "sample" in ds.dims:
        axes = [str(k) for k in ds.coords if ds[k].dims == ("sample",) and k != "sample"]
    designs = list(ds["design"].values)
    colors = {d: f"C{i}" for i, d in enumerate(designs)}
    ncol = 1 + len(axes)
    fig, axs = _subplots(len(metrics), ncol, figsize=(3.3 * ncol + 0.5, 2.5 * len(metrics) + 0.8), squeeze=False)
    for r, m in enumerate(metrics):
        label = _DRIVE_METRIC_LABELS.get(m, f"{m} ({ds[m].attrs.get('units', '')})")
        vals = np.asarray(ds[m].values, dtype=float)
        pos = vals[np.isfinite(vals) & (vals > 0)]
        logy = pos.size > 0 and pos.max() / max(pos.min(), 1e-300) > 30  # designs that differ by decades
        ax = axs[r, 0]
        for d in designs:
            v = np.sort(np.asarray(ds[m].sel(design=d)).ravel())
            v = v[np.isfinite(v)]
            lost = int(ds["lost_lock_count"].sel(design=d))
            if v.size:
                frac = np.arange(1, v.size + 1) / v.size
                ax.step(v, frac, where="post", color=colors[d], label=f"{d} (lost: {lost})")
        if logy:
            ax.set_xscale("log")
        ax.set_xlabel(label, fontsize=8)
        ax.set_ylabel("fraction of scenarios", fontsize=8)
        ax.grid(True, alpha=0.3)
        if r == 0:
            ax.legend(fontsize=6)
        for c, a in enumerate(axes, start=1):
            ax = axs[r, c]
            scale = _DRIVE_AXIS_SCALE.get(a, 1.0)
            for d in designs:
                x, med, q95 = _vs_axis(ds, m, d, a)
                ax.plot(x * scale, med, "o-", color=colors[d], ms=3, lw=1.2, label=f"{d} median")
                ax.plot(x * scale, q95, "s--", color=colors[d], ms=2.5, lw=0.9, label=f"{d} 95 %")
            if logy:
                ax.set_yscale("log")
            ax.set_xlabel(_drive_axis_label(ds, a), fontsize=8)
            ax.set_ylabel(label if c == 1 else "", fontsize=8)
            ax.grid(True, alpha=0.3)
            ax.tick_params(labelsize=7)
        if len(axes) > 1:  # one y-scale per metric across the axes' panels
            lo = min(axs[r, c].get_ylim()[0] for c in range(1, ncol))
            hi = max(axs[r, c].get_ylim()[1] for c in range(1, ncol))
            for c in range(1, ncol):
                axs[r, c].set_ylim(lo, hi)
        axs[r, 0].tick_params(labelsize=7)
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=colors[d], lw=2, label=str(d)) for d in designs]
    handles += [
        Line2D([], [], color="k", ls="-", marker="o", ms=3, label="median"),
        Line2D([], [], color="k", ls="--", marker="s", ms=3, label="95 % quantile"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8, frameon=False)
    how = "the other axes" if "sample" not in ds.dims else f"bins of the axis ({ds.attrs.get('sampling', 'sample')})"
    fig.suptitle(
        f"drive study: {int(ds.attrs['scenarios'])} scenarios per design, sensorless; left: distribution over the "
        f"scenarios; right: median and 95 % quantile over {how}",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, 0.035, 1, 1))
    _save(fig, path, 90)
    return fig
