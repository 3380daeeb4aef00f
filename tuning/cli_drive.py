"""``jaxobs drive check DRIVE.toml``: a drive file checked in full, and what follows from it.

It prints the machine's speeds (base speed, the highest speed at u_dc with and without field weakening), its
characteristic current and time constants, a saturation map's (``[machine.saturation]``) no-load flux, its Ld and
Lq at no load and at the rated current's MTPA point (which it prints) and the constants the controller assumes, the
controller's bandwidths and gains as derived (each with its
rule, ``*`` where the file set it), the sensors' and the I-f start-up's values, the lowest speed at which
each observer family closes the speed loop, the torque–speed capability curve (the steady maximum torque from
standstill to the speed limit, :meth:`jaxobs.drive.DriveFile.capability`; ``--figure PATH`` draws it), and the
warnings.  A bad file: one line naming the key, exit 2 (the command line's ``ValueError``).

``--simulate`` runs the derived controller sensored at the rated point and at the top speed the check claims,
loaded at 95 % of the capability there (:mod:`jaxobs.analysis.drive_points`), and reports whether each is held.
It is a flag, not the default: the plain check must answer within 2 s (a check run at every edit of the file),
and it is the file's arithmetic: it compiles no XLA program and imports none of the tuning commands (most of its
time is importing JAX; ``tests/test_cli.py`` guards both), while the runs compile and run a closed loop, tens of
seconds on a laptop's CPU.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence

import numpy as np

from jaxobs.drive import DriveFile, read_drive
from jaxobs.drive.weakening import mtpv_iq_np

from .cli_common import enable_x64

_SECTIONS = (
    ("machine", ("psi_f", "kt", "i_char", "tau_d", "tau_q", "t_accel", "i_rated_point")),
    (
        "saturation map ([machine.saturation]; inductances incremental unless marked secant)",
        (
            "nominal_L",
            "sat_psi_f",
            "sat_Ld0",
            "sat_Lq0",
            "sat_mtpa_id",
            "sat_mtpa_iq",
            "sat_mtpa_torque",
            "sat_Ld_rated",
            "sat_Lq_rated",
            "sat_Ldq_rated",
            "sat_Ld_sec",
            "sat_Lq_sec",
        ),
    ),
    (
        "speeds",
        (
            "u_max",
            "u_rated_point",
            "u_rated_point_fw",
            "base_speed_rpm",
            "emf_speed_rpm",
            "max_speed_fw_rpm",
            "speed_limit_rpm",
        ),
    ),
    ("timing", ("ts", "use_delay", "advance", "speed_every")),
    ("current loop", ("alpha_c", "alpha_c_ts", "current_phase_margin", "kp_d", "ki_d", "kp_q", "ki_q")),
    ("speed loop", ("alpha_s", "omega_est", "speed_schedule", "kp_w", "ki_w")),
    ("limits and policy", ("i_max", "i_ref_max", "error_limit", "id_policy", "field_weakening", "fw_margin")),
    ("sensors", ("adc_lsb", "i_noise", "encoder_angle_step", "encoder_speed_step")),
    ("I-f start-up", ("if_current", "if_switch_rpm", "if_ramp_s")),
)


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "on" if v else "off"
    if isinstance(v, str):
        return v
    if isinstance(v, int):
        return str(v)
    return "inf" if math.isinf(v) else f"{v:.5g}"


_NEAR = 1e-3  # a limit binds where its use is within 0.1 % of it


def _table_speeds(f: DriveFile) -> np.ndarray:
    """The table's speeds, r/min: standstill, the rated and base speeds, 1.5 × base, quarters of the speed limit."""
    top = f.speed_limit_rpm
    base = float(f.derived["base_speed_rpm"].value)
    pts = [0.0, float(f.machine.n_rated), base, 1.5 * base, *(top * np.array([0.25, 0.5, 0.75, 1.0]))]
    pts = np.unique(np.round([v for v in pts if 0.0 <= v <= top * (1 + 1e-9)], 6))
    return pts[np.concatenate([[True], np.diff(pts) > 1e-3 * top])]  # near-equal speeds once


def _capability(f: DriveFile) -> list[str]:
    """Print the capability table; the warnings it finds."""
    d = f.derived
    i_max, u_max, m_fw = (float(d[k].value) for k in ("i_max", "u_max", "fw_margin"))
    i_ref = float(d.get("i_ref_max", d["i_max"]).value)  # the references' circle: where the current limit binds
    n = _table_speeds(f)
    c = f.capability(n)
    near = _NEAR if f.machine.sat is None else 1e-2  # a map's grid binds within about 1 %
    flux = "the saturation map's flux" if f.machine.sat is not None else "constant inductances Ld, Lq, psi_f"
    fw = (
        "field weakening on"
        if d["field_weakening"].value
        else f"field weakening off: the {d['id_policy'].value} i_d policy"
    )
    lim = f"i_ref_max = {i_ref:.5g} A" if i_ref < i_max else f"i_max = {i_max:.5g} A"
    print(f"capability (steady maximum torque; |i| <= {lim}, |u| <= fw_margin × u_dc/√3 = "
          f"{m_fw * u_max:.5g} V; {flux}; {fw}):")  # fmt: skip
    print(f"  {'speed':>9} {'torque':>9} {'power':>8} {'i_d':>8} {'i_q':>8} {'|i|/i_max':>9} {'|u|/u_max':>9}  limit")
    print(f"  {'r/min':>9} {'N·m':>9} {'kW':>8} {'A':>8} {'A':>8}")
    m = f.machine
    # field weakening's own stop at −ψf/Ld (where it lies inside the circle), and the MTPV line it respects on an
    # inverse-salient machine (jaxobs.drive.weakening): limits of the reference, named where they bind
    weak = bool(d["field_weakening"].value)
    stop = -float(m.psi_f) / float(m.Ld) if weak and float(m.psi_f) / float(m.Ld) < i_ref else None
    mtpv = mtpv_iq_np(m, c["i_d"]) if weak else np.full(len(n), np.inf)
    for k in range(len(n)):
        te, i_d, i_q, u = (float(c[key][k]) for key in ("torque", "i_d", "i_q", "u"))
        if not np.isfinite(te):
            print(f"  {n[k]:>9.5g} {'none':>9}  no current within the limits fits the voltage")
            continue
        i_r = float(np.hypot(i_d, i_q)) / i_max
        on_circle = i_r * i_max / i_ref >= 1 - near
        binds = [w for w, on in (("current", on_circle), ("voltage", u / u_max >= m_fw * (1 - near)),
                                 ("i_d_stop", stop is not None and i_d <= stop * (1 - near)),
                                 ("MTPV", i_q >= mtpv[k] * (1 - near))) if on]  # fmt: skip
        power = te * n[k] * 2 * np.pi / 60 / 1e3
        print(f"  {n[k]:>9.5g} {te:>9.4g} {power:>8.3g} {i_d:>8.4g} {i_q:>8.4g} {i_r:>9.3f} {u / u_max:>9.3f}  "
              f"{'+'.join(binds) or '-'}")  # fmt: skip
    if stop is not None or np.isfinite(mtpv).any():
        print("  (i_d_stop: i_d at −psi_f/Ld, where field weakening stops; MTPV: on the maximum-torque-per-volt line)")
    warns = []
    none = n[~np.isfinite(c["torque"])]
    # at a speed limit the voltage sets (no-load, at u_dc/√3) no torque fits fw_margin of u_dc/√3: that is the
    # margin, not a fault; a speed below fw_margin × the limit without torque is (a map, or a claimed max speed)
    if none.size and none.min() < m_fw * f.speed_limit_rpm * (1 - 1e-9):
        warns.append(
            f"speed_limit_rpm: no steady current within the limits fits fw_margin × u_dc/√3 at {none.min():.5g} r/min"
            f" and above ({flux}): lower machine.max_speed_rpm or raise inverter.u_dc"
        )
    fw_hint = "" if d["field_weakening"].value else ", or set control.field_weakening = true"
    t_r = float(f.capability([float(f.machine.n_rated)])["torque"][0])
    if not t_r >= float(f.machine.T_rated) * (1 - 1e-9):
        warns.append(
            f"machine.rated_torque_nm: the capability at the rated speed is {t_r:.4g} N·m, below the rated "
            f"{float(f.machine.T_rated):.4g} N·m (raise inverter.u_dc or control.i_max_a{fw_hint}, or lower the "
            "rating)"
        )
    return warns


def _figure(f: DriveFile, path: str) -> None:
    """Draw the capability curve (torque and power over speed, the rated point marked) to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = np.linspace(0.0, f.speed_limit_rpm, 241)
    c = f.capability(n)
    fig, ax = plt.subplots(figsize=(7.0, 4.2), layout="constrained")
    ax.plot(n, c["torque"], color="C0", label="max torque")
    ax.plot([float(f.machine.n_rated)], [float(f.machine.T_rated)], "o", color="C3", label="rated point")
    ax.axvline(float(f.derived["base_speed_rpm"].value), color="0.6", ls=":", lw=1, label="base speed (rated torque)")
    ax.set_xlabel("speed (r/min)")
    ax.set_ylabel("torque (N·m)", color="C0")
    ax.set_xlim(0.0, f.speed_limit_rpm)
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)
    ax2 = ax.twinx()
    ax2.plot(n, c["torque"] * n * 2 * np.pi / 60 / 1e3, color="C1", ls="--", label="power")
    ax2.set_ylabel("power (kW)", color="C1")
    ax2.set_ylim(bottom=0.0)
    lines = ax.get_legend_handles_labels()[0] + ax2.get_legend_handles_labels()[0]
    ax.legend(lines, [str(h.get_label()) for h in lines], loc="center right", fontsize=8)
    model = "saturation map" if f.machine.sat is not None else "constant inductances"
    ax.set_title(f"{f.name}: steady capability (|i| ≤ i_max, |u| ≤ fw_margin·u_dc/√3; {model})", fontsize=9)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _simulate(f: DriveFile) -> list[str]:
    """Run the rated and top points sensored (:mod:`jaxobs.analysis.drive_points`); print them; the warnings."""
    from jaxobs.analysis.drive_points import HOLD_TOL, TOP_MARGIN, horizon, point_verdict, run_points

    res = run_points(f)
    print(f"operating points, sensored (the FOC on the true angle), each from its steady state for {horizon(f):.3g} s "
          f"(one jit(vmap) batch); held: mean speed of the last quarter within {HOLD_TOL:.0%}:")  # fmt: skip
    warns = []
    for r in res:
        if r.name == "rated":
            what = "rated torque"
        else:
            what = f"{TOP_MARGIN:.0%} of the capability" if r.load_nm > 0 else "no load: the capability has none"
        verdict, warn = point_verdict(r)
        print(f"  {r.name:<5} {r.speed_rpm:>8.5g} r/min {r.load_nm:>8.4g} N·m ({what}): mean {r.mean_rpm:.5g} r/min "
              f"({(r.mean_rpm - r.speed_rpm) / r.speed_rpm:+.2%}), max |i|/i_max {r.i_ratio:.3f}, max |u|/u_max "
              f"{r.u_ratio:.3f}: {verdict}")  # fmt: skip
        if warn is not None:
            warns.append(warn)
    return warns


def cmd_drive_check(args: argparse.Namespace) -> int:
    """``jaxobs drive check``: print a drive file's derived values (module doc); 0, or a ``ValueError``.

    Args:
        args: The parsed command line.

    Returns:
        0.

    Raises:
        ValueError: Bad input (one line, exit 2).
    """
    if args.simulate:
        enable_x64()  # the runs in float64, as every command that simulates (before any array is made)
    f = read_drive(args.file)
    _derived(f, args.file)
    warns = [*f.warnings, *_capability(f)]
    if args.figure:
        _figure(f, args.figure)
        print(f"capability figure: {args.figure}")
    if args.simulate:
        warns += _simulate(f)
    for w in warns:
        print(f"warning: {w}")
    if not args.simulate:
        print("operating points not simulated: --simulate runs the rated point and the top speed sensored")
    return 0


def _derived(f: DriveFile, file: str) -> None:
    """Print the file's derived values, section by section, and the observers' lowest speeds."""
    print(f"drive file {file}: {f.name}, valid")
    if f.dual is not None:
        print(
            "dual three-phase machine ([dual]): every value below is one set's, carrying half of J, B and the "
            "rated torque"
        )
    seen = set()
    for title, keys in _SECTIONS:
        rows = [(k, f.derived[k]) for k in keys if k in f.derived]
        if not rows:
            continue
        print(f"{title}:")
        for k, r in rows:
            seen.add(k)
            hz = (
                f" ({r.value / (2 * math.pi):.4g} Hz)"
                if r.unit == "rad/s" and k.startswith(("alpha", "omega")) and isinstance(r.value, (int, float))
                else ""
            )
            mark = "*" if r.given else " "
            print(f"  {mark}{k:<20} {_fmt(r.value):>12} {r.unit:<10}{hz}  {r.rule}")
    rest = [k for k in f.derived if k not in seen]
    if rest:
        print("other:")
        for k in rest:
            r = f.derived[k]
            print(f"  {'*' if r.given else ' '}{k:<20} {_fmt(r.value):>12} {r.unit:<10}  {r.rule}")
    print("lowest speed at which each observer family closes the speed loop:")
    for fam, (rpm, rule) in f.lowest_speeds.items():
        print(f"  {fam:<50} {'none' if rpm is None else f'{rpm:.4g} r/min':>14}  {rule}")
    print("(* set by the file; the rest derived)")


def add_drive_parser(
    subparsers: argparse._SubParsersAction, parents: Sequence[argparse.ArgumentParser] = ()
) -> argparse.ArgumentParser:
    """Add ``jaxobs drive check`` to the CLI's subparsers.

    Args:
        subparsers: The CLI's subparsers.
        parents: The parsers of the options every command shares.

    Returns:
        The ``drive`` parser.
    """
    d = subparsers.add_parser(
        "drive",
        help="drive files: check one and print what follows from it",
        description="Drive files: check one and print what follows from it.",
    )
    sub = d.add_subparsers(dest="drive_cmd", metavar="ACTION", required=True, parser_class=type(d))
    c = sub.add_parser(
        "check",
        help="validate a drive file and print its derived values",
        description="Validate a drive file and print its derived values and its torque-speed capability. The "
        "plain check is the file's arithmetic (no closed loop compiled or run: it answers within about 2 s); "
        "--simulate also runs the rated point and the top speed in closed loop, sensored (one compiled batch: tens "
        "of seconds).",
        parents=list(parents),
    )
    c.add_argument("file", help="a drive file (TOML)")
    c.add_argument("--figure", metavar="PATH", help="draw the torque–speed capability curve to PATH (PNG, PDF, SVG)")
    c.add_argument(
        "--simulate",
        action="store_true",
        help="also run the rated point and the top speed sensored in closed loop (one compiled batch: tens of "
        "seconds; off by default so that the plain check answers at once)",
    )
    c.set_defaults(func=cmd_drive_check)
    return d
