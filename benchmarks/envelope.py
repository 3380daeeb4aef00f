"""The envelope map's cost (target: 200 operating points × 3 designs in ≤ 60 s, compile included).

    .venv/bin/python -m benchmarks.envelope [--speeds 20] [--loads 10] [--horizon 2] [--method floquet|lyapunov]
        [--matrix auto|full|free] [--runs 1] [--out MAP.nc]

000's SPMSM on its bench drive, sensorless; three designs of the second-order SOIFO (the job's initial gains,
000's closed form, and a third as a tuned one would be: another lam), so one program serves all three, as
in `jaxobs envelope RESULT.json`.  No persistent compile cache: a fresh process compiles everything.  Prints
the wall time with the machine's load average beside it (a shared machine: the number means little without
it), the process's CPU time (what it would cost alone, summed over its threads) and the envelope's summary.
``--runs 2`` maps again in the same process: the first run is cold (compile included), the later ones warm.
``--out`` writes the last run's map (NetCDF), to compare the verdicts of two trees or options point by point.
"""

from __future__ import annotations

import argparse
import os
import time


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.envelope")
    p.add_argument("--speeds", type=int, default=20)
    p.add_argument("--loads", type=int, default=10)
    p.add_argument("--horizon", type=float, default=2.0)
    p.add_argument("--method", choices=("floquet", "lyapunov"), default="floquet", help="the stability verdict")
    p.add_argument(
        "--matrix", choices=("auto", "full", "free"), default="auto", help="floquet's path (stability.floquet)"
    )
    p.add_argument("--runs", type=int, default=1, help="maps in this process: the first cold, the rest warm")
    p.add_argument("--out", default=None, help="write the last run's map here (NetCDF)")
    a = p.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxobs
    from jaxobs.analysis.envelope import default_loads, default_speeds, envelope
    from jaxobs.drive import bench_drive, bench_machine

    par = bench_machine("spmsm000")
    designs = {
        "initial": jaxobs.SecondOrderSOIFO(0.0, 1.0, 1.56, 3.11, 0.61, 100.0),
        "closed_form": jaxobs.SecondOrderSOIFO(0.0, 1.0, 1.56, 3.11, 1.56**3 / (2 * 3.11), 100.0),
        "tuned-like": jaxobs.SecondOrderSOIFO(0.0, 1.0, 1.8, 3.4, 0.9, 100.0),
    }
    speeds, loads = default_speeds(par, a.speeds), default_loads(par, a.loads)
    n = len(speeds) * len(loads)
    stab = {"method": a.method} if a.method == "lyapunov" else {"method": a.method, "matrix": a.matrix}
    what = a.method if a.method == "lyapunov" else f"floquet, matrix {a.matrix}"
    for run in range(max(a.runs, 1)):
        load0 = os.getloadavg()
        t0, c0 = time.perf_counter(), time.process_time()
        ds = envelope(designs, machine=par, drive=bench_drive(par), speeds_rpm=speeds, loads_nm=loads,
                      horizon=a.horizon, stability=stab)  # fmt: skip
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        load1 = os.getloadavg()
        print(
            f"envelope ({what}, run {run + 1}, {'cold' if run == 0 else 'warm'}): {n} points x {len(designs)} "
            f"designs, {a.horizon:g} s runs: {wall:.1f} s wall, {cpu:.1f} s CPU "
            f"(this process, all threads){', compile included' if run == 0 else ''} ({os.cpu_count()} CPUs; "
            f"1-min load average {load0[0]:.1f} before, {load1[0]:.1f} after)"
        )
        for d in designs:
            s = ds.sel(design=d)
            print(f"  {d:<12} holds at {int(s['holds'].sum())}/{n}, stable at {int(s['stable'].sum())}/{n}")
    if a.out:
        ds.to_netcdf(a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
