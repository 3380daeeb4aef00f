"""The ``jaxobs`` console script: the library's commands plus ``jaxobs tune``.

The library (``jaxobs/``) never imports ``tuning/`` (DESIGN.md: data flows one
way), so the tuning command is added here, at the application layer, on top of
``jaxobs.cli``'s parser.

    jaxobs tune [JOB.toml] [--out DIR] [--resume] [--check] [--quiet]

Without a file it runs the embedded default job (``tuning/presets/wif_robust.toml``).
Job-file problems end with one line naming the field, exit status 2.
"""

from __future__ import annotations

import sys
from importlib import resources
from pathlib import Path

from jaxobs import cli as base


def default_job_path() -> Path:
    return Path(str(resources.files("tuning") / "presets" / "wif_robust.toml"))


def _cmd_tune(args) -> int:
    base._enable_x64()
    from .job import load_job, run_job

    path = Path(args.job) if args.job else default_job_path()
    job = load_job(path)
    if args.check:
        n = 1
        for v in job.scenarios.axes.values():
            n *= len(v)
        n = job.scenarios.sample or n
        print(f"{path}: OK — {job.component}, free gains {', '.join(g.name for g in job.gains)}, {n} scenarios, solver {job.solver.kind}")
        return 0
    out = Path(args.out) if args.out else Path("out") / job.name
    result = run_job(job, out, resume=args.resume, quiet=args.quiet)
    _print_summary(result, out)
    return 0


def _print_summary(result: dict, out: Path):
    g, s = result["gains"], result["scores"]
    names = list(g["tuned"])
    print(f"{result['component']} tuned in {result['iterations']} iterations ({result['stopped']}), {result['time_s']:.1f} s, "
          f"{result['scenarios']['count']} scenarios")
    head = f"{'gain':<8}{'initial':>14}{'closed form':>14}{'tuned':>14}"
    print(head)
    for n in names:
        print(f"{n:<8}{g['initial'][n]:>14.6g}{g['closed_form'][n]:>14.6g}{g['tuned'][n]:>14.6g}")
    print(f"closed form: {result['closed_form_source']}")
    keys = [k for k in s["tuned"] if k not in ("diverged",)]
    print(f"{'score':<28}{'initial':>14}{'closed form':>14}{'tuned':>14}")
    for k in keys:
        print(f"{k:<28}{s['initial'][k]:>14.6g}{s['closed_form'][k]:>14.6g}{s['tuned'][k]:>14.6g}")
    if "holdout" in result:
        h = result["holdout"]
        print(f"held-out set ({h['count']} scenarios): worst {h['closed_form']['per_scenario_worst']:.6g} (closed form) vs {h['tuned']['per_scenario_worst']:.6g} (tuned)")
    print(f"results: {out / 'result.json'}")


def build_parser():
    p = base.build_parser()
    sub = next(a for a in p._actions if a.dest == "cmd")
    t = sub.add_parser("tune", help="gradient-based gain tuning from a TOML job (default: embedded WIF job)")
    t.add_argument("job", nargs="?", help="job file (TOML); default: the embedded robust SOGI-FLL-WIF job")
    t.add_argument("--out", help="results folder (default: out/<job name>)")
    t.add_argument("--resume", action="store_true", help="continue from the checkpoint in --out")
    t.add_argument("--check", action="store_true", help="validate the job file and exit")
    t.add_argument("--quiet", action="store_true", help="no progress bar")
    t.set_defaults(func=_cmd_tune)
    return p


def main(argv=None) -> int:
    # JobError is a ValueError: base.main prints it as one line naming the field, exit 2
    return base.main(argv, parser=build_parser())


if __name__ == "__main__":
    sys.exit(main())


