"""The reduced-order flux observer beside motulator's: the same machine, cases and closed-form gains, peak errors.

``python -m benchmarks.peer_observer [--drive FILE] [--motulator-python PATH] [--json FILE] [--result RESULT.json
[--drs X]]``

jaxobs runs :class:`jaxobs.ReducedOrderFluxObserver` (closed form) closing the sensorless loop of a drive file
(``--drive``, default the 2.2-kW lab IPMSM's ``docs/examples/ipmsm_2p2kw_lab.toml``: 8 kHz, 2π·200 rad/s current
loop, 2π·4 rad/s speed loop, ideal sensors); motulator 0.18 runs its own drive with its default observer, the same
observer by its authors (:mod:`benchmarks.peer_motulator`, in a Python that has motulator: ``--motulator-python``
or ``$MOTULATOR_PYTHON``; skipped, and said so, where there is none), given the drive file's machine, inertia,
viscous friction, u_dc, sampling period, current limit and current- and speed-loop bandwidths.  Cases, scaled to
the file's rating (:func:`drive_cases`): a ±(half rated speed) reversal in 1 s without load, a 50 % rated-torque
step at 1 % of rated speed, a rated-torque step at half rated speed (on the lab drive: ±750 r/min, 7 N·m at
15 r/min, 14 N·m at 750 r/min).  Printed per case: the peak electrical angle error and the lowest and final speed
over the window from 0.2 s before the event to the end.  The two drives differ in their speed controllers
(jaxobs: the file's, I-P or 2-DOF PI on Ĵ/K̂t; motulator: its 2-DOF PI on Ĵ) and in how they start (jaxobs starts
steady after a 0.2 s settle; motulator ramps from standstill), so the speeds differ slightly; the angle errors
are the observers'.

``--result RESULT.json`` (a ``jaxobs tune`` result of the component ``rofo``, e.g. of
``docs/examples/ipmsm_2p2kw_rofo_tune.toml``) runs that job's closed form and its tuned design on the same cases
beside the observer's own closed form and motulator, and says per case whether the tuned design beats both closed
forms and meets the case's target (:data:`TARGETS`: the peak angle error, and for the 15 r/min step the speed back
within 10 % of its reference within 0.5 s of the event).  Without a Python that has motulator the motulator column
is, on the lab drive, the one stored in ``benchmarks/results/2026-12-02-peer-observer.txt`` (said so in the
output), and left out on any other drive.  ``--drs X`` runs
the three designs with the assumed R̂s off by the fraction X (controller and observer alike, as the through-zero
benchmark's rows), motulator left out: a design tuned with the machine known exactly, checked off it.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
LAB = ROOT / "docs" / "examples" / "ipmsm_2p2kw_lab.toml"
T_EVENT = 0.2  # the event's time in the jaxobs runs (each starts steady at t = 0), s
STORED = ROOT / "benchmarks" / "results" / "2026-12-02-peer-observer.txt"  # motulator's numbers, measured once
# case kind -> (the largest peak angle error, deg; the recovery within ±10 % of the reference after the event, s, or
# None): the reversal, the low-speed step, the rated step of :func:`drive_cases`
TARGETS = {"reversal": (1.0, None), "low": (2.0, 0.5), "rated": (1.5, None)}

Case = tuple[str, float, tuple[tuple[float, float], ...], float, float, float]


def drive_cases(path: Path = LAB) -> dict[str, Case]:
    """The three cases scaled to a drive file's rating ``[machine]`` (rated_speed_rpm N, rated_torque_nm T).

    Args:
        path: The drive file.

    Returns:
        case name -> (kind, a :data:`TARGETS` key; speed before, r/min; the speed profile's knots after it (times
        from the event, r/min); load step, N·m; jaxobs's t_end, s; motulator's t_end, s): a ±N/2 reversal in 1 s
        without load, a T/2 step at N/100, a T step at N/2.  On the lab drive (N = 1500 r/min, T = 14 N·m) the
        names and numbers the benchmark always had (``reversal_750``, ``step_7nm_15rpm``, ``step_14nm_750rpm``).

    Raises:
        ValueError: The file's ``[machine]`` lacks a positive rated_speed_rpm or rated_torque_nm.
    """
    with open(path, "rb") as fh:
        m = tomllib.load(fh).get("machine", {})
    for key in ("rated_speed_rpm", "rated_torque_nm"):
        if not isinstance(m.get(key), int | float) or not m[key] > 0:
            raise ValueError(f"{path}: [machine] {key} must be a number > 0 (the cases scale with it)")
    rated = float(m["rated_speed_rpm"])
    half, low, torque = 0.5 * rated, 0.01 * rated, float(m["rated_torque_nm"])
    t0 = 1.0  # motulator's event time (benchmarks/peer_motulator.py: it ramps from standstill first), s
    return {  # motulator scores the reversal to 1.3 s after its event, the steps to jaxobs's t_end after it
        f"reversal_{half:g}": ("reversal", half, ((0.0, half), (1.0, -half)), 0.0, 1.5, t0 + 1.3),
        f"step_{0.5 * torque:.3g}nm_{low:g}rpm": ("low", low, (), 0.5 * torque, 1.0, t0 + 1.0),
        f"step_{torque:.3g}nm_{half:g}rpm": ("rated", half, (), torque, 0.6, t0 + 0.6),
    }


CASES = drive_cases(LAB)  # the lab drive's cases (the stored motulator numbers are of these)


def jaxobs_cases(observer: Any = None, drs: float = 0.0, path: Path = LAB) -> dict:
    """The cases run by jaxobs (float64), each ``{"peak_deg", "min_rpm", "final_rpm", "recovered_s"}``.

    Args:
        observer: The drive observer to run (bound per case to the machine and its speed); None: the
            reduced-order flux observer's closed form.
        drs: The relative error of the assumed stator resistance R̂s, controller and observer alike (0: exact).
        path: The drive file (:func:`drive_cases` scales the cases to its rating).

    Returns:
        case -> its numbers (``recovered_s``: the last time the speed is outside ±10 % of its reference, from the
        event; 0 where it never leaves; None where it is still outside at the end: never back).
    """
    import jax
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    import equinox as eqx

    import jaxobs
    from jaxobs import drive as D
    from jaxobs import metrics
    from jaxobs.drive.drivefile import read_drive

    f = read_drive(path)
    par, drive = f.machine, f.drive_for(sensorless=True)
    if not isinstance(drive, D.Drive):
        raise ValueError(f"{path}: a [dual] drive file; the benchmark runs a single machine's drive")
    est = eqx.tree_at(lambda m: m.Rs, par, par.Rs * (1.0 + drs)) if drs else par
    base = jaxobs.ReducedOrderFluxObserver.closed_form(ts=drive.ts) if observer is None else observer
    out = {}
    for name, (_, rpm, knots, load, t_end, _) in drive_cases(path).items():
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
        if abs(n[-1] - ref[-1]) > 0.1 * max(abs(ref[-1]), 1e-9):  # still outside at the end: never back (the
            rec = None  # last time outside would be the run's end, read as a recovery time)
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


def motulator_setup(path: Path = LAB) -> dict:
    """What :mod:`benchmarks.peer_motulator` needs of a drive file: its machine and drive, and the cases.

    Args:
        path: The drive file.

    Returns:
        ``{"drive": {n_p, R_s, L_d, L_q, psi_f, J, B, u_dc, T_s, i_max, alpha_c, alpha_s}, "cases": name ->
        [speed before, knots, load, motulator's t_end]}`` (SI, peak currents, rad/s), JSON-ready.

    Raises:
        ValueError: A file with a flux map or a dual machine (motulator's side here takes the linear model only).
    """
    import jax

    jax.config.update("jax_enable_x64", True)  # the file's values as written (float32 would round them)
    from jaxobs.drive.drivefile import read_drive

    f = read_drive(path)
    par, kw = f.machine, f.foc_kw
    if f.dual is not None or "saturation" in f.table.get("machine", {}):
        raise ValueError(f"{path}: motulator's side takes a linear single machine (no [dual], no saturation map)")
    drive = {"n_p": int(par.p), "R_s": float(par.Rs), "L_d": float(par.Ld), "L_q": float(par.Lq),
             "psi_f": float(par.psi_f), "J": float(par.J), "B": float(par.B), "u_dc": float(f.drive.inverter.udc),
             "T_s": float(kw["ts"]), "i_max": float(kw["i_max"]), "alpha_c": float(kw["alpha_c"]),
             "alpha_s": float(kw["alpha_s"])}  # fmt: skip
    cases = {n: [rpm, [list(k) for k in knots], load, t_mot]
             for n, (_, rpm, knots, load, _, t_mot) in drive_cases(path).items()}  # fmt: skip
    return {"drive": drive, "cases": cases}


def motulator_cases(python: str | None, path: Path = LAB) -> dict | None:
    """The cases run by motulator in ``python`` (:mod:`benchmarks.peer_motulator`) on the drive file ``path``'s
    machine and drive (:func:`motulator_setup`), or None without one."""
    if not python:
        return None
    setup = json.dumps(motulator_setup(path))
    done = subprocess.run([python, str(ROOT / "benchmarks" / "peer_motulator.py"), setup], capture_output=True,
                          text=True)  # fmt: skip
    if done.returncode != 0:
        raise RuntimeError(f"motulator run failed ({python}):\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def table(ours: dict, peer: dict | None) -> str:
    w = max(18, *map(len, ours))  # the lab's width at least
    head = f"{'case':<{w}} {'jaxobs peak':>12} {'min r/min':>10} {'final':>9}"
    head += f" | {'motulator peak':>14} {'min r/min':>10} {'final':>9}" if peer else " | motulator: not run"
    rows = [head]
    for name, r in ours.items():
        line = f"{name:<{w}} {r['peak_deg']:>11.3f}° {r['min_rpm']:>10.1f} {r['final_rpm']:>9.1f}"
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


def _verdict(name: str, kind: str, r: dict, others: dict[str, dict]) -> str:
    peak, rec = TARGETS[kind]
    back = r["recovered_s"]
    ok = r["peak_deg"] <= peak and (rec is None or (back is not None and 0.0 < back <= rec))
    beats = ", ".join(f"{'beats' if r['peak_deg'] < o['peak_deg'] else 'does NOT beat'} {k}" for k, o in others.items())
    target = f"peak <= {peak:g}°" + ("" if rec is None else f", back within 10 % by {rec:g} s")
    return f"{name}: tuned {beats}; target ({target}) {'met' if ok else 'NOT met'}"


def tuned_table(designs: dict[str, dict], peer: dict | None, peer_note: str, path: Path = LAB) -> str:
    """The cases' rows, one per design (``designs``: label -> :func:`jaxobs_cases`'s numbers) and motulator's.

    Args:
        designs: label -> case -> numbers, in the order printed.
        peer: motulator's numbers (:func:`stored_motulator`'s form), or None (not comparable: an R̂s error, or
            not run).
        peer_note: How motulator's numbers were had (run now, or stored).
        path: The drive file the cases were run on (:func:`drive_cases`: their names and kinds).

    Returns:
        The table, then one verdict line per case.
    """
    kinds = {n: c[0] for n, c in drive_cases(path).items()}
    peaks = [c[n]["peak_deg"] for c in designs.values() for n in kinds] + ([] if peer is None else
             [peer["cases"][n]["peak_deg"] for n in kinds])  # fmt: skip
    w, pw = max(18, *map(len, kinds)), max(7, *(len(f"{x:.3f}") for x in peaks))  # the lab's widths at least
    rows = [f"{'case':<{w}} {'design':<34} {'peak':>{pw + 1}} {'min r/min':>10} {'final':>9} {'back ±10 %':>11}"]
    for name in kinds:
        for label, cases in designs.items():
            r = cases[name]
            rec = "never" if r["recovered_s"] is None else f"{r['recovered_s']:.3f} s"
            rows.append(f"{name:<{w}} {label:<34} {r['peak_deg']:>{pw}.3f}° {r['min_rpm']:>10.1f} "
                        f"{r['final_rpm']:>9.1f} {rec:>11}")  # fmt: skip
        if peer is None:
            continue
        p = peer["cases"][name]
        rows.append(f"{name:<{w}} {'motulator (' + peer_note + ')':<34} {p['peak_deg']:>{pw}.3f}° "
                    f"{p['min_rpm']:>10.1f} {p['final_rpm']:>9.1f} {'-':>11}")  # fmt: skip
    tuned = designs["tuned (rofo + mechanical)"]
    others = {k: v for k, v in designs.items() if k != "tuned (rofo + mechanical)"}
    rows += [
        _verdict(
            n,
            kind,
            tuned[n],
            {k: v[n] for k, v in others.items()} | ({} if peer is None else {"motulator": peer["cases"][n]}),
        )
        for n, kind in kinds.items()
    ]
    return "\n".join(rows)


def _run_result(path: Path, python: str | None, drs: float = 0.0, drive: Path = LAB) -> dict:
    """``--result``: the three designs and motulator, printed; the numbers returned.  With an R̂s error (``drs``)
    motulator's runs, with its machine known exactly, are not comparable: left out, and said so.  Without a
    motulator Python: the stored numbers on the lab drive, none on another."""
    built = result_designs_of(path)
    designs = {
        "rofo closed form (type-2 loop)": jaxobs_cases(None, drs, drive),
        "job closed form (rofo + mechanical)": jaxobs_cases(built["closed_form"], drs, drive),
        "tuned (rofo + mechanical)": jaxobs_cases(built["tuned"], drs, drive),
    }
    if drs:
        print(f"R̂s {drs:+.0%} (controller and observer); motulator left out (its runs assume R̂s exact)")
        print(tuned_table(designs, None, "", drive))
        out = {"jaxobs": designs, "drs": drs, "result": str(path)}
        return out if drive.resolve() == LAB.resolve() else out | {"drive": str(drive)}
    peer = motulator_cases(python, drive)
    note = "run now"
    if peer is None and drive.resolve() != LAB.resolve():
        print(tuned_table(designs, None, "", drive))
        print("motulator: not run (no --motulator-python or $MOTULATOR_PYTHON; numbers stored for the lab drive only)")
        return {"jaxobs": designs, "motulator": None, "result": str(path), "drive": str(drive)}
    if peer is None:
        peer, note = stored_motulator(), "stored"
    print(tuned_table(designs, peer, note, drive))
    if note == "stored":
        print(f"motulator: not run here (no --motulator-python or $MOTULATOR_PYTHON); its numbers are the ones stored "
              f"in {STORED.relative_to(ROOT)} ({peer['motulator']})")  # fmt: skip
    else:
        print(f"motulator {peer['motulator']}")
    out = {"jaxobs": designs, "motulator": peer, "motulator_source": note, "result": str(path)}
    return out if drive.resolve() == LAB.resolve() else out | {"drive": str(drive)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument(
        "--motulator-python",
        default=os.environ.get("MOTULATOR_PYTHON"),
        help="a Python with motulator 0.18 (default $MOTULATOR_PYTHON; none: motulator is skipped)",
    )
    ap.add_argument("--drive", type=Path, default=LAB, help="the drive file (default the 2.2-kW lab IPMSM's)")
    ap.add_argument("--json", type=Path, help="also write the numbers to this file")
    ap.add_argument("--result", type=Path, help="a `jaxobs tune` result.json of rofo: its tuned design beside")
    ap.add_argument("--drs", type=float, default=0.0, help="with --result: the relative error of the assumed R̂s")
    args = ap.parse_args(argv)
    if args.drs and args.result is None:
        ap.error("--drs applies with --result only")
    if not -0.95 <= args.drs <= 10.0:
        ap.error(f"--drs must be in [-0.95, 10] (a relative error), got {args.drs}")
    if args.result is not None:
        numbers = _run_result(args.result, args.motulator_python, args.drs, args.drive)
        if args.json is not None:
            args.json.write_text(json.dumps(numbers, indent=1) + "\n")
        return 0
    ours = jaxobs_cases(path=args.drive)
    peer = motulator_cases(args.motulator_python, args.drive)
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
