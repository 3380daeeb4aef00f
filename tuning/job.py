"""TOML tuning jobs: parse, validate (every error names its field), build, run, report.

A job file::

    [job]
    name = "wif-robust"
    component = "SOGIFLLWIF"        # SOGIFLL | SOGIFLLWPF | SOGIFLLWIF | SOIFO | SecondOrderSOIFO | LPFFlux
                                     # | CLESO | GILESO | FALESO
    seed = 0

    [component]                      # constructor values; frozen unless listed in [gains]
    k1 = 1.815
    k2 = 0.752
    lam = 11559.0

    [gains.lam]                      # a free gain: initial value, bounds, log parametrization
    init = 11559.0
    lower = 1000.0
    upper = 100000.0
    log = true

    [scenarios]                      # "grid" signals for the FLL family, "emf" for flux observers,
                                     # "drive" for the drive observers (LESOs, LPFFlux, the SOIFOs)
    signal = "grid"
    t_event = 0.1
    horizon = 0.4
    steady_from = 0.3
    [scenarios.grid]                 # cartesian product of named axes
    freq_step = [-2.0, 2.0]
    phase_jump_deg = [-30.0, 30.0]

    [holdout]                        # optional: a held-out set, scored but never tuned on
    [holdout.grid]
    freq_step = [-1.5, 1.5]

    [drive]                          # drive jobs only (scenarios.signal = "drive")
    loop = "sensorless"              # sensorless (the tuned observer closes the loop) | sensored
    machine = "spmsm000"             # ipmsm002 | spmsm000; default: the component's (LESOs 002, flux 000)

    [objective]
    terms = [{ metric = "itae_freq", weight = 1.0 }]
    aggregate = "cvar"               # mean | max | cvar
    alpha = 0.9
    penalty = 1000.0

    [solver]
    kind = "adam"                    # adam | adamw | sgd | bfgs
    learning_rate = 0.05
    steps = 60
    patience = 20
    checkpoint_every = 5
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import jaxobs
from jaxobs import drive as D
from jaxobs import linear, papers
from jaxobs import metrics as M
from jaxobs.drive import BENCH_MACHINES
from jaxobs.drive_study import DRIVE_STUDY_AXES, bind_observer, drive_scenarios
from jaxobs.progress import Progress
from jaxobs.provenance import sha256, versions
from jaxobs.scenarios import Grid, Random, grid_signals
from jaxobs.signals import EMFSignal, stack

from . import strategies
from .aggregations import AbstractAggregation
from .objective import DRIVE_METRICS, LOST_SYNC_DEG, METRICS, MetricContext, Objective, Term
from .outdir import atomic_path, atomic_write_text
from .params import GainSpec, Parametrization
from .report import write_report
from .solvers import AbstractSolver, tune
from .structure import structure

__all__ = ["JobError", "Job", "load_job", "parse_job", "run_job", "COMPONENTS", "rule_spec", "write_json"]


class JobError(ValueError):
    """A problem with a job file; ``str()`` is one line naming the field, at most :data:`MAX_ERROR` characters."""

    def __init__(self, field: str, message: str):
        self.field = field
        field = _cap(field, 80)
        line = " ".join(f"{field}: {message}".split())  # one line, whatever the message holds
        super().__init__(_cap(line, MAX_ERROR))


MAX_ERROR = 200  # characters in a job-file error
MAX_FILE_BYTES = 1_000_000  # a job file larger than this is refused before it is parsed
MAX_DEPTH = 20  # nesting of tables, arrays and dotted keys
MAX_STEPS = 10_000_000  # time steps of one simulation (horizon / ts)
MAX_SCENARIOS = 1_000_000  # scenarios of a grid or of `sample`
MAX_INT = 2**63 - 1
MAX_SOLVER_STEPS = 1_000_000
# bytes a simulation keeps per scenario and time step while its gradient is taken (states, outputs and
# their cotangents, float64): an estimate for the memory check, not a measurement
BYTES_PER_STEP = {"grid": 512, "emf": 512, "drive": 2048}


def _cap(text: str, n: int) -> str:
    return text if len(text) <= n else text[: n - 1] + "…"


def _show(v) -> str:
    """A value for an error message: its repr, long ones elided."""
    if isinstance(v, int) and not isinstance(v, bool) and abs(v) > 10**20:
        return f"an integer of {len(str(abs(v)))} digits"
    try:
        r = repr(v) if not isinstance(v, (list, dict)) or len(v) <= 8 else f"{type(v).__name__} of {len(v)}"
    except (RecursionError, ValueError):
        r = type(v).__name__
    return _cap(r, 60)


# --------------------------------------------------------------------------
# components: constructor, free gains, closed form
# --------------------------------------------------------------------------

W_N = papers.FLL_OMEGA_N
SOIFO_K, SOIFO2_K1, SOIFO2_K2 = papers.SOIFO_K, papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2


def _cf_sogi(comp):
    k = papers.SOGI_FLL_K
    return {"k": k, "lam": float(linear.sogi_fll_lambda(k, float(comp.omega_n)))}


def _cf_wpf(comp):
    return {"k1": papers.WPF_K1, "k2": papers.WPF_K2, "lam": float(linear.wpf_lambda(float(comp.omega_n)))}


def _cf_wif(comp):
    k1, k2, lam = linear.wif_symmetric_optimum(papers.WIF_B, papers.WIF_OMEGA_C, float(comp.omega_n))
    return {"k1": float(k1), "k2": float(k2), "lam": float(lam)}


def _cf_soifo(comp):
    return {"k": SOIFO_K, "lam": linear.soifo_lambda(SOIFO_K)}


def _cf_sosoifo(comp):
    return {"K1": SOIFO2_K1, "K2": SOIFO2_K2, "lam": linear.second_order_soifo_lambda(SOIFO2_K1, SOIFO2_K2)}


def _cf_lpf(comp):
    return {"omega_c": papers.LPF_OMEGA_C, **_flux_pll_cf()}


def _flux_pll_cf():
    kp, ki = linear.pll_gains(2 * math.pi * papers.FLUX_PLL_HZ)
    return {"kp_pll": float(kp), "ki_pll": float(ki)}


def _cf_cleso(comp):
    return {"omega0": papers.LESO_OMEGA0}


def _pll_cf():
    kp, ki = linear.pll_gains(2 * math.pi * papers.LESO_PLL_HZ)
    return {"kp_pll": float(kp), "ki_pll": float(ki)}


def _cf_faleso(comp):
    return {"k1": papers.FALESO_K1, "k2": papers.FALESO_K2, **_pll_cf()}


@dataclass(frozen=True)
class ComponentInfo:
    ctor: object
    gains: tuple
    defaults: dict
    closed_form: object
    signal: str
    closed_form_source: str
    bind: object = None
    # the machines a sensorless drive job may run this component on, the default first (BENCH_MACHINES);
    # empty: no drive jobs.  A component whose ``signal`` is "emf" runs on EMF signals by default and in the
    # drive with ``scenarios.signal = "drive"``.
    machines: tuple = ()

    @property
    def signals(self) -> tuple:
        """The scenario signals this component runs on, its default first."""
        return (self.signal, "drive") if self.machines and self.signal != "drive" else (self.signal,)


_IPMSM = papers.IPMSM_002  # the LESO drive jobs' machine (ASSUMED, see jaxobs.papers): the LESOs assume its Rs, Lq
# A LESO's extended-EMF model (002 eqs 4–5) holds on a non-salient machine too (Ld = Lq), so the LESOs
# may run on 000's SPMSM; the flux observers may not run on the IPMSM: their back EMF u − R̂s i − L̂ di/dt
# with one inductance is not dψ_f/dt on a salient machine.
_LESO_MACHINES = ("ipmsm002", "spmsm000")

COMPONENTS = {
    "SOGIFLL": ComponentInfo(
        jaxobs.SOGIFLL,
        gains=("k", "lam"),
        defaults=dict(k=papers.SOGI_FLL_K, lam=papers.SOGI_FLL_LAM, omega_n=W_N),
        closed_form=_cf_sogi,
        signal="grid",
        closed_form_source="001 eq (22), Table I",
    ),
    "SOGIFLLWPF": ComponentInfo(
        jaxobs.SOGIFLLWPF,
        gains=("k1", "k2", "lam"),
        defaults=dict(k1=papers.WPF_K1, k2=papers.WPF_K2, lam=papers.WPF_LAM, omega_n=W_N),
        closed_form=_cf_wpf,
        signal="grid",
        closed_form_source="001 eq (29), Table I",
    ),
    "SOGIFLLWIF": ComponentInfo(
        jaxobs.SOGIFLLWIF,
        gains=("k1", "k2", "lam"),
        defaults=dict(k1=papers.WIF_K1, k2=papers.WIF_K2, lam=papers.WIF_LAM, omega_n=W_N),
        closed_form=_cf_wif,
        signal="grid",
        closed_form_source="001 eq (34), Table I",
    ),
    "SOIFO": ComponentInfo(
        jaxobs.SOIFO,
        gains=("k", "lam"),
        defaults=dict(Rs=0.0, L=1.0, k=SOIFO_K, lam=0.5, omega0=W_N),
        closed_form=_cf_soifo,
        signal="emf",
        closed_form_source="000 (k = 1.414), lam = k²/4",
        machines=("spmsm000",),
    ),
    "SecondOrderSOIFO": ComponentInfo(
        jaxobs.SecondOrderSOIFO,
        gains=("K1", "K2", "lam"),
        defaults=dict(
            Rs=0.0,
            L=1.0,
            K1=SOIFO2_K1,
            K2=SOIFO2_K2,
            lam=linear.second_order_soifo_lambda(SOIFO2_K1, SOIFO2_K2),
            omega0=W_N,
        ),
        closed_form=_cf_sosoifo,
        signal="emf",
        closed_form_source="000 (K1 = 1.56, K2 = 3.11), lam = K1³/(2K2)",
        machines=("spmsm000",),
    ),
    # 000's LPF flux estimator ψ̂ = ê/(s + ωc), uncompensated as in 000 Fig. 5, with the type-2 PLL (ASSUMED,
    # papers.FLUX_PLL_HZ) that gives it a speed: drive jobs only (on a bare EMF signal its PLL has nothing
    # to close).  The pure integrator is no job component: its flux starts from zero, so its circle is
    # offset by the flux at its start (000's "unknown integral initial value") and θ̂ is wrong by up to
    # 90° whatever its PLL gains; in a sensorless drive it loses synchronism (README, "Drive jobs").
    "LPFFlux": ComponentInfo(
        jaxobs.LPFFlux,
        gains=("omega_c", "kp_pll", "ki_pll"),
        defaults=dict(
            Rs=papers.SPMSM_000["Rs"], L=papers.SPMSM_000["Ld"], omega_c=papers.LPF_OMEGA_C, **_flux_pll_cf()
        ),
        closed_form=_cf_lpf,
        signal="drive",
        closed_form_source="000 Fig. 5 (omega_c = 100 rad/s), PLL pole placement omega_b = 2 pi 20 (ASSUMED)",
        bind=bind_observer,  # the scenario's assumed Rs, L; the PLL starts at its speed
        machines=("spmsm000",),
    ),
    # the drive jobs run the ASSUMED IPMSM of jaxobs.papers; a LESO starts from its Rs and Lq
    "CLESO": ComponentInfo(
        jaxobs.CLESO,
        gains=("omega0", "kp_pll", "ki_pll"),
        defaults=dict(Rs=papers.IPMSM_002["Rs"], Lq=papers.IPMSM_002["Lq"], omega0=papers.LESO_OMEGA0, **_pll_cf()),
        closed_form=lambda c: {**_cf_cleso(c), **_pll_cf()},
        signal="drive",
        closed_form_source="002 Table II (ω0 = 500π), PLL pole placement ω_b = 2π·15",
        bind=bind_observer,  # the scenario's assumed Rs, Lq; the PLL starts at its speed
        machines=_LESO_MACHINES,
    ),
    "GILESO": ComponentInfo(
        jaxobs.GILESO,
        gains=("omega0", "K_r", "omega_c", "kp_pll", "ki_pll"),
        defaults=dict(
            Rs=papers.IPMSM_002["Rs"],
            Lq=papers.IPMSM_002["Lq"],
            omega0=papers.LESO_OMEGA0,
            K_r=papers.GILESO_K_R,
            omega_c=papers.GILESO_OMEGA_C,
            **_pll_cf(),
        ),
        closed_form=lambda c: {
            "omega0": papers.LESO_OMEGA0,
            "K_r": papers.GILESO_K_R,
            "omega_c": papers.GILESO_OMEGA_C,
            **_pll_cf(),
        },
        signal="drive",
        closed_form_source="002 Table II (ω0 = 500π, K_r = 2ω0², ωc = π), PLL pole placement ω_b = 2π·15",
        bind=bind_observer,  # the scenario's assumed Rs, Lq; the PLL starts at its speed
        machines=_LESO_MACHINES,
    ),
    "FALESO": ComponentInfo(
        jaxobs.FALESO,
        gains=("k1", "k2", "kp_pll", "ki_pll"),
        defaults=dict(
            Rs=papers.IPMSM_002["Rs"], Lq=papers.IPMSM_002["Lq"], k1=papers.FALESO_K1, k2=papers.FALESO_K2, **_pll_cf()
        ),
        closed_form=_cf_faleso,
        signal="drive",
        closed_form_source="002 Table II (k1 = 10π, k2 = 100π), PLL pole placement ω_b = 2π·15",
        bind=bind_observer,  # the scenario's assumed Rs, Lq; the PLL starts at its speed
        machines=_LESO_MACHINES,
    ),
}

GRID_AXES = ("freq_step", "phase_jump_deg", "sag", "dc", "harmonics_scale", "sub_amplitude", "phase_deg")
# (an "omega0_error" axis was accepted and ignored: removed.  The flux observers start their FLL at
# omega0 = 2π·50 Hz whatever speed_hz is, so speed_hz already sets the initial frequency error.)
EMF_AXES = ("speed_hz", "dc_alpha", "dc_beta", "h5", "h7", "phase_deg")
# paper 002's IPMSM (assumed, see the README) on its bench: jaxobs.drive_study's axes (units and ranges there)
DRIVE_AXES = tuple(DRIVE_STUDY_AXES)


# --------------------------------------------------------------------------
# validation helpers
# --------------------------------------------------------------------------


def _get(table: dict, key: str, field: str, kind, default=None, required=False):
    if key not in table:
        if required:
            raise JobError(field, "missing (required)")
        return default
    v = table[key]
    if kind is float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise JobError(field, f"must be a number, got {type(v).__name__} {_show(v)}")
        return _finite(v, field)
    if kind is int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise JobError(field, f"must be an integer, got {type(v).__name__} {_show(v)}")
        if abs(v) > MAX_INT:
            raise JobError(field, f"out of range (|value| <= 2^63 - 1), got {_show(v)}")
        return v
    if kind is bool:
        if not isinstance(v, bool):
            raise JobError(field, f"must be true or false, got {_show(v)}")
        return v
    if kind is str:
        if not isinstance(v, str):
            raise JobError(field, f"must be a string, got {type(v).__name__} {_show(v)}")
        return v
    if kind is list:
        if not isinstance(v, list) or not v:
            raise JobError(field, f"must be a non-empty list of numbers, got {_show(v)}")
        if len(v) > MAX_SCENARIOS:
            raise JobError(field, f"too many values ({len(v)} > {MAX_SCENARIOS})")
        for i, x in enumerate(v):
            if isinstance(x, bool) or not isinstance(x, (int, float)):
                raise JobError(f"{field}[{i}]", f"must be a finite number, got {type(x).__name__} {_show(x)}")
            _finite(x, f"{field}[{i}]")
        return [float(x) for x in v]
    if kind is dict:
        if not isinstance(v, dict):
            raise JobError(field, f"must be a table, got {type(v).__name__}")
        return v
    raise AssertionError(kind)


def _finite(v, field: str) -> float:
    """``v`` as a finite float: an integer beyond the float range (10^309) or NaN / inf is an error."""
    try:
        f = float(v)
    except OverflowError:
        raise JobError(field, f"out of the float range, got {_show(v)}") from None
    if not math.isfinite(f):
        raise JobError(field, f"must be finite, got {_show(v)}")
    return f


def _no_unknown(table: dict, allowed, where: str):
    for key in table:
        if key not in allowed:
            raise JobError(f"{where}.{_cap(str(key), 40)}", f"unknown key; allowed: {', '.join(allowed)}")


# --------------------------------------------------------------------------
# the job
# --------------------------------------------------------------------------


@dataclass
class ScenarioSpec:
    signal: str
    t_event: float
    horizon: float
    steady_from: float
    axes: dict  # name -> list of values
    sample: int  # 0: full grid; n > 0: n random combinations (seeded)
    seed: int
    recording: RecordingSpec | None = None  # [scenarios.recording]: recorded signals instead of a grid


@dataclass
class Job:
    raw: dict
    name: str
    component: str
    seed: int
    values: dict  # constructor values
    gains: list  # GainSpec
    scenarios: ScenarioSpec
    holdout: ScenarioSpec | None
    terms: list
    aggregation: AbstractAggregation  # objective.aggregate (with alpha, temperature), tuning.strategies
    penalty: float
    solver: AbstractSolver  # [solver], tuning.strategies
    sha256: str | None = None  # of the job file's bytes (load_job); None for a job built from a dict
    drive: DriveSpec | None = None  # signal = "drive" jobs: how the observer sits in the loop


@dataclass(frozen=True)
class DriveSpec:
    """``[drive]`` of a drive job: ``loop = "sensorless"`` (the default: the tuned observer closes the loop,
    from t = 0 after its settling phase, or from ``handover`` s on) or ``"sensored"`` (the encoder closes it and
    the observer estimates beside it); ``settle`` (s): the observer's unscored settling phase before t = 0;
    ``start``: ``"steady"`` (each scenario starts in its operating point) or ``"standstill"`` (from rest, by
    the I-f start-up :meth:`jaxobs.drive.IfStartup.for_machine` of the job's machine, then its hand-over);
    ``machine``: the drive's machine (:data:`BENCH_MACHINES`; by default the component's: the LESOs run
    002's IPMSM, the flux observers 000's SPMSM)."""

    loop: str = "sensorless"
    handover: float = 0.0
    settle: float = 0.2
    start: str = "steady"
    machine: str = "ipmsm002"  # a key of BENCH_MACHINES; a job's default is its component's first machine


# the physical range of every scenario axis (closed intervals unless noted), checked at --check time;
# freq_step is checked against the component's nominal frequency, speed_hz against the sample rate
AXIS_RANGES = {
    "grid": {
        "freq_step": ("Hz", (-1e4, 1e4)),
        "phase_jump_deg": ("deg", (-360.0, 360.0)),
        "sag": ("1", (0.0, 0.999)),
        "dc": ("pu", (-10.0, 10.0)),
        "harmonics_scale": ("1", (0.0, 100.0)),
        "sub_amplitude": ("pu", (0.0, 10.0)),
        "phase_deg": ("deg", (-360.0, 360.0)),
    },
    "emf": {
        "speed_hz": ("Hz", (1e-3, 1e4)),
        "dc_alpha": ("V", (-1e4, 1e4)),
        "dc_beta": ("V", (-1e4, 1e4)),
        "h5": ("1", (0.0, 10.0)),
        "h7": ("1", (0.0, 10.0)),
        "omega0_error": ("1", (-0.99, 10.0)),
        "phase_deg": ("deg", (-360.0, 360.0)),
    },
    "drive": DRIVE_STUDY_AXES,
}


def _available_memory() -> int:
    """Bytes of memory available now (MemAvailable on Linux, else the physical memory; 16 GiB if unknown)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return 16 * 2**30


def _check_size(spec: ScenarioSpec, where: str, ts: float, extra_s: float = 0.0) -> None:
    """Time steps, scenario count and the memory a simulation of the batch needs, at --check time."""
    n_scen = spec.sample or math.prod(len(v) for v in spec.axes.values())  # a recording: one per file
    if n_scen > MAX_SCENARIOS:
        raise JobError(f"{where}.grid", f"{n_scen} scenarios (the product of the axes' lengths) > {MAX_SCENARIOS}")
    steps = (spec.horizon + extra_s) / ts
    if spec.horizon < ts:
        raise JobError(f"{where}.horizon", f"shorter than one sample (ts = {ts:g} s), got {spec.horizon:g} s")
    if steps > MAX_STEPS:
        raise JobError(f"{where}.horizon", f"{steps:.3g} time steps of {ts:g} s > {MAX_STEPS:g}: too long")
    if (spec.horizon - spec.steady_from) / ts < 10:
        raise JobError(
            f"{where}.steady_from",
            f"the steady window [{spec.steady_from:g}, {spec.horizon:g}) s holds fewer than 10 samples of {ts:g} s",
        )
    need = steps * n_scen * BYTES_PER_STEP[spec.signal]
    have = _available_memory()
    if need > have:
        raise JobError(
            f"{where}.horizon",
            f"{n_scen} scenarios x {steps:.3g} steps need about {need / 2**30:.3g} GiB, "
            f"{have / 2**30:.3g} GiB available: shorten the horizon or use fewer scenarios",
        )


def _parse_scenarios(
    tab: dict, where: str, signals: tuple, seed: int, freq_n: float, ts: float, base: Path | None = None
) -> ScenarioSpec:
    """``signals``: the component's (its default first); ``base``: the job file's folder (recordings)."""
    tab = _get({"s": tab}, "s", where, dict)
    _no_unknown(tab, ("signal", "t_event", "horizon", "steady_from", "grid", "sample", "seed", "recording"), where)
    signal = _get(tab, "signal", f"{where}.signal", str, signals[0])
    if signal not in ("grid", "emf", "drive"):
        raise JobError(f"{where}.signal", f"must be 'grid', 'emf' or 'drive', got {_show(signal)}")
    if signal not in signals:
        need = " or ".join(f"'{x}'" for x in signals)
        raise JobError(f"{where}.signal", f"the component needs {need} signals, got {_show(signal)}")
    t_event = _get(tab, "t_event", f"{where}.t_event", float, 0.1)
    horizon = _get(tab, "horizon", f"{where}.horizon", float, 0.4)
    if t_event < 0:
        raise JobError(f"{where}.t_event", f"must be >= 0 s, got {t_event}")
    if horizon <= t_event:
        raise JobError(f"{where}.horizon", f"must exceed t_event ({t_event:g} s), got {horizon:g}")
    if horizon > MAX_STEPS * ts:
        raise JobError(f"{where}.horizon", f"{horizon:g} s is more than {MAX_STEPS:g} time steps of {ts:g} s")
    steady = _get(tab, "steady_from", f"{where}.steady_from", float, t_event + 0.75 * (horizon - t_event))
    if not (0 <= steady < horizon):
        raise JobError(f"{where}.steady_from", f"must be in [0, horizon), got {steady:g}")
    if "recording" in tab:
        return _parse_recording_scenarios(tab, where, signal, t_event, horizon, steady, seed, ts, base)
    grid = _get(tab, "grid", f"{where}.grid", dict, required=True)
    allowed = AXIS_RANGES[signal]
    axes = {}
    if not grid:
        raise JobError(f"{where}.grid", f"at least one axis is required; allowed: {', '.join(allowed)}")
    for k in grid:
        if k not in allowed:
            raise JobError(f"{where}.grid.{_cap(k, 40)}", f"unknown axis; allowed: {', '.join(allowed)}")
        v = axes[k] = _get(grid, k, f"{where}.grid.{k}", list)
        unit, (lo, hi) = allowed[k]
        if signal == "grid" and k == "freq_step":  # the frequency stays in (0, 1/(4 ts)]
            lo, hi = max(lo, -freq_n * (1 - 1e-6)), min(hi, 0.25 / ts - freq_n)
        if signal == "emf" and k == "speed_hz":
            hi = min(hi, 0.25 / ts)
        for i, x in enumerate(v):
            if not lo <= x <= hi:
                u = "" if unit == "1" else f" {unit}"
                raise JobError(f"{where}.grid.{k}[{i}]", f"must be in [{lo:g}, {hi:g}]{u}, got {x:g}")
    sample = _get(tab, "sample", f"{where}.sample", int, 0)
    if not 0 <= sample <= MAX_SCENARIOS:
        raise JobError(f"{where}.sample", f"must be in [0, {MAX_SCENARIOS}] (0: the full grid), got {_show(sample)}")
    sseed = _get(tab, "seed", f"{where}.seed", int, seed)
    if not 0 <= sseed < 2**32:
        raise JobError(f"{where}.seed", f"must be in [0, 2^32), got {_show(sseed)}")
    return ScenarioSpec(signal, t_event, horizon, steady, axes, sample, sseed)


# --------------------------------------------------------------------------
# [scenarios.recording]: recorded signals as the scenarios
# --------------------------------------------------------------------------

MAX_RECORDING_BYTES = 8 * 2**20  # a recording file of a job or study larger than this is refused
MAX_RECORDINGS = 64  # files of one [scenarios.recording]
# what each kind of job reads from a recording: its signal columns and its truth columns (defaults)
RECORDING_COLUMNS = {
    "grid": (["v"], ["theta", "omega", "amplitude"]),  # v; true phase (rad), ω (rad/s), amplitude
    "emf": (["u_a", "u_b", "i_a", "i_b"], ["theta_e", "omega_e"]),  # u/i; encoder angle (rad), speed (rad/s)
    "drive": (["u_a", "u_b", "i_a", "i_b"], ["theta_e", "omega_e"]),
}


@dataclass(frozen=True)
class RecordingSpec:
    """``[scenarios.recording]``: one scenario per file, read at the component's ``ts``."""

    files: tuple  # as written in the job file
    paths: tuple  # resolved against the job file's folder (or the working folder)
    time_column: object  # a column name or index, or None
    sample_rate: float | None  # Hz, when there is no time column
    columns: tuple
    truth: tuple
    ts: float
    sha256: tuple = ()  # of each file's bytes, when checked at parse time


def _col_spec(v, field: str):
    if isinstance(v, bool) or not isinstance(v, (str, int)) or (isinstance(v, int) and not 0 <= v < 10_000):
        raise JobError(field, f"must be a column name or a 0-based index, got {_show(v)}")
    return v


def _parse_recording_scenarios(tab, where, signal, t_event, horizon, steady, seed, ts, base) -> ScenarioSpec:
    """``[<where>.recording]``: the file(s), the time base, the columns; read and checked now when the job
    file's folder is known (``base``): exists, at most :data:`MAX_RECORDING_BYTES`, the columns present,
    finite, time strictly increasing, sampled at least at 1/ts, long enough for the horizon."""
    w = f"{where}.recording"
    if "grid" in tab or "sample" in tab:
        key = "grid" if "grid" in tab else "sample"
        raise JobError(f"{where}.{key}", "does not apply with a recording: the recordings are the scenarios")
    rec = _get(tab, "recording", w, dict)
    _no_unknown(rec, ("file", "time_column", "sample_rate", "columns", "truth"), w)
    files = rec.get("file")
    if isinstance(files, str):
        files = [files]
    if not isinstance(files, list) or not files or not all(isinstance(f, str) and f for f in files):
        raise JobError(f"{w}.file", f"missing (required): a CSV file name or a list of them, got {_show(files)}")
    if len(files) > MAX_RECORDINGS:
        raise JobError(f"{w}.file", f"{len(files)} files, more than {MAX_RECORDINGS}")
    if ("time_column" in rec) == ("sample_rate" in rec):
        raise JobError(w, "give exactly one of time_column (a column of seconds) and sample_rate (Hz)")
    tcol = _col_spec(rec["time_column"], f"{w}.time_column") if "time_column" in rec else None
    rate = _get(rec, "sample_rate", f"{w}.sample_rate", float)
    if rate is not None and not 0 < rate <= 1e9:
        raise JobError(f"{w}.sample_rate", f"must be in (0, 1e9] Hz, got {rate:g}")
    cols_default, truth_default = RECORDING_COLUMNS[signal]
    cols, truth = rec.get("columns", cols_default), rec.get("truth", truth_default)
    n_truth = (3,) if signal == "grid" else (1, 2)  # grid: theta, omega, amplitude; u/i: theta_e [, omega_e]
    for key, v, n_ok in (("columns", cols, (len(cols_default),)), ("truth", truth, n_truth)):
        if not isinstance(v, list) or len(v) not in n_ok:
            raise JobError(f"{w}.{key}", f"must be a list of {' or '.join(map(str, n_ok))} column(s), got {_show(v)}")
        for i, c in enumerate(v):
            _col_spec(c, f"{w}.{key}[{i}]")
    root = Path.cwd() if base is None else Path(base)
    paths = tuple(str(Path(f) if Path(f).is_absolute() else root / f) for f in files)
    spec = RecordingSpec(tuple(files), paths, tcol, rate, tuple(cols), tuple(truth), ts)
    if base is not None:
        digests = []
        for i, path in enumerate(paths):
            field = f"{w}.file" if len(files) == 1 else f"{w}.file[{i}]"
            try:
                size = Path(path).stat().st_size
            except OSError as e:
                msg = f"cannot read {_cap(files[i], 80)!r} (relative to the job file): {e.strerror}"
                raise JobError(field, msg) from None
            if size > MAX_RECORDING_BYTES:
                raise JobError(field, f"{files[i]!r} is {size} bytes, more than {MAX_RECORDING_BYTES} (8 MiB)")
            try:
                sig = _load_one(spec, signal, path)
            except jaxobs.signals.RecordingColumnError as e:  # a column not in the file: the key that named it
                raise JobError(_column_field(w, e, spec), str(e).replace(path, files[i])) from None
            except ValueError as e:
                raise JobError(field, str(e).replace(path, files[i])) from None
            need = int(round(horizon / ts))
            if sig.n < need:
                raise JobError(
                    f"{where}.horizon",
                    f"{horizon:g} s needs {need} samples of {ts:g} s; {files[i]!r} gives {sig.n} "
                    f"({(sig.n - 1) * ts:.6g} s)",
                )
            digests.append(sha256(Path(path)))
        spec = dataclasses.replace(spec, sha256=tuple(digests))
    axes = {"recording": [float(i) for i in range(len(files))]}
    return ScenarioSpec(signal, t_event, horizon, steady, axes, 0, seed, recording=spec)


def _column_field(w: str, e, spec: RecordingSpec) -> str:
    """The job field of a recording column that the file lacks: ``<w>.columns[i]``, ``<w>.truth[i]`` or
    ``<w>.time_column``."""
    if e.role == "time":
        return f"{w}.time_column"
    key, listed = ("columns", spec.columns) if e.role == "signal" else ("truth", spec.truth)
    return f"{w}.{key}[{listed.index(e.spec)}]" if e.spec in listed else f"{w}.{key}"


def _load_one(spec: RecordingSpec, signal: str, path: str):
    kw = dict(time_column=spec.time_column, sample_rate=spec.sample_rate, ts=spec.ts, max_bytes=MAX_RECORDING_BYTES)
    if signal == "grid":
        return jaxobs.SampledSignal.from_csv(path, columns=spec.columns[0], truth=spec.truth, **kw)
    truth = dict(zip(("theta_e", "omega_e"), spec.truth))
    return jaxobs.DriveRecording.from_csv(path, columns=spec.columns, **truth, **kw)


def load_recordings(spec: RecordingSpec, signal: str):
    """The recordings of a job as one batched signal (each cut to the shortest, all read at ``spec.ts``)."""
    sigs = [_load_one(spec, signal, p) for p in spec.paths]
    n = min(s.n for s in sigs)
    return stack(jax.tree.map(lambda x: x[..., :n] if eqx.is_array(x) else x, s) for s in sigs)


def _bind_recording(obs, rec):
    """A drive observer on a recording starts from the recorded speed at t = 0 (the encoder's, as a drive job's
    observer starts from the scenario's true speed): flux observers' omega0, LESOs' omega0_pll."""
    w0 = rec.omega_e[..., 0]
    if hasattr(obs, "Lq"):
        return eqx.tree_at(lambda o: o.omega0_pll, obs, w0.astype(obs.omega0_pll.dtype))
    return eqx.tree_at(lambda o: o.omega0, obs, jnp.maximum(jnp.abs(w0), 1.0).astype(obs.omega0.dtype))


def _check_recording_job(job, comp_t: dict) -> None:
    """What a recording cannot give: the closed loop's metrics; a flux observer on u/i needs the machine's Rs, L."""
    for spec, where in ((job.scenarios, "scenarios"), (job.holdout, "holdout")):
        if spec is None or spec.recording is None:
            continue
        for i, t in enumerate(job.terms):
            if t.metric in DRIVE_METRICS:
                raise JobError(
                    f"objective.terms[{i}].metric",
                    f"{t.metric!r} needs the closed-loop drive; a recording runs the observer open loop "
                    "(use iae_position, rms_position_steady, ripple_position)",
                )
        if spec.signal != "grid" and "L" in COMPONENTS[job.component].defaults:  # a flux observer
            for k in ("Rs", "L"):
                if k not in comp_t:
                    raise JobError(
                        f"component.{k}",
                        f"required with a u/i recording ({where}.recording): the machine's {k} "
                        "(the default Rs = 0, L = 1 is for back-EMF signals)",
                    )


def parse_job(raw: dict, base: Path | None = None) -> Job:
    """Validate a job dict (the parsed TOML); raises :class:`JobError` naming the field.

    ``base``: the job file's folder, against which a recording's relative ``file`` is read (and then
    checked now: it exists, its columns, its rate); without it the files are read when the job runs."""
    _no_unknown(raw, ("job", "component", "gains", "scenarios", "holdout", "objective", "solver", "drive"), "job file")
    job_t = _get(raw, "job", "job", dict, required=True)
    _no_unknown(job_t, ("name", "component", "seed"), "job")
    name = _get(job_t, "name", "job.name", str, "job")
    comp = _get(job_t, "component", "job.component", str, required=True)
    if comp == "PureIntegratorFlux":
        raise JobError(
            "job.component",
            "PureIntegratorFlux is not tunable: its flux keeps the integration constant of its start, so it "
            "cannot hold a sensorless drive; use LPFFlux, SOIFO or SecondOrderSOIFO",
        )
    if comp not in COMPONENTS:
        raise JobError("job.component", f"unknown component {_show(comp)}; known: {', '.join(COMPONENTS)}")
    info = COMPONENTS[comp]
    seed = _get(job_t, "seed", "job.seed", int, 0)
    if not 0 <= seed < 2**32 - 1:
        raise JobError("job.seed", f"must be in [0, 2^32 - 1), got {_show(seed)}")

    values = dict(info.defaults)
    comp_t = _get(raw, "component", "component", dict, {})
    for k in comp_t:
        if k not in info.defaults:
            raise JobError(f"component.{k}", f"unknown for {comp}; allowed: {', '.join(info.defaults)}")
        values[k] = _get(comp_t, k, f"component.{k}", float)
    try:
        ts = float(info.ctor(**values).ts)
    except (ValueError, ArithmeticError, TypeError) as e:
        raise JobError("component", str(e)) from None
    freq_n = float(values.get("omega_n", W_N)) / (2 * math.pi)

    gains_t = _get(raw, "gains", "gains", dict, required=True)
    if not gains_t:
        raise JobError("gains", "at least one free gain is required")
    gains = []
    for gname, spec in gains_t.items():
        where = f"gains.{gname}"
        if gname not in info.gains:
            raise JobError(_cap(where, 60), f"unknown gain for {comp}; tunable: {', '.join(info.gains)}")
        spec = _get(gains_t, gname, where, dict)
        _no_unknown(spec, ("init", "lower", "upper", "log"), where)
        init = _get(spec, "init", f"{where}.init", float, values[gname])
        lower = _get(spec, "lower", f"{where}.lower", float)
        upper = _get(spec, "upper", f"{where}.upper", float)
        log = _get(spec, "log", f"{where}.log", bool, True)
        if lower is not None and lower < 0:
            raise JobError(f"{where}.lower", f"must be >= 0 (gains are positive), got {lower}")
        if log and lower is not None and lower <= 0:
            raise JobError(f"{where}.lower", f"must be > 0 with log = true, got {lower}")
        if upper is not None and upper <= 0:
            raise JobError(f"{where}.upper", f"must be > 0, got {upper}")
        if lower is not None and upper is not None and not lower < upper:
            raise JobError(f"{where}.upper", f"must exceed lower ({lower}), got {upper}")
        if init <= 0:
            raise JobError(f"{where}.init", f"must be > 0, got {init}")
        if (lower is not None and init <= lower) or (upper is not None and init >= upper):
            raise JobError(f"{where}.init", f"must lie strictly inside [{lower}, {upper}], got {init}")
        if lower is not None and upper is not None and (upper - lower) < 1e-6 * upper:
            raise JobError(f"{where}.upper", f"bounds [{lower:g}, {upper:g}] are too narrow (relative width < 1e-6)")
        g = GainSpec(gname, init, lower, upper, log)
        try:  # the parametrization must map init (and the closed form, nudged inside) to a finite θ
            th = g.to_theta(init)
        except (ValueError, ArithmeticError):
            th = math.nan
        if not math.isfinite(th):
            raise JobError(f"{where}.init", f"{init:g} cannot be parametrized inside its bounds [{lower}, {upper}]")
        gains.append(g)
        values[gname] = init

    scen = _parse_scenarios(
        _get(raw, "scenarios", "scenarios", dict, required=True), "scenarios", info.signals, seed, freq_n, ts, base
    )
    drive = None
    if scen.signal == "drive":
        dt = _get(raw, "drive", "drive", dict, {})
        _no_unknown(dt, ("loop", "handover", "settle", "start", "machine"), "drive")
        loop = _get(dt, "loop", "drive.loop", str, "sensorless")
        if loop not in ("sensorless", "sensored"):
            raise JobError("drive.loop", f"must be 'sensorless' or 'sensored', got {_show(loop)}")
        handover = _get(dt, "handover", "drive.handover", float, 0.0)
        if not 0.0 <= handover < scen.horizon:
            raise JobError("drive.handover", f"must be in [0, horizon = {scen.horizon:g}) s, got {handover:g}")
        settle = _get(dt, "settle", "drive.settle", float, 0.2)
        if not 0.0 <= settle <= 10.0:
            raise JobError("drive.settle", f"must be in [0, 10] s, got {settle:g}")
        machine = _get(dt, "machine", "drive.machine", str, info.machines[0])
        if machine not in BENCH_MACHINES:
            raise JobError("drive.machine", f"must be one of {', '.join(BENCH_MACHINES)}, got {_show(machine)}")
        if machine not in info.machines:
            raise JobError(
                "drive.machine",
                f"{comp} cannot run on {machine} ({BENCH_MACHINES[machine]}); allowed: {', '.join(info.machines)}",
            )
        drive = DriveSpec(loop, handover, settle, machine=machine)
        drive = _parse_start(dt, drive, scen)
    elif "drive" in raw:
        raise JobError("drive", f"applies to drive jobs (scenarios.signal = 'drive'), not {scen.signal!r} signals")
    holdout = None
    if "holdout" in raw:
        h = dict(_get(raw, "holdout", "holdout", dict))
        for key in ("t_event", "horizon", "steady_from"):
            h.setdefault(key, getattr(scen, key))
        h.setdefault("signal", scen.signal)
        holdout = _parse_scenarios(h, "holdout", (scen.signal,), seed + 1, freq_n, ts, base)
    if holdout is not None and holdout.recording is None and drive is not None and drive.start == "standstill":
        _check_standstill(drive, holdout, "holdout")
    settle = drive.settle if drive is not None else 0.0
    for spec, where in ((scen, "scenarios"), (holdout, "holdout")):
        if spec is not None:
            _check_size(spec, where, ts, settle)
            if drive is not None:
                _check_drive_speeds(spec, where, drive.machine)

    obj_t = _get(raw, "objective", "objective", dict, required=True)
    _no_unknown(obj_t, ("terms", "aggregate", "alpha", "temperature", "penalty"), "objective")
    terms_raw = obj_t.get("terms")
    if not isinstance(terms_raw, list) or not terms_raw:
        raise JobError("objective.terms", "missing (required): a list of { metric = ..., weight = ... }")
    terms = []
    for i, t in enumerate(terms_raw):
        where = f"objective.terms[{i}]"
        if not isinstance(t, dict):
            raise JobError(where, f"must be a table {{ metric = ..., weight = ... }}, got {_show(t)}")
        _no_unknown(t, ("metric", "weight"), where)
        metric = _get(t, "metric", f"{where}.metric", str, required=True)
        if metric not in METRICS:
            raise JobError(f"{where}.metric", f"unknown metric {_show(metric)}; known: {', '.join(METRICS)}")
        grid_only = metric.endswith(("_freq", "_phase", "freq_steady", "phase_steady"))
        if metric in DRIVE_METRICS and scen.signal != "drive":
            raise JobError(
                f"{where}.metric", f"{_show(metric)} needs the closed-loop drive, not {comp} ({scen.signal})"
            )
        if (scen.signal != "grid") == grid_only:
            raise JobError(f"{where}.metric", f"{_show(metric)} does not apply to {comp} ({scen.signal} signals)")
        weight = _get(t, "weight", f"{where}.weight", float, 1.0)
        if weight <= 0:
            raise JobError(f"{where}.weight", f"must be > 0, got {weight}")
        terms.append(Term(metric, weight))
    agg = _get(obj_t, "aggregate", "objective.aggregate", str, "mean")
    if agg not in strategies.AGGREGATIONS:
        raise JobError("objective.aggregate", f"must be {strategies.one_of(strategies.AGGREGATIONS)}, got {_show(agg)}")
    alpha = _get(obj_t, "alpha", "objective.alpha", float, 0.9)
    if not 0 <= alpha < 1:
        raise JobError("objective.alpha", f"must be in [0, 1), got {alpha}")
    temperature = _get(obj_t, "temperature", "objective.temperature", float)
    if temperature is not None and temperature <= 0:
        raise JobError("objective.temperature", f"must be > 0, got {temperature}")
    penalty = _get(obj_t, "penalty", "objective.penalty", float, 1e3)
    if penalty <= 0:
        raise JobError("objective.penalty", f"must be > 0, got {penalty}")

    sol_t = _get(raw, "solver", "solver", dict, {})
    _no_unknown(
        sol_t,
        ("kind", "learning_rate", "steps", "patience", "tol", "schedule", "checkpoint_every", "progress_every"),
        "solver",
    )
    kind = _get(sol_t, "kind", "solver.kind", str, "adam")
    if kind not in strategies.SOLVER_KINDS:
        raise JobError("solver.kind", f"must be {strategies.one_of(strategies.SOLVER_KINDS)}, got {_show(kind)}")
    if kind in strategies.MINIMISERS:  # optimistix: no learning rate, schedule, patience or checkpoints
        for key in strategies.OPTAX_ONLY:
            if key in sol_t:
                raise JobError(
                    f"solver.{key}", f"does not apply to kind = '{kind}' (it applies to {', '.join(strategies.OPTAX)})"
                )
    opts = dict(
        learning_rate=_get(sol_t, "learning_rate", "solver.learning_rate", float, 0.05),
        steps=_get(sol_t, "steps", "solver.steps", int, 100),
        patience=_get(sol_t, "patience", "solver.patience", int, 25),
        tol=_get(sol_t, "tol", "solver.tol", float, 1e-6),
        schedule=_get(sol_t, "schedule", "solver.schedule", str, "constant"),
        checkpoint_every=_get(sol_t, "checkpoint_every", "solver.checkpoint_every", int, 5),
        progress_every=_get(sol_t, "progress_every", "solver.progress_every", int, 1),
    )
    if not 0 < opts["learning_rate"] <= 1e6:
        raise JobError("solver.learning_rate", f"must be in (0, 1e6], got {opts['learning_rate']:g}")
    if opts["tol"] < 0:
        raise JobError("solver.tol", f"must be >= 0, got {opts['tol']:g}")
    if opts["steps"] > MAX_SOLVER_STEPS:
        raise JobError("solver.steps", f"must be <= {MAX_SOLVER_STEPS}, got {_show(opts['steps'])}")
    for fld in ("steps", "patience", "checkpoint_every", "progress_every"):
        if opts[fld] < 1:
            raise JobError(f"solver.{fld}", f"must be >= 1, got {opts[fld]}")
    if opts["schedule"] not in strategies.SCHEDULES:
        raise JobError(
            "solver.schedule", f"must be {strategies.one_of(strategies.SCHEDULES)}, got {_show(opts['schedule'])}"
        )
    job = Job(
        raw=raw,
        name=name,
        component=comp,
        seed=seed,
        values=values,
        gains=gains,
        scenarios=scen,
        holdout=holdout,
        terms=terms,
        aggregation=strategies.aggregation(agg, alpha=alpha, temperature=temperature),
        penalty=penalty,
        solver=strategies.solver(kind, **opts),
        drive=drive,
    )
    _check_recording_job(job, comp_t)
    return job


_STRINGS = re.compile(r'"""(?:[^\\]|\\.)*?"""|\'\'\'.*?\'\'\'|"(?:[^"\\\n]|\\.)*"|\'[^\'\n]*\'|#[^\n]*', re.S)


def check_nesting(text: str, what: str = "job file") -> None:
    """Refuse TOML nested deeper than :data:`MAX_DEPTH` (arrays, inline tables, dotted keys) before it is
    parsed: the parser recurses on nesting and builds one table per dotted-key part."""
    bare = _STRINGS.sub('""', text)
    depth = 0
    for m in re.finditer(r"[\[\]{}]", bare):
        depth += 1 if m.group() in "[{" else -1
        if depth > MAX_DEPTH + 2:  # + 2: a [[table]] header's brackets
            raise JobError(what, f"nested deeper than {MAX_DEPTH} levels (arrays / inline tables)")
    for n, line in enumerate(bare.splitlines(), 1):
        key = line.split("=", 1)[0] if "=" in line else line
        if key.count(".") > MAX_DEPTH:
            raise JobError(what, f"line {n}: a dotted key of more than {MAX_DEPTH} parts")


def _depth(obj) -> int:
    """Nesting depth of parsed TOML (iterative: no recursion on a deep value)."""
    best, stack = 0, [(obj, 0)]
    while stack:
        o, d = stack.pop()
        best = max(best, d)
        if d > MAX_DEPTH + 1:
            break
        if isinstance(o, dict):
            stack.extend((v, d + 1) for v in o.values())
        elif isinstance(o, list):
            stack.extend((v, d + 1) for v in o)
    return best


def read_toml(path, what: str = "job file") -> tuple[dict, bytes]:
    """A TOML file's table and bytes, or a :class:`JobError` of one line: unreadable, larger than
    :data:`MAX_FILE_BYTES`, not UTF-8, nested deeper than :data:`MAX_DEPTH`, not TOML."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_FILE_BYTES + 1)
    except OSError as e:
        raise JobError(what, f"cannot read {_cap(str(path), 80)!r}: {e.strerror}") from None
    if len(data) > MAX_FILE_BYTES:
        raise JobError(what, f"larger than {MAX_FILE_BYTES} bytes")
    try:
        text = data.decode()
    except UnicodeDecodeError as e:
        raise JobError(what, f"not UTF-8 text: byte {e.start} is {data[e.start : e.start + 1]!r}") from None
    check_nesting(text, what)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise JobError(what, f"not valid TOML: {e}") from None
    except RecursionError:
        raise JobError(what, f"nested deeper than {MAX_DEPTH} levels") from None
    if _depth(raw) > MAX_DEPTH:
        raise JobError(what, f"nested deeper than {MAX_DEPTH} levels")
    return raw, data


def load_job(path) -> Job:
    """Read, check and parse a job file (:func:`read_toml`, then :func:`parse_job`)."""
    raw, data = read_toml(path)
    job = parse_job(raw, Path(path).parent)
    job.sha256 = sha256(data)
    return job


# --------------------------------------------------------------------------
# scenarios
# --------------------------------------------------------------------------


def _combos(spec: ScenarioSpec):
    """The axes' names and the scenarios' points: the studies' samplers (a grid, or ``sample`` uniform draws)."""
    if not spec.axes:
        return [], [()]
    sampler = Random(spec.axes, spec.sample, spec.seed) if spec.sample else Grid(spec.axes)
    return list(sampler.names), sampler.points()


def _drive_scenarios(names, combos, seed=0, t_event=0.0, machine="ipmsm002"):
    """The machine's bench (:func:`jaxobs.drive.bench_machine`) for every combination; each starts steady at
    its speed, and the speed_step_rpm / load_step_nm axes step the reference and the load at t_event."""
    return drive_scenarios(D.bench_machine(machine), names, combos, seed=seed, t_event=t_event)


def _check_standstill(drive: DriveSpec, spec: ScenarioSpec, where: str) -> None:
    """What an I-f start-up can do, checked before any run (``--check`` too): the load it must carry, the
    speed reference it hands over to, and a steady window after its hand-over."""
    par = D.bench_machine(drive.machine)
    s = D.IfStartup.for_machine(par)
    axes = spec.axes
    rpm_sw = float(s.omega_switch) / par.p * 30 / math.pi
    t_ho = D.if_handover_earliest(par)
    if spec.steady_from < t_ho:
        raise JobError(
            f"{where}.steady_from",
            f"must be >= {t_ho:.3g} s with start = 'standstill' (the I-f start-up hands over at {t_ho:.3g} s at "
            f"the earliest), got {spec.steady_from:g}",
        )
    speeds = axes.get("speed_rpm", [600.0])
    steps = axes.get("speed_step_rpm", [0.0])
    low = min(min(abs(v) for v in speeds), min(abs(v + d) for v in speeds for d in steps))
    if low < rpm_sw:
        raise JobError(
            f"{where}.grid.speed_rpm",
            f"must be >= the I-f hand-over speed {rpm_sw:.4g} r/min with start = 'standstill' (with any "
            f"speed_step_rpm), got {low:g}",
        )
    dj = max(axes.get("dJ", [0.0]))
    limit = D.if_load_limit(par, dj)
    load = max(abs(v) for v in axes.get("load_nm", [0.0]))
    if spec.t_event < t_ho:  # a load step during the start-up is carried by it too
        load += max(abs(v) for v in axes.get("load_step_nm", [0.0]))
    if load > limit:
        raise JobError(
            f"{where}.grid.load_nm",
            f"the load during the I-f start-up must be <= {limit:.4g} N·m on {drive.machine} (0.7246 K_t I_f − "
            f"J a_peak − B ω_sw, jaxobs.drive.if_load_limit), got {load:g}",
        )


def _parse_start(dt: dict, drive: DriveSpec, scen) -> DriveSpec:
    """``[drive] start``: "steady" or "standstill" (the I-f start-up must fit in the horizon; it hands over
    itself, so ``handover`` stays 0; :func:`_check_standstill`).  ``loop = "sensored"`` with a standstill
    start is allowed: the same I-f start-up hands over to the encoder's angle (by the same agreement test),
    and the observer estimates beside it from t = 0, scored from the hand-over on."""
    start = _get(dt, "start", "drive.start", str, "steady")
    if start not in ("steady", "standstill"):
        raise JobError("drive.start", f"must be 'steady' or 'standstill', got {_show(start)}")
    drive = dataclasses.replace(drive, start=start)
    if start == "standstill":
        if drive.handover > 0:
            raise JobError("drive.handover", "must be 0 with start = 'standstill' (the I-f start-up hands over)")
        s = job_drive(drive).startup
        t_if = float(s.omega_switch / s.accel + s.hold + s.dwell)
        if scen.horizon <= t_if:
            raise JobError(
                "drive.start", f"'standstill' needs horizon > {t_if:.3g} s (the I-f start-up), got {scen.horizon:g}"
            )
        if scen.recording is None:  # a recording has no drive to start
            _check_standstill(drive, scen, "scenarios")
    return drive


def _check_drive_speeds(spec: ScenarioSpec, where: str, machine: str) -> None:
    """speed_rpm and speed_rpm + speed_step_rpm (every combination of the grid) within ± the machine's
    :func:`jaxobs.drive.drive_speed_limit_rpm`, at --check time."""
    speeds, steps = spec.axes.get("speed_rpm"), spec.axes.get("speed_step_rpm", [0.0])
    if not speeds:
        return
    n_max = D.drive_speed_limit_rpm(D.bench_machine(machine))
    rng = f"must be in [1, {n_max:.0f}] r/min on {machine} (its back EMF reaches the inverter's voltage limit there)"
    for i, x in enumerate(speeds):
        if abs(x) > n_max:
            raise JobError(f"{where}.grid.speed_rpm[{i}]", f"{rng}, got {x:g}")
    for j, d in enumerate(steps):
        after = max(speeds) + d if d >= 0 else min(speeds) + d  # the extreme speed after this step
        if abs(after) > n_max:
            raise JobError(
                f"{where}.grid.speed_step_rpm[{j}]",
                f"speed_rpm + speed_step_rpm must be in [-{n_max:.0f}, {n_max:.0f}] r/min on {machine} (its back "
                f"EMF reaches the inverter's voltage limit there), got {after:g}",
            )


def job_drive(spec: DriveSpec | None = None):
    """The drive a ``signal = "drive"`` job runs: FOC on its machine's bench; sensorless by default (``spec``)."""
    spec = DriveSpec() if spec is None else spec
    par = D.bench_machine(spec.machine)
    startup = D.IfStartup.for_machine(par) if spec.start == "standstill" else None  # [drive] start
    return D.bench_drive(
        par, sensorless=spec.loop == "sensorless", handover=spec.handover, settle=spec.settle, startup=startup
    )


def build_scenarios(spec: ScenarioSpec, values: dict, machine: str = "ipmsm002"):
    """A batched signal for every combination of the axes (or ``sample`` random ones); ``machine``: a drive
    job's (:data:`BENCH_MACHINES`)."""
    names, combos = _combos(spec)
    if spec.recording is not None:
        return load_recordings(spec.recording, spec.signal), names, combos
    if spec.signal == "drive":
        return _drive_scenarios(names, combos, spec.seed, spec.t_event, machine), names, combos
    if spec.signal == "grid":
        return (
            grid_signals(
                names, combos, spec.t_event, float(values.get("omega_n", W_N)) / (2 * math.pi), seed=spec.seed
            ),
            names,
            combos,
        )
    sigs = []
    for combo in combos:  # back EMFs for the flux observers
        a = dict(zip(names, combo))
        f = a.get("speed_hz", 50.0)
        sigs.append(
            EMFSignal(
                A1=100.0 * f / 50.0,  # BEMF ∝ speed: 100 V at 50 Hz
                omega1=2 * math.pi * f,
                phase=math.radians(a.get("phase_deg", 0.0)),
                dc=(a.get("dc_alpha", 0.0), a.get("dc_beta", 0.0)),
                harmonics={-5: a.get("h5", 0.0) * 100.0 * f / 50.0, 7: a.get("h7", 0.0) * 100.0 * f / 50.0},
            )
        )
    return stack(sigs), names, combos


# --------------------------------------------------------------------------
# running
# --------------------------------------------------------------------------


def build_objective(job: Job, spec: ScenarioSpec | None = None):
    spec = job.scenarios if spec is None else spec
    comp = COMPONENTS[job.component].ctor(**job.values)
    machine = job.drive.machine if job.drive is not None else "ipmsm002"
    scen, names, combos = build_scenarios(spec, job.values, machine)
    ctx = MetricContext(t_event=spec.t_event, steady_from=spec.steady_from)
    param = Parametrization(job.gains)
    drive = job_drive(job.drive) if spec.signal == "drive" else None
    bind = bind_observer if drive is not None else None  # the scenario's assumed machine and speed
    if spec.recording is not None:  # the observer runs open loop on the recorded u/i or voltage
        drive, bind = None, (_bind_recording if spec.signal != "grid" else None)
    obj = Objective(
        comp,
        param,
        scen,
        horizon=spec.horizon,
        terms=job.terms,
        ctx=ctx,
        aggregation=job.aggregation,
        penalty=job.penalty,
        drive=drive,
        bind=bind,
    )
    return obj, (names, combos)


def _inside(g: GainSpec, v: float) -> float:
    """A closed-form value nudged inside the gain's open bounds (the parametrization cannot reach them)."""
    if g.lower is not None:
        v = max(v, g.lower * (1 + 1e-9))
    if g.upper is not None:
        v = min(v, g.upper * (1 - 1e-9))
    return float(v)


def rule_spec(rule) -> dict:
    """A discretization rule as JSON that :func:`tuning.export.parse_rule` reads back: ``{"name": ..., options}``."""
    opts = {f.name: getattr(rule, f.name) for f in dataclasses.fields(rule)}
    return {"name": type(rule).__name__, **{k: v for k, v in opts.items() if isinstance(v, (bool, int, float, str))}}


def sanitize(obj, path: str = "", reasons: dict | None = None):
    """``obj`` with every non-finite float replaced by ``None``; ``reasons[path]`` says what it was."""
    reasons = {} if reasons is None else reasons
    if isinstance(obj, dict):
        return {k: sanitize(v, f"{path}.{k}" if path else str(k), reasons) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [sanitize(v, f"{path}[{i}]", reasons) for i, v in enumerate(obj)]
    if isinstance(obj, (float, np.floating)) and not math.isfinite(float(obj)):
        reasons[path] = f"not a finite number ({float(obj)})"
        return None
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def write_json(path: Path, obj) -> None:
    """JSON without NaN or Infinity tokens: non-finite numbers become null, listed under ``null_reasons``."""
    reasons: dict = {}
    clean = sanitize(obj, "", reasons)
    if reasons and isinstance(clean, dict):
        clean["null_reasons"] = {**clean.get("null_reasons", {}), **reasons}
    atomic_write_text(path, json.dumps(clean, indent=1, allow_nan=False) + "\n")


def _at_bounds(job: Job, gains: dict) -> dict:
    """Free gains within 1 % of a bound: {name: {"bound": "lower" | "upper", "limit": ..., "value": ...}}."""
    out = {}
    for g in job.gains:
        v = gains[g.name]
        for side, lim in (("lower", g.lower), ("upper", g.upper)):
            if lim is not None and abs(v - lim) <= 0.01 * abs(lim):
                out[g.name] = {"bound": side, "limit": lim, "value": v}
    return out


def _scores_dataset(obj, names, combos, spec: ScenarioSpec, per: dict):
    """Per-scenario metrics of each design as an xarray Dataset: the grid's axes as dims (a full grid),
    else one ``scenario`` dim with the axes as coordinates (sampled scenarios)."""
    import xarray as xr

    designs = list(per)
    grid = spec.sample == 0
    if grid:
        dims = ("design", *names)
        shape = tuple(len(spec.axes[n]) for n in names)
        coords = {"design": designs, **{n: list(spec.axes[n]) for n in names}}
    else:
        dims, shape = ("design", "scenario"), (len(combos),)
        coords = {"design": designs, "scenario": np.arange(len(combos))}
        coords.update({n: ("scenario", [c[i] for c in combos]) for i, n in enumerate(names)})
    data = {}
    keys = [t.metric for t in obj.terms]
    extra = ("lost_sync", "lost_speed") if obj.drive is not None else ()
    for key in (*keys, "total", "diverged", "lost_lock", *extra):
        rows = []
        for d in designs:
            mets, total, good = per[d]
            flags = {"total": total, "diverged": ~good, "lost_lock": mets["lost_lock"] | ~good}
            x = flags.get(key, mets.get(key) if key in mets else None)
            rows.append(np.asarray(x, dtype=float).reshape(shape))
        data[key] = (dims, np.stack(rows))
    ds = xr.Dataset(data, coords=coords)
    ds["diverged"] = ds["diverged"].astype("int8")
    ds["lost_lock"] = ds["lost_lock"].astype("int8")
    ds.attrs["note"] = (
        "total: the weighted objective per scenario (the penalty where diverged); diverged: 1/0; lost_lock: 1 where "
        "the estimate ended far from the truth in the steady window (45 deg or 10 % on signals, 90 deg on the "
        "drive) or diverged"
    )
    if extra:
        ds["lost_sync"] = ds["lost_sync"].astype("int8")
        ds["lost_speed"] = ds["lost_speed"].astype("int8")
        ds.attrs["note"] += f"; lost_sync: 1 where diverged or |position error| > {LOST_SYNC_DEG:g} deg (drive)"
        ds.attrs["note"] += (
            f"; lost_speed: 1 where diverged or the steady window's mean |speed - reference| > "
            f"{100 * M.SPEED_TOL:g} % of the mean |reference| (at least {M.SPEED_FLOOR_RPM:g} r/min) (drive)"
        )
    return ds


def _recordings_provenance(job: Job) -> dict:
    """``{"recordings": [{"file", "sha256"}, ...]}`` of a job on recordings (else nothing)."""
    rec = job.scenarios.recording
    if rec is None:
        return {}
    return {"recordings": [{"file": f, "sha256": h} for f, h in zip(rec.files, rec.sha256 or [None] * len(rec.files))]}


def _score_designs(obj, thetas: dict, bar: Progress, what: str) -> dict:
    """Each design's per-scenario scores, one progress step each (the first one compiles)."""
    per = {}
    for i, (k, th) in enumerate(thetas.items()):
        bar.stage(f"{what}{k}" + (" (compiling the metrics)" if i == 0 else ""))
        per[k] = obj.per_scenario(th)
        bar.update()
    return per


CHECKPOINT = "checkpoint.npz"


def _lost_only(per: dict) -> int | None:
    """Scenarios where the tuned design lost lock (or diverged) and the closed form did not (None: no tuned)."""
    if "tuned" not in per:
        return None
    lost = {k: np.asarray(per[k][0]["lost_lock"] | ~per[k][2]) for k in ("tuned", "closed_form")}
    return int(np.sum(lost["tuned"] & ~lost["closed_form"]))


def job_fingerprint(job: Job) -> str:
    """What a checkpoint is checked against: the job file's sha256, or the sha256 of the job dict's JSON."""
    fp = job.sha256 or hashlib.sha256(json.dumps(job.raw, sort_keys=True, default=str).encode()).hexdigest()
    recs = [s.recording.sha256 for s in (job.scenarios, job.holdout) if s is not None and s.recording is not None]
    if any(recs):  # a checkpoint is this job's only on the same recordings
        fp = hashlib.sha256((fp + "".join(d for r in recs for d in r)).encode()).hexdigest()
    return fp


def run_job(job: Job, out: Path, resume: bool = False, quiet: bool = False) -> dict:
    """Tune, score initial / tuned / closed form on the same scenarios, write the results folder.

    ``result.json`` (outcome, gains, every constructor value, scores, linear structure, what is needed to
    rebuild the design) and ``history.json`` are byte-identical for two runs of one job; the timings go
    to ``timing.json``, the per-scenario scores to ``scores.nc`` (and ``holdout_scores.nc``).
    """
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    obj, (names, combos) = build_objective(job)
    param = obj.param
    theta0 = param.theta0()
    info = COMPONENTS[job.component]
    cf_all = info.closed_form(obj.component)
    cf = {g.name: cf_all[g.name] for g in job.gains}
    theta_cf = param.to_theta({g.name: _inside(g, cf[g.name]) for g in job.gains})
    res = tune(
        obj,
        job.solver,
        theta0,
        checkpoint=out / CHECKPOINT,
        resume=resume,
        quiet=quiet,
        fingerprint=job_fingerprint(job),
    )
    thetas = {"initial": theta0, "closed_form": theta_cf}
    if res.theta is not None:  # never a design that diverged in some scenario
        thetas["tuned"] = res.theta
    gains = {
        "initial": param.values(theta0),
        # the closed form is reported exactly; it is scored at θ nudged inside the gains' open bounds
        "closed_form": {g.name: float(cf[g.name]) for g in job.gains},
        "tuned": param.values(res.theta) if res.theta is not None else None,
    }
    fixed = {k: float(v) for k, v in job.values.items() if k not in param.names}
    values = {k: (None if g is None else {**fixed, **g}) for k, g in gains.items()}
    n_scored = len(thetas) * (2 if job.holdout is not None else 1)
    bar = Progress(not quiet and "auto", n_scored, "score", unit="design")
    per = _score_designs(obj, thetas, bar, "")
    scores = {k: (obj.summarize(*per[k]) if k in per else None) for k in gains}
    bar.stage("linear structure of each design (margins, poles)")
    lin = {k: (None if v is None else structure(job.component, v, job)) for k, v in values.items()}
    result = {
        "status": res.status,
        "reason": res.reason,
        "job": job.raw,
        "job_sha256": job.sha256,
        "component": job.component,
        "loop": None if job.drive is None else job.drive.loop,
        "start": None if job.drive is None else job.drive.start,
        "ts": float(obj.component.ts),
        "rule": rule_spec(obj.component.rule),
        "omega_n": float(job.values["omega_n"]) if "omega_n" in job.values else None,
        "closed_form_source": info.closed_form_source,
        "gains": gains,
        "values": values,
        "at_bound": _at_bounds(job, gains["tuned"]) if gains["tuned"] is not None else {},
        "scores": scores,
        "linear": lin,
        "scenarios": {"axes": names, "count": len(combos)},
        **_recordings_provenance(job),
        "iterations": res.iterations,
        "best_iteration": res.best_iteration,
        "versions": versions(),
    }
    nulls = {}
    if "omega_n" not in job.values:
        nulls["omega_n"] = f"{job.component} has no nominal frequency omega_n"
    if gains["tuned"] is None:
        why = "status 'diverged': every design tried diverged in some tuning scenario, so nothing is tuned"
        for key in ("gains.tuned", "values.tuned", "scores.tuned", "linear.tuned", "lost_lock_tuned_only"):
            nulls[key] = why
    if job.drive is not None:
        result["machine"] = job.drive.machine
        result["values_note"] = (
            "Rs, Lq (LESOs) or Rs, L (flux observers) and the PLL's or FLL's initial speed (omega0_pll, omega0) "
            f"are set per scenario from its estimated machine ({BENCH_MACHINES[job.drive.machine]})"
        )
    if nulls:
        result["null_reasons"] = nulls
    result["lost_lock_tuned_only"] = {"tuning": _lost_only(per)}
    if job.holdout is not None:
        hobj, (hn, hc) = build_objective(job, job.holdout)
        hper = _score_designs(hobj, thetas, bar, "held-out ")
        result["holdout"] = {k: (hobj.summarize(*hper[k]) if k in hper else None) for k in gains}
        result["holdout"]["count"] = len(hc)
        result["lost_lock_tuned_only"]["holdout"] = _lost_only(hper)
        with atomic_path(out / "holdout_scores.nc") as tmp:
            _scores_dataset(hobj, hn, hc, job.holdout, hper).to_netcdf(tmp, engine="scipy")
    bar.close()
    with atomic_path(out / "scores.nc") as tmp:
        _scores_dataset(obj, names, combos, job.scenarios, per).to_netcdf(tmp, engine="scipy")
    write_json(out / "history.json", res.history)
    write_report(out, job, obj, thetas, res.history)
    timing = {"total_s": time.time() - t0, **res.timing, "iterations": res.iterations}
    atomic_write_text(out / "timing.json", json.dumps(timing, indent=1) + "\n")
    write_json(out / "result.json", result)  # last: a result.json means a complete results folder
    return result
