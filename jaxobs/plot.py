"""matplotlib figures (imported lazily: the library itself never needs a display)."""

from __future__ import annotations

import math

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def fll_demo_figure(traces, tests, t_event, path=None):
    """Frequency estimate and phase error of each FLL for each test (rows = tests)."""
    from . import metrics

    plt = _plt()
    fig, axes = plt.subplots(len(tests), 2, figsize=(11, 2.2 * len(tests)), sharex=False, squeeze=False)
    for name, sol in traces.items():
        t = np.asarray(sol.t[0])
        f_hat = np.asarray(sol.out.omega) / (2 * math.pi)
        err = np.degrees(np.asarray(metrics.wrap(sol.out.theta - sol.truth.theta)))
        for i, test in enumerate(tests):
            span = 0.3 if test in ("A", "B") else 1.2
            m = (t >= t_event - 0.05) & (t <= t_event + span)
            axes[i, 0].plot(1e3 * (t[m] - t_event), f_hat[i][m], lw=1, label=name)
            axes[i, 1].plot(1e3 * (t[m] - t_event), err[i][m], lw=1, label=name)
    for i, test in enumerate(tests):
        axes[i, 0].set_ylabel(f"Test {test}\nf̂ (Hz)")
        axes[i, 1].set_ylabel("θ̂ − θ (deg)")
        for ax in axes[i]:
            ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time after event (ms)")
    axes[-1, 1].set_xlabel("time after event (ms)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Paper 001 Tests A–E, Table I gains (simulated, 10 kHz, AB3)")
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return fig
