"""``jaxobs drive check DRIVE.toml``: a drive file checked in full, and what follows from it.

It prints the machine's speeds (base speed, the highest speed at u_dc with and without field weakening), its
characteristic current and time constants, a saturation map's (``[machine.saturation]``) no-load flux, its Ld and
Lq at no load and at the rated current's MTPA point (which it prints) and the constants the controller assumes, the
controller's bandwidths and gains as derived (each with its
rule, ``*`` where the file set it), the sensors' and the I-f start-up's values, the lowest speed at which
each observer family closes the speed loop, and the warnings.  A bad file: one line naming the key, exit 2
(the command line's ``ValueError``).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence

from jaxobs.drive import read_drive

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
    ("limits and policy", ("i_max", "id_policy", "field_weakening", "fw_margin")),
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


def cmd_drive_check(args: argparse.Namespace) -> int:
    """``jaxobs drive check``: print a drive file's derived values (module doc); 0, or a ``ValueError``.

    Args:
        args: The parsed command line.

    Returns:
        0.

    Raises:
        ValueError: Bad input (one line, exit 2).
    """
    f = read_drive(args.file)
    print(f"drive file {args.file}: {f.name}, valid")
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
    for w in f.warnings:
        print(f"warning: {w}")
    return 0


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
        description="Validate a drive file and print its derived values.",
        parents=list(parents),
    )
    c.add_argument("file", help="a drive file (TOML)")
    c.set_defaults(func=cmd_drive_check)
    return d
