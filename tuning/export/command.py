"""``jaxobs export``: its arguments (:func:`add_export_parser`, wired into the one parser by
:mod:`jaxobs_tuning.cli`) and what it runs (:func:`cli_export`)."""

from __future__ import annotations

import argparse
import math
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import cast

import jax

from jaxobs.drive import read_drive
from jaxobs.drive.drivefile import DriveFile
from jaxobs.observers import (
    AbstractDriveObserver,
)
from jaxobs.studies.registry import REGISTRY, spelled

from ..job import parse_job
from ..outdir import OutDir
from ..results import load_result
from .files import EXPORT_FILES, export_observer
from .golden import MAX_STEPS, MIN_STEPS, recording_bench
from .harness import CFLAGS, TOLERANCE, compile_and_check
from .sources import DESIGNS, RULES, observer_from_design, observer_from_result, rebuild


def add_export_parser(
    subparsers: argparse._SubParsersAction, parents: Sequence[argparse.ArgumentParser] = ()
) -> argparse.ArgumentParser:
    """Add ``jaxobs export`` to the CLI's subparsers.

    Args:
        subparsers: The CLI's subparsers.
        parents: The parsers of the options every command shares (--quiet, --no-cache), so that their help reads
            the same in each command.

    Returns:
        The ``export`` parser.
    """
    e = subparsers.add_parser(
        "export",
        help="an observer as C99 float32 with golden vectors and a test harness",
        description="An observer as C99 float32 with golden vectors and a test harness.",
        parents=list(parents),
    )
    e.add_argument("result", nargs="?", help="a `jaxobs tune` result.json (its tuned gains)")
    e.add_argument(
        "--design", choices=list(DESIGNS), type=spelled, help="a closed-form design instead of a result"
    )  # a class name or an alias, in any case
    e.add_argument("--out", default="out/export", help="folder for the files (default: out/export)")
    e.add_argument(
        "--gains",
        choices=["tuned", "closed_form", "initial"],
        default="tuned",
        help="which gains of the result (default: tuned)",
    )
    e.add_argument("--rule", choices=list(RULES), help="discretization rule (default: the result's or the component's)")
    e.add_argument("--ts", type=float, help="sample time, s (default: the result's or the component's)")
    e.add_argument("--steps", type=int, default=12_000, help=f"golden record length (>= {MIN_STEPS}, default 12000)")
    e.add_argument(
        "--record",
        choices=["drive", "synthetic"],
        default="drive",
        help="drive observers' golden record: u/i recorded in a sensored FOC drive of the family's machine, "
        "the observer bound to its Rs, L and speed (default), or the synthesized PMSM signal on the observer's "
        "own Rs, L",
    )
    e.add_argument(
        "--drive",
        help="a drive file (TOML): the C runs at its ts and the golden record is a sensored run of it (default: "
        "the result's job's drive file, else the bench of the observer's family)",
    )
    e.add_argument("--check", action="store_true", help="compile with cc and replay the golden vectors")
    e.add_argument("--force", action="store_true", help="overwrite an export already in --out")
    if not parents:  # a parser of its own (tests build one): the shared options, briefly
        e.add_argument("--quiet", action="store_true", help="no progress on stderr")
        e.add_argument("--no-cache", action="store_true", help="do not keep compiled programs on disk")
    e.set_defaults(func=cli_export)
    return e


MIN_TS, MAX_TS = 1e-9, 1.0  # --ts, s: a normal float32, a sample rate from 1 Hz to 1 GHz


def cli_export(args: argparse.Namespace) -> int:
    """``jaxobs export``: 0 on success, 1 if --check finds the C off the golden vectors; bad input raises ValueError.

    Args:
        args: The parsed command line.

    Returns:
        0 on success, 1 if --check finds the C off the golden vectors.

    Raises:
        ValueError: Bad input (one line, exit 2).
    """
    jax.config.update("jax_enable_x64", True)  # the closed forms in double, as `jaxobs closed-form` computes them
    if (args.result is None) == (args.design is None):
        raise ValueError("export: give a result.json or --design (one of them)")
    if args.ts is not None and not (math.isfinite(args.ts) and MIN_TS <= args.ts <= MAX_TS):
        # float32 C: 1e-300 underflowed to 0 and --check said OK
        raise ValueError(f"--ts must be a sample time in [{MIN_TS:g}, {MAX_TS:g}] s, got {args.ts}")
    if not MIN_STEPS <= args.steps <= MAX_STEPS:  # every golden record: bounded work, bounded golden.csv
        raise ValueError(f"--steps must be in {MIN_STEPS}..{MAX_STEPS}, got {args.steps}")
    # the output folder is checked and locked before any work (jaxobs_tuning.outdir): no symlinks, one writer,
    # an existing export kept unless --force
    with OutDir(Path(args.out), EXPORT_FILES, force=getattr(args, "force", False)):
        args.log_dir = Path(args.out)
        return _export(args)


def _drive_file(args: argparse.Namespace) -> DriveFile | None:
    """The drive file of an export: ``--drive``, else the result's job's own drive file (a result keeps it
    inline), else None (a shipped bench, or no drive: the recording runs on the observer family's bench)."""
    if getattr(args, "drive", None):
        return read_drive(args.drive)
    if args.result is None:
        return None
    job = parse_job(load_result(args.result)["job"])
    return None if job.drive is None else cast("DriveFile | None", job.drive.file)  # DriveSpec.file


def _export(args) -> int:
    notes: list = []
    kw = {}
    if args.ts is not None:
        kw["ts"] = args.ts
    if args.rule is not None:
        kw["rule"] = RULES[args.rule]()
    df = _drive_file(args)
    if args.result is None and df is not None and args.ts is None:
        # a closed form designed at the drive's period, not rebuilt there from the default's (the reduced-order
        # flux observer's matched-pole speed gains depend on the period)
        kw["ts"] = df.ts
    if args.result is not None:
        obs = observer_from_result(args.result, gains=args.gains, notes=notes)
        if kw:
            obs = rebuild(obs, **kw)
            notes = [n for n in notes if not any(f"no '{k}'" in n for k in kw)]
        source = f"{args.result} ({args.gains} gains)"
    else:
        obs = observer_from_design(args.design, **kw)
        source = f"closed form {args.design}, {DESIGNS[args.design].closed_form_design().rule}"
    signal = None
    record_drive = None
    if df is not None:
        why = REGISTRY[type(obs).__name__].refusal(df.machine) if type(obs).__name__ in REGISTRY else None
        if why is not None:
            raise ValueError(f"export: {why}")
        if args.ts is not None and abs(args.ts - df.ts) > 1e-12 * df.ts:
            raise ValueError(
                f"--ts must be the drive file's {df.ts:g} s (1/f_sample_hz) with a drive file, got {args.ts:g}"
            )
        if abs(float(obs.ts) - df.ts) > 1e-12 * df.ts:
            notes.append(f"ts = {df.ts:g} s: the drive file's {df.name} (1/f_sample_hz), not {float(obs.ts):g} s")
            obs = rebuild(obs, ts=df.ts)
    if isinstance(obs, AbstractDriveObserver) and args.record == "drive":
        if df is None:
            machine, rpm = recording_bench(obs)
        else:  # a sensored run of the drive file, at half its rated speed (the benches' 1000 of 2000, 300 of 600)
            machine, rpm = df.machine, 0.5 * float(df.machine.n_rated)
            drive = df.drive_for(sensorless=False, settle=0.0)
            record_drive = dict(machine=machine, rpm=rpm, drive=drive, label=f"drive file {df.name}")
        cls = type(obs)
        # the one binding (its clamp included); bind returns the observer's own class
        obs = cast(AbstractDriveObserver, obs.bind(machine, rpm * math.pi / 30 * int(machine.p)))
        # resistance, inductance, start speed, then any other machine value (the reduced-order observer's Lq, ψf)
        bound = cls.bound_fields
        r_name, l_name, speed, more = bound.resistance, bound.inductance, bound.speed, bound.more
        notes = [n for n in notes if "sets Rs, Lq" not in n]
        names = [n for n in (r_name, l_name, *more) if n is not None]  # the roles this observer has
        machine_values = "".join(f"{n} = {float(getattr(obs, n)):g}, " for n in names)
        start = "" if speed is None else f"{speed} = {float(getattr(obs, speed)):.6g} rad/s "
        notes.append(f"bound to the recording's machine: {machine_values}{start}({rpm:g} r/min)")
        if args.steps < MIN_STEPS:
            raise ValueError(f"export: --steps must be >= {MIN_STEPS}, got {args.steps}")
    elif isinstance(obs, AbstractDriveObserver):
        signal = "synthetic"
    coeffs = export_observer(
        obs,
        args.out,
        n_steps=args.steps,
        signal=signal,
        source=source,
        notes=notes,
        progress=not args.quiet and "auto",
        record_drive=record_drive,
    )
    out = Path(args.out)
    o = coeffs["ops_per_step"]
    print(f"{coeffs['component']} ({coeffs['rule']['name']}, ts = {coeffs['ts']:g} s, float32) from {source}")
    print(
        f"  {out / 'observer.h'}, observer.c   jx_init / jx_step, "
        f"JX_NU = {len(coeffs['inputs'])}, JX_NY = {len(coeffs['outputs'])}"
    )
    print(f"  {out / 'golden.csv'}   {coeffs['golden']['steps']} steps: {coeffs['golden']['signal']}")
    start = f", {o['worst']['total']} in a step taking every dearer branch" if "worst" in o else ""
    print(f"  {out / 'coefficients.json'}   gains, state; {o['steady']['total']} operations per step{start}")
    print(f"  {out / 'test_main.c'}   {' '.join(('cc',) + CFLAGS)} observer.c test_main.c -lm && ./a.out golden.csv")
    for n in notes:
        print(f"note: {n}")
    if args.check:
        if shutil.which("cc") is None:
            print("check: no C compiler (cc) on PATH: not checked")
            return 0
        err = compile_and_check(out)
        ok = err <= TOLERANCE
        print(
            f"check: max |y_C - y_golden|/(1 + |y_golden|) = {err:.3g} over {coeffs['golden']['steps']} steps "
            f"(tolerance {TOLERANCE:g}): {'OK' if ok else 'FAIL'}"
        )
        return 0 if ok else 1
    return 0
