"""The callback of the gain-slider notebook (05_gain_sliders.ipynb): a SOGI-FLL's (k, λ) in, its response and its
margins redrawn.

:class:`GainSliders` is a plain callable: ``ui(k, lam)`` re-simulates paper 001's Test A (a 50 → 52 Hz step) with
the gains, recomputes the open loop's margins and Bode curves (001 eqs 18–20, ``jaxobs.linear.sogi_fll_model``),
updates the figure's lines and draws it. The simulation, the margins and the Bode curves are one ``jax.jit``
program whose gains are traced arguments, so moving a slider compiles nothing: after the first call, a call takes
well under 0.3 s (tests/test_gain_sliders.py measures it without a browser). The notebook connects it to two
ipywidgets sliders.
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

import jaxobs
from jaxobs import linear, papers

T_EVENT, HORIZON = 0.1, 0.4  # s: Test A's step, and the end of the run
OMEGA = np.logspace(0, 4, 300)  # rad/s, the Bode curves' grid


class GainSliders:
    """A SOGI-FLL's response to Test A and its open-loop margins, for gains (k, λ) given one pair at a time.

    Args:
        reference: the (k, λ) drawn as a fixed reference line (default: 001 Table I's closed form).
    """

    def __init__(self, reference: tuple[float, float] = (papers.SOGI_FLL_K, papers.SOGI_FLL_LAM)):
        self.signal = jaxobs.paper001_test("A", t_event=T_EVENT)
        self._run = jax.jit(self._evaluate)
        ref = self._run(*map(float, reference))
        self.fig, (self.ax_f, self.ax_mag, self.ax_ph) = plt.subplots(
            3, 1, figsize=(8, 8), gridspec_kw={"height_ratios": [1.4, 1, 1]}
        )
        t = np.asarray(ref["t"])
        self.ax_f.plot(t, np.asarray(ref["f"]), color="0.6", label=f"Table I (k = {reference[0]:.3g}, λ = {reference[1]:.4g})")
        (self.line_f,) = self.ax_f.plot(t, np.asarray(ref["f"]), color="C0", label="the sliders' gains")
        self.ax_f.plot(t, np.asarray(ref["f_true"]), "k:", lw=1, label="grid frequency")
        self.ax_f.set(xlabel="time (s)", ylabel="estimated frequency (Hz)", ylim=(47, 55))
        self.ax_f.legend(fontsize=9, loc="lower right")
        hz = OMEGA / (2 * np.pi)
        self.ax_mag.semilogx(hz, np.asarray(ref["db"]), color="0.6")
        self.ax_ph.semilogx(hz, np.asarray(ref["deg"]), color="0.6")
        (self.line_mag,) = self.ax_mag.semilogx(hz, np.asarray(ref["db"]), color="C0")
        (self.line_ph,) = self.ax_ph.semilogx(hz, np.asarray(ref["deg"]), color="C0")
        self.mark_gc = self.ax_mag.axvline(1.0, color="C3", ls="--", lw=1)
        self.mark_pm = self.ax_ph.axvline(1.0, color="C3", ls="--", lw=1)
        self.ax_mag.axhline(0, color="k", lw=0.5)
        self.ax_ph.axhline(-180, color="k", lw=0.5)
        self.ax_mag.set(ylabel="|L| (dB)", ylim=(-40, 60))
        self.ax_ph.set(xlabel="frequency (Hz)", ylabel="∠L (deg)", ylim=(-270, 0))
        self.ax_mag.set_title("open loop L = θ̂/(θ − θ̂) (001 eqs 18–20); dashed: gain crossover", fontsize=10)
        self.fig.tight_layout()

    def _evaluate(self, k, lam):
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

    def __call__(self, k: float, lam: float) -> dict:
        """Simulate and draw gains ``(k, lam)``; returns the margins (``linear.Margins``), the title shown and the
        seconds the call took (simulation, margins, Bode curves and drawing)."""
        t0 = time.perf_counter()
        r = jax.device_get(self._run(float(k), float(lam)))
        m = r["margins"]
        self.line_f.set_ydata(r["f"])
        self.line_mag.set_ydata(r["db"])
        self.line_ph.set_ydata(r["deg"])
        f_gc = float(m.omega_gc) / (2 * np.pi)
        self.mark_gc.set_xdata([f_gc, f_gc])
        self.mark_pm.set_xdata([f_gc, f_gc])
        title = (
            f"k = {k:.3g}, λ = {lam:.4g}: phase margin {float(m.phase_margin):.1f}°, "
            f"gain crossover {f_gc:.1f} Hz, gain margin {float(m.gain_margin):.3g}"
        )
        self.ax_f.set_title(f"Test A (50 → 52 Hz at {T_EVENT} s)\n{title}", fontsize=10)
        self.fig.canvas.draw()
        return {"margins": m, "title": title, "seconds": time.perf_counter() - t0}
