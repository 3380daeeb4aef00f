"""Plots for a tuning run: convergence, and responses of initial / closed-form / tuned gains."""

from __future__ import annotations

import math
from pathlib import Path

import jax
import numpy as np

from jaxobs.metrics import wrap

from .outdir import atomic_path


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def write_report(out: Path, job, obj, thetas: dict, history: list):
    plt = _plt()
    # convergence
    if history:
        fig, ax = plt.subplots(figsize=(6, 3.5))
        ax.semilogy([h["iteration"] for h in history], [h["value"] for h in history], lw=1.2)
        ax.set_xlabel("iteration")
        ax.set_ylabel("objective")
        ax.set_title(f"{job.name}: convergence")
        ax.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        with atomic_path(out / "convergence.png") as tmp:
            fig.savefig(tmp, dpi=110)
        plt.close(fig)
    # responses on the scenario where the closed form does worst
    per = obj.per_scenario(thetas["closed_form"])[1]
    worst = int(np.argmax(np.asarray(per)))
    sig = jax.tree.map(lambda x: x[worst], obj.scenarios)
    fig, axes = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    for label, th in thetas.items():
        comp = obj.param.apply(obj.component, th)
        sol = obj._simulate(comp, sig)
        t, so = np.asarray(sol.t), sol.outputs
        if hasattr(so, "theta_e"):  # drive: observer speed and position error
            axes[0].plot(t, np.asarray(so.obs.omega) / (2 * math.pi), lw=1, label=label)
            axes[1].plot(t, np.degrees(np.asarray(wrap(so.obs.theta - so.theta_e))), lw=1, label=label)
        elif so.truth is not None:
            axes[0].plot(t, np.asarray(so.obs.omega) / (2 * math.pi), lw=1, label=label)
            axes[1].plot(t, np.degrees(np.asarray(wrap(so.obs.theta - so.truth.theta))), lw=1, label=label)
        else:
            axes[0].plot(t, np.asarray(so.obs.omega) / (2 * math.pi), lw=1, label=label)
            err = wrap(so.obs.theta - (sig.omega1 * sol.t + sig.phase - math.pi / 2))
            axes[1].plot(t, np.degrees(np.asarray(err)), lw=1, label=label)
    axes[0].set_ylabel("estimated frequency (Hz)")
    axes[1].set_ylabel("phase / position error (deg)")
    axes[1].set_xlabel("time (s)")
    axes[0].legend(fontsize=8)
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.suptitle(f"{job.name}: closed form vs tuned on the closed form's worst scenario (#{worst})", fontsize=10)
    fig.tight_layout()
    with atomic_path(out / "responses.png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
