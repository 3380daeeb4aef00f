"""Firmware export: an observer as C99 float32, checked against golden vectors from the JAX step.

    jaxobs export RESULT.json --out DIR        the tuned design of a ``jaxobs tune`` result
    jaxobs export --design wif --out DIR       a closed-form design (sogi-fll, wpf, wif)

writes to DIR:

- ``observer.h`` / ``observer.c``: ``jx_state``, ``jx_init(&s)``, ``jx_step(&s, u, y)``,
  ``JX_NU`` / ``JX_NY`` inputs and outputs per step.  The step is the JAX step itself,
  generated from the jaxpr of ``observer.step`` (:mod:`tuning.export.codegen`): the rule,
  the back EMF, the drive observers' memory of the previous sample and the step
  convention of :mod:`jaxobs.observers.base` are whatever the Python does, so any
  observer that follows the contract exports, a user's own included.  ``jx_state`` is the
  JAX state leaf by leaf, the gains are float32 macros ``JX_<NAME>``.  The header's
  comment gives the operation count per step (that of the emitted C);
- ``golden.csv``: a header line, then per step the ``JX_NU`` inputs and the ``JX_NY``
  outputs of the JAX step run in float32 (``lax.scan`` of ``observer.step``) over a
  test record of ≥ 10 000 samples: for an FLL a unit sine at ωn with a +2 Hz step at
  one third and a +40° phase jump at two thirds (:func:`fll_test_signal`); for a drive
  observer the u and i recorded in a sensored FOC drive of its family's machine (000's SPMSM
  for the flux observers, 002's IPMSM for the LESOs) with a speed step and a load step
  (:func:`drive_recording`; the CLI binds the observer to that machine's Rs, L and speed), or
  with ``--record synthetic`` the synthesized PMSM signal of :func:`drive_test_signal` (a +10 %
  speed step and a +30° angle jump on the observer's own Rs, L), or a recording passed as
  ``signal``;
- ``coefficients.json``: the gains, static options, rule, initial state, the step
  convention and the operation count;
- ``test_main.c``: the harness: replays golden.csv through ``jx_step`` and fails if
  max |y_C − y_golden| / (1 + |y_golden|) > 1e-4 at any step (angles compared modulo 2π).

:func:`compile_and_check` compiles the harness with the system C compiler
(``cc -std=c99 -O2 -Wall -Werror -pedantic``) and returns that error; the tests do
it for every observer family and rule and for the default job's result.  A drive
observer (flux observers, LESOs) reads (u_a, u_b, i_a, i_b) per step, any other
observer one sample ``v``; outputs named ``theta...`` are angles.

The C cannot be bit-identical to XLA's float32 (XLA contracts multiply-adds into FMAs
and rewrites divisions by constants), so the check is a tolerance, and the golden
records avoid the few instants where an output is discontinuous in the state: see
:func:`drive_test_signal` (the first period of the drive records, shaped the same way in
:func:`drive_recording`: unshaped, a pure integrator's θ̂ misses by 5e-2 rad and a Tustin
SOIFO's signed ω̂ flips, error 2).  Before writing, the export runs the emitted
statements in Python (float32 numpy) at random states and compares them with the JAX
step, so a code generator bug fails at export time, with or without a C compiler.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import re
import shutil
import subprocess
import tempfile
from importlib import resources
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxobs import AB3, RK4, DriveInput, Euler, Tustin
from jaxobs.observers import (
    SOIFO,
    AbstractDriveObserver,
    AbstractFluxObserver,
    AbstractLESO,
    LPFFlux,
    PureIntegratorFlux,
    SecondOrderSOIFO,
)
from jaxobs.progress import Progress

from ..job import COMPONENTS
from ..outdir import OutDir, atomic_path, atomic_write_text
from ..results import load_result
from .codegen import CStep, gain_macro, generate, is_angle, leaf_name, reference, rule_doc, statics, write_c

__all__ = [
    "export_observer",
    "observer_from_result",
    "observer_from_design",
    "compile_and_check",
    "fll_test_signal",
    "drive_test_signal",
    "drive_recording",
    "add_export_parser",
    "cli_export",
    "DESIGNS",
    "TOLERANCE",
    "MIN_STEPS",
]

EXPORT_FILES = ("observer.h", "observer.c", "test_main.c", "golden.csv", "coefficients.json")
TOLERANCE = 1e-4  # max |y_C − y_golden| / (1 + |y_golden|)
MIN_STEPS = 10_000  # the golden record is at least this long
CFLAGS = ("-std=c99", "-O2", "-Wall", "-Werror", "-pedantic")

DESIGNS = {  # closed forms, as `jaxobs closed-form` computes them (defaults: paper 001 Table I)
    "sogi-fll": ("sogi_fll_closed_form", "001 eq (22): k = 1/√2, λ = k²ωn²/(8ζ²), ζ = 1/√2"),
    "wpf": ("wpf_closed_form", "001 eq (29): k1 = k2 = √2, λ = 2(ζ+1)ωn²/(2ζ+1)³, ζ = 1/√2"),
    "wif": ("wif_closed_form", "001 eq (34), symmetric optimum: b = 1+√2, ωc = 2π·18.8 rad/s"),
}

_RULES = {"euler": Euler, "tustin": Tustin, "ab3": AB3, "rk4": RK4}


# --------------------------------------------------------------------------------------------
# where the observer comes from
# --------------------------------------------------------------------------------------------


def parse_rule(spec, where: str = "rule"):
    """A rule from its name (``"AB3"``), its repr (``"Tustin(newton_iters=3)"``) or ``{"name": ..., ...}``."""
    kw = {}
    if isinstance(spec, dict):
        kw = {k: v for k, v in spec.items() if k not in ("name", "kind")}
        spec = spec.get("name", spec.get("kind"))
    if not isinstance(spec, str):
        known = ", ".join(c.__name__ for c in _RULES.values())
        raise ValueError(f"{where}: must be a rule name ({known}), got {spec!r}")
    m = re.fullmatch(r"\s*(\w+)\s*(?:\((.*)\))?\s*", spec)
    cls = _RULES.get(m.group(1).lower()) if m else None
    if cls is None:
        raise ValueError(f"{where}: unknown rule {spec!r}; known: {', '.join(c.__name__ for c in _RULES.values())}")
    for item in filter(None, (s.strip() for s in (m.group(2) or "").split(","))):
        k, _, v = item.partition("=")
        try:
            kw[k.strip()] = int(v)
        except ValueError:
            raise ValueError(f"{where}: cannot read the rule option {item!r} in {spec!r}") from None
    try:
        return cls(**kw)
    except TypeError as e:
        raise ValueError(f"{where}: {e}") from None


def observer_from_result(path, *, gains: str = "tuned", notes: list | None = None):
    """The observer of a ``jaxobs tune`` result.json with its ``gains`` ("tuned", "closed_form" or "initial").

    Constructor values are rebuilt as the job built them: the component's
    defaults, then the job's ``[component]`` table, then the chosen gains.  The
    sample time, rule and nominal frequency are read from the result's ``ts``,
    ``rule`` and ``omega_n`` when it has them; otherwise the component's defaults
    are used and a line saying so is appended to ``notes``.
    """
    notes = [] if notes is None else notes
    path = Path(path)
    res = load_result(path)
    comp = res.get("component")
    if comp not in COMPONENTS:
        raise ValueError(f"result file {str(path)!r}: component {comp!r} is not a jaxobs component")
    info = COMPONENTS[comp]
    table = res.get("gains", {}).get(gains)
    if not isinstance(table, dict):
        have = ", ".join(res.get("gains", {})) or "none"
        raise ValueError(f"result file {str(path)!r}: no gains.{gains} (has: {have})")
    if gains == "tuned" and str(res.get("status", "")).lower() == "diverged":
        raise ValueError(
            f"result file {str(path)!r}: status 'diverged': the tuned gains are not a design "
            "(export --gains closed_form instead)"
        )
    values = dict(info.defaults)
    values.update(res.get("job", {}).get("component", {}))
    values.update(table)
    kw = {}
    name = info.ctor.__name__
    if "omega_n" in res and "omega_n" in values:
        values["omega_n"] = float(res["omega_n"])
    elif "omega_n" in values:
        notes.append(f"result.json has no 'omega_n': the job's value {values['omega_n']:.9g} rad/s is used")
    probe = info.ctor(**values)  # defaults of ts and rule
    if "ts" in res:
        kw["ts"] = float(res["ts"])
    else:
        notes.append(f"result.json has no 'ts': the {name} default ts = {probe.ts:g} s is used")
    if "rule" in res:
        kw["rule"] = parse_rule(res["rule"], "result.json rule")
    else:
        notes.append(f"result.json has no 'rule': the {name} default {type(probe.rule).__name__} is used")
    if info.bind is not None or res.get("loop") is not None:  # a drive job bound these per scenario
        # LESOs: Rs, Lq and the PLL's initial speed; flux observers: Rs, L and the FLL's or PLL's omega0
        keys = type(probe).bound_fields
        bound = ", ".join(f"{k} = {float(getattr(probe, k)):g}" for k in keys)
        notes.append(f"the job sets {', '.join(keys)} per scenario; exported with {bound}")
    diverged = res.get("scores", {}).get(gains, {}).get("diverged") if gains in res.get("scores", {}) else None
    if diverged:
        notes.append(f"the {gains} design diverged on {diverged} of the job's scenarios")
    return info.ctor(**values, **kw)


def observer_from_design(name: str, **kw):
    """A closed-form design by name (``sogi-fll``, ``wpf``, ``wif``); ``kw`` go to its jaxobs.linear function."""
    from jaxobs import linear

    if name not in DESIGNS:
        raise ValueError(f"design must be one of {', '.join(DESIGNS)}, got {name!r}")
    return getattr(linear, DESIGNS[name][0])(**kw)


# --------------------------------------------------------------------------------------------
# golden vectors
# --------------------------------------------------------------------------------------------


def fll_test_signal(ts: float, n_steps: int, f0: float = 50.0, amplitude: float = 1.0):
    """Unit sine at ``f0`` with a +2 Hz step at n/3 and a +40° phase jump at 2n/3 (GridSignal's settle-then-disturb).

    Returns (samples as float32, shape (n_steps, 1), a one-line description).
    """
    t = np.arange(n_steps) * ts
    t1, t2 = (n_steps // 3) * ts, (2 * n_steps // 3) * ts
    theta = 2 * np.pi * f0 * t + np.where(t >= t1, 2 * np.pi * 2.0 * (t - t1), 0.0)
    theta = theta + np.where(t >= t2, np.radians(40.0), 0.0)
    v = (amplitude * np.cos(theta)).astype(np.float32)
    doc = f"{amplitude:g} cos at {f0:g} Hz, +2 Hz step at {t1:g} s, +40 deg phase jump at {t2:g} s, ts = {ts:g} s"
    return v[:, None], doc


def drive_test_signal(
    ts: float,
    n_steps: int,
    *,
    omega: float,
    Rs: float,
    L: float,
    psi: float = 0.1,
    current: float | None = None,
    start: str = "",
):
    """Sampled (u_α, u_β, i_α, i_β) of a surface PMSM turning at electrical speed ``omega``, with a +10 % speed
    step at n/3 and a +30° angle jump at 2n/3.

    θ(0) = π/2; i = I (−sin θ, cos θ) (q-axis current, I = min(5 A, ψ/(2L)) unless given),
    e = ω ψ (−sin θ, cos θ) (002 eq 5), u = R i + L di/dt + e.  ``u`` at sample k is the voltage applied
    over [t_k, t_k+1] (its period average: R i + e averaged over 8 midpoints, L Δi/ts exactly), as a drive
    observer expects; ``i`` is sampled at t_k.  Returns (float32 array (n_steps, 4), a one-line description).

    ``start`` shapes the first period so that the outputs are well conditioned from the first step
    (otherwise a float32 implementation other than XLA's own, bit for bit, cannot be held to 1e-4 there):

    - ``"flux"``: the first voltage sample also carries ψ(0)/ts, the flux the integrators cannot know
      (000's initial-value problem).  A pure integrator started at 0 estimates ψ(t) − ψ(0), which passes
      through 0 once per turn, where atan2 turns rounding into any angle;
    - ``"alpha"``: the first voltage and the first two current samples have no β component, so the first
      back EMF is on α only.  After a single back-EMF sample the two SOGIs of a SOIFO hold proportional
      states, the cross product whose sign gives the direction of rotation is 0 but for rounding, and
      the signed ω̂ is ±|ω̂| by chance; with a β-free first sample that product is exactly 0.
    """
    if start not in ("", "flux", "alpha"):
        raise ValueError(f"drive_test_signal: start must be '', 'flux' or 'alpha', got {start!r}")
    current = min(5.0, 0.5 * psi / L) if current is None else current
    t1, t2 = (n_steps // 3) * ts, (2 * n_steps // 3) * ts

    def theta(t):
        return (
            np.pi / 2
            + omega * t
            + np.where(t >= t1, 0.1 * omega * (t - t1), 0.0)
            + np.where(t >= t2, np.radians(30.0), 0.0)
        )

    def cur(t):
        th = theta(t)
        return current * np.stack([-np.sin(th), np.cos(th)], axis=-1)

    def emf(t):
        th = theta(t)
        w = omega * np.where(t >= t1, 1.1, 1.0)
        return (w * psi)[..., None] * np.stack([-np.sin(th), np.cos(th)], axis=-1)

    t = np.arange(n_steps + 1) * ts
    mid = t[:-1, None] + (np.arange(8) + 0.5) / 8 * ts
    u = np.mean(Rs * cur(mid) + emf(mid), axis=1) + L * (cur(t[1:]) - cur(t[:-1])) / ts
    i = cur(t[:-1])
    if start == "flux":
        th0 = theta(np.asarray(0.0))
        u[0] += psi * np.array([np.cos(th0), np.sin(th0)]) / ts
    elif start == "alpha":
        u[0, 1] = i[0, 1] = i[1, 1] = 0.0
    data = np.concatenate([u, i], axis=1).astype(np.float32)
    first = {"": "", "flux": ", first period carries psi(0)/ts", "alpha": ", first period on alpha only"}[start]
    doc = (
        f"PMSM u/i at {omega / (2 * np.pi):g} Hz electrical (psi = {psi:g} Wb, I = {current:.3g} A, "
        f"Rs = {Rs:g} ohm, L = {L:g} H){first}, +10 % speed step at {t1:g} s, +30 deg angle jump at {t2:g} s, "
        f"ts = {ts:g} s"
    )
    return data, doc


# the bench (jaxobs.drive.bench_machine) a drive observer's recording runs on, its speed (r/min) and its name in
# the record's description, by family (the observer's abstract base)
_RECORDING_BENCH = {
    AbstractFluxObserver: ("spmsm000", 1000.0, "000 SPMSM"),  # 000's SPMSM, p = 3: 50 Hz
    AbstractLESO: ("ipmsm002", 300.0, "002 IPMSM"),  # 002's (assumed) IPMSM, p = 5: 25 Hz (see drive_recording)
}


def _bench_of(observer) -> tuple:
    for family, bench in _RECORDING_BENCH.items():
        if isinstance(observer, family):
            return bench
    raise ValueError(f"export: {type(observer).__name__} is not a drive observer (flux observer or LESO)")


def _recording_bench(observer):
    """The machine (:func:`jaxobs.drive.bench_machine`: 000's SPMSM for the flux observers, 002's IPMSM for the
    LESOs, on the drive jobs' bench inertia) and the speed (r/min) a drive observer's recording runs at."""
    from jaxobs.drive import bench_machine

    name, rpm, _ = _bench_of(observer)
    return bench_machine(name), rpm


class _Tap(eqx.Module):
    """An "observer" that returns what it is fed: the measurements a ClosedLoop gives its observer."""

    def init(self, u0=None):
        return None

    def step(self, state, u):
        return state, u


def drive_recording(
    observer,
    n_steps: int = 12_000,
    *,
    machine=None,
    rpm: float | None = None,
    load: tuple = (0.3, 0.8),
    speed_step: float = 0.1,
    start: str = "",
    encoder: bool = False,
):
    """The (u_α, u_β, i_α, i_β) a drive observer is fed in a sensored FOC drive, ``n_steps`` samples at its ts.

    ``jaxobs.simulate(ClosedLoop(Drive(FOC.imc(machine, 2π·300, 2π·5)), _Tap(), scenario), t1)``: the
    encoder closes the loop, the sensors are ideal (no offsets, gain errors or noise, no dead time), and
    the drive starts in the steady state of ``rpm`` (default 1000 r/min on 000's SPMSM, 600 r/min on
    002's IPMSM: 50 Hz electrical) with ``load[0]``·T_rated.  The speed reference steps by
    ``speed_step`` (+10 %) at n/3, the load to ``load[1]``·T_rated at 2n/3.  The rows are the
    measurements the loop hands its observer at each sample (a tap observer returns them), so the
    voltage in row k is the one applied over [t_k, t_k+1] (the FOC computed it at t_k−1) and the
    current is sampled at t_k: the drive observers' contract.  With ideal sensors they equal the
    outputs' u_a, u_b, i_a, i_b.

    ``machine``: a :class:`jaxobs.drive.PMSMParams` (default: the bench of the observer's family,
    :func:`jaxobs.drive.bench_machine`).  Export the observer bound to the same machine and speed
    (``observer.bind(machine, ω_e)``).  Returns (float32 array (n_steps, 4), a one-line description).

    The rotor starts at θe = π/2, where the q-axis current and the back EMF lie on −α, so the
    β components of the first samples are small.  ``start`` shapes the first period as
    :func:`drive_test_signal` does (the reasons are there): ``"flux"`` adds the rotor flux at t = 0,
    ψf (cos θe0, sin θe0), divided by ts to the first voltage (the pure integrator's initial value);
    ``"alpha"`` zeroes the β components of the first voltage and the first two currents (a few
    per cent of their amplitude at θe0 = π/2: 5 % of the voltage, the ω_e L i_q drop; 3 % of the current).

    ``encoder=True`` appends two columns, the true electrical angle θe (rad, wrapped) and speed ωe
    (rad/s) at t_k: what an encoder would record beside u and i (the shipped example recording,
    ``tuning/presets/recordings/``, is made this way).
    """
    if start not in ("", "flux", "alpha"):
        raise ValueError(f"drive_recording: start must be '', 'flux' or 'alpha', got {start!r}")
    import jaxobs
    from jaxobs import drive as D

    bench, bench_rpm = _recording_bench(observer)
    machine = bench if machine is None else machine
    rpm = bench_rpm if rpm is None else float(rpm)
    if not (isinstance(n_steps, int) and n_steps >= 2):
        raise ValueError(f"drive_recording: n_steps must be an integer >= 2, got {n_steps!r}")
    ts = float(observer.ts)
    t1, t2 = (n_steps // 3) * ts, (2 * n_steps // 3) * ts
    t_rated = float(machine.T_rated)
    scenario = D.Scenario(
        machine,
        speed_ref=D.Scenario.speed_rpm([0.0, t1], [rpm, (1 + speed_step) * rpm]),
        load=D.Scenario.load_steps([0.0, t2], [load[0] * t_rated, load[1] * t_rated]),
        omega_m0=rpm * D.RPM,
        theta_e0=math.pi / 2,
    )
    drive = D.bench_drive(machine, sensorless=False, settle=0.0, ts=ts)  # the encoder closes the loop
    sol = jaxobs.simulate(D.ClosedLoop(drive, _Tap(), scenario), n_steps * ts)
    m = sol.outputs.obs
    data = np.stack([np.asarray(m.u_a), np.asarray(m.u_b), np.asarray(m.i_a), np.asarray(m.i_b)], axis=1)
    data = data[:n_steps].astype(np.float64)
    if start == "flux":
        th0 = float(np.asarray(sol.outputs.theta_e)[0])
        data[0, :2] += float(machine.psi_f) * np.array([math.cos(th0), math.sin(th0)]) / ts
    elif start == "alpha":
        data[0, 1] = data[0, 3] = data[1, 3] = 0.0
    if encoder:
        th = np.asarray(sol.outputs.theta_e, dtype=np.float64)[:n_steps]
        we_true = np.asarray(sol.outputs.omega_m, dtype=np.float64)[:n_steps] * int(machine.p)
        data = np.concatenate([data, th[:, None], we_true[:, None]], axis=1)
    if data.shape[0] != n_steps or not np.all(np.isfinite(data)):
        raise ValueError(f"drive_recording: the drive gave {data.shape[0]} finite rows of {n_steps}")
    we = rpm * math.pi / 30 * int(machine.p)
    doc = (
        f"sensored FOC drive ({_bench_of(observer)[2]}: Rs = {float(machine.Rs):g} ohm, "
        f"Ld = {float(machine.Ld):g} H, Lq = {float(machine.Lq):g} H, psi = {float(machine.psi_f):g} Wb, "
        f"p = {int(machine.p)}), steady start at {rpm:g} r/min ({we / (2 * math.pi):g} Hz electrical) and "
        f"{load[0]:g} T_rated, speed reference {speed_step:+.0%} at {t1:g} s, load to {load[1]:g} T_rated at "
        f"{t2:g} s, ideal sensors, ts = {ts:g} s"
    )
    doc += {"": "", "flux": ", first period carries psi(0)/ts", "alpha": ", first period on alpha only"}[start]
    return data.astype(np.float32), doc


def _float32(observer):
    return jax.tree.map(lambda a: a.astype(jnp.float32) if eqx.is_inexact_array(a) else a, observer)


def _is_drive(observer) -> bool:
    """A drive observer reads (u_a, u_b, i_a, i_b) each step; any other observer reads one sample v."""
    return isinstance(observer, AbstractDriveObserver)


def _zero_input(observer):
    z = jnp.zeros((), jnp.float32)
    return DriveInput(z, z, z, z) if _is_drive(observer) else z


@eqx.filter_jit
def _scan_outputs(observer, state0, u):
    # one compile per observer class and rule: the gains are traced leaves
    _, out = jax.lax.scan(lambda s, x: observer.step(s, x), state0, u)
    return out


def _golden(obs32, state0, step: CStep, u: np.ndarray) -> np.ndarray:
    # 64-bit types off: every number in the step is float32, as on the target (some rules, e.g.
    # diffrax's Euler, would otherwise promote a float32 state with a float64 step size)
    with jax.enable_x64(False):
        uj = jnp.asarray(u, jnp.float32)
        inputs = DriveInput(*(uj[:, k] for k in range(4))) if _is_drive(obs32) else uj[:, 0]
        out = _scan_outputs(obs32, state0, inputs)
    cols = []
    for leaf in jax.tree.leaves(out):
        c = np.asarray(leaf)
        if c.dtype != np.float32:
            raise ValueError(f"export: the float32 JAX step returned an output as {c.dtype}")
        cols.append(c.reshape(c.shape[0], -1))
    y = np.concatenate(cols, axis=1)
    if y.shape[1] != len(step.output_names):
        raise AssertionError(f"export: {y.shape[1]} golden outputs for {len(step.output_names)} in the C")
    return y


def _harness() -> str:
    return (resources.files("tuning.export") / "test_main.c").read_text()


# --------------------------------------------------------------------------------------------
# the export
# --------------------------------------------------------------------------------------------


# How a drive recording's first period is shaped (drive_test_signal explains why): the flux the
# integrators cannot know for a pure integrator or an LPF, a beta-free first back EMF for the SOIFOs,
# whose signed speed is otherwise the sign of a rounding error.  Any other observer: unshaped.
_RECORD_START = {PureIntegratorFlux: "flux", LPFFlux: "flux", SOIFO: "alpha", SecondOrderSOIFO: "alpha"}


def _record_start(observer) -> str:
    return _RECORD_START.get(type(observer), "")


def _signal_speed(observer) -> float:
    """The electrical speed (rad/s) of a drive observer's synthetic record: its initial speed, else 50 Hz."""
    w = float(getattr(observer, "omega0_pll", getattr(observer, "omega0", 0.0)))
    return w if w > 0 else 2 * math.pi * 50.0


def _machine(obs) -> tuple[float, float]:
    """(R̂s, L̂) the drive observer assumes: the golden signal's machine."""
    rs, ls = type(obs).bound_fields[:2]  # (resistance, inductance, start speed)
    return float(getattr(obs, rs)), float(getattr(obs, ls))


def export_observer(
    observer, out_dir, *, n_steps: int = 12_000, signal=None, source: str = "", notes=(), progress=None
) -> dict:
    """Write ``observer`` as C99 float32 with its golden vectors into ``out_dir``; returns coefficients.json's content.

    Args:
        observer: any observer that follows the step contract (jaxobs.observers.base), a user's own
            included: the C is generated from the jaxpr of its ``step``; its gains are rounded to
            float32, as the C holds them.  A drive observer reads (u_a, u_b, i_a, i_b) per step, any
            other one sample ``v``.
        out_dir: folder for observer.h, observer.c, test_main.c, golden.csv, coefficients.json.
        n_steps: length of the default test signal (:func:`fll_test_signal` for a signal-level
            observer, :func:`drive_recording` for drive observers), >= 10 000.
        signal: instead of the default, the inputs per step, shape (n,) or (n, JX_NU) (drive
            observers: columns u_a, u_b, i_a, i_b, e.g. :func:`drive_recording` at another speed),
            or ``"synthetic"`` for a drive observer: :func:`drive_test_signal` on the observer's
            own Rs and L.  The default recording runs on its bench (:func:`jaxobs.drive.bench_machine`): export the
            observer bound to it (``observer.bind``) to get that machine's Rs and L in the C.
        source: where the design comes from (a result file, a closed form), for the header.
        notes: lines recorded in the header and coefficients.json (e.g. defaults used).
        progress: its three stages (C generated, the test record, the golden vectors), each named as
            it runs (:mod:`jaxobs.progress`: ``True`` a tqdm bar on stderr, or a callable).
    """
    notes = list(notes)
    bar = Progress(progress, 3, "export", unit="stage")
    bar.stage("generating the C from the jaxpr of the step")
    obs32 = _float32(observer)
    kind = "drive" if _is_drive(obs32) else "signal"
    with jax.enable_x64(False):
        u0 = _zero_input(obs32)
        state0 = obs32.init(u0)
        step = generate(obs32, state0, u0, input_names=list(DriveInput._fields) if kind == "drive" else ["v"])
    component = type(obs32).__name__
    _self_check(obs32, step, state0)
    header, source_c = write_c(obs32, step, kind, source or f"{component} as given", notes)
    bar.update()
    bar.stage("the test record" + (" (compiling and running the sensored drive)" if kind == "drive" else ""))
    nu = len(step.input_names)
    if signal is None or (isinstance(signal, str) and signal == "synthetic" and kind == "drive"):
        if not (isinstance(n_steps, int) and n_steps >= MIN_STEPS):
            raise ValueError(f"export: n_steps must be an integer >= {MIN_STEPS}, got {n_steps!r}")
    if signal is None and kind == "signal":
        # an FLL's nominal frequency when it has one, else 50 Hz
        f0 = float(getattr(obs32, "omega_n", 2 * math.pi * 50.0)) / (2 * math.pi)
        u, signal_doc = fll_test_signal(obs32.ts, n_steps, f0)
    elif signal is None:
        u, signal_doc = drive_recording(observer, n_steps, start=_record_start(obs32))
    elif isinstance(signal, str) and signal == "synthetic" and kind == "drive":
        rs, ls = _machine(obs32)
        u, signal_doc = drive_test_signal(
            obs32.ts, n_steps, omega=_signal_speed(obs32), Rs=rs, L=ls, start=_record_start(obs32)
        )
    elif isinstance(signal, str):
        raise ValueError(f"export: signal must be an array (or 'synthetic' for a drive observer), got {signal!r}")
    else:
        u = np.asarray(signal, np.float32)
        u = u[:, None] if u.ndim == 1 else u
        if u.ndim != 2 or u.shape[1] != nu or u.shape[0] < 1 or not np.all(np.isfinite(u)):
            raise ValueError(f"export: signal must be finite, shape (n,) or (n, {nu}), got shape {np.shape(signal)}")
        signal_doc = f"user signal, {u.shape[0]} steps"
    bar.update()
    bar.stage(f"golden vectors: the float32 JAX step over {u.shape[0]} samples (compiling)")
    y = _golden(obs32, state0, step, u)
    bar.update()
    bar.close()
    if not np.all(np.isfinite(y)):
        raise ValueError(
            f"export: the JAX step of {component} gave non-finite outputs on the test signal "
            "(an unstable design?): no golden vectors written"
        )

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    # each file to a temp file, then renamed (tuning.outdir): a symlink there is replaced, never followed
    atomic_write_text(out / "observer.h", header)
    atomic_write_text(out / "observer.c", source_c)
    atomic_write_text(out / "test_main.c", _harness())
    columns = step.input_names + step.output_names
    with atomic_path(out / "golden.csv") as tmp:
        np.savetxt(
            tmp, np.concatenate([u, y], axis=1), fmt="%.9g", delimiter=",", header=",".join(columns), comments=""
        )
    step_doc = {
        "signal": "jx_step returns the outputs of the state before the sample is integrated (signal-level observer)",
        "drive": "jx_step integrates the period that just ended and returns the outputs after it (drive "
        "observer); the first call only records u and i",
    }
    gains = {}
    for g in step.gains:
        for i, v in enumerate(g.value.flat):
            key = g.name if g.shape == () else f"{g.name}_{i}"
            given = np.asarray(_leaf_at(observer, g.name)).flat[i]
            gains[key] = {
                "c_name": gain_macro(g, None if g.shape == () else i),
                "value": float(v),
                "given": float(given),
            }
    state = [
        {"name": n, "c": f"s->{leaf.name}" + ("" if leaf.shape == () else f"[{i}]"), "initial": v.item()}
        for leaf in step.state
        for i, (n, v) in enumerate(zip(leaf.scalars(), np.asarray(leaf.value).flat))
    ]
    ops = {"steady": step.ops_steady}
    if step.has_branch:
        ops["worst"] = step.ops_worst
    coeffs = {
        "component": component,
        "reference": reference(obs32),
        "design": source or f"{component} as given",
        "notes": notes,
        "dtype": "float32",
        "ts": obs32.ts,
        "rule": rule_doc(getattr(obs32, "rule", None)),
        "step": step_doc[kind],
        "gains": gains,
        "static": statics(obs32),
        "state": state,
        "inputs": step.input_names,
        "outputs": step.output_names,
        "angle_outputs": [n for n in step.output_names if is_angle(n)],
        "ops_per_step": ops,
        "golden": {
            "steps": int(u.shape[0]),
            "signal": signal_doc,
            "columns": columns,
            "tolerance": TOLERANCE,
            "error": "max |y_C - y_golden| / (1 + |y_golden|), angles modulo 2 pi",
        },
    }
    atomic_write_text(out / "coefficients.json", json.dumps(coeffs, indent=1, ensure_ascii=False) + "\n")
    return coeffs


@eqx.filter_jit
def _one_step(observer, state, u):
    return observer.step(state, u)


def _self_check(obs32, step: CStep, state0, n_points: int = 8):
    """The emitted statements, run in Python on float32 numpy scalars, against the JAX step at random states
    and inputs (floats around the initial state, flags and counters through a few values): a code
    generator bug fails here, with or without a C compiler, and before anything is written."""
    rng = np.random.default_rng(0)
    leaves, tree = jax.tree.flatten(state0)
    n_in = len(step.input_names)
    for k in range(n_points):
        state = []
        for leaf in leaves:
            a = np.asarray(leaf)
            if a.dtype == np.bool_:
                a = np.full(a.shape, k % 2 == 1)
            elif a.dtype.kind in "iu":
                a = np.full(a.shape, k % 3, a.dtype)
            else:
                a = (a + rng.normal(size=a.shape) * np.maximum(1.0, 0.1 * np.abs(a))).astype(a.dtype)
            state.append(a)
        u = (rng.normal(size=n_in) * 10.0).astype(np.float32)
        with jax.enable_x64(False):
            uj = DriveInput(*(jnp.float32(v) for v in u)) if _is_drive(obs32) else jnp.float32(u[0])
            new, out = _one_step(obs32, jax.tree.unflatten(tree, [jnp.asarray(a) for a in state]), uj)
        got_state, got_y = step.run(state, u)
        want = [np.asarray(a, np.float64).reshape(-1) for a in [*jax.tree.leaves(new), *jax.tree.leaves(out)]]
        got = [np.asarray(a, np.float64).reshape(-1) for a in [*got_state, got_y]]
        names = [n for leaf in step.state for n in leaf.scalars()] + step.output_names
        want, got = np.concatenate(want), np.concatenate(got)
        bad = ~(np.abs(got - want) <= 1e-4 * (1 + np.abs(want)))
        if np.any(bad):
            i = int(np.argmax(bad))
            raise AssertionError(
                f"export: the generated C of {type(obs32).__name__} differs from the JAX step at {names[i]}: "
                f"{got[i]!r} vs {want[i]!r} (a code generator bug; nothing written)"
            )


def _leaf_at(observer, name: str):
    """The observer's array leaf whose path name (codegen.leaf_name) is ``name``."""
    params, _ = eqx.partition(observer, eqx.is_array)
    for path, leaf in jax.tree_util.tree_flatten_with_path(params)[0]:
        if leaf_name(path) == name:
            return leaf
    raise KeyError(name)


def compile_and_check(out_dir, *, cc: str | None = None, extra_flags=()) -> float:
    """Compile ``out_dir``'s observer.c + test_main.c with the system C compiler and replay golden.csv.

    Runs ``cc -std=c99 -O2 -Wall -Werror -pedantic observer.c test_main.c -lm`` in a temporary
    folder and returns max |y_C − y_golden| / (1 + |y_golden|) over every step and output.
    Raises ``RuntimeError`` if there is no compiler, the code does not compile or the harness
    cannot read the vectors.
    """
    out = Path(out_dir).resolve()
    cc = cc or shutil.which("cc")
    if cc is None:
        raise RuntimeError("no C compiler (cc) on PATH: export not checked")
    with tempfile.TemporaryDirectory() as tmp:
        exe = Path(tmp) / "jx_test"
        cmd = [cc, *CFLAGS, *extra_flags, str(out / "observer.c"), str(out / "test_main.c"), "-o", str(exe), "-lm"]
        p = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp)
        if p.returncode != 0:
            raise RuntimeError(f"export: {' '.join(cmd)} failed:\n{p.stderr}")
        r = subprocess.run([str(exe), str(out / "golden.csv")], capture_output=True, text=True, timeout=120)
    m = re.search(r"max_rel_err=(\S+)", r.stdout)
    if r.returncode not in (0, 1) or m is None:
        raise RuntimeError(f"export: the harness failed (exit {r.returncode}): {r.stdout}{r.stderr}")
    return float(m.group(1))


# --------------------------------------------------------------------------------------------
# command line (wired into the one parser by tuning.cli)
# --------------------------------------------------------------------------------------------


def add_export_parser(subparsers) -> argparse.ArgumentParser:
    """Add ``jaxobs export`` to the CLI's subparsers."""
    e = subparsers.add_parser("export", help="an observer as C99 float32 with golden vectors and a test harness")
    e.add_argument("--no-cache", action="store_true", help="do not keep compiled programs on disk")
    e.add_argument("result", nargs="?", help="a `jaxobs tune` result.json (its tuned gains)")
    e.add_argument("--design", choices=list(DESIGNS), help="a closed-form design instead of a result")
    e.add_argument("--out", default="out/export", help="folder for the files (default: out/export)")
    e.add_argument(
        "--gains",
        choices=["tuned", "closed_form", "initial"],
        default="tuned",
        help="which gains of the result (default: tuned)",
    )
    e.add_argument(
        "--rule", choices=list(_RULES), help="discretization rule (default: the result's or the component's)"
    )
    e.add_argument("--ts", type=float, help="sample time, s (default: the result's or the component's)")
    e.add_argument("--steps", type=int, default=12_000, help=f"golden record length (>= {MIN_STEPS}, default 12000)")
    e.add_argument(
        "--record",
        choices=["drive", "synthetic"],
        default="drive",
        help="drive observers' golden record: u/i recorded in a sensored FOC drive of the family's machine, "
        "the observer bound to its Rs, L and speed (default), or the synthesized PMSM signal on the observer's "
        "own Rs, L",
    )
    e.add_argument("--check", action="store_true", help="compile with cc and replay the golden vectors")
    e.add_argument("--quiet", action="store_true", help="no progress on stderr")
    e.add_argument("--force", action="store_true", help="overwrite an export already in --out")
    e.set_defaults(func=cli_export)
    return e


def cli_export(args) -> int:
    """``jaxobs export``: 0 on success, 1 if --check finds the C off the golden vectors; bad input raises ValueError."""
    jax.config.update("jax_enable_x64", True)  # the closed forms in double, as `jaxobs closed-form` computes them
    if (args.result is None) == (args.design is None):
        raise ValueError("export: give a result.json or --design (one of them)")
    if args.ts is not None and not (math.isfinite(args.ts) and args.ts > 0):
        raise ValueError(f"--ts must be a sample time > 0 s, got {args.ts}")
    # the output folder is checked and locked before any work (tuning.outdir): no symlinks, one writer,
    # an existing export kept unless --force
    with OutDir(Path(args.out), EXPORT_FILES, force=getattr(args, "force", False)):
        args.log_dir = Path(args.out)
        return _export(args)


def _export(args) -> int:
    notes: list = []
    kw = {}
    if args.ts is not None:
        kw["ts"] = args.ts
    if args.rule is not None:
        kw["rule"] = _RULES[args.rule]()
    if args.result is not None:
        obs = observer_from_result(args.result, gains=args.gains, notes=notes)
        if kw:
            obs = _rebuild(obs, **kw)
            notes = [n for n in notes if not any(f"no '{k}'" in n for k in kw)]
        source = f"{args.result} ({args.gains} gains)"
    else:
        obs = observer_from_design(args.design, **kw)
        source = f"closed form {args.design}, {DESIGNS[args.design][1]}"
    signal = None
    if isinstance(obs, AbstractDriveObserver) and args.record == "drive":
        machine, rpm = _recording_bench(obs)
        obs = obs.bind(machine, rpm * math.pi / 30 * int(machine.p))  # the one binding (its clamp included)
        r_name, l_name, speed = type(obs).bound_fields
        notes = [n for n in notes if "sets Rs, Lq" not in n]
        notes.append(
            f"bound to the recording's machine: {r_name} = {float(getattr(obs, r_name)):g}, "
            f"{l_name} = {float(getattr(obs, l_name)):g}, "
            f"{speed} = {float(getattr(obs, speed)):.6g} rad/s ({rpm:g} r/min)"
        )
        if args.steps < MIN_STEPS:
            raise ValueError(f"export: --steps must be >= {MIN_STEPS}, got {args.steps}")
    elif isinstance(obs, AbstractDriveObserver):
        signal = "synthetic"
    coeffs = export_observer(
        obs, args.out, n_steps=args.steps, signal=signal, source=source, notes=notes, progress=not args.quiet and "auto"
    )
    out = Path(args.out)
    o = coeffs["ops_per_step"]
    print(f"{coeffs['component']} ({coeffs['rule']['name']}, ts = {coeffs['ts']:g} s, float32) from {source}")
    print(
        f"  {out / 'observer.h'}, observer.c   jx_init / jx_step, "
        f"JX_NU = {len(coeffs['inputs'])}, JX_NY = {len(coeffs['outputs'])}"
    )
    print(f"  {out / 'golden.csv'}   {coeffs['golden']['steps']} steps: {coeffs['golden']['signal']}")
    start = f", {o['worst']['total']} in a step taking every dearer branch" if "worst" in o else ""
    print(f"  {out / 'coefficients.json'}   gains, state; {o['steady']['total']} operations per step{start}")
    print(f"  {out / 'test_main.c'}   {' '.join(('cc',) + CFLAGS)} observer.c test_main.c -lm && ./a.out golden.csv")
    for n in notes:
        print(f"note: {n}")
    if args.check:
        if shutil.which("cc") is None:
            print("check: no C compiler (cc) on PATH: not checked")
            return 0
        err = compile_and_check(out)
        ok = err <= TOLERANCE
        print(
            f"check: max |y_C - y_golden|/(1 + |y_golden|) = {err:.3g} over {coeffs['golden']['steps']} steps "
            f"(tolerance {TOLERANCE:g}): {'OK' if ok else 'FAIL'}"
        )
        return 0 if ok else 1
    return 0


def _rebuild(obs, **kw):
    """The same observer with another ts or rule (static fields: rebuilt through the constructor)."""

    values = {f.name: getattr(obs, f.name) for f in dataclasses.fields(obs) if f.name not in ("ts", "rule")}
    values.update(ts=kw.get("ts", obs.ts), rule=kw.get("rule", obs.rule))
    return type(obs)(**values)
