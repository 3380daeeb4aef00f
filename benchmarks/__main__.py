"""``python -m benchmarks [--quick] [--json] [--out FILE] [--only PART ...] [--no-time-to-result] [--no-scale]``.

Run from the repository root (``make bench`` is the full run).  The full run has three parts, in this order:
``throughput`` (the rows of :func:`benchmarks.run.run_bench` with their same-run ratios, the ceilings,
gradient and compile figures), ``time-to-result`` (``make run``'s job twice in fresh processes, the first
with an empty compilation cache: :mod:`benchmarks.first_second`) and ``scale`` (an FLL study of 10⁶
scenarios and a drive study of 10⁵ streamed to disk, peak RSS: :mod:`benchmarks.scale`); their tables are
printed in that order and go into the JSON under ``"rows"`` (and the throughput figures' own keys),
``"time_to_result"`` and ``"scale"``, with each part's wall seconds under ``"parts_s"``.  ``--only PART ...``
runs only the parts named (``--only time-to-result scale``: the two after the throughput rows);
``--no-time-to-result`` and ``--no-scale`` leave one out.  ``--quick`` is the throughput part only, at batch
1024 in float64 (a look at the reference rows).  With ``--out`` the file is written after each part, so a
part that fails (reported in its table and the JSON as ``{"error": ...}``, exit status 1) keeps what ran.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

# numba's OpenMP threads sleep when idle instead of spinning: a spinning pool kept both cores busy after every
# numba call, slowing whichever implementation was timed next (set before numba starts its threads)
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import jaxobs

from . import extra
from .run import run_bench, table


def parse_args(argv=None) -> argparse.Namespace:
    """The command line; ``.parts`` is the parts to run, in :data:`benchmarks.extra.PARTS` order."""
    p = argparse.ArgumentParser(
        prog="python -m benchmarks",
        description="scenario-steps/s of jaxobs beside NumPy and numba, gradient cost and memory; time to result "
        "and scale",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="the throughput part only: batch 1024, float64, jaxobs beside the batch-inner numba kernels and "
        "NumPy (a few minutes on 2 cores, mostly numba's compilation)",
    )
    p.add_argument("--json", action="store_true", help="print the results as JSON (progress goes to stderr)")
    p.add_argument("--out", help="also write the JSON results to this file (rewritten after each part)")
    p.add_argument("--batches", type=int, nargs="+", help="batch sizes (default 1 64 1024 8192; --quick 1024)")
    p.add_argument("--no-serial", action="store_true", help="leave out the serial scalar numba rows")
    p.add_argument(
        "--only",
        nargs="+",
        choices=extra.PARTS,
        metavar="PART",
        help=f"run only these parts ({', '.join(extra.PARTS)}; default all three, --quick throughput)",
    )
    p.add_argument(
        "--no-time-to-result",
        action="store_true",
        help="leave out make run's first and second run (41 s at load 3; minutes under load)",
    )
    p.add_argument(
        "--no-scale", action="store_true", help="leave out the 10⁶ FLL / 10⁵ drive studies (1 min at load 4)"
    )
    a = p.parse_args(argv)
    only = set(a.only or extra.PARTS)
    if a.quick and a.only and only - {"throughput"}:
        p.error("--quick is the throughput part only; leave it out to run time-to-result or scale")
    for part, flag in (("time-to-result", a.no_time_to_result), ("scale", a.no_scale)):
        if flag and a.only and part in only:
            p.error(f"--only {part} and --no-{part} contradict each other")
    if a.quick:
        only = {"throughput"}
    only -= {part for part, flag in (("time-to-result", a.no_time_to_result), ("scale", a.no_scale)) if flag}
    if not only:
        p.error("nothing to run: every part is left out")
    if "throughput" not in only and (a.batches is not None or a.no_serial):
        p.error("--batches and --no-serial choose throughput rows, and the throughput part is not run")
    a.parts = tuple(part for part in extra.PARTS if part in only)
    return a


def main(argv=None) -> int:
    args = parse_args(argv)
    log = (lambda m: print(m, file=sys.stderr)) if args.json else print
    res: dict = {"parts_s": {}}

    def save():
        if args.out:
            path = Path(args.out)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(res, indent=1))

    failed = False
    if "throughput" in args.parts:
        # before any JAX computation: one JAX CPU device per usable core; the jaxobs rows shard the batch over them
        jaxobs.use_host_devices()
        batches = None if args.batches is None else tuple(args.batches)
        part = None if not args.out else str(Path(args.out).with_suffix(".partial.json"))
        t0 = time.perf_counter()
        res.update(run_bench(quick=args.quick, log=log, batches=batches, serial=not args.no_serial, partial_out=part))
        res["parts_s"]["throughput"] = round(time.perf_counter() - t0, 1)
        save()
        if part:
            Path(part).unlink(missing_ok=True)
    # each in fresh processes of its own: this process's JAX and numba state do not enter their numbers
    for name, key, run in (
        ("time-to-result", "time_to_result", extra.time_to_result),
        ("scale", "scale", extra.scale_rows),
    ):
        if name not in args.parts:
            continue
        t0 = time.perf_counter()
        try:
            res[key] = run(log)
        except (Exception, SystemExit) as e:  # first_second exits, scale raises: keep the other parts
            failed = True
            res[key] = {"error": f"{type(e).__name__}: {e}"[:1000]}
            log(f"{name} failed: {res[key]['error']}")
        res["parts_s"][name] = round(time.perf_counter() - t0, 1)
        save()
    if args.json:
        print(json.dumps(res, indent=1))
    else:
        print("\n\n".join(s for s in (table(res) if "rows" in res else "", extra.tables(res)) if s))
        print("wall time of the parts, s: " + ", ".join(f"{k} {v:.0f}" for k, v in res["parts_s"].items()))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
