"""The full run's parts after the throughput rows: time to result and scale.

- ``time-to-result``: :func:`benchmarks.first_second.measure` of ``make run``'s job (``make-run``), two runs
  in fresh processes sharing a compilation cache that starts empty: the first compiles, the second reads the
  cache;
- ``scale``: :func:`benchmarks.scale.measure` of an FLL study of 10⁶ scenarios and a drive study of 10⁵,
  each streamed to disk in a fresh process (scenarios/s, peak RSS).

Each is those modules' own measurement, called as it is; this module only names the sizes and assembles the
tables.  ``python -m benchmarks`` (``make bench``) runs them after the throughput rows, ``--only
time-to-result scale`` runs them alone, ``--no-time-to-result`` / ``--no-scale`` leave them out.
"""

from __future__ import annotations

from collections.abc import Callable

from . import first_second, scale

PARTS = ("throughput", "time-to-result", "scale")
TIME_TO_RESULT = {"cmds": ("make-run",), "runs": 2}  # make run's first and second run
SCALE = (("fll", 1_000_000), ("drive", 100_000))  # 10⁶ FLL and 10⁵ drive scenarios


def time_to_result(log: Callable[[str], None] = print) -> list[dict]:
    """The time-to-result rows (:func:`benchmarks.first_second.measure`), each logged as it is measured."""
    log(f"time to result: {', '.join(TIME_TO_RESULT['cmds'])}, {TIME_TO_RESULT['runs']} runs, empty cache first")
    return first_second.measure(
        TIME_TO_RESULT["cmds"],
        TIME_TO_RESULT["runs"],
        log=lambda r: log(f"  {r['command']} run {r['run']}: {r['wall_s']:.1f} s wall, {r['cpu_s']:.1f} s CPU"),
    )


def scale_rows(log: Callable[[str], None] = print) -> list[dict]:
    """The scale rows (:func:`benchmarks.scale.measure`): the FLL study of 10⁶ scenarios, the drive's of 10⁵."""
    rows = []
    for kind, n in SCALE:
        log(f"scale: {kind} study of {n:,} scenarios")
        rows += scale.measure([n], kind, log=lambda m: log(f"  {m}"))
    return rows


def tables(res: dict) -> str:
    """The time-to-result and scale tables of ``res`` (``"time_to_result"``, ``"scale"``: rows, or an
    ``{"error": ...}`` when the part failed); empty where neither ran."""
    out = []
    for key, title, fmt in (
        (
            "time_to_result",
            "time to result (first run with an empty compilation cache, then the second)",
            first_second.table,
        ),
        ("scale", "scale (studies streamed to disk, one fresh process each)", scale.table),
    ):
        if key not in res:
            continue
        part = res[key]
        out.append(f"{title}:")
        out.append(f"  failed: {part['error']}" if isinstance(part, dict) else fmt(part))
    return "\n".join(out)
