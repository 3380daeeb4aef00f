"""Plots for a tuning run: convergence, and responses of initial / closed-form / tuned gains."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import jax
import numpy as np

from jaxobs.families import GridSignals

from .outdir import atomic_path


def _subplots(*args, figsize, **kwargs):
    """``pyplot.subplots`` without pyplot: no backend selected, so a notebook running a job keeps its own."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(*args, **kwargs)


# how each design's curve is drawn: "initial" often equals the closed form (a job that starts there), so it is
# dashed and on top, visible over "closed_form"
_STYLE = {"initial": dict(ls="--", lw=1.2, zorder=3), "closed_form": dict(lw=1.6), "tuned": dict(lw=1.2)}


def scenario_values(spec) -> tuple[list, list]:
    """The axis names and the value tuple of every scenario of a job's ``ScenarioSpec``, in the objective's order.

    The same enumeration as the scenarios' builder (``jaxobs_tuning.job``): the Cartesian grid, or ``sample``
    random points drawn (seeded) between each axis' smallest and largest value.
    """
    names = list(spec.axes)
    if spec.sample:
        rng = np.random.default_rng(spec.seed)
        lo, hi = {n: min(spec.axes[n]) for n in names}, {n: max(spec.axes[n]) for n in names}
        return names, [tuple(rng.uniform(lo[n], hi[n]) for n in names) for _ in range(spec.sample)]
    return names, list(itertools.product(*(spec.axes[n] for n in names)))


_UNITS = {"freq_step": " Hz", "speed_hz": " Hz", "speed_rpm": " r/min", "dc": " p.u.", "sag": " p.u.", "noise": " p.u."}


def _describe(spec, index: int) -> str:
    """The scenario's axis values, or for a job on recordings the recording's file name."""
    rec = getattr(spec, "recording", None)
    if rec is not None and index < len(rec.files):
        return f"scenario #{index}: recording {Path(rec.files[index]).name}"
    names, combos = scenario_values(spec)
    if not names or index >= len(combos):
        return f"scenario #{index}"
    values = ", ".join(f"{n} = {v:.4g}{_UNITS.get(n, '')}" for n, v in zip(names, combos[index]))
    return f"scenario #{index}: {values}"


# the axes whose non-zero value is an event at t_event: a grid signal's disturbances (jaxobs.signals: every one
# switches on at t_event) and a drive's reference and load steps (jaxobs.drive_study)
_EVENT_AXES = {
    "grid": ("freq_step", "phase_jump_deg", "sag", "dc", "harmonics_scale", "sub_amplitude"),
    "drive": ("speed_step_rpm", "load_step_nm"),
}


def _has_event(spec, index: int) -> bool:
    """Whether scenario ``index`` of ``spec`` changes at t_event (True where the signal kind's events are not
    listed: the mark is then kept)."""
    axes = _EVENT_AXES.get(spec.signal)
    if axes is None:
        return True
    names, combos = scenario_values(spec)
    if index >= len(combos):
        return True
    return any(n in axes and float(v) != 0.0 for n, v in zip(names, combos[index]))


def convergence_figure(history: list, name: str, path: Path):
    """The objective against the iteration (``history``: dicts with "iteration" and "value") into ``path``."""
    fig, ax = _subplots(figsize=(6, 3.5))
    it, val = [h["iteration"] for h in history], [h["value"] for h in history]
    ax.plot(it, val, lw=1.2)
    # a log scale where every value is positive; an objective with a margin term (sosoifo.toml) goes negative,
    # and a log axis drew nothing at all.  Not near the largest double either: a log axis pads its range by
    # decades, and a run at 1.3e307 (weights of 1e308, tuned in forward mode) made matplotlib's tick
    # locator overflow (an internal error after the results were computed)
    if min(val) > 0 and max(val) < 1e300:
        ax.set_yscale("log")
    ax.set_xlabel("iteration")
    ax.set_ylabel("objective")
    ax.set_title(f"{name}: convergence")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    return fig


def write_report(out: Path, job, obj, thetas: dict, history: list, closed_form_totals=None):
    """convergence.png and responses.png in ``out``.  ``closed_form_totals``: the closed form's per-scenario
    totals on ``obj``'s scenarios (:meth:`Objective.per_scenario`'s second value), where the caller has them
    (else they are computed again); the responses show the scenario where it does worst."""
    if history:
        convergence_figure(history, job.name, out / "convergence.png")
    # responses on the scenario where the closed form does worst
    per = obj.per_scenario(thetas["closed_form"])[1] if closed_form_totals is None else closed_form_totals
    worst = int(np.argmax(np.asarray(per)))
    sig = jax.tree.map(lambda x: x[worst], obj.scenarios)
    fig, axes = _subplots(2, 1, figsize=(8, 5.5), sharex=True)
    for label, th in thetas.items():
        style = _STYLE.get(label, dict(lw=1))
        t, omega, err = (np.asarray(x) for x in obj.response(th, sig))
        name = label.replace("_", " ")  # in words ("closed form"); result.json's keys have an underscore
        axes[0].plot(t, omega / (2 * math.pi), label=name, **style)
        axes[1].plot(t, np.degrees(err), label=name, **style)
    # an FLL's ("grid") error is the grid voltage's phase; a flux observer's or a drive's (on an "emf" recording or
    # closing the loop) is the rotor's electrical position: the labels say which
    if job.scenarios.family is not GridSignals:
        axes[0].set_ylabel("speed estimate ω̂e/2π (Hz)")
        axes[1].set_ylabel("position error (deg el.)")
    else:
        axes[0].set_ylabel("estimated frequency (Hz)")
        axes[1].set_ylabel("phase error θ̂ − θ (deg)")
    axes[1].set_xlabel("time (s)")
    axes[0].legend(fontsize=8)
    # the scenario's steps and jumps (the title's values) happen here; none marked where it has none (cleso.toml)
    t_event = float(job.scenarios.t_event) if _has_event(job.scenarios, worst) else 0.0
    for ax in axes:
        ax.grid(True, alpha=0.3)
        if t_event > 0:
            ax.axvline(t_event, color="0.3", lw=0.8, ls=":")
    if t_event > 0:
        axes[1].annotate(
            f"events at t = {t_event:g} s",
            (t_event, 0.03),
            xycoords=("data", "axes fraction"),
            xytext=(4, 0),
            textcoords="offset points",
            fontsize=8,
            color="0.3",
        )
    fig.suptitle(
        f"{job.name}: closed form vs tuned on the closed form's worst scenario\n{_describe(job.scenarios, worst)}",
        fontsize=10,
    )
    fig.tight_layout()
    with atomic_path(out / "responses.png") as tmp:
        fig.savefig(tmp, dpi=110)
