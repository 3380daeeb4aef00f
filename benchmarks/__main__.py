"""``python -m benchmarks [--quick] [--json] [--out FILE]`` (from the repository root; ``make bench``)."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

# numba's OpenMP threads sleep when idle instead of spinning: a spinning pool kept both cores busy after every
# numba call, slowing whichever implementation was timed next (set before numba starts its threads)
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import jaxobs

from .run import run_bench, table


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m benchmarks",
        description="scenario-steps/s of jaxobs beside NumPy and numba, gradient cost and memory",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="batch 1024, float64, jaxobs beside the batch-inner numba kernels and NumPy "
        "(a few minutes on 2 cores, mostly numba's compilation)",
    )
    p.add_argument("--json", action="store_true", help="print the results as JSON (progress goes to stderr)")
    p.add_argument("--out", help="also write the JSON results to this file")
    p.add_argument("--batches", type=int, nargs="+", help="batch sizes (default 1 64 1024 8192; --quick 1024)")
    p.add_argument("--no-serial", action="store_true", help="leave out the serial scalar numba rows")
    args = p.parse_args(argv)
    # before any JAX computation: one JAX CPU device per usable core; the jaxobs rows shard the batch over them
    jaxobs.use_host_devices()
    log = (lambda m: print(m, file=sys.stderr)) if args.json else print
    batches = None if args.batches is None else tuple(args.batches)
    part = None if not args.out else str(Path(args.out).with_suffix(".partial.json"))
    res = run_bench(quick=args.quick, log=log, batches=batches, serial=not args.no_serial, partial_out=part)
    if part:
        Path(part).unlink(missing_ok=True)
    if args.out:
        path = Path(args.out)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(res, indent=1))
    if args.json:
        print(json.dumps(res, indent=1))
    else:
        print(table(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
