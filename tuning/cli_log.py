"""``jaxobs log check FILE``: a drive log read as declared, and what was understood of it, before any job runs.

It reads the log with :func:`jaxobs.signals.read_drive_log` (the reader every job uses: the same layout, sidecar
and checks) and prints the columns taken for each role with their frame and units, the sample rate and length, the
speed range, the events found (steps in speed or in current), and every warning.  A log the reader refuses: one
line naming the column or line, exit 2 (the command line's ``ValueError``).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

# an event: the mean over a block of speed or current amplitude moves, against the block _EVENT_LAG blocks before,
# by more than _EVENT_FRACTION of the range the log's block means span (and 1 % of their largest): a step, or a ramp
# such as a speed loop's response (000's SPMSM: 314 → 320 rad/s in 25 ms after a speed step)
_EVENT_FRACTION = 0.05
_EVENT_BLOCK_S = 0.005  # the blocks' length, s
_EVENT_LAG = 4  # blocks
_MAX_EVENTS = 12  # events listed (the rest counted)


def _columns(text: str | None, default: tuple[str, ...]) -> tuple[str, ...]:
    if text is None:
        return default
    cols = tuple(c.strip() for c in text.split(",") if c.strip())
    if len(cols) not in (2, 3):
        raise ValueError(f"log check: a column list takes 2 or 3 names separated by commas, got {text!r}")
    return cols


def _layout(path: str | None):
    from jaxobs.io.safetoml import read_toml
    from jaxobs.signals import RecordingLayout

    if path is None:
        return None
    doc, _ = read_toml(path, "--layout")
    table = doc.get("layout", doc)  # a sidecar's [layout] table, or the keys at the top
    return RecordingLayout.from_table(table, where=f"--layout {Path(path).name}")


def _machine(name: str | None):
    if name is None:
        return None
    from jaxobs.drive import bench_machine, load_drive

    return load_drive(name)[0] if name.endswith(".toml") else bench_machine(name)


def _block_means(x: np.ndarray, m: int) -> np.ndarray:
    k = x.size // m
    return x[: k * m].reshape(k, m).mean(axis=1)


def events(t0: float, ts: float, speed: np.ndarray | None, amp: np.ndarray) -> list[str]:
    """The steps found in a log: block means of speed and current amplitude against the block before.

    Args:
        t0: The time of the first row, s.
        ts: The sample interval, s.
        speed: The electrical speed per row (rad/s), or None.
        amp: The current amplitude per row, A.

    Returns:
        One line per step (time, quantity, from → to), in time order.
    """
    m = max(2, int(round(_EVENT_BLOCK_S / ts)))
    L = _EVENT_LAG
    found = []
    for what, x, unit in (("speed", speed, "rad/s"), ("current amplitude", amp, "A")):
        if x is None or x.size < (L + 2) * m:
            continue
        b = _block_means(np.asarray(x, dtype=float), m)
        span = float(np.max(b) - np.min(b))
        tol = max(_EVENT_FRACTION * span, 0.01 * float(np.max(np.abs(b))))
        if span <= tol:
            continue
        d = b[L:] - b[:-L]  # d[k]: block k + L against block k
        for sign in (1.0, -1.0):  # rises and falls apart: a rise straight into a fall is two events
            moving = sign * d > tol
            starts = np.flatnonzero(moving & ~np.concatenate([[False], moving[:-1]]))
            for s in starts:
                e = s
                while e + 1 < moving.size and moving[e + 1]:
                    e += 1
                a, z = s, e + L  # from the block before the change to the last block of its run
                z = a + int(np.argmax(sign * b[a : z + 1]))  # where it turns
                step = sign * np.diff(b[a : z + 1])
                onset = a + int(np.argmax(step > tol / L))  # the first block that moves by a lag's share
                kind = "step" if z - onset <= 2 else "ramp"
                t = t0 + (onset + 1) * m * ts
                found.append((t, f"{t:.4g} s: {what} {kind}, {b[a]:.4g} → {b[z]:.4g} {unit}"))
    return [line for _, line in sorted(found)]


def cmd_log_check(args: argparse.Namespace) -> int:
    """``jaxobs log check``: read a log as declared and print what was understood (module doc).

    Args:
        args: The parsed command line.

    Returns:
        0.

    Raises:
        ValueError: Bad input (one line, exit 2).
    """
    import warnings

    from jaxobs.signals import RecordingLayout, RecordingWarning, read_drive_log

    voltages = _columns(args.voltages, ("u_a", "u_b"))
    currents = _columns(args.currents, ("i_a", "i_b"))
    layout = _layout(args.layout)
    machine = _machine(args.machine)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RecordingWarning)  # printed below from log.warnings, once each
        log = read_drive_log(
            args.file,
            voltages=voltages,
            currents=currents,
            theta_e=None if args.theta == "" else args.theta,
            omega_e=args.omega,
            # `--sample-rate 0` is a rate, refused as one ("sample_rate must be ... > 0"), not a second time base
            time_column=args.time if args.time is not None or args.sample_rate is not None else "t",
            sample_rate=args.sample_rate,
            layout=layout,
            machine=machine,
        )
    shown = layout or RecordingLayout.sidecar(args.file) or RecordingLayout()
    source = "--layout" if layout is not None else ("its sidecar" if RecordingLayout.sidecar(args.file) else "default")
    print(f"log {args.file}: read ({log.n} rows kept)")
    print(f"  layout ({source}):")
    print(f"    voltages {', '.join(map(str, voltages))}: {shown.voltage_frame}, {shown.voltage_unit}", end="")
    if shown.voltage_timing == "reference":
        print(f", references applied {shown.voltage_delay} period(s) after they are logged")
    else:
        print(", applied over the period from their row")
    print(f"    currents {', '.join(map(str, currents))}: {shown.current_frame}, {shown.current_unit}")
    if log.theta_e is not None:
        print(f"    angle {args.theta}: {shown.angle_kind}, {shown.angle_unit}", end="")
        print(f"; speed {args.omega}: {shown.speed_kind}, {shown.speed_unit}" if args.omega else "")
    rate = 1.0 / log.ts
    print(f"  sampled at {rate:.6g} Hz (ts = {log.ts:.6g} s), from {log.t0:.6g} s, {log.n * log.ts:.6g} s long")
    speed = amp = None
    n = log.n
    if log.omega_e is not None:
        speed = np.asarray(log.omega_e[0:n])
    elif log.theta_e is not None:
        speed = np.gradient(np.asarray(log.theta_e[0:n]), log.ts)
    if speed is not None:
        w_lo, w_hi = float(np.min(speed)), float(np.max(speed))
        p = shown.pole_pairs or (machine.p if machine is not None else None)
        rpm = (
            f" ({w_lo * 60 / (2 * math.pi * p):.5g} … {w_hi * 60 / (2 * math.pi * p):.5g} r/min, p = {p})" if p else ""
        )
        print(f"  electrical speed {w_lo:.5g} … {w_hi:.5g} rad/s{rpm}")
    amp = np.hypot(np.asarray(log.i_a[0:n]), np.asarray(log.i_b[0:n]))
    print(f"  current amplitude {float(np.min(amp)):.4g} … {float(np.max(amp)):.4g} A")
    ev = events(log.t0, log.ts, speed, amp)
    print(f"  events found: {len(ev) if ev else 'none'}")
    for line in ev[:_MAX_EVENTS]:
        print(f"    {line}")
    if len(ev) > _MAX_EVENTS:
        print(f"    ... and {len(ev) - _MAX_EVENTS} more")
    if machine is None:
        print("  no machine given (--machine): the power direction and voltage timing were not checked")
    print(f"  warnings: {len(log.warnings) if log.warnings else 'none'}")
    for w in log.warnings:
        print(f"    {w}")
    return 0


def add_log_parser(
    subparsers: argparse._SubParsersAction, parents: Sequence[argparse.ArgumentParser] = ()
) -> argparse.ArgumentParser:
    """Add ``jaxobs log check`` to the CLI's subparsers.

    Args:
        subparsers: The CLI's subparsers.
        parents: The parsers of the options every command shares.

    Returns:
        The ``log`` parser.
    """
    lg = subparsers.add_parser(
        "log",
        help="a drive log read as declared: what was understood, and its warnings",
        description="Read a drive log (CSV) as a job would and print what was understood of it.",
    )
    lsub = lg.add_subparsers(dest="log_cmd", metavar="SUBCOMMAND", required=True)
    c = lsub.add_parser(
        "check",
        help="read a log and print its columns, frames, units, rate, speed range, events and warnings",
        description=(
            "Read a drive log with the layout it declares (its sidecar FILE.toml, or --layout) and print the "
            "columns taken for each role, frame and units, the sample rate, the speed range, the steps found in "
            "speed and current, and every warning of the reader's checks."
        ),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
        parents=list(parents),
    )
    c.add_argument("file", help="the log, a CSV file")
    c.add_argument("--layout", help="a TOML file with the layout (a [layout] table, as a sidecar)")
    c.add_argument("--machine", help="a shipped machine's name (spmsm000, ipmsm002) or a drive file (.toml)")
    c.add_argument("--voltages", help="the voltage columns, 2 or 3 names separated by commas (default u_a,u_b)")
    c.add_argument("--currents", help="the current columns, 2 or 3 names separated by commas (default i_a,i_b)")
    c.add_argument("--theta", default="theta_e", help="the angle column ('' for none)")
    c.add_argument("--omega", default=None, help="a speed column (default: none, the angle's slope)")
    c.add_argument("--time", default=None, help="the time column (default t, unless --sample-rate)")
    c.add_argument("--sample-rate", type=float, default=None, help="the rows' rate, Hz, where no time column")
    c.set_defaults(func=cmd_log_check)
    return lg
