"""A drive file's saturation map, ``[machine.saturation]``: the map, and ``[machine]``'s omitted Ld, Lq and psi_f
filled from it (:mod:`jaxobs.drive.drivefile`, :mod:`jaxobs.drive.saturation`)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ._filekeys import DRIVE_FILE_KEYS, PSI_F_KEYS, key_value, show
from .saturation import NOMINAL_RULES, AlgebraicSaturation, FluxTable, check_inverse, map_summary, saturation_from_table

__all__ = ["machine_map"]

_S2 = math.sqrt(2.0)
# the flux map's inversion residual allowed, relative to the current: 1000 roundings of the working precision
_INV_TOL = 1e3 * float(np.finfo(np.float32).eps)


def machine_map(
    raw: dict[str, Any], base: str | Path | None = None
) -> tuple[dict[str, Any], AlgebraicSaturation | FluxTable | None, dict[str, tuple[Any, ...]]]:
    """A file's ``[machine.saturation]`` (:func:`jaxobs.drive.saturation.saturation_from_table`): the tables without
    it, with ``[machine]``'s missing Ld, Lq, psi_f filled from the map by its ``nominal`` rule, the map (or None),
    and what the check prints of it (name -> (value, unit, rule, given)).

    ``nominal`` (the constants the controller and the observers assume): "rated_secant" (default; the secant
    inductances (ψd − ψf)/i_d, ψq/i_q at the rated current's MTPA point on the map, which give the map's flux, so
    its torque and voltage, at that point), "rated_incremental" (∂ψd/∂i_d, ∂ψq/∂i_q there: the current loop's
    plant), "no_load" (the incremental ones at i = 0); ψf is the map's no-load flux in each.

    Args:
        raw: The parsed file.
        base: The folder a map's CSV name is relative to (None: the working one).

    Returns:
        ``(the tables without the map, the map or None, name -> (value, unit, rule, given))``.

    Raises:
        ValueError: One line naming the key.
    """
    mt = raw.get("machine")
    if not isinstance(mt, dict) or "saturation" not in mt:
        return raw, None, {}
    if "dual" in raw:
        raise ValueError("machine.saturation: a dual drive ([dual]) has no saturation map; remove it")
    tbl = mt["saturation"]
    sat = saturation_from_table(tbl, base)
    nominal = tbl.get("nominal", "rated_secant")
    if nominal not in NOMINAL_RULES:
        raise ValueError(f"machine.saturation.nominal must be one of {', '.join(map(repr, NOMINAL_RULES))}, got "
                         f"{show(nominal)}")  # fmt: skip
    mt = {k: v for k, v in mt.items() if k != "saturation"}
    keys = DRIVE_FILE_KEYS["machine"]
    for k in ("p", "rated_current_a"):
        if k not in mt:
            raise ValueError(f"machine.{k}: missing (required)")
        mt[k] = key_value(mt, "machine", k, keys[k])
    i_rated = _S2 * mt["rated_current_a"]
    summ = map_summary(sat, mt["p"], i_rated)
    bad_inverse = False
    if isinstance(sat, AlgebraicSaturation) and sat.state_is_flux:  # the plant inverts the map
        bad_inverse = check_inverse(sat, 3.0 * i_rated) > _INV_TOL
    if not all(math.isfinite(v) for v in summ.values()) or bad_inverse:
        raise ValueError(
            "machine.saturation: the map's flux cannot be found from the current up to 3 × the rated current "
            "(Newton's method did not converge): check the coefficients' units (A, Vs)"
        )
    pick = {"rated_secant": ("Ld_sec", "Lq_sec"), "rated_incremental": ("Ld_inc", "Lq_inc"),
            "no_load": ("Ld0", "Lq0")}[nominal]  # fmt: skip
    fill = {"Ld": summ[pick[0]], "Lq": summ[pick[1]], "psi_f": summ["psi_f"]}
    given = {"Ld": "Ld" in mt, "Lq": "Lq" in mt, "psi_f": any(k in mt for k in PSI_F_KEYS)}  # ψf or Ke/Kt
    missing = [k for k in fill if not given[k]]
    if not missing and "nominal" in tbl:
        raise ValueError("machine.saturation.nominal: machine.Ld, Lq and psi_f are all given; remove nominal or them")
    for k in missing:
        mt[k] = fill[k]
    rule = f"from the map ({nominal})"
    out = {
        "sat_psi_f": (summ["psi_f"], "Wb", "the map's ψd at i = 0"),
        "sat_Ld0": (summ["Ld0"], "H", "∂ψd/∂i_d at i = 0"),
        "sat_Lq0": (summ["Lq0"], "H", "∂ψq/∂i_q at i = 0"),
        "sat_mtpa_id": (summ["mtpa_id"], "A", "the map's MTPA at √2 rated_current_a: i_d"),
        "sat_mtpa_iq": (summ["mtpa_iq"], "A", "the map's MTPA at √2 rated_current_a: i_q"),
        "sat_mtpa_torque": (summ["mtpa_torque"], "N·m", "the map's torque there, 1.5 p (ψd i_q − ψq i_d)"),
        "sat_Ld_rated": (summ["Ld_inc"], "H", "∂ψd/∂i_d at the rated MTPA point"),
        "sat_Lq_rated": (summ["Lq_inc"], "H", "∂ψq/∂i_q at the rated MTPA point"),
        "sat_Ldq_rated": (summ["Ldq_inc"], "H", "∂ψd/∂i_q at the rated MTPA point (cross-saturation)"),
        "sat_Ld_sec": (summ["Ld_sec"], "H", "(ψd − ψf)/i_d at the rated MTPA point"),
        "sat_Lq_sec": (summ["Lq_sec"], "H", "ψq/i_q at the rated MTPA point"),
        "nominal_L": (f"Ld {mt['Ld']:.5g} H, Lq {mt['Lq']:.5g} H, "
            + (f"psi_f {mt['psi_f']:.5g} Wb" if "psi_f" in mt else "psi_f from Ke/Kt"), "",
                      f"what the controller and observers assume: {'given' if not missing else rule}"
                      + (f" ({', '.join(missing)})" if missing and len(missing) < 3 else "")),
    }  # fmt: skip
    return {**raw, "machine": mt}, sat, {k: (*v, False) for k, v in out.items()}
