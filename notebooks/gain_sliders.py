"""The callback of the gain-slider notebook (05_gain_sliders.ipynb): a SOGI-FLL's (k, λ) in, its response and its
margins redrawn.

:class:`GainSliders` is a plain callable: ``ui(k, lam)`` re-simulates paper 001's Test A (a 50 → 52 Hz step) with
the gains, recomputes the open loop's margins and Bode curves (001 eqs 18–20, ``jaxobs.linear.sogi_fll_model``),
updates the figure's lines in place and redraws only what moved; ``ui.png()`` is the picture the notebook shows.

What a move costs, and why it is cheap:

- The simulation, the margins and the Bode curves are one ``jax.jit`` program whose gains are traced arguments: it is
  traced and compiled once, in ``__init__`` (``ui.traces`` counts its traces; a move adds none), and a call runs in
  a few milliseconds.
- Drawing is what costs: a full render of the three axes (ticks, labels, the legend) takes 100-160 ms of CPU here,
  and showing a figure with ``display(fig)`` under the inline backend renders it again with ``bbox_inches="tight"``
  (a layout pass, then the render) and encodes it. So the layout is fixed once (``tight_layout`` in ``__init__``, no
  layout engine after it), the still part of the figure is rendered once into a saved background, and a move
  restores it and draws only the artists that change (the sliders' three lines, the two crossover marks, the title,
  and what a full render draws over them: the grid-frequency line, the spines, the legend), then blits: the pixels
  are a full render's, exactly (tests/test_gain_sliders.py). ``ui.png()`` encodes the canvas's pixels as they are
  (no further render); the notebook puts them in an ``ipywidgets.Image``.
- The figure is a plain ``matplotlib.figure.Figure`` on an Agg canvas, not one of pyplot's: the inline backend
  closes pyplot's figures after each cell, and a closed figure's canvas is a ``FigureCanvasBase`` whose ``draw()``
  renders nothing. Nor is ``canvas.draw_idle`` used: on an Agg canvas it is a full render at once.

A displayed move (a browser's slider message to the kernel, the callback, the PNG sent) took a median 124 ms wall and
64 ms of CPU on the shared 2-core machine at load 5.6-6.2, with no XLA compilation
(``benchmarks/results/2026-12-03-sliders.txt``, by ``python -m benchmarks.sliders``).
"""

from __future__ import annotations

import io
import time

import jax
import jax.numpy as jnp
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

import jaxobs
from jaxobs import linear, papers

T_EVENT, HORIZON = 0.1, 0.4  # s: Test A's step, and the end of the run
OMEGA = np.logspace(0, 4, 300)  # rad/s, the Bode curves' grid
# 8 x 8 in at 100 dpi, 800 x 800 pixels, as the inline backend showed it before. 72 dpi was measured and not taken:
# the blitted draw does not depend on it (25-35 ms of CPU at 100, 90 and 72 dpi here) and the PNG encoding saves 7 ms
# a move (17 -> 10 ms), for a figure whose text is a third smaller
FIGSIZE, DPI = (8.0, 8.0), 100
# zlib level 1: these flat-coloured line plots come out 5-8 % larger than at the default level 6; the encoding took
# 14-22 ms against 18-24 ms here (noisy on the shared cores; never slower)
PNG_LEVEL = 1


def _title(k: float, lam: float, m) -> tuple[str, float]:
    f_gc = float(m.omega_gc) / (2 * np.pi)
    title = (
        f"k = {k:.3g}, λ = {lam:.4g}: phase margin {float(m.phase_margin):.1f}°, "
        f"gain crossover {f_gc:.1f} Hz, gain margin {float(m.gain_margin):.3g}"
    )
    return title, f_gc


class GainSliders:
    """A SOGI-FLL's response to Test A and its open-loop margins, for gains (k, λ) given one pair at a time.

    Args:
        reference: the (k, λ) drawn as a fixed reference line (default: 001 Table I's closed form).
        dpi: the figure's resolution (dots per inch; 8 x 8 in).
    """

    def __init__(self, reference: tuple[float, float] = (papers.SOGI_FLL_K, papers.SOGI_FLL_LAM), dpi: float = DPI):
        if not 20 <= dpi <= 300:
            raise ValueError(f"dpi must be in [20, 300], got {dpi}")
        self.signal = jaxobs.paper001_test("A", t_event=T_EVENT)
        self.traces = 0  # how often _evaluate was traced: once, whatever the gains
        self._run = jax.jit(self._evaluate)
        k0, lam0 = map(float, reference)
        ref = jax.device_get(self._run(k0, lam0))
        self.fig = Figure(figsize=FIGSIZE, dpi=dpi)
        self.fig.set_layout_engine("none")  # whatever matplotlibrc says: no layout engine reruns at each draw
        FigureCanvasAgg(self.fig)
        self.ax_f, self.ax_mag, self.ax_ph = self.fig.subplots(3, 1, gridspec_kw={"height_ratios": [1.4, 1, 1]})
        t, hz = np.asarray(ref["t"]), OMEGA / (2 * np.pi)
        # the still artists first, the moving ones last in each axes: each is then drawn over what a full render
        # draws before it, as a blit draws it over the background
        self.ax_f.plot(t, ref["f"], color="0.6", label=f"Table I (k = {k0:.3g}, λ = {lam0:.4g})")
        self.ax_mag.semilogx(hz, ref["db"], color="0.6")
        self.ax_ph.semilogx(hz, ref["deg"], color="0.6")
        self.ax_mag.axhline(0, color="k", lw=0.5)
        self.ax_ph.axhline(-180, color="k", lw=0.5)
        (self.line_f,) = self.ax_f.plot(t, ref["f"], color="C0", label="the sliders' gains")
        (truth,) = self.ax_f.plot(t, ref["f_true"], "k:", lw=1, label="grid frequency")
        (self.line_mag,) = self.ax_mag.semilogx(hz, ref["db"], color="C0")
        (self.line_ph,) = self.ax_ph.semilogx(hz, ref["deg"], color="C0")
        self.mark_gc = self.ax_mag.axvline(1.0, color="C3", ls="--", lw=1)
        self.mark_pm = self.ax_ph.axvline(1.0, color="C3", ls="--", lw=1)
        self.ax_f.set(xlabel="time (s)", ylabel="estimated frequency (Hz)", ylim=(47, 55))
        legend = self.ax_f.legend(fontsize=9, loc="lower right")
        self.ax_mag.set(ylabel="|L| (dB)", ylim=(-40, 60))
        self.ax_ph.set(xlabel="frequency (Hz)", ylabel="∠L (deg)", ylim=(-270, 0))
        self.ax_mag.set_title("open loop L = θ̂/(θ − θ̂) (001 eqs 18–20); dashed: gain crossover", fontsize=10)
        # the axes' limits are fixed from here: a move changes data, never the scales or ticks of the background
        for ax in (self.ax_f, self.ax_mag, self.ax_ph):
            ax.set_autoscale_on(False)
        first = f"Test A (50 → 52 Hz at {T_EVENT} s)\n{_title(k0, lam0, ref['margins'])[0]}"
        # y given: the title's place is fixed (an automatic one is recomputed at each full render, from the axes'
        # decorations, and came out far off the figure when the background was rendered without them)
        self.title = self.ax_f.set_title(first, fontsize=10, y=1.0)
        self.fig.tight_layout()  # once, with the two-line title in place
        # what a move redraws, in a full render's order: the data lines, then what a full render draws over them
        # (the spines, the title, the legend)
        spines = [s for ax in (self.ax_f, self.ax_mag, self.ax_ph) for s in ax.spines.values()]
        self._moving = [self.line_f, truth, self.line_mag, self.mark_gc, self.line_ph, self.mark_pm, *spines]
        self._moving += [self.title, legend]
        self._background = None
        self._key: tuple[float, float, float] | None = None

    def _evaluate(self, k, lam):
        self.traces += 1  # runs while jax traces, not when the compiled program runs
        obs = jaxobs.SOGIFLL(k=k, lam=lam)
        sol = jaxobs.simulate(jaxobs.OnSignal(obs, self.signal), HORIZON)
        loop = linear.sogi_fll_model(k, lam, papers.FLL_OMEGA_N).open_loop
        db, deg = linear.bode(loop, jnp.asarray(OMEGA))
        return {
            "t": sol.t,
            "f": sol.outputs.obs.omega / (2 * jnp.pi),
            "f_true": sol.outputs.truth.omega / (2 * jnp.pi),
            "margins": linear.margins(loop),
            "db": db,
            "deg": deg,
        }

    def _canvas(self) -> FigureCanvasAgg:
        canvas = self.fig.canvas
        if not isinstance(canvas, FigureCanvasAgg):
            raise RuntimeError(f"the figure's canvas must be Agg's (its pixels are blitted), got {type(canvas).__name__}")
        return canvas

    def _capture_background(self) -> None:
        """Render the figure without its moving artists, once per canvas size, and keep the pixels."""
        canvas = self._canvas()
        for a in self._moving:
            a.set_visible(False)
        try:
            canvas.draw()
        finally:
            for a in self._moving:
                a.set_visible(True)
        self._background = canvas.copy_from_bbox(self.fig.bbox)
        self._key = (*self.fig.bbox.size, self.fig.dpi)

    def draw(self) -> None:
        """Redraw what moved: restore the still background and draw the moving artists over it, then blit (on an
        interactive canvas, what it shows; on Agg, nothing more). The background is rendered again only when the
        figure's size or resolution changed."""
        canvas = self._canvas()
        if self._key != (*self.fig.bbox.size, self.fig.dpi):
            self._capture_background()
        renderer = canvas.get_renderer()  # a fresh one if something rendered the figure at another size meanwhile
        renderer.restore_region(self._background)
        for a in self._moving:
            a.draw(renderer)
        canvas.blit(self.fig.bbox)

    def png(self) -> bytes:
        """The figure as drawn by the last call, PNG-encoded from the canvas's pixels (no render)."""
        rgba = np.asarray(self._canvas().buffer_rgba())
        out = io.BytesIO()
        Image.fromarray(rgba[..., :3]).save(out, format="png", compress_level=PNG_LEVEL)
        return out.getvalue()

    def __call__(self, k: float, lam: float) -> dict:
        """Simulate and draw gains ``(k, lam)``; returns the margins (``linear.Margins``), the title shown and the
        seconds the call took (simulation, margins, Bode curves and drawing)."""
        t0 = time.perf_counter()
        r = jax.device_get(self._run(float(k), float(lam)))
        self.line_f.set_ydata(r["f"])
        self.line_mag.set_ydata(r["db"])
        self.line_ph.set_ydata(r["deg"])
        title, f_gc = _title(k, lam, r["margins"])
        self.mark_gc.set_xdata([f_gc, f_gc])
        self.mark_pm.set_xdata([f_gc, f_gc])
        self.title.set_text(f"Test A (50 → 52 Hz at {T_EVENT} s)\n{title}")
        self.draw()
        return {"margins": r["margins"], "title": title, "seconds": time.perf_counter() - t0}
