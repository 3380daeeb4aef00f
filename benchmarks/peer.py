"""motulator as a yardstick: the same sensored drive in jaxobs and in motulator 0.18, agreement and time.

``python -m benchmarks.peer [--motulator-python PATH] [--batches 1 64 1024 8192] [--batch-horizon S]
[--max-runs N] [--budget-s S] [--json FILE]``

The drive: the 2.2-kW lab IPMSM of ``docs/examples/ipmsm_2p2kw_lab.toml`` (p = 3, 540 V, 8 kHz), sensored (the
true rotor angle to the FOC), float64.  jaxobs runs the file's own controller (IMC current PIs at α_c = 2π·200
rad/s, the 2DOF speed PI with both poles at α_s = 2π·4 rad/s, setpoint weight 0.5, MTPA, i_max 9.12 A) with the
speed loop run every period (``speed_every = 1``, as motulator's; the file's 1 kHz speed loop is a second,
labelled agreement row); motulator runs its own sensored current-vector drive given the file's machine, J, u_dc,
T_s, i_max, α_c and α_s (:func:`benchmarks.peer_observer.motulator_setup`, the gains matched as there;
:mod:`benchmarks.peer_motulator_sensored`, in a Python that has motulator: ``--motulator-python`` or
``$MOTULATOR_PYTHON``; skipped, and said so, where there is none).

The scenario (:data:`SCENARIO`): from rest, the speed reference ramps to 1000 r/min over 0.25 s (a bare step
would drive both tools into their current and voltage limits, where their anti-windup schemes differ), the rated
14 N·m load steps on at 0.5 s, the run ends at 1 s.  Agreement: both tools' speed and rotor-frame currents at the
same sampling instants t_k = k T_s (jaxobs's outputs at t_k, motulator's model state at its solver's point at
t_k), the largest difference over the run (speed in r/min, the current vector |Δi_dq| relative to the rated
current's peak, √2·4.3 A).

Time, in the same run, wall (``time.perf_counter``) and CPU (``time.process_time``; motulator's measured inside
its process, and its whole process's by ``resource.getrusage(RUSAGE_CHILDREN)``): one scenario cold (jaxobs's
first call, compiling; motulator's process's first run) and warm (the best of 3); then batches of operating
points (final speed × load, :func:`operating_points`): jaxobs one ``jit(vmap)`` call per batch (its compile
apart, the best of ``--repeats``), motulator, which has no batch, one scenario after another: measured on up to
``--max-runs`` of them or ``--budget-s`` seconds, its time for a batch of n "extrapolated = n × the measured
per-scenario time", labelled so.  The batch rows run ``--batch-horizon`` seconds (the scenario's times scaled to
it, the ramp's slope kept) in both tools.  ``uptime`` at the start and the end: this machine's load moves every
time.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
LAB = ROOT / "docs" / "examples" / "ipmsm_2p2kw_lab.toml"
MOTULATOR_SCRIPT = ROOT / "benchmarks" / "peer_motulator_sensored.py"
# from rest: speed reference ramped to rpm over ramp_s, the load stepped to load_nm at load_at, the run t_end, s
SCENARIO = {"rpm": 1000.0, "ramp_s": 0.25, "load_nm": 14.0, "load_at": 0.5, "t_end": 1.0}
RPM = 2 * math.pi / 60
# motulator's two lags that jaxobs's drive does not have, moved out of the way for one agreement row: its current
# reference tracks the torque and flux references at alpha_ref (default 2π·100 rad/s) and its sensored speed comes
# from an observer on the measured angle (poles 2π·400 rad/s), where jaxobs's FOC takes i_q* at once and the true
# speed.  2π·1000 rad/s keeps alpha_ref·T_s = 0.79 (motulator asks for it well below the sampling rate).
FAST_MOTULATOR = {"alpha_ref": 2 * math.pi * 1000.0, "alpha_o": 2 * math.pi * 1500.0}


def _uptime() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def _machine() -> str:
    """The CPU's model name (Linux's /proc/cpuinfo) and the cores this process sees."""
    try:
        names = [ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                 if ln.startswith("model name")]  # fmt: skip
    except OSError:
        names = []
    return f"{names[0] if names else 'CPU'}, {os.cpu_count()} cores"


def batch_scenario(horizon: float) -> dict[str, float]:
    """The batch rows' scenario timing: :data:`SCENARIO`'s times scaled to ``horizon``.

    Args:
        horizon: The batch rows' run, s (> 0).

    Returns:
        ``{"ramp_s", "load_at", "t_end"}``; the final speeds are scaled with the ramp's time (its slope, 4000
        r/min/s, and so the acceleration torque kept: a faster ramp would reach the current limit).

    Raises:
        ValueError: ``horizon`` not in (0, 10] s.
    """
    if not 0.0 < horizon <= 10.0:
        raise ValueError(f"--batch-horizon must be in (0, 10] s, got {horizon}")
    f = horizon / SCENARIO["t_end"]
    return {"ramp_s": SCENARIO["ramp_s"] * f, "load_at": SCENARIO["load_at"] * f, "t_end": horizon, "scale": f}


def operating_points(n: int, speed_scale: float = 1.0) -> list[tuple[float, float]]:
    """``n`` operating points, final speed × load step: speeds 250–1250 r/min (× ``speed_scale``), loads 0–14 N·m.

    Args:
        n: How many (≥ 1); n = 1 is :data:`SCENARIO`'s own point.
        speed_scale: The speeds' factor (the batch horizon's, :func:`batch_scenario`).

    Returns:
        ``[(rpm, load_nm), ...]``: a grid of a = 2^⌈log2(n)/2⌉ speeds by ⌈n/a⌉ loads (8 × 8, 32 × 32, 128 × 64),
        or the scenario's point for n = 1.

    Raises:
        ValueError: ``n`` < 1.
    """
    if n < 1:
        raise ValueError(f"batch size must be >= 1, got {n}")
    if n == 1:
        return [(SCENARIO["rpm"] * speed_scale, SCENARIO["load_nm"])]
    a = min(1 << math.ceil(math.log2(n) / 2), n)  # speeds by loads: 8 x 8, 32 x 32, 128 x 64
    b = -(-n // a)
    speeds = [speed_scale * (250.0 + 1000.0 * i / max(a - 1, 1)) for i in range(a)]
    loads = [14.0 * j / max(b - 1, 1) for j in range(b)]
    return [(s, ld) for s in speeds for ld in loads][:n]


def jaxobs_run(path: Path = LAB, speed_every: int | None = 1, timing: dict[str, float] | None = None) -> Any:
    """One scenario on the drive file's sensored jaxobs drive, as a function of its operating point.

    Args:
        path: The drive file.
        speed_every: The speed loop's period in control periods (1: every period, as motulator's; None: the
            file's).
        timing: ``{"ramp_s", "load_at", "t_end"}`` (default :data:`SCENARIO`'s).

    Returns:
        ``f(rpm, load_nm) -> (speed r/min, i_d A, i_q A)`` over the samples, traceable (``jit``, ``vmap``).
    """
    import equinox as eqx
    import jax.numpy as jnp

    import jaxobs
    from jaxobs import drive as D
    from jaxobs.drive.drivefile import read_drive

    f = read_drive(path)
    drive = f.drive_for(sensorless=False)
    assert isinstance(drive, D.Drive)  # the lab file: a single machine
    if speed_every is not None and speed_every != drive.foc.speed_every:
        foc = D.FOC.imc(f.machine, **{**f.foc_kw, "speed_every": speed_every}, u_max=drive.inverter.u_max)
        drive = eqx.tree_at(lambda d: d.foc, drive, foc)
    tm = timing or SCENARIO
    base = D.Scenario(f.machine, speed_ref=D.Profile([0.0, tm["ramp_s"]], [0.0, 1.0]), omega_m0=0.0,
                      load=D.Scenario.load_steps([0.0, tm["load_at"]], [0.0, 1.0]))  # fmt: skip
    t_end = float(tm["t_end"])

    def run(rpm, load_nm):
        z = jnp.zeros_like(rpm)
        sc = eqx.tree_at(lambda s: (s.speed_ref.values, s.load.values), base,
                         (jnp.stack([z, rpm * RPM]), jnp.stack([z, load_nm])))  # fmt: skip
        o = jaxobs.simulate(D.ClosedLoop(drive, None, sc), t_end).outputs
        return o.omega_m / RPM, o.i_d, o.i_q

    return run


def _timed(fn: Any, *args: Any) -> tuple[Any, float, float]:
    import jax

    t0, c0 = time.perf_counter(), time.process_time()
    out = jax.block_until_ready(fn(*args))
    return out, time.perf_counter() - t0, time.process_time() - c0


def jaxobs_timing(batches: list[int], horizon: float, repeats: int) -> dict[str, Any]:
    """jaxobs's times: one scenario cold (the drive built and compiled: the process's first) and warm (the best of
    3), and each batch (its first call, compiling, and the best of ``repeats``); the single scenario's trajectory.

    Args:
        batches: The batch sizes.
        horizon: The batch rows' run, s.
        repeats: The batch rows' timed calls (the best is kept).

    Returns:
        ``{"cold": (wall, cpu), "warm": [(wall, cpu)...], "trajectory": (rpm, i_d, i_q) arrays, "batches":
        {n: {"compile": (wall, cpu), "best": (wall, cpu)}}}``.
    """
    import jax
    import jax.numpy as jnp

    rpm, load = jnp.asarray(SCENARIO["rpm"]), jnp.asarray(SCENARIO["load_nm"])
    built: list[Any] = []

    def cold_call(rpm, load):  # cold: reading the file and building the drive too, as motulator's runs do
        built.append(jax.jit(jaxobs_run()))
        return built[0](rpm, load)

    traj, *cold = _timed(cold_call, rpm, load)
    one = built[0]
    warm = [tuple(_timed(one, rpm, load)[1:]) for _ in range(3)]
    out: dict[str, Any] = {"cold": tuple(cold), "warm": warm, "trajectory": traj, "batches": {}}
    bs = batch_scenario(horizon)
    many = jax.jit(jax.vmap(jaxobs_run(timing=bs)))
    for n in batches:
        pts = jnp.asarray(operating_points(n, bs["scale"]))
        _, *first = _timed(many, pts[:, 0], pts[:, 1])
        times = [tuple(_timed(many, pts[:, 0], pts[:, 1])[1:]) for _ in range(repeats)]
        out["batches"][n] = {"compile": tuple(first), "best": min(times)}
        print(f"  jaxobs batch {n}: first call {first[0]:.2f} s, best of {repeats} {min(times)[0]:.3f} s", flush=True)
    return out


def motulator_timing(python: str, batches: list[int], horizon: float, max_runs: int, budget_s: float) -> dict:
    """motulator's run of :mod:`benchmarks.peer_motulator_sensored`: its times and the scenario's trajectory.

    Args:
        python: A Python with motulator 0.18.
        batches: The batch sizes (the largest's operating points are the ones it runs one after another).
        horizon: The batch rows' run, s.
        max_runs: The most batch scenarios run.
        budget_s: The batch scenarios' time budget, s (the run under way finishes).

    Returns:
        The script's JSON, with ``"process": (wall, user + system CPU)`` of its whole process.

    Raises:
        RuntimeError: motulator's run failed.
    """
    from benchmarks.peer_observer import motulator_setup

    bs = batch_scenario(horizon)
    pts = operating_points(max(batches), bs["scale"])
    stride = max(1, len(pts) // max_runs)
    setup = {"drive": motulator_setup(LAB)["drive"], "scenario": SCENARIO, "warm": 3, "variants": [FAST_MOTULATOR],
             "batch": {"scenarios": pts[stride // 2 :: stride][:max_runs], "ramp_s": bs["ramp_s"],
                       "load_at": bs["load_at"], "t_end": bs["t_end"], "max_runs": max_runs,
                       "budget_s": budget_s}}  # fmt: skip
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run([python, str(MOTULATOR_SCRIPT), json.dumps(setup)], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"motulator run failed ({python}):\n{done.stderr[-2000:]}")
    out = json.loads(done.stdout.strip().splitlines()[-1])
    out["process"] = (wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime))
    return out


def agreement(ours: Any, peer: dict, i_rated: float) -> dict[str, float]:
    """The largest differences between jaxobs's and motulator's trajectories at the same sampling instants.

    Args:
        ours: jaxobs's ``(rpm, i_d, i_q)`` at t_k = k T_s, k = 0 … n − 1.
        peer: motulator's ``{"t", "rpm", "i_d", "i_q"}`` at its sampling instants.
        i_rated: The rated current's peak, A (the currents' scale).

    Returns:
        ``{"samples", "speed_rpm", "i_dq_pu", "i_d_pu", "i_q_pu", "final_rpm_jaxobs", "final_rpm_motulator",
        "final_iq_jaxobs", "final_iq_motulator"}``: the largest |Δ| over the common samples (speed, r/min;
        currents per unit of ``i_rated``) and the last sample's values.
    """
    import numpy as np

    n_j, d_j, q_j = (np.asarray(x) for x in ours)
    n_m, d_m, q_m = (np.asarray(peer[k]) for k in ("rpm", "i_d", "i_q"))
    k = min(n_j.size, n_m.size)
    di = np.hypot(d_j[:k] - d_m[:k], q_j[:k] - q_m[:k])
    return {"samples": int(k), "speed_rpm": float(np.max(np.abs(n_j[:k] - n_m[:k]))),
            "i_dq_pu": float(di.max() / i_rated), "i_d_pu": float(np.max(np.abs(d_j[:k] - d_m[:k])) / i_rated),
            "i_q_pu": float(np.max(np.abs(q_j[:k] - q_m[:k])) / i_rated), "final_rpm_jaxobs": float(n_j[k - 1]),
            "final_rpm_motulator": float(n_m[k - 1]), "final_iq_jaxobs": float(q_j[k - 1]),
            "final_iq_motulator": float(q_m[k - 1])}  # fmt: skip


def _row(label: str, j: tuple[float, float], m: tuple[float, float] | None, how: str) -> str:
    line = f"{label:<26} {j[0]:>10.3f} {j[1]:>9.3f} |"
    if m is None:
        return line + " motulator skipped"
    return line + f" {m[0]:>12.3f} {m[1]:>9.3f} {how:<13} | {m[0] / j[0]:>9.1f} {m[1] / j[1]:>8.1f}"


def time_table(ours: dict, peer: dict | None, horizon: float) -> list[str]:
    """The timing rows: label, jaxobs wall and CPU, motulator's (measured or extrapolated), the ratios.

    Args:
        ours: :func:`jaxobs_timing`'s result.
        peer: :func:`motulator_timing`'s, or None.
        horizon: The batch rows' run, s.

    Returns:
        The table's lines.
    """
    head = f"{'row':<26} {'jaxobs s':>10} {'CPU s':>9} | {'motulator s':>12} {'CPU s':>9} {'how':<13} | "
    rows = [head + f"{'wall ×':>9} {'CPU ×':>8}"]
    warm = min(ours["warm"])
    if peer is None:
        rows += [_row("1 scenario, cold", ours["cold"], None, ""), _row("1 scenario, warm", warm, None, "")]
    else:
        m_warm = min(tuple(w) for w in peer["warm_s"])
        rows += [_row(f"1 scenario {SCENARIO['t_end']:g} s, cold", ours["cold"], tuple(peer["cold_s"]), "measured"),
                 _row(f"1 scenario {SCENARIO['t_end']:g} s, warm", warm, m_warm, "measured")]  # fmt: skip
    per = None
    if peer is not None and peer["batch_s"]:
        runs = peer["batch_s"]
        per = (sum(r[0] for r in runs) / len(runs), sum(r[1] for r in runs) / len(runs))
    for n, b in ours["batches"].items():
        m = None if per is None else (n * per[0], n * per[1])
        how = "measured" if n <= (0 if peer is None else len(peer["batch_s"])) else "extrapolated"
        if m is not None and how == "measured":
            m = (sum(r[0] for r in peer["batch_s"][:n]), sum(r[1] for r in peer["batch_s"][:n]))  # type: ignore[index]
        rows.append(_row(f"batch {n} × {horizon:g} s", b["best"], m, how))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument(
        "--motulator-python",
        default=os.environ.get("MOTULATOR_PYTHON"),
        help="a Python with motulator 0.18 (default $MOTULATOR_PYTHON; none: motulator is skipped)",
    )
    ap.add_argument("--batches", type=int, nargs="+", default=[1, 64, 1024, 8192], help="jaxobs's batch sizes")
    ap.add_argument("--batch-horizon", type=float, default=1.0, help="the batch rows' run, s (default 1)")
    ap.add_argument("--repeats", type=int, default=3, help="timed calls per batch row, the best kept (default 3)")
    ap.add_argument("--max-runs", type=int, default=8, help="motulator's batch scenarios at most (default 8)")
    ap.add_argument("--budget-s", type=float, default=60.0, help="motulator's batch scenarios' budget, s")
    ap.add_argument("--json", type=Path, help="also write the numbers to this file")
    args = ap.parse_args(argv)
    if any(n < 1 for n in args.batches) or args.repeats < 1 or args.max_runs < 1:
        ap.error("--batches, --repeats and --max-runs must be >= 1")
    batch_scenario(args.batch_horizon)  # checks it
    python = args.motulator_python
    if python and not (Path(python).is_file() or shutil.which(python)):
        ap.error(f"--motulator-python / $MOTULATOR_PYTHON: no such Python: {python}")  # before minutes of jaxobs
    import jax

    jax.config.update("jax_enable_x64", True)
    start = _uptime()
    print(time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), f"jax {jax.__version__}, float64")
    print(f"machine: {_machine()} (shared: other work on it moves every time; the load average at start and end)")
    print(f"start: {start}", flush=True)
    ours = jaxobs_timing(args.batches, args.batch_horizon, args.repeats)
    peer = None
    if args.motulator_python:
        peer = motulator_timing(args.motulator_python, args.batches, args.batch_horizon, args.max_runs, args.budget_s)
    return _report(args, start, ours, peer)


def _report(args: argparse.Namespace, start: str, ours: dict, peer: dict | None) -> int:
    """Print the agreement and timing tables and write the JSON (:func:`main`'s second half)."""
    import jax

    sc = SCENARIO
    print(f"scenario: {LAB.name}, sensored, float64: from rest, speed ramp to {sc['rpm']:g} r/min in "
          f"{sc['ramp_s']:g} s, {sc['load_nm']:g} N·m at {sc['load_at']:g} s, {sc['t_end']:g} s at 8 kHz")  # fmt: skip
    i_rated = math.sqrt(2) * 4.3
    agree: dict[str, Any] = {}
    if peer is not None:
        agree["speed_every_1"] = agreement(ours["trajectory"], peer["trajectory"], i_rated)
        file_run = jax.jit(jaxobs_run(speed_every=None))
        agree["speed_every_file"] = agreement(file_run(sc["rpm"], sc["load_nm"]), peer["trajectory"], i_rated)
        print(f"agreement with motulator {peer['motulator']} (sample instants t_k = k·T_s, max |Δ| over the run; "
              f"currents per unit of √2·4.3 A):")  # fmt: skip
        agree["fast_motulator"] = agreement(ours["trajectory"], peer["variants"][0], i_rated)
        rows = (
            ("speed_every_1", "jaxobs, speed loop every period"),
            ("speed_every_file", "jaxobs, the file's 1 kHz loop"),
            ("fast_motulator", "motulator's 2 lags moved out *"),
        )
        for key, label in rows:
            a = agree[key]
            print(f"  {label:<33}: speed {a['speed_rpm']:.3f} r/min, |Δi_dq| {a['i_dq_pu']:.4f} pu "
                  f"(i_d {a['i_d_pu']:.4f}, i_q {a['i_q_pu']:.4f}) over {a['samples']} samples; final "
                  f"{a['final_rpm_jaxobs']:.2f} vs {a['final_rpm_motulator']:.2f} r/min, "
                  f"i_q {a['final_iq_jaxobs']:.4f} vs {a['final_iq_motulator']:.4f} A")  # fmt: skip
        hz = {k: v / (2 * math.pi) for k, v in FAST_MOTULATOR.items()}
        print(f"  * jaxobs every period against motulator with alpha_ref = 2π·{hz['alpha_ref']:g} rad/s (its current "
              f"reference's tracking, default 2π·100) and alpha_o = 2π·{hz['alpha_o']:g} rad/s "
              f"(its speed observer on the measured angle, "
              f"default 2π·400): the lags jaxobs's FOC does not have")  # fmt: skip
    else:
        print("motulator: skipped (no --motulator-python or $MOTULATOR_PYTHON)")
    print("time (wall and CPU seconds; × = motulator / jaxobs):")
    for line in time_table(ours, peer, args.batch_horizon):
        print("  " + line)
    if peer is not None:
        n = len(peer["batch_s"])
        per = sum(r[0] for r in peer["batch_s"]) / max(n, 1)
        print(f"  motulator: {n} batch scenarios run one after another, {per:.3f} s each (wall); rows above {n} "
              f"are extrapolated = n × that, not measured; its import {peer['import_s'][0]:.2f} s, its whole "
              f"process {peer['process'][0]:.1f} s wall, {peer['process'][1]:.1f} s CPU (getrusage)")  # fmt: skip
    print("  jaxobs: each batch row's first call (compiling) apart: " + ", ".join(
        f"{n}: {b['compile'][0]:.1f} s" for n, b in ours["batches"].items()))  # fmt: skip
    end = _uptime()
    print(f"end: {end}")
    if args.json is not None:
        doc = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "uptime_start": start, "uptime_end": end,
               "machine": _machine(), "scenario": SCENARIO, "batch_horizon_s": args.batch_horizon,
               "agreement": agree, "jaxobs": {k: v for k, v in ours.items() if k != "trajectory"},
               "motulator": None if peer is None else {k: v for k, v in peer.items() if k != "trajectory"}}  # fmt: skip
        args.json.write_text(json.dumps(doc, indent=1, default=str) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
