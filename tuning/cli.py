"""The ``jaxobs`` command line: the one parser, with every command (the top layer).

    jaxobs tune [JOB.toml] [--out DIR] [--resume] [--check] [--quiet]
                                                           gradient tuning job (default: embedded WIF job)
    jaxobs demo [--out DIR] [--force] [--json]             the FLL family on paper 001 Tests A–E
    jaxobs closed-form {sogi-fll,wpf,wif,cleso} [--name value ...] [--json]
                                                           closed-form gains, formula and source
    jaxobs bode [--out DIR] [--force] [--rad-per-s]        the papers' Bode figures (000 Fig. 5,
                                                           002 Fig. 4, 001 Fig. 14), in Hz (or rad/s)
    jaxobs reproduce flux [--out DIR] [--force] [--json] [--quick]
                                                           paper 000's experiments, paper vs ours
    jaxobs reproduce leso [--out DIR] [--force] [--json] [--machine dual|single]   paper 002's experiments
    jaxobs study [STUDY.toml] [--out DIR] [--force] [--check] [--resume] [--quiet]
                 [--coordinator HOST:PORT --num-processes N --process-id I | --distributed] [--timeout S]
                                                           robustness study → NetCDF, worst cases, figures
    jaxobs export [RESULT.json | --design D] [--out DIR] [--force] [--check]
                                                           the observer as C99 float32 with golden vectors
    jaxobs drive check DRIVE.toml                          a drive file checked, and what follows from it
    jaxobs --version

Every command takes ``--quiet``: without it the long ones show their progress on stderr when it is a
terminal (tqdm bars that name each compilation before it starts, one step per solver iteration, study
chunk, reproduced experiment or export stage; nothing in a pipe or a log, where an error stays one
line); stdout holds the results either way.

The console script ``jaxobs`` and ``python -m jaxobs`` both run :func:`main`.
It first calls :func:`jaxobs.use_host_devices` (one JAX CPU device per usable
core; ``JAXOBS_HOST_DEVICES=1`` turns it off), then the command.  ``jaxobs
tune`` without a file runs the embedded default job
(``tuning/presets/wif_robust.toml``).  Benchmarks are not a command: ``make
bench`` (``benchmarks/``).

Every failure ends the program with one line on stderr.  Exit statuses:

- 0: done;
- 1: an internal error (a bug, or the machine ran out of memory): the one line names the log file
  holding the traceback (``<out>/error.log``, or a temporary file before ``--out`` is known);
- 2: bad input: arguments, a job or study file (the line names the field; ``tune --check`` and
  ``study --check`` check the whole file and stop), an output folder that cannot be used (a symlink, not
  writable, locked by another process, results there without ``--force``), a checkpoint that ``--resume``
  cannot use (corrupt, or another job's);
- 3: ``tune`` only: every design tried diverged (status ``diverged``, nothing tuned), or the objective
  overflowed (status ``overflow``: a weight so large the objective is not finite; nothing tuned);
- 4: ``tune`` only: status ``unsafe``: the tuned design lost stability or synchronism inside the job's
  ``[envelope]`` where the closed form holds (its results are written; the warning names the points);
- 130: interrupted (Ctrl-C).

Every command that writes (``tune``, ``study``, ``demo``, ``bode``, ``reproduce``, ``export``) writes only
under ``--out`` (``tune`` and ``study``: default ``./out/<name>``, the job's or study's name reduced to
``[A-Za-z0-9._-]``; the others ``./out/<command>``), checked and locked before any work: see
:mod:`jaxobs_tuning.outdir` for the lock file, symlinks and ``--force``.
``study --coordinator HOST:PORT --num-processes N --process-id I`` (or ``--distributed``: from the
environment, e.g. SLURM) runs one process of a study split over processes (:func:`jaxobs.init_distributed`,
before the study file is loaded): process 0 alone checks, locks and writes ``--out``, prints the table and
shows progress; the others compute their share, print one line and exit 0; when process 0 cannot use
``--out`` every process ends with exit 2 before computing.  FLL studies only (a drive or recording study
is refused before joining).  ``--timeout S`` (default 300): how long each process waits for the others;
a process other than 0 that finds no coordinator, or another program listening at its port, then exits 2
with one line, a process 0 left alone is aborted by JAX's runtime (exit 134).
``tune --resume`` continues from ``<out>/checkpoint.npz`` if it is this job's (the job file's sha256 is
in it); with no checkpoint it says so in one line and starts fresh.  ``study --resume`` (FLL and drive
studies; a study split over processes too, every process given ``--resume``) continues from the chunks in
``<out>/study.chunks/`` if they are this study's (its files' and the versions' sha256, the same device
count): a study.nc byte-identical to an uninterrupted run's.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, cast

import jaxobs
from jaxobs.runtime.chunkstore import ChunkStore
from jaxobs.studies.registry import spelled

from .cli_common import enable_x64, progress_of
from .cli_drive import add_drive_parser
from .cli_log import add_log_parser
from .cli_papers import BODE_FILES as BODE_FILES
from .cli_papers import CF_OPTIONS, cf_flags, cmd_bode, cmd_closed_form, cmd_demo, cmd_reproduce
from .cli_papers import DEMO_FILES as DEMO_FILES
from .cli_papers import REPRODUCE_FILES as REPRODUCE_FILES
from .cli_papers import closed_form_rows as closed_form_rows
from .cli_run import Parser as _Parser
from .cli_run import quiet_parent, run_parser
from .distributed import distributed_asked, distributed_study, join_distributed, refuse_unsplittable
from .envelope import add_envelope_parser
from .export import add_export_parser
from .job import CHECKPOINT, UNSAFE_EXIT, load_job, load_recordings, run_job
from .job.drive import check_three_phase
from .outdir import OutDir, atomic_write_text, safe_name
from .study_file import load_study as _load_study
from .study_file import study_fingerprint
from .summary import print_summary, study_warnings

if TYPE_CHECKING:
    from xarray import Dataset

STUDY_CHUNKS = "study.chunks"  # a study's results while it runs (jaxobs.runtime.chunkstore), in --out


def load_study(path: str | Path) -> tuple[str, dict, dict, dict]:
    """A study file as (name, designs, axes, options): :func:`jaxobs_tuning.study_file.load_study`, checked in
    full; the options hold its preset's keywords, ``family`` (:mod:`jaxobs.scenarios.families`) among them.

    Args:
        path: The study file (TOML).

    Returns:
        ``(name, designs, axes, options)``.

    Raises:
        ValueError: A file that does not pass the checks.
    """
    spec = _load_study(path)
    return spec.name, spec.designs, spec.axes, dict(spec.opts, family=spec.family)


def _cmd_drive_study(name, designs, axes, opts, out: Path, quiet: bool, provenance=None, store=None) -> int:
    from jaxobs.core.quantities import text_unit
    from jaxobs.metrics import METRICS
    from jaxobs.plot import drive_study_figure
    from jaxobs.studies.drive import DRIVE_STUDY_METRICS
    from jaxobs.studies.study import run_study, write_study

    ds = cast("Dataset", run_study(designs, axes, progress=progress_of(quiet=quiet), store=store, **opts))
    ds.attrs.update(provenance or {})  # the study file's and the result files' sha256, the machine
    fig = out / "drive_study.png"
    drive_study_figure(ds, fig)
    write_study(ds, out / "study.nc", store)  # last: a study.nc means a complete results folder
    n = int(ds.attrs["scenarios"])
    print(f"drive study {name}: {len(designs)} designs x {n} scenarios ({ds.attrs['sampling']}), sensorless")
    if store is not None and store.resumed:
        print(f"resumed: {store.resumed} chunks of {store.total} were on disk from the stopped run")
    qs = [float(q) for q in ds["quantile"].values]
    # columns sized from their content (long design names and metric labels never run together)
    # each in its display units (study.nc keeps SI: jaxobs.metrics.Metric.shown)
    labels = {m: f"{m} ({text_unit(METRICS[m].display_units)})" for m in DRIVE_STUDY_METRICS}
    wd = max(len("design"), *(len(str(d)) for d in ds["design"].values)) + 2
    wm = max(len(x) for x in labels.values()) + 2
    head = f"{'design':<{wd}}{'metric':<{wm}}" + "".join(f"{'q' + format(q, 'g'):>10}" for q in qs)
    head += f"{'diverged':>10}{'lost lock':>11}{'lost speed':>12}"
    print(head)
    for d in ds["design"].values:
        lost = int(ds["lost_lock_count"].sel(design=d))
        div = int(ds["diverged"].sel(design=d).sum())
        speed = int(ds["lost_speed_count"].sel(design=d))
        for m in DRIVE_STUDY_METRICS:
            vals = METRICS[m].shown(ds[f"{m}_q"].sel(design=d).values)
            row = f"{str(d):<{wd}}{labels[m]:<{wm}}" + "".join(f"{v:>10.4g}" for v in vals)
            print(row + f"{div:>10}{lost:>11}{speed:>12}")
    print(f"results: {out / 'study.nc'}, {fig}")
    for w in study_warnings(ds):  # on stderr too: a summary piped away still says what was lost
        print(f"jaxobs: warning: {w}", file=sys.stderr)
    return 0


def _recording_study(
    designs: dict, *, family, recording, t_event, horizon, steady_from, band_hz, progress, store=None, **_
) -> tuple[Dataset, float]:
    """Every FLL design on every recording of ``[study.recording]``: :func:`jaxobs.studies.study.run_study` with a
    :class:`jaxobs.scenarios.Recordings` sampler of ``family``'s recordings (dims (design, recording), the files'
    sha256); (Dataset, s)."""
    import jax

    from jaxobs.scenarios import Recordings
    from jaxobs.studies.study import run_study

    rec = recording
    sampler = Recordings(load_recordings(rec, family), rec.files, rec.sha256)
    res = run_study(
        designs,
        sampler,
        t_event=t_event,
        horizon=horizon,
        steady_from=steady_from,
        band_hz=band_hz,
        progress=progress,
        return_seconds=True,
        store=store,
        mesh=jaxobs.batch_mesh(jax.devices()[:1]),
    )
    return cast("tuple[Dataset, float]", res)


def _cmd_study(args) -> int:
    enable_x64()
    path = Path(args.study) if args.study else Path(str(resources.files("jaxobs") / "data" / "default_study.toml"))
    # a distributed run is joined before anything starts JAX (loading the designs does); --check joins nothing.
    # What cannot be split over processes is refused before joining: a process that refuses after joining
    # leaves the others waiting for it.
    rank = None
    if distributed_asked(args):
        refuse_unsplittable(path)  # --check too: a file that passes --check is one the run accepts
        if not args.check:
            rank = join_distributed(args)
    spec = _load_study(path)  # everything checked: tables, keys, ranges, sizes, result files
    name, designs, axes = spec.name, spec.designs, spec.axes
    opts = dict(spec.opts, family=spec.family, provenance=spec.provenance)
    out = Path(args.out) if args.out else Path("out") / safe_name(str(name), "study")
    # a study writes each chunk's results under study.chunks/ as it finishes (jaxobs.runtime.chunkstore): a
    # kill loses at most the chunks being computed, and --resume continues from the last complete one
    resume = f"jaxobs study {shlex.quote(str(path))} --out {shlex.quote(str(out))} --resume"
    if distributed_asked(args):  # every process is given --resume (process 0 tells the others what is done)
        resume = "every process of the run again, each with --resume"
    hint = f"an earlier run stopped here: continue it with `{resume}` (--force starts over and discards it)"
    products = ["study.nc"] + ([] if args.resume else [STUDY_CHUNKS])
    if args.check:
        if args.out:  # what the real run would refuse (an explicit --out: the default one may not exist yet)
            OutDir(out, products, force=args.force, hints={STUDY_CHUNKS: hint}).check()
        family = type(
            spec.family
        ).__name__  # GridSignals, RecordedSignals or DriveScenarios (jaxobs.scenarios.families)
        label = path if args.study else f"the default study ({path.name})"  # not the installed package's path
        print(f"{label}: OK — {family} study {name!r}, {len(designs)} designs x {spec.scenarios} scenarios")
        return 0
    outdir = OutDir(out, products, force=args.force, hints={STUDY_CHUNKS: hint})
    store = ChunkStore(out / STUDY_CHUNKS, study_fingerprint(spec), resume=args.resume)
    if rank is not None and rank[1] > 1:
        args.on_interrupt = _resume_hint(resume, store.has_chunks)  # what Ctrl-C says (main)
        return distributed_study(name, designs, axes, opts, out, args, rank, _run_study, outdir, store)
    with outdir:
        args.log_dir = out
        args.on_interrupt = _resume_hint(resume, store.has_chunks)
        return _run_study(name, designs, axes, opts, out, args.quiet, store=store)


def _run_study(name, designs, axes, opts, out: Path, quiet: bool, store=None) -> int:
    from jaxobs.core.quantities import text_unit
    from jaxobs.metrics import METRICS
    from jaxobs.plot import study_figures
    from jaxobs.studies.study import STUDY_METRICS, run_study, worst_cases, write_study

    provenance = opts.pop("provenance", None) or {}
    if opts["family"].closed_loop:  # the family's designs close the drive's loop: the drive study's preset
        return _cmd_drive_study(name, designs, axes, opts, out, quiet, provenance, store)
    if opts.get("recording") is not None:  # [study.recording]: the recordings are the scenarios
        ds, seconds = _recording_study(designs, progress=progress_of(quiet=quiet), store=store, **opts)
    else:
        opts.pop("recording", None)
        ds, seconds = cast(
            "tuple[Dataset, float]",
            run_study(designs, axes, progress=progress_of(quiet=quiet), return_seconds=True, store=store, **opts),
        )
    ds.attrs.update(provenance)  # the study file's and the result files' sha256
    worst = {m: worst_cases(ds, m, 3) for m in STUDY_METRICS}
    atomic_write_text(out / "worst_cases.json", json.dumps(worst, indent=1))
    figs = study_figures(ds, out)
    write_study(ds, out / "study.nc", store)  # last: a study.nc means a complete results folder
    n = int(ds.attrs["scenarios"])
    print(f"study {name}: {len(designs)} designs x {n} scenarios in {seconds:.1f} s")
    if store is not None and store.resumed:
        print(f"resumed: {store.resumed} chunks of {store.total} were on disk from the stopped run")
    wd = max(len("design"), *(len(str(d)) for d in ds["design"].values)) + 2  # sized from the names
    # each column in its display units; the phase in degrees, as in the figures (study.nc keeps rad)
    cols = [METRICS[m] for m in ("settling_freq", "ripple_freq", "rms_phase_steady")]
    print(
        f"{'design':<{wd}}"
        + "".join(f"{f'{m.name} ({text_unit(m.display_units)}) mean':>32}{'worst':>10}" for m in cols)
        + f"{'diverged':>10}{'lost lock':>11}"
    )
    for d in ds["design"].values:
        sel = ds.sel(design=d)
        row = f"{str(d):<{wd}}"
        for m in cols:
            row += f"{m.shown(float(sel[m.name].mean())):>32.4g}{m.shown(float(sel[m.name].max())):>10.4g}"
        print(row + f"{int(sel['diverged'].sum()):>10}{int(sel['lost_lock_count']):>11}")
    print(f"results: {out / 'study.nc'}, {out / 'worst_cases.json'}, {len(figs)} figures")
    for w in study_warnings(ds):  # on stderr too: a summary piped away still says what was lost
        print(f"jaxobs: warning: {w}", file=sys.stderr)
    return 0


def default_job_path() -> Path:
    """The embedded default job (the robust SOGI-FLL-WIF job that ``jaxobs tune`` runs without a file)."""
    return Path(str(resources.files("jaxobs_tuning") / "presets" / "wif_robust.toml"))


def _cmd_tune(args) -> int:
    enable_x64()
    path = Path(args.job) if args.job else default_job_path()
    job = load_job(path)
    if job.drive is not None and job.scenarios.recording is None:
        check_three_phase(job.drive)  # a dual drive file is the envelope's only, refused before any run
    out = Path(args.out) if args.out else Path("out") / safe_name(job.name)
    products = ["result.json"]
    if not args.resume:
        products.append(CHECKPOINT)  # a fresh run would overwrite it: --resume, or --force to start over
    resume = f"jaxobs tune {shlex.quote(str(path))} --out {shlex.quote(str(out))} --resume"
    hint = f"an earlier run stopped here: continue it with `{resume}` (--force starts over and discards it)"
    if args.check:
        if args.out:  # what the real run would refuse (an explicit --out: the default one may not exist yet)
            OutDir(out, products, force=args.force, hints={CHECKPOINT: hint}).check()
        n = 1
        for v in job.scenarios.axes.values():
            n *= len(v)
        n = job.scenarios.sample or n
        drive = "" if job.drive is None else f", {job.drive.loop} drive on {job.drive.machine}"
        if job.scenarios.recording is not None:  # the observer runs open loop on the files, whatever the signal
            rec = job.scenarios.recording
            drive = f", open loop on {len(rec.files)} recording(s)"
            if rec.startup_s:  # the drive logs' scores skip the observer's start-up
                drive += f" scored from {rec.startup_s:.4g} s ({rec.startup_periods:g} electrical periods of start-up)"
        label = path if args.job else f"the default job ({path.name})"  # not the installed package's path
        print(
            f"{label}: OK — {job.component}, free gains {', '.join(g.name for g in job.gains)}, {n} scenarios"
            f"{drive}, solver {job.solver.name}"
        )
        return 0
    with OutDir(out, products, force=args.force, hints={CHECKPOINT: hint}):
        args.log_dir = out
        args.on_interrupt = _resume_hint(resume, (out / CHECKPOINT).is_file)  # what Ctrl-C says (main)
        result = run_job(job, out, resume=args.resume, quiet=args.quiet)
    try:
        timing = json.loads((out / "timing.json").read_text())
    except (OSError, ValueError):
        timing = {}
    print_summary(result, out, timing)
    return {"diverged": 3, "overflow": 3, "unsafe": UNSAFE_EXIT}.get(result["status"], 0)


def _host_port(text: str) -> str:
    """argparse type of ``--coordinator``: ``HOST:PORT``, the port in 1..65535."""
    host, sep, port = text.rpartition(":")
    if not (sep and host and port.isdigit() and 1 <= int(port) <= 65535):
        raise argparse.ArgumentTypeError(f"must be HOST:PORT with a port in 1..65535, got {text!r}")
    return text


def _int_at_least(low: int, high: int):
    """argparse type: an integer in ``low..high`` (its digits bounded before conversion)."""

    def parse(text: str) -> int:
        try:
            v = int(text) if len(text) <= 20 else None
        except ValueError:
            v = None
        if v is None or not low <= v <= high:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low} and <= {high}, got {text[:30]!r}")
        return v

    return parse


MAX_PROCESSES = 65_536  # --num-processes
MAX_TIMEOUT_S = 86_400  # --timeout: a day (2147483648 overflowed JAX's timer: a TypeError)


def build_parser() -> argparse.ArgumentParser:
    """The one parser: every subcommand of ``jaxobs``, and ``--version``.

    Returns:
        The parser.
    """
    p = _Parser(prog="jaxobs", description="Differentiable simulation and tuning of motor-drive observers and FLLs.")
    p.add_argument("--version", action="version", version=f"jaxobs {jaxobs.__version__}")
    sub = p.add_subparsers(dest="cmd", parser_class=_Parser, metavar="COMMAND")  # none given: main lists them
    quiet = quiet_parent()
    _add_tune_parser(sub, quiet)
    _add_demo_parser(sub, quiet)
    _add_closed_form_parser(sub, quiet)
    _add_bode_parser(sub, quiet)
    _add_reproduce_parser(sub, quiet)
    _add_study_parser(sub, quiet)
    add_export_parser(sub, parents=[quiet])
    add_envelope_parser(sub, parents=[quiet])
    add_drive_parser(sub, parents=[quiet])
    add_log_parser(sub, parents=[quiet])
    return p


def _add_tune_parser(sub: argparse._SubParsersAction, quiet: argparse.ArgumentParser) -> None:
    """``jaxobs tune``."""
    t = sub.add_parser(
        "tune",
        help="gradient-based gain tuning from a TOML job (default: embedded WIF job)",
        description="Gradient-based gain tuning from a TOML job (default: embedded WIF job).",
        parents=[quiet],
    )
    t.add_argument("job", nargs="?", help="job file (TOML); default: the embedded robust SOGI-FLL-WIF job")
    t.add_argument("--out", help="results folder (default: out/<job name>)")
    t.add_argument("--resume", action="store_true", help="continue from the checkpoint in --out")
    t.add_argument("--check", action="store_true", help="validate the job file and exit")
    t.add_argument("--force", action="store_true", help="overwrite results (and a checkpoint) already in --out")
    t.set_defaults(func=_cmd_tune)


def _add_demo_parser(sub: argparse._SubParsersAction, quiet: argparse.ArgumentParser) -> None:
    """``jaxobs demo``."""
    d = sub.add_parser(
        "demo",
        help="FLL family (SOGI-FLL, -WPF, -WIF) on paper 001 Tests A-E",
        description="FLL family (SOGI-FLL, -WPF, -WIF) on paper 001 Tests A-E.",
        parents=[quiet],
    )
    d.add_argument("--out", default="out/demo", help="folder for the figure (default: out/demo)")
    d.add_argument("--force", action="store_true", help="overwrite the figure already in --out")
    d.add_argument("--json", action="store_true", help="print the table as JSON rows")
    d.add_argument("--t-event", type=float, default=0.2, help="time of the test event, s (default 0.2)")
    d.set_defaults(func=cmd_demo)


def _add_closed_form_parser(sub: argparse._SubParsersAction, quiet: argparse.ArgumentParser) -> None:
    """``jaxobs closed-form``."""
    c = sub.add_parser(
        "closed-form",
        help="closed-form gains with formula and source equation",
        description="Closed-form gains with formula and source equation.",
        parents=[quiet],
    )
    # a class name or an alias, in any case (jaxobs.studies.registry.spelled)
    c.add_argument("design", choices=list(CF_OPTIONS), type=spelled, help="which design rule")
    for flag, (dest, what) in cf_flags().items():  # each design's inputs (its class's closed_form_design)
        c.add_argument(flag, dest=dest, type=float, help=what)
    c.add_argument("--json", action="store_true", help="print JSON")
    c.set_defaults(func=cmd_closed_form)


def _add_bode_parser(sub: argparse._SubParsersAction, quiet: argparse.ArgumentParser) -> None:
    """``jaxobs bode``."""
    b = sub.add_parser(
        "bode",
        help="Bode figures of the papers' flux observers, LESOs and FLL loops",
        description="Bode figures of the papers' flux observers, LESOs and FLL loops.",
        parents=[quiet],
    )
    b.add_argument("--out", default="out/bode", help="folder for the figures (default: out/bode)")
    b.add_argument("--force", action="store_true", help="overwrite figures already in --out")
    b.add_argument("--rad-per-s", action="store_true", help="frequency axis in rad/s (default: Hz)")
    b.set_defaults(func=cmd_bode)


def _add_reproduce_parser(sub: argparse._SubParsersAction, quiet: argparse.ArgumentParser) -> None:
    """``jaxobs reproduce``."""
    r = sub.add_parser(
        "reproduce",
        help="reproduce a paper's experiments on the simulated drive",
        description="Reproduce a paper's experiments on the simulated drive.",
        parents=[quiet],
    )
    r.add_argument(
        "paper", choices=["flux", "leso"], help="flux: paper 000 (rotor-flux observers); leso: paper 002 (LESOs)"
    )
    r.add_argument("--out", help="folder for the figures (default: out/reproduce-<paper>)")
    r.add_argument("--force", action="store_true", help="overwrite figures already in --out")
    r.add_argument("--json", action="store_true", help="print rows {experiment, observer, metric, unit, paper, ours}")
    r.add_argument("--quick", action="store_true", help="skip the long runs (20 r/min steady state, I-f start-up)")
    r.add_argument(
        "--machine",
        choices=["single", "dual"],
        default=None,
        help="leso: 'dual' (the default) adds 002's dual three-phase IPMSM (Figs 13-15, individual sets and VSD"
        " control; the ramp and the load step with each LESO closing the loop); 'single': the single machine only",
    )
    r.set_defaults(func=cmd_reproduce)


def _add_study_parser(sub: argparse._SubParsersAction, quiet: argparse.ArgumentParser) -> None:
    """``jaxobs study``, with the options of a distributed run."""
    st = sub.add_parser(
        "study",
        help="robustness study of FLL or sensorless-drive designs over a scenario grid (xarray/NetCDF)",
        description="Robustness study of FLL or sensorless-drive designs over a scenario grid (xarray/NetCDF).",
        parents=[quiet],
    )
    st.add_argument("study", nargs="?", help="study file (TOML); default: the FLL family's closed forms")
    st.add_argument("--out", help="results folder (default: out/<study name>)")
    st.add_argument("--force", action="store_true", help="overwrite a study.nc already in --out")
    st.add_argument("--check", action="store_true", help="validate the study file (every range, the sizes) and exit")
    st.add_argument(
        "--resume",
        action="store_true",
        help=f"continue an FLL study that was stopped, from the chunks in --out/{STUDY_CHUNKS} (the same study only)",
    )
    dist = st.add_argument_group(
        "distributed run",
        "one process of a study split over processes (jaxobs.init_distributed): give all three, or "
        "--distributed to take them from the environment (JAX_COORDINATOR_ADDRESS, SLURM's srun, Open MPI)",
    )
    dist.add_argument("--coordinator", type=_host_port, metavar="HOST:PORT", help="process 0's address and a free port")
    dist.add_argument(
        "--num-processes", type=_int_at_least(1, MAX_PROCESSES), metavar="N", help="the number of processes, >= 1"
    )
    dist.add_argument(
        "--process-id", type=_int_at_least(0, MAX_PROCESSES - 1), metavar="I", help="this process's index, 0..N-1"
    )
    dist.add_argument(
        "--distributed", action="store_true", help="join a distributed run; what is not given, the environment gives"
    )
    dist.add_argument(
        "--timeout",
        type=_int_at_least(1, MAX_TIMEOUT_S),
        metavar="S",
        help="seconds to wait for every process to join (default 300); then a process other than 0 that found "
        "no process 0 exits 2 with one line, and a process 0 left alone is aborted by JAX (exit 134)",
    )
    st.set_defaults(func=_cmd_study)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line.

    Args:
        argv: The arguments (default ``sys.argv[1:]``).

    Returns:
        The exit status.
    """
    return run_parser(build_parser(), argv)


def _resume_hint(resume: str, saved):
    """What Ctrl-C adds to "interrupted" (``args.on_interrupt``): the command that continues the run, only
    when ``saved()`` finds something on disk to continue from (interrupted before a checkpoint: nothing)."""
    return lambda: f"; continue with: {resume}" if saved() else ""


if __name__ == "__main__":
    sys.exit(main())
