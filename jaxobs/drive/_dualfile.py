"""A dual three-phase drive file: ``[dual]`` beside a drive file's other tables (:mod:`jaxobs.drive.drivefile`).

A file with a ``[dual]`` table declares a dual three-phase PMSM (two star-connected sets 30° apart, isolated
neutrals, :mod:`jaxobs.drive.dual`) driven by :class:`~jaxobs.drive.DualFOC`::

    [dual]
    Lls = 0.0015           # H, the xy-subspace inductance (the stator leakage), required
    mode = "vsd"           # current control: "vsd" (αβ + xy PIs) or "individual" (one FOC per set)
    fw_voltage = "ab"      # the voltage the field weakening budgets under "vsd": "ab" or "set" (DualFOC)

Its ``[machine]`` table is then the αβ subspace in amplitude-invariant VSD variables: per-phase ``Rs``, the VSD
inductances ``Ld`` and ``Lq``, ``psi_f`` (peak phase flux), the rated current per phase, and the *whole*
machine's ``J``, ``B`` and rated torque (:class:`~jaxobs.drive.DualPMSMParams`).  Every value the drive file
derives (current limit, voltages, base and top speed, loop gains, start-up, lowest speeds) is derived on one set
carrying half the rotor (:meth:`~jaxobs.drive.DualPMSMParams.per_set`): with both sets carrying the same current
its equations are the dual machine's, per set, and the observers and the speed loop are designed on it
(:attr:`DriveFile.machine` is that set; :attr:`DriveFile.dual` the whole machine).

What the dual loop does not model is refused, one line each: a DSP timing other than the default (the dual loop
samples at the period's start and applies one period later, :attr:`~jaxobs.drive.DualDrive.latency`) and the
q-axis saturation (the dual plant's inductances are constant).

The xy (differential) current loop.  Under "vsd" the xy PIs (k_p = α_c L̂ls, k_i = α_c R̂s) cross over at α_c, as
the αβ loop does.  Under "individual" each set's FOC is designed on its self inductances (L̂ + L̂ls)/2
(:meth:`~jaxobs.drive.DualFOC.imc`), which the differential mode sees as Lls: it crosses over at
r α_c, r = (L̂ + L̂ls)/(2 L̂ls) with L̂ the larger of L̂d and L̂q, and keeps 90° − r α_c n T_s of phase margin.  A
file that leaves ``current_bandwidth_hz`` to the derivation gets α_c lowered by r (the differential loop then
keeps the single file's 60°); a given bandwidth whose differential margin is under 30° is refused, under 45° warned.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, Protocol

import equinox as eqx
import jax

from .dual import DualPMSMParams
from .dual_loop import DualDrive, DualFOC
from .latency import Latency
from .loop import Drive
from .machine import PMSMParams
from .weakening import VoltageFeedbackFW


class SetFile(Protocol):
    """One set's drive file, as :func:`dual_drive_file` reads it: a :class:`~jaxobs.drive.DriveFile` (defined
    above this module, which it imports)."""

    @property
    def machine(self) -> PMSMParams:
        """The set's machine (half the rotor)."""
        ...

    @property
    def drive(self) -> Drive | DualDrive:
        """The sensorless drive derived on it."""
        ...

    @property
    def foc_kw(self) -> Mapping[str, Any]:
        """:meth:`FOC.imc`'s keywords as derived."""
        ...

    @property
    def derived(self) -> Mapping[str, Any]:
        """Name -> derived value (``.value``, ``.unit``)."""
        ...

    @property
    def ts(self) -> float:
        """The control and PWM period, s."""
        ...


def dual_foc_kw(foc_kw: Mapping[str, Any], drop: tuple[str, ...] = ("alpha_c", "alpha_s")) -> dict[str, Any]:
    """The single set's :meth:`FOC.imc` keywords as :meth:`DualFOC.imc` takes them: without ``drop``, and without the
    single drive's current-limit features (``d_priority``, ``flux_map``, the bounded field weakening, the references'
    margin and the error limit of :mod:`jaxobs.drive._reflimit`), which
    the dual loops (``jaxobs.drive.dual_loop``) do not run: a ``[dual]`` file builds 002's dual bench unchanged.

    Args:
        foc_kw: The single set's keywords.
        drop: The keywords to leave out besides.

    Returns:
        The keywords.
    """
    single_only = ("d_priority", "flux_map", "current_margin", "error_limit")
    kw = {k: v for k, v in foc_kw.items() if k not in (*drop, *single_only)}
    fw = kw.get("field_weakening")
    if isinstance(fw, VoltageFeedbackFW) and fw.bounded:
        kw["field_weakening"] = VoltageFeedbackFW(float(fw.alpha_fw), float(fw.margin), float(fw.omega_min))
    return kw


def halved(raw: dict) -> dict:
    """The file's tables with ``[dual]`` removed and ``[machine]`` as one set carrying half the rotor.

    Half of ``J``, ``B`` and the rated torque; the single-machine derivation then checks and derives on it.

    Args:
        raw: The file's tables, name -> table (``[machine]`` among them).

    Returns:
        The tables without ``[dual]``, ``[machine]`` halved (a new dict; ``raw`` is not changed).
    """
    m = dict(raw["machine"])
    for k in ("J", "B", "rated_torque_nm"):
        if k in m and isinstance(m[k], (int, float)) and not isinstance(m[k], bool):
            m[k] = m[k] / 2
    return {**{k: v for k, v in raw.items() if k != "dual"}, "machine": m}


def individual_ratio(machine: PMSMParams, lls: jax.Array | float) -> float:
    """r = (L̂ + L̂ls)/(2 L̂ls), L̂ the larger of ``machine``'s Ld and Lq.

    How much faster than α_c the differential current loop of "individual" control runs (module doc).

    Args:
        machine: One set's machine (its assumed Ld and Lq).
        lls: L̂ls, the xy (leakage) inductance, H.

    Returns:
        r.
    """
    big = max(float(machine.Ld), float(machine.Lq))
    return (big + float(lls)) / (2.0 * float(lls))


def lowered_bandwidth(half: dict, single: SetFile, dual_table: dict, pm_design: float) -> dict | None:
    """``half`` with a lower current bandwidth where "individual" control needs one (module doc).

    Args:
        half: The tables of :func:`halved`.
        single: The drive file derived on ``half``.
        dual_table: ``[dual]``.
        pm_design: The phase margin the differential loop should keep, deg.

    Returns:
        ``half`` with ``control.current_bandwidth_hz`` set to the derived α_c / r where "individual" control's
        differential loop would otherwise keep less than ``pm_design`` degrees, else None (also where the file
        sets ``control.current_bandwidth_hz`` itself).
    """
    if dual_table.get("mode", "vsd") != "individual" or "current_bandwidth_hz" in half.get("control", {}):
        return None
    r = individual_ratio(single.machine, dual_table["Lls"])
    alpha_c = float(single.foc_kw["alpha_c"])
    n, ts = float(single.derived["use_delay"].value), single.ts
    if r <= 1.0 or 90.0 - math.degrees(r * alpha_c * n * ts) >= pm_design:
        return None
    return {**half, "control": {**half.get("control", {}), "current_bandwidth_hz": alpha_c / r / (2 * math.pi)}}


def dual_drive_file(
    single: SetFile,
    raw: dict,
    dual_table: dict,
    *,
    lowered: bool = False,
    pm: tuple[float, float] = (30.0, 45.0),
) -> tuple[DualPMSMParams, DualDrive, dict[str, tuple[float | str, str, str, bool]], tuple[str, ...]]:
    """The dual machine and drive on the per-set derivation ``single`` (the drive file of :func:`halved`).

    Args:
        single: The :class:`~jaxobs.drive.DriveFile` of one set carrying half the rotor.
        raw: The file's own tables.
        dual_table: ``[dual]``, its keys checked.
        lowered: ``single``'s α_c was lowered for "individual" control (:func:`lowered_bandwidth`).
        pm: The least phase margin of the differential loop (refused below), and the one warned below, deg.

    Returns:
        ``(dual, drive, derived, warnings)``: the whole :class:`~jaxobs.drive.DualPMSMParams`, the sensorless
        :class:`~jaxobs.drive.DualDrive`, the derived values, name -> ``(value, unit, rule, given)``, that the
        dual file adds or replaces, and its warnings (one line each).

    Raises:
        ValueError: one line naming the key the dual loop cannot run.
    """
    inv = raw.get("inverter", {})
    if single.drive.latency != Latency():
        key = "compute_delay" if "compute_delay" in inv and inv["compute_delay"] != 1 else "sampling"
        raise ValueError(
            f"inverter.{key}: a dual drive ([dual]) runs the default timing (sampling 'start', compute_delay 1), "
            f"got {inv.get(key)!r}"
        )
    if inv.get("pwm", "averaged") != "averaged" or inv.get("device_drop_v", 0.0) != 0.0:
        key = "pwm" if inv.get("pwm", "averaged") != "averaged" else "device_drop_v"
        raise ValueError(f"inverter.{key}: a dual drive ([dual]) runs the averaged inverter without device drops")
    if single.machine.q_sat is not None:
        raise ValueError("machine.q_sat_current_a: a dual drive ([dual]) has no q-axis saturation model; remove it")
    per_set = single.machine
    whole = eqx.tree_at(lambda q: (q.J, q.B, q.T_rated), per_set, (2 * per_set.J, 2 * per_set.B, 2 * per_set.T_rated))
    dual = DualPMSMParams(whole, dual_table["Lls"])
    mode = dual_table.get("mode", "vsd")
    fw_voltage = dual_table.get("fw_voltage", "ab")
    alpha_c = float(single.foc_kw["alpha_c"])
    n, ts = float(single.derived["use_delay"].value), single.ts
    warn = []
    derived: dict[str, tuple[float | str, str, str, bool]] = {
        "Lls": (float(dual.Lls), "H", "[dual] Lls: the xy-subspace inductance", True)
    }
    mode_rule = "[dual] mode: 'vsd' (αβ + xy PIs) or 'individual' (a FOC per set)"
    derived["dual_mode"] = (mode, "", mode_rule, "mode" in dual_table)
    if float(dual.Lls) >= min(float(per_set.Ld), float(per_set.Lq)):
        warn.append(
            f"dual.Lls: {float(dual.Lls):.4g} H is not below Ld and Lq ({float(per_set.Ld):.4g}, "
            f"{float(per_set.Lq):.4g} H): the xy inductance is the stator's leakage, usually a small fraction of them"
        )
    if mode == "vsd":
        fw_rule = "[dual] fw_voltage: the voltage the field weakening budgets (DualFOC)"
        derived["fw_voltage"] = (fw_voltage, "", fw_rule, "fw_voltage" in dual_table)
        pm_xy = 90.0 - math.degrees(alpha_c * n * ts)
        xy_rule = "the xy PIs cross over at α_c: 90° − α_c n T_s"
    else:
        if "fw_voltage" in dual_table:
            warn.append("dual.fw_voltage: ignored under mode = 'individual' (each set's FOC limits its own voltage)")
        r = individual_ratio(per_set, dual.Lls)
        pm_xy = 90.0 - math.degrees(r * alpha_c * n * ts)
        xy_rule = f"the differential loop crosses over at r α_c, r = (L̂ + L̂ls)/(2 L̂ls) = {r:.3g}: 90° − r α_c n T_s"
        if pm_xy < pm[0]:
            a_max = math.radians(90.0 - pm[0]) / (r * n * ts)
            raise ValueError(
                f"dual.mode: 'individual' runs the differential current loop at {r:.3g} α_c, a phase margin of "
                f"{pm_xy:.0f}° (at least {pm[0]:g}°): lower control.current_bandwidth_hz to <= "
                f"{a_max / (2 * math.pi):.4g} Hz or use mode = 'vsd'"
            )
        if pm_xy < pm[1]:
            warn.append(
                f"dual.mode: 'individual''s differential current loop keeps {pm_xy:.0f}° of phase margin "
                f"(< {pm[1]:g}°): it rings"
            )
        if lowered:
            rule = f"IMC at the single rule's α_c / r (r = {r:.3g}): the differential loop keeps its phase margin"
            derived["alpha_c"] = (alpha_c, "rad/s", rule, False)
    derived["xy_phase_margin"] = (pm_xy, "deg", xy_rule, False)
    kw = dual_foc_kw(single.foc_kw)
    ctrl = DualFOC.imc(dual, alpha_c, single.foc_kw["alpha_s"], mode=mode, fw_voltage=fw_voltage, **kw)
    d = single.drive
    drive = DualDrive(ctrl, d.inverter, sensorless=True, handover=0.0, n_sub=d.n_sub, rule=d.rule)
    if mode == "individual":  # each set's current loops on its self inductances (L + Lls)/2 (DualFOC.imc)
        for g in ("kp_d", "ki_d", "kp_q", "ki_q"):
            old = single.derived[g]
            derived[g] = (float(getattr(ctrl.foc, g)), old.unit, "IMC on one set's self inductances (L̂ + L̂ls)/2", False)
    else:
        derived["kp_xy"] = (float(ctrl.kp_xy), "V/A", "IMC: α_c L̂ls (the xy PIs)", False)
        derived["ki_xy"] = (float(ctrl.ki_xy), "V/(A·s)", "IMC: α_c R̂s (the xy PIs)", False)
    return dual, drive, derived, tuple(warn)
