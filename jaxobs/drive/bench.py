"""The simulated benches: the papers' machines on their benches' inertia, the FOC they run, and what the
I-f start-up and the inverter allow on them.

The two benches are two drive files shipped with the package (``jaxobs/data/<name>.toml``, each value with its
source, ASSUMED ones marked): :data:`SHIPPED_DRIVES` maps a name to its file, :func:`shipped_drive` reads it
(:func:`jaxobs.drive.read_drive`, the same checks as any drive file), :func:`bench_machine` is its machine.
:func:`bench_drive` builds the benches' FOC on any machine (the mismatched machines of ``jaxobs.reproduce``).

- ``"spmsm000"``: 000 Table II's SPMSM (p = 3).  Table II's J = 3.78e-4 kg·m² is the motor's; the bench
  couples a load machine, so we ASSUME a total J = :data:`jaxobs.papers.BENCH_J_000` (10×).
- ``"ipmsm002"``: the ASSUMED IPMSM of 002 (p = 5, :data:`jaxobs.papers.IPMSM_002`) on the ASSUMED bench
  inertia :data:`jaxobs.papers.BENCH_J_002` (10× the motor's: with the motor alone an 80 % load step stalls
  the drive before any speed loop reacts).

The FOC of both benches: IMC current loop α_c = 2π·:data:`~jaxobs.papers.BENCH_CURRENT_HZ` rad/s, I-P
speed loop α_s = 2π·:data:`~jaxobs.papers.BENCH_SPEED_HZ` rad/s (:meth:`jaxobs.drive.FOC.imc`).
"""

from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import Any, Literal

import jax

from .. import papers
from .control import FOC, IfStartup
from .drivefile import DriveFile, read_drive, speed_limit
from .hardware import Inverter
from .latency import Latency
from .loop import Drive
from .machine import PMSMParams
from .weakening import map_speed_flux

__all__ = [
    "IF_SUDDEN_LOAD_PU",
    "SHIPPED_DRIVES",
    "bench_drive",
    "bench_machine",
    "drive_speed_limit_rpm",
    "if_handover_earliest",
    "if_load_limit",
    "ipmsm_paper002",
    "shipped_drive",
    "spmsm_paper000",
]

_DATA = Path(__file__).resolve().parent.parent / "data"
# the drive files shipped with the package: name -> its file (jaxobs/data)
SHIPPED_DRIVES = {"ipmsm002": _DATA / "ipmsm002.toml", "spmsm000": _DATA / "spmsm000.toml"}


def shipped_drive(name: str) -> DriveFile:
    """The shipped drive file ``name``, read and checked once per precision.

    Args:
        name: A key of :data:`SHIPPED_DRIVES`.

    Returns:
        The :class:`DriveFile`.

    Raises:
        ValueError: an unknown name, in one line naming the shipped ones.
    """
    if name not in SHIPPED_DRIVES:
        raise ValueError(f"machine must be one of {', '.join(SHIPPED_DRIVES)} or a drive file (.toml), got {name!r}")
    # keyed by the precision too: the file's arrays take the dtype of the moment they are read, and a process
    # that switches jax_enable_x64 (a benchmark timing float32 then float64) must not get float32 parameters
    # into a float64 drive (its loop's carry would change dtype in the first step)
    return _read_shipped(name, bool(jax.config.jax_enable_x64))  # pyright: ignore[reportAttributeAccessIssue]  # stub lacks flags


@functools.cache
def _read_shipped(name: str, x64: bool) -> DriveFile:
    return read_drive(SHIPPED_DRIVES[name])


def bench_machine(name: str = "ipmsm002", **overrides: Any) -> PMSMParams:
    """The machine of a shipped drive file, on its bench's inertia (kg·m²).

    Args:
        name: A key of :data:`SHIPPED_DRIVES`.
        **overrides: Other parameters (e.g. ``a5``, ``a7`` or a mismatched ``Rs``), as the presets take them.

    Returns:
        The :class:`PMSMParams`.

    Raises:
        ValueError: an unknown name or a refused parameter.
    """
    m = shipped_drive(name).machine
    if not overrides:
        return m
    kw = dict(Rs=m.Rs, Ld=m.Ld, Lq=m.Lq, psi_f=m.psi_f, J=m.J, p=m.p, B=m.B, a5=m.a5, a7=m.a7, T_rated=m.T_rated,
              n_rated=m.n_rated, q_sat=m.q_sat)  # fmt: skip
    unknown = set(overrides) - set(kw)
    if unknown:
        raise ValueError(f"bench_machine: unknown parameter(s) {', '.join(sorted(unknown))}; allowed: {', '.join(kw)}")
    return PMSMParams(**{**kw, **overrides})


def _paper_machine(name, inertia, motor_J, overrides) -> PMSMParams:
    if inertia not in ("bench", "motor"):
        raise ValueError(f"inertia must be 'bench' or 'motor', got {inertia!r}")
    if inertia == "motor" and "J" in overrides:
        raise ValueError("give the inertia once: inertia='motor' or J=..., not both")
    return bench_machine(name, **({"J": motor_J} if inertia == "motor" else {}), **overrides)


def spmsm_paper000(*, inertia: Literal["bench", "motor"] = "bench", **overrides: Any) -> PMSMParams:
    """Paper 000's SPMSM: the machine of the shipped drive file ``spmsm000`` (``jaxobs/data/spmsm000.toml``), the
    one ``jaxobs reproduce flux``, drive jobs and studies simulate.

    Table II: ψf = 0.35 Wb, 2000 r/min, 3 pole pairs, L = 5 mH, Rs = 0.8 Ω, 14 N·m, J = 3.78e-4 kg·m²
    (:data:`jaxobs.papers.SPMSM_000`); friction is not given, B = 0.  Table II's J is the motor's; the bench
    couples a load machine, so the bench's J is :data:`jaxobs.papers.BENCH_J_000` (10×, ASSUMED).

    Args:
        inertia: ``"bench"`` (default: the drive file's J, the bench's total) or ``"motor"`` (Table II's J,
            the motor alone).
        **overrides: :class:`PMSMParams` keywords that replace the file's values (``J`` among them).

    Returns:
        The :class:`PMSMParams`.

    Raises:
        ValueError: an unknown ``inertia`` or parameter, or both ``inertia="motor"`` and ``J``.
    """
    return _paper_machine("spmsm000", inertia, papers.SPMSM_000["J"], overrides)


def ipmsm_paper002(*, inertia: Literal["bench", "motor"] = "bench", **overrides: Any) -> PMSMParams:
    """The IPMSM for paper 002's operating points: the machine of the shipped drive file ``ipmsm002``
    (``jaxobs/data/ipmsm002.toml``), the one ``jaxobs reproduce leso --machine single``, drive jobs and studies
    simulate.  Its values are ASSUMED (our copy lacks 002's machine table; :data:`jaxobs.papers.IPMSM_002`).

    002 runs 300/600/840 r/min at 25/50/70 Hz, so p = 5.  The rest is chosen as a plausible ~2 kW lab machine
    and documented as assumed:

    - Rs = 0.6 Ω, Ld = 6 mH, Lq = 12 mH (saliency 2, an IPMSM),
    - ψf = 0.45 Wb: BEMF 141 V peak at 600 r/min, 198 V at 840 r/min,
    - motor J = 5e-3 kg·m², B = 1e-3 N·m·s/rad, rated 30 N·m at 600 r/min (8.9 A at i_d = 0); the bench's J
      is :data:`jaxobs.papers.BENCH_J_002` (10×: with the motor alone an 80 % load step stalls the drive).

    002's machine is dual three-phase under vector space decomposition; this is its αβ subspace, the one the
    observers see (002 eqs 4–5), as an equivalent three-phase machine (the whole dual machine:
    :func:`jaxobs.drive.dual_ipmsm_paper002`).  002 Sec. V-B runs one set alone to expose the 5th and 7th BEMF
    harmonics; ``a5``/``a7`` model that case.

    Args:
        inertia: ``"bench"`` (default: the drive file's J) or ``"motor"`` (the motor alone).
        **overrides: :class:`PMSMParams` keywords that replace the file's values (``J`` among them).

    Returns:
        The :class:`PMSMParams`.

    Raises:
        ValueError: an unknown ``inertia`` or parameter, or both ``inertia="motor"`` and ``J``.
    """
    return _paper_machine("ipmsm002", inertia, papers.IPMSM_002["J"], overrides)


def bench_drive(
    machine: PMSMParams,
    *,
    sensorless: bool = True,
    handover: float = 0.0,
    settle: float = 0.2,
    startup: IfStartup | None = None,
    alpha_s: float | None = None,
    ts: float | None = None,
    latency: Latency | None = None,
    inverter: Inverter | None = None,
    **foc_kw: Any,
) -> Drive:
    """The bench's drive: IMC current loop at 2π·BENCH_CURRENT_HZ rad/s, I-P speed loop at ``alpha_s``.

    Args:
        machine: The machine the FOC assumes.
        sensorless: Whether the observer closes the loop.
        handover: The time from which the observer closes the loop, s.
        settle: The observer's unscored settling before t = 0, s.
        startup: An I-f start-up from standstill (:meth:`IfStartup.for_machine`), or None (each scenario
            starts steady).
        alpha_s: The speed loop's bandwidth, rad/s (default 2π·BENCH_SPEED_HZ).
        ts: The control period, s (default the FOC's).
        latency: As :class:`Drive` takes it (default :class:`Latency`'s timing).
        inverter: As :class:`Drive` takes it (default a 540 V :class:`Inverter`).
        **foc_kw: :class:`FOC`'s options (``advance``, ``field_weakening``, ``speed_schedule``, ...).

    Returns:
        The :class:`Drive`.
    """
    alpha_s = 2 * math.pi * papers.BENCH_SPEED_HZ if alpha_s is None else alpha_s
    kw = dict(foc_kw) if ts is None else {"ts": ts, **foc_kw}
    foc = FOC.imc(machine, alpha_c=2 * math.pi * papers.BENCH_CURRENT_HZ, alpha_s=alpha_s, **kw)
    return Drive(
        foc, inverter, sensorless=sensorless, handover=handover, settle=settle, startup=startup, latency=latency
    )


# The sudden-load limit of a synchronous machine held by a current vector (the equal-area criterion): a torque
# T applied at once to a rotor at rest in the I-f frame swings it, undamped, from δ = 0 past its load angle δ0
# (T = T_max sin δ0) to δ_peak with ∫0^δpeak (T_max sin δ − T) dδ = 0; it pulls out unless δ_peak ≤ π − δ0,
# i.e. 1 + cos δ0 ≥ (π − δ0) sin δ0: δ0 ≤ 46.44°, T ≤ 0.7246 T_max.
IF_SUDDEN_LOAD_PU = 0.7246


def if_load_limit(machine: PMSMParams, dJ: float = 0.0, startup: IfStartup | None = None) -> float:
    """The largest load that ``machine`` may carry during its I-f start-up.

    During I-f the rotor is held by the current vector I_f only: its torque is at most T_max = K_t I_f (the
    magnet torque; an IPMSM's reluctance torque is left out).  The load is on from t = 0 (a step), so the
    sudden-load limit applies (:data:`IF_SUDDEN_LOAD_PU`); the ramp's peak acceleration torque J·a_peak
    (a_peak = 2 × the mean for the raised cosine) and the friction at the switch speed B·ω_sw count as load
    too — conservatively, as if sudden (they build up gradually).  Hence

        T_L ≤ 0.7246 K_t I_f − J (1 + dJ) a_peak − B ω_m,sw.

    On 000's SPMSM bench: 0.7246 · 7.0 − 1.25 − 0 = 3.82 N·m; measured with the SOIFO at 1000 r/min, 4.5 N·m
    still started and 5.0 N·m ran backwards (−320 r/min, flagged lost_speed): sufficient, not necessary.

    Args:
        machine: The machine.
        dJ: The relative inertia error: the inertia is scaled by ``1 + dJ``.
        startup: The I-f start-up (default :meth:`IfStartup.for_machine`: a drive file states its own).

    Returns:
        The load limit, N·m.
    """
    s = IfStartup.for_machine(machine) if startup is None else startup
    a_peak_m = float(s.accel) / machine.p * (2.0 if s.smooth else 1.0)  # mechanical, rad/s²
    w_sw_m = float(s.omega_switch) / machine.p
    return (
        IF_SUDDEN_LOAD_PU * float(machine.kt) * float(s.i_f)
        - float(machine.J) * (1.0 + dJ) * a_peak_m
        - float(machine.B) * w_sw_m
    )


def if_handover_earliest(machine: PMSMParams, startup: IfStartup | None = None) -> float:
    """The earliest time the I-f start-up of ``machine`` can hand over.

    The ramp to the switch speed, then both the hold and the agreement's dwell at it (they run at the same
    time).

    Args:
        machine: The machine.
        startup: The I-f start-up (default :meth:`IfStartup.for_machine`).

    Returns:
        The time, s.
    """
    s = IfStartup.for_machine(machine) if startup is None else startup
    return float(s.omega_switch / s.accel) + max(float(s.hold), float(s.dwell))


def drive_speed_limit_rpm(machine: PMSMParams, inverter: Inverter | None = None) -> float:
    """The highest speed a drive may ask of ``machine``.

    The speed at which the back EMF alone, ωe ψf, reaches the inverter's voltage limit u_max = U_dc/√3: the
    drive file's one rule without field weakening (a saturation map's no-load flux where the machine has one;
    :func:`jaxobs.drive.drivefile.speed_limit`; a drive file
    states its own: ``DriveFile.derived["speed_limit_rpm"]``).  Above it an FOC without field
    weakening (i_d* is 0 or MTPA, never negative) cannot hold even zero current:
    the machine would run away from its reference.
    It is a no-load bound (load adds Rs·i and ωe·Lq·i to the voltage), so it is necessary, not sufficient:
    ipmsm002 1323 r/min (2.2 × its 600 r/min rating), spmsm000 2835 r/min (1.4 × 2000 r/min).

    Args:
        machine: The machine.
        inverter: The inverter (default the benches' :class:`Inverter`).

    Returns:
        The speed, r/min (either direction).
    """
    u_max = float((Inverter() if inverter is None else inverter).u_max)
    return speed_limit(machine.p, float(machine.psi_f), float(machine.Ld), math.inf, u_max, False,
                       float(machine.n_rated), None, map_speed_flux(machine, math.inf, False))[0]  # fmt: skip
