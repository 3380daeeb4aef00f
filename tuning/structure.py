"""The linear structure of a design: what the papers' small-signal models say about a set of gains.

For a design (every constructor value of a component: the tuned or fixed gains,
ωn, ...) :func:`structure` returns one JSON-ready table:

- ``phase_margin_deg``, ``crossover_hz`` (and ``gain_margin_db``) of the loop the
  paper closes (001 Fig. 14 for the FLL family; the PLL through the FA-LESO, 002);
- ``dominant_damping``: the damping ratio −Re p/|p| of the closed loop's slowest
  poles (1 for a real pole), with ``dominant_hz`` = |p|/2π, ``least_pair_damping``
  (the least damped complex pair; 1 if none) and ``stable``; poles cancelled by a zero
  (a zero within 1 % of |p| and a mode whose step-response amplitude |r/p| is below 1e-3
  of the largest mode's: :data:`NEAR_ZERO_REL`, :data:`CANCELLED_REL`) are left out of these
  three and listed in ``cancelled_poles`` (``stable`` and ``poles`` keep every pole);
- the closed-form rule re-evaluated at the design's other gains: the λ of 001 eq (22)
  at the design's k (SOGI-FLL), of eq (29) (WPF), of the symmetric optimum at the
  design's k1, k2 (WIF, with the implied b = k1/k2 and ωc = k2ωn/2 and the PM that b
  would give, eq 39); lam = k²/4 and K1³/(2K2) for the flux observers, and for the
  second-order SOIFO 000's equal-settling-time K1 at the design's K2 (``k1_rule``);
- a Routh test where the paper gives one (FA-LESO, 002 eq 24).

What a model cannot say is ``None``, and ``not_available`` says why, field by field.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from jaxobs import linear, papers
from jaxobs.drive import DriveFile, bench_machine
from jaxobs.observers import CLESO, FALESO, AbstractFluxObserver
from jaxobs.studies.registry import REGISTRY, canonical_key

from .targets import _settling_at_k2, k1_for_settling_time_at_k2, soifo_settling_time

__all__ = ["structure", "STRUCTURE_FIELDS"]

STRUCTURE_FIELDS = ("phase_margin_deg", "crossover_hz", "gain_margin_db", "dominant_damping", "dominant_hz", "stable")


class _ScenarioAxes(Protocol):
    @property
    def axes(self) -> dict[str, list[float]]: ...


class _DriveOfJob(Protocol):
    @property
    def drive_file(self) -> DriveFile: ...


class JobView(Protocol):
    """What :func:`structure` reads of a job (a :class:`jaxobs_tuning.job.Job`, a layer above): its scenarios'
    axes and its drive."""

    @property
    def scenarios(self) -> _ScenarioAxes:
        """The tuning set (its ``axes``: the first ``speed_rpm`` is the operating point)."""
        ...

    @property
    def drive(self) -> _DriveOfJob | None:
        """The job's ``[drive]`` (its ``drive_file``'s machine), or None."""
        ...


# One compiled program per loop shape (the designs of a job share it; the persistent compilation cache keeps
# it across runs): run eagerly, margins dispatched every operation on its own and traced its two vmapped Newton
# root finds anew per design (its cost: docs/performance.md); the same numbers bit for bit.
def _margin_values(loop):
    """The margins this table reads, as a tuple of arrays."""
    m = linear.margins(loop)
    return m.phase_margin, m.omega_gc, m.gain_margin


# not a kept program (jaxobs.kept_jit): keeping its trace saved 0.24 CPU s of a warm default job (0.26 s against
# 0.50 s on the persistent compilation cache alone) for an export on every first run (docs/performance.md)
_margins_of = eqx.filter_jit(_margin_values)


def _margins(loop) -> tuple[dict, dict]:
    pm, wgc, gm = (float(x) for x in _margins_of(loop))
    out, why = {}, {}
    out["phase_margin_deg"] = pm if math.isfinite(pm) else None
    out["crossover_hz"] = wgc / (2 * math.pi) if math.isfinite(wgc) else None
    if out["phase_margin_deg"] is None:
        why["phase_margin_deg"] = why["crossover_hz"] = "the loop gain never crosses 1"
    out["gain_margin_db"] = 20 * math.log10(gm) if math.isfinite(gm) and gm > 0 else None
    if out["gain_margin_db"] is None:
        why["gain_margin_db"] = "the loop's phase never crosses -180 deg (infinite gain margin)"
    return out, why


# A pole-zero doublet is left out of dominant_damping, dominant_hz and least_pair_damping (it stays in "poles",
# "stable" and is listed in "cancelled_poles"): a pole with a zero within NEAR_ZERO_REL |p| of it whose mode
# contributes less than CANCELLED_REL of the largest mode's amplitude to the step response (|r_i/p_i|, r_i its
# residue).  The zero test keeps a numerically split repeated pole, whose residues are huge, from hiding the
# others.  The FA-LESO's PLL loop (002) has such a doublet near ±jωe: the FA-LESO's own slow pole
# -k1/(k2 - jωe) sits next to its zero -k1/k2, a nearly undamped pair with a zero pair beside it whose mode is
# far below 1e-3 of the largest (docs/performance.md), so it is no "dominant" dynamics of the loop, while
# reporting it read as a nearly unstable design.  1e-3 keeps every mode a plot of the response could show.
CANCELLED_REL = 1e-3
NEAR_ZERO_REL = 1e-2


def _mode_amplitudes(tf, p) -> np.ndarray:
    """|r_i / p_i|: each pole's coefficient in the step response (inf where undefined: a repeated pole, or a
    pole at 0, is never taken for cancelled)."""
    num, den = np.asarray(tf.num, dtype=complex), np.asarray(tf.den, dtype=complex)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.abs(np.polyval(num, p) / np.polyval(np.polyder(den), p) / p)
    return np.where(np.isfinite(a), a, np.inf)


def _poles(tf) -> dict:
    p = np.asarray(tf.poles(), dtype=complex)
    amp = _mode_amplitudes(tf, p)
    finite = amp[np.isfinite(amp)]
    big = float(np.max(finite)) if finite.size else 0.0
    z = np.asarray(tf.zeros(), dtype=complex)
    near = np.array([bool(z.size) and np.min(np.abs(z - x)) < NEAR_ZERO_REL * abs(x) for x in p], dtype=bool)
    cancelled = near & np.isfinite(amp) & (amp < CANCELLED_REL * big)
    seen = p[~cancelled] if np.any(~cancelled) else p  # the modes the response shows
    dom = seen[np.argmax(np.real(seen))]
    mag = abs(dom)
    cplx = [z for z in seen if abs(z.imag) > 1e-9 * abs(z)]
    return {
        "least_pair_damping": float(min(-z.real / abs(z) for z in cplx)) if cplx else 1.0,
        "stable": bool(np.all(np.real(p) < 0)),
        "dominant_damping": float(-dom.real / mag) if mag > 0 else None,
        "dominant_hz": float(mag / (2 * math.pi)),
        "poles": [[float(z.real), float(z.imag)] for z in sorted(p, key=lambda z: (z.real, z.imag))],
        "cancelled_poles": [
            [float(z.real), float(z.imag)] for z in sorted(p[cancelled], key=lambda z: (z.real, z.imag))
        ],
    }


def _na(out: dict, why: dict, reason: str, *fields):
    for f in fields:
        out[f] = None
        why[f] = reason


def _fll(name: str, v: dict, small_signal: Callable) -> tuple[dict, dict]:
    wn = float(v["omega_n"])
    model = small_signal(v)  # 001's small-signal model of this FLL
    if name == "SOGIFLL":
        k = float(v["k"])
        rule = {
            "rule": "001 eq (22): lam = k^2 omega_n^2 / (8 zeta^2), zeta = 1/sqrt(2), at this k",
            "lam_rule": float(linear.sogi_fll_lambda(k, wn)),
        }
    elif name == "SOGIFLLWPF":
        rule = {
            "rule": "001 eq (29): lam = 2 (zeta + 1) omega_n^2 / (2 zeta + 1)^3 (it assumes k1 = k2 = sqrt(2))",
            "lam_rule": float(linear.wpf_lambda(wn)),
        }
    else:
        k1, k2 = float(v["k1"]), float(v["k2"])
        b, wc = k1 / k2, k2 * wn / 2
        rule = {
            "rule": "001 eq (34), symmetric optimum at this k1, k2: b = k1/k2, omega_c = k2 omega_n/2, "
            "lam = 2 omega_c^2 / b",
            "b_implied": b,
            "omega_c_implied": wc,
            "crossover_hz_implied": wc / (2 * math.pi),
            "lam_rule": 2 * wc**2 / b,
            "phase_margin_deg_implied": float(np.degrees(linear.symmetric_optimum_pm(b))) if b > 1 else None,
        }
    out, why = _margins(model.open_loop)
    out.update(_poles(model.frequency))
    rule["lam_over_rule"] = float(v["lam"]) / rule["lam_rule"]
    if rule.get("phase_margin_deg_implied", 0.0) is None:
        why["phase_margin_deg_implied"] = "b = k1/k2 <= 1: no symmetric optimum"
    out["model"] = {"SOGIFLL": "001 eqs (18)-(21)", "SOGIFLLWPF": "001 eqs (23)-(25)"}.get(name, "001 eqs (30)-(33)")
    out["closed_form_rule"] = rule
    return out, why


def _flux(name: str, v: dict, small_signal: Callable) -> tuple[dict, dict]:
    w = float(v["omega_init"])
    out, why = {}, {}
    _na(
        out,
        why,
        "jaxobs.linear has no small-signal model of the flux observers' frequency loop (000 gives the filter only)",
        "phase_margin_deg",
        "crossover_hz",
        "gain_margin_db",
    )
    if name == "SOIFO":
        k, lam = float(v["k"]), float(v["lam"])
        out.update(_poles(small_signal(v)))
        rule = {"rule": "lam = k^2/4 (001 eq 22 normalized), at this k", "lam_rule": linear.soifo_lambda(k)}
    else:
        K1, K2, lam = float(v["K1"]), float(v["K2"]), float(v["lam"])
        out.update(_poles(small_signal(v)))
        rule = {"rule": "lam = K1^3/(2 K2), at this K1, K2", "lam_rule": linear.second_order_soifo_lambda(K1, K2)}
        rule.update(_k1_rule(K1, K2, w, why))
    rule["lam_over_rule"] = lam / rule["lam_rule"]
    out["model"] = "000 eqs (15), (20): the filter psi/e at omega_init (poles and damping are the filter's)"
    out["closed_form_rule"] = rule
    return out, why


def _k1_rule(K1: float, K2: float, omega_init: float, why: dict) -> dict:
    """000's settling-time rule re-evaluated at this K2 (jaxobs_tuning.targets.k1_for_settling_time_at_k2).

    Both envelope models depend on ω't only, so the K1 found at ω' = 100π holds at any ω' (the design's
    ``omega_init``), and the settling times scale as 100π/ω'.  One compile per process (docs/performance.md).
    """
    w = papers.FLUX_FIG5_OMEGA
    target = soifo_settling_time(papers.SOIFO_K, w)
    k1 = k1_for_settling_time_at_k2(target, K2, w)
    own = float(_settling_at(K1, K2, w))
    scale = w / omega_init if omega_init > 0 else float("nan")
    out = {
        "k1_rule_doc": "000: equal 2 % settling time of the amplitude envelope (001 eqs 18, 30) with the SOIFO at "
        "k = 1.414, at this K2: the smallest K1 that settles as fast (at fixed K2 the settling time is not "
        "monotonic in K1; see tuning/targets.py)",
        "k1_rule": k1,
        "k1_over_rule": K1 / k1 if k1 else None,
        "settling_time_target_ms": 1e3 * target * scale,
        "settling_time_ms": 1e3 * own * scale,
    }
    if k1 is None:
        why["k1_rule"] = why["k1_over_rule"] = (
            f"no K1 in [0.05, 20] settles within the SOIFO's {1e3 * target * scale:.3g} ms at K2 = {K2:.4g} "
            f"(the envelope decays at K2 omega_init/4 whatever K1 is)"
        )
    return out


def _settling_at(K1, K2, omega):
    return _settling_at_k2(jnp.asarray(np.full(64, float(K1))), jnp.asarray(float(K2)), float(omega), 0.02)[
        0
    ]  # same compile


def _drive_speed(job: JobView | None) -> float:
    """The electrical speed (rad/s) the drive jobs linearize at: the first scenario's speed (600 r/min default)
    times the pole pairs of the job's machine (its drive file; 002's IPMSM without a job)."""
    rpm = (job.scenarios.axes.get("speed_rpm") if job is not None else None) or [600.0]
    rpm = rpm[0]
    machine = job.drive.drive_file.machine if job is not None and job.drive is not None else bench_machine("ipmsm002")
    return rpm * math.pi / 30 * machine.p


def _leso(name: str, v: dict, job: JobView | None) -> tuple[dict, dict]:
    from jaxobs.linear import TransferFunction

    we = _drive_speed(job)
    kp, ki = float(v["kp_pll"]), float(v["ki_pll"])
    out, why = {}, {}
    if name == "FALESO":
        k1, k2 = float(v["k1"]), float(v["k2"])
        loop = linear.faleso_pll_loop(k1, k2, we, kp, ki)
        m, why = _margins(loop)
        out.update(m)
        out.update(_poles(loop.feedback()))
        out["routh_stable"] = bool(linear.faleso_is_stable(k1, k2, we))
        out["model"] = f"002 eqs (21)-(24): the PLL through the FA-LESO, linearized at omega_e = {we:.6g} rad/s"
    else:
        pll = TransferFunction(np.array([kp, ki]), np.array([1.0, 0.0, 0.0]))
        m, why = _margins(pll)
        out.update(m)
        out.update(_poles(pll.feedback()))
        out["leso"] = _poles(linear.cleso_tf(float(v["omega0"])))
        out["model"] = "the type-2 PLL alone, (kp s + ki)/s^2 (the C-LESO is not in the loop model)"
        why["routh_stable"] = "no Routh test for the C-LESO in the papers (its poles are real, at -omega0)"
        out["routh_stable"] = None
    out["omega_e"] = we
    # Scope: this is the observer's loop alone.  In a sensorless job the PLL's
    # θ̂ and ω̂ close the FOC's current and speed loops, and an Lq mismatch makes the LESO's angle error
    # depend on i_q, which the speed loop sets from ω̂: a second loop (speed loop -> i_q -> θ̂ error -> ω̂
    # -> speed loop) that this model leaves open.  So "stable" and the margins are necessary, not sufficient
    # (a design stable here oscillated in the sensorless drive: docs/performance.md): the drive presets score
    # the closed loop on a long horizon.
    out["scope"] = (
        "the observer's PLL loop alone, nominal machine (no Rs/L mismatch), speed loop and FOC open; it does "
        "not model the sensorless drive's speed loop closing through the estimate, so 'stable' here does not "
        "mean the sensorless drive is stable (the long-horizon simulation scores that)"
    )
    b = math.sqrt(ki)
    out["closed_form_rule"] = {
        "rule": "PLL pole placement kp = 2 zeta omega_b, ki = omega_b^2 (zeta = 1/sqrt(2)) at this ki",
        "kp_rule": float(linear.pll_gains(b)[0]),
        "pll_bandwidth_hz_implied": b / (2 * math.pi),
    }
    return out, why


def structure(component: str, values: dict, job: JobView | None = None) -> dict:
    """The linear structure of a design (see the module docstring).

    Args:
        component: The registered class name.
        values: Every constructor value.
        job: The job (its scenarios' first speed and its drive file's machine set a drive observer's operating
            point), or None (600 r/min on 002's IPMSM).

    Returns:
        The structure's fields, with ``"not_available"``: field -> why, where some could not be given.
    """
    # the paper's small-signal model of the class (jaxobs.studies.registry), analysed by its family: an FLL's loop, a
    # flux observer's filter, a LESO's PLL loop (the C-LESO's and the FA-LESO's: 002 gives them)
    entry = REGISTRY.get(component)
    cls = entry.cls if entry is not None else None
    if cls is not None:  # a result.json's values may name a flux observer's omega_init omega0
        values = {canonical_key(cls, k): v for k, v in values.items()}
    try:
        if cls in (CLESO, FALESO):
            out, why = _leso(component, values, job)
        elif entry is not None and entry.model is not None and issubclass(entry.cls, AbstractFluxObserver):
            out, why = _flux(component, values, entry.model)
        elif entry is not None and entry.model is not None:
            out, why = _fll(component, values, entry.model)
        else:
            out, why = {}, {}
            _na(out, why, f"no small-signal model of {component} in jaxobs.linear", *STRUCTURE_FIELDS)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as e:  # a model that cannot be evaluated
        out, why = {}, {}
        _na(out, why, f"the linear model could not be evaluated: {e}", *STRUCTURE_FIELDS)
    if why:
        out["not_available"] = why
    return out
