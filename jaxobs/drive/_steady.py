"""A drive file's steady-state rules: the policy's currents for a torque, the steady voltage, the base speed and
the one speed limit of a drive (:mod:`jaxobs.drive.drivefile`; plain floats, no JAX)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .machine import RPM

__all__ = [
    "MECH_SPEED_PU",
    "base_speed",
    "fw_voltage",
    "no_load_rpm",
    "policy_currents",
    "rpm_of",
    "speed_limit",
    "steady_voltage",
]

# ASSUMED: without [machine] max_speed_rpm, a drive whose voltage never bounds its speed (field weakening with
# ψf/Ld ≤ i_max) is limited to 3 × its rated speed (a common top-to-base ratio of traction and spindle drives)
MECH_SPEED_PU = 3.0


def _mtpa_id(Ld: float, Lq: float, psi_f: float, iq: float) -> float:
    """MTPA's i_d for i_q (A): ψf/(2(Lq − Ld)) − √(ψf²/(4(Lq − Ld)²) + i_q²) (:meth:`FOC._id_ref`)."""
    dl = Lq - Ld
    if abs(dl) <= 1e-12:
        return 0.0
    a = psi_f / (2 * dl)
    return a - math.copysign(1.0, dl) * math.sqrt(a * a + iq * iq)


def _torque(p: int, Ld: float, Lq: float, psi_f: float, i_d: float, i_q: float) -> float:
    return 1.5 * p * (psi_f + (Ld - Lq) * i_d) * i_q


def policy_currents(m: dict[str, Any], policy: str, torque: float) -> tuple[float, float]:
    """(i_d, i_q) of the policy that give ``torque`` (N·m) on the machine table ``m``: bisection on i_q.

    Args:
        m: The checked ``[machine]`` table (``p``, ``Ld``, ``Lq``, ``psi_f``).
        policy: The i_d policy, ``"zero"`` or ``"mtpa"``.
        torque: The torque, N·m.

    Returns:
        ``(i_d, i_q)``, A.
    """
    p, Ld, Lq, psi = m["p"], m["Ld"], m["Lq"], m["psi_f"]

    def te(iq: float) -> float:
        i_d = _mtpa_id(Ld, Lq, psi, iq) if policy == "mtpa" else 0.0
        return _torque(p, Ld, Lq, psi, i_d, iq)

    lo, hi = 0.0, torque / (1.5 * p * psi)  # the magnet alone needs the most i_q; MTPA's reluctance adds torque
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if te(mid) < torque else (lo, mid)
    iq = 0.5 * (lo + hi)
    return (_mtpa_id(Ld, Lq, psi, iq) if policy == "mtpa" else 0.0), iq


def steady_voltage(m: dict[str, Any], w_e: float, i_d: float, i_q: float) -> float:
    """|u| (V, peak) of the steady state at ω_e (rad/s) and (i_d, i_q) (A).

    Args:
        m: The checked ``[machine]`` table.
        w_e: The electrical speed, rad/s.
        i_d: The d current, A.
        i_q: The q current, A.

    Returns:
        |u|, V.
    """
    u_d = m["Rs"] * i_d - w_e * m["Lq"] * i_q
    u_q = m["Rs"] * i_q + w_e * (m["Ld"] * i_d + m["psi_f"])
    return math.hypot(u_d, u_q)


def fw_voltage(m: dict[str, Any], w_e: float, torque: float, i_max: float, id_top: float) -> float:
    """The least |u| (V) at ω_e that carries ``torque`` within the current circle i_max with i_d ≤ ``id_top``
    (field weakening: a more negative i_d, down to where the FOC stops it, max(−i_max, −ψf/Ld):
    :func:`jaxobs.drive.weakening.id_stop`); inf where no i_d does.

    Args:
        m: The checked ``[machine]`` table.
        w_e: The electrical speed, rad/s.
        torque: The torque, N·m.
        i_max: The current limit, A.
        id_top: The largest i_d tried, A.

    Returns:
        The least |u|, V (inf where none).
    """
    p, Ld, Lq, psi = m["p"], m["Ld"], m["Lq"], m["psi_f"]
    best = math.inf
    for i_d in np.linspace(id_top, max(-i_max, min(-psi / Ld, id_top)), 4001):  # to the FOC's stop (weakening)
        k = 1.5 * p * (psi + (Ld - Lq) * i_d)
        if k <= 0:
            continue
        i_q = torque / k
        if i_d * i_d + i_q * i_q <= i_max * i_max * (1 + 1e-12):
            best = min(best, steady_voltage(m, w_e, float(i_d), i_q))
    return best


def base_speed(
    m: dict[str, Any], i_d: float, i_q: float, u_max: float, flux: tuple[float, float] | None = None
) -> float:
    """ω_e (rad/s) at which the steady |u| at (i_d, i_q) reaches u_max: the root of a quadratic in ω_e.

    Args:
        m: The checked ``[machine]`` table.
        i_d: The d current, A.
        i_q: The q current, A.
        u_max: The voltage limit, V.
        flux: (ψd, ψq) at (i_d, i_q), Vs: a saturation map's (:func:`jaxobs.drive.weakening.map_flux_at`); None:
            the constants', (ψf + Ld i_d, Lq i_q).

    Returns:
        ω_e, rad/s (0 where |u| already exceeds u_max at standstill).
    """
    a, b = (m["Lq"] * i_q, m["Ld"] * i_d + m["psi_f"]) if flux is None else (flux[1], flux[0])
    rs = m["Rs"]
    qa = a * a + b * b
    qb = 2 * rs * (-i_d * a + i_q * b)
    qc = rs * rs * (i_d * i_d + i_q * i_q) - u_max * u_max
    disc = qb * qb - 4 * qa * qc
    if qc >= 0 or disc < 0:
        return 0.0
    return (-qb + math.sqrt(disc)) / (2 * qa)


def rpm_of(w_e: float, p: int) -> float:
    """The mechanical speed of an electrical one.

    Args:
        w_e: The electrical speed, rad/s.
        p: The pole pairs.

    Returns:
        The speed, r/min.
    """
    return w_e / p / RPM


def no_load_rpm(u_max: float, flux: float, p: int) -> float:
    """The speed (r/min) where ωe · ``flux`` = u_max (inf for flux ≤ 0), in the one order of operations every
    speed limit uses (the envelope's default speeds are 0.98 × it: the same bits everywhere).

    Args:
        u_max: The voltage limit, V.
        flux: The flux linkage the speed turns into voltage, Wb.
        p: The pole pairs.

    Returns:
        The speed, r/min.
    """
    return math.inf if flux <= 0.0 else u_max / flux / float(p) * 60.0 / (2 * math.pi)


def speed_limit(
    p: int,
    psi_f: float,
    Ld: float,
    i_max: float,
    u_max: float,
    weakening: bool,
    rated_speed_rpm: float,
    max_speed_rpm: float | None = None,
    flux: float | None = None,
) -> tuple[float, str]:
    """The one speed limit of a drive (r/min, either direction) and its rule, which ``jaxobs drive check``
    prints and ``tune``, ``study`` and ``envelope`` use.

    The voltage's no-load bound: ωe ψf = u_max without field weakening (the FOC cannot hold even zero current
    above it); ωe (ψf − Ld i_max) = u_max with it (i_d stops at max(−i_max, −ψf/Ld): unbounded where
    Ld i_max ≥ ψf); on a saturation map the map's flux there, ``flux`` (:func:`jaxobs.drive.weakening.map_speed_flux`:
    |ψ(i_d,lo, 0)|; the constants' line overstated the PM-SyRM of ``docs/examples/pmsyrm_5p6kw_sat.toml`` by 29 %,
    19131 against 14869 r/min).  Then the mechanical limit: ``max_speed_rpm`` (``[machine] max_speed_rpm``) where
    given, else :data:`MECH_SPEED_PU` × the rated speed where the voltage leaves the speed unbounded.

    Args:
        p: The pole pairs.
        psi_f: ψf, Wb.
        Ld: The d inductance, H.
        i_max: The current limit, A.
        u_max: The voltage limit, V.
        weakening: Whether the FOC weakens the field.
        rated_speed_rpm: The rated speed, r/min.
        max_speed_rpm: The mechanical limit, r/min, or None.
        flux: A saturation map's flux at the no-load stop, Vs (None: the constants').

    Returns:
        ``(limit, rule)``.
    """
    if flux is None:
        flux = psi_f - Ld * i_max if weakening else psi_f
        why = "no-load ωe (ψf − Ld i_max) = u_max" if weakening else "no-load ωe ψf = u_max"
    else:
        at = "i_d = max(−i_max, −ψf/Ld)" if weakening else "i = 0"
        why = f"no-load ωe |ψ| = u_max, the map's flux at {at}"
    n_v = no_load_rpm(u_max, flux, p)
    if max_speed_rpm is not None:
        return min(n_v, float(max_speed_rpm)), f"min({why}, machine.max_speed_rpm)"
    if math.isinf(n_v):
        return MECH_SPEED_PU * float(rated_speed_rpm), (
            f"{MECH_SPEED_PU:g} × rated_speed_rpm (ASSUMED; machine.max_speed_rpm sets it): {why} is unbounded "
            "(ψf/Ld ≤ i_max)"
        )
    return n_v, why + (" (field weakening)" if weakening else " (no field weakening)")
