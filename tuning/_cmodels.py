"""C emitters for the observers' cores, composed per observer class as the JAX observers compose them.

Each function here mirrors one function of :mod:`jaxobs.observers._cores` (or
of the observer modules) operator for operator, on :mod:`tuning._cexpr`
expressions instead of arrays, so the emitted C adds and multiplies in the
order the JAX step does.  A model (:class:`CModel`) is what :mod:`tuning.export`
needs to write one observer: its state, inputs, outputs, vector field
``f(x, e)``, outputs, the input over the period, and its gains, named.

Two kinds of step (:mod:`jaxobs.observers.base`):

- ``signal`` (the FLL family of 001): the input ``e`` of ``f`` is the sample itself,
  held over the period; the step returns the outputs of the state *before* the update;
- ``drive`` (the flux observers of 000, the LESOs of 002 with their PLL): the state
  also holds the previous current and the voltage applied over the period; ``f``'s input
  is the back EMF of the period (000 eq 6, held) or the LESO's (u, i) at the start,
  middle and end of the period (``Knots``); the first sample only records them; the
  step returns the outputs *after* the update.

Not written: ``SecondOrderSOIFO(discretization="paper")`` (000's printed difference
equations, a step of its own).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import equinox as eqx
import numpy as np

from jaxobs.observers.fll import SOGIFLL, SOGIFLLWIF, SOGIFLLWPF
from jaxobs.observers.flux import SOIFO, LPFFlux, PureIntegratorFlux, SecondOrderSOIFO
from jaxobs.observers.leso import CLESO, FALESO, GILESO

from ._cexpr import atan, atan2, cos, fabs, fmax, fmod, gt, let, lt, named, select, sin, sqrt, var

# --------------------------------------------------------------------------------------------
# cores (jaxobs/observers/_cores.py, jaxobs/_math.py)
# --------------------------------------------------------------------------------------------


def gi_vf(y, q, x, w):
    """Generalized integrator: (ẏ, q̇) = (ω'(x − q), ω' y)."""
    return w * (x - q), w * y


def sogi_vf(y, q, v, w, k):
    """SOGI (001 eqs 6–7): the GI with input k (v − y)."""
    return gi_vf(y, q, k * (v - y), w)


def sogi2_vf(za, zb, y, q, v, w, K1, K2):
    """Second-order SOGI (000 eqs 17–18): two GIs in cascade, returns (ża, żb, ẏ, q̇)."""
    dza, dzb = gi_vf(za, zb, K2 * (K1 * (v - y) - za), w)
    dy, dq = gi_vf(y, q, za, w)
    return dza, dzb, dy, dq


def safe_sq_amplitude(y, q, v_floor):
    """V̂² = max(y² + q², v_floor²); ``v_floor`` a Python float, as in the JAX core."""
    return let("v2", fmax(y * y + q * q, v_floor * v_floor))


def fll_rate(err, q, y, lam, v_floor):
    """Normalized FLL, 001 eq (8): ω̂̇ = −λ · err · q / V̂²."""
    return -lam * err * q / safe_sq_amplitude(y, q, v_floor)


def pll_vf(theta_p, omega_p, err, kp, ki):
    """Type-2 PLL: (θ̇_p, ω̇_p) = (ω_p + k_p err, k_i err)."""
    return omega_p + kp * err, ki * err


def quadrature_error(x_a, x_b, theta_p, floor):
    """Normalized quadrature detector (x_b cos θ_p − x_a sin θ_p)/max(|x|, floor)."""
    mag = let("mag", sqrt(fmax(x_a * x_a + x_b * x_b, floor * floor)))
    return let("err", (x_b * cos(theta_p) - x_a * sin(theta_p)) / mag)


_TINY = 1e-30  # jaxobs._math._TINY


def safe_norm2(x, y):
    """√(x² + y²), 0 below 1e-30 (the value of jaxobs._math.safe_norm2; its inner where only guards gradients)."""
    sq = let("sq", x * x + y * y)
    return select(let("ok", gt(sq, _TINY)), sqrt(sq), 0.0)


def safe_atan2(y, x):
    """atan2(y, x), 0 at the origin (the value of jaxobs._math.safe_atan2)."""
    return select(let("ok", gt(x * x + y * y, _TINY)), atan2(y, x), 0.0)


def wrap(a):
    """jaxobs.observers.leso._wrap: π − mod(π − a, 2π), ``jnp.mod`` (sign of the divisor) from C's fmodf."""
    r = let("r", fmod(math.pi - a, 2 * math.pi))
    return math.pi - select(lt(r, 0.0), r + 2 * math.pi, r)  # divisor > 0: jnp.mod adds it to a negative rem


# --------------------------------------------------------------------------------------------
# models
# --------------------------------------------------------------------------------------------


@dataclass
class CModel:
    """An observer ready to be written as C: everything but the discretization rule."""

    component: str  # class name
    reference: str  # paper and equations
    kind: str  # "signal" or "drive" (module doc)
    states: list  # C names of the state variables, in the order of the flat JAX state
    state_doc: list  # one line each
    inputs: list  # names of the step inputs u[0..JX_NU-1]
    input_doc: list
    field: list  # names of f's input e[0..JX_NE-1]
    outputs: list  # names of the outputs y[0..JX_NY-1] (the JAX output NamedTuple's fields)
    output_doc: list
    angles: tuple  # indices of the outputs that are angles (compared modulo 2π)
    gains: dict  # leaf name -> (C macro, float32 value)
    statics: dict  # static fields (floors, options) -> value, for the record
    f: list  # ẋ in the state and field variables
    out: list  # outputs in the state (and, for drive observers, field) variables
    x0: np.ndarray  # initial state (float32)
    path: str = "held"  # "held": one e per period; "knots": e at the start, middle and end
    # drive observers: e (held) or e0, em, e1 (knots) from the step inputs and the memory
    # variables u_prev_a, u_prev_b, i_prev_a, i_prev_b, started; as (array name, index, expr)
    period_input: list = field(default_factory=list)
    post: list = field(default_factory=list)  # (state index, expr in the state vars) applied to x₊
    jax_f: Callable | None = None  # (observer, x, e) -> f, for the export's self-check
    jax_out: Callable | None = None  # (observer, x, e) -> outputs, idem (None: checked by the golden run only)
    omega_signal: float = 2 * math.pi * 50  # electrical frequency of the golden test signal, rad/s
    signal_start: str = ""  # drive observers: how the golden record starts (tuning.export.drive_test_signal)


def _gains(obs) -> dict:
    """Every array leaf of the observer as a named float32 constant ``JX_<NAME>``."""
    gains = {}
    macros = set()
    for fld in dataclasses.fields(obs):
        v = getattr(obs, fld.name)
        if eqx.is_array(v):
            if np.ndim(v) != 0:
                raise ValueError(
                    f"{type(obs).__name__}.{fld.name}: only scalar gains can be exported, got shape {np.shape(v)}"
                )
            macro = "JX_" + fld.name.upper()
            if macro in macros:
                raise ValueError(f"{type(obs).__name__}: two gains map to the C name {macro}")
            macros.add(macro)
            gains[fld.name] = named(macro, np.float32(v))
    return gains


def _statics(obs) -> dict:
    out = {}
    for fld in dataclasses.fields(obs):
        v = getattr(obs, fld.name)
        if fld.name in ("ts", "rule") or eqx.is_array(v):
            continue
        out[fld.name] = v
    return out


def _named(g: dict) -> dict:
    return {k: (e.value[0], e.value[1]) for k, e in g.items()}


# --- the FLL family (001) ------------------------------------------------------------------

_FLL_OUT_DOC = [
    "v_alpha: filtered in-phase signal v' (input units)",
    "v_beta: filtered quadrature signal qv' (input units)",
    "amplitude: V^ = sqrt(v'^2 + qv'^2) (input units)",
    "theta: phase atan2(qv', v') (rad, in (-pi, pi])",
    "omega: frequency w^ (rad/s)",
]


def fll_output(y, q, w):
    """The FLL family's outputs (fll.py ``_fll_output``): v', qv', V̂, θ̂ = atan2(qv', v'), ω̂."""
    return [y, q, safe_norm2(y, q), safe_atan2(q, y), w]


def _fll_model(obs, name, reference, states, state_doc, f, out, g) -> CModel:
    return CModel(
        component=name,
        reference=reference,
        kind="signal",
        states=states,
        state_doc=state_doc,
        inputs=["v"],
        input_doc=["v: the sampled single-phase signal (input units)"],
        field=["v"],
        outputs=["v_alpha", "v_beta", "amplitude", "theta", "omega"],
        output_doc=_FLL_OUT_DOC,
        angles=(3,),
        gains=_named(g),
        statics=_statics(obs),
        f=f,
        out=out,
        x0=np.asarray(obs.initial_state(), np.float32),
        jax_f=lambda o, x, e: o.f(x, e[0]),
        jax_out=lambda o, x, e: o.output(x),
        omega_signal=float(obs.omega_n),
    )


_FLL_STATE_DOC = ["v', in-phase output", "qv', quadrature output", "w^, frequency (rad/s)"]


def _sogifll(obs: SOGIFLL) -> CModel:
    g = _gains(obs)
    y, q, w, v = var("vp"), var("qvp"), var("w"), var("v")
    dy, dq = sogi_vf(y, q, v, w, g["k"])
    dw = fll_rate(v - y, q, y, g["lam"], obs.v_floor)
    return _fll_model(
        obs,
        "SOGIFLL",
        "paper 001 Fig. 1(a), eqs (6)-(8)",
        ["vp", "qvp", "w"],
        _FLL_STATE_DOC,
        [dy, dq, dw],
        fll_output(y, q, w),
        g,
    )


def _wpf(obs: SOGIFLLWPF) -> CModel:
    g = _gains(obs)
    p, qp, y, q, w, v = var("p"), var("qp"), var("vp"), var("qvp"), var("w"), var("v")
    dp, dqp = sogi_vf(p, qp, v, w, g["k1"])
    dy, dq = sogi_vf(y, q, p, w, g["k2"])
    dw = fll_rate(p - y, q, y, g["lam"], obs.v_floor)
    return _fll_model(
        obs,
        "SOGIFLLWPF",
        "paper 001 Fig. 1(b) (SOGI prefilter + SOGI-FLL)",
        ["p", "qp", "vp", "qvp", "w"],
        ["prefilter in-phase output", "prefilter quadrature"] + _FLL_STATE_DOC,
        [dp, dqp, dy, dq, dw],
        fll_output(y, q, w),
        g,
    )


def _wif(obs: SOGIFLLWIF) -> CModel:
    g = _gains(obs)
    za, zb, y, q, w, v = var("za"), var("zb"), var("vp"), var("qvp"), var("w"), var("v")
    # Golestan's (k1, k2) = Xu's (K2, K1)
    dza, dzb, dy, dq = sogi2_vf(za, zb, y, q, v, w, K1=g["k2"], K2=g["k1"])
    if obs.fll_error == "input":
        dw = fll_rate(za, q, y, g["lam"] / g["k2"], obs.v_floor)
    else:
        dw = fll_rate(v - y, q, y, g["lam"], obs.v_floor)
    return _fll_model(
        obs,
        "SOGIFLLWIF",
        "paper 001 Fig. 1(c) (second-order SOGI of 000 eqs 17-18 + FLL)",
        ["za", "zb", "vp", "qvp", "w"],
        ["first GI, in-phase (input of the output GI)", "first GI, quadrature"] + _FLL_STATE_DOC,
        [dza, dzb, dy, dq, dw],
        fll_output(y, q, w),
        g,
    )


# --- drive observers: shared pieces --------------------------------------------------------

_DRIVE_INPUTS = ["u_a", "u_b", "i_a", "i_b"]  # jaxobs.drive DriveInput's fields, in order
_DRIVE_INPUT_DOC = [
    "u_a: voltage applied over the period starting now, alpha (V)",
    "u_b: voltage applied over the period starting now, beta (V)",
    "i_a: current sampled now, alpha (A)",
    "i_b: current sampled now, beta (A)",
]
MEMORY = {  # the drive observers' memory in jx_state, as variables of period_input
    "u_prev_a": "s->u_prev[0]",
    "u_prev_b": "s->u_prev[1]",
    "i_prev_a": "s->i_prev[0]",
    "i_prev_b": "s->i_prev[1]",
}


def _drive_vars():
    u = [var("u_a"), var("u_b")]
    i = [var("i_a"), var("i_b")]
    u_prev = [var("u_prev_a"), var("u_prev_b")]
    i_prev = [var("i_prev_a"), var("i_prev_b")]
    return u, i, u_prev, i_prev, var("started")


# --- flux observers (000) --------------------------------------------------------------------

_FLUX_OUT = ["psi_a", "psi_b", "theta", "omega", "e_a", "e_b"]
_FLUX_OUT_DOC = [
    "psi_a: estimated rotor flux, alpha (Wb)",
    "psi_b: estimated rotor flux, beta (Wb)",
    "theta: position atan2(psi_b, psi_a) (rad, in (-pi, pi])",
    "omega: speed w^e (rad/s, signed)",
    "e_a: back EMF fed to the filter over the period just ended, alpha (V)",
    "e_b: back EMF, beta (V)",
]


def back_emf(g, ts):
    """_FluxBase.back_emf: e = u_prev − R̂s·0.5·(i + i_prev) − L̂ (i − i_prev)/ts, 0 at the first sample."""
    u, i, u_prev, i_prev, started = _drive_vars()
    e = [u_prev[k] - g["Rs"] * 0.5 * (i[k] + i_prev[k]) - g["L"] * (i[k] - i_prev[k]) / ts for k in (0, 1)]
    return [("e", k, select(started, e[k], 0.0)) for k in (0, 1)]


def _signed(omega_abs, psi_a, psi_b, y_a, y_b):
    cross = psi_a * y_b - psi_b * y_a
    return select(lt(cross, 0.0), -omega_abs, omega_abs)


def _fll_norm(ya, qa, yb, qb, e, v_floor):
    """flux._fll_norm: max(V̂α² + V̂β², |ê|², v_floor²)."""
    v2 = safe_sq_amplitude(ya, qa, 0.0) + safe_sq_amplitude(yb, qb, 0.0)
    return let("norm", fmax(fmax(v2, e[0] * e[0] + e[1] * e[1]), v_floor * v_floor))


def _flux_model(obs, name, reference, states, state_doc, f, out, g, omega_signal, start) -> CModel:
    return CModel(
        component=name,
        reference=reference,
        kind="drive",
        states=states,
        state_doc=state_doc,
        inputs=list(_DRIVE_INPUTS),
        input_doc=list(_DRIVE_INPUT_DOC),
        field=["e_a", "e_b"],
        outputs=list(_FLUX_OUT),
        output_doc=list(_FLUX_OUT_DOC),
        angles=(2,),
        gains=_named(g),
        statics=_statics(obs),
        f=f,
        out=out,
        x0=np.asarray(obs.initial_state(), np.float32),
        path="held",
        period_input=back_emf(g, obs.ts),
        jax_f=lambda o, x, e: o.f(x, e),
        jax_out=lambda o, x, e: o.output(x, e),
        omega_signal=omega_signal if omega_signal > 0 else 2 * math.pi * 50,
        signal_start=start,
    )


def _pll_flux(obs, name, reference, dpsi, out_psi, g):
    psi_a, psi_b, th, w = var("psi_a"), var("psi_b"), var("th"), var("w")
    e = [var("e_a"), var("e_b")]
    err = quadrature_error(psi_a, psi_b, th, obs.psi_floor)
    dth, dw = pll_vf(th, w, err, g["kp_pll"], g["ki_pll"])
    pa, pb = out_psi(psi_a, psi_b, w)
    out = [pa, pb, safe_atan2(pb, pa), w, e[0], e[1]]
    return _flux_model(
        obs,
        name,
        reference,
        ["psi_a", "psi_b", "th", "w"],
        ["flux estimate, alpha (Wb)", "flux estimate, beta (Wb)", "PLL angle (rad)", "PLL speed (rad/s)"],
        [*dpsi(psi_a, psi_b, e), dth, dw],
        out,
        g,
        float(obs.omega0),
        "flux",
    )


def _pure_integrator(obs: PureIntegratorFlux) -> CModel:
    g = _gains(obs)
    return _pll_flux(
        obs,
        "PureIntegratorFlux",
        "paper 000 eq (6): psi = integral of the back EMF, type-2 PLL on psi",
        lambda pa, pb, e: [e[0], e[1]],
        lambda pa, pb, w: (pa, pb),
        g,
    )


def _lpf(obs: LPFFlux) -> CModel:
    g = _gains(obs)
    wc = g["omega_c"]

    def psi_out(pa, pb, w):
        if not obs.compensate:
            return pa, pb
        w_safe = let("w_safe", select(gt(fabs(w), 1.0), w, 1.0))
        gain = let("gain", sqrt(w_safe * w_safe + wc**2) / fabs(w_safe))
        rot = -atan(wc / w_safe)
        c, s = let("rot_c", cos(rot)), let("rot_s", sin(rot))
        return gain * (c * pa - s * pb), gain * (s * pa + c * pb)

    return _pll_flux(
        obs,
        "LPFFlux",
        "paper 000 Sec. II: psi = e/(s + wc), eq (11) compensation, type-2 PLL",
        lambda pa, pb, e: [e[0] - wc * pa, e[1] - wc * pb],
        psi_out,
        g,
    )


def _soifo(obs: SOIFO) -> CModel:
    g = _gains(obs)
    ya, qa, yb, qb, w = var("y_a"), var("q_a"), var("y_b"), var("q_b"), var("w")
    e = [var("e_a"), var("e_b")]
    dya, dqa = sogi_vf(ya, qa, e[0], w, g["k"])
    dyb, dqb = sogi_vf(yb, qb, e[1], w, g["k"])
    num = (e[0] - ya) * qa + (e[1] - yb) * qb
    lam = g["lam"] * w * w  # frequency-normalized FLL gain
    dw = -lam * num / _fll_norm(ya, qa, yb, qb, e, obs.v_floor)
    wm = let("w_out", fmax(w, obs.omega_min))
    pa, pb = let("pa", qa / wm), let("pb", qb / wm)
    out = [pa, pb, safe_atan2(pb, pa), _signed(w, pa, pb, ya, yb), e[0], e[1]]
    return _flux_model(
        obs,
        "SOIFO",
        "paper 000 Sec. III-A, eq (15), Fig. 3 (two SOGIs, one FLL)",
        ["y_a", "q_a", "y_b", "q_b", "w"],
        [
            "SOGI alpha, in-phase",
            "SOGI alpha, quadrature",
            "SOGI beta, in-phase",
            "SOGI beta, quadrature",
            "FLL frequency |w^e| (rad/s)",
        ],
        [dya, dqa, dyb, dqb, dw],
        out,
        g,
        float(obs.omega0),
        "alpha",
    )


def _sosoifo(obs: SecondOrderSOIFO) -> CModel:
    if obs.discretization != "rule":
        raise ValueError(
            "export: SecondOrderSOIFO(discretization='paper') (000 eqs 22-25) is not supported yet; "
            "export the rule-discretized SecondOrderSOIFO"
        )
    g = _gains(obs)
    names = ["za_a", "zb_a", "y_a", "q_a", "za_b", "zb_b", "y_b", "q_b", "w"]
    x = [var(n) for n in names]
    e = [var("e_a"), var("e_b")]
    w = x[8]
    ax = sogi2_vf(x[0], x[1], x[2], x[3], e[0], w, g["K1"], g["K2"])
    bx = sogi2_vf(x[4], x[5], x[6], x[7], e[1], w, g["K1"], g["K2"])
    num = x[0] * x[3] + x[4] * x[7]
    lam = g["lam"] * w * w
    dw = -(lam / g["K1"]) * num / _fll_norm(x[2], x[3], x[6], x[7], e, obs.v_floor)
    wm = let("w_out", fmax(w, obs.omega_min))
    pa, pb = let("pa", x[3] / wm), let("pb", x[7] / wm)
    out = [pa, pb, safe_atan2(pb, pa), _signed(w, pa, pb, x[2], x[6]), e[0], e[1]]
    doc = ["first GI, in-phase", "first GI, quadrature", "output GI, in-phase", "output GI, quadrature"]
    return _flux_model(
        obs,
        "SecondOrderSOIFO",
        "paper 000 Sec. III-B, eq (20), Fig. 4 (second-order SOGIs, one FLL)",
        names,
        [f"alpha {d}" for d in doc] + [f"beta {d}" for d in doc] + ["FLL frequency |w^e| (rad/s)"],
        [*ax, *bx, dw],
        out,
        g,
        float(obs.omega0),
        "alpha",
    )


# --- LESOs (002) with their PLL ------------------------------------------------------------

_LESO_OUT = ["e_a", "e_b", "theta", "omega", "theta_emf"]
_LESO_OUT_DOC = [
    "e_a: estimated equivalent back EMF, alpha (V)",
    "e_b: estimated equivalent back EMF, beta (V)",
    "theta: PLL angle (rad, wrapped to (-pi, pi])",
    "omega: PLL speed w^e (rad/s)",
    "theta_emf: the back EMF's own angle atan2(-e_a, e_b) (rad)",
]


def _cleso(g, xl, u, i, w):
    mu, b0 = g["Rs"] / g["Lq"], 1.0 / g["Lq"]
    l1, l2 = 2 * g["omega0"] - mu, g["omega0"] ** 2
    x1, x2 = xl[0:2], xl[2:4]
    eps = [let(f"eps_{ax}", x1[k] - i[k]) for k, ax in enumerate("ab")]
    dx1 = [x2[k] + b0 * u[k] - mu * x1[k] - l1 * eps[k] for k in (0, 1)]
    dx2 = [-l2 * eps[k] for k in (0, 1)]
    return [*dx1, *dx2], [-g["Lq"] * x2[k] for k in (0, 1)]


def _gileso(g, xl, u, i, w):
    mu, b0 = g["Rs"] / g["Lq"], 1.0 / g["Lq"]
    l1 = 2 * g["omega0"] - mu
    x1, x2a, r, rd = xl[0:2], xl[2:4], xl[4:6], xl[6:8]
    eps = [let(f"eps_{ax}", x1[k] - i[k]) for k, ax in enumerate("ab")]
    x2 = [x2a[k] - r[k] for k in (0, 1)]
    dx1 = [x2[k] + b0 * u[k] - mu * x1[k] - l1 * eps[k] for k in (0, 1)]
    dx2a = [-(g["omega0"] ** 2) * eps[k] for k in (0, 1)]
    drd = [2 * g["K_r"] * g["omega_c"] * eps[k] - 2 * g["omega_c"] * rd[k] - w * w * r[k] for k in (0, 1)]
    return [*dx1, *dx2a, *rd, *drd], [-g["Lq"] * x2[k] for k in (0, 1)]


def _faleso(g, xl, u, i, w):
    mu, b0 = g["Rs"] / g["Lq"], 1.0 / g["Lq"]
    x1, z = xl[0:2], xl[2:4]
    eps = [let(f"eps_{ax}", x1[k] - i[k]) for k, ax in enumerate("ab")]
    x2 = [let(f"x2_{ax}", -g["k2"] * eps[k] - g["k1"] * z[k]) for k, ax in enumerate("ab")]
    rot = [-w * eps[1], w * eps[0]]  # j w^ eps
    dx1 = [x2[k] + b0 * u[k] - mu * x1[k] + mu * eps[k] + rot[k] for k in (0, 1)]
    return [*dx1, *eps], [-g["Lq"] * x2[k] for k in (0, 1)]


_LESO = {  # per class: the LESO part, its state pairs (alpha, beta) with their meaning, the reference
    CLESO: (
        _cleso,
        [("x1", "current estimate x^1 (A)"), ("x2", "disturbance x^2 = -e/Lq (A/s)")],
        "paper 002 eqs (15)-(17): conventional LESO, l1 = 2 w0 - mu, l2 = w0^2, quadrature PLL",
    ),
    GILESO: (
        _gileso,
        [("x1", "current estimate x^1 (A)"), ("x2a", "x^2a (A/s)"), ("r", "GI state r"), ("rd", "GI state dr/dt")],
        "paper 002 eqs (29)-(30): LESO with a generalized integrator at w^e, quadrature PLL",
    ),
    FALESO: (
        _faleso,
        [("x1", "current estimate x^1 (A)"), ("z", "integral of eps (A s)")],
        "paper 002 eqs (25)-(28): frequency-adaptive complex-coefficient LESO, quadrature PLL",
    ),
}


def _leso(obs) -> CModel:
    g = _gains(obs)
    leso, pairs, reference = _LESO[type(obs)]
    names = [f"{p}_{ax}" for p, _ in pairs for ax in "ab"]
    doc = [f"{d}, {axis}" for _, d in pairs for axis in ("alpha", "beta")]
    n = obs.n_leso
    xl = [var(s) for s in names]
    th, w = var("th"), var("w")
    fu, fi = [var("u_a"), var("u_b")], [var("i_a"), var("i_b")]
    # _LESOBase.f: the LESO, then the PLL on its back EMF
    dxl, e = leso(g, xl, fu, fi, w)
    e = [let("e_a", e[0]), let("e_b", e[1])]
    mag = let("mag", sqrt(fmax(e[0] * e[0] + e[1] * e[1], obs.e_floor**2)))
    err = let("err", select(lt(w, 0.0), -1.0, 1.0) * (-e[0] * cos(th) - e[1] * sin(th)) / mag)
    dth, dw = pll_vf(th, w, err, g["kp_pll"], g["ki_pll"])
    # _LESOBase.step: outputs from the updated state (the LESO's ê does not use u, i)
    _, e_out = leso(g, xl, fu, fi, w)
    out = [e_out[0], e_out[1], th, w, safe_atan2(-e_out[0], e_out[1])]
    # the input path over the period: voltage held, current linear between its samples (Knots)
    u, i, u_prev, i_prev, _ = _drive_vars()
    period = [
        (arr, k, v)
        for arr, vals in (
            ("e0", [*u_prev, *i_prev]),
            ("em", [*u_prev, *(0.5 * (i[k] + i_prev[k]) for k in (0, 1))]),
            ("e1", [*u_prev, *i]),
        )
        for k, v in enumerate(vals)
    ]

    def jax_f(o, x, ev):
        return o.f(x, (ev[:2], ev[2:]))

    return CModel(
        component=type(obs).__name__,
        reference=reference,
        kind="drive",
        states=names + ["th", "w"],
        state_doc=doc + ["PLL angle (rad)", "PLL speed (rad/s)"],
        inputs=list(_DRIVE_INPUTS),
        input_doc=list(_DRIVE_INPUT_DOC),
        field=["u_a", "u_b", "i_a", "i_b"],
        outputs=list(_LESO_OUT),
        output_doc=list(_LESO_OUT_DOC),
        angles=(2, 4),
        gains=_named(g),
        statics=_statics(obs),
        f=[*dxl, dth, dw],
        out=out,
        x0=np.asarray(obs.initial_state(), np.float32),
        path="knots",
        period_input=period,
        post=[(n, wrap(th))],
        jax_f=jax_f,
        jax_out=None,
        omega_signal=float(obs.omega0_pll) if float(obs.omega0_pll) > 0 else 2 * math.pi * 50,
    )


MODELS: dict[type, Callable] = {
    SOGIFLL: _sogifll,
    SOGIFLLWPF: _wpf,
    SOGIFLLWIF: _wif,
    PureIntegratorFlux: _pure_integrator,
    LPFFlux: _lpf,
    SOIFO: _soifo,
    SecondOrderSOIFO: _sosoifo,
    CLESO: _leso,
    GILESO: _leso,
    FALESO: _leso,
}


def supported() -> list[str]:
    return [c.__name__ for c in MODELS]


def model_for(observer) -> CModel:
    """The C model of ``observer``; a ``ValueError`` naming the component if there is none."""
    build = MODELS.get(type(observer))
    if build is None:
        raise ValueError(
            f"export: component {type(observer).__name__} is not supported yet; supported: {', '.join(supported())}"
        )
    return build(observer)
