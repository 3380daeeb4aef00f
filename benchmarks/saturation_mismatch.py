"""Every drive observer's closed form over a saturation mismatch on the 5.6-kW PM-SyRM: the worst case per design,
and the designs ranked by how much the mismatch costs them.

``python -m benchmarks.saturation_mismatch [--dsat V ...] [--speeds PU ...] [--load PU] [--designs NAME ...]
[--result RESULT.json] [--ascent N] [--ascent-designs NAME ...] [--json FILE]``

One drive study (:func:`jaxobs.studies.study.run_study` on :class:`jaxobs.scenarios.families.drive.DriveScenarios`,
float64) of the drive file ``docs/examples/pmsyrm_5p6kw_sat.toml`` (Hinkkanen et al. 2017's algebraic flux map,
8 kHz, sensorless): every design on the grid ``dsat`` × speed at a constant load, each run started steady, scored
over its steady window.  ``dsat`` = v makes the true machine saturate (1 + v) times as much (the map's a_dd, a_qq,
a_dq scaled) while the controller and the observers keep the nominal machine: the rated-secant constants, and the
reduced-order flux observer, whose current model is the map (jaxobs/observers/rofo.py), the nominal map
(docs/studies.md).

Printed per design: the steady peak and rms electrical position error at dsat = 0 (each speed's worst), the worst
over the grid and where, the sensitivity (worst peak minus the worst peak at dsat = 0) and the lost-lock count; the
designs ranked by sensitivity (a design that loses lock anywhere ranks first, by its lost scenarios).

``--result RESULT.json`` adds a tuning result's design (``jaxobs_tuning.results.load_result`` + ``tuned_component``)
as ``<component>_tuned`` beside the closed forms.  ``--ascent N`` finds every design's worst case by gradients
(``--ascent-designs``: some of them; :mod:`benchmarks.saturation_worst`): N rounds of a projected gradient ascent
of the steady rms position error over dsat in :data:`ASCENT_BOX` at each speed, from the grid points that held
lock, its forward-mode derivatives checked against central differences at every start and at the worst found (a
start where they disagree, the metric not smooth there, is not climbed; a loss of lock is reported as such); the
designs ranked by the mismatch's lost scenarios, then by the rise of their worst rms over dsat = 0.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
DRIVE = ROOT / "docs" / "examples" / "pmsyrm_5p6kw_sat.toml"
DSAT = (-0.5, 0.0, 0.5, 1.0, 2.0)  # the mismatch grid (−0.5: half the map's saturation; 2: three times)
# of rated speed (1800 r/min): 900 and 1440 r/min.  Not 30 %: at 540 r/min and rated load every family but the
# reduced-order flux observer (the one that models the map) loses lock with dsat = 0 already
SPEEDS_PU = (0.5, 0.8)
LOAD_PU = 1.0  # of rated torque (29.7 N·m)
HORIZON = 0.2  # s; each run starts steady (the observer settled 0.2 s before t = 0), scored from horizon/2
ASCENT_BOX = (-0.5, 2.0)  # the gradient ascent's dsat range
FAMILIES = ("rofo", "cleso", "gileso", "faleso", "soifo", "soifo2", "lpf")


def closed_forms(ts: float) -> dict[str, Any]:
    """Every drive observer family's closed form at the sampling period ``ts``, by name."""
    import jaxobs
    from jaxobs.observers import CLESO, FALESO, GILESO, SOIFO, LPFFlux, SecondOrderSOIFO

    return {
        "rofo": jaxobs.ReducedOrderFluxObserver.closed_form(ts=ts),
        "cleso": CLESO.closed_form(ts=ts),
        "gileso": GILESO.closed_form(ts=ts),
        "faleso": FALESO.closed_form(ts=ts),
        "soifo": SOIFO.closed_form(ts=ts),
        "soifo2": SecondOrderSOIFO.closed_form(ts=ts),
        "lpf": LPFFlux.closed_form(ts=ts),
    }


def tuned_design(path: Path, ts: float) -> tuple[str, Any, dict]:
    """A tuning result's design, named ``<family>_tuned`` (the family of :func:`closed_forms` of its class), and its
    job's scenario grid (axis -> values)."""
    from jaxobs_tuning.results import load_result, tuned_component

    res = load_result(path)
    comp = tuned_component(res)
    family = next((k for k, v in closed_forms(ts).items() if type(v) is type(comp)), type(comp).__name__.lower())
    return f"{family}_tuned", comp, res["job"].get("scenarios", {}).get("grid", {})


def study(designs: dict[str, Any], dsat, speeds_rpm, load_nm: float) -> dict[str, dict]:
    """Run the one study; per design its grid of steady peak / rms position error (deg) and lost-lock flags."""
    import numpy as np

    from jaxobs.drive import Drive, read_drive
    from jaxobs.scenarios.families.drive import DriveScenarios
    from jaxobs.studies.study import run_study

    f = read_drive(DRIVE)
    drive = f.drive_for(sensorless=True)
    if not isinstance(drive, Drive):
        raise ValueError(f"{DRIVE}: a [dual] drive file; the benchmark runs a single machine's drive")
    family = DriveScenarios(f.machine, drive)
    axes = {"dsat": list(dsat), "speed_rpm": list(speeds_rpm), "load_nm": [load_nm]}
    ds = run_study(designs, axes, family=family, horizon=HORIZON)
    assert not isinstance(ds, tuple)
    out = {}
    for i, name in enumerate(designs):
        pick = {"design": i, "load_nm": 0}
        out[name] = {
            "peak_deg": np.degrees(ds["peak_position_steady"].isel(pick).values).tolist(),
            "rms_deg": np.degrees(ds["rms_position_steady"].isel(pick).values).tolist(),
            "lost_lock": ds["lost_lock"].isel(pick).values.astype(bool).tolist(),
        }
    return out


def summarize(grid: dict, dsat, speeds_rpm) -> dict:
    """One design's worst case over the grid (dims dsat × speed), its dsat = 0 value and its sensitivity."""
    import numpy as np

    peak, rms, lost = np.array(grid["peak_deg"]), np.array(grid["rms_deg"]), np.array(grid["lost_lock"])
    i0 = list(dsat).index(0.0)
    where_lost = [(float(dsat[a]), float(speeds_rpm[b])) for a, b in zip(*np.nonzero(lost), strict=True)]
    held = np.where(lost, -np.inf, peak)
    a, b = np.unravel_index(int(np.argmax(held)), held.shape)

    def top(x, mask):  # the largest among the scenarios that kept lock (nan: none did)
        return float(np.max(x[~mask])) if (~mask).any() else math.nan

    worst, nominal = top(peak, lost), top(peak[i0], lost[i0])
    return {
        "nominal_peak_deg": nominal,
        "nominal_rms_deg": top(rms[i0], lost[i0]),
        "worst_peak_deg": worst,
        "worst_rms_deg": top(rms, lost),
        "worst_at": {"dsat": float(dsat[a]), "speed_rpm": float(speeds_rpm[b])},
        "sensitivity_deg": worst - nominal,
        "lost_lock": where_lost,
        "lost_by_mismatch": sum(1 for d, r in where_lost if d != 0.0 and (0.0, r) not in where_lost),
        "speeds_rpm": [float(r) for r in speeds_rpm],
    }


def rank(summary: dict) -> list[str]:
    """The designs, most sensitive first: by the scenarios the mismatch loses (lost at some dsat != 0 at a speed that
    held at dsat = 0: lock lost is the worst an observer can do), then by the sensitivity."""

    def key(name):
        s = summary[name]
        return (-s["lost_by_mismatch"], -s["sensitivity_deg"] if math.isfinite(s["sensitivity_deg"]) else 0.0)

    return sorted(summary, key=key)


def compare(tuned: str, grids: dict, dsat, speeds_rpm, job_grid: dict) -> list[dict]:
    """Print the tuned design beside its family's closed form per scenario, each marked in or out of its job's grid
    (``*``: out); return the rows."""
    family = tuned.removesuffix("_tuned")
    print(f"{tuned} against {family} (closed form), steady peak / rms deg; * = outside the job's grid:")
    rows = []
    for i, v in enumerate(dsat):
        for j, r in enumerate(speeds_rpm):
            inside = v in job_grid.get("dsat", [v]) and r in job_grid.get("speed_rpm", [r])
            cells = []
            for k in (family, tuned):
                g = grids[k]
                lost = g["lost_lock"][i][j]
                cells.append("lost lock" if lost else f"{g['peak_deg'][i][j]:.2f} / {g['rms_deg'][i][j]:.2f}")
                rows.append({"design": k, "dsat": v, "speed_rpm": r, "in_grid": inside, "lost_lock": lost,
                             "peak_deg": g["peak_deg"][i][j], "rms_deg": g["rms_deg"][i][j]})  # fmt: skip
            print(f"  {'' if inside else '*':1} dsat {v:5g} {r:6g} r/min  {cells[0]:>16}  {cells[1]:>16}")
    return rows


def gradient_worst(designs: dict, grids: dict, dsat, speeds_rpm, load_nm: float, iters: int, names) -> dict:
    """The worst case by gradients per design (:mod:`benchmarks.saturation_worst`), printed; the designs ranked by it.

    Args:
        designs: name -> observer (the study's).
        grids: name -> the study's grid of that design.
        dsat: The grid's dsat values.
        speeds_rpm: The grid's speeds.
        load_nm: The load.
        iters: The ascent's line-search rounds.
        names: The designs to climb (None: all).

    Returns:
        name -> the ascent's findings and its sensitivity; ``ranking`` and ``most_sensitive``.
    """
    from jaxobs.drive import Drive, read_drive
    from jaxobs.scenarios.families.drive import DriveScenarios

    from . import saturation_worst as W

    f = read_drive(DRIVE)
    drive = f.drive_for(sensorless=True)
    assert isinstance(drive, Drive)
    family = DriveScenarios(f.machine, drive)
    names = [k for k in designs if names is None or k in names]
    found, sens = {}, {}
    for k in names:
        ev = W.Evaluator(family, designs[k], speeds_rpm, load_nm, HORIZON, W.BATCH)
        found[k] = W.climb(ev, grids[k], dsat, ASCENT_BOX, iters)
        sens[k] = W.sensitivity(found[k], grids[k], dsat, speeds_rpm)
    order = W.rank_by_gradient(sens)
    took = ", ".join(f"{k} {found[k]['seconds']:.0f} s" for k in names)
    print(f"ascent per design (compilation included): {took}")
    print(f"worst case by gradients: steady rms position error (deg) over dsat in {list(ASCENT_BOX)} at each speed,")
    print(
        f"{iters} rounds of projected gradient ascent (Armijo line search) from every held grid point; d rms / d dsat"
    )
    print(f"by forward mode (AD) against central differences (FD, h = {W.FD_STEP:g}); rough: they differ by more than")
    print(
        f"{W.SMOOTH_RTOL:.0%} + {W.SMOOTH_ATOL:g} deg/unit (not climbed); v-lim: share of periods at the voltage limit"
    )
    print(f"  {'design':<12}{'dsat':>6}{'r/min':>7}{'rms':>8}{'peak':>8}{'AD':>11}{'FD':>11}{'v-lim':>7}  verdict")
    for k in order:
        w = found[k]["worst"]
        for tag, r in [("", r) for r in found[k]["starts"]] + ([("worst", w)] if w is not None else []):
            verdict = "lost lock" if r["lost_lock"] else ("smooth" if r["smooth"] else "rough")
            verdict += " (minimum)" if r["minimum"] and not r["smooth"] else ""
            print(f"  {k if tag == '' else k + ' worst':<12}{r['dsat']:6.3g}{r['speed_rpm']:7g}{r['rms_deg']:8.2f}"
                  f"{r['peak_deg']:8.2f}{r['ad']:11.4g}{r['fd']:11.4g}{r['at_v_limit']:7.1%}  {verdict}")  # fmt: skip
    i0 = list(dsat).index(0.0)
    print("designs ranked by gradients (lost by the mismatch first, then by sens = worst held rms - rms at dsat 0 at")
    print("the same speed); worst: the grid's and the ascent's, (dsat, r/min):")
    print(
        f"  {'design':<12}{'rms@0 by speed':>16}  {'grid worst':<22}{'gradient worst':<22}{'sens':>7}  lost by mismatch"
    )
    for k in order:
        g, z, fw = grids[k], sens[k], found[k]["worst"]
        at0 = "/".join(
            "lost" if g["lost_lock"][i0][j] else f"{g['rms_deg'][i0][j]:.2f}" for j in range(len(speeds_rpm))
        )
        gw = _grid_worst_rms(g, dsat, speeds_rpm)
        fws = "no smooth start" if fw is None else f"{fw['rms_deg']:.2f} ({fw['dsat']:.3g}, {fw['speed_rpm']:g})"
        lost = ", ".join(f"({d:.3g}, {r:g})" for d, r in z["lost_by_mismatch"]) or "-"
        lost = lost if math.isfinite(z["sensitivity_deg"]) else "no reference: lost at dsat 0 at every speed"
        print(f"  {k:<12}{at0:>16}  {gw:<22}{fws:<22}{z['sensitivity_deg']:7.2f}  {lost}")
    held_max = {k: _worst_held(grids[k], found[k]["worst"]) for k in order}
    by_worst = sorted((k for k in order if math.isfinite(held_max[k])), key=lambda k: -held_max[k])
    print("by the worst held rms alone (grid or gradient, any speed):", end=" ")
    print(", ".join(f"{k} {held_max[k]:.2f}" for k in by_worst))
    top = sens[order[0]]
    if top["lost_by_mismatch"]:
        d, r = top["lost_by_mismatch"][0]
        why = f"loses lock at dsat {d:.3g}, {r:g} r/min; {len(top['lost_by_mismatch'])} scenarios lost by the mismatch"
    else:
        why = f"worst rms {top['worst_rms_deg']:.2f} deg by the {top['by']}, at dsat {top['at']['dsat']:.3g}, " \
              f"{top['at']['speed_rpm']:g} r/min; sens {top['sensitivity_deg']:.2f} deg"  # fmt: skip
    print(f"most sensitive: {order[0]} ({why})")
    held = [k for k in order if not sens[k]["lost_by_mismatch"]]
    if held and held[0] != order[0]:
        h = sens[held[0]]
        print(
            f"most sensitive that holds lock: {held[0]} (worst rms {h['worst_rms_deg']:.2f} deg by the {h['by']}, at "
            f"dsat {h['at']['dsat']:.3g}, {h['at']['speed_rpm']:g} r/min; sens {h['sensitivity_deg']:.2f} deg)"
        )
    return {"designs": {k: {**found[k], **sens[k]} for k in names}, "ranking": order, "most_sensitive": order[0]}


def _worst_held(g: dict, found_worst: dict | None) -> float:
    """The largest rms among the grid's held scenarios and the ascent's worst (if held); nan: none held."""
    rows = zip(g["rms_deg"], g["lost_lock"], strict=True)
    xs = [x for row, lk in rows for x, b in zip(row, lk, strict=True) if not b]
    if found_worst is not None and not found_worst["lost_lock"]:
        xs.append(found_worst["rms_deg"])
    return max(xs) if xs else math.nan


def _grid_worst_rms(g: dict, dsat, speeds_rpm) -> str:
    """The grid's worst held rms and where, as text."""
    cells = [(g["rms_deg"][i][j], v, r) for i, v in enumerate(dsat) for j, r in enumerate(speeds_rpm)
             if not g["lost_lock"][i][j]]  # fmt: skip
    if not cells:
        return "all lost"
    x, v, r = max(cells)
    return f"{x:.2f} ({v:g}, {r:g})"


def main(argv: list[str] | None = None) -> int:
    """Run the study (and the ascent), print the table, write ``--json``."""
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.saturation_mismatch", description=(__doc__ or "").split("\n")[0]
    )
    ap.add_argument("--dsat", type=float, nargs="+", default=list(DSAT))
    ap.add_argument("--speeds", type=float, nargs="+", default=list(SPEEDS_PU), help="of rated speed")
    ap.add_argument("--load", type=float, default=LOAD_PU, help="of rated torque")
    ap.add_argument("--designs", nargs="+", choices=FAMILIES, default=list(FAMILIES))
    ap.add_argument("--result", type=Path, help="a tuning result.json: its design added as <component>_tuned")
    ap.add_argument("--ascent", type=int, default=0, help="gradient-ascent rounds per design (worst case by gradients)")
    ap.add_argument("--ascent-designs", nargs="+", help="the designs the ascent runs (default: every design studied)")
    ap.add_argument("--json", type=Path)
    a = ap.parse_args(argv)
    if 0.0 not in a.dsat:
        ap.error("--dsat must include 0 (the nominal machine, the sensitivity's reference)")
    if not all(-1.0 <= v <= 10.0 for v in a.dsat):
        ap.error("--dsat values must be in [-1, 10]")

    import jax

    jax.config.update("jax_enable_x64", True)
    from jaxobs.drive import read_drive

    f = read_drive(DRIVE)
    drive = f.drive_for(sensorless=True)
    rated_rpm, rated_nm = float(f.machine.n_rated), float(f.machine.T_rated)
    speeds = [s * rated_rpm for s in a.speeds]
    load = a.load * rated_nm
    designs = {k: v for k, v in closed_forms(drive.ts).items() if k in a.designs}
    if a.result is not None:
        tuned, comp, job_grid = tuned_design(a.result, drive.ts)
        designs[tuned] = comp
    if a.ascent < 0:
        ap.error("--ascent must be >= 0 (rounds)")
    unknown = sorted(set(a.ascent_designs or ()) - set(designs))
    if unknown:
        ap.error(f"--ascent-designs: {', '.join(unknown)} not studied; allowed: {', '.join(designs)}")
    t0 = time.time()
    grids = study(designs, a.dsat, speeds, load)
    seconds = time.time() - t0
    summary = {k: summarize(g, a.dsat, speeds) for k, g in grids.items()}
    order = rank(summary)

    print(f"{DRIVE.relative_to(ROOT)}: sensorless, {load:.3g} N·m, speeds {', '.join(f'{s:g}' for s in speeds)} r/min,")
    print(f"dsat {', '.join(f'{v:g}' for v in a.dsat)}; {HORIZON} s runs started steady, scored from {HORIZON / 2} s;")
    print(f"one study, {len(designs)} designs x {len(a.dsat) * len(speeds)} scenarios, {seconds:.0f} s (float64)")
    print("steady position error, electrical deg (@0: dsat = 0, both speeds' worst; worst: over the grid, among the")
    print("scenarios that kept lock; sens: worst - @0; by mism.: scenarios lost at dsat != 0 where dsat = 0 held)")
    print(f"{'design':<14}{'peak@0':>8}{'rms@0':>7}{'worst pk':>9}{'rms':>7}{'  at dsat, rpm':<16}{'sens':>7}", end="")
    print(f"{'by mism.':>9}  lost lock (dsat, r/min)")
    for k in order:
        s = summary[k]
        at = f"  {s['worst_at']['dsat']:g}, {s['worst_at']['speed_rpm']:g}"[:16]
        lost = ", ".join(f"({d:g}, {r:g})" for d, r in s["lost_lock"]) or "-"
        print(
            f"{k:<14}{s['nominal_peak_deg']:8.2f}{s['nominal_rms_deg']:7.2f}{s['worst_peak_deg']:9.2f}"
            f"{s['worst_rms_deg']:7.2f}{at:<16}{s['sensitivity_deg']:7.2f}{s['lost_by_mismatch']:9d}  {lost}"
        )
    print("per scenario steady peak (deg), by dsat, at each speed:")
    for k in order:
        rows = "; ".join(
            f"{v:g}: " + " ".join(f"{x:.2f}" if not lk else "lost" for x, lk in zip(p, lo, strict=True))
            for v, p, lo in zip(a.dsat, grids[k]["peak_deg"], grids[k]["lost_lock"], strict=True)
        )
        print(f"  {k:<12} {rows}")
    closed = [k for k in order if not k.endswith("_tuned")]
    print(f"most sensitive closed form: {closed[0]}")
    out: dict[str, Any] = {
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "load_average": list(os.getloadavg()),  # the shared machine's load, as uptime prints it
        "drive": str(DRIVE.relative_to(ROOT)),
        "load_nm": load,
        "speeds_rpm": speeds,
        "dsat": a.dsat,
        "horizon_s": HORIZON,
        "seconds": seconds,
        "grids": grids,
        "summary": summary,
        "ranking": order,
        "most_sensitive": closed[0],
    }
    if a.result is not None:
        out["tuned"] = compare(tuned, grids, a.dsat, speeds, job_grid)
    if a.ascent:
        out["gradient"] = gradient_worst(designs, grids, a.dsat, speeds, load, a.ascent, a.ascent_designs)
    if a.json:
        a.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
