"""A study on one device, on the host devices of one process, and split over processes (README, Performance).

    python -m benchmarks.study_processes [--scenarios 8192] [--runs 3] [--processes 2]

Each configuration runs in fresh processes (JAX fixes its device count at start-up), ``--runs`` times:
``run_study`` of the SOGI-FLL-WIF on random scenarios (4 axes), 0.4 s, float64, chunks of 2048, no
persistent compilation cache, so every run compiles (``run_study`` traces anew per call) as a user's
study does.  Reported per run: the wall time and the CPU cores busy (``os.times`` over the run); for
the split, process 0's (the processes wait for each other at every chunk, so their times agree).
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import time

AXES = {"freq_step": [-3.0, 3.0], "phase_jump_deg": [-60.0, 60.0], "dc": [0.0, 0.1], "harmonics_scale": [0.0, 2.0]}


def _worker(devices: int, scenarios: int, runs: int, coordinator: str | None, nproc: int, pid: int) -> None:
    import jax

    import jaxobs

    jaxobs.use_host_devices(devices)
    jax.config.update("jax_enable_x64", True)
    if coordinator:
        jaxobs.init_distributed(coordinator, nproc, pid)
    from jaxobs import linear
    from jaxobs.studies.study import run_study

    designs = {"WIF": linear.wif_closed_form()}
    rows = []
    for _ in range(runs):
        c0, w0 = sum(os.times()[:2]), time.perf_counter()
        run_study(designs, AXES, sample=scenarios, chunk_size=2048, horizon=0.4)
        w = time.perf_counter() - w0
        rows.append(f"{w:.2f} s ({(sum(os.times()[:2]) - c0) / w:.2f} cores)")
    if jax.process_index() == 0:
        print(f"{jax.process_count()} process(es) x {len(jax.local_devices())} device(s): " + ", ".join(rows))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        prog="python -m benchmarks.study_processes",
        description=__doc__.split("\n")[0] + " (1–2 minutes in all with the defaults on a 2-core machine)",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--scenarios", type=int, default=8192, help="scenarios of the study")
    p.add_argument("--runs", type=int, default=3, help="runs of each setup; the best is reported")
    p.add_argument("--processes", type=int, default=2, help="processes (and host devices) to compare with one")
    p.add_argument("--worker", nargs=4, metavar=("DEVICES", "COORDINATOR", "NPROC", "PID"), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        devices, coordinator, nproc, pid = a.worker
        _worker(int(devices), a.scenarios, a.runs, None if coordinator == "-" else coordinator, int(nproc), int(pid))
        return
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAXOBS_HOST_DEVICES")}
    env.setdefault("JAX_PLATFORMS", "cpu")
    base = [sys.executable, "-m", "benchmarks.study_processes", "--scenarios", str(a.scenarios), "--runs", str(a.runs)]
    n = a.processes
    for devices in (1, n):  # one process: one device, then n host devices
        subprocess.run([*base, "--worker", str(devices), "-", "1", "0"], env=env, check=True)
    coordinator = f"127.0.0.1:{_free_port()}"
    procs = [subprocess.Popen([*base, "--worker", "1", coordinator, str(n), str(i)], env=env) for i in range(n)]
    for q in procs:
        if q.wait(timeout=1800):
            sys.exit(f"process failed with exit status {q.returncode}")


if __name__ == "__main__":
    main()
