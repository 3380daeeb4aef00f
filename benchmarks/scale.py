"""Scale: an FLL study of 10⁴ … 10⁶ scenarios, results streamed to disk chunk by chunk (issue 31.5).

    python -m benchmarks.scale [--scenarios 10000 100000] [--horizon 0.01] [--held]

Each size runs in a fresh process (so its peak RSS is its own): ``run_study`` of the SOGI-FLL-WIF on
random scenarios (4 axes), float64, chunks of 2048, one device, with a :class:`jaxobs.chunkstore.ChunkStore`
in a temporary folder (each chunk's metrics to disk as it finishes, as ``jaxobs study`` does), then the
Dataset written as study.nc (NetCDF4, h5netcdf).  ``--held``: without the store (every chunk's values held
in memory until the end), for comparison.  Reported: the wall time of the study (compilation included, from
the persistent cache when warm), scenarios/s, the peak RSS of the process (``resource.getrusage``) and the
1-minute load average at the start (the machine may be shared).  A short horizon keeps the runs short:
what is measured is the runner's overhead and memory, not the loop's pace (``make bench`` has that).
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


def _worker(scenarios: int, horizon: float, held: bool) -> None:
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxobs
    from jaxobs import linear
    from jaxobs.chunkstore import ChunkStore
    from jaxobs.study import run_study

    jaxobs.use_compile_cache()
    with tempfile.TemporaryDirectory(prefix="jaxobs-scale-") as tmp:
        store = None if held else ChunkStore(Path(tmp) / "study.chunks", "scale")
        t0 = time.perf_counter()
        ds = run_study(
            {"WIF": linear.wif_closed_form()},
            AXES,
            sample=scenarios,
            chunk_size=2048,
            t_event=horizon / 2,
            horizon=horizon,
            store=store,
            mesh=jaxobs.batch_mesh(jax.devices()[:1]),
        )
        study_s = time.perf_counter() - t0
        ds.to_netcdf(Path(tmp) / "study.nc", engine="h5netcdf")
        total_s = time.perf_counter() - t0
    rss_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB
    print(
        json.dumps(
            {
                "scenarios": scenarios,
                "streamed": not held,
                "study_s": round(study_s, 2),
                "with_netcdf_s": round(total_s, 2),
                "scenarios_per_s": round(scenarios / total_s),
                "peak_rss_mib": round(rss_mib),
            }
        )
    )


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m benchmarks.scale", description=__doc__.split("\n")[0])
    p.add_argument("--scenarios", type=int, nargs="+", default=[10_000, 100_000], help="study sizes, one process each")
    p.add_argument("--horizon", type=float, default=0.01, help="seconds simulated per scenario (event at half)")
    p.add_argument("--held", action="store_true", help="hold every chunk in memory (no store), for comparison")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        return _worker(a.scenarios[0], a.horizon, a.held)
    print(f"load average (1 min) {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; horizon {a.horizon} s")
    for n in a.scenarios:
        cmd = [sys.executable, "-m", "benchmarks.scale", "--worker", "--scenarios", str(n), "--horizon", str(a.horizon)]
        subprocess.run(cmd + (["--held"] if a.held else []), check=True)


if __name__ == "__main__":
    main()
