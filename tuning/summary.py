"""The summaries' warnings and the one ``jaxobs tune`` prints: gains, linear structure and scores of the three
designs, warnings.  :func:`study_warnings`: what a study lost, per design, for ``jaxobs study``'s stderr."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from xarray import Dataset


def _fmt(v, spec=">14.6g") -> str:
    if v is None:
        return f"{'-':>14}"
    if isinstance(v, bool):
        return f"{'yes' if v else 'no':>14}"
    return format(v, spec)


_LINEAR_ROWS = (
    ("phase margin (deg)", lambda s: s.get("phase_margin_deg")),
    ("crossover (Hz)", lambda s: s.get("crossover_hz")),
    ("dominant damping", lambda s: s.get("dominant_damping")),
    ("dominant pole (Hz)", lambda s: s.get("dominant_hz")),
    ("least pair damping", lambda s: s.get("least_pair_damping")),
    ("stable (linear)", lambda s: s.get("stable")),
    ("Routh stable", lambda s: s.get("routh_stable")),
    ("b = k1/k2", lambda s: s.get("closed_form_rule", {}).get("b_implied")),
    ("wc = k2 wn/2 (Hz)", lambda s: s.get("closed_form_rule", {}).get("crossover_hz_implied")),
    ("PM of SO at b (deg)", lambda s: s.get("closed_form_rule", {}).get("phase_margin_deg_implied")),
    ("lam by the rule", lambda s: s.get("closed_form_rule", {}).get("lam_rule")),
    ("lam / rule", lambda s: s.get("closed_form_rule", {}).get("lam_over_rule")),
    ("kp by the rule", lambda s: s.get("closed_form_rule", {}).get("kp_rule")),
)


def print_summary(result: dict, out: Path, timing: dict | None = None) -> None:
    """Print a tuning run's table on stdout: gains, linear margins, objective and worst cases of the initial,
    closed-form and tuned designs, then the files written.

    Args:
        result: result.json's content.
        out: The results folder.
        timing: timing.json's content (its ``total_s`` printed), or None.
    """
    g, s, lin = result["gains"], result["scores"], result.get("linear", {})
    designs = ("initial", "closed_form", "tuned")
    heads = "".join(f"{h:>14}" for h in ("initial", "closed form", "tuned"))
    secs = f", {timing['total_s']:.1f} s" if timing and "total_s" in timing else ""
    print(
        f"{result['component']}: {result['status']} after {result['iterations']} iterations{secs}, "
        f"{result['scenarios']['count']} scenarios"
    )
    print(f"  {result['reason']}")
    if result["status"] == "diverged":
        print("DIVERGED: no gains are reported as tuned (every design tried diverged in some tuning scenario)")
    if result["status"] == "overflow":
        print("OVERFLOW: no gains are reported as tuned (the objective is not finite: lower its weights)")
    names = list(g["initial"])
    print(f"{'gain':<22}{heads}")
    for n in names:
        print(f"{n:<22}" + "".join(_fmt((g[d] or {}).get(n)) for d in designs))
    print(f"closed form: {result['closed_form_source']}")
    rows = [(label, [None if lin.get(d) is None else f(lin[d]) for d in designs]) for label, f in _LINEAR_ROWS]
    rows = [(label, vals) for label, vals in rows if any(v is not None for v in vals)]
    if rows:
        print(f"{'linear model':<22}{heads}")
        for label, vals in rows:
            print(f"{label:<22}" + "".join(_fmt(v) for v in vals))
    keys = [k for k in s["initial"] if k not in ("diverged", "lost_lock", "lost_sync", "lost_speed", "null_reason")]
    print(f"{'score':<22}{heads}")
    for k in keys:
        print(f"{k:<22}" + "".join(_fmt((s[d] or {}).get(k)) for d in designs))
    print(f"{'diverged scenarios':<22}" + "".join(_fmt((s[d] or {}).get("diverged"), ">14d") for d in designs))
    print(f"{'lost lock':<22}" + "".join(_fmt((s[d] or {}).get("lost_lock"), ">14d") for d in designs))
    if "lost_sync" in s["initial"]:  # drive jobs: diverged or |position error| > 90 deg
        print(f"{'lost sync scenarios':<22}" + "".join(_fmt((s[d] or {}).get("lost_sync"), ">14d") for d in designs))
    if "lost_speed" in s["initial"]:  # drive jobs: missed the speed reference by > 20 % in the steady window
        print(f"{'lost speed scenarios':<22}" + "".join(_fmt((s[d] or {}).get("lost_speed"), ">14d") for d in designs))
    if "holdout" in result:
        h = result["holdout"]
        worst = {d: (h[d] or {}).get("per_scenario_worst") for d in designs}
        div = {d: (h[d] or {}).get("diverged") for d in designs}
        print(f"{'held-out worst':<22}" + "".join(_fmt(worst[d]) for d in designs) + f"   ({h['count']} scenarios)")
        print(f"{'held-out diverged':<22}" + "".join(_fmt(div[d], ">14d") for d in designs))
        lost = {d: (h[d] or {}).get("lost_lock") for d in designs}
        print(f"{'held-out lost lock':<22}" + "".join(_fmt(lost[d], ">14d") for d in designs))
    for where, n in (result.get("lost_lock_tuned_only") or {}).items():
        if n:
            sets, nc = ("tuning", "scores.nc") if where == "tuning" else ("held-out", "holdout_scores.nc")
            msg = f"warning: the tuned design lost lock in {n} {sets} scenarios where the closed form holds it"
            print(f"jaxobs: {msg} (lost_lock in {nc})", file=sys.stderr)
    for d in designs:  # a drive that missed its speed reference (e.g. ran backwards) is flagged, never silent
        n = (s[d] or {}).get("lost_speed")
        if n:
            print(
                f"jaxobs: warning: the {d.replace('_', ' ')} drive missed its speed reference (> 20 % off, or "
                f"turning against it) in {n} scenarios (lost_speed in scores.nc)",
                file=sys.stderr,
            )
    for name, b in result.get("at_bound", {}).items():
        msg = f"warning: tuned {name} = {b['value']:.6g} is within 1 % of its {b['bound']} bound {b['limit']:g}"
        print(f"jaxobs: {msg}", file=sys.stderr)
    ver = result.get("verification")
    if ver is not None:
        n = {d: v["failed_points"] for d, v in ver["designs"].items()}
        line = ", ".join(f"{d.replace('_', ' ')} fails {k}" for d, k in n.items())
        print(f"verified over {ver['horizon_s']:g} s at {len(ver['points'])} envelope points: {line}")
    if result["status"] == "unsafe":
        print(f"jaxobs: warning: UNSAFE: {result['reason']} (verification in result.json)", file=sys.stderr)
    if result.get("tuning_status", result["status"]) == "budget":
        print(
            f"jaxobs: warning: the solver's budget ran out before its stopping rule ({result['reason']}): "
            "the tuned gains may not be an optimum (raise solver.steps)",
            file=sys.stderr,
        )
    # every file the run wrote beside result.json (the held-out scores and the two figures too, where written)
    beside = ("history.json", "timing.json", "scores.nc", "holdout_scores.nc", "convergence.png", "responses.png")
    print(f"results: {out / 'result.json'} ({', '.join(n for n in beside if (out / n).exists())})")


def study_warnings(ds: Dataset) -> list[str]:
    """One line per design of a study's Dataset (FLL or drive) that diverged, lost lock or (drive studies,
    ``lost_speed_count``) missed its speed reference in any scenario: ``"<design>: diverged in D, lost lock in
    L[, lost speed in S] of N scenarios"``; none for a design that lost nothing.  ``jaxobs study`` prints them
    on stderr after its table, so that a summary piped away still says what was lost.

    Args:
        ds: The study's Dataset.

    Returns:
        The lines, in design order.
    """
    n = int(ds.attrs["scenarios"])
    drive = "lost_speed_count" in ds
    lines = []
    for d in ds["design"].values:
        div, lost = int(ds["diverged"].sel(design=d).sum()), int(ds["lost_lock_count"].sel(design=d))
        speed = int(ds["lost_speed_count"].sel(design=d)) if drive else 0
        if div or lost or speed:
            lines.append(
                f"{d}: diverged in {div}, lost lock in {lost}"
                + (f", lost speed in {speed}" if drive else "")
                + f" of {n} scenarios"
            )
    return lines
