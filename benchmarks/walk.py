"""A tune job walked through the code: which modules a reader visits, in order, and how often each is come back to.

The walk is the job's call tree read once, depth first, the way a reader follows a call: every Python call from one
function of the project (``jaxobs``, ``jaxobs_tuning``) to another is recorded the first time that call site (caller,
callee) is taken, and left out when taken again (a solver's second step reads the same code as its first).  Calls
into the same module are part of the stay there; a call into another module starts a new stay.  A module's
*returns* are its stays after the first: a reader who comes back to a module for the third time has met a module
that does two jobs, or a flow that bounces.

Run from the repository root::

    python -m benchmarks.walk [JOB.toml] [--steps N] [--depth D] [--out DIR]

It runs the job (default: ``tuning/presets/sogi_fll.toml`` with 2 solver steps, to keep it short) with
``jaxobs_tuning.job.run_job`` under ``sys.setprofile``, prints the modules in visiting order with their stays, and
the module with the most returns.  ``--depth`` keeps only calls at most D project frames below ``run_job`` (default
3: the orchestration a reader follows; deeper calls are the observers, metrics and the loop's internals).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _module(code) -> str | None:
    """The project module a code object belongs to, or None."""
    f = code.co_filename
    for top, pkg in (("jaxobs", "jaxobs"), ("tuning", "jaxobs_tuning")):
        base = ROOT / top
        if f.startswith(str(base) + "/"):
            rel = Path(f).relative_to(base).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            return ".".join([pkg, *parts])
    return None


def walk(job_path: Path, steps: int, depth: int) -> list[str]:
    """The modules visited, one entry per stay, in order.

    Args:
        job_path: The tune job.
        steps: The solver's steps (the job's own are replaced).
        depth: The deepest project frame kept, counted from ``run_job``.

    Returns:
        One module name per stay.
    """
    from jaxobs_tuning.job import load_job, run_job

    job = load_job(job_path)
    job = dataclasses.replace(job, solver=dataclasses.replace(job.solver, steps=steps))
    seen: set[tuple] = set()
    order: list[str] = []
    stack: list[tuple] = []  # (code, module) of the project frames below run_job

    def profile(frame, event, arg):
        if event == "call":
            mod = _module(frame.f_code)
            if mod is None:
                return
            if not stack and frame.f_code.co_name != "run_job":
                return
            caller = stack[-1][0] if stack else None
            stack.append((frame.f_code, mod))
            if len(stack) - 1 > depth:
                return
            edge = (caller, frame.f_code)
            if edge in seen:
                return
            seen.add(edge)
            if not order or order[-1] != mod:
                order.append(mod)
        elif event == "return" and stack and stack[-1][0] is frame.f_code:
            stack.pop()

    with tempfile.TemporaryDirectory() as out:
        sys.setprofile(profile)
        try:
            run_job(job, Path(out), quiet=True)
        finally:
            sys.setprofile(None)
    return order


def main(argv: list[str] | None = None) -> int:
    """Print the walk of a tune job.

    Args:
        argv: The command line (default ``sys.argv[1:]``).

    Returns:
        0.
    """
    ap = argparse.ArgumentParser(prog="python -m benchmarks.walk", description=__doc__.splitlines()[0])
    ap.add_argument("job", nargs="?", default=str(ROOT / "tuning/presets/sogi_fll.toml"))
    ap.add_argument("--steps", type=int, default=2)
    ap.add_argument("--depth", type=int, default=3)
    args = ap.parse_args(argv)
    order = walk(Path(args.job), args.steps, args.depth)
    stays = Counter(order)
    print(f"{len(order)} stays in {len(stays)} modules, {sum(n - 1 for n in stays.values())} returns in all")
    for i, mod in enumerate(order):
        print(f"{i + 1:3d}  {mod}")
    print("stays per module (returns = stays - 1):")
    for mod, n in stays.most_common():
        print(f"  {n:2d}  {mod}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
