"""Every layout :func:`jaxobs.signals.read_drive_log` reads, scored alike (docs/recordings.md, "Every layout, one
score").

``python -m benchmarks.log_layouts [--rows N] [--json FILE]``

One clean lab log, the shipped ``tuning/presets/recordings/drive_spmsm_1000rpm.csv`` (paper 000's SPMSM under
sensored FOC at 1000 r/min, 10 kHz; α-β currents and applied α-β voltages, electrical rad and rad/s, seconds), is
rewritten in each layout a controller may log (:data:`LAYOUTS`: phase currents, phase or d-q voltages, references
applied a period later, other units, another delimiter) with every digit of float64 (``%.17g``), read back with
its declared :class:`~jaxobs.signals.RecordingLayout`, and scored by the same observer (paper 000's second-order
SOIFO at its published gains, bound to the recorded speed at the first sample as a recording job binds it) with the
same metrics (:data:`METRICS`, scored from 0.02 s, past the observer's start-up, with the steady window from 0.2 s).
Each row's scores are printed beside the clean file's, with their largest relative difference.

A layout without a voltage delay reads back the clean samples to float64 rounding (a unit's factor, a Clarke or
Park transform and its inverse), so its scores equal the clean file's to 1e-6 relative (tests/test_log_layouts.py
checks a few).  A reference layout (``voltage_timing = "reference"``) drops its first ``voltage_delay`` rows, whose
applied voltage is before the log: its observer starts that many periods later, from the speed recorded there, so
its run is another run.  Its scores are compared with the clean file's read from the same first row (the last
column), where they again agree to rounding.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CLEAN = ROOT / "tuning" / "presets" / "recordings" / "drive_spmsm_1000rpm.csv"
NAMES = ("t", "u_a", "u_b", "i_a", "i_b", "theta_e", "omega_e")
P = 3  # paper 000's SPMSM's pole pairs
S3 = math.sqrt(3.0)
METRICS = ("iae_position", "rms_position_steady", "rms_speed_error_steady", "peak_speed_error")
# the shipped recording job's steady window (tuning/presets/recording_sosoifo.toml), and its event moved past the
# observer's start-up: one electrical period at 1000 r/min (p = 3: 50 Hz, 20 ms).  From t = 0 the peak speed error is
# the first sample's: the SOIFO signs ω̂ by the cross product of its flux and EMF estimates, still near zero at the
# first step, so a rounding of 3e-14 V in the voltages flips ω̂ from +314 to −314 rad/s there (a peak of 627 rad/s
# against 28)
T_EVENT, STEADY_FROM = 0.02, 0.2


@dataclass(frozen=True)
class Layout:
    """One way of logging the clean log: its columns (made from the clean ones), how it is read, what it declares.

    Attributes:
        name: The table's label.
        make: The clean columns (by :data:`NAMES`) → the logged columns (name → values).
        voltages: The voltage columns read.
        currents: The current columns read.
        layout: The declared layout (keyword arguments of :class:`~jaxobs.signals.RecordingLayout`).
        sep: The delimiter written; ``decimal`` the decimal mark.
        decimal: The decimal mark written.
    """

    name: str
    make: Callable[[dict], dict]
    voltages: tuple[str, ...] = ("u_a", "u_b")
    currents: tuple[str, ...] = ("i_a", "i_b")
    layout: dict = field(default_factory=dict)
    sep: str = ","
    decimal: str = "."

    @property
    def delay(self) -> int:
        """Rows dropped at the start: a reference's delay (0: applied voltages)."""
        return int(self.layout.get("voltage_delay", 1)) if self.layout.get("voltage_timing") == "reference" else 0


def _phases(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """α-β (amplitude-invariant) → the phases a, b, c."""
    return a, -0.5 * a + S3 / 2 * b, -0.5 * a - S3 / 2 * b


def _dq(c: dict, ua: np.ndarray, ub: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    cos, sin = np.cos(c["theta_e"]), np.sin(c["theta_e"])
    return cos * ua + sin * ub, -sin * ua + cos * ub


def _with(c: dict, **cols) -> dict:
    """The clean log with some columns replaced (or removed: None), in its order, new ones after the currents."""
    out = {k: v for k, v in c.items() if k not in cols}
    out.update({k: v for k, v in cols.items() if v is not None})
    return out


def _three_currents(c: dict) -> dict:
    ia, ib, ic = _phases(c["i_a"], c["i_b"])
    return _with(c, i_a=None, i_b=None, ia=ia, ib=ib, ic=ic)


def _two_currents(c: dict) -> dict:
    ia, ib, _ = _phases(c["i_a"], c["i_b"])
    return _with(c, i_a=None, i_b=None, ia=ia, ib=ib)


def _three_voltages(c: dict) -> dict:
    ua, ub, uc = _phases(c["u_a"], c["u_b"])
    zero = 0.1 * np.cos(3 * c["theta_e"]) * np.max(np.abs(ua))  # a third-harmonic injection: no part of u_αβ
    return _with(c, u_a=None, u_b=None, ua=ua + zero, ub=ub + zero, uc=uc + zero)


def _two_voltages(c: dict) -> dict:
    ua, ub, _ = _phases(c["u_a"], c["u_b"])
    return _with(c, u_a=None, u_b=None, ua=ua, ub=ub)


def _dq_applied(c: dict) -> dict:
    ud, uq = _dq(c, c["u_a"], c["u_b"])
    return _with(c, u_a=None, u_b=None, ud=ud, uq=uq)


def _reference(c: dict, delay: int) -> dict:
    """Row k holds the reference computed at t_k, applied ``delay`` periods later (the last rows' never are)."""
    return _with(c, u_a=np.roll(c["u_a"], -delay), u_b=np.roll(c["u_b"], -delay))


def _dq_reference(c: dict) -> dict:
    r = _reference(c, 1)
    ud, uq = _dq(c, r["u_a"], r["u_b"])  # turned by the angle at t_k, the one the controller used
    return _with(c, u_a=None, u_b=None, ud=ud, uq=uq)


def _units(c: dict) -> dict:
    return _with(c, u_a=c["u_a"] / 1e3, u_b=c["u_b"] / 1e3, i_a=c["i_a"] * 1e3, i_b=c["i_b"] * 1e3)


def _degrees(c: dict) -> dict:
    return _with(c, theta_e=np.degrees(np.mod(c["theta_e"], 2 * math.pi)))


def _mechanical(c: dict) -> dict:
    th_m = np.mod(np.unwrap(c["theta_e"]) / P, 2 * math.pi)
    return _with(c, theta_e=np.degrees(th_m), omega_e=c["omega_e"] / P * 60 / (2 * math.pi))


def _power(c: dict) -> dict:
    k = math.sqrt(1.5)  # the power-invariant Clarke transform: √(3/2) times the amplitude-invariant one
    return _with(c, u_a=k * c["u_a"], u_b=k * c["u_b"], i_a=k * c["i_a"], i_b=k * c["i_b"])


def _ms(c: dict) -> dict:
    return _with(c, t=c["t"] * 1e3)


def _same(c: dict) -> dict:
    return dict(c)


I3, I2, V3, V2, DQ = ("ia", "ib", "ic"), ("ia", "ib"), ("ua", "ub", "uc"), ("ua", "ub"), ("ud", "uq")
LAYOUTS: tuple[Layout, ...] = (
    Layout("α-β currents and voltages (rewritten)", _same),
    Layout("three phase currents", _three_currents, currents=I3, layout=dict(current_frame="abc")),
    Layout("two phase currents (c = −a − b)", _two_currents, currents=I2, layout=dict(current_frame="abc")),
    Layout("three phase voltages (3rd harmonic)", _three_voltages, voltages=V3, layout=dict(voltage_frame="abc")),
    Layout(
        "two phase voltages, zero sequence none",
        _two_voltages,
        voltages=V2,
        layout=dict(voltage_frame="abc", voltage_zero_sequence="none"),
    ),
    Layout("d-q voltages, turned by the angle", _dq_applied, voltages=DQ, layout=dict(voltage_frame="dq")),
    Layout("α-β power-invariant", _power, layout=dict(alpha_beta_scaling="power")),
    Layout("kV and mA", _units, layout=dict(voltage_unit="kV", current_unit="mA")),
    Layout("angle in degrees", _degrees, layout=dict(angle_unit="deg")),
    Layout(
        "mechanical degrees, r/min",
        _mechanical,
        layout=dict(
            angle_unit="deg", angle_kind="mechanical", speed_unit="r/min", speed_kind="mechanical", pole_pairs=P
        ),
    ),
    Layout("time in ms", _ms, layout=dict(time_unit="ms")),
    Layout("';' and decimal ','", _same, layout=dict(delimiter=";", decimal=","), sep=";", decimal=","),
    Layout("tab-separated", _same, layout=dict(delimiter="tab"), sep="\t"),
    Layout("α-β references, delay 1", lambda c: _reference(c, 1), layout=dict(voltage_timing="reference")),
    Layout(
        "α-β references, delay 2",
        lambda c: _reference(c, 2),
        layout=dict(voltage_timing="reference", voltage_delay=2),
    ),
    Layout(
        "d-q references + phase currents, delay 1",
        lambda c: _two_currents(_dq_reference(c)),
        voltages=DQ,
        currents=I2,
        layout=dict(voltage_frame="dq", voltage_timing="reference", current_frame="abc"),
    ),
)


def clean_columns(rows: int | None = None) -> dict:
    """The clean log's columns (the shipped file's, its first ``rows`` rows).

    Args:
        rows: How many rows (None: all 3000).

    Returns:
        Name → values, by :data:`NAMES`.
    """
    data = np.loadtxt(CLEAN, delimiter=",", comments="#", skiprows=2)
    return {k: v[:rows] for k, v in zip(NAMES, data.T)}


def write(path: Path, cols: dict, sep: str = ",", decimal: str = ".") -> Path:
    """The columns as a CSV with a header row, every digit of float64.

    Args:
        path: The file.
        cols: Name → values.
        sep: The delimiter.
        decimal: The decimal mark.

    Returns:
        ``path``.
    """
    rows = np.column_stack(list(cols.values()))
    lines = [sep.join(cols)]
    lines += [sep.join(format(float(x), ".17g").replace(".", decimal) for x in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def read(path: Path, lay: Layout):
    """The log read as its layout declares (:func:`jaxobs.signals.read_drive_log`).

    Args:
        path: The file.
        lay: Its layout.

    Returns:
        The :class:`~jaxobs.signals.LogData`.
    """
    from jaxobs.signals import RecordingLayout, read_drive_log

    return read_drive_log(
        path,
        voltages=list(lay.voltages),
        currents=list(lay.currents),
        time_column="t",
        omega_e="omega_e",
        layout=RecordingLayout(**lay.layout),
    )


def scorer(t1: float) -> Callable:
    """The scoring function of a recording, compiled once per recording shape: the second-order SOIFO (paper 000's
    gains, its Rs and L) bound to the recorded speed at the first sample, run open loop to ``t1``, and
    :data:`METRICS`.

    Args:
        t1: The horizon's end, s, from the recording's first row (its own t = 0).

    Returns:
        ``score(recording) -> {metric: value}``.
    """
    import equinox as eqx

    import jaxobs
    from jaxobs import drive as D
    from jaxobs import papers
    from jaxobs.metrics import METRICS as TABLE
    from jaxobs.metrics import MetricContext

    par = D.spmsm_paper000()
    k1, k2 = papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2
    obs = jaxobs.SecondOrderSOIFO(par.Rs, par.Ld, k1, k2, k1**3 / (2 * k2), 2 * math.pi * 50)
    ctx = MetricContext(t_event=T_EVENT, steady_from=STEADY_FROM)

    @eqx.filter_jit
    def run(rec):
        sys_ = jaxobs.OnSignal(obs.bind(None, rec.omega_e[0]), rec)
        sol = jaxobs.simulate(sys_, t1)
        return {m: TABLE[m](sol, rec, ctx) for m in METRICS}

    def score(rec) -> dict:
        return {k: float(v) for k, v in run(rec).items()}

    return score


def rel_diff(a: dict, b: dict) -> float:
    """The largest relative difference of two score sets."""
    return max(abs(a[m] - b[m]) / abs(b[m]) for m in METRICS)


def measure(rows: int | None = None, layouts: tuple[Layout, ...] = LAYOUTS, folder: Path | None = None) -> dict:
    """Each layout's scores beside the clean file's.

    Args:
        rows: The clean log's first rows taken (None: all).
        layouts: The layouts.
        folder: Where the files are written (None: a temporary folder).

    Returns:
        ``{"clean": scores, "rows": [{"layout", "scores", "rel_diff", "delay", "rel_diff_same_row"}]}``.
    """
    c = clean_columns(rows)
    n = c["t"].size
    ts = float(c["t"][1] - c["t"][0])
    # one horizon for every run, from its first row: the rows the longest delay leaves (n − 2 samples)
    score = scorer((n - max(lay.delay for lay in LAYOUTS)) * ts)
    with tempfile.TemporaryDirectory() as tmp:
        where = Path(tmp) if folder is None else folder
        base = read(write(where / "clean.csv", c), LAYOUTS[0])
        clean = score(base.recording())
        from_row = {}
        out = []
        for lay in layouts:
            got = score(read(write(where / "log.csv", lay.make(c), lay.sep, lay.decimal), lay).recording())
            row = {"layout": lay.name, "scores": got, "rel_diff": rel_diff(got, clean), "delay": lay.delay}
            if lay.delay:
                if lay.delay not in from_row:
                    from_row[lay.delay] = score(base.recording(lay.delay))
                row["rel_diff_same_row"] = rel_diff(got, from_row[lay.delay])
            out.append(row)
    return {"clean": clean, "rows": out}


def _rel(x: float) -> str:
    # below 1e-9 a difference is float64 rounding through the run: shown as a bound, machine-independent
    return "< 1e-9" if x < 1e-9 else f"{x:.2g}"


def table(res: dict) -> str:
    """The printed table.

    Args:
        res: :func:`measure`'s result.

    Returns:
        The text.
    """
    head = ["layout", "iae_position", "rms_pos_steady", "rms_speed_steady", "peak_speed", "rel. diff", "same row"]
    rows = [["clean α-β file", *(f"{res['clean'][m]:.6g}" for m in METRICS), "", ""]]
    for r in res["rows"]:
        same = _rel(r["rel_diff_same_row"]) if r["delay"] else ""
        rows.append([r["layout"], *(f"{r['scores'][m]:.6g}" for m in METRICS), _rel(r["rel_diff"]), same])
    w = [max(len(x[i]) for x in [head, *rows]) for i in range(len(head))]
    lines = ["  ".join(x.ljust(w[i]) if i == 0 else x.rjust(w[i]) for i, x in enumerate(r)).rstrip() for r in rows]
    sep = "  ".join("-" * k for k in w)
    return "\n".join(["  ".join(x.ljust(w[i]) if i == 0 else x.rjust(w[i]) for i, x in enumerate(head)), sep, *lines])


def main(argv: list[str] | None = None) -> int:
    """The command line (module doc).

    Args:
        argv: The arguments (default ``sys.argv[1:]``).

    Returns:
        The exit status.
    """
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.log_layouts", description="every layout a drive log is read in, scored alike"
    )
    ap.add_argument("--rows", type=int, default=None, help="the clean log's first rows only (default all 3000)")
    ap.add_argument("--json", type=Path, default=None, help="also write the results here")
    args = ap.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    t = time.perf_counter()
    res = measure(args.rows)
    print(table(res))
    if args.json is not None:
        res["seconds"] = time.perf_counter() - t
        args.json.write_text(json.dumps(res, indent=1, ensure_ascii=False) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
