"""Sensorless through zero speed on the 2.2-kW lab IPMSM: each observer family's lowest speed that holds a 50 % load
step, its standstill hold, and its slowest held ±750 r/min reversal (docs/through-zero.md).

``python -m benchmarks.through_zero [--designs NAME ...] [--json FILE] [--traces DIR]``
``python -m benchmarks.through_zero --traces DIR --figures DIR --figures-of NAME ...`` (figures from kept traces)

Every run is the drive file ``docs/examples/ipmsm_2p2kw_lab.toml``'s sensorless drive (8 kHz, ideal sensors,
steady start), its observer's closed form, judged by :func:`jaxobs.analysis.verdict.verdict` (one state per
run).  Per design:

- **lowest held speed under a 50 % load step**: one batched run at each speed of :data:`SPEEDS_PU` × rated
  speed, 0.5 × rated torque stepped on at :data:`T_EVENT` (:func:`jaxobs.drive.low_speed_load_step`); lock judged
  from the step, the speed from :data:`RECOVER` s after it (the issue's "back within 10 % within 0.5 s" is the
  recovery this window starts from) to :data:`T_END`.  The lowest held speed is the lowest one from which every
  faster speed holds as well.  The same batch holds the standstill run (:func:`jaxobs.drive.standstill_hold`,
  the same step at zero speed).
- **slowest held reversal**: :func:`jaxobs.analysis.verdict.held_rate` over ramp rates :data:`RATES` (r/min per
  second) of ±750 r/min reversals without load, to :data:`RESOLUTION`, each probe one batched run
  (:func:`jaxobs.analysis.verdict.reversal_holds`, one horizon for every probe); then the same under a constant
  50 % load where some unloaded reversal held.

Traces (with ``--traces``) and figures (``--figures``, from the traces kept): each design's ±750 r/min reversal
in 1 s and its 15 r/min load step, speed and angle error against time.  The numbers are printed as a table and
written with ``--json``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LAB = ROOT / "docs" / "examples" / "ipmsm_2p2kw_lab.toml"
SPEEDS_PU = (1.0, 0.5, 0.2, 0.1, 0.05, 0.02, 0.01, 0.005)  # of rated speed (1500 r/min)
LOAD_PU = 0.5  # of rated torque (14 N·m)
T_EVENT = 0.2  # the load step, s
RECOVER = 0.5  # the settled window opens this long after the step, s
T_END = 1.5  # s
REV_RPM = 750.0  # the reversal's speed, ±r/min
RATES = (150.0, 15000.0)  # the search range, r/min per second: a ±750 r/min reversal in 10 s to one in 0.1 s
RESOLUTION = 0.1  # the search's relative resolution
PROBES = 3  # rates per probe inside the bracket
REV_START = 0.2  # the ramp's start, s
REV_SETTLE = 1.0  # after the slowest ramp, s


# The LESOs' through-zero options (jaxobs.observers.leso, jaxobs.observers.speed), at the values
# tests/test_zero_speed.py uses: the faded phase detector's ω_f and the mechanical speed observer's bandwidth.
ZERO_FADE = 20.0  # rad/s
ALPHA_O = 2 * math.pi * 10.0  # rad/s: the triple pole of MechanicalSpeed.closed_form
# The reduced-order flux observer with the mechanical speed observer: the closed form of its tuning job
# (docs/examples/ipmsm_2p2kw_rofo_tune.toml, [observer.speed] kind = "mechanical": the triple pole at 2π·50 rad/s,
# the type-2 loop's closed-form pole) and, where its stored result exists, that job's tuned design.
ROFO_ALPHA_O = 2 * math.pi * 50.0  # rad/s
ROFO_TUNED = ROOT / "benchmarks" / "results" / "2026-12-02-rofo-tune-result.json"
# The other families' tuned designs on the lab drive, each of its job in docs/examples/lab_<family>_mech_tune.toml
# (its closed form: this benchmark's "<family>_mech" row, the mechanical model's triple pole at ALPHA_O and the
# faded detector), run where the stored result exists.  The GI-LESO's job found nothing better than its closed form
# (benchmarks/results/2026-12-03-lab-gileso-mech-tune.txt), so it has no tuned row.
TUNED = {
    f"{family}_mech_tuned": ROOT / "benchmarks" / "results" / f"2026-12-03-lab-{family}-mech-tune-result.json"
    for family in ("faleso", "cleso", "lpf")
}


def designs(ts: float) -> dict:
    """The closed forms run here, by name: each (a drive observer, unbound; the relative error of the R̂s it and
    the controller assume).  The error rows show what an exact model hides: at zero speed the reduced-order
    observer's angle is unobservable (its flux poles are 0 and −2σ0), so with R̂s = Rs nothing moves it there."""
    import jaxobs
    from jaxobs.observers import CLESO, FALESO, GILESO, SOIFO, LPFFlux
    from jaxobs.observers.speed import MechanicalSpeed

    rofo = jaxobs.ReducedOrderFluxObserver.closed_form(ts=ts)
    mech = MechanicalSpeed.closed_form(ALPHA_O)  # Ĵ, B̂ and p are bound from the assumed machine
    rofo_mech = jaxobs.ReducedOrderFluxObserver.closed_form(ts=ts, speed=MechanicalSpeed.closed_form(ROFO_ALPHA_O))
    tuned = {}
    if ROFO_TUNED.exists():  # the job's tuned design, built as its run scored it (benchmarks.peer_observer)
        from benchmarks.peer_observer import result_designs_of

        tuned["rofo_mech_tuned"] = (result_designs_of(ROFO_TUNED)["tuned"], 0.0)
    from jaxobs_tuning.results import load_result, tuned_component

    for name, path in TUNED.items():
        if path.exists():
            tuned[name] = (tuned_component(load_result(path)), 0.0)
    return {
        "rofo": (rofo, 0.0),
        "rofo_rs+20": (rofo, 0.2),
        "rofo_rs-20": (rofo, -0.2),
        "cleso": (CLESO.closed_form(ts=ts), 0.0),
        "gileso": (GILESO.closed_form(ts=ts), 0.0),
        "faleso": (FALESO.closed_form(ts=ts), 0.0),
        "faleso_fade": (FALESO.closed_form(ts=ts, zero_fade=ZERO_FADE), 0.0),
        "cleso_mech": (CLESO.closed_form(ts=ts, speed=mech, zero_fade=ZERO_FADE), 0.0),
        "gileso_mech": (GILESO.closed_form(ts=ts, speed=mech, zero_fade=ZERO_FADE), 0.0),
        "faleso_mech": (FALESO.closed_form(ts=ts, speed=mech, zero_fade=ZERO_FADE), 0.0),
        "soifo": (SOIFO.closed_form(ts=ts), 0.0),
        "lpf_mech": (LPFFlux.closed_form(ts=ts, speed=mech), 0.0),
        "rofo_mech": (rofo_mech, 0.0),
        "rofo_mech_rs+20": (rofo_mech, 0.2),
        "rofo_mech_rs-20": (rofo_mech, -0.2),
        **tuned,
    }


def run_design(name, design, par, drive, figures):
    """One design's numbers (and its figures' traces)."""
    import equinox as eqx
    import jax
    import numpy as np

    import jaxobs
    from jaxobs import drive as D
    from jaxobs import metrics
    from jaxobs.analysis.verdict import held_rate, reversal_holds, verdict, verdict_names, verdict_of

    obs, d_rs = design
    est = eqx.tree_at(lambda q: q.Rs, par, par.Rs * (1.0 + d_rs))
    base = D.Scenario(par, est_par=est)
    scs = [D.low_speed_load_step(base, s, LOAD_PU, t_event=T_EVENT) for s in SPEEDS_PU]
    scs.append(D.standstill_hold(base, LOAD_PU, t_event=T_EVENT))
    batch = D.stack_scenarios(scs)

    # every run starts steady after the observer's settling phase, SETTLE_PERIODS electrical periods at the
    # lowest speed the batch starts at (Drive.settled_for, as the envelope does: the flux observers' time
    # constants scale with 1/ωe; the phase is cheap, observer steps on synthetic measurements)
    step_drive = drive.settled_for(par.p * min(SPEEDS_PU) * float(par.n_rated) * D.RPM)
    rev_drive = drive.settled_for(par.p * REV_RPM * D.RPM)

    def loop(sc, drive=step_drive):
        return D.ClosedLoop(drive, obs.bind(sc.est_par, sc.est_par.p * sc.omega_m0), sc)

    t0 = time.time()

    @jax.jit
    def steps(b):
        sol = jax.vmap(lambda sc: jaxobs.simulate(loop(sc), T_END))(b)
        v = verdict_of(sol, T_EVENT, T_EVENT + RECOVER)
        o = sol.outputs
        i15 = SPEEDS_PU.index(0.01)
        trace = (o.t[i15], o.omega_m[i15], o.omega_m_ref[i15], o.obs.theta[i15] - o.theta_e[i15])
        return v, jax.numpy.min(o.omega_m, axis=-1), trace

    v, w_min, trace15 = steps(batch)
    states = np.asarray(v.state)
    names = list(verdict_names(states))
    held = states[: len(SPEEDS_PU)] == 0
    lowest = None
    for i in range(len(SPEEDS_PU)):
        if held[: i + 1].all():
            lowest = SPEEDS_PU[i]
    rated = float(par.n_rated)
    step = {
        "speeds_rpm": [s * rated for s in SPEEDS_PU],
        "verdicts": names[: len(SPEEDS_PU)],
        "peak_angle_deg": [float(x) for x in np.asarray(v.peak_angle_deg)[: len(SPEEDS_PU)]],
        "min_rpm": [float(x) / D.RPM for x in np.asarray(w_min)[: len(SPEEDS_PU)]],
        "lowest_held_rpm": None if lowest is None else lowest * rated,
        "standstill": {
            "verdict": names[-1],
            "peak_angle_deg": float(np.asarray(v.peak_angle_deg)[-1]),
            "mean_speed_err_rpm": float(np.asarray(v.speed_err)[-1]) / D.RPM,
        },
        "seconds": time.time() - t0,
    }
    horizon = REV_START + 2 * REV_RPM / RATES[0] + REV_SETTLE

    def search(load_nm):
        t0 = time.time()
        states_at = reversal_holds(
            rev_drive, obs, base, REV_RPM, load_nm=load_nm, t_start=REV_START, settle=REV_SETTLE, horizon=horizon
        )
        r = held_rate(*RATES, states_at=states_at, resolution=RESOLUTION, probes=PROBES)
        return {
            "load_nm": load_nm,
            "slowest_held_rpm_s": None if np.isnan(r.rate) else r.rate,
            "fastest_failing_rpm_s": None if np.isnan(r.other) else r.other,
            "resolution": None if np.isnan(r.resolution) else r.resolution,
            "probed_rpm_s": [float(x) for x in r.rates],
            "probed_verdicts": list(verdict_names(r.states)),
            "probes": r.probes,
            "monotone": r.monotone,
            "seconds": time.time() - t0,
        }

    rev = search(0.0)
    # under a 50 % load only where some unloaded reversal held (one that fails unloaded is not rerun loaded)
    rev_loaded = search(LOAD_PU * float(par.T_rated)) if rev["slowest_held_rpm_s"] is not None else None
    out = {"load_step": step, "reversal": rev, "reversal_loaded": rev_loaded}
    traces = None
    if figures:  # the traces
        t0 = time.time()
        sc = D.reversal(base, REV_RPM, 2 * REV_RPM / 1.0, t_start=REV_START)
        o = jax.jit(lambda s: jaxobs.simulate(loop(s, rev_drive), REV_START + 1.0 + REV_SETTLE).outputs)(sc)
        e = np.degrees(np.asarray(metrics.wrap(o.obs.theta - o.theta_e)))
        v1 = verdict(o.t, np.radians(e), o.omega_m, o.omega_m_ref, REV_START, REV_START + 1.0 + 0.5 * REV_SETTLE)
        rev["one_second"] = {"verdict": str(verdict_names(v1.state)), "peak_angle_deg": float(v1.peak_angle_deg)}
        traces = {
            "reversal_1s": (np.asarray(o.t), np.asarray(o.omega_m) / D.RPM, np.asarray(o.omega_m_ref) / D.RPM, e),
            "step_15rpm": (
                np.asarray(trace15[0]),
                np.asarray(trace15[1]) / D.RPM,
                np.asarray(trace15[2]) / D.RPM,
                np.degrees(np.asarray(metrics.wrap(trace15[3]))),
            ),
        }
        rev["figure_seconds"] = time.time() - t0
    return out, traces


LABELS = {
    "rofo": "reduced-order flux observer",
    "rofo_rs+20": "reduced-order, R̂s +20 %",
    "rofo_rs-20": "reduced-order, R̂s −20 %",
    "cleso": "C-LESO + PLL",
    "gileso": "GI-LESO + PLL",
    "faleso": "FA-LESO + PLL",
    "faleso_fade": "FA-LESO + PLL, faded detector",
    "cleso_mech": "C-LESO + mechanical",
    "gileso_mech": "GI-LESO + mechanical",
    "faleso_mech": "FA-LESO + mechanical",
    "soifo": "SOIFO (active flux)",
    "lpf_mech": "LPF flux + mechanical",
    "rofo_mech": "reduced-order + mechanical",
    "rofo_mech_rs+20": "rofo + mechanical, R̂s +20 %",
    "rofo_mech_rs-20": "rofo + mechanical, R̂s −20 %",
    "rofo_mech_tuned": "reduced-order + mech., tuned",
    "faleso_mech_tuned": "FA-LESO + mechanical, tuned",
    "cleso_mech_tuned": "C-LESO + mechanical, tuned",
    "lpf_mech_tuned": "LPF flux + mech., tuned",
}


def figure(traces: dict, key: str, title: str, path: Path) -> None:
    """Speed and angle error of every design's run ``key`` against time, one column per design."""
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(traces)
    fig, axes = plt.subplots(2, len(names), figsize=(3.2 * len(names), 4.6), sharex=True, squeeze=False)
    for j, name in enumerate(names):
        t, w, wr, e = traces[name][key]
        ax = axes[0, j]
        ax.plot(t, wr, "k--", lw=0.8, label="reference")
        ax.plot(t, w, lw=1.0, label="speed")
        ax.set_title(LABELS.get(name, name), fontsize=9)
        ax.set_ylabel("speed (r/min)" if j == 0 else "")
        ax.grid(alpha=0.3)
        ax = axes[1, j]
        ax.plot(t, e, lw=0.8, color="C3")
        ax.set_ylabel("angle error (° el.)" if j == 0 else "")
        ax.set_xlabel("t (s)")
        if not np.nanmax(np.abs(e)) <= 20:  # a lost lock: the whole circle
            ax.set_ylim(-185, 185)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _rate_text(rev) -> str:
    """A reversal search's result as text."""
    if rev is None:
        return "not run"
    slow = rev["slowest_held_rpm_s"]
    if slow is None:
        held = [round(r) for r, v in zip(rev["probed_rpm_s"], rev["probed_verdicts"]) if v == "holds"]
        # held at slow rates only: the search's premise (fast ones hold) fails; the rates that held are named
        return "none held" if not held else "only " + ",".join(map(str, sorted(held))) + " *"
    odd = "" if rev["monotone"] else " *"  # the probes changed verdict more than once
    if rev["fastest_failing_rpm_s"] is None:
        return f"<= {slow:.0f} (bound){odd}"
    return f"{slow:.0f} ({rev['fastest_failing_rpm_s']:.0f} fails){odd}"


def table(results: dict) -> str:
    """The results as a text table (rates in r/min per second)."""
    rows = [
        f"{'design':<30} {'lowest held, 50 % step':>22} {'peak° there':>11} {'standstill 50 %':>15} "
        f"{'slowest held reversal':>22} {'... under 50 %':>20} {'1 s reversal':>14}"
    ]
    for name, r in results.items():
        st, rev = r["load_step"], r["reversal"]
        low = st["lowest_held_rpm"]
        peak = st["peak_angle_deg"][st["speeds_rpm"].index(low)] if low is not None else float("nan")
        one = rev.get("one_second", {}).get("verdict", "-")
        rows.append(
            f"{LABELS.get(name, name):<30} {('none' if low is None else f'{low:g} r/min'):>22} {peak:>10.2f}° "
            f"{st['standstill']['verdict']:>15} {_rate_text(rev):>22} {_rate_text(r.get('reversal_loaded')):>20} "
            f"{one:>14}"
        )
    rows.append("rates in r/min per second; * the probes changed verdict more than once (not monotone in the rate)")
    return "\n".join(rows)


def save_traces(folder: Path, name: str, traces: dict) -> None:
    """A design's traces, every 4th sample (2 kHz: the figures' resolution), to ``folder/name.npz``."""
    import numpy as np

    folder.mkdir(parents=True, exist_ok=True)
    flat = {f"{key}__{i}": np.asarray(x)[::4] for key, tr in traces.items() for i, x in enumerate(tr)}
    np.savez_compressed(folder / f"{name}.npz", **flat)


def load_traces(folder: Path, names) -> dict:
    """The traces :func:`save_traces` wrote, for ``names`` (those with a file)."""
    import numpy as np

    out = {}
    for name in names:
        path = folder / f"{name}.npz"
        if path.exists():
            z = np.load(path)
            keys = sorted({k.split("__")[0] for k in z.files})
            out[name] = {k: tuple(z[f"{k}__{i}"] for i in range(4)) for k in keys}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--designs", nargs="+", help="the designs to run (default: all; none with --figures-of)")
    ap.add_argument("--json", type=Path, help="write the numbers to this file (merged into it if it exists)")
    ap.add_argument("--traces", type=Path, help="keep each design's traces in this folder (NAME.npz)")
    ap.add_argument("--figures", type=Path, help="draw the figures into this folder from the --traces folder")
    ap.add_argument("--figures-of", nargs="+", default=[], help="the designs the figures show, in order")
    ap.add_argument("--table", action="store_true", help="run nothing: print the table of --json")
    args = ap.parse_args(argv)
    if args.figures is not None and (args.traces is None or not args.figures_of):
        ap.error("--figures needs --traces and --figures-of")
    import jax

    jax.config.update("jax_enable_x64", True)
    from jaxobs.drive.drivefile import read_drive

    f = read_drive(LAB)
    par, drive = f.machine, f.drive_for(sensorless=True)
    all_designs = designs(drive.ts)
    if args.designs is not None:
        chosen = args.designs
    else:
        chosen = [] if (args.figures_of or args.table) else list(all_designs)
    unknown = [d for d in [*chosen, *args.figures_of] if d not in all_designs]
    if unknown:
        ap.error(f"unknown design(s) {', '.join(unknown)}; known: {', '.join(all_designs)}")
    results = {}
    for name in chosen:
        results[name], traces = run_design(name, all_designs[name], par, drive, args.traces is not None)
        if args.traces is not None:
            save_traces(args.traces, name, traces)
        print(f"{name}: {json.dumps(results[name])}", flush=True)
    if args.json is not None:
        old = json.loads(args.json.read_text()) if args.json.exists() else {}
        old.update(results)
        args.json.write_text(json.dumps(old, indent=1) + "\n")
        results = old
    print(table(results))
    if args.figures is not None:
        traces = load_traces(args.traces, args.figures_of)
        args.figures.mkdir(parents=True, exist_ok=True)
        figure(traces, "reversal_1s", "±750 r/min reversal in 1 s, no load", args.figures / "through-zero-reversal.png")
        figure(traces, "step_15rpm", "7 N·m (50 %) load step at 15 r/min", args.figures / "through-zero-step.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
