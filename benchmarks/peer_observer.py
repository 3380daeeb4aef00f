"""The reduced-order flux observer beside motulator's: the same machine, cases and closed-form gains, peak errors.

``python -m benchmarks.peer_observer [--motulator-python PATH] [--json FILE] [--result RESULT.json [--drs X]]``

jaxobs runs :class:`jaxobs.ReducedOrderFluxObserver` (closed form) closing the sensorless loop of the 2.2-kW lab
IPMSM drive file (``docs/examples/ipmsm_2p2kw_lab.toml``: 8 kHz, 2π·200 rad/s current loop, 2π·4 rad/s speed
loop, ideal sensors); motulator 0.18 runs its own drive with its default observer, the same observer by its
authors (:mod:`benchmarks.peer_motulator`, in a Python that has motulator: ``--motulator-python`` or
``$MOTULATOR_PYTHON``; skipped, and said so, where there is none).  Cases: a ±750 r/min reversal in 1 s without
load, a 7 N·m step at 15 r/min, a 14 N·m step at 750 r/min.  Printed per case: the peak electrical angle error
and the lowest and final speed over the window from 0.2 s before the event to the end.  The two drives differ
in their speed controllers (jaxobs: I-P on Ĵ/K̂t; motulator: its 2-DOF PI on Ĵ) and in how they start (jaxobs
starts steady after a 0.2 s settle; motulator ramps from standstill), so the speeds differ slightly; the angle
errors are the observers'.

``--result RESULT.json`` (a ``jaxobs tune`` result of the component ``rofo``, e.g. of
``docs/examples/ipmsm_2p2kw_rofo_tune.toml``) runs that job's closed form and its tuned design on the same cases
beside the observer's own closed form and motulator, and says per case whether the tuned design beats both closed
forms and meets the case's target (:data:`TARGETS`: the peak angle error, and for the 15 r/min step the speed back
within 10 % of its reference within 0.5 s of the event).  Without a Python that has motulator the motulator column
is the one stored in ``benchmarks/results/2026-12-02-peer-observer.txt`` (said so in the output).  ``--drs X`` runs
the three designs with the assumed R̂s off by the fraction X (controller and observer alike, as the through-zero
benchmark's rows), motulator left out: a design tuned with the machine known exactly, checked off it.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
LAB = ROOT / "docs" / "examples" / "ipmsm_2p2kw_lab.toml"
T_EVENT = 0.2  # the event's time in the jaxobs runs (each starts steady at t = 0), s
STORED = ROOT / "benchmarks" / "results" / "2026-12-02-peer-observer.txt"  # motulator's numbers, measured once
# case -> (the largest peak angle error, deg; the recovery within ±10 % of the reference after the event, s, or None)
TARGETS = {"reversal_750": (1.0, None), "step_7nm_15rpm": (2.0, 0.5), "step_14nm_750rpm": (1.5, None)}

# case -> (speed before, r/min; the speed profile's knots after it (times from the event, r/min); load step; t_end)
CASES = {
    "reversal_750": (750.0, ((0.0, 750.0), (1.0, -750.0)), 0.0, 1.5),
    "step_7nm_15rpm": (15.0, (), 7.0, 1.0),
    "step_14nm_750rpm": (750.0, (), 14.0, 0.6),
}


def jaxobs_cases(observer: Any = None, drs: float = 0.0) -> dict:
    """The cases run by jaxobs (float64), each ``{"peak_deg", "min_rpm", "final_rpm", "recovered_s"}``.

    Args:
        observer: The drive observer to run (bound per case to the machine and its speed); None: the
            reduced-order flux observer's closed form.
        drs: The relative error of the assumed stator resistance R̂s, controller and observer alike (0: exact).

    Returns:
        case -> its numbers (``recovered_s``: the last time the speed is outside ±10 % of its reference, from the
        event; 0 where it never leaves).
    """
    import jax
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    import equinox as eqx

    import jaxobs
    from jaxobs import drive as D
    from jaxobs import metrics
    from jaxobs.drive.drivefile import read_drive

    f = read_drive(LAB)
    par, drive = f.machine, f.drive_for(sensorless=True)
    est = eqx.tree_at(lambda m: m.Rs, par, par.Rs * (1.0 + drs)) if drs else par
    base = jaxobs.ReducedOrderFluxObserver.closed_form(ts=drive.ts) if observer is None else observer
    out = {}
    for name, (rpm, knots, load, t_end) in CASES.items():
        times = [0.0, *(T_EVENT + dt for dt, _ in knots)] if knots else [0.0]
        values = [rpm * D.RPM, *(r * D.RPM for _, r in knots)] if knots else [rpm * D.RPM]
        sc = D.Scenario(par, speed_ref=D.Profile(times, values), omega_m0=rpm * D.RPM,
                        load=D.Scenario.load_steps([0.0, T_EVENT], [0.0, load]), est_par=est)  # fmt: skip
        obs = base.bind(est, par.p * rpm * D.RPM)
        o = jax.jit(lambda s, obs=obs: jaxobs.simulate(D.ClosedLoop(drive, obs, s), t_end))(sc).outputs
        err = np.degrees(np.abs(np.asarray(metrics.wrap(o.obs.theta - o.theta_e))))
        n = np.asarray(o.omega_m) / D.RPM
        t, ref = np.asarray(o.t), np.asarray(o.omega_m_ref) / D.RPM
        out_band = t[(t >= T_EVENT) & (np.abs(n - ref) > 0.1 * np.maximum(np.abs(ref), 1e-9))]
        rec = float(out_band[-1] - T_EVENT) if out_band.size else 0.0
        out[name] = {"peak_deg": float(err.max()), "min_rpm": float(n.min()), "final_rpm": float(n[-1]),
                     "recovered_s": rec}  # fmt: skip
    return out


def stored_motulator(path: Path = STORED) -> dict:
    """motulator's numbers as :func:`main` printed them into ``path`` (its table's right-hand columns).

    Args:
        path: A stored output of this benchmark with motulator's columns.

    Returns:
        ``{"motulator": its version line, "cases": case -> {"peak_deg", "min_rpm", "final_rpm"}}``.

    Raises:
        ValueError: ``path`` holds no motulator row of a case.
    """
    cases, version = {}, "?"
    for line in path.read_text().splitlines():
        head, _, right = line.partition("|")
        words = head.split()
        if words and words[0] in CASES and right.strip():
            peak, lo, fin = right.replace("°", " ").split()[:3]
            cases[words[0]] = {"peak_deg": float(peak), "min_rpm": float(lo), "final_rpm": float(fin)}
        elif line.startswith("motulator "):
            version = line.split(maxsplit=1)[1]
    missing = sorted(set(CASES) - set(cases))
    if missing:
        raise ValueError(f"{path}: no motulator row for {', '.join(missing)}")
    return {"motulator": version, "cases": cases}


def motulator_cases(python: str | None) -> dict | None:
    """The cases run by motulator in ``python`` (:mod:`benchmarks.peer_motulator`), or None without one."""
    if not python:
        return None
    done = subprocess.run([python, str(ROOT / "benchmarks" / "peer_motulator.py")], capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"motulator run failed ({python}):\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def table(ours: dict, peer: dict | None) -> str:
    head = f"{'case':<18} {'jaxobs peak':>12} {'min r/min':>10} {'final':>9}"
    head += f" | {'motulator peak':>14} {'min r/min':>10} {'final':>9}" if peer else " | motulator: not run"
    rows = [head]
    for name, r in ours.items():
        line = f"{name:<18} {r['peak_deg']:>11.3f}° {r['min_rpm']:>10.1f} {r['final_rpm']:>9.1f}"
        if peer:
            p = peer["cases"][name]
            line += f" | {p['peak_deg']:>13.3f}° {p['min_rpm']:>10.1f} {p['final_rpm']:>9.1f}"
        rows.append(line)
    return "\n".join(rows)


def result_designs_of(path: Path) -> dict:
    """The job's closed form and tuned design of a ``jaxobs tune`` result, built as the run scored them.

    Args:
        path: The result.json.

    Returns:
        ``{"closed_form": observer, "tuned": observer}`` (float64 leaves).

    Raises:
        ValueError: Not a result of the reduced-order flux observer, or nothing tuned.
    """
    import jax

    jax.config.update("jax_enable_x64", True)
    from jaxobs_tuning.results import load_result, result_designs, tuned_component

    res = load_result(path)
    if res["component"] != "ReducedOrderFluxObserver":
        raise ValueError(f"{path}: a result of {res['component']}, not of the reduced-order flux observer (rofo)")
    return {"closed_form": result_designs(res, str(path))["closed_form"], "tuned": tuned_component(res)}


def _verdict(name: str, r: dict, others: dict[str, dict]) -> str:
    peak, rec = TARGETS[name]
    ok = r["peak_deg"] <= peak and (rec is None or 0.0 < r["recovered_s"] <= rec)
    beats = ", ".join(f"{'beats' if r['peak_deg'] < o['peak_deg'] else 'does NOT beat'} {k}" for k, o in others.items())
    target = f"peak <= {peak:g}°" + ("" if rec is None else f", back within 10 % by {rec:g} s")
    return f"{name}: tuned {beats}; target ({target}) {'met' if ok else 'NOT met'}"


def tuned_table(designs: dict[str, dict], peer: dict | None, peer_note: str) -> str:
    """The cases' rows, one per design (``designs``: label -> :func:`jaxobs_cases`'s numbers) and motulator's.

    Args:
        designs: label -> case -> numbers, in the order printed.
        peer: motulator's numbers (:func:`stored_motulator`'s form), or None (not comparable: an R̂s error).
        peer_note: How motulator's numbers were had (run now, or stored).

    Returns:
        The table, then one verdict line per case.
    """
    rows = [f"{'case':<18} {'design':<34} {'peak':>8} {'min r/min':>10} {'final':>9} {'back ±10 %':>11}"]
    for name in CASES:
        for label, cases in designs.items():
            r = cases[name]
            rec = f"{r['recovered_s']:.3f} s"
            rows.append(f"{name:<18} {label:<34} {r['peak_deg']:>7.3f}° {r['min_rpm']:>10.1f} {r['final_rpm']:>9.1f} "
                        f"{rec:>11}")  # fmt: skip
        if peer is None:
            continue
        p = peer["cases"][name]
        rows.append(f"{name:<18} {'motulator (' + peer_note + ')':<34} {p['peak_deg']:>7.3f}° {p['min_rpm']:>10.1f} "
                    f"{p['final_rpm']:>9.1f} {'-':>11}")  # fmt: skip
    tuned = designs["tuned (rofo + mechanical)"]
    others = {k: v for k, v in designs.items() if k != "tuned (rofo + mechanical)"}
    rows += [
        _verdict(
            n,
            tuned[n],
            {k: v[n] for k, v in others.items()} | ({} if peer is None else {"motulator": peer["cases"][n]}),
        )
        for n in CASES
    ]
    return "\n".join(rows)


def _run_result(path: Path, python: str | None, drs: float = 0.0) -> dict:
    """``--result``: the three designs and motulator, printed; the numbers returned.  With an R̂s error (``drs``)
    motulator's runs, with its machine known exactly, are not comparable: left out, and said so."""
    built = result_designs_of(path)
    designs = {
        "rofo closed form (type-2 loop)": jaxobs_cases(None, drs),
        "job closed form (rofo + mechanical)": jaxobs_cases(built["closed_form"], drs),
        "tuned (rofo + mechanical)": jaxobs_cases(built["tuned"], drs),
    }
    if drs:
        print(f"R̂s {drs:+.0%} (controller and observer); motulator left out (its runs assume R̂s exact)")
        print(tuned_table(designs, None, ""))
        return {"jaxobs": designs, "drs": drs, "result": str(path)}
    peer = motulator_cases(python)
    note = "run now"
    if peer is None:
        peer, note = stored_motulator(), "stored"
    print(tuned_table(designs, peer, note))
    if note == "stored":
        print(f"motulator: not run here (no --motulator-python or $MOTULATOR_PYTHON); its numbers are the ones stored "
              f"in {STORED.relative_to(ROOT)} ({peer['motulator']})")  # fmt: skip
    else:
        print(f"motulator {peer['motulator']}")
    return {"jaxobs": designs, "motulator": peer, "motulator_source": note, "result": str(path)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--motulator-python",
        default=os.environ.get("MOTULATOR_PYTHON"),
        help="a Python with motulator 0.18 (default $MOTULATOR_PYTHON; none: motulator is skipped)",
    )
    ap.add_argument("--json", type=Path, help="also write the numbers to this file")
    ap.add_argument("--result", type=Path, help="a `jaxobs tune` result.json of rofo: its tuned design beside")
    ap.add_argument("--drs", type=float, default=0.0, help="with --result: the relative error of the assumed R̂s")
    args = ap.parse_args(argv)
    if args.drs and args.result is None:
        ap.error("--drs applies with --result only")
    if not -0.95 <= args.drs <= 10.0:
        ap.error(f"--drs must be in [-0.95, 10] (a relative error), got {args.drs}")
    if args.result is not None:
        numbers = _run_result(args.result, args.motulator_python, args.drs)
        if args.json is not None:
            args.json.write_text(json.dumps(numbers, indent=1) + "\n")
        return 0
    ours = jaxobs_cases()
    peer = motulator_cases(args.motulator_python)
    print(table(ours, peer))
    if peer is None:
        print("motulator: skipped (no --motulator-python or $MOTULATOR_PYTHON)")
    else:
        print(f"motulator {peer['motulator']}")
    if args.json is not None:
        args.json.write_text(json.dumps({"jaxobs": ours, "motulator": peer}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
