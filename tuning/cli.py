"""The ``jaxobs`` command line: the one parser, with every command (DESIGN.md: the top layer).

    jaxobs tune [JOB.toml] [--out DIR] [--resume] [--check] [--quiet]
                                                           gradient tuning job (default: embedded WIF job)
    jaxobs demo [--out DIR] [--force] [--json]             the FLL family on paper 001 Tests A–E
    jaxobs closed-form {sogi-fll,wpf,wif,cleso} [--name value ...] [--json]
                                                           closed-form gains, formula and source
    jaxobs bode [--out DIR] [--force]                      the papers' Bode figures (000 Fig. 5,
                                                           002 Fig. 4, 001 Fig. 14)
    jaxobs reproduce flux [--out DIR] [--force] [--json] [--quick]
                                                           paper 000's experiments, paper vs ours
    jaxobs reproduce leso [--out DIR] [--force] [--json]   paper 002's experiments, paper vs ours
    jaxobs study [STUDY.toml] [--out DIR] [--force] [--check] [--quiet]
                 [--coordinator HOST:PORT --num-processes N --process-id I | --distributed] [--timeout S]
                                                           robustness study → NetCDF, worst cases, figures
    jaxobs export [RESULT.json | --design D] [--out DIR] [--force] [--check]
                                                           the observer as C99 float32 with golden vectors
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
- 3: ``tune`` only: every design tried diverged (status ``diverged``, nothing tuned);
- 130: interrupted (Ctrl-C).

Every command that writes (``tune``, ``study``, ``demo``, ``bode``, ``reproduce``, ``export``) writes only
under ``--out`` (``tune`` and ``study``: default ``./out/<name>``, the job's or study's name reduced to
``[A-Za-z0-9._-]``; the others ``./out/<command>``), checked and locked before any work: see
:mod:`tuning.outdir` for the lock file, symlinks and ``--force``.
``study --coordinator HOST:PORT --num-processes N --process-id I`` (or ``--distributed``: from the
environment, e.g. SLURM) runs one process of a study split over processes (:func:`jaxobs.init_distributed`,
before the study file is loaded): process 0 alone checks, locks and writes ``--out``, prints the table and
shows progress; the others compute their share, print one line and exit 0; when process 0 cannot use
``--out`` every process ends with exit 2 before computing.  FLL studies only (a drive or recording study
is refused before joining).  ``--timeout S`` (default 300): how long each process waits for the others;
a process other than 0 that finds no coordinator then exits 2 with one line, a process 0 left alone is
aborted by JAX's runtime (exit 134).
``tune --resume`` continues from ``<out>/checkpoint.npz`` if it is this job's (the job file's sha256 is
in it); with no checkpoint it says so in one line and starts fresh.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import re
import shlex
import sys
import tempfile
import traceback
from importlib import resources
from pathlib import Path

import jaxobs
from jaxobs import linear, papers, use_compile_cache, use_host_devices

from .envelope import add_envelope_parser
from .export import add_export_parser
from .job import CHECKPOINT, load_job, load_recordings, run_job
from .outdir import OutDir, atomic_path, atomic_write_text, safe_name
from .study_file import load_study as _load_study

# the files each command writes under --out (refused there without --force; jaxobs.plot names them)
DEMO_FILES = ("fll_tests_A_E.png",)
BODE_FILES = ("bode_flux_observers_000_fig5.png", "bode_lesos_002_fig4.png", "bode_fll_open_loop_001_fig14.png")
REPRODUCE_FILES = {
    "flux": (
        "flux_circles_du_alpha_5V.png",
        "flux_circles_400rpm.png",
        "position_error_load_step.png",
        "position_error_speed_variation.png",
        "position_error_du_alpha_5V.png",
    ),
    "leso": ("leso_position_error_600rpm.png", "leso_speed_ramp.png", "leso_load_step.png"),
}


class _out(OutDir):
    """``with _out(args, files) as out``: ``--out`` checked and locked before any work (tuning.outdir), its
    path as the value; an internal error's log goes there."""

    def __init__(self, args, files):
        super().__init__(Path(args.out), files, force=args.force)
        self.args = args

    def __enter__(self) -> Path:
        super().__enter__()
        self.args.log_dir = self.path
        return self.path


def _progress(args=None, quiet=None):
    """The library's ``progress`` for a command: bars when stderr is a terminal, none with --quiet."""
    quiet = args.quiet if quiet is None else quiet
    return False if quiet else "auto"


def _enable_x64():
    import jax

    jax.config.update("jax_enable_x64", True)


def _cmd_demo(args) -> int:
    _enable_x64()
    from jaxobs.demo import DEMO_TESTS, fll_demo, format_table
    from jaxobs.plot import fll_demo_figure

    if args.t_event <= 0:
        raise ValueError(f"--t-event must be > 0 s, got {args.t_event}")
    with _out(args, DEMO_FILES) as out:
        rows, traces = fll_demo(t_event=args.t_event, progress=_progress(args))
        fig_path = out / DEMO_FILES[0]
        with atomic_path(fig_path) as tmp:
            fll_demo_figure(traces, DEMO_TESTS, args.t_event, tmp)
    if args.json:
        print(json.dumps(rows, indent=1))
    else:
        print("Paper 001 FLLs with Table I gains on Tests A–E (float64, AB3 at 10 kHz)")
        print(format_table(rows))
        print(f"figure: {fig_path}")
    return 0 if all(r["ok"] for r in rows) else 1


_CF_OPTIONS = {
    "sogi-fll": ("k", "omega_n", "zeta"),
    "wpf": ("omega_n", "zeta"),
    "wif": ("omega_c", "b", "omega_n"),
    "cleso": ("omega0", "rs", "lq"),
}


def closed_form_rows(design: str, values: dict) -> dict:
    """Gains of a closed-form design with the formula and source of each (used by the CLI)."""
    import math

    pi = math.pi
    if design == "sogi-fll":
        k = values.get("k", 1 / math.sqrt(2))
        wn = values.get("omega_n", 100 * pi)
        zeta = values.get("zeta", 1 / math.sqrt(2))
        obs = linear.sogi_fll_closed_form(k=k, omega_n=wn, zeta=zeta)
        gains = [
            ("k", float(obs.k), "chosen (001 uses 1/√2)", "001 Sec. II-B"),
            ("lam", float(obs.lam), "λ = k²ωn²/(8ζ²)", "001 eq (22)"),
        ]
        inputs = dict(k=k, omega_n=wn, zeta=zeta)
    elif design == "wpf":
        wn = values.get("omega_n", 100 * pi)
        zeta = values.get("zeta", 1 / math.sqrt(2))
        obs = linear.wpf_closed_form(omega_n=wn, zeta=zeta)
        gains = [
            ("k1", float(obs.k1), "k1 = √2 (prefilter ζ = 1/√2)", "001 eq (26)"),
            ("k2", float(obs.k2), "k2 = k1 (amplitude poles coincide)", "001 Sec. III-B"),
            ("lam", float(obs.lam), "λ = 2(ζ+1)ωn²/(2ζ+1)³", "001 eq (29)"),
        ]
        inputs = dict(omega_n=wn, zeta=zeta)
    elif design == "wif":
        wc = values.get("omega_c", papers.WIF_OMEGA_C)
        b = values.get("b", 1 + math.sqrt(2))
        wn = values.get("omega_n", 100 * pi)
        obs = linear.wif_closed_form(omega_c=wc, b=b, omega_n=wn)
        pm = math.degrees(float(linear.symmetric_optimum_pm(b)))
        gains = [
            ("k1", float(obs.k1), "k1 = 2bωc/ωn", "001 eq (34)"),
            ("k2", float(obs.k2), "k2 = 2ωc/ωn", "001 eq (34)"),
            ("lam", float(obs.lam), "λ = 2ωc²/b", "001 eq (34)"),
            ("phase_margin_deg", pm, "PM = atan((b²−1)/(2b))", "001 eq (39)"),
        ]
        inputs = dict(omega_c=wc, b=b, omega_n=wn)
    elif design == "cleso":
        if "rs" not in values or "lq" not in values:
            raise ValueError(
                "closed-form cleso needs --rs (stator resistance, ohm >= 0) and --lq (q-axis inductance, H > 0)"
            )
        w0 = values.get("omega0", 500 * pi)
        g = linear.cleso_closed_form(w0, values["rs"], values["lq"])
        gains = [
            ("l1", float(g.l1), "l1 = 2ω0 − μ, μ = Rs/Lq", "002 eq (16)"),
            ("l2", float(g.l2), "l2 = ω0²", "002 eq (16)"),
        ]
        inputs = dict(omega0=w0, rs=values["rs"], lq=values["lq"])
    else:  # argparse restricts the choices
        raise ValueError(f"design must be one of {', '.join(_CF_OPTIONS)}, got {design!r}")
    return {
        "design": design,
        "inputs": inputs,
        "gains": [dict(name=n, value=v, formula=f, source=src) for n, v, f, src in gains],
    }


def _cmd_closed_form(args) -> int:
    _enable_x64()
    values = {}
    for name in ("k", "omega_n", "zeta", "omega_c", "b", "omega0", "rs", "lq"):
        v = getattr(args, name)
        if v is None:
            continue
        if name not in _CF_OPTIONS[args.design]:
            allowed = ", ".join("--" + o.replace("_", "-") for o in _CF_OPTIONS[args.design])
            raise ValueError(f"--{name.replace('_', '-')} does not apply to {args.design} (allowed: {allowed})")
        values[name] = v
    try:
        res = closed_form_rows(args.design, values)
    except ValueError as e:  # name the flag the user typed (wif_closed_form.b -> --b), not the function's field
        raise ValueError(re.sub(r"\b\w+_closed_form\.(\w+)", lambda m: "--" + m[1].replace("_", "-"), str(e))) from None
    if args.json:
        print(json.dumps(res, indent=1))
    else:
        ins = ", ".join(f"{k} = {v:.6g}" for k, v in res["inputs"].items())
        print(f"{args.design}: {ins}")
        for g in res["gains"]:
            print(f"  {g['name']:<18}{g['value']:>14.6g}   {g['formula']:<36}{g['source']}")
    return 0


def _cmd_bode(args) -> int:
    _enable_x64()
    from jaxobs.plot import paper_bode_figures

    with _out(args, BODE_FILES) as out:
        figs = paper_bode_figures(out)
    for p in figs:
        print(p)
    return 0


def load_study(path):
    """A study file as (name, designs, axes, options): :func:`tuning.study_file.load_study`, checked in full."""
    spec = _load_study(path)
    return spec.name, spec.designs, spec.axes, dict(spec.opts, kind=spec.kind)


def _cmd_drive_study(name, designs, axes, opts, out: Path, quiet: bool, provenance=None) -> int:
    from jaxobs.drive_study import DRIVE_STUDY_METRICS, run_drive_study
    from jaxobs.plot import drive_study_figure

    ds = run_drive_study(designs, axes, progress=_progress(quiet=quiet), **opts)
    ds.attrs.update(provenance or {})  # the study file's and the result files' sha256, the machine
    fig = out / "drive_study.png"
    drive_study_figure(ds, fig)
    with atomic_path(out / "study.nc") as tmp:
        ds.to_netcdf(tmp, engine="scipy")
    n = int(ds.attrs["scenarios"])
    print(f"drive study {name}: {len(designs)} designs x {n} scenarios ({ds.attrs['sampling']}), sensorless")
    qs = [float(q) for q in ds["quantile"].values]
    # columns sized from their content (long design names and metric labels never run together)
    labels = {m: f"{m} ({u})" for m, (u, _) in DRIVE_STUDY_METRICS.items()}
    wd = max(len("design"), *(len(str(d)) for d in ds["design"].values)) + 2
    wm = max(len(x) for x in labels.values()) + 2
    head = f"{'design':<{wd}}{'metric':<{wm}}" + "".join(f"{'q' + format(q, 'g'):>10}" for q in qs)
    head += f"{'lost lock':>11}"
    print(head)
    for d in ds["design"].values:
        lost = int(ds["lost_lock_count"].sel(design=d))
        for m in DRIVE_STUDY_METRICS:
            vals = ds[f"{m}_q"].sel(design=d).values
            row = f"{str(d):<{wd}}{labels[m]:<{wm}}" + "".join(f"{v:>10.4g}" for v in vals)
            print(row + f"{lost:>11}")
    print(f"results: {out / 'study.nc'}, {fig}")
    return 0


def _recording_study(designs: dict, *, recording, t_event, horizon, steady_from, band_hz, progress, **_):
    """Every FLL design on every recording of ``[study.recording]``: :func:`jaxobs.study.run_study` with a
    :class:`jaxobs.scenarios.Recordings` sampler (dims (design, recording), the files' sha256); (Dataset, s)."""
    import jax

    from jaxobs.scenarios import Recordings
    from jaxobs.study import run_study

    rec = recording
    sampler = Recordings(load_recordings(rec, "grid"), rec.files, rec.sha256)
    return run_study(
        designs,
        sampler,
        t_event=t_event,
        horizon=horizon,
        steady_from=steady_from,
        band_hz=band_hz,
        progress=progress,
        return_seconds=True,
        mesh=jaxobs.batch_mesh(jax.devices()[:1]),
    )


def _cmd_study(args) -> int:
    _enable_x64()
    path = Path(args.study) if args.study else Path(str(resources.files("jaxobs") / "data" / "default_study.toml"))
    # a distributed run is joined before anything starts JAX (loading the designs does); --check joins nothing.
    # What cannot be split over processes is refused before joining: a process that refuses after joining
    # leaves the others waiting for it.
    rank = None
    if _distributed_asked(args):
        _refuse_unsplittable(path)  # --check too: a file that passes --check is one the run accepts
        if not args.check:
            rank = _join_distributed(args)
    spec = _load_study(path)  # everything checked: tables, keys, ranges, sizes, result files
    name, designs, axes = spec.name, spec.designs, spec.axes
    opts = dict(spec.opts, kind=spec.kind, provenance=spec.provenance)
    if args.check:
        print(f"{path}: OK — {spec.kind} study {name!r}, {len(designs)} designs x {spec.scenarios} scenarios")
        return 0
    out = Path(args.out) if args.out else Path("out") / safe_name(str(name), "study")
    if rank is not None and rank[1] > 1:
        return _distributed_study(name, designs, axes, opts, out, args, rank)
    with OutDir(out, ["study.nc"], force=args.force):
        args.log_dir = out
        return _run_study(name, designs, axes, opts, out, args.quiet)


def _distributed_asked(args) -> bool:
    """Whether ``study`` was given any of the distributed run's options."""
    given = (args.coordinator, args.num_processes, args.process_id, args.timeout)
    return args.distributed or any(v is not None for v in given)


def _refuse_unsplittable(path: Path) -> None:
    """Drive and recording studies run in one process: refused from the raw TOML, before JAX starts.

    A file that does not parse passes here; :func:`tuning.study_file.load_study` reports it after joining
    (every process reads the same file, so every process stops with the same one-line error)."""
    from .job import JobError, read_toml
    from .study_file import WHAT

    try:
        raw, _ = read_toml(path, WHAT)
    except JobError:
        return
    st = raw.get("study") if isinstance(raw.get("study"), dict) else {}
    kind = "drive" if st.get("kind") == "drive" else "recording" if "recording" in st else None
    if kind is not None:
        raise ValueError(
            f"{path}: only FLL studies on a scenario grid or sample are split over processes; "
            f"run this {kind} study without --coordinator/--num-processes/--process-id/--distributed"
        )


def _join_distributed(args):
    """``study --coordinator/--num-processes/--process-id/--distributed``: join the run
    (jaxobs.init_distributed); (process id, process count).  Without ``--distributed`` all three are
    required; with it, what is not given comes from the environment (JAX_COORDINATOR_ADDRESS, SLURM, Open MPI)."""
    given = (args.coordinator, args.num_processes, args.process_id)
    if not args.distributed:
        missing = [f for f, v in zip(("--coordinator", "--num-processes", "--process-id"), given) if v is None]
        if len(missing) == 3:  # --timeout alone
            raise ValueError(
                "--timeout applies to a distributed run: give --coordinator, --num-processes and --process-id, "
                "or --distributed"
            )
        if missing:
            raise ValueError(
                f"a distributed study needs --coordinator, --num-processes and --process-id (missing: "
                f"{', '.join(missing)}), or --distributed to take them from the environment"
            )
    if None not in given[1:] and args.process_id >= args.num_processes:
        n = args.num_processes
        raise ValueError(f"--process-id must be in 0..{n - 1} (--num-processes {n}), got {args.process_id}")
    timeout = 300 if args.timeout is None else args.timeout
    if not args.quiet and args.process_id == 0 and (args.num_processes or 0) > 1:
        # process 0 left alone is aborted by JAX's runtime (a C++ stack dump): say so first.  The others
        # check that process 0 listens before JAX starts and end with one line if it does not.
        print(
            f"jaxobs: process 0 waits up to {timeout} s (--timeout) for the other {args.num_processes - 1} "
            "process(es); if they do not come, JAX aborts it (exit 134)",
            file=sys.stderr,
        )
    try:
        return jaxobs.init_distributed(*given, timeout=timeout)
    except ValueError as e:  # what JAX could not find: name the CLI's options and variables, not the function's
        jax_says = str(e.__context__ or e).rstrip(".")  # init_distributed raises from JAX's own ValueError
        raise ValueError(
            f"--distributed: the environment does not give the run ({jax_says}): set JAX_COORDINATOR_ADDRESS "
            "(with --num-processes and --process-id), launch under SLURM's srun or Open MPI's mpirun, "
            "or give --coordinator, --num-processes and --process-id"
        ) from None


@contextlib.contextmanager
def _stdout_to_stderr():
    """File descriptor 1 points at stderr inside (what native code prints there goes to stderr)."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def _distributed_study(name, designs, axes, opts, out: Path, args, rank) -> int:
    """One process of a study split over processes: every process computes its share of every chunk
    (jaxobs.study.run_study), process 0 alone checks, locks and writes ``--out`` (and shows progress)."""
    import numpy as np
    from jax.experimental import multihost_utils

    from jaxobs.study import run_study

    pid, count = rank
    with contextlib.ExitStack() as stack:
        failure = None
        if pid == 0:
            try:
                stack.enter_context(OutDir(out, ["study.nc"], force=args.force))
                args.log_dir = out
            except Exception as e:  # told to the others first, so that none of them waits for it in a collective
                failure = e
        # every process learns whether process 0 can write, and whether all were given the same study (file and
        # result files, by sha256), before any of them computes: different files would give different chunk
        # shapes, on which the collectives abort the processes.  The first collective connects the CPU
        # collectives, whose gloo prints a line on the C++ stdout: to stderr, stdout is results.
        prov = {k: v for k, v in (opts.get("provenance") or {}).items() if k != "study_file"}
        digest = hashlib.sha256(json.dumps(prov, sort_keys=True, default=str).encode()).digest()
        with _stdout_to_stderr():
            ok = int(multihost_utils.broadcast_one_to_all(np.int32(failure is None)))
            digests = np.asarray(multihost_utils.process_allgather(np.frombuffer(digest[:16], dtype=np.int32)))
        if failure is not None:
            raise failure
        if not ok:
            raise ValueError("process 0 cannot use its --out (its error says why); nothing computed")
        differ = [i for i, d in enumerate(digests) if not np.array_equal(d, digests[0])]
        if differ:
            raise ValueError(
                f"the processes were given different study files (or result files): process(es) "
                f"{', '.join(map(str, differ))} differ from process 0; give every process the same; nothing computed"
            )
        if pid == 0:
            return _run_study(name, designs, axes, opts, out, args.quiet)
        kw = {k: v for k, v in opts.items() if k not in ("kind", "provenance", "recording")}
        run_study(designs, axes, progress=False, **kw)
        print(f"study {name}: process {pid} of {count} computed its share; process 0 writes the results")
        return 0


def _run_study(name, designs, axes, opts, out: Path, quiet: bool) -> int:
    from jaxobs.plot import study_figures
    from jaxobs.study import STUDY_METRICS, run_study, worst_cases

    provenance = opts.pop("provenance", None) or {}
    if opts.pop("kind", "fll") == "drive":
        return _cmd_drive_study(name, designs, axes, opts, out, quiet, provenance)
    if opts.get("recording") is not None:  # [study.recording]: the recordings are the scenarios
        ds, seconds = _recording_study(designs, progress=_progress(quiet=quiet), **opts)
    else:
        opts.pop("recording", None)
        ds, seconds = run_study(designs, axes, progress=_progress(quiet=quiet), return_seconds=True, **opts)
    ds.attrs.update(provenance)  # the study file's and the result files' sha256
    worst = {m: worst_cases(ds, m, 3) for m in STUDY_METRICS}
    atomic_write_text(out / "worst_cases.json", json.dumps(worst, indent=1))
    figs = study_figures(ds, out)
    with atomic_path(out / "study.nc") as tmp:  # last: a study.nc means a complete results folder
        ds.to_netcdf(tmp, engine="scipy")
    n = int(ds.attrs["scenarios"])
    print(f"study {name}: {len(designs)} designs x {n} scenarios in {seconds:.1f} s")
    wd = max(len("design"), *(len(str(d)) for d in ds["design"].values)) + 2  # sized from the names
    print(
        f"{'design':<{wd}}"
        + "".join(f"{m + ' mean':>20}{'worst':>12}" for m in ("settling_freq", "ripple_freq", "rms_phase"))
        + f"{'diverged':>10}{'lost lock':>11}"
    )
    for d in ds["design"].values:
        sel = ds.sel(design=d)
        row = f"{str(d):<{wd}}"
        for m in ("settling_freq", "ripple_freq", "rms_phase"):
            row += f"{float(sel[m].mean()):>20.4g}{float(sel[m].max()):>12.4g}"
        print(row + f"{int(sel['diverged'].sum()):>10}{int(sel['lost_lock_count']):>11}")
    print(f"results: {out / 'study.nc'}, {out / 'worst_cases.json'}, {len(figs)} figures")
    return 0


def _emit_rows(rows, figs, as_json: bool, title: str) -> int:
    """Print paper-vs-ours rows (table or JSON); non-zero exit if any simulation diverged."""
    from jaxobs.reproduce.flux import format_rows

    if as_json:
        print(json.dumps(rows, indent=1))
    else:
        print(title)
        print(format_rows(rows))
        for p in figs:
            print(f"figure: {p}")
    return 0 if all(r["ours"] for r in rows if r["metric"] == "finite") else 1


def _error_figures(traces, names, paper: str, specs, out: Path):
    """One position-error figure per (experiment, file name, start time) in ``specs``."""
    from jaxobs.plot import position_error_figure

    paths = []
    for key, fname, t_from in specs:
        p = out / fname
        position_error_figure(traces[key], names, f"Paper {paper}: {key}", p, t_from=t_from)
        paths.append(p)
    return paths


def _cmd_reproduce(args) -> int:
    _enable_x64()
    if args.paper not in REPRODUCE_FILES:
        raise ValueError(f"reproduce: unknown paper {args.paper!r}")
    args.out = args.out or f"out/reproduce-{args.paper}"
    with _out(args, REPRODUCE_FILES[args.paper]) as out:
        return _reproduce(args, out)


def _reproduce(args, out: Path) -> int:
    if args.paper == "flux":
        from jaxobs.plot import flux_circles_figure
        from jaxobs.reproduce.flux import OBSERVER_NAMES, run_flux_experiments

        rows, traces = run_flux_experiments(quick=args.quick, progress=_progress(args))
        figs = []
        files = REPRODUCE_FILES["flux"]
        for key, fname in zip(("du_alpha = 5 V at 1000 r/min", "steady 400 r/min"), files[:2], strict=True):
            p = out / fname
            flux_circles_figure(traces[key], OBSERVER_NAMES, f"Paper 000: estimated flux, {key}", p)
            figs.append(p)
        figs += _error_figures(
            traces,
            OBSERVER_NAMES,
            "000",
            zip(
                ("load step 10 N·m at 2000 r/min", "speed 400-2000-400 r/min", "du_alpha = 5 V at 1000 r/min"),
                files[2:],
                (0.3, 0.8, 0.8),
                strict=True,
            ),
            out,
        )
        return _emit_rows(
            rows,
            figs,
            args.json,
            "Paper 000 (second-order SOIFO) experiments on the simulated SPMSM drive — paper vs ours",
        )
    if args.paper == "leso":
        from jaxobs.reproduce.leso import LESO_NAMES, run_leso_experiments

        rows, traces = run_leso_experiments(progress=_progress(args))
        figs = _error_figures(
            traces,
            LESO_NAMES,
            "002",
            zip(
                (
                    "steady 600 r/min no load",
                    "speed ramp 300-600-840-600-300 r/min",
                    "load step 0-80 % at 600 r/min",
                ),
                REPRODUCE_FILES["leso"],
                (0.4, 0.4, 0.4),
                strict=True,
            ),
            out,
        )
        return _emit_rows(
            rows, figs, args.json, "Paper 002 (LESOs) experiments on the simulated IPMSM drive — paper vs ours"
        )
    raise ValueError(f"reproduce: unknown paper {args.paper!r}")


def default_job_path() -> Path:
    return Path(str(resources.files("tuning") / "presets" / "wif_robust.toml"))


def _cmd_tune(args) -> int:
    _enable_x64()
    path = Path(args.job) if args.job else default_job_path()
    job = load_job(path)
    if args.check:
        n = 1
        for v in job.scenarios.axes.values():
            n *= len(v)
        n = job.scenarios.sample or n
        drive = "" if job.drive is None else f", {job.drive.loop} drive on {job.drive.machine}"
        print(
            f"{path}: OK — {job.component}, free gains {', '.join(g.name for g in job.gains)}, {n} scenarios"
            f"{drive}, solver {job.solver.name}"
        )
        return 0
    out = Path(args.out) if args.out else Path("out") / safe_name(job.name)
    products = ["result.json"]
    if not args.resume:
        products.append(CHECKPOINT)  # a fresh run would overwrite it: --resume, or --force to start over
    resume = f"jaxobs tune {shlex.quote(str(path))} --out {shlex.quote(str(out))} --resume"
    hint = f"an earlier run stopped here: continue it with `{resume}` (--force starts over and discards it)"
    with OutDir(out, products, force=args.force, hints={CHECKPOINT: hint}):
        args.log_dir = out
        args.on_interrupt = f"; continue with: {resume}"  # what Ctrl-C says (main)
        result = run_job(job, out, resume=args.resume, quiet=args.quiet)
    try:
        timing = json.loads((out / "timing.json").read_text())
    except (OSError, ValueError):
        timing = {}
    _print_summary(result, out, timing)
    return 3 if result["status"] == "diverged" else 0


def _fmt(v, spec=">14.6g") -> str:
    if v is None:
        return f"{'-':>14}"
    if isinstance(v, bool):
        return f"{'yes' if v else 'no':>14}"
    return format(v, spec)


_LINEAR_ROWS = (
    ("phase margin (deg)", lambda s: s.get("phase_margin_deg")),
    ("crossover (Hz)", lambda s: s.get("crossover_hz")),
    ("dominant damping", lambda s: s.get("dominant_damping")),
    ("dominant pole (Hz)", lambda s: s.get("dominant_hz")),
    ("least pair damping", lambda s: s.get("least_pair_damping")),
    ("stable (linear)", lambda s: s.get("stable")),
    ("Routh stable", lambda s: s.get("routh_stable")),
    ("b = k1/k2", lambda s: s.get("closed_form_rule", {}).get("b_implied")),
    ("wc = k2 wn/2 (Hz)", lambda s: s.get("closed_form_rule", {}).get("crossover_hz_implied")),
    ("PM of SO at b (deg)", lambda s: s.get("closed_form_rule", {}).get("phase_margin_deg_implied")),
    ("lam by the rule", lambda s: s.get("closed_form_rule", {}).get("lam_rule")),
    ("lam / rule", lambda s: s.get("closed_form_rule", {}).get("lam_over_rule")),
    ("kp by the rule", lambda s: s.get("closed_form_rule", {}).get("kp_rule")),
)


def _print_summary(result: dict, out: Path, timing: dict | None = None):
    g, s, lin = result["gains"], result["scores"], result.get("linear", {})
    designs = ("initial", "closed_form", "tuned")
    heads = "".join(f"{h:>14}" for h in ("initial", "closed form", "tuned"))
    secs = f", {timing['total_s']:.1f} s" if timing and "total_s" in timing else ""
    print(
        f"{result['component']}: {result['status']} after {result['iterations']} iterations{secs}, "
        f"{result['scenarios']['count']} scenarios"
    )
    print(f"  {result['reason']}")
    if result["status"] == "diverged":
        print("DIVERGED: no gains are reported as tuned (every design tried diverged in some tuning scenario)")
    names = list(g["initial"])
    print(f"{'gain':<22}{heads}")
    for n in names:
        print(f"{n:<22}" + "".join(_fmt((g[d] or {}).get(n)) for d in designs))
    print(f"closed form: {result['closed_form_source']}")
    rows = [(label, [None if lin.get(d) is None else f(lin[d]) for d in designs]) for label, f in _LINEAR_ROWS]
    rows = [(label, vals) for label, vals in rows if any(v is not None for v in vals)]
    if rows:
        print(f"{'linear model':<22}{heads}")
        for label, vals in rows:
            print(f"{label:<22}" + "".join(_fmt(v) for v in vals))
    keys = [k for k in s["initial"] if k not in ("diverged", "lost_lock", "lost_sync", "lost_speed", "null_reason")]
    print(f"{'score':<22}{heads}")
    for k in keys:
        print(f"{k:<22}" + "".join(_fmt((s[d] or {}).get(k)) for d in designs))
    print(f"{'diverged scenarios':<22}" + "".join(_fmt((s[d] or {}).get("diverged"), ">14d") for d in designs))
    print(f"{'lost lock':<22}" + "".join(_fmt((s[d] or {}).get("lost_lock"), ">14d") for d in designs))
    if "lost_sync" in s["initial"]:  # drive jobs: diverged or |position error| > 90 deg
        print(f"{'lost sync scenarios':<22}" + "".join(_fmt((s[d] or {}).get("lost_sync"), ">14d") for d in designs))
    if "lost_speed" in s["initial"]:  # drive jobs: missed the speed reference by > 20 % in the steady window
        print(f"{'lost speed scenarios':<22}" + "".join(_fmt((s[d] or {}).get("lost_speed"), ">14d") for d in designs))
    if "holdout" in result:
        h = result["holdout"]
        worst = {d: (h[d] or {}).get("per_scenario_worst") for d in designs}
        div = {d: (h[d] or {}).get("diverged") for d in designs}
        print(f"{'held-out worst':<22}" + "".join(_fmt(worst[d]) for d in designs) + f"   ({h['count']} scenarios)")
        print(f"{'held-out diverged':<22}" + "".join(_fmt(div[d], ">14d") for d in designs))
        lost = {d: (h[d] or {}).get("lost_lock") for d in designs}
        print(f"{'held-out lost lock':<22}" + "".join(_fmt(lost[d], ">14d") for d in designs))
    for where, n in (result.get("lost_lock_tuned_only") or {}).items():
        if n:
            sets, nc = ("tuning", "scores.nc") if where == "tuning" else ("held-out", "holdout_scores.nc")
            msg = f"warning: the tuned design lost lock in {n} {sets} scenarios where the closed form holds it"
            print(f"jaxobs: {msg} (lost_lock in {nc})", file=sys.stderr)
    for d in designs:  # a drive that missed its speed reference (e.g. ran backwards) is flagged, never silent
        n = (s[d] or {}).get("lost_speed")
        if n:
            print(
                f"jaxobs: warning: the {d.replace('_', ' ')} drive missed its speed reference (> 20 % off, or "
                f"turning against it) in {n} scenarios (lost_speed in scores.nc)",
                file=sys.stderr,
            )
    for name, b in result.get("at_bound", {}).items():
        msg = f"warning: tuned {name} = {b['value']:.6g} is within 1 % of its {b['bound']} bound {b['limit']:g}"
        print(f"jaxobs: {msg}", file=sys.stderr)
    if result["status"] == "budget":
        print(
            f"jaxobs: warning: the solver's budget ran out before its stopping rule ({result['reason']}): "
            "the tuned gains may not be an optimum (raise solver.steps)",
            file=sys.stderr,
        )
    print(f"results: {out / 'result.json'} (history.json, timing.json, scores.nc)")


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2, no usage dump
        self.exit(2, f"jaxobs: error: {message}\n")


def _host_port(text: str) -> str:
    """argparse type of ``--coordinator``: ``HOST:PORT``, the port in 1..65535."""
    host, sep, port = text.rpartition(":")
    if not (sep and host and port.isdigit() and 1 <= int(port) <= 65535):
        raise argparse.ArgumentTypeError(f"must be HOST:PORT with a port in 1..65535, got {text!r}")
    return text


def _int_at_least(low: int):
    """argparse type: an integer >= ``low``."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            v = None
        if v is None or v < low:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low}, got {text!r}")
        return v

    return parse


def build_parser() -> argparse.ArgumentParser:
    """The one parser: every subcommand of ``jaxobs``, and ``--version``."""
    p = _Parser(prog="jaxobs", description="Differentiable simulation and tuning of motor-drive observers and FLLs.")
    p.add_argument("--version", action="version", version=f"jaxobs {jaxobs.__version__}")
    sub = p.add_subparsers(dest="cmd", parser_class=_Parser, metavar="COMMAND")  # none given: main lists them
    # every command takes --quiet: no progress on stderr (stdout, the results, is the same either way)
    quiet = _Parser(add_help=False)
    quiet.add_argument("--quiet", action="store_true", help="no progress bars or compile notices on stderr")
    quiet.add_argument(
        "--no-cache",
        action="store_true",
        help="do not keep compiled programs on disk (default: kept in $JAXOBS_CACHE_DIR or ~/.cache/jaxobs/jax, "
        "so a second run skips most of XLA's work; JAXOBS_CACHE_DIR=off turns it off too)",
    )
    t = sub.add_parser(
        "tune", help="gradient-based gain tuning from a TOML job (default: embedded WIF job)", parents=[quiet]
    )
    t.add_argument("job", nargs="?", help="job file (TOML); default: the embedded robust SOGI-FLL-WIF job")
    t.add_argument("--out", help="results folder (default: out/<job name>)")
    t.add_argument("--resume", action="store_true", help="continue from the checkpoint in --out")
    t.add_argument("--check", action="store_true", help="validate the job file and exit")
    t.add_argument("--force", action="store_true", help="overwrite results (and a checkpoint) already in --out")
    t.set_defaults(func=_cmd_tune)

    d = sub.add_parser("demo", help="FLL family (SOGI-FLL, -WPF, -WIF) on paper 001 Tests A-E", parents=[quiet])
    d.add_argument("--out", default="out/demo", help="folder for the figure (default: out/demo)")
    d.add_argument("--force", action="store_true", help="overwrite the figure already in --out")
    d.add_argument("--json", action="store_true", help="print the table as JSON rows")
    d.add_argument("--t-event", type=float, default=0.2, help="time of the test event, s (default 0.2)")
    d.set_defaults(func=_cmd_demo)

    c = sub.add_parser("closed-form", help="closed-form gains with formula and source equation", parents=[quiet])
    c.add_argument("design", choices=list(_CF_OPTIONS), help="which design rule")
    c.add_argument("--k", type=float, help="SOGI gain k (sogi-fll)")
    c.add_argument("--omega-n", dest="omega_n", type=float, help="nominal frequency, rad/s (default 100π)")
    c.add_argument("--zeta", type=float, help="damping ratio (default 1/√2)")
    c.add_argument("--omega-c", dest="omega_c", type=float, help="crossover, rad/s (wif, default 2π·18.8)")
    c.add_argument("--b", type=float, help="symmetric-optimum factor b > 1 (wif, default 1+√2)")
    c.add_argument("--omega0", type=float, help="LESO bandwidth, rad/s (cleso, default 500π)")
    c.add_argument("--rs", type=float, help="stator resistance, ohm (cleso)")
    c.add_argument("--lq", type=float, help="q-axis inductance, H (cleso)")
    c.add_argument("--json", action="store_true", help="print JSON")
    c.set_defaults(func=_cmd_closed_form)

    b = sub.add_parser("bode", help="Bode figures of the papers' flux observers, LESOs and FLL loops", parents=[quiet])
    b.add_argument("--out", default="out/bode", help="folder for the figures (default: out/bode)")
    b.add_argument("--force", action="store_true", help="overwrite figures already in --out")
    b.set_defaults(func=_cmd_bode)

    r = sub.add_parser("reproduce", help="reproduce a paper's experiments on the simulated drive", parents=[quiet])
    r.add_argument(
        "paper", choices=["flux", "leso"], help="flux: paper 000 (rotor-flux observers); leso: paper 002 (LESOs)"
    )
    r.add_argument("--out", help="folder for the figures (default: out/reproduce-<paper>)")
    r.add_argument("--force", action="store_true", help="overwrite figures already in --out")
    r.add_argument("--json", action="store_true", help="print rows {experiment, observer, metric, unit, paper, ours}")
    r.add_argument("--quick", action="store_true", help="skip the long runs (20 r/min steady state, I-f start-up)")
    r.set_defaults(func=_cmd_reproduce)

    st = sub.add_parser(
        "study",
        help="robustness study of FLL or sensorless-drive designs over a scenario grid (xarray/NetCDF)",
        parents=[quiet],
    )
    st.add_argument("study", nargs="?", help="study file (TOML); default: the FLL family's closed forms")
    st.add_argument("--out", help="results folder (default: out/<study name>)")
    st.add_argument("--force", action="store_true", help="overwrite a study.nc already in --out")
    st.add_argument("--check", action="store_true", help="validate the study file (every range, the sizes) and exit")
    dist = st.add_argument_group(
        "distributed run",
        "one process of a study split over processes (jaxobs.init_distributed): give all three, or "
        "--distributed to take them from the environment (JAX_COORDINATOR_ADDRESS, SLURM's srun, Open MPI)",
    )
    dist.add_argument("--coordinator", type=_host_port, metavar="HOST:PORT", help="process 0's address and a free port")
    dist.add_argument("--num-processes", type=_int_at_least(1), metavar="N", help="the number of processes, >= 1")
    dist.add_argument("--process-id", type=_int_at_least(0), metavar="I", help="this process's index, 0..N-1")
    dist.add_argument(
        "--distributed", action="store_true", help="join a distributed run; what is not given, the environment gives"
    )
    dist.add_argument(
        "--timeout",
        type=_int_at_least(1),
        metavar="S",
        help="seconds to wait for every process to join (default 300); then a process other than 0 that found "
        "no process 0 exits 2 with one line, and a process 0 left alone is aborted by JAX (exit 134)",
    )
    st.set_defaults(func=_cmd_study)

    add_export_parser(sub)
    add_envelope_parser(sub)
    return p


def main(argv=None) -> int:
    """Run the command line (``argv`` defaults to ``sys.argv[1:]``); returns the exit status."""
    parser = build_parser()
    args = None
    try:
        use_host_devices()  # before any JAX computation: one CPU device per usable core
        args = parser.parse_args(argv)
        if args.cmd is None:  # `jaxobs` alone: the commands, not argparse's "arguments are required: cmd"
            parser.print_help(sys.stderr)
            return 2
        if not getattr(args, "no_cache", False):
            use_compile_cache()  # before any compilation: compiled programs are reused by the next process
        return args.func(args)
    except ValueError as e:  # bad input, job-file errors (JobError) included: one line, exit 2
        print(f"jaxobs: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:  # an output folder that cannot be made or written, a file that cannot be read
        where = f": {e.filename}" if e.filename else ""
        print(f"jaxobs: error: {e.strerror or e}{where}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        # on a line of its own: a progress bar may hold the terminal's current line
        start = "\n" if sys.stderr.isatty() else ""
        print(f"{start}jaxobs: interrupted{getattr(args, 'on_interrupt', '')}", file=sys.stderr)
        return 130
    except (Exception, MemoryError) as e:  # an internal error: the traceback to a log, one line here
        log = _write_error_log(getattr(args, "log_dir", None))
        what = "out of memory" if isinstance(e, MemoryError) else f"internal error ({type(e).__name__})"
        print(f"jaxobs: {what}: {' '.join(str(e).split())[:120]} — traceback in {log}", file=sys.stderr)
        return 1


def _write_error_log(out) -> str:
    """The current exception's traceback to ``<out>/error.log`` (else a temporary file); its path."""
    text = traceback.format_exc()
    if out is not None:
        try:
            path = Path(out) / "error.log"
            if not path.is_symlink():
                path.write_text(text)
                return str(path)
        except OSError:
            pass
    try:
        fd, path = tempfile.mkstemp(prefix="jaxobs-error-", suffix=".log")
        with open(fd, "w") as f:
            f.write(text)
        return path
    except OSError:
        return "(no log: nothing writable)"


if __name__ == "__main__":
    sys.exit(main())
