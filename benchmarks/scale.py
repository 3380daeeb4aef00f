"""Scale: an FLL study of 10⁴ … 10⁶ scenarios, or a drive study, results streamed to disk chunk by chunk.

    python -m benchmarks.scale [--scenarios 10000 100000] [--horizon 0.01] [--held]
    python -m benchmarks.scale --kind drive [--scenarios 10000 100000] [--horizon 0.005]

Each size runs in a fresh process (so its peak RSS is its own): ``run_study`` of the SOGI-FLL-WIF on
random scenarios (4 axes), float64, chunks of 2048, one device, with a :class:`jaxobs.runtime.chunkstore.ChunkStore`
in a temporary folder (each chunk's metrics to disk as it finishes, as ``jaxobs study`` does), then the
Dataset written as study.nc (NetCDF4, h5netcdf).  ``--held``: without the store (every chunk's values held
in memory until the end), for comparison.  Reported: the wall time of the study (compilation included, from
the persistent cache when warm), scenarios/s, the peak RSS of the process (its VmHWM: see ``_peak_rss_mib``) and the
1-minute load average at the start (the machine may be shared).  ``--kind drive``: ``run_study`` on the drive family of
paper 000's second-order SOIFO closing the loop of its SPMSM (the drive jobs' bench, ``spmsm000``),
sensorless, on Sobol points over speed × load × Rs mismatch × voltage noise (``study_flux_drive.toml``'s
axes), float64, chunks of 1024, one device, streamed the same way; its settling pass before t = 0 is
the drive's own, so even a short horizon runs several hundred steps a scenario.  A short horizon keeps the runs short:
what is measured is the runner's overhead and memory, not the loop's pace (``make bench`` has that).

:func:`measure` gives the rows and :func:`table` the Markdown table; ``make bench`` (``python -m benchmarks``)
calls them for the FLL at 10⁶ scenarios and the drive at 10⁵ after its throughput rows (:mod:`benchmarks.extra`).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

AXES = {"freq_step": [-3.0, 3.0], "phase_jump_deg": [-60.0, 60.0], "dc": [0.0, 0.1], "harmonics_scale": [0.0, 2.0]}
SETTLE = 0.01  # s: the drive's settling pass before t = 0 (the jobs' 0.2 s would be 40x the horizon)
ROOT = Path(__file__).resolve().parents[1]  # the repository root
DRIVE_AXES = {"speed_rpm": [400.0, 2000.0], "load_nm": [0.0, 10.0], "dRs": [-0.5, 0.5], "u_noise": [0.0, 2.0]}


def _drive_study(scenarios: int, horizon: float, store, mesh):
    import jaxobs
    from jaxobs import drive as D
    from jaxobs import linear, papers
    from jaxobs.scenarios.families import DriveScenarios
    from jaxobs.studies.study import run_study

    par = D.bench_machine("spmsm000")
    k1, k2 = papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2
    lam = linear.second_order_soifo_lambda(k1, k2)
    obs = jaxobs.SecondOrderSOIFO(par.Rs, par.Ld, k1, k2, lam, omega_init=par.p * 1000 * D.RPM)  # bound per scenario
    return run_study(
        {"second-order-SOIFO": obs},
        DRIVE_AXES,
        family=DriveScenarios(par, D.bench_drive(par, settle=SETTLE)),
        horizon=horizon,
        sampling="sobol",
        sample=scenarios,
        chunk_size=1024,
        store=store,
        mesh=mesh,
    )


def _peak_rss_mib() -> float:
    """This process's peak resident memory, MiB: Linux's VmHWM (/proc/self/status), the high-water mark of
    this program's own memory.  Not ``getrusage``'s ru_maxrss: Linux keeps that across fork and exec, so a
    worker started by ``make bench`` after its throughput part (a parent at 9.9 GB after the 10 s reverse-mode
    gradient) reported the parent's 9 902 MiB as its own.  Elsewhere ru_maxrss (KiB on Linux, bytes on macOS)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024  # kB
    except OSError:
        pass
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / 2**20 if sys.platform == "darwin" else rss / 1024


def _worker(scenarios: int, horizon: float, held: bool, kind: str = "fll") -> None:
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxobs
    from jaxobs import linear
    from jaxobs.runtime.chunkstore import ChunkStore
    from jaxobs.studies.study import run_study

    jaxobs.use_compile_cache()
    with tempfile.TemporaryDirectory(prefix="jaxobs-scale-") as tmp:
        store = None if held else ChunkStore(Path(tmp) / "study.chunks", "scale")
        t0 = time.perf_counter()
        mesh = jaxobs.batch_mesh(jax.devices()[:1])
        if kind == "drive":
            ds = _drive_study(scenarios, horizon, store, mesh)
        else:
            ds = run_study(
                {"WIF": linear.wif_closed_form()},
                AXES,
                sample=scenarios,
                chunk_size=2048,
                t_event=horizon / 2,
                horizon=horizon,
                store=store,
                mesh=mesh,
            )
        study_s = time.perf_counter() - t0
        ds.to_netcdf(Path(tmp) / "study.nc", engine="h5netcdf")
        total_s = time.perf_counter() - t0
    rss_mib = _peak_rss_mib()
    print(
        json.dumps(
            {
                "kind": kind,
                "scenarios": scenarios,
                "streamed": not held,
                "study_s": round(study_s, 2),
                "with_netcdf_s": round(total_s, 2),
                "scenarios_per_s": round(scenarios / total_s),
                "peak_rss_mib": round(rss_mib),
            }
        )
    )


def default_horizon(kind: str) -> float:
    """Seconds simulated per scenario when none is given: FLL 0.01 (event at half), drive 0.005."""
    return 0.005 if kind == "drive" else 0.01


def measure(scenarios, kind: str = "fll", horizon: float | None = None, held: bool = False, log=print) -> list[dict]:
    """One study per size in ``scenarios``, each in a fresh process (its peak RSS its own); one row a size.

    A row is the worker's (``kind``, ``scenarios``, ``streamed``, ``study_s``, ``with_netcdf_s`` (s),
    ``scenarios_per_s``, ``peak_rss_mib``) with ``horizon`` (s) and ``load`` (the 1-minute load average at
    its start and end) added.  ``log`` gets the load line first, then each worker's JSON line as it ends.
    """
    if kind not in ("fll", "drive"):
        raise ValueError(f"scale: kind must be 'fll' or 'drive', got {kind!r}")
    horizon = default_horizon(kind) if horizon is None else horizon
    log(f"load average (1 min) {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; horizon {horizon} s")
    rows = []
    for n in scenarios:
        cmd = [sys.executable, "-m", "benchmarks.scale", "--worker", "--scenarios", str(n), "--horizon", str(horizon)]
        cmd += ["--kind", kind]
        load0 = os.getloadavg()[0]
        # stdout read back (the worker's last line is its JSON row), stderr passed through; from the repository
        # root, where `-m benchmarks.scale` is found wherever the caller runs
        proc = subprocess.run(
            cmd + (["--held"] if held else []), check=True, stdout=subprocess.PIPE, text=True, cwd=ROOT
        )
        line = proc.stdout.strip().splitlines()[-1]
        log(line)
        row = json.loads(line)
        row["horizon"] = horizon
        row["load"] = [round(load0, 1), round(os.getloadavg()[0], 1)]
        rows.append(row)
    return rows


def table(rows: list[dict]) -> str:
    """The rows of :func:`measure` as a Markdown table (docs/performance.md, Scale)."""
    lines = [
        "| study | scenarios | horizon (s) | streamed | study (s) | with study.nc (s) | scenarios/s | peak RSS (MiB) "
        "| load (start, end) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        load = r.get("load") or ("", "")
        lines.append(
            f"| {r['kind']} | {r['scenarios']:,} | {r.get('horizon', '')} | {'yes' if r['streamed'] else 'no'} | "
            f"{r['study_s']:.1f} | {r['with_netcdf_s']:.1f} | {r['scenarios_per_s']:,} | {r['peak_rss_mib']:,} | "
            f"{load[0]}, {load[1]} |"
        )
    return "\n".join(lines)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m benchmarks.scale", description=__doc__.split("\n")[0])
    p.add_argument("--scenarios", type=int, nargs="+", default=[10_000, 100_000], help="study sizes, one process each")
    p.add_argument("--kind", choices=("fll", "drive"), default="fll", help="an FLL study or a drive study")
    p.add_argument(
        "--horizon", type=float, help="seconds simulated per scenario (FLL: default 0.01, event at half; drive: 0.005)"
    )
    p.add_argument("--held", action="store_true", help="hold every chunk in memory (no store), for comparison")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    horizon = a.horizon if a.horizon is not None else default_horizon(a.kind)
    if a.worker:
        return _worker(a.scenarios[0], horizon, a.held, a.kind)
    measure(a.scenarios, a.kind, horizon, a.held)


if __name__ == "__main__":
    main()
