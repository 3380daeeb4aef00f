"""A drive file: one TOML file that declares a PMSM drive (machine, inverter, controller, sensors, start-up), and
what follows from it.

:func:`read_drive` checks the file and builds a :class:`DriveFile`: the machine (:class:`PMSMParams`), the
:class:`Drive` (IMC current loop, I-P speed loop, inverter, DSP timing), the :class:`Sensors`, the I-f
:class:`IfStartup`, every derived value with the rule that gave it (:attr:`DriveFile.derived`) and the
warnings a drive engineer would want.  :func:`load_drive` returns the machine and the ``Drive``.  Every
refusal is one line naming the key and its allowed range (a ``ValueError``).

The file (SI units, or the unit in the key's name; ``[machine]``'s keys from ``p`` to ``rated_current_a`` and
``[inverter]``'s ``u_dc`` and ``f_sample_hz`` are required, everything else optional)::

    name = "my drive"          # optional, a label
    description = "..."        # optional, one line: what the drive is (results and messages quote it)
    [machine]
    p = 4                      # pole pairs
    Rs = 0.45                  # Ω
    Ld = 0.0028                # H
    Lq = 0.0041                # H
    psi_f = 0.11               # Wb, peak (amplitude-invariant); or exactly one of the datasheet constants:
    # ke_v_per_krpm_ll_rms = 37.6  # V per 1000 r/min, line to line, rms: ψf = Ke √2/√3 / (p 2π 1000/60)
    # ke_v_per_krpm_ll_peak = 53.2 # V per 1000 r/min, line to line, peak: ψf = Ke/√3 / (p 2π 1000/60)
    # kt_nm_per_a_rms = 0.93       # N·m per A rms: ψf = Kt / (1.5 √2 p)
    J = 0.0012                 # kg·m², everything on the shaft
    rated_speed_rpm = 3000
    rated_torque_nm = 3.2
    rated_current_a = 4.0      # rms phase current
    B = 0.0                    # N·m·s/rad, viscous friction
    a5 = 0.0                   # 5th / 7th back-EMF harmonic, fraction of the fundamental
    a7 = 0.0
    q_sat_current_a = 20.0     # q-axis saturation (QSaturation): the current at which Lq has fallen to 2^(−1/n)
    q_sat_n = 2.0
    max_speed_rpm = 9000.0     # the mechanical limit (speed_limit_rpm below)
    [machine.saturation]       # a saturation map with cross-saturation (jaxobs.drive.saturation): the plant uses
    model = "algebraic"        # it; Hinkkanen et al. 2017's current map i(ψ) (+ Lelli et al. 2024's PM bridge)
    nominal = "rated_secant"   # how [machine]'s omitted Ld, Lq, psi_f follow from the map: "rated_secant",
    a_d0 = 3.96                # "rated_incremental" (at the rated current's MTPA point) or "no_load"
    a_dd = 28.5                # A/Vs^(S+1); required: a_d0, a_dd, S, a_q0, a_qq, T (A and Vs throughout)
    S = 4.0
    a_q0 = 5.89
    a_qq = 2.67
    T = 6.0
    a_dq = 41.5                # cross-saturation (default 0), exponents U = 1, V = 0 by default
    U = 1.0
    V = 1.0
    psi_n = 0.804              # the PM bridge (default none: a SyRM): ψn (Vs), a_b, a_bp, W = 2, k_q
    a_b = 81.75
    a_bp = 1.0
    W = 2.0
    k_q = 0.1
                               # or model = "table": current_unit ("A", "kA") and flux_unit ("Vs", "Wb", "mVs",
                               # "mWb") required; i_d = [...], i_q = [...], psi_d = [[...]], psi_q = [[...]] (one
                               # row per i_d), or csv = "map.csv" (columns i_d, i_q, psi_d, psi_q; one row per
                               # node; relative to the drive file); flux strictly increasing along its own axis
    [inverter]
    u_dc = 320.0               # V
    f_sample_hz = 16000.0      # control and PWM period = 1/f_sample_hz
    f_pwm_hz = 16000.0         # switching frequency (dead time's error), default f_sample_hz
    sampling = "start"         # "start" or "centre" of the PWM period (jaxobs.drive.latency)
    compute_delay = 1          # periods, 0 or 1
    pwm = "averaged"           # or "carrier": carrier-comparison PWM, f_pwm_hz = f_sample_hz (jaxobs.drive.pwm)
    device_drop_v = 0.0        # V, each conducting switch's or diode's drop
    voltage_limit = "circle"   # or "hexagon": up to 2 u_dc/3 at its vertices, minimum phase error (Inverter.limit)
    [control]
    current_bandwidth_hz = 500 # α_c/2π
    speed_bandwidth_hz = 5     # α_s/2π
    speed_estimate_hz = 15     # the bandwidth of the speed estimate a sensorless loop closes through
    speed_every = 16           # the speed loop runs every this many periods
    overload = 1.5             # i_max = overload × √2 × rated_current_a
    i_max_a = 8.5              # or the current limit itself, A peak
    id_policy = "mtpa"         # "zero" or "mtpa"
    field_weakening = false    # VoltageFeedbackFW
    fw_bandwidth_hz = 20.0
    fw_margin = 0.95           # m: field weakening holds |u*| at m u_dc/√3, in [0.5, 1] (default 0.95)
    current_margin = true      # |i| <= i_max at every sample: references below i_max, error limit (_reflimit)
    speed_schedule = 0.0       # N > 0: speed loop at min(α_s, |ωe*|/N) (docs/stability.md)
    setpoint_weight = 0.0      # b: 0 is I-P, 1 is PI
    advance = 1.5              # delay compensation, periods (default: the timing's use delay)
    [sensors]
    i_noise_a = 0.0            # white noise, standard deviation
    u_noise_v = 0.0
    i_offset_a = [0.0, 0.0]    # (α, β)
    u_offset_v = [0.0, 0.0]
    i_gain_error = [0.0, 0.0]  # relative
    adc_bits = 12              # current ADC: bits over ±adc_range_a
    adc_range_a = 10.0
    encoder_lines = 2500       # lines per revolution (4 edges each)
    [startup]                  # the I-f start-up (IfStartup.for_machine's keywords)
    current_a = 2.0            # I_f, A peak
    switch_rpm = 600.0
    hold_s = 0.1
    blend_s = 0.05
    dwell_s = 0.02
    angle_tol_rad = 0.2
    speed_tol = 0.1
    [dual]                     # a dual three-phase machine (jaxobs.drive._dualfile): [machine] is then the αβ
    Lls = 0.0015               # subspace with the whole machine's J, B and rated torque; Lls the xy inductance, H
    mode = "vsd"               # "vsd" (αβ + xy current PIs) or "individual" (a FOC per set)
    fw_voltage = "ab"          # the voltage the field weakening budgets under "vsd": "ab" or "set" (DualFOC)

Derived defaults (each recorded in :attr:`DriveFile.derived` with its rule):

- **Current-loop bandwidth** α_c.  The IMC design (k_p = α_c L̂, k_i = α_c R̂s; Harnefors & Nee, "Model-based
  current control of AC machines using the internal model control method", IEEE Trans. Ind. Appl. 34(1),
  1998) leaves the loop gain α_c e^(−s n T_s)/s, n = :attr:`Latency.use_delay` periods of computation and PWM
  delay (1.5 by default).  Its crossover is α_c and its phase margin 90° − α_c n T_s: the default puts it
  at :data:`PM_DESIGN_DEG` (60°), α_c = (π/6)/(n T_s), and at most :data:`ALPHA_C_TS_MAX` / T_s (where the
  delay's continuous model still holds); a given α_c must keep at least :data:`PM_MIN_DEG` (30°).  The
  machine's electrical time constants L/Rs are printed beside it: IMC cancels that pole, so α_c may lie
  above or below 1/τ (a warning when α_c < 1/τ: the loop then slows the current down).
- **Speed-loop bandwidth** α_s = min(α_c/10, ω_est/3).  α_c/10: the cascade's decade between the loops
  (Harnefors, Saarakkala & Hinkkanen, "Speed control of electrical drives using classical control methods",
  IEEE Trans. Ind. Appl. 49(2), 2013).  ω_est/3: a sensorless loop closes through the observer's speed
  estimate, whose bandwidth ω_est = 2π·``speed_estimate_hz`` (default the LESOs' PLL,
  :data:`jaxobs.papers.LESO_PLL_HZ` = 15 Hz) must stay above the loop's; ASSUMED ratio 3, the benches' pair
  (5 Hz loop, 15 Hz PLL) that holds the LESOs' maps from 11.6 r/min (docs/envelope.md), where a 10 Hz loop
  through a 400 r/min FLL oscillated (:data:`jaxobs.papers.BENCH_SPEED_HZ`).  An estimate whose bandwidth
  scales with the speed (the FLL flux observers) needs ω_e ≥ 4.3 α_s (docs/stability.md, the linear
  boundary of 000's closed forms; ``speed_schedule`` ≥ 4.3 keeps that at every speed): :attr:`lowest_speeds`.
- **Current limit** i_max = ``overload`` × √2 × ``rated_current_a`` (peak), overload 1.5 by default (the
  project's :meth:`FOC.imc` default, 1.5 × rated).
- **i_d policy**: MTPA where Lq > Ld (an IPMSM's reluctance torque), zero otherwise.
- **Field weakening** on when the rated point (rated torque at rated speed, the policy's currents) needs a
  voltage above ``fw_margin`` × u_dc/√3 (the voltage field weakening would hold it at), or when
  ``max_speed_rpm`` lies above the speed where the back EMF alone reaches u_dc/√3; the file is refused when no
  i_d within the current circle reaches the rated point under u_dc/√3.  ``fw_margin`` = 0.95 by default
  (:data:`jaxobs.drive.weakening.FW_MARGIN`: 5 % of the voltage left to the current PIs).
- **The current limit at every sample** (``current_margin = true``, the default; the shipped benches set it
  false): the current PIs see an error of at most E i_max (E = 0.1) and the references' circle lies at
  i_ref_max = (1 − h) i_max, h = 1.25 o E, o the designed current loop's step overshoot with its delay (5.7 % at
  the derived α_c: h = 0.71 %); the capability is drawn within i_ref_max (:mod:`jaxobs.drive._reflimit`).
- **Speed limit** (one rule, :func:`speed_limit`; ``jaxobs drive check`` prints it, tune, study and envelope
  use it): the no-load voltage bound, ωe ψf = u_dc/√3, or ωe (ψf − Ld i_max) = u_dc/√3 with field weakening (on a
  saturation map its flux there instead, |ψ(max(−i_max, −ψf/Ld), 0)|; the base speed, too, from the map's flux);
  within ``max_speed_rpm`` where given; where the voltage leaves the speed unbounded (ψf/Ld ≤ i_max) and no
  ``max_speed_rpm`` is given, :data:`MECH_SPEED_PU` (3) × the rated speed, ASSUMED.
- **ψf from a datasheet**: exactly one of ``psi_f``, ``ke_v_per_krpm_ll_rms``, ``ke_v_per_krpm_ll_peak``,
  ``kt_nm_per_a_rms`` (:func:`~jaxobs.drive.psi_f_from_ke`, :func:`~jaxobs.drive.psi_f_from_kt`; the rule is
  recorded with ``psi_f``).
- **Tiny values**: every number has a floor (e.g. inductances ≥ 1e-8 H, torques and currents ≥ 1e-6, u_dc ≥
  1 V); zero and subnormal values are one-line refusals, never a division by zero.
- **Speed-loop period**: ``speed_every`` = round(f_s / 1 kHz) (000's DSP runs its speed loop at 1 kHz,
  :mod:`jaxobs.drive.control`), at least 1.
- **I-f start-up**: :meth:`IfStartup.for_machine` (rated torque, inertia: the ramp's torque and the rotor's
  swing), with ``[startup]``'s keys overriding; its current papers.IF_CURRENT_PU × the smaller of T_rated/K_t
  and the rated peak √2 ``rated_current_a`` (an IPMSM carries its rated torque with less than T_rated/K_t), at
  least 1 % of i_max.
- **A dual machine** (``[dual]``): every value above is derived on one set carrying half of ``J``, ``B`` and the
  rated torque (:meth:`DualPMSMParams.per_set`, what the observers and the speed loop are designed on); the xy
  PIs get k_p = α_c L̂ls, k_i = α_c R̂s.  The dual loop runs the default timing and no q-axis saturation: a file
  that asks for either is refused.  ``jaxobs envelope`` and ``jaxobs drive check`` take a dual file; the tuning
  and study commands refuse it in one line.
- **A saturation map** (``[machine.saturation]``): the plant runs on the map (its state in flux linkages,
  :mod:`jaxobs.drive.saturation`); the controller, the observers and every rule above use ``[machine]``'s Ld, Lq,
  psi_f, where omitted the map's by the ``nominal`` rule.  The check prints the map's no-load flux, its Ld and Lq at
  no load and at the rated current's MTPA point on the map, and that point; a map whose inverse ψ(i) does not
  converge up to 3 × the rated current is refused.
- **Sensors**: an ADC of b bits over ±R A adds its quantization as white noise of σ = (2R/2^b)/√12
  (Widrow's model, valid when the signal spans many steps), in quadrature with ``i_noise_a``; the encoder
  (ideal in the loop) gives 2π/(4 N) rad mechanical per edge and a speed step of that per speed-loop period.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..io.safetoml import TomlFieldError, read_toml
from ._dualfile import dual_drive_file, dual_foc_kw, halved, lowered_bandwidth
from ._filebuild import ALPHA_C_TS_MAX as ALPHA_C_TS_MAX
from ._filebuild import PM_DESIGN_DEG as PM_DESIGN_DEG
from ._filebuild import PM_MIN_DEG as PM_MIN_DEG
from ._filebuild import (
    PM_WARN_DEG,
    Record,
    base_speed_table,
    controller,
    current_limit,
    current_loop,
    inverter_table,
    lowest_speeds,
    machine_quantities,
    machine_table,
    sensors_table,
    speed_loop,
    startup_table,
    timing,
)
from ._filebuild import Derived as Derived
from ._filekeys import DRIVE_FILE_KEYS as DRIVE_FILE_KEYS
from ._filekeys import checked_tables
from ._filemap import machine_map
from ._steady import MECH_SPEED_PU as MECH_SPEED_PU
from ._steady import speed_limit as speed_limit
from .control import FOC, IfStartup
from .dual import DualPMSMParams
from .dual_loop import DualDrive, DualFOC
from .hardware import Sensors
from .loop import Drive
from .machine import RPM, PMSMParams
from .weakening import capability_curve

__all__ = [
    "ALPHA_C_TS_MAX",
    "MECH_SPEED_PU",
    "speed_limit",
    "DRIVE_FILE_KEYS",
    "Derived",
    "DriveFile",
    "PM_DESIGN_DEG",
    "PM_MIN_DEG",
    "drive_from_table",
    "load_drive",
    "read_drive",
]


@dataclasses.dataclass(frozen=True)
class DriveFile:
    """A checked drive file (:func:`read_drive`): what it builds and what follows from it.

    Attributes:
        name: the file's ``name`` (or its stem).
        description: the file's ``description`` (or its name).
        foc_kw: :meth:`FOC.imc`'s keywords as derived (:meth:`drive_for` rebuilds the FOC from them).
        table: the file's tables as read (``[machine]``, ``[inverter]``, ...): a job's result keeps them inline.
        machine: the machine, true and assumed alike.
        drive: the sensorless drive on it, starting steady (``Drive(sensorless=True)``, 0.2 s settle).
        sensors: the file's sensor errors (quantization as noise).
        startup: the I-f start-up a standstill start runs.
        derived: name -> :class:`Derived`, in the order the check prints them.
        lowest_speeds: observer family -> (lowest speed in r/min or None where none, the rule).
        warnings: one line each.
        dual: a ``[dual]`` file's whole dual three-phase machine (:class:`DualPMSMParams`; :attr:`machine` is
            then one set carrying half the rotor and :attr:`drive` a :class:`DualDrive`), else None.
    """

    name: str
    machine: PMSMParams
    drive: Drive | DualDrive
    sensors: Sensors
    startup: IfStartup
    derived: dict[str, Derived]
    lowest_speeds: dict[str, tuple[float | None, str]]
    warnings: tuple[str, ...]
    description: str = ""
    foc_kw: dict[str, Any] = dataclasses.field(default_factory=dict, repr=False)
    table: dict[str, Any] = dataclasses.field(default_factory=dict, repr=False)
    dual: DualPMSMParams | None = None

    @property
    def ts(self) -> float:
        """The control and PWM period (s): 1/``inverter.f_sample_hz``."""
        return float(self.drive.ts)

    @property
    def speed_limit_rpm(self) -> float:
        """The highest speed (r/min) a drive may be asked for (``derived["speed_limit_rpm"]``)."""
        return float(self.derived["speed_limit_rpm"].value)

    def capability(self, speeds_rpm: Sequence[float] | np.ndarray) -> dict[str, np.ndarray]:
        """The steady torque–speed capability at ``speeds_rpm`` (:func:`~jaxobs.drive.weakening.capability_curve`
        with this file's controller: its references' circle (``i_ref_max``, else i_max), its field weakening and i_d
        policy, fw_margin × u_dc/√3; the machine's saturation map where the file has one, else the constant
        inductances).  The voltage is the
        FOC's u_max = u_dc/√3 under a hexagon too: the inscribed circle of the hexagon is the largest voltage a
        steady sinusoidal current gets without overmodulation's harmonics, and field weakening holds |u*| at
        fw_margin of it (the hexagon's vertices are transient headroom).  A ``[dual]`` file's: one set's.

        Args:
            speeds_rpm: The mechanical speeds, r/min (≥ 0).

        Returns:
            ``torque`` (N·m; NaN where no current fits the voltage), ``i_d``, ``i_q`` (A) and ``u`` (V), each
            shaped as ``speeds_rpm``.
        """
        d, m = self.derived, self.machine
        w_e = np.asarray(speeds_rpm, float) * m.p * RPM
        i_ref = d.get("i_ref_max", d["i_max"]).value  # the currents the controller asks for (jaxobs.drive._reflimit)
        return capability_curve(m, w_e, float(d["u_max"].value), float(i_ref),
                                float(d["fw_margin"].value), weakening=bool(d["field_weakening"].value),
                                id_mode=str(d["id_policy"].value))  # fmt: skip

    def drive_for(
        self,
        *,
        sensorless: bool = True,
        handover: float = 0.0,
        settle: float = 0.2,
        standstill: bool = False,
        speed_schedule: float | None = None,
    ) -> Drive | DualDrive:
        """This file's drive as a run needs it: the same machine, inverter, timing and controller.

        Args:
            sensorless: the observer closes the loop (else the encoder, the observer beside it).
            handover: the observer closes it from this time on (s).
            settle: the observer's unscored settling phase before t = 0 (s).
            standstill: start from rest by :attr:`startup` (else each scenario starts steady).
            speed_schedule: the FOC's speed-loop schedule N (:class:`FOC`), or None: the file's.

        Returns:
            The :class:`Drive` (a :class:`DualDrive` for a ``[dual]`` file, whose settle and hand-over it takes;
            ``speed_schedule`` applies to both).
        """
        d = self.drive
        common: dict[str, Any] = dict(startup=self.startup if standstill else None, n_sub=d.n_sub, rule=d.rule,
                                      sensorless=sensorless, handover=handover, settle=settle)  # fmt: skip
        if isinstance(d, DualDrive) and self.dual is not None:  # a [dual] file
            ctrl = d.ctrl
            if speed_schedule is not None and float(speed_schedule) != float(ctrl.foc.speed_schedule):
                kw = dual_foc_kw(self.foc_kw, ("alpha_c", "alpha_s", "speed_schedule"))
                ctrl = DualFOC.imc(self.dual, self.foc_kw["alpha_c"], self.foc_kw["alpha_s"], mode=ctrl.mode,
                                   fw_voltage=ctrl.fw_voltage, speed_schedule=float(speed_schedule), **kw)  # fmt: skip
            return DualDrive(ctrl, d.inverter, **common)
        assert isinstance(d, Drive)  # a single machine's file
        foc = d.foc
        if speed_schedule is not None and float(speed_schedule) != float(foc.speed_schedule):
            foc = FOC.imc(self.machine, **{**self.foc_kw, "speed_schedule": float(speed_schedule)})
        return Drive(foc, d.inverter, latency=d.latency, **common)


def drive_from_table(raw: dict[str, Any], name: str = "drive", base: str | Path | None = None) -> DriveFile:
    """A :class:`DriveFile` from a parsed drive file's table (module doc).

    Args:
        raw: the file's tables (``tomllib`` output).
        name: the label when the table has no ``name``.
        base: the folder a ``[machine.saturation]`` CSV name is relative to (the file's; None: the working one).

    Returns:
        The checked drive file.

    Raises:
        ValueError: one line naming the key and its allowed range.
    """
    full_raw = raw
    raw, sat, sat_rec = machine_map(raw, base)
    t = checked_tables(raw)
    if "dual" in raw:
        return _dual_drive_file(raw, t, name)
    m, inv, ctl, sen, st = t["machine"], t["inverter"], t["control"], t["sensors"], t["startup"]
    rec = Record()
    for k, v in sat_rec.items():
        rec(k, *v)
    m, machine = machine_table(m, sat, rec)
    p = m["p"]
    w_rated = p * m["rated_speed_rpm"] * RPM  # electrical, rad/s
    kt = 1.5 * p * m["psi_f"]
    f_s, ts, sampling, latency, n_use = timing(inv, w_rated, rec)
    u_max = machine_quantities(m, inv, kt, rec)
    i_max, policy, i_d_r, i_q_r = current_limit(m, ctl, rec)
    fw, margin = base_speed_table(m, inv, ctl, w_rated, u_max, i_max, (i_d_r, i_q_r), rec, machine)
    alpha_c = current_loop(m, ctl, f_s, ts, n_use, rec)
    alpha_s, schedule, w_est, speed_every, t_w = speed_loop(ctl, f_s, ts, alpha_c, rec)
    loops = dict(alpha_c=alpha_c, alpha_s=alpha_s, i_max=i_max, ts=ts, speed_every=speed_every, id_mode=policy,
                 speed_schedule=schedule)  # fmt: skip
    foc_kw, foc = controller(machine, ctl, loops, fw, margin, n_use, rec)
    inverter = inverter_table(inv, f_s, sampling, rec)
    drive = Drive(foc, inverter, sensorless=True, latency=latency)
    sensors = sensors_table(sen, i_max, p, t_w, rec)
    startup = startup_table(st, m, machine, i_max, kt, rec)
    return DriveFile(
        name=str(raw.get("name", name)),
        machine=machine,
        drive=drive,
        sensors=sensors,
        startup=startup,
        derived=rec.derived,
        lowest_speeds=lowest_speeds(p, alpha_s, schedule, w_est),
        warnings=tuple(rec.warnings),
        description=str(raw.get("description", raw.get("name", name))),
        foc_kw=foc_kw,
        table={k: full_raw[k] for k in DRIVE_FILE_KEYS if k in full_raw},
    )


def _dual_drive_file(raw: dict[str, Any], t: dict[str, dict[str, Any]], name: str) -> DriveFile:
    """A ``[dual]`` file: derived on one set carrying half the rotor, then the dual machine and drive on it."""
    half = halved(raw)
    single = drive_from_table(half, name)
    lowered = lowered_bandwidth(half, single, t["dual"], PM_DESIGN_DEG)  # "individual": α_c for the xy loop
    if lowered is not None:
        single = drive_from_table(lowered, name)
    dual, drive, extra, warned = dual_drive_file(
        single, raw, t["dual"], lowered=lowered is not None, pm=(PM_MIN_DEG, PM_WARN_DEG)
    )
    # the dual loops run without the single FOC's reference margin and error limit (dual_foc_kw)
    kept = {k: v for k, v in single.derived.items() if k not in ("i_ref_max", "error_limit")}
    derived = {**kept, **{k: Derived(*v) for k, v in extra.items()}}
    table = {k: raw[k] for k in DRIVE_FILE_KEYS if k in raw}
    warnings = single.warnings + warned
    return dataclasses.replace(single, dual=dual, drive=drive, derived=derived, table=table, warnings=warnings)


def read_drive(path: str | Path) -> DriveFile:
    """The drive file at ``path``, read safely (size at most 1 MB, nesting, encoding: :mod:`jaxobs.io.safetoml`)
    and checked in full.

    Args:
        path: a TOML drive file (module doc).

    Returns:
        The :class:`DriveFile`.

    Raises:
        ValueError: one line naming the key (or the file) and the allowed range.
    """
    try:
        raw, _ = read_toml(path, "drive file")
    except TomlFieldError as e:
        raise ValueError(str(e)) from None
    return drive_from_table(raw, Path(path).stem, Path(path).parent)


def load_drive(path: str | Path) -> tuple[PMSMParams, Drive | DualDrive]:
    """The machine and the sensorless, steady-start :class:`Drive` a drive file declares (:func:`read_drive`:
    the same checks; its sensors, start-up and derived values are on the :class:`DriveFile`).

    Args:
        path: a TOML drive file.

    Returns:
        ``(machine, drive)``.

    Raises:
        ValueError: one line naming the key and the allowed range.
    """
    f = read_drive(path)
    return f.machine, f.drive
