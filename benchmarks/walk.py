"""A tune job walked through the code: which modules a reader enters, in order, and how often each is come back to.

The walk is the job's call tree read once, depth first, the way a reader follows a call.  Reading a function, the
reader opens each other project module (``jaxobs``, ``jaxobs_tuning``) it calls once, however many of that
module's functions it calls: an *entry* into a module is a call into it from a function of another module, counted
once per calling function (a comprehension or generator counts as the function it is written in).  Coming back
from a call is no new entry (the reader is back in the function being read), nor is a call inside one module.  A
module's *returns* are its entries after the first: a module entered from three places of the flow does more than
one job, or the flow bounces through it.  A *climb* is an entry into a module already on the call stack (a callee
calling back up into its caller's module).

Run from the repository root::

    python -m benchmarks.walk [JOB.toml] [--steps N] [--depth D]

It runs the job (default: ``tuning/presets/sogi_fll.toml`` with 2 solver steps, to keep it short) with
``jaxobs_tuning.job.run_job`` under ``sys.setprofile``, prints the entries in visiting order, the entries per
module and the climbs.  ``--depth`` keeps only calls at most D project frames below ``run_job`` (default 3: the
orchestration a reader follows; deeper calls are the observers, metrics and the loop's internals).
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


def walk(job_path: Path, steps: int, depth: int) -> tuple[list[tuple[str, str]], list[tuple[str, str]]]:
    """The modules entered, in order, and the climbs.

    Args:
        job_path: The tune job.
        steps: The solver's steps (the job's own are replaced).
        depth: The deepest project frame kept, counted from ``run_job``.

    Returns:
        ``(entries, climbs)``: one ``(module, "caller -> callee")`` per entry; the climbs among them.
    """
    from jaxobs_tuning.job import load_job, run_job

    job = load_job(job_path)
    job = dataclasses.replace(job, solver=dataclasses.replace(job.solver, steps=steps))
    seen: set[tuple] = set()
    entries: list[tuple[str, str]] = []
    climbs: list[tuple[str, str]] = []
    stack: list[tuple] = []  # (code, module) of the project frames below run_job

    def profile(frame, event, arg):
        if event == "call":
            mod = _module(frame.f_code)
            if mod is None:
                return
            if not stack and frame.f_code.co_name != "run_job":
                return
            # the function being read: a comprehension's or generator's enclosing one
            caller = next((f for f in reversed(stack) if not f[0].co_name.startswith("<")), (None, None))
            on_stack = {m for _, m in stack}
            stack.append((frame.f_code, mod))
            if len(stack) - 1 > depth or caller[1] == mod:
                return
            edge = (caller[0], mod)
            if edge in seen:
                return
            seen.add(edge)
            name = f"{caller[1]}.{caller[0].co_name} -> {frame.f_code.co_name}" if caller[0] else "run_job"
            entries.append((mod, name))
            if mod in on_stack:
                climbs.append((mod, name))
        elif event == "return" and stack and stack[-1][0] is frame.f_code:
            stack.pop()

    with tempfile.TemporaryDirectory() as out:
        sys.setprofile(profile)
        try:
            run_job(job, Path(out), quiet=True)
        finally:
            sys.setprofile(None)
    return entries, climbs


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
    entries, climbs = walk(Path(args.job), args.steps, args.depth)
    per = Counter(m for m, _ in entries)
    returns = sum(n - 1 for n in per.values())
    print(f"{len(entries)} entries into {len(per)} modules, {returns} returns, {len(climbs)} climbs")
    for i, (mod, how) in enumerate(entries):
        print(f"{i + 1:3d}  {mod:34s} {how}")
    print("entries per module (returns = entries - 1):")
    for mod, n in per.most_common():
        print(f"  {n:2d}  {mod}")
    for mod, how in climbs:
        print(f"climb: {mod} ({how})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
