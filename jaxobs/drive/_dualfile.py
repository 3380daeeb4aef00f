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
"""

from __future__ import annotations

import equinox as eqx

from .dual import DualPMSMParams
from .dual_loop import DualDrive, DualFOC
from .latency import Latency


def halved(raw: dict) -> dict:
    """The file's tables with ``[dual]`` removed and ``[machine]`` as one set carrying half the rotor (half of
    ``J``, ``B`` and the rated torque), which the single-machine derivation then checks and derives on."""
    m = dict(raw["machine"])
    for k in ("J", "B", "rated_torque_nm"):
        if k in m and isinstance(m[k], (int, float)) and not isinstance(m[k], bool):
            m[k] = m[k] / 2
    return {**{k: v for k, v in raw.items() if k != "dual"}, "machine": m}


def dual_drive_file(single, raw: dict, dual_table: dict):
    """The dual machine and drive on the per-set derivation ``single`` (the drive file of :func:`halved`).

    Args:
        single: The :class:`~jaxobs.drive.DriveFile` of one set carrying half the rotor.
        raw: The file's own tables.
        dual_table: ``[dual]``, its keys checked.

    Returns:
        ``(dual, drive, derived)``: the whole :class:`~jaxobs.drive.DualPMSMParams`, the sensorless
        :class:`~jaxobs.drive.DualDrive` and the derived values, name -> ``(value, unit, rule, given)``, that
        the dual file adds or replaces.

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
    if single.machine.q_sat is not None:
        raise ValueError("machine.q_sat_current_a: a dual drive ([dual]) has no q-axis saturation model; remove it")
    per_set = single.machine
    whole = eqx.tree_at(lambda q: (q.J, q.B, q.T_rated), per_set, (2 * per_set.J, 2 * per_set.B, 2 * per_set.T_rated))
    dual = DualPMSMParams(whole, dual_table["Lls"])
    mode = dual_table.get("mode", "vsd")
    fw_voltage = dual_table.get("fw_voltage", "ab")
    kw = {k: v for k, v in single.foc_kw.items() if k not in ("alpha_c", "alpha_s")}
    ctrl = DualFOC.imc(dual, single.foc_kw["alpha_c"], single.foc_kw["alpha_s"], mode=mode, fw_voltage=fw_voltage, **kw)
    d = single.drive
    drive = DualDrive(ctrl, d.inverter, sensorless=True, handover=0.0, n_sub=d.n_sub, rule=d.rule)
    derived = {}
    derived["Lls"] = (float(dual.Lls), "H", "[dual] Lls: the xy-subspace inductance", True)
    mode_rule = "[dual] mode: 'vsd' (αβ + xy PIs) or 'individual' (a FOC per set)"
    derived["dual_mode"] = (mode, "", mode_rule, "mode" in dual_table)
    fw_rule = "[dual] fw_voltage: the voltage the field weakening budgets (DualFOC)"
    derived["fw_voltage"] = (fw_voltage, "", fw_rule, "fw_voltage" in dual_table)
    if mode == "individual":  # each set's current loops on its self inductances (L + Lls)/2 (DualFOC.imc)
        for g in ("kp_d", "ki_d", "kp_q", "ki_q"):
            old = single.derived[g]
            derived[g] = (float(getattr(ctrl.foc, g)), old.unit, "IMC on one set's self inductances (L̂ + L̂ls)/2")
    derived["kp_xy"] = (float(ctrl.kp_xy), "V/A", "IMC: α_c L̂ls (the xy PIs, 'vsd')")
    derived["ki_xy"] = (float(ctrl.ki_xy), "V/(A·s)", "IMC: α_c R̂s (the xy PIs, 'vsd')")
    return dual, drive, derived
