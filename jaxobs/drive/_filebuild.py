"""A drive file's derivation, one table (or one concern) at a time: the machine, the timing, the current limit, the
voltage and field weakening, the current and speed loops, the controller, the inverter, the sensors and the I-f
start-up (:func:`jaxobs.drive.drivefile.drive_from_table` runs them in this order; module doc there)."""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from .. import papers
from ._filekeys import PSI_F_KEYS
from ._reflimit import ERROR_LIMIT_PU, reference_margin
from ._steady import base_speed, fw_voltage, no_load_rpm, policy_currents, rpm_of, speed_limit, steady_voltage
from .control import FOC, IfStartup
from .hardware import Inverter, Sensors
from .latency import Latency, PeriodStart, PWMCentre
from .loop import SETTLE_PERIODS
from .machine import RPM, PMSMParams, QSaturation, psi_f_from_ke, psi_f_from_kt
from .saturation import AlgebraicSaturation, FluxTable
from .weakening import FW_MARGIN, VoltageFeedbackFW, map_flux_at, map_speed_flux

__all__ = [
    "ALPHA_C_TS_MAX",
    "Derived",
    "Record",
    "PM_DESIGN_DEG",
    "PM_MIN_DEG",
    "PM_WARN_DEG",
    "base_speed_table",
    "controller",
    "current_limit",
    "current_loop",
    "inverter_table",
    "lowest_speeds",
    "machine_quantities",
    "machine_table",
    "sensors_table",
    "speed_loop",
    "startup_table",
    "timing",
]

PM_DESIGN_DEG = 60.0  # the current loop's phase margin a derived α_c gives
PM_MIN_DEG = 30.0  # the least phase margin a given α_c may leave (below: refused)
PM_WARN_DEG = 45.0  # below it: a warning
ALPHA_C_TS_MAX = 2 * math.pi / 10  # α_c T_s at most this (α_c ≤ a tenth of the sampling frequency, rad/s)
SPEED_DECADE = 10.0  # α_s ≤ α_c / 10 by default
SPEED_CASCADE_MIN = 4.0  # α_s ≤ α_c / 4 or refused
ESTIMATE_RATIO = 3.0  # α_s ≤ ω_est / 3 (ASSUMED: the benches' 5 Hz loop through a 15 Hz PLL)
FLL_RATIO = 4.3  # a speed estimate scaling with ω_e closes the loop from ω_e ≥ 4.3 α_s (docs/stability.md)
OVERLOAD = 1.5  # i_max = 1.5 × rated (peak), FOC.imc's default
SPEED_LOOP_HZ = 1000.0  # the default speed-loop rate (000's DSP)
IF_CURRENT_MIN_PU = 0.01  # the I-f current at least 1 % of i_max (tiny values are refused, not divided by)

_S2, _S3 = math.sqrt(2.0), math.sqrt(3.0)


class Derived(NamedTuple):
    """One value that follows from a drive file.

    Attributes:
        value: The value, in ``unit``.
        unit: Its unit.
        rule: How it follows, and its source.
        given: True: the file set it.
    """

    value: float | str
    unit: str
    rule: str
    given: bool = False


class Record:
    """What a drive file's check finds besides what it builds: the derived values, in order, and the warnings."""

    def __init__(self) -> None:
        self.derived: dict[str, Derived] = {}
        self.warnings: list[str] = []

    def __call__(self, key: str, value: Any, unit: str, rule: str, given: bool = False) -> Any:
        """Record one derived value.

        Args:
            key: Its name.
            value: The value, in ``unit``.
            unit: Its unit.
            rule: How it follows, and its source.
            given: True: the file set it.

        Returns:
            ``value``.
        """
        self.derived[key] = Derived(value, unit, rule, given)
        return value


def machine_table(
    m: dict[str, Any], sat: AlgebraicSaturation | FluxTable | None, rec: Record
) -> tuple[dict[str, Any], PMSMParams]:
    """The machine of ``[machine]``: ψf from a datasheet constant where given so, the q-axis saturation or map.

    Args:
        m: The checked ``[machine]`` table.
        sat: The saturation map, or None.
        rec: The record the derived values and warnings go to.

    Returns:
        ``(the table with psi_f, the PMSMParams)``.

    Raises:
        ValueError: One line naming the key and its allowed range.
    """
    p = m["p"]
    given_flux = [k for k in PSI_F_KEYS if k in m]
    if len(given_flux) != 1:
        what = "missing" if not given_flux else f"give one, got {', '.join(given_flux)}"
        raise ValueError(f"machine.psi_f: {what} (the magnet flux: one of {', '.join(PSI_F_KEYS)})")
    if "psi_f" not in m:  # a datasheet's back-EMF or torque constant, converted (the rule printed)
        key = given_flux[0]
        if key == "kt_nm_per_a_rms":
            psi_f, rule = psi_f_from_kt(m[key], p)
        else:
            psi_f, rule = psi_f_from_ke(m[key], p, line_peak=key.endswith("peak"))
        if not (1e-6 <= psi_f <= 100.0):
            raise ValueError(f"machine.{key}: gives psi_f = {psi_f:.4g} Wb, outside [1e-06, 100] Wb, got {m[key]:g}")
        m = {**m, "psi_f": psi_f}
        rec("psi_f", psi_f, "Wb", f"machine.{key}: {rule}", True)
    if "q_sat_n" in m and "q_sat_current_a" not in m:
        raise ValueError("machine.q_sat_n: needs machine.q_sat_current_a (the saturation's current)")
    q_sat = QSaturation(m["q_sat_current_a"], m.get("q_sat_n", 2.0)) if "q_sat_current_a" in m else None
    if q_sat is not None and sat is not None:
        raise ValueError("machine.q_sat_current_a: give either it (q-axis only) or [machine.saturation], not both")
    machine = PMSMParams(
        m["Rs"], m["Ld"], m["Lq"], m["psi_f"], m["J"], p, B=m.get("B", 0.0), a5=m.get("a5", 0.0),
        a7=m.get("a7", 0.0), T_rated=m["rated_torque_nm"], n_rated=m["rated_speed_rpm"], q_sat=q_sat, sat=sat,
    )  # fmt: skip
    return m, machine


def timing(inv: dict[str, Any], w_rated: float, rec: Record) -> tuple[float, float, str, Latency, float]:
    """The DSP timing of ``[inverter]``: the period, the sampling and the use delay.

    Args:
        inv: The checked ``[inverter]`` table.
        w_rated: The rated electrical speed, rad/s.
        rec: The record the derived values and warnings go to.

    Returns:
        ``(f_s, ts, sampling, latency, use delay in periods)``.
    """
    f_s = inv["f_sample_hz"]
    ts = 1.0 / f_s
    sampling = inv.get("sampling", "start")
    latency = Latency(PeriodStart() if sampling == "start" else PWMCentre(), inv.get("compute_delay", 1))
    n_use = latency.use_delay
    rec("ts", ts, "s", "1 / inverter.f_sample_hz", True)
    rec("use_delay", n_use, "periods", "from the sample to the centre of the PWM period it drives (Latency)")
    if f_s < 10 * w_rated / (2 * math.pi):
        rec.warnings.append(
            f"inverter.f_sample_hz: {f_s / (w_rated / (2 * math.pi)):.3g} samples per electrical period at the "
            "rated speed (fewer than 10: the discrete current loop and observers lose accuracy)"
        )
    return f_s, ts, sampling, latency, n_use


def machine_quantities(m: dict[str, Any], inv: dict[str, Any], kt: float, rec: Record) -> float:
    """The machine's own quantities: u_max, the time constants, K_t, the characteristic current, t_accel.

    Args:
        m: The checked ``[machine]`` table.
        inv: The checked ``[inverter]`` table.
        kt: The magnet torque per ampere, N·m/A.
        rec: The record the derived values and warnings go to.

    Returns:
        u_max, V.
    """
    u_max = inv["u_dc"] / _S3
    rec("u_max", u_max, "V", "u_dc/√3, the linear range of space-vector modulation (Inverter)")
    for ax in ("d", "q"):
        L = m[f"L{ax}"]
        rec(f"tau_{ax}", L / m["Rs"] if m["Rs"] > 0 else math.inf, "s", f"L{ax}/Rs, electrical time constant")
    rec("kt", kt, "N·m/A", "1.5 p ψf, the magnet torque per ampere (peak) at i_d = 0")
    rec("i_char", m["psi_f"] / m["Ld"], "A", "ψf/Ld, characteristic current (peak): field weakening's limit")
    rec(
        "t_accel",
        m["J"] * m["rated_speed_rpm"] * RPM / m["rated_torque_nm"],
        "s",
        "J ω_rated / T_rated: rated torque to rated speed, no load",
    )
    return u_max


def current_limit(m: dict[str, Any], ctl: dict[str, Any], rec: Record) -> tuple[float, str, float, float]:
    """The current limit and the i_d policy, and the rated point's currents under it.

    Args:
        m: The checked ``[machine]`` table.
        ctl: The checked ``[control]`` table.
        rec: The record the derived values and warnings go to.

    Returns:
        ``(i_max, policy, i_d, i_q of the rated point)``.

    Raises:
        ValueError: One line naming the key and its allowed range.
    """
    if "i_max_a" in ctl:
        if "overload" in ctl:
            raise ValueError("control.overload: give either control.overload or control.i_max_a, not both")
        i_max = rec("i_max", ctl["i_max_a"], "A", "control.i_max_a", True)
    else:
        ov = ctl.get("overload", OVERLOAD)
        i_max = rec("i_max", ov * _S2 * m["rated_current_a"], "A", f"{ov:g} × √2 × rated_current_a", "overload" in ctl)
    saliency = m["Lq"] > m["Ld"] * (1 + 1e-9)
    policy = ctl.get("id_policy", "mtpa" if saliency else "zero")
    rec("id_policy", policy, "", "MTPA where Lq > Ld (reluctance torque), else zero", "id_policy" in ctl)
    i_d_r, i_q_r = policy_currents(m, policy, m["rated_torque_nm"])
    i_r = math.hypot(i_d_r, i_q_r)
    rec("i_rated_point", i_r, "A", f"|i| of rated torque under the {policy} policy (peak)")
    if i_r > i_max * (1 + 1e-9):
        raise ValueError(
            f"machine.rated_torque_nm: needs |i| = {i_r:.4g} A peak under the {policy} policy, above the current "
            f"limit i_max = {i_max:.4g} A (raise control.overload / i_max_a or rated_current_a); must be <= "
            f"{m['rated_torque_nm'] * i_max / i_r:.4g} N·m"
        )
    if i_r > 1.1 * _S2 * m["rated_current_a"]:
        rec.warnings.append(
            f"machine.rated_current_a: the rated torque needs {i_r / _S2:.4g} A rms under the {policy} policy, more "
            f"than 1.1 × the rated {m['rated_current_a']:g} A (check psi_f or the rating)"
        )
    return i_max, policy, i_d_r, i_q_r


def base_speed_table(
    m: dict[str, Any],
    inv: dict[str, Any],
    ctl: dict[str, Any],
    w_rated: float,
    u_max: float,
    i_max: float,
    rated: tuple[float, float],
    rec: Record,
    machine: PMSMParams | None = None,
) -> tuple[bool, float]:
    """The voltage: the rated point's, the base speed, the speed range and the field weakening.

    On a saturation map (``machine.sat``) the base speed, the no-load bound with field weakening and the speed
    limit take the map's flux (the rated torque's currents, the FOC's no-load stop); the rated point's voltage and
    field weakening's default stay the constants' (what the controller assumes).

    Args:
        m: The checked ``[machine]`` table.
        inv: The checked ``[inverter]`` table.
        ctl: The checked ``[control]`` table.
        w_rated: The rated electrical speed, rad/s.
        u_max: The voltage limit, V.
        i_max: The current limit, A.
        rated: The rated point's ``(i_d, i_q)``, A.
        rec: The record the derived values and warnings go to.
        machine: The machine (its map, where it has one); None: the constants alone.

    Returns:
        ``(field weakening on, its margin)``.

    Raises:
        ValueError: One line naming the key and its allowed range.
    """
    p = m["p"]
    i_d_r, i_q_r = rated
    u_rated = steady_voltage(m, w_rated, i_d_r, i_q_r)
    rec("u_rated_point", u_rated, "V", "steady |u| at rated torque and speed")
    on_map = machine is not None and machine.sat is not None
    flux_r = map_flux_at(machine, i_d_r, i_q_r) if machine is not None else None
    on_map_rule = " (the map's flux at its currents)" if on_map else ""
    rec("base_speed_rpm", rpm_of(base_speed(m, i_d_r, i_q_r, u_max, flux_r), p), "r/min",
        "the speed where rated torque's |u| reaches u_max" + on_map_rule)  # fmt: skip
    n_emf = rec("emf_speed_rpm", no_load_rpm(u_max, m["psi_f"], p), "r/min",
                "no-load speed where ωe ψf = u_max (no weakening)")  # fmt: skip
    fw_flux = map_speed_flux(machine, i_max, True) if machine is not None else None
    rec("max_speed_fw_rpm", no_load_rpm(u_max, m["psi_f"] - m["Ld"] * i_max if fw_flux is None else fw_flux, p),
        "r/min", "no-load ωe (ψf − Ld i_max) = u_max (inf: i_char ≤ i_max, unbounded by the voltage)" if not on_map
        else "no-load ωe |ψ| = u_max, the map's flux at i_d = max(−i_max, −ψf/Ld)")  # fmt: skip
    fw_needed = u_rated > u_max
    margin = rec("fw_margin", ctl.get("fw_margin", FW_MARGIN), "1",
                 "5 % of u_max left to the current PIs (jaxobs.drive.weakening)", "fw_margin" in ctl)  # fmt: skip
    fw_default = u_rated > margin * u_max or m.get("max_speed_rpm", 0.0) > n_emf
    fw = ctl.get("field_weakening", fw_default)
    rec("field_weakening", fw, "", "on when the rated point needs |u| > fw_margin × u_dc/√3, or machine.max_speed_rpm "
        "lies above emf_speed_rpm (where the back EMF alone reaches u_max)", "field_weakening" in ctl)  # fmt: skip
    limit, limit_rule = speed_limit(p, m["psi_f"], m["Ld"], i_max, u_max, fw, m["rated_speed_rpm"],
                                    m.get("max_speed_rpm"), fw_flux if fw else map_speed_flux(machine, i_max, False)
                                    if machine is not None else None)  # fmt: skip
    rec("speed_limit_rpm", limit, "r/min", limit_rule, "max_speed_rpm" in m)
    if fw_needed:
        id_top = min(i_d_r, 0.0)
        u_fw = fw_voltage(m, w_rated, m["rated_torque_nm"], i_max, id_top) if fw else math.inf
        if not fw or u_fw > u_max:
            need = u_rated if not fw else u_fw
            how = "with field weakening within i_max" if fw else "without field weakening (control.field_weakening)"
            raise ValueError(
                f"inverter.u_dc: must be >= {_S3 * need:.4g} V for the rated point ({m['rated_torque_nm']:g} N·m at "
                f"{m['rated_speed_rpm']:g} r/min {how}), got {inv['u_dc']:g}"
            )
        rec("u_rated_point_fw", u_fw, "V", "least |u| at the rated point with i_d ≤ the policy's, |i| ≤ i_max")
    elif u_rated > margin * u_max and not fw:
        rec.warnings.append(
            f"inverter.u_dc: the rated point needs {u_rated / u_max:.1%} of u_dc/√3 (less than {1 - margin:.0%} left "
            "for the current loop to regulate; control.field_weakening = true would hold it at fw_margin)"
        )
    return fw, margin


def current_loop(m: dict[str, Any], ctl: dict[str, Any], f_s: float, ts: float, n_use: float, rec: Record) -> float:
    """The current loop's bandwidth α_c (IMC) and its phase margin.

    Args:
        m: The checked ``[machine]`` table.
        ctl: The checked ``[control]`` table.
        f_s: The sampling frequency, Hz.
        ts: The period, s.
        n_use: The use delay, periods.
        rec: The record the derived values and warnings go to.

    Returns:
        α_c, rad/s.

    Raises:
        ValueError: One line naming the key and its allowed range.
    """
    pm_of = lambda a: 90.0 - math.degrees(a * n_use * ts)  # noqa: E731 - the phase margin of IMC with the delay
    a_cap = min(math.radians(90.0 - PM_DESIGN_DEG) / (n_use * ts), ALPHA_C_TS_MAX / ts) if n_use > 0 else (
        ALPHA_C_TS_MAX / ts)  # fmt: skip
    if "current_bandwidth_hz" in ctl:
        alpha_c = 2 * math.pi * ctl["current_bandwidth_hz"]
        a_lim = min(math.radians(90.0 - PM_MIN_DEG) / (n_use * ts) if n_use > 0 else math.inf, ALPHA_C_TS_MAX / ts)
        if alpha_c > a_lim * (1 + 1e-12):
            raise ValueError(
                f"control.current_bandwidth_hz: must be <= {a_lim / (2 * math.pi):.4g} Hz at f_sample_hz = {f_s:g} "
                f"(phase margin >= {PM_MIN_DEG:g}° with {n_use:g} periods of delay, α_c T_s <= {ALPHA_C_TS_MAX:.3g}), "
                f"got {ctl['current_bandwidth_hz']:g}"
            )
    else:
        alpha_c = a_cap
    if "current_bandwidth_hz" in ctl:
        rec("alpha_c", alpha_c, "rad/s", "2π·current_bandwidth_hz (IMC, Harnefors & Nee 1998)", True)
    else:
        rec("alpha_c", alpha_c, "rad/s", f"IMC: (π/6)/(n T_s), phase margin {PM_DESIGN_DEG:g}° (Harnefors & Nee 1998)")
    rec("current_phase_margin", pm_of(alpha_c), "deg", "90° − α_c n T_s (loop gain α_c e^(−s n T_s)/s)")
    rec("alpha_c_ts", alpha_c * ts, "rad", "α_c T_s")
    if pm_of(alpha_c) < PM_WARN_DEG:
        rec.warnings.append(
            f"control.current_bandwidth_hz: α_c·ts = {alpha_c * ts:.3g} leaves a phase margin of "
            f"{pm_of(alpha_c):.0f}° (< {PM_WARN_DEG:g}°): the current loop rings"
        )
    tau_max = max(m["Ld"], m["Lq"]) / m["Rs"] if m["Rs"] > 0 else math.inf
    if alpha_c * tau_max < 1.0:
        rec.warnings.append(
            f"control.current_bandwidth_hz: α_c = {alpha_c:.4g} rad/s is below the machine's own 1/τ = "
            f"{1 / tau_max:.4g} rad/s: the current loop is slower than the open machine"
        )
    return alpha_c


def speed_loop(
    ctl: dict[str, Any], f_s: float, ts: float, alpha_c: float, rec: Record
) -> tuple[float, float, float, int, float]:
    """The speed loop: the estimate's bandwidth, its period, α_s and the schedule.

    Args:
        ctl: The checked ``[control]`` table.
        f_s: The sampling frequency, Hz.
        ts: The period, s.
        alpha_c: The current loop's bandwidth, rad/s.
        rec: The record the derived values and warnings go to.

    Returns:
        ``(α_s, schedule N, ω_est, speed_every, the speed loop's period)``.

    Raises:
        ValueError: One line naming the key and its allowed range.
    """
    w_est = 2 * math.pi * ctl.get("speed_estimate_hz", papers.LESO_PLL_HZ)
    rec("omega_est", w_est, "rad/s", "2π·speed_estimate_hz (default the LESOs' PLL, papers.LESO_PLL_HZ)",
        "speed_estimate_hz" in ctl)  # fmt: skip
    speed_every = ctl.get("speed_every", max(1, round(f_s / SPEED_LOOP_HZ)))
    rec("speed_every", speed_every, "periods", "round(f_s / 1 kHz): the speed loop at 1 kHz", "speed_every" in ctl)
    t_w = speed_every * ts
    if "speed_bandwidth_hz" in ctl:
        alpha_s = 2 * math.pi * ctl["speed_bandwidth_hz"]
        if alpha_s > alpha_c / SPEED_CASCADE_MIN * (1 + 1e-12):
            raise ValueError(
                f"control.speed_bandwidth_hz: must be <= {alpha_c / SPEED_CASCADE_MIN / (2 * math.pi):.4g} Hz, a "
                f"quarter of the current loop's {alpha_c / (2 * math.pi):.4g} Hz (a cascade), got "
                f"{ctl['speed_bandwidth_hz']:g}"
            )
        if alpha_s * t_w > 0.5:
            raise ValueError(
                f"control.speed_bandwidth_hz: must be <= {0.5 / t_w / (2 * math.pi):.4g} Hz at a speed-loop period "
                f"of {t_w:g} s (α_s T <= 0.5), got {ctl['speed_bandwidth_hz']:g}"
            )
        if alpha_s > alpha_c / SPEED_DECADE * (1 + 1e-12):
            rec.warnings.append(
                f"control.speed_bandwidth_hz: α_s = α_c/{alpha_c / alpha_s:.3g}, less than a decade below the "
                "current loop: the two loops interact"
            )
        if alpha_s > w_est / ESTIMATE_RATIO * (1 + 1e-12):
            rec.warnings.append(
                f"control.speed_bandwidth_hz: above a third of the speed estimate's {w_est / (2 * math.pi):.3g} Hz "
                "(speed_estimate_hz): a sensorless speed loop through it rings"
            )
    else:
        alpha_s = min(alpha_c / SPEED_DECADE, w_est / ESTIMATE_RATIO, 0.1 / t_w)
    rec("alpha_s", alpha_s, "rad/s", "min(α_c/10, ω_est/3, 0.1/T_speed): a decade below the current loop "
        "(Harnefors et al. 2013), a third of the speed estimate's bandwidth", "speed_bandwidth_hz" in ctl)  # fmt: skip
    schedule = ctl.get("speed_schedule", 0.0)
    if 0.0 < schedule < 1.0:
        raise ValueError(f"control.speed_schedule: must be 0 (off) or in [1, 1000], got {schedule:g}")
    rec("speed_schedule", schedule, "1", "0: off; N: the speed loop at min(α_s, |ωe*|/N) (docs/stability.md)",
        "speed_schedule" in ctl)  # fmt: skip
    return alpha_s, schedule, w_est, speed_every, t_w


def controller(
    machine: PMSMParams,
    ctl: dict[str, Any],
    loops: dict[str, Any],
    fw: bool,
    margin: float,
    n_use: float,
    rec: Record,
) -> tuple[dict[str, Any], FOC]:
    """The FOC: :meth:`FOC.imc`'s keywords and the FOC they give, its gains recorded.

    Args:
        machine: The machine.
        ctl: The checked ``[control]`` table.
        loops: ``alpha_c``, ``alpha_s``, ``i_max``, ``ts``, ``speed_every``, ``id_mode`` and ``speed_schedule``.
        fw: Field weakening on.
        margin: Its voltage margin.
        n_use: The use delay, periods.
        rec: The record the derived values and warnings go to.

    Returns:
        ``(foc_kw, the FOC)``.
    """
    fw_obj = None
    if fw:
        fw_obj = VoltageFeedbackFW(2 * math.pi * ctl.get("fw_bandwidth_hz", 20.0), margin, bounded=True)
    advance = ctl.get("advance", n_use)
    rec("advance", advance, "periods", "the timing's use delay (Latency.use_delay)", "advance" in ctl)
    # |i| <= i_max at every sample: the PIs' error limit and the references' margin below i_max (jaxobs.drive._reflimit)
    # (control.current_margin = false: the references on i_max itself, the papers' benches)
    on = ctl.get("current_margin", True)
    margin_i = reference_margin(loops["alpha_c"] * loops["ts"], n_use, ERROR_LIMIT_PU) if on else 0.0
    e_lim = ERROR_LIMIT_PU if on else 0.0
    rec("i_ref_max", loops["i_max"] * (1.0 - margin_i), "A", f"(1 − h) i_max, h = 1.25 o E = {margin_i:.3%}: o the "
        "current loop's step overshoot with its delay, E the error limit (jaxobs.drive._reflimit; "
        "control.current_margin)", "current_margin" in ctl)  # fmt: skip
    rec("error_limit", e_lim * loops["i_max"], "A", "E i_max, E = 0.1: the current PIs' longest error (a step onto "
        "the circle becomes a ramp; jaxobs.drive._reflimit; 0: off)", "current_margin" in ctl)  # fmt: skip
    foc_kw = dict(
        alpha_c=loops["alpha_c"],
        alpha_s=loops["alpha_s"],
        i_max=loops["i_max"],
        ts=loops["ts"],
        speed_every=loops["speed_every"],
        id_mode=loops["id_mode"],
        advance=advance,
        field_weakening=fw_obj,
        setpoint_weight=ctl.get("setpoint_weight", 0.0),
        speed_schedule=loops["speed_schedule"],
        d_priority=fw,
        flux_map=machine.sat is not None,
        current_margin=margin_i,
        error_limit=e_lim,
    )
    foc = FOC.imc(machine, **foc_kw)
    for g in ("kp_d", "ki_d", "kp_q", "ki_q", "kp_w", "ki_w"):
        unit = {"kp": "V/A", "ki": "V/(A·s)"}[g[:2]] if g[-1] != "w" else {"kp": "A·s/rad", "ki": "A/rad"}[g[:2]]
        rule = "IMC: α_c L̂, α_c R̂s" if g[-1] != "w" else "double pole at −α_s: 2α_s Ĵ/K_t, α_s² Ĵ/K_t"
        rec(g, float(getattr(foc, g)), unit, rule)
    return foc_kw, foc


def inverter_table(inv: dict[str, Any], f_s: float, sampling: str, rec: Record) -> Inverter:
    """The plant's inverter of ``[inverter]``: the PWM, the device drop and the voltage limit.

    Args:
        inv: The checked ``[inverter]`` table.
        f_s: The sampling frequency, Hz.
        sampling: ``"start"`` or ``"centre"``.
        rec: The record the derived values and warnings go to.

    Returns:
        The :class:`Inverter`.

    Raises:
        ValueError: One line naming the key and its allowed range.
    """
    f_pwm = inv.get("f_pwm_hz", f_s)
    pwm = inv.get("pwm", "averaged")
    if pwm == "carrier" and (f_pwm != f_s or sampling != "start"):
        raise ValueError(
            'inverter.pwm: "carrier" runs one carrier period per sample (single update, sampled at the carrier\'s '
            f'peak): it needs f_pwm_hz = f_sample_hz and sampling = "start", got {f_pwm:g} Hz and {sampling!r}'
        )
    if "pwm" in inv:  # printed where the file chooses (a file without it prints what it printed before)
        rec("pwm", pwm, "", "the plant's inverter: averaged, or carrier comparison (jaxobs.drive.pwm)", True)
    limit = inv.get("voltage_limit", "circle")
    if "voltage_limit" in inv:  # printed where the file chooses
        rule = "the circle u_dc/√3 in every direction"
        if limit == "hexagon":
            rule = (
                "the hexagon: u_dc/√3 across its edges, 2 u_dc/3 at its vertices, minimum phase error (Inverter.limit)"
            )
        rec("u_vertex", 2 * inv["u_dc"] / 3 if limit == "hexagon" else inv["u_dc"] / _S3, "V", rule, True)
    inverter = Inverter(inv["u_dc"], f_pwm, pwm=pwm, u_device=inv.get("device_drop_v", 0.0), voltage_limit=limit)
    return inverter


def sensors_table(sen: dict[str, Any], i_max: float, p: int, t_w: float, rec: Record) -> Sensors:
    """The sensors of ``[sensors]``: the ADC's quantization as noise, the encoder's steps.

    Args:
        sen: The checked ``[sensors]`` table.
        i_max: The current limit, A.
        p: The pole pairs.
        t_w: The speed loop's period, s.
        rec: The record the derived values and warnings go to.

    Returns:
        The :class:`Sensors`.

    Raises:
        ValueError: One line naming the key and its allowed range.
    """
    i_noise = sen.get("i_noise_a", 0.0)
    if ("adc_bits" in sen) != ("adc_range_a" in sen):
        missing = "adc_range_a" if "adc_bits" in sen else "adc_bits"
        raise ValueError(f"sensors.{missing}: missing (adc_bits and adc_range_a go together)")
    if "adc_bits" in sen:
        rng = sen["adc_range_a"]
        if rng < i_max:
            raise ValueError(
                f"sensors.adc_range_a: must be >= the current limit i_max = {i_max:.4g} A (the ADC would clip the "
                f"currents the controller may ask for), got {rng:g}"
            )
        lsb = 2 * rng / 2 ** sen["adc_bits"]
        rec("adc_lsb", lsb, "A", "2 adc_range_a / 2^adc_bits")
        i_noise = math.hypot(i_noise, lsb / math.sqrt(12.0))
        rec("i_noise", i_noise, "A", "√(i_noise_a² + LSB²/12): quantization as white noise (Widrow)")
    if "encoder_lines" in sen:
        edges = 4 * sen["encoder_lines"]
        rec("encoder_angle_step", math.degrees(2 * math.pi * p / edges), "deg el.", "360° p / (4 lines)")
        rec("encoder_speed_step", 60.0 / (edges * t_w), "r/min", "one edge per speed-loop period: 60/(4 lines T)")
    sensors = Sensors(
        i_offset=tuple(sen.get("i_offset_a", (0.0, 0.0))),
        u_offset=tuple(sen.get("u_offset_v", (0.0, 0.0))),
        i_gain_error=tuple(sen.get("i_gain_error", (0.0, 0.0))),
        i_noise=i_noise,
        u_noise=sen.get("u_noise_v", 0.0),
    )
    return sensors


def startup_table(
    st: dict[str, Any], m: dict[str, Any], machine: PMSMParams, i_max: float, kt: float, rec: Record
) -> IfStartup:
    """The I-f start-up of ``[startup]`` (:meth:`IfStartup.for_machine`, its keys overriding).

    Args:
        st: The checked ``[startup]`` table.
        m: The checked ``[machine]`` table.
        machine: The machine.
        i_max: The current limit, A.
        kt: The magnet torque per ampere, N·m/A.
        rec: The record the derived values and warnings go to.

    Returns:
        The :class:`IfStartup`.

    Raises:
        ValueError: One line naming the key and its allowed range.
    """
    p = m["p"]
    kw = {k2: st[k1] for k1, k2 in (("hold_s", "hold"), ("blend_s", "blend"), ("dwell_s", "dwell"),
                                      ("angle_tol_rad", "tol"), ("speed_tol", "speed_tol")) if k1 in st}  # fmt: skip
    if "switch_rpm" in st and st["switch_rpm"] >= m["rated_speed_rpm"]:
        raise ValueError(
            f"startup.switch_rpm: must be below the rated speed {m['rated_speed_rpm']:g} r/min, "
            f"got {st['switch_rpm']:g}"
        )
    if "current_a" in st and st["current_a"] > i_max:
        raise ValueError(f"startup.current_a: must be <= the current limit {i_max:.4g} A, got {st['current_a']:g}")
    # the I-f current: IF_CURRENT_PU of the rated current, the smaller of T_rated/K_t (the i_d = 0 current of
    # rated torque) and the rated peak √2 rated_current_a (an IPMSM's rated torque needs less than T_rated/K_t)
    i_rated_pk = _S2 * m["rated_current_a"]
    i_kt = m["rated_torque_nm"] / kt
    i_f = st.get("current_a", papers.IF_CURRENT_PU * (i_rated_pk if i_rated_pk < i_kt * (1 - 1e-9) else i_kt))
    # None: IfStartup.for_machine's own T_rated/K_t rule, computed as it always was (the benches' presets)
    i_f_arg = i_f if ("current_a" in st or i_rated_pk < i_kt * (1 - 1e-9)) else None
    if i_f < IF_CURRENT_MIN_PU * i_max:
        raise ValueError(
            f"startup.current_a: must be >= {IF_CURRENT_MIN_PU:g} × the current limit "
            f"({IF_CURRENT_MIN_PU * i_max:.4g} A: below it the I-f vector carries no torque to start with), got {i_f:g}"
        )
    startup = IfStartup.for_machine(machine, rpm_switch=st.get("switch_rpm"), i_f=i_f_arg, **kw)
    rec("if_current", float(startup.i_f), "A", "papers.IF_CURRENT_PU × min(T_rated/K_t, √2 rated_current_a)",
        "current_a" in st)  # fmt: skip
    rec("if_switch_rpm", float(startup.omega_switch) / p / RPM, "r/min", "papers.IF_SWITCH_PU × rated speed",
        "switch_rpm" in st)  # fmt: skip
    rec("if_ramp_s", float(np.asarray(startup.omega_switch) / np.asarray(startup.accel)), "s",
        "peak ramp torque papers.IF_ACCEL_TORQUE_PU × K_t I_f, ≥ 3 swing periods (IfStartup.for_machine)")  # fmt: skip
    return startup


def lowest_speeds(p: int, alpha_s: float, schedule: float, w_est: float) -> dict[str, tuple[float | None, str]]:
    """Observer family -> (the lowest speed, r/min, at which it closes the speed loop, or None; the rule).

    Args:
        p: The pole pairs.
        alpha_s: The speed loop's bandwidth, rad/s.
        schedule: The speed loop's schedule N (0: off).
        w_est: The speed estimate's bandwidth, rad/s.

    Returns:
        family -> ``(lowest speed or None, rule)``.
    """
    floor = max(1.0, SETTLE_PERIODS / p)  # 10 electrical periods in the steady start's 60 s settle limit
    out: dict[str, tuple[float | None, str]] = {}
    if schedule >= FLL_RATIO:
        fll = (floor, f"speed_schedule {schedule:g} ≥ {FLL_RATIO:g}: α ≤ ωe/{FLL_RATIO:g} at every speed; floor: "
               f"{SETTLE_PERIODS:g} periods within a 60 s settle")  # fmt: skip
    else:
        fll = (rpm_of(FLL_RATIO * alpha_s, p), f"ωe ≥ {FLL_RATIO:g} α_s (docs/stability.md; 5.4 α_s for a slower FLL)")
    out["FLL flux observers (SOIFO, SecondOrderSOIFO)"] = fll
    for fam, hz in (("PLL flux observers (PureIntegratorFlux, LPFFlux)", papers.FLUX_PLL_HZ),
                    ("LESOs (CLESO, GILESO, FALESO)", papers.LESO_PLL_HZ)):  # fmt: skip
        wb = 2 * math.pi * hz
        if alpha_s <= wb / ESTIMATE_RATIO * (1 + 1e-12):
            out[fam] = (
                floor,
                f"no bound from the speed loop (its {hz:g} Hz PLL ≥ 3 α_s); shown: the steady start's "
                f"floor, {SETTLE_PERIODS:g} periods within a 60 s settle",
            )
        else:
            out[fam] = (None, f"none: α_s > 1/3 of its {hz:g} Hz PLL (lower speed_bandwidth_hz)")
    return out
