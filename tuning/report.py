"""Plots for a tuning run: convergence, and responses of initial / closed-form / tuned gains."""

from __future__ import annotations

import itertools
import math
import textwrap
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from jaxobs.core.quantities import text_unit
from jaxobs.scenarios.families import GridSignals

from .aggregations import CVaR, Mean, SmoothMax

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def _subplots(*args, figsize, **kwargs):
    """``pyplot.subplots`` without pyplot: no backend selected, so a notebook running a job keeps its own."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(*args, **kwargs)


# how each design's curve is drawn: "initial" often equals the closed form (a job that starts there), so it is
# dashed and on top, visible over "closed_form"
_STYLE = {"initial": dict(ls="--", lw=1.2, zorder=3), "closed_form": dict(lw=1.6), "tuned": dict(lw=1.2)}


def scenario_values(spec: Any) -> tuple[list, list]:
    """The axis names and the value tuple of every scenario of a job's ``ScenarioSpec``, in the objective's order.

    The same enumeration as the scenarios' builder (``jaxobs_tuning.job``): the Cartesian grid, or ``sample``
    random points drawn (seeded) between each axis' smallest and largest value.

    Args:
        spec: The job's ``ScenarioSpec`` (:mod:`jaxobs_tuning.job.spec`, a layer above): its axes, sample
            and seed.

    Returns:
        The axis names, and one tuple of values per scenario.
    """
    names = list(spec.axes)
    if spec.sample:
        rng = np.random.default_rng(spec.seed)
        lo, hi = {n: min(spec.axes[n]) for n in names}, {n: max(spec.axes[n]) for n in names}
        return names, [tuple(rng.uniform(lo[n], hi[n]) for n in names) for _ in range(spec.sample)]
    return names, list(itertools.product(*(spec.axes[n] for n in names)))


def _axis_text(family, name: str, value: float) -> str:
    """One axis value as a figure's title states it: the axis's long name (before any parenthesis), the value and
    its unit (:class:`jaxobs.core.quantities.Axis`; a dimensionless value alone)."""
    axis = family.axes.get(name)
    if axis is None:
        return f"{name} = {value:.4g}"
    label, _, note = axis.long_name.partition(" (")
    note = note.rstrip(")")
    unit = "" if axis.units in ("1", "") else f" {text_unit(axis.units)}"
    if not unit and note.startswith("p.u."):  # "dc offset (p.u. of the fundamental)": 0.1 p.u.
        unit = " p.u."
    elif not unit and note.startswith("multiple of "):  # "harmonic distortion (multiple of ...)": 1 × ...
        unit = f" × {note[len('multiple of ') :]}"
    return f"{label} = {value:.4g}{unit}"


def _describe(spec, family, index: int) -> str:
    """The scenario's axis values (their long names and units), or for a job on recordings the recording's file
    name; a long line broken in two."""
    rec = spec.recording
    if rec is not None and index < len(rec.files):
        return f"scenario #{index}: recording {Path(rec.files[index]).name}"
    names, combos = scenario_values(spec)
    if not names or index >= len(combos):
        return f"scenario #{index}"
    lines = [f"scenario #{index}:"]
    for n, v in zip(names, combos[index]):  # lines of at most about 100 characters, broken between the axes
        item = _axis_text(family, n, v)
        if len(lines[-1]) + len(item) > 100:
            lines[-1] += ","
            lines.append(item)
        else:
            lines[-1] += (" " if lines[-1].endswith(":") else ", ") + item
    return "\n".join(lines)


# the axes whose non-zero value is an event at t_event: a grid signal's disturbances (jaxobs.signals: every one
# switches on at t_event) and a drive's reference and load steps (jaxobs.studies.drive)
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


def objective_text(objective: Any) -> str:
    """What an :class:`~jaxobs_tuning.objective.Objective` minimises, in words and symbols: ``J = <aggregate>
    over the scenarios of w1·metric1 + ...``, a number (each weight is per its metric's unit), a diverged
    scenario scoring the penalty.

    Args:
        objective: The :class:`~jaxobs_tuning.objective.Objective` (its layer's peer, not imported here).

    Returns:
        The text, two lines.
    """
    agg = objective.aggregation
    if isinstance(agg, CVaR):
        how = f"CVaR (α = {agg.alpha:g}: the mean of the worst {100 * (1 - agg.alpha):.3g} %)"
    elif isinstance(agg, SmoothMax):
        how = "smooth max" + ("" if agg.temperature is None else f" (T = {agg.temperature:g})")
    elif isinstance(agg, Mean):
        how = "mean"
    else:
        how = type(agg).__name__
    terms = " + ".join(
        f"{float(t.weight):g}·{t.metric if isinstance(t.metric, str) else t.metric.name}" for t in objective.terms
    )
    return (
        f"J = {how} over the scenarios of {terms}\n(a number: each weight is per its metric's unit; "
        f"a diverged scenario scores the penalty {float(objective.penalty):g})"
    )


def convergence_figure(history: list, name: str, objective: str | None = None, best: int | None = None) -> Figure:
    """The objective against the iteration.

    Args:
        history: dicts with "iteration", "value" and "diverged" (the solvers' history).
        name: the job's name (the title).
        objective: the objective's definition (:func:`objective_text`), printed under the axis; None: none.
        best: the iteration whose design is the tuned one (the result's ``best_iteration``); None: the least
            value among the iterations that diverged in no scenario (none marked where every one diverged).
    """
    # the definition wrapped to the figure's width (a long metric's name ran past both edges), a line each
    lines = [w for line in (objective or "").split("\n") for w in textwrap.wrap(line, 105)] if objective else []
    fig, ax = _subplots(figsize=(6.4, 3.5 + 0.25 * len(lines)))
    it, val = [h["iteration"] for h in history], [h["value"] for h in history]
    ax.plot(it, val, lw=1.2, marker=".", ms=4, label="objective J of each design scored")
    # a log scale where every value is positive; an objective with a margin term (sosoifo.toml) goes negative,
    # and a log axis drew nothing at all.  Not near the largest double either: a log axis pads its range by
    # decades, and a run at 1.3e307 (weights of 1e308, tuned in forward mode) made matplotlib's tick
    # locator overflow (an internal error after the results were computed)
    if min(val) > 0 and max(val) < 1e300:
        ax.set_yscale("log")
    if best is None:
        stable = [h for h in history if not h.get("diverged", 0) and math.isfinite(h["value"])]
        best = min(stable, key=lambda h: h["value"])["iteration"] if stable else None
    at = [h for h in history if h["iteration"] == best]
    if at:
        ax.plot(
            [best], [at[0]["value"]], "*", color="C3", ms=13, zorder=4,
            label=f"best: iteration {best}, J = {at[0]['value']:.4g} (the tuned design)",
        )  # fmt: skip
    ax.set_xlabel("iteration")
    ax.set_ylabel("objective J (1)")
    ax.set_title(f"{name}: convergence")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    if objective:
        fig.text(0.5, 0.015, "\n".join(lines), ha="center", va="bottom", fontsize=8, color="0.2")
    fig.tight_layout(rect=(0, 0.01 + 0.16 * len(lines) / (3.5 + 0.25 * len(lines)), 1, 1))
    return fig


def _coincide(traces: dict, gains: dict, tol: float = 1e-3) -> dict:
    """{label: what its legend entry adds} for each design drawn on an earlier one's line (an initial design at
    the closed form, a tuned one that did not move): every trace within ``tol`` of its panel's span of the
    earlier design's, so only one line shows.  The note names that design and how far apart the gains are.

    Args:
        traces: {label: (frequency, error)}, the curves drawn, in the legend's order.
        gains: {label: {gain: value}}.
    """
    out, seen = {}, []
    for label, curves in traces.items():
        for other in seen:
            near = all(
                np.max(np.abs(a - b)) <= tol * max(float(np.ptp(b)), 1e-300)
                for a, b in zip(curves, traces[other])
                if np.all(np.isfinite(a)) and np.all(np.isfinite(b))
            )
            if near:
                g, h = gains[label], gains[other]
                rel = max((abs(g[k] - h[k]) / max(abs(h[k]), 1e-300) for k in g), default=0.0)
                how = "the same gains" if rel == 0 else f"gains within {100 * rel:.2g} %"
                out[label] = f" (on the {other.replace('_', ' ')} line: {how})"
                break
        seen.append(label)
    return out


def report_figures(
    job: Any,
    family: type,
    objective: str,
    history: list,
    responses: dict,
    gains: dict,
    best_iteration: int | None = None,
) -> dict[str, Figure]:
    """The figures of a tuning run's results folder: ``convergence.png`` (where the solver has a history) and
    ``responses.png``, the designs' responses on the scenario where the closed form does worst.

    Args:
        job: The :class:`~jaxobs_tuning.job.Job` (a layer above, not imported here): its name and scenarios.
        family: The scenario family its ``scenarios.signal`` names (:mod:`jaxobs.scenarios.families`).
        objective: The objective's definition (:func:`objective_text`).
        history: The solver's history.
        responses: ``{"worst": index, label: (t, omega, err)}``: each design's response on that scenario, by
            label ("initial", "closed_form", "tuned"); omega in rad/s, err in rad.
        gains: Each drawn design's free gains, by label.
        best_iteration: The tuned design's iteration, marked on convergence.png (None: the least stable value).

    Returns:
        The figures, by file name.
    """
    figures = {}
    if history:
        figures["convergence.png"] = convergence_figure(history, job.name, objective, best_iteration)
    worst = int(responses["worst"])
    fig, axes = _subplots(2, 1, figsize=(8, 5.5), sharex=True)
    drawn, times = {}, {}
    for label in gains:
        times[label], omega, err = responses[label]
        drawn[label] = (omega / (2 * math.pi), np.degrees(err))
    notes = _coincide(drawn, gains)  # a dashed line exactly on another: the legend says why
    for label, (freq, err) in drawn.items():
        style = _STYLE.get(label, dict(lw=1))
        name = label.replace("_", " ")  # in words ("closed form"); result.json's keys have an underscore
        axes[0].plot(times[label], freq, label=name + notes.get(label, ""), **style)
        axes[1].plot(times[label], err, label=name + notes.get(label, ""), **style)
    # an FLL's ("grid") error is the grid voltage's phase; a flux observer's or a drive's (on an "emf" recording or
    # closing the loop) is the rotor's electrical position: the labels say which
    if family is not GridSignals:
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
    where = _describe(job.scenarios, family, worst)
    fig.suptitle(
        f"{job.name}: closed form vs tuned on the closed form's worst scenario\n{where}",
        fontsize=10,
    )
    fig.tight_layout()
    figures["responses.png"] = fig
    return figures
