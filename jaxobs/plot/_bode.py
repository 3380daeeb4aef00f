"""Bode figures (:mod:`jaxobs.plot` re-exports them): a grid refined at lightly damped poles, one line
style per trace, frequency in Hz (or rad/s), and the papers' three Bode figures."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from .. import linear, papers
from ._figure import FigurePath, _finish, _mark_event, _subplots

if TYPE_CHECKING:
    from matplotlib.figure import Figure

# one look per trace, so a trace never hides under another: widths fall as the dashes rise, and markers
# (spaced along the curve, matplotlib's float markevery) tell overlapping curves apart
_TRACE_STYLES = (
    {"ls": "-", "lw": 2.6},
    {"ls": "--", "lw": 1.7, "marker": "o", "ms": 4, "markevery": 0.07},
    {"ls": "-.", "lw": 1.5, "marker": "s", "ms": 3.5, "markevery": (0.035, 0.07)},
    {"ls": ":", "lw": 1.8, "marker": "^", "ms": 4, "markevery": (0.02, 0.07)},
)


def resonance_grid(
    tfs: dict[str, linear.TransferFunction] | Sequence[linear.TransferFunction],
    omega: ArrayLike,
    n: int = 241,
    damping_ratio: float = 0.3,
) -> np.ndarray:
    """``omega`` (rad/s) refined around every lightly damped pole of ``tfs`` (a dict or a list of
    :class:`~jaxobs.linear.TransferFunction`), sorted and unique.

    A pole σ + jω_p with |σ| < ``damping_ratio``·|ω_p| makes a peak (or a notch, with a zero beside it)
    about |σ| rad/s wide at ω = ω_p (the sign matters for a complex-coefficient filter, whose response is
    not symmetric).  The GI-LESO's at ±50 Hz (σ ≈ −8.8 rad/s) swings ±1.1 dB within a few rad/s: a log grid
    spaced ~1 % in ω draws it within 0.04 dB but only just; around each such pole ``n`` points
    ω_p + |σ|·sinh(u), u uniform in [−8, 8] (steps of |σ|/15 at the peak, out to ~1500 |σ|), draw its
    shape to 0.005 dB (tests/test_figures.py), kept inside the range of ``omega`` and on its side of zero.

    Args:
        tfs: The transfer functions, name -> transfer function or a sequence of them.
        omega: The grid to refine, rad/s.
        n: The points added around each lightly damped pole.
        damping_ratio: A pole σ + jω_p is lightly damped where |σ| < ``damping_ratio``·|ω_p|.

    Returns:
        The refined grid, rad/s (sorted, unique).
    """
    omega = np.asarray(omega, dtype=float)
    lo, hi = float(omega.min()), float(omega.max())
    u = np.sinh(np.linspace(-8.0, 8.0, n))
    extra = [omega]
    for tf in tfs.values() if isinstance(tfs, dict) else tfs:
        for pk in np.atleast_1d(np.asarray(tf.poles())):
            sigma, wp = abs(float(pk.real)), float(pk.imag)
            if not (0 < sigma < damping_ratio * abs(wp)):
                continue
            w = wp + sigma * u
            w = w[(w >= lo) & (w <= hi) & (np.sign(w) == np.sign(wp))]
            extra.append(w)
    return np.unique(np.concatenate(extra))


def bode_figure(
    tfs: dict[str, linear.TransferFunction],
    omega: ArrayLike,
    title: str,
    path: FigurePath = None,
    hz: bool = True,
    mark: float | None = None,
    refine: bool = True,
    mark_text: str = "",
) -> Figure:
    """Bode magnitude (dB) and phase (deg) of several transfer functions on one grid.

    The frequency axis is in Hz (``hz=False``: rad/s); ``omega`` is in rad/s either way, refined around
    lightly damped poles (:func:`resonance_grid`; ``refine=False`` keeps it as given).  Each trace has its
    own line style and markers, so one lying on another stays visible.  Complex-coefficient filters are
    plotted over negative and positive frequency when ``omega`` contains both signs (their response is
    not conjugate-symmetric).  ``mark`` (rad/s) draws a dotted line there, named ``mark_text`` on the magnitude.

    Args:
        tfs: The transfer functions, trace name -> transfer function.
        omega: The frequency grid, rad/s.
        title: The figure's title.
        path: Where to save the figure (None: not saved).
        hz: Frequency axis in Hz (else rad/s).
        mark: A frequency to mark with a dotted line, rad/s, or None.
        refine: Whether to refine ``omega`` around lightly damped poles.
        mark_text: The name of the marked frequency.

    Returns:
        The figure.
    """
    omega = resonance_grid(tfs, omega) if refine else np.asarray(omega)
    x = omega / (2 * math.pi) if hz else omega
    fig, (ax_m, ax_p) = _subplots(2, 1, figsize=(7.5, 6), sharex=True)
    for i, (name, tf) in enumerate(tfs.items()):
        mag, ph = linear.bode(tf, omega)[:2]
        style = _TRACE_STYLES[i % len(_TRACE_STYLES)]
        ax_m.plot(x, np.asarray(mag), label=name, color=f"C{i}", **style)
        ax_p.plot(x, np.asarray(ph), label=name, color=f"C{i}", **style)
    if np.all(omega > 0):
        ax_m.set_xscale("log")
    if mark is not None:  # named: a reader should not have to guess what the dotted line is
        _mark_event(ax_m, mark / (2 * math.pi) if hz else mark, mark_text)
        _mark_event(ax_p, mark / (2 * math.pi) if hz else mark, "")
    ax_m.set_ylabel("magnitude (dB)")
    ax_p.set_ylabel("phase (deg)")
    ax_p.set_xlabel("frequency (Hz)" if hz else "ω (rad/s)")
    for ax in (ax_m, ax_p):
        ax.grid(True, which="both", alpha=0.3)
    ax_m.legend(fontsize=9)
    ax_m.set_title(title)
    return _finish(fig, path)


def _freq(w: float, hz: bool) -> str:
    """``w`` (rad/s) as the axis shows it: Hz, or rad/s."""
    return f"{w / (2 * math.pi):.3g} Hz" if hz else f"{w:.4g} rad/s"


def _two_sided_ticks(ax, linthresh: float, x_max: float) -> None:
    """A symlog frequency axis labelled every other decade, as plain numbers (−1000, −10, −0.1, 0, 0.1, ...),
    the decades between as unlabelled minor ticks: a label at every decade of both signs (−10³ … 10³ and
    −10⁰ written out) ran into its neighbours."""
    from matplotlib.ticker import FixedLocator, FuncFormatter

    top = int(math.floor(math.log10(x_max)))
    low = int(math.ceil(math.log10(linthresh))) + 1  # the first decade clear of the linear part
    labelled = list(range(top, low - 1, -2))
    minor = [10.0**k for k in range(low, top + 1) if k not in labelled]
    major = sorted([0.0] + [sg * 10.0**k for k in labelled for sg in (-1.0, 1.0)])
    ax.xaxis.set_major_locator(FixedLocator(major))
    ax.xaxis.set_minor_locator(FixedLocator(sorted(minor + [-m for m in minor])))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}".replace("-", "−")))


def paper_bode_figures(out_dir: str | os.PathLike[str], hz: bool = True) -> list[Path]:
    """The three Bode figures of the papers: 000 Fig. 5, 002 Fig. 4, 001 Fig. 14.

    Args:
        out_dir: The folder the PNG files are written to (created if missing).
        hz: Frequency axis in Hz (else rad/s).

    Returns:
        The paths of the three files.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    # 000 Fig. 5: ω' = 100π, ωc = 100, k = 1.414, K1 = 1.56, K2 = 3.11
    w1 = papers.FLUX_FIG5_OMEGA
    k, K1, K2 = papers.SOIFO_K, papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2
    flux = {
        "pure integrator": linear.integrator_flux_tf(),
        f"LPF (ωc = {papers.LPF_OMEGA_C:g} rad/s)": linear.lpf_flux_tf(papers.LPF_OMEGA_C),
        f"SOIFO (k = {k:g})": linear.soifo_tf(k, w1),
        f"second-order SOIFO (K1 = {K1:g}, K2 = {K2:g})": linear.sosoifo_tf(K1, K2, w1),
    }
    p = out / "bode_flux_observers_000_fig5.png"
    title = "Paper 000 Fig. 5: flux observers ψ̂/e"
    bode_figure(flux, np.logspace(0, 5, 2000), title, p, hz=hz, mark=w1, mark_text=f"ω' = {_freq(w1, hz)}")
    paths.append(p)
    # 002 Fig. 4 / Table II (two-sided, the FA-LESO is complex)
    we = papers.LESO_TABLE_II_OMEGA_E
    leso = {
        "C-LESO (ω0 = 500π)": linear.cleso_tf(papers.LESO_OMEGA0),
        "GI-LESO (Kr = 2ω0², ωc = π)": linear.gileso_tf(
            papers.LESO_OMEGA0, papers.GILESO_K_R, papers.GILESO_OMEGA_C, we
        ),
        "FA-LESO (k1 = 10π, k2 = 100π)": linear.faleso_tf(papers.FALESO_K1, papers.FALESO_K2, we),
    }
    # down to 1e-3 rad/s: the FA-LESO has a pole-zero pair near dc (zero at −k1/k2 = −0.1 rad/s, a pole
    # at ≈ −k1/(k2 − jω̂e)), a real 3 dB step within ±0.02 Hz that a grid starting at 1 rad/s drew as a
    # glitch at 0 Hz; the symlog axis's linear part (±1 mHz, ±0.01 rad/s) is narrower than that step
    wpos = np.logspace(-3, 4.5, 1800)
    omega = np.concatenate([-wpos[::-1], wpos])
    p = out / "bode_lesos_002_fig4.png"
    title = "Paper 002 Fig. 4: LESOs ê/e at ω̂e = 100π (two-sided)"
    fig = bode_figure(leso, omega, title, None, hz=hz, mark=we, mark_text=f"ω̂e = {_freq(we, hz)}")
    lin = 1e-3 if hz else 1e-2
    x_max = float(np.max(omega)) / (2 * math.pi) if hz else float(np.max(omega))
    for ax in fig.axes:
        ax.set_xscale("symlog", linthresh=lin)
        _two_sided_ticks(ax, lin, x_max)
    # a zoom on +50 Hz: the GI-LESO's ±1 dB there is its response (a pole-zero pair), not a sampling spike
    ax_m = fig.axes[0]
    ins = ax_m.inset_axes((0.13, 0.08, 0.3, 0.42))
    wz = 2 * math.pi * np.linspace(40.0, 60.0, 801)
    for i, tf in enumerate(leso.values()):
        style = {k: v for k, v in _TRACE_STYLES[i].items() if k not in ("marker", "ms", "markevery")}
        ins.plot(wz / (2 * math.pi) if hz else wz, np.asarray(linear.bode(tf, wz)[0]), color=f"C{i}", **style)
    ins.axvline(we / (2 * math.pi) if hz else we, color="k", lw=0.6, ls=":")
    ins.set_title("zoom, magnitude (dB): 40–60 Hz" if hz else "zoom, magnitude (dB): 2π·40–2π·60 rad/s", fontsize=8)
    ins.tick_params(labelsize=8)
    ins.grid(True, alpha=0.3)
    ax_m.legend(fontsize=9, loc="lower right", bbox_to_anchor=(0.86, 0.02))
    _finish(fig, p)
    paths.append(p)
    # 001 Fig. 14: open loops θ̂/(θ − θ̂), Table I gains
    s, wp, wi = linear.sogi_fll_closed_form(), linear.wpf_closed_form(), linear.wif_closed_form()
    fll = {
        "SOGI-FLL": linear.sogi_fll_model(s.k, s.lam, s.omega_n).open_loop,
        "SOGI-FLL-WPF": linear.wpf_model(wp.k1, wp.k2, wp.lam, wp.omega_n).open_loop,
        "SOGI-FLL-WIF": linear.wif_model(wi.k1, wi.k2, wi.lam, wi.omega_n).open_loop,
    }
    p = out / "bode_fll_open_loop_001_fig14.png"
    bode_figure(
        fll,
        np.logspace(0, 4, 1500),
        "Paper 001 Fig. 14: FLL open loops, Table I gains",
        p,
        hz=hz,
        mark=papers.WIF_OMEGA_C,
        mark_text=f"designed crossover {_freq(papers.WIF_OMEGA_C, hz)}",
    )
    paths.append(p)
    return paths
