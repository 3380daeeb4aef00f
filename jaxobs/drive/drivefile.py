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
- **Speed limit** (one rule, :func:`speed_limit`; ``jaxobs drive check`` prints it, tune, study and envelope
  use it): the no-load voltage bound, ωe ψf = u_dc/√3, or ωe (ψf − Ld i_max) = u_dc/√3 with field weakening;
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
import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .. import papers
from ..io.safetoml import TomlFieldError, read_toml
from ._dualfile import dual_drive_file, halved, lowered_bandwidth
from .control import FOC, IfStartup
from .dual import DualPMSMParams
from .dual_loop import DualDrive, DualFOC
from .hardware import Inverter, Sensors
from .latency import Latency, PeriodStart, PWMCentre
from .loop import SETTLE_PERIODS, Drive
from .machine import RPM, PMSMParams, QSaturation, psi_f_from_ke, psi_f_from_kt
from .saturation import NOMINAL_RULES, check_inverse, map_summary, saturation_from_table
from .weakening import FW_MARGIN, VoltageFeedbackFW

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
# ASSUMED: without [machine] max_speed_rpm, a drive whose voltage never bounds its speed (field weakening with
# ψf/Ld ≤ i_max) is limited to 3 × its rated speed (a common top-to-base ratio of traction and spindle drives)
MECH_SPEED_PU = 3.0
IF_CURRENT_MIN_PU = 0.01  # the I-f current at least 1 % of i_max (tiny values are refused, not divided by)
PSI_F_KEYS = ("psi_f", "ke_v_per_krpm_ll_rms", "ke_v_per_krpm_ll_peak", "kt_nm_per_a_rms")

_S2, _S3 = math.sqrt(2.0), math.sqrt(3.0)


class _Key(NamedTuple):
    kind: str  # "float", "int", "bool", "str", "pair"
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    unit: str = ""
    required: bool = False
    choices: tuple = ()


_F, _I = "float", "int"
# every key of a drive file: table -> key -> its type and range (DriveFile's docs list them; the check prints them)
DRIVE_FILE_KEYS: dict[str, dict[str, _Key]] = {
    "machine": {
        "p": _Key(_I, 1, 100, unit="pole pairs", required=True),
        "Rs": _Key(_F, 0.0, 1e3, unit="Ω", required=True),
        "Ld": _Key(_F, 1e-8, 10.0, unit="H", required=True),
        "Lq": _Key(_F, 1e-8, 10.0, unit="H", required=True),
        # the magnet flux: psi_f, or one of the datasheet constants it is converted from (PSI_F_KEYS)
        "psi_f": _Key(_F, 1e-6, 100.0, unit="Wb"),
        "ke_v_per_krpm_ll_rms": _Key(_F, 1e-3, 1e6, unit="V/krpm"),
        "ke_v_per_krpm_ll_peak": _Key(_F, 1e-3, 1e6, unit="V/krpm"),
        "kt_nm_per_a_rms": _Key(_F, 1e-6, 1e4, unit="N·m/A"),
        "J": _Key(_F, 1e-10, 1e5, unit="kg·m²", required=True),
        "rated_speed_rpm": _Key(_F, 1.0, 1e6, unit="r/min", required=True),
        "rated_torque_nm": _Key(_F, 1e-6, 1e6, unit="N·m", required=True),
        "rated_current_a": _Key(_F, 1e-6, 1e5, unit="A rms", required=True),
        "max_speed_rpm": _Key(_F, 1.0, 1e6, unit="r/min"),
        "B": _Key(_F, 0.0, 1e3, unit="N·m·s/rad"),
        "a5": _Key(_F, 0.0, 1.0, unit="1"),
        "a7": _Key(_F, 0.0, 1.0, unit="1"),
        "q_sat_current_a": _Key(_F, 1e-6, 1e6, unit="A"),
        "q_sat_n": _Key(_F, 1.0, 16.0, unit="1"),
    },
    "inverter": {
        "u_dc": _Key(_F, 1.0, 1e5, unit="V", required=True),
        "f_sample_hz": _Key(_F, 100.0, 1e6, unit="Hz", required=True),
        "f_pwm_hz": _Key(_F, 100.0, 1e6, unit="Hz"),
        "sampling": _Key("str", choices=("start", "centre")),
        "compute_delay": _Key(_I, 0, 1, unit="periods"),
        "pwm": _Key("str", choices=("averaged", "carrier")),
        "device_drop_v": _Key(_F, 0.0, 100.0, unit="V"),
        "voltage_limit": _Key("str", choices=("circle", "hexagon")),
    },
    "control": {
        "current_bandwidth_hz": _Key(_F, 0.01, 1e5, unit="Hz"),
        "speed_bandwidth_hz": _Key(_F, 0.001, 1e4, unit="Hz"),
        "speed_estimate_hz": _Key(_F, 0.001, 1e4, unit="Hz"),
        "speed_every": _Key(_I, 1, 10_000, unit="periods"),
        "overload": _Key(_F, 1.0, 10.0, unit="1"),
        "i_max_a": _Key(_F, 1e-6, 1e6, unit="A"),
        "id_policy": _Key("str", choices=("zero", "mtpa")),
        "field_weakening": _Key("bool"),
        "fw_bandwidth_hz": _Key(_F, 0.01, 1e4, unit="Hz"),
        "fw_margin": _Key(_F, 0.5, 1.0, unit="1"),
        "speed_schedule": _Key(_F, 0.0, 1000.0, unit="1"),
        "setpoint_weight": _Key(_F, 0.0, 1.0, unit="1"),
        "advance": _Key(_F, 0.0, 3.0, unit="periods"),
    },
    "sensors": {
        "i_noise_a": _Key(_F, 0.0, 1e3, unit="A"),
        "u_noise_v": _Key(_F, 0.0, 1e4, unit="V"),
        "i_offset_a": _Key("pair", -1e3, 1e3, unit="A"),
        "u_offset_v": _Key("pair", -1e4, 1e4, unit="V"),
        "i_gain_error": _Key("pair", -0.5, 0.5, unit="1"),
        "adc_bits": _Key(_I, 6, 24, unit="bits"),
        "adc_range_a": _Key(_F, 1e-6, 1e6, unit="A"),
        "encoder_lines": _Key(_I, 1, 10_000_000, unit="lines/rev"),
    },
    "startup": {
        "current_a": _Key(_F, 1e-6, 1e6, unit="A"),
        "switch_rpm": _Key(_F, 0.01, 1e6, unit="r/min"),
        "hold_s": _Key(_F, 0.0, 60.0, unit="s"),
        "blend_s": _Key(_F, 0.0, 10.0, unit="s"),
        "dwell_s": _Key(_F, 1e-6, 10.0, unit="s"),
        "angle_tol_rad": _Key(_F, 1e-6, 3.14, unit="rad"),
        "speed_tol": _Key(_F, 1e-6, 1.0, unit="1"),
    },
    # a dual three-phase machine (jaxobs.drive._dualfile): the xy inductance and the current control's mode
    "dual": {
        "Lls": _Key(_F, 1e-8, 10.0, unit="H", required=True),
        "mode": _Key("str", choices=("vsd", "individual")),
        "fw_voltage": _Key("str", choices=("ab", "set")),
    },
}
_TOP = ("name", "description")


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
    drive: Drive
    sensors: Sensors
    startup: IfStartup
    derived: dict
    lowest_speeds: dict
    warnings: tuple
    description: str = ""
    foc_kw: dict = dataclasses.field(default_factory=dict, repr=False)
    table: dict = dataclasses.field(default_factory=dict, repr=False)
    dual: DualPMSMParams | None = None

    @property
    def ts(self) -> float:
        """The control and PWM period (s): 1/``inverter.f_sample_hz``."""
        return float(self.drive.ts)

    @property
    def speed_limit_rpm(self) -> float:
        """The highest speed (r/min) a drive may be asked for (``derived["speed_limit_rpm"]``)."""
        return float(self.derived["speed_limit_rpm"].value)

    def drive_for(
        self,
        *,
        sensorless: bool = True,
        handover: float = 0.0,
        settle: float = 0.2,
        standstill: bool = False,
        speed_schedule: float | None = None,
    ) -> Drive:
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
        new_schedule = speed_schedule is not None
        common = dict(startup=self.startup if standstill else None, n_sub=d.n_sub, rule=d.rule,
                      sensorless=sensorless, handover=handover, settle=settle)  # fmt: skip
        if self.dual is not None:
            ctrl = d.ctrl
            if new_schedule and float(speed_schedule) != float(ctrl.foc.speed_schedule):
                kw = {k: v for k, v in self.foc_kw.items() if k not in ("alpha_c", "alpha_s", "speed_schedule")}
                ctrl = DualFOC.imc(self.dual, self.foc_kw["alpha_c"], self.foc_kw["alpha_s"], mode=ctrl.mode,
                                   fw_voltage=ctrl.fw_voltage, speed_schedule=float(speed_schedule), **kw)  # fmt: skip
            return DualDrive(ctrl, d.inverter, **common)
        foc = d.foc
        if new_schedule and float(speed_schedule) != float(foc.speed_schedule):
            foc = FOC.imc(self.machine, **{**self.foc_kw, "speed_schedule": float(speed_schedule)})
        return Drive(foc, d.inverter, latency=d.latency, **common)


def _value(table: dict, tname: str, key: str, spec: _Key):
    field = f"{tname}.{key}"
    v = table[key]
    rng = ""
    if spec.lo is not None:
        rng = f"{'(' if spec.lo_open else '['}{spec.lo:g}, {spec.hi:g}]" + (f" {spec.unit}" if spec.unit else "")
    if spec.kind == "str":
        if v not in spec.choices:
            raise ValueError(f"{field} must be one of {', '.join(map(repr, spec.choices))}, got {_show(v)}")
        return v
    if spec.kind == "bool":
        if not isinstance(v, bool):
            raise ValueError(f"{field} must be true or false, got {_show(v)}")
        return v
    if spec.kind == "pair":
        if not (isinstance(v, list) and len(v) == 2):
            raise ValueError(f"{field} must be a pair [α, β] of numbers in {rng}, got {_show(v)}")
        return [_number(x, f"{field}[{i}]", spec, rng) for i, x in enumerate(v)]
    if spec.kind == "int":
        if isinstance(v, bool) or not isinstance(v, int) or not spec.lo <= v <= spec.hi:
            what = "a positive integer" if spec.lo == 1 else "an integer"
            raise ValueError(f"{field} must be {what} in {rng}, got {_show(v)}")
        return int(v)
    return _number(v, field, spec, rng)


def _number(v, field: str, spec: _Key, rng: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"{field} must be a number in {rng}, got {_show(v)}")
    x = float(v)
    ok = math.isfinite(x) and (x > spec.lo if spec.lo_open else x >= spec.lo) and x <= spec.hi
    if not ok:
        raise ValueError(f"{field} must be in {rng}, got {_show(v)}")
    return x


def _show(v) -> str:
    r = repr(v)
    return r if len(r) <= 40 else r[:39] + "…"


def _tables(raw: dict) -> dict:
    """The file's tables, every key known and in range: table -> {key: value}."""
    for k, v in raw.items():
        if k in _TOP:
            if not isinstance(v, str) or len(v) > 200:
                raise ValueError(f"{k} must be a string of at most 200 characters, got {_show(v)}")
            continue
        if k not in DRIVE_FILE_KEYS:
            raise ValueError(
                f"{k}: unknown table or key; allowed: {', '.join((*_TOP, *(f'[{t}]' for t in DRIVE_FILE_KEYS)))}"
            )
        if not isinstance(v, dict):
            raise ValueError(f"{k} must be a table ([{k}]), got {type(v).__name__}")
    out = {}
    for tname, keys in DRIVE_FILE_KEYS.items():
        table = raw.get(tname, {})
        for k in table:
            if k not in keys:
                near = ", ".join(keys)
                raise ValueError(f"{tname}.{k}: unknown key; allowed: {near}"[:300])
        for k, spec in keys.items():
            if spec.required and k not in table and (tname in raw or tname != "dual"):  # [dual]: when present
                raise ValueError(f"{tname}.{k}: missing (required)")
        out[tname] = {k: _value(table, tname, k, keys[k]) for k in table}
    return out


def _mtpa_id(Ld, Lq, psi_f, iq):
    """MTPA's i_d for i_q (A): ψf/(2(Lq − Ld)) − √(ψf²/(4(Lq − Ld)²) + i_q²) (:meth:`FOC._id_ref`)."""
    dl = Lq - Ld
    if abs(dl) <= 1e-12:
        return 0.0
    a = psi_f / (2 * dl)
    return a - math.copysign(1.0, dl) * math.sqrt(a * a + iq * iq)


def _torque(p, Ld, Lq, psi_f, i_d, i_q):
    return 1.5 * p * (psi_f + (Ld - Lq) * i_d) * i_q


def _policy_currents(m: dict, policy: str, torque: float):
    """(i_d, i_q) of the policy that give ``torque`` (N·m) on the machine table ``m``: bisection on i_q."""
    p, Ld, Lq, psi = m["p"], m["Ld"], m["Lq"], m["psi_f"]

    def te(iq):
        i_d = _mtpa_id(Ld, Lq, psi, iq) if policy == "mtpa" else 0.0
        return _torque(p, Ld, Lq, psi, i_d, iq)

    lo, hi = 0.0, torque / (1.5 * p * psi)  # the magnet alone needs the most i_q; MTPA's reluctance adds torque
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if te(mid) < torque else (lo, mid)
    iq = 0.5 * (lo + hi)
    return (_mtpa_id(Ld, Lq, psi, iq) if policy == "mtpa" else 0.0), iq


def _voltage(m: dict, w_e: float, i_d: float, i_q: float) -> float:
    """|u| (V, peak) of the steady state at ω_e (rad/s) and (i_d, i_q) (A)."""
    u_d = m["Rs"] * i_d - w_e * m["Lq"] * i_q
    u_q = m["Rs"] * i_q + w_e * (m["Ld"] * i_d + m["psi_f"])
    return math.hypot(u_d, u_q)


def _fw_voltage(m: dict, w_e: float, torque: float, i_max: float, id_top: float) -> float:
    """The least |u| (V) at ω_e that carries ``torque`` within the current circle i_max with i_d ≤ ``id_top``
    (field weakening: a more negative i_d, down to where the FOC stops it, max(−i_max, −ψf/Ld):
    :func:`jaxobs.drive.weakening.id_stop`); inf where no i_d does."""
    p, Ld, Lq, psi = m["p"], m["Ld"], m["Lq"], m["psi_f"]
    best = math.inf
    for i_d in np.linspace(id_top, max(-i_max, min(-psi / Ld, id_top)), 4001):  # to the FOC's stop (weakening)
        k = 1.5 * p * (psi + (Ld - Lq) * i_d)
        if k <= 0:
            continue
        i_q = torque / k
        if i_d * i_d + i_q * i_q <= i_max * i_max * (1 + 1e-12):
            best = min(best, _voltage(m, w_e, float(i_d), i_q))
    return best


def _base_speed(m: dict, i_d: float, i_q: float, u_max: float) -> float:
    """ω_e (rad/s) at which the steady |u| at (i_d, i_q) reaches u_max: the root of a quadratic in ω_e."""
    a, b = m["Lq"] * i_q, m["Ld"] * i_d + m["psi_f"]
    rs = m["Rs"]
    qa = a * a + b * b
    qb = 2 * rs * (-i_d * a + i_q * b)
    qc = rs * rs * (i_d * i_d + i_q * i_q) - u_max * u_max
    disc = qb * qb - 4 * qa * qc
    if qc >= 0 or disc < 0:
        return 0.0
    return (-qb + math.sqrt(disc)) / (2 * qa)


def _rpm(w_e: float, p: int) -> float:
    return w_e / p / RPM


def _no_load_rpm(u_max: float, flux: float, p: int) -> float:
    """The speed (r/min) where ωe · ``flux`` = u_max (inf for flux ≤ 0), in the one order of operations every
    speed limit uses (the envelope's default speeds are 0.98 × it: the same bits everywhere)."""
    return math.inf if flux <= 0.0 else u_max / flux / float(p) * 60.0 / (2 * math.pi)


def speed_limit(p, psi_f, Ld, i_max, u_max, weakening, rated_speed_rpm, max_speed_rpm=None) -> tuple[float, str]:
    """The one speed limit of a drive (r/min, either direction) and its rule, which ``jaxobs drive check``
    prints and ``tune``, ``study`` and ``envelope`` use.

    The voltage's no-load bound: ωe ψf = u_max without field weakening (the FOC cannot hold even zero current
    above it); ωe (ψf − Ld i_max) = u_max with it (i_d stops at max(−i_max, −ψf/Ld): unbounded where
    Ld i_max ≥ ψf).  Then the mechanical limit: ``max_speed_rpm`` (``[machine] max_speed_rpm``) where given,
    else :data:`MECH_SPEED_PU` × the rated speed where the voltage leaves the speed unbounded.

    Args:
        p: The pole pairs.
        psi_f: ψf, Wb.
        Ld: The d inductance, H.
        i_max: The current limit, A.
        u_max: The voltage limit, V.
        weakening: Whether the FOC weakens the field.
        rated_speed_rpm: The rated speed, r/min.
        max_speed_rpm: The mechanical limit, r/min, or None.

    Returns:
        ``(limit, rule)``.
    """
    flux = psi_f - Ld * i_max if weakening else psi_f
    n_v = _no_load_rpm(u_max, flux, p)
    why = "no-load ωe (ψf − Ld i_max) = u_max" if weakening else "no-load ωe ψf = u_max"
    if max_speed_rpm is not None:
        return min(n_v, float(max_speed_rpm)), f"min({why}, machine.max_speed_rpm)"
    if math.isinf(n_v):
        return MECH_SPEED_PU * float(rated_speed_rpm), (
            f"{MECH_SPEED_PU:g} × rated_speed_rpm (ASSUMED; machine.max_speed_rpm sets it): {why} is unbounded "
            "(ψf/Ld ≤ i_max)"
        )
    return n_v, why + (" (field weakening)" if weakening else " (no field weakening)")


def drive_from_table(raw: dict, name: str = "drive", base=None) -> DriveFile:
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
    raw, sat, sat_rec = _machine_map(raw, base)
    t = _tables(raw)
    if "dual" in raw:  # derived on one set carrying half the rotor, then the dual machine and drive on it
        half = halved(raw)
        single = drive_from_table(half, name)
        lowered = lowered_bandwidth(half, single, t["dual"], PM_DESIGN_DEG)  # "individual": α_c for the xy loop
        if lowered is not None:
            single = drive_from_table(lowered, name)
        dual, drive, extra, warned = dual_drive_file(
            single, raw, t["dual"], lowered=lowered is not None, pm=(PM_MIN_DEG, PM_WARN_DEG)
        )
        derived = {**single.derived, **{k: Derived(*v) for k, v in extra.items()}}
        table = {k: raw[k] for k in DRIVE_FILE_KEYS if k in raw}
        warnings = single.warnings + warned
        return dataclasses.replace(single, dual=dual, drive=drive, derived=derived, table=table, warnings=warnings)
    m, inv, ctl, sen, st = t["machine"], t["inverter"], t["control"], t["sensors"], t["startup"]
    d: dict[str, Derived] = {}
    warn: list[str] = []

    def rec(key, value, unit, rule, given=False):
        d[key] = Derived(value, unit, rule, given)
        return value

    for k, v in sat_rec.items():
        rec(k, *v)

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
    w_rated = p * m["rated_speed_rpm"] * RPM  # electrical, rad/s
    kt = 1.5 * p * m["psi_f"]

    # --- timing
    f_s = inv["f_sample_hz"]
    ts = 1.0 / f_s
    sampling = inv.get("sampling", "start")
    latency = Latency(PeriodStart() if sampling == "start" else PWMCentre(), inv.get("compute_delay", 1))
    n_use = latency.use_delay
    rec("ts", ts, "s", "1 / inverter.f_sample_hz", True)
    rec("use_delay", n_use, "periods", "from the sample to the centre of the PWM period it drives (Latency)")
    if f_s < 10 * w_rated / (2 * math.pi):
        warn.append(
            f"inverter.f_sample_hz: {f_s / (w_rated / (2 * math.pi)):.3g} samples per electrical period at the "
            "rated speed (fewer than 10: the discrete current loop and observers lose accuracy)"
        )

    # --- machine's own quantities
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

    # --- current limit and i_d policy
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
    i_d_r, i_q_r = _policy_currents(m, policy, m["rated_torque_nm"])
    i_r = math.hypot(i_d_r, i_q_r)
    rec("i_rated_point", i_r, "A", f"|i| of rated torque under the {policy} policy (peak)")
    if i_r > i_max * (1 + 1e-9):
        raise ValueError(
            f"machine.rated_torque_nm: needs |i| = {i_r:.4g} A peak under the {policy} policy, above the current "
            f"limit i_max = {i_max:.4g} A (raise control.overload / i_max_a or rated_current_a); must be <= "
            f"{m['rated_torque_nm'] * i_max / i_r:.4g} N·m"
        )
    if i_r > 1.1 * _S2 * m["rated_current_a"]:
        warn.append(
            f"machine.rated_current_a: the rated torque needs {i_r / _S2:.4g} A rms under the {policy} policy, more "
            f"than 1.1 × the rated {m['rated_current_a']:g} A (check psi_f or the rating)"
        )

    # --- voltage: rated point, base speed, speed range, field weakening
    u_rated = rec("u_rated_point", _voltage(m, w_rated, i_d_r, i_q_r), "V", "steady |u| at rated torque and speed")
    rec("base_speed_rpm", _rpm(_base_speed(m, i_d_r, i_q_r, u_max), p), "r/min",
                 "the speed where rated torque's |u| reaches u_max")  # fmt: skip
    n_emf = rec("emf_speed_rpm", _no_load_rpm(u_max, m["psi_f"], p), "r/min",
                "no-load speed where ωe ψf = u_max (no weakening)")  # fmt: skip
    rec("max_speed_fw_rpm", _no_load_rpm(u_max, m["psi_f"] - m["Ld"] * i_max, p), "r/min",
        "no-load ωe (ψf − Ld i_max) = u_max (inf: i_char ≤ i_max, unbounded by the voltage)")  # fmt: skip
    fw_needed = u_rated > u_max
    margin = rec("fw_margin", ctl.get("fw_margin", FW_MARGIN), "1",
                 "5 % of u_max left to the current PIs (jaxobs.drive.weakening)", "fw_margin" in ctl)  # fmt: skip
    fw_default = u_rated > margin * u_max or m.get("max_speed_rpm", 0.0) > n_emf
    fw = ctl.get("field_weakening", fw_default)
    rec("field_weakening", fw, "", "on when the rated point needs |u| > fw_margin × u_dc/√3, or machine.max_speed_rpm "
        "lies above emf_speed_rpm (where the back EMF alone reaches u_max)", "field_weakening" in ctl)  # fmt: skip
    limit, limit_rule = speed_limit(p, m["psi_f"], m["Ld"], i_max, u_max, fw, m["rated_speed_rpm"],
                                    m.get("max_speed_rpm"))  # fmt: skip
    rec("speed_limit_rpm", limit, "r/min", limit_rule, "max_speed_rpm" in m)
    if fw_needed:
        id_top = min(i_d_r, 0.0)
        u_fw = _fw_voltage(m, w_rated, m["rated_torque_nm"], i_max, id_top) if fw else math.inf
        if not fw or u_fw > u_max:
            need = u_rated if not fw else u_fw
            how = "with field weakening within i_max" if fw else "without field weakening (control.field_weakening)"
            raise ValueError(
                f"inverter.u_dc: must be >= {_S3 * need:.4g} V for the rated point ({m['rated_torque_nm']:g} N·m at "
                f"{m['rated_speed_rpm']:g} r/min {how}), got {inv['u_dc']:g}"
            )
        rec("u_rated_point_fw", u_fw, "V", "least |u| at the rated point with i_d ≤ the policy's, |i| ≤ i_max")
    elif u_rated > margin * u_max and not fw:
        warn.append(
            f"inverter.u_dc: the rated point needs {u_rated / u_max:.1%} of u_dc/√3 (less than {1 - margin:.0%} left "
            "for the current loop to regulate; control.field_weakening = true would hold it at fw_margin)"
        )

    # --- current loop
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
        warn.append(
            f"control.current_bandwidth_hz: α_c·ts = {alpha_c * ts:.3g} leaves a phase margin of "
            f"{pm_of(alpha_c):.0f}° (< {PM_WARN_DEG:g}°): the current loop rings"
        )
    tau_max = max(m["Ld"], m["Lq"]) / m["Rs"] if m["Rs"] > 0 else math.inf
    if alpha_c * tau_max < 1.0:
        warn.append(
            f"control.current_bandwidth_hz: α_c = {alpha_c:.4g} rad/s is below the machine's own 1/τ = "
            f"{1 / tau_max:.4g} rad/s: the current loop is slower than the open machine"
        )

    # --- speed loop
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
            warn.append(
                f"control.speed_bandwidth_hz: α_s = α_c/{alpha_c / alpha_s:.3g}, less than a decade below the "
                "current loop: the two loops interact"
            )
        if alpha_s > w_est / ESTIMATE_RATIO * (1 + 1e-12):
            warn.append(
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

    # --- controller
    fw_obj = None
    if fw:
        fw_obj = VoltageFeedbackFW(2 * math.pi * ctl.get("fw_bandwidth_hz", 20.0), margin)
    advance = ctl.get("advance", n_use)
    rec("advance", advance, "periods", "the timing's use delay (Latency.use_delay)", "advance" in ctl)
    foc_kw = dict(
        alpha_c=alpha_c,
        alpha_s=alpha_s,
        i_max=i_max,
        ts=ts,
        speed_every=speed_every,
        id_mode=policy,
        advance=advance,
        field_weakening=fw_obj,
        setpoint_weight=ctl.get("setpoint_weight", 0.0),
        speed_schedule=schedule,
    )
    foc = FOC.imc(machine, **foc_kw)
    for g in ("kp_d", "ki_d", "kp_q", "ki_q", "kp_w", "ki_w"):
        unit = {"kp": "V/A", "ki": "V/(A·s)"}[g[:2]] if g[-1] != "w" else {"kp": "A·s/rad", "ki": "A/rad"}[g[:2]]
        rule = "IMC: α_c L̂, α_c R̂s" if g[-1] != "w" else "double pole at −α_s: 2α_s Ĵ/K_t, α_s² Ĵ/K_t"
        rec(g, float(getattr(foc, g)), unit, rule)
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
    drive = Drive(foc, inverter, sensorless=True, latency=latency)

    # --- sensors
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

    # --- I-f start-up
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
    rec("if_ramp_s", float(startup.omega_switch / startup.accel), "s",
        "peak ramp torque papers.IF_ACCEL_TORQUE_PU × K_t I_f, ≥ 3 swing periods (IfStartup.for_machine)")  # fmt: skip

    lowest = _lowest_speeds(p, alpha_s, schedule, w_est)
    return DriveFile(
        name=str(raw.get("name", name)),
        machine=machine,
        drive=drive,
        sensors=sensors,
        startup=startup,
        derived=d,
        lowest_speeds=lowest,
        warnings=tuple(warn),
        description=str(raw.get("description", raw.get("name", name))),
        foc_kw=foc_kw,
        table={k: full_raw[k] for k in DRIVE_FILE_KEYS if k in full_raw},
    )


# the flux map's inversion residual allowed, relative to the current: 1000 roundings of the working precision
_INV_TOL = 1e3 * float(np.finfo(np.float32).eps)


def _machine_map(raw: dict, base=None):
    """A file's ``[machine.saturation]`` (:func:`jaxobs.drive.saturation.saturation_from_table`): the tables without
    it, with ``[machine]``'s missing Ld, Lq, psi_f filled from the map by its ``nominal`` rule, the map (or None),
    and what the check prints of it (name -> (value, unit, rule, given)).

    ``nominal`` (the constants the controller and the observers assume): "rated_secant" (default; the secant
    inductances (ψd − ψf)/i_d, ψq/i_q at the rated current's MTPA point on the map, which give the map's flux, so
    its torque and voltage, at that point), "rated_incremental" (∂ψd/∂i_d, ∂ψq/∂i_q there: the current loop's
    plant), "no_load" (the incremental ones at i = 0); ψf is the map's no-load flux in each."""
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
                         f"{_show(nominal)}")  # fmt: skip
    mt = {k: v for k, v in mt.items() if k != "saturation"}
    keys = DRIVE_FILE_KEYS["machine"]
    for k in ("p", "rated_current_a"):
        if k not in mt:
            raise ValueError(f"machine.{k}: missing (required)")
        mt[k] = _value(mt, "machine", k, keys[k])
    i_rated = _S2 * mt["rated_current_a"]
    summ = map_summary(sat, mt["p"], i_rated)
    bad_inverse = sat.state_is_flux and check_inverse(sat, 3.0 * i_rated) > _INV_TOL
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


def _lowest_speeds(p: int, alpha_s: float, schedule: float, w_est: float) -> dict:
    """Observer family -> (the lowest speed, r/min, at which it closes the speed loop, or None; the rule)."""
    floor = max(1.0, SETTLE_PERIODS / p)  # 10 electrical periods in the steady start's 60 s settle limit
    out = {}
    if schedule >= FLL_RATIO:
        fll = (floor, f"speed_schedule {schedule:g} ≥ {FLL_RATIO:g}: α ≤ ωe/{FLL_RATIO:g} at every speed; floor: "
               f"{SETTLE_PERIODS:g} periods within a 60 s settle")  # fmt: skip
    else:
        fll = (_rpm(FLL_RATIO * alpha_s, p), f"ωe ≥ {FLL_RATIO:g} α_s (docs/stability.md; 5.4 α_s for a slower FLL)")
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


def read_drive(path) -> DriveFile:
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


def load_drive(path) -> tuple[PMSMParams, Drive]:
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
