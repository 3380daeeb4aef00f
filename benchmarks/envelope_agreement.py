"""The envelope's verdict at each point against 3 s simulations of the same drive pulsed both ways, on drives
that are neither paper's (docs/envelope.md, "Agreement with 3 s simulations").

``python -m benchmarks.envelope_agreement [--cases NAME ...] [--reversal] [--json FILE]``
``python -m benchmarks.envelope_agreement --json FILE --table`` (print the stored results, run nothing)

Each case is a drive file of ``docs/examples`` with its own ``[sensors]`` (the envelope's default) and one
observer's closed form, mapped by :func:`jaxobs.analysis.envelope.envelope` at a few points (speed × load, its
default 2 s horizon at least, the Floquet verdict).  At every point two independent simulations of 3 s run the same
drive (settled as the envelope settles it, the same sensors), the speed reference pulsed by +2 % and by −2 % for
one time constant 1/α of the point's speed loop from 0.05 s (:func:`jaxobs.analysis.envelope.speed_pulse`), each
kept whole and judged by :func:`jaxobs.analysis.verdict.verdict_of` (lock from the pulse, the speed over
[1.5, 3) s).  The envelope pulses each point both ways too and reads the worse run (``pulse``: which), so a point
agrees when the envelope's ``state`` is the worse of the two runs' states (the higher verdict code: a point holds
only if it holds pulsed either way); ``holds`` is compared too, with the pulse criterion of ``tests/pulses.py``
(late peak speed deviation under 1 % and at most 2 % above the early one): the map holds where both runs hold.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "docs" / "examples"
HORIZON = 3.0  # s: the simulations' length
SETTLED = 1.5  # s: the verdict's settled window opens here (its second half from 2.25 s)
T_PULSE = 0.05  # s: the pulse's start, as the envelope's
HEIGHT = 0.02  # the pulse, relative (both signs run)

# name -> (drive file, observer, speeds r/min, loads as fractions of rated torque)
CASES = {
    "teknic_cleso": ("teknic_m2310p.toml", "cleso", (40.0, 80.0, 200.0, 450.0), (0.0, 0.5)),
    "lab_rofo": ("ipmsm_2p2kw_lab.toml", "rofo", (30.0, 150.0, 750.0), (0.0, 0.5)),
    "lab_cleso": ("ipmsm_2p2kw_lab.toml", "cleso", (30.0, 150.0, 750.0), (0.0, 0.5)),
    "traction_cleso": ("traction_ipmsm.toml", "cleso", (30.0, 300.0, 3000.0), (0.0, 0.5)),
}


def _observer(kind: str, ts: float):
    import jaxobs
    from jaxobs.observers import CLESO

    return {
        "cleso": lambda: CLESO.closed_form(ts=ts),
        "rofo": lambda: jaxobs.ReducedOrderFluxObserver.closed_form(ts=ts),
    }[kind]()


def run_case(name: str) -> dict:
    """The envelope and the pulsed simulations of one case (module doc), as plain numbers."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    import jaxobs
    from jaxobs.analysis.envelope import envelope, speed_pulse
    from jaxobs.analysis.verdict import verdict_names, verdict_of
    from jaxobs.drive import RPM, SETTLE_PERIODS, ClosedLoop
    from jaxobs.drive.drivefile import read_drive
    from jaxobs.scenarios.families import bind_observer, drive_scenarios

    file, kind, speeds, loads_pu = CASES[name]
    f = read_drive(EXAMPLES / file)
    par, drive, sensors = f.machine, f.drive_for(sensorless=True), f.sensors
    obs = _observer(kind, drive.ts)
    loads = [x * float(par.T_rated) for x in loads_pu]
    t0 = time.time()
    ds = envelope({"cf": obs}, machine=par, drive=drive, speeds_rpm=list(speeds), loads_nm=loads, sensors=sensors)
    t_env = time.time() - t0
    cf = ds.sel(design="cf")
    # the simulations run the drive the envelope ran: its settle (Drive.settled_for: SETTLE_PERIODS periods)
    sim_drive = drive.settled_for(SETTLE_PERIODS * 2.0 * math.pi / float(ds.attrs["drive_settle"]))
    assert abs(sim_drive.settle - float(ds.attrs["drive_settle"])) < 1e-9
    points = [(s, ld) for s in speeds for ld in loads]
    foc = drive.foc.bind(par, drive.inverter.u_max)
    width = np.array(
        [float(kp) / (2 * float(ki)) for kp, ki in (foc.speed_gains(jnp.asarray(s * RPM)) for s, _ in points)]
    )

    @jax.jit
    def runs(sc, t_early):
        def one(sc, te):
            sol = jaxobs.simulate(ClosedLoop(sim_drive, bind_observer(obs, sc), sc), HORIZON)
            o = sol.outputs
            dev = jnp.abs(o.omega_m - o.omega_m_ref) / jnp.abs(o.omega_m_ref)
            early = jnp.max(jnp.where((o.t >= te) & (o.t < 0.5 * HORIZON), dev, 0.0))
            late = jnp.max(jnp.where(o.t >= 0.5 * HORIZON, dev, 0.0))
            held = (late < 0.01) & (late <= 1.02 * early) & jnp.isfinite(late)
            return verdict_of(sol, T_PULSE, SETTLED).state, held, late

        return jax.vmap(one)(sc, t_early)

    sims = {}
    t0 = time.time()
    for sign in (1.0, -1.0):
        base = drive_scenarios(par, ["speed_rpm", "load_nm"], points, sensors=sensors)
        sc = speed_pulse(base, T_PULSE, width, sign * HEIGHT)
        state, held, late = jax.device_get(runs(sc, jnp.asarray(T_PULSE + 4 * width)))
        sims["+2 %" if sign > 0 else "-2 %"] = (verdict_names(state).tolist(), np.asarray(held).tolist(), late)
    t_sim = time.time() - t0
    rows = []
    for i, (s, ld) in enumerate(points):
        p = cf.sel(speed_rpm=s, load_nm=ld)
        env_state = str(verdict_names(int(p["state"])))
        row = {
            "speed_rpm": s,
            "load_nm": ld,
            "state": env_state,
            "run_state": str(verdict_names(int(p["run_state"]))),
            "margin": float(p["margin"]),
            "resolution": float(p["resolution"]),
            "off_orbit": bool(int(p["off_orbit"])),
            "holds": bool(int(p["holds"])),
            "stable": bool(int(p["stable"])),
        }
        for k, (st, held, late) in sims.items():
            row[f"sim {k} state"], row[f"sim {k} holds"] = st[i], bool(held[i])
            row[f"sim {k} late peak deviation"] = float(late[i])
        row["pulse"] = float(p["pulse"])
        row["states agree"], row["holds agree"] = agreement(row)
        rows.append(row)
    return {
        "drive": file,
        "observer": kind,
        "sensors_i_noise": float(sensors.i_noise),
        "horizon": float(ds.attrs["horizon"]),
        "envelope_seconds": t_env,
        "simulation_seconds": t_sim,
        "points": rows,
    }


REVERSAL_DESIGNS = ("rofo", "faleso", "faleso_mech")  # benchmarks.through_zero's closed forms
REVERSAL = {"speed_rpm": 750.0, "loads_nm": (0.0, 7.0), "rates": (150.0, 15000.0), "resolution": 0.1, "probes": 3}


def run_reversal() -> dict:
    """The envelope's reversal verdict (``reversal=``) on the lab IPMSM for :data:`REVERSAL_DESIGNS`, with
    benchmarks/through_zero.py's search (±750 r/min, 150 to 15 000 r/min per second, 10 %, unloaded and 7 N·m),
    to hold against its stored results (benchmarks/results/2026-12-02-through-zero.json); the map itself is one
    point (750 r/min, no load)."""
    import numpy as np

    from benchmarks.through_zero import designs
    from jaxobs.analysis.envelope import envelope
    from jaxobs.drive.drivefile import read_drive

    f = read_drive(EXAMPLES / "ipmsm_2p2kw_lab.toml")
    par, drive = f.machine, f.drive_for(sensorless=True)
    chosen = {k: designs(drive.ts)[k][0] for k in REVERSAL_DESIGNS}
    t0 = time.time()
    ds = envelope(chosen, machine=par, drive=drive, speeds_rpm=[750.0], loads_nm=[0.0], sensors=f.sensors,
                  reversal=REVERSAL)  # fmt: skip
    out = {"seconds": time.time() - t0, "options": REVERSAL, "designs": {}}
    for d in chosen:
        r = ds.sel(design=d)
        out["designs"][d] = [
            {
                "load_nm": float(x),
                "rate": None if np.isnan(v := float(r["reversal_rate"].sel(reversal_load_nm=x))) else v,
                "fails_at": None if np.isnan(o := float(r["reversal_fails_at"].sel(reversal_load_nm=x))) else o,
                "monotone": bool(int(r["reversal_monotone"].sel(reversal_load_nm=x))),
                "probed": str(r["reversal_probed"].sel(reversal_load_nm=x).values),
            }
            for x in REVERSAL["loads_nm"]
        ]
    return out


def reversal_table(rev: dict) -> str:
    """The reversal verdict as a table, beside benchmarks/through_zero.py's stored searches."""
    stored = json.loads((ROOT / "benchmarks" / "results" / "2026-12-02-through-zero.json").read_text())

    def cell(rate, other, monotone):
        if rate is None:
            return "none held"
        c = f"<= {rate:.4g} (bound)" if other is None else f"{rate:.4g} ({other:.4g} fails)"
        return c + ("" if monotone else " *")

    lines = [f"{'design':<14}{'load N·m':>9}  {'envelope --reversal':<24}{'benchmarks/through_zero.py':<24}"]
    for d, rows in rev["designs"].items():
        for row in rows:
            key = "reversal" if row["load_nm"] == 0.0 else "reversal_loaded"
            tz = stored[d].get(key)
            ref = (
                "not run" if tz is None else cell(tz["slowest_held_rpm_s"], tz["fastest_failing_rpm_s"], tz["monotone"])
            )
            lines.append(
                f"{d:<14}{row['load_nm']:>9.3g}  {cell(row['rate'], row['fails_at'], row['monotone']):<24}{ref:<24}"
            )
    return "\n".join(line.rstrip() for line in lines)


def agreement(row: dict) -> tuple[bool, bool]:
    """Whether the map's state is the worse of the two simulations' (the higher verdict code), and whether the map
    holds exactly where both simulations hold (module doc)."""
    from jaxobs.analysis.verdict import VERDICTS

    worse = max((row[f"sim {k} state"] for k in ("+2 %", "-2 %")), key=VERDICTS.index)
    return row["state"] == worse, row["holds"] == (row["sim +2 % holds"] and row["sim -2 % holds"])


def table(results: dict) -> str:
    """The results as a table: one line per point (the map's pulse: the direction whose run it read)."""
    head = f"{'case':<14}{'r/min':>7}{'N·m':>8}  {'envelope state':<20}{'pulse':<6}{'margin 1/s':>18}  "
    head += f"{'+2 % for 3 s':<20}{'-2 % for 3 s':<20}{'holds: map / sims':>18}"
    lines = [head]
    n = agree = agree_h = 0
    for name, r in results.items():
        for p in r["points"]:
            m = f"{p['margin']:.3g} (off orbit)" if p["off_orbit"] else f"{p['margin']:.3g} ± {p['resolution']:.2g}"
            hs = f"{int(p['holds'])} / {int(p['sim +2 % holds'])},{int(p['sim -2 % holds'])}"
            pulse = {1.0: "up", -1.0: "down"}.get(p.get("pulse", 1.0), "?")  # before both ways: up only
            lines.append(
                f"{name:<14}{p['speed_rpm']:>7.4g}{p['load_nm']:>8.3g}  {p['state']:<20}{pulse:<6}{m:>18}  "
                f"{p['sim +2 % state']:<20}{p['sim -2 % state']:<20}{hs:>18}"
            )
            ok, ok_h = agreement(p)
            n, agree, agree_h = n + 1, agree + ok, agree_h + ok_h
    lines.append(
        f"states agree at {agree} of {n} points (the worse of both directions); holds agrees at {agree_h} of {n}"
    )
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", choices=list(CASES), help="the cases to run (default: all)")
    ap.add_argument("--json", type=Path, help="write the numbers to this file (merged into it if it exists)")
    ap.add_argument("--table", action="store_true", help="run nothing: print the table of --json")
    ap.add_argument("--reversal", action="store_true", help="also the reversal verdict on the lab IPMSM")
    args = ap.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    results = {}
    for name in [] if args.table else (args.cases or list(CASES)):
        results[name] = run_case(name)
        print(f"{name}: {json.dumps(results[name])}", flush=True)
    if args.reversal and not args.table:
        results["reversal"] = run_reversal()
        print(f"reversal: {json.dumps(results['reversal'])}", flush=True)
    if args.json is not None:
        old = json.loads(args.json.read_text()) if args.json.exists() else {}
        old.update(results)
        if not args.table:
            args.json.write_text(json.dumps(old, indent=1) + "\n")
        results = old
    rev = results.pop("reversal", None)
    print(table(results))
    if rev is not None:
        print(reversal_table(rev))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
