"""Peak memory of a long drive log, read by the library and by a recording job (docs/recordings.md, "Long logs").

``python -m benchmarks.log_memory [--rows 100000 10000000] [--folder /tmp/jaxobs-logs] [--json FILE]``

For each size, a synthetic drive log with a time column (``t, u_a, u_b, i_a, i_b, theta_e, omega_e``: 10 kHz,
1000 r/min on a 3-pole-pair machine, 100 V and 3 A; written once into ``--folder`` and kept there) is read in a
fresh process by each path, and the process's peak RSS is reported (``resource.getrusage``: ``RUSAGE_SELF`` for the
library, ``RUSAGE_CHILDREN`` of a fresh parent for a command):

- ``library``: :func:`jaxobs.signals.read_drive_log`, then a window of 5000 rows as a recording;
- ``tune --check``: ``jaxobs tune JOB --check`` on a recording job that cuts the log into 8 windows of 0.1 s
  (paper 000's second-order SOIFO, ``tuning/presets/recording_sosoifo.toml``'s gains);
- ``tune 1 step``: the same job tuned one Adam step (``jaxobs tune JOB --out DIR --force``).

The job's simulated part is the same at every size (8 windows of 1000 samples); what grows is the file read.
The target: at 10⁷ rows, at most 1.5 × the 10⁵-row peak of the same path.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TS = 1e-4  # s
W_E = 2 * math.pi * 50.0  # rad/s electrical: 1000 r/min, p = 3
CHUNK = 500_000
TARGET = 1.5  # the 10^7-row peak against the 10^5-row one, at most


def write_log(path: Path, rows: int) -> Path:
    """A steady drive log of ``rows`` rows with a time column (kept if it is already there with that many rows).

    Args:
        path: The file.
        rows: Its rows.

    Returns:
        ``path``.
    """
    marker = path.with_name(path.name + ".rows")
    if path.exists() and marker.exists() and marker.read_text() == str(rows):
        return path
    with open(path, "w") as f:
        f.write("t,u_a,u_b,i_a,i_b,theta_e,omega_e\n")
        for a in range(0, rows, CHUNK):
            t = TS * np.arange(a, min(a + CHUNK, rows))
            th = W_E * t
            blk = np.column_stack([t, 100 * np.cos(th + 1.6), 100 * np.sin(th + 1.6), 3 * np.cos(th + 1.7),
                                   3 * np.sin(th + 1.7), np.mod(th, 2 * math.pi), np.full(t.size, W_E)])  # fmt: skip
            np.savetxt(f, blk, delimiter=",", fmt="%.9g")
    marker.write_text(str(rows))
    return path


def write_job(folder: Path, log: Path) -> Path:
    """The recording job on ``log``: 8 windows of 0.1 s, one Adam step.

    Args:
        folder: Where the job file goes.
        log: The drive log.

    Returns:
        The job file.
    """
    text = (ROOT / "tuning" / "presets" / "recording_sosoifo.toml").read_text()
    head = text.split("[scenarios]")[0]
    job = folder / f"job_{log.stem}.toml"
    job.write_text(
        head
        + textwrap.dedent(f"""
        [scenarios]
        signal = "emf"
        t_event = 0.05
        horizon = 0.1
        steady_from = 0.06
        [scenarios.recording]
        file = "{log.name}"
        time_column = "t"
        truth = ["theta_e", "omega_e"]
        windows = 8

        [objective]
        terms = [{{ metric = "iae_position", weight = 1.0 }}]

        [solver]
        kind = "adam"
        learning_rate = 0.05
        steps = 1
        """)
    )
    return job


_SELF = """
import resource, sys
from jaxobs.signals import read_drive_log
log = read_drive_log(sys.argv[1], time_column="t", omega_e="omega_e")
rec = log.recording(log.n // 2, 5000)
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
"""

_CHILD = """
import resource, subprocess, sys
r = subprocess.run(sys.argv[1:], capture_output=True, text=True)
if r.returncode != 0:
    sys.exit(r.stderr[-2000:])
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024)
"""


def _peak(args: list[str]) -> tuple[float, float]:
    t = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", *args], capture_output=True, text=True, cwd=ROOT)
    if out.returncode != 0:
        raise RuntimeError(out.stderr[-2000:])
    return float(out.stdout.split()[-1]), time.perf_counter() - t


def measure(rows: int, folder: Path) -> dict:
    """Each path's peak RSS (MiB) and wall time (s) on a log of ``rows`` rows.

    Args:
        rows: The log's rows.
        folder: Where the log, the job and its results go.

    Returns:
        ``{"rows", "csv_mib", path: {"peak_mib", "seconds"}}``.
    """
    log = write_log(folder / f"log_{rows}.csv", rows)
    job = write_job(folder, log)
    exe = str(Path(sys.executable).with_name("jaxobs"))
    out = {"rows": rows, "csv_mib": log.stat().st_size / 2**20}
    for name, args in (
        ("library", [_SELF, str(log)]),
        ("tune --check", [_CHILD, exe, "tune", str(job), "--check"]),
        ("tune 1 step", [_CHILD, exe, "tune", str(job), "--out", str(folder / f"out_{rows}"), "--force", "--quiet"]),
    ):
        peak, secs = _peak(args)
        out[name] = {"peak_mib": peak, "seconds": secs}
        print(f"  {rows} rows, {name}: {peak:.0f} MiB, {secs:.1f} s", file=sys.stderr)
    return out


PATHS = ("library", "tune --check", "tune 1 step")


def table(res: list[dict]) -> str:
    """The printed table: each path's peak RSS at each size, and the largest size's ratio to the smallest's.

    Args:
        res: :func:`measure`'s results, smallest first.

    Returns:
        The text.
    """
    sizes = [f"{r['rows']:.0e} rows ({r['csv_mib']:.0f} MiB)".replace("e+0", "e") for r in res]
    head = ["path", *sizes, "ratio"]
    rows = []
    for p in PATHS:
        ratio = res[-1][p]["peak_mib"] / res[0][p]["peak_mib"]
        rows.append([p, *(f"{r[p]['peak_mib']:.0f} MiB, {r[p]['seconds']:.0f} s" for r in res), f"{ratio:.2f}"])
    w = [max(len(x[i]) for x in [head, *rows]) for i in range(len(head))]
    lines = ["  ".join(x.ljust(w[i]) if i == 0 else x.rjust(w[i]) for i, x in enumerate(r)) for r in [head, *rows]]
    return "\n".join([lines[0], "  ".join("-" * k for k in w), *lines[1:]])


def main(argv: list[str] | None = None) -> int:
    """The command line (module doc).

    Args:
        argv: The arguments (default ``sys.argv[1:]``).

    Returns:
        The exit status.
    """
    ap = argparse.ArgumentParser(prog="python -m benchmarks.log_memory", description="peak RSS of long drive logs")
    ap.add_argument("--rows", type=int, nargs="+", default=[100_000, 10_000_000])
    ap.add_argument("--folder", type=Path, default=Path("/tmp/jaxobs-logs"), help="the logs (kept), jobs, results")
    ap.add_argument("--json", type=Path, default=None, help="also write the results here")
    args = ap.parse_args(argv)
    args.folder.mkdir(parents=True, exist_ok=True)
    # a first tune fills the compilation cache, so that each size's peak is its run's, not a cold compile's
    # (which the first measured size alone would carry)
    first = min(args.rows)
    job = write_job(args.folder, write_log(args.folder / f"log_{first}.csv", first))
    exe = str(Path(sys.executable).with_name("jaxobs"))
    cold, secs = _peak([_CHILD, exe, "tune", str(job), "--out", str(args.folder / "warm"), "--force", "--quiet"])
    print(f"  warm-up: {first} rows, tune 1 step with a cold cache: {cold:.0f} MiB, {secs:.1f} s", file=sys.stderr)
    res = [measure(n, args.folder) for n in sorted(args.rows)]
    print(table(res))
    if args.json is not None:
        warm = {"rows": first, "peak_mib": cold, "seconds": secs}
        args.json.write_text(json.dumps({"target_ratio": TARGET, "cold_tune": warm, "sizes": res}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
