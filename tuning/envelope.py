"""``jaxobs envelope (JOB.toml | RESULT.json)``: the operating envelope of a drive job's designs.

For a drive job file, its initial and closed-form designs; for a ``jaxobs tune`` result.json of a drive job,
its initial, closed-form and tuned designs (the result's own values).  The job's machine and drive (the
bench FOC), always sensorless and started steady whatever the job's loop and start: the envelope is where the
observer can close the loop, measured through the drive file's ``[sensors]`` (``--ideal-sensors``: ideal; a
shipped bench's are ideal); the Floquet stability verdict (:func:`jaxobs.analysis.stability.floquet`) with the
job's ``[envelope]`` settle and window where it has one.  ``--speeds`` may hold negative speeds
(``--speeds=-450,450``); ``--reversal`` adds each design's slowest held reversal.  Writes ``envelope.nc`` (NetCDF,
:func:`jaxobs.analysis.envelope.envelope`) and ``envelope.png`` (:func:`jaxobs.plot.envelope_figure`) under ``--out``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, cast

from jaxobs.io.provenance import cf_labels

from .job import COMPONENTS, Job, JobError, job_drive, load_job, parse_job
from .outdir import OutDir, atomic_path, safe_name
from .results import load_result, result_designs

if TYPE_CHECKING:
    from jaxobs.drive import DriveFile
    from jaxobs.observers.base import AbstractDriveObserver

    from .job.verify import EnvelopeSpec

ENVELOPE_FILES = ("envelope.nc", "envelope.png")


def envelope_designs(path: Path, drive: str | None = None) -> tuple[Job, dict[str, AbstractDriveObserver]]:
    """(job, {design name: observer}) of a job file or of a result.json (its job and its values).

    Args:
        path: The job file (TOML) or result.json.
        drive: A drive file that replaces the result's job's (a result keeps its job's drive file inline);
            None: the job's own.

    Returns:
        ``(job, designs)``.

    Raises:
        JobError: A job that is not a drive job, or ``drive`` with a job file.
    """
    if path.suffix == ".json":  # the one reader of result files (jaxobs_tuning.results), as study and export
        result = load_result(path)
        raw = result["job"]
        if drive is not None:
            keep = {k: v for k, v in raw.get("drive", {}).items() if not isinstance(v, dict) and k != "machine"}
            keep = {k: v for k, v in keep.items() if k not in ("file", "name", "description")}
            raw = {**raw, "drive": {**keep, "file": str(Path(drive).resolve())}}
        job = parse_job(raw, path.parent)
        designs = result_designs(result, f"result file {str(path)[:120]!r}")
    else:
        if drive is not None:
            raise JobError("--drive", "applies to a result.json; a job file names its drive file ([drive] file)")
        job = load_job(path)
        info = COMPONENTS[job.component]
        initial = info.ctor(**job.values)
        cf = info.closed_form(initial, job.values)
        closed = info.ctor(**info.values_with(job.values, {g.name: float(cf[g.name]) for g in job.gains}))
        designs = {"initial": initial, "closed_form": closed}
    if job.drive is None or not job.scenarios.family.closed_loop:
        raise JobError(
            "scenarios.signal", f"must be 'drive' for an envelope (a drive job), got {job.scenarios.signal!r}"
        )
    return job, designs


def _seconds(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds in [0.5, 20], got {text!r}") from None
    if not 0.5 <= v <= 20.0:
        raise argparse.ArgumentTypeError(f"must be a number of seconds in [0.5, 20], got {v:g}")
    return v


def _count_or_list(what: str, unit: str, low: int, high: int, floor: float):
    """A count of values (an integer in [low, high]) or the values themselves, comma-separated (``20,50,100``;
    one value with a trailing comma: ``400,``; negative values after ``=``: ``--speeds=-400,400``), finite, of
    magnitude >= ``floor`` and strictly increasing."""
    usage = (
        f"must be a count in [{low}, {high}] or comma-separated {what} ({unit}, |value| >= {floor:g}, increasing; "
        f"one value with a trailing comma: 600,; negative ones after =: --{what}=-600,600)"
    )

    def parse(text: str):
        if "," not in text:
            try:
                v = int(text)
            except ValueError:
                raise argparse.ArgumentTypeError(f"{usage}, got {text[:40]!r}") from None
            if not low <= v <= high:
                raise argparse.ArgumentTypeError(f"{usage}, got {v}")
            return v
        try:
            vals = [float(x) for x in text.split(",") if x.strip()]
        except ValueError:
            raise argparse.ArgumentTypeError(f"{usage}, got {text[:40]!r}") from None
        if not vals or len(vals) > 256 or not all(math.isfinite(v) and abs(v) >= floor for v in vals):
            raise argparse.ArgumentTypeError(f"{usage}, got {text[:40]!r}")
        if any(b <= a for a, b in zip(vals, vals[1:])):
            raise argparse.ArgumentTypeError(f"{usage}: not increasing, got {text[:40]!r}")
        return tuple(vals)

    return parse


def cli_envelope(args: argparse.Namespace) -> int:
    """``jaxobs envelope``: the operating envelope of a drive job's designs (module doc).

    Args:
        args: The parsed command line.

    Returns:
        The exit status: 0.

    Raises:
        ValueError: Bad input (one line, exit 2).
    """
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    from jaxobs.analysis.envelope import default_loads, default_speeds, envelope, speed_limit_rpm
    from jaxobs.plot import envelope_figure

    path = Path(args.source)
    job, designs = envelope_designs(path, getattr(args, "drive", None))
    assert job.drive is not None  # envelope_designs refuses a job without a drive
    spec = dataclasses.replace(job.drive, loop="sensorless", start="steady", handover=0.0)
    # a dual three-phase drive file maps the whole dual machine (its [machine] per set is what observers assume)
    df = cast("DriveFile", spec.drive_file)  # the job's checked drive file (jaxobs_tuning.job.spec.DriveSpec)
    par = df.machine if df.dual is None else df.dual
    drive = job_drive(spec, dual=True)
    ax = df.machine if df.dual is None else df.dual.m  # the whole machine's ratings, ψf and p set the axes
    # a count: the default axes (log-spaced speeds from 1 % of rated to the drive's limit, loads 0..rated); or
    # the values themselves, within the drive's limit and the study's loads
    mech = df.table.get("machine", {}).get("max_speed_rpm")  # the file's mechanical limit, if any
    if isinstance(args.speeds, tuple):
        top = speed_limit_rpm(ax, drive, mech)
        far = max(args.speeds, key=abs)
        if abs(far) > top:
            raise ValueError(f"--speeds: |speed| must be <= {top:.4g} r/min (the drive's speed limit), got {far:g}")
        speeds = np.asarray(args.speeds)
    else:
        speeds = default_speeds(ax, args.speeds, drive=drive, max_speed_rpm=mech)
    loads = np.asarray(args.loads) if isinstance(args.loads, tuple) else default_loads(ax, args.loads)
    n = len(speeds) * len(loads)
    # the job's own settle and (shortest) window where it states them ([envelope]), else the library's defaults
    # (jaxobs.analysis.envelope.STABILITY_METHODS: settle 0.2 s, windows of at least 0.2 s)
    env = cast("EnvelopeSpec | None", job.envelope)  # the job's [envelope] (Job types it object)
    stab = {} if env is None else {"settle": env.settle, "window": env.window}
    # the drive file's sensors (its [sensors]: the ADC's quantization as noise) unless --ideal-sensors; a shipped
    # bench's are ideal (as a job's scenarios run them: jaxobs_tuning.job.scenarios)
    sensors = None if (args.ideal_sensors or spec.file is None) else df.sensors
    what = (
        f"{path}: {job.component} on {spec.machine}, designs {', '.join(designs)}; {len(speeds)} speeds "
        f"{speeds[0]:.4g}..{speeds[-1]:.4g} r/min x {len(loads)} loads {loads[0]:.4g}..{loads[-1]:.4g} N·m = "
        f"{n} points, runs of at least {args.horizon:g} s, {_sensors_text(sensors, args.ideal_sensors)}"
    )
    if args.check:
        # the window is only a floor: envelope() stretches it to one electrical period of the lowest speed (the
        # Floquet verdict's whole periods: 1.0 s at 20 r/min on 000's SPMSM), most of a map's cost
        w = 1.02 * 60.0 / (float(ax.p) * float(np.abs(speeds).min()))
        win = "" if env is None else f", Floquet settle {env.settle:g} s"
        print(
            f"{what}{win}, windows of whole electrical periods, up to {max(w, 2.0):.3g} s (one at the lowest speed): OK"
        )
        return 0
    out = Path(args.out) if args.out else Path("out") / f"envelope-{safe_name(job.name)}"
    with OutDir(out, ENVELOPE_FILES, force=args.force):
        args.log_dir = out
        ds = envelope(
            designs,
            machine=par,
            drive=drive,
            speeds_rpm=speeds,
            loads_nm=loads,
            horizon=args.horizon,
            stability=stab,
            progress=False if args.quiet else "auto",
            max_speed_rpm=mech,
            sensors=sensors,
            reversal={} if args.reversal else None,
        )
        # source (CF: how the data were made) stays the library function; the job file is its own attribute
        ds.attrs.update(job_file=str(path), job_name=job.name, component=job.component, machine=spec.machine)
        if job.sha256:
            ds.attrs["job_sha256"] = job.sha256
        with atomic_path(out / "envelope.png") as tmp:
            envelope_figure(ds, tmp)
        with atomic_path(out / "envelope.nc") as tmp:
            cf_labels(ds).to_netcdf(tmp, engine="h5netcdf")  # a numeric design index, the names its label
    a = ds.attrs  # what ran: the stretched window and warm-up, and the steady start's settle (Drive.settled_for)
    print(
        f"{what}, Floquet verdict: settle {a['stability_settle']:.3g} s, windows {a['stability_window']:.3g} s up to "
        f"{a['stability_max_window']:.3g} s (whole electrical periods); "
        f"observers settled {a['drive_settle']:.3g} s before each run"
    )
    _print_table(ds, list(designs), n)
    if args.reversal:
        _print_reversal(ds, list(designs))
    print(f"results: {out / 'envelope.nc'}, {out / 'envelope.png'}")
    return 0


def _print_table(ds, designs: list[str], n: int) -> None:
    """The summary: per design, how many points hold, are stable, marginal and synchronous, the smallest resolved
    margin and the lowest speed held at every load."""
    wd = max(len("design"), *(len(d) for d in designs)) + 2
    head = f"{'design':<{wd}}{'holds':>9}{'stable':>9}{'marginal':>9}{'sync':>9}{'min margin 1/s':>16}"
    print(head + f"{'lowest r/min held at all loads':>32}")
    for d in designs:
        s = ds.sel(design=d)
        all_loads = s["holds"].astype(bool).all("load_nm")
        low = f"{float(s['speed_rpm'][all_loads].min()):.4g}" if bool(all_loads.any()) else "none"
        # the smallest margin among the resolved points only: a marginal point's (within its resolution of 0) or
        # an off-orbit point's (a bound on a rate, not a margin) is no margin to report
        resolved = (s["marginal"] == 0) & (s["off_orbit"] == 0) & s["resolution"].notnull()
        m_min = f"{float(s['margin'].where(resolved).min()):.4g}" if bool(resolved.any()) else "none"
        print(
            f"{d:<{wd}}{int(s['holds'].sum()):>5}/{n:<3}{int(s['stable'].sum()):>5}/{n:<3}{int(s['marginal'].sum()):>5}/{n:<3}"
            f"{int(s['synchronous'].sum()):>5}/{n:<3}{m_min:>16}{low:>32}"
        )


def _print_reversal(ds, designs: list[str]) -> None:
    """The reversal verdict: per design and load, the slowest held rate (the nearest failing one in brackets;
    "(bound)" where every probed rate held; "none held"; "*" where the probes changed verdict more than once)."""
    import numpy as np

    a = ds.attrs
    lo, hi = (float(x) for x in np.atleast_1d(a["reversal_rates"]))
    print(
        f"slowest held reversal, +{float(a['reversal_speed_rpm']):.4g} to -{float(a['reversal_speed_rpm']):.4g} "
        f"r/min, rates {_rate(lo)}..{_rate(hi)} r/min per second to {100 * float(a['reversal_resolution']):.3g} %"
    )
    loads = [float(x) for x in ds["reversal_load_nm"].values]
    wd = max(len("design"), *(len(d) for d in designs)) + 2
    print(f"{'design':<{wd}}" + "".join(f"{f'{x:.4g} N·m':>28}" for x in loads))
    for d in designs:
        cells = []
        for x in loads:
            r = ds.sel(design=d, reversal_load_nm=x)
            rate, other = float(r["reversal_rate"]), float(r["reversal_fails_at"])
            if not np.isfinite(rate):
                cell = "none held"
            elif not np.isfinite(other):
                cell = f"<= {_rate(rate)} (bound)"
            else:
                cell = f"{_rate(rate)} ({_rate(other)} fails)"
            cells.append(cell + ("" if int(r["reversal_monotone"]) else " *"))
        print(f"{d:<{wd}}" + "".join(f"{c:>28}" for c in cells))
    print("rates in r/min per second; * the probes changed verdict more than once (not monotone in the rate)")


def _rate(x: float) -> str:
    """A ramp rate, r/min per second: whole above 100, else 3 digits."""
    return f"{x:.0f}" if x >= 100 else f"{x:.3g}"


def _sensors_text(sensors, forced: bool) -> str:
    """What the runs measure through, in words."""
    if sensors is None:
        return "ideal sensors (--ideal-sensors)" if forced else "ideal sensors (a shipped bench)"
    import numpy as np

    parts = [f"current noise {float(sensors.i_noise):.3g} A", f"voltage noise {float(sensors.u_noise):.3g} V"]
    if np.any(np.asarray(sensors.i_offset) != 0) or np.any(np.asarray(sensors.u_offset) != 0):
        parts.append("offsets")
    if np.any(np.asarray(sensors.i_gain) != 1):
        parts.append("gain errors")
    if not sensors.noisy and len(parts) == 2:
        return "ideal sensors (the drive file's [sensors])"
    return "the drive file's sensors (" + ", ".join(parts) + ")"


def add_envelope_parser(
    subparsers: argparse._SubParsersAction, parents: Sequence[argparse.ArgumentParser] = ()
) -> argparse.ArgumentParser:
    """Add ``jaxobs envelope`` to the CLI's subparsers.

    Args:
        subparsers: The CLI's subparsers.
        parents: The parsers of the options every command shares (--quiet, --no-cache).

    Returns:
        The ``envelope`` parser.
    """
    e = subparsers.add_parser(
        "envelope",
        help="where a drive job's designs hold: stability and synchronism over speed x load",
        description="Where a drive job's designs hold: stability and synchronism over speed x load.",
        parents=list(parents),
    )
    e.add_argument("source", help="a drive job file (TOML) or a `jaxobs tune` result.json of one")
    e.add_argument("--out", help="results folder (default: out/envelope-<job name>)")
    e.add_argument("--drive", help="a drive file (TOML) to map a result.json on (default: the result's job's drive)")
    e.add_argument(
        "--speeds",
        type=_count_or_list("speeds", "r/min", 2, 64, 1.0),
        default=8,
        help="a count of speeds, log-spaced from 1 %% of rated to the drive's speed limit (default 8), or the "
        "speeds, r/min, comma-separated (20,50,100)",
    )
    e.add_argument(
        "--loads",
        type=_count_or_list("loads", "N·m", 1, 32, 0.0),
        default=4,
        help="a count of loads, 0..rated torque (default 4), or the loads, N·m, comma-separated (0,2.5,5)",
    )
    e.add_argument("--horizon", type=_seconds, default=2.0, help="long-run horizon, s (default 2)")
    e.add_argument(
        "--ideal-sensors",
        action="store_true",
        help="run ideal sensors (default: the drive file's [sensors], its ADC's quantization as noise)",
    )
    e.add_argument(
        "--reversal",
        action="store_true",
        help="also search each design's slowest held reversal, +n to -n at half the rated speed, with no load and "
        "half the rated torque (batched simulations up to 10 s long: minutes)",
    )
    e.add_argument("--check", action="store_true", help="validate the source and print what would run")
    e.add_argument("--force", action="store_true", help="overwrite an envelope already in --out")
    if not parents:  # a parser of its own (tests build one): the shared options, briefly
        e.add_argument("--quiet", action="store_true", help="no progress on stderr")
        e.add_argument("--no-cache", action="store_true", help="do not keep compiled programs on disk")
    e.set_defaults(func=cli_envelope)
    return e
