"""C emitters for the observers' cores, composed per observer class as the JAX observers compose them.

Each function here mirrors one function of :mod:`jaxobs.observers._cores` (or
of the observer modules) operator for operator, on :mod:`tuning._cexpr`
expressions instead of arrays, so the emitted C adds and multiplies in the
order the JAX step does.  A model (:class:`CModel`) is what :mod:`tuning.export`
needs to write one observer: its state, inputs, outputs, vector field
``f(x, u)``, outputs ``out(x)`` and its gains, named.

Supported: the FLL family of paper 001 (``SOGIFLL``, ``SOGIFLLWPF``,
``SOGIFLLWIF`` with either FLL error).  The drive observers (flux observers of
000, LESOs of 002) need their own step (back EMF from the sampled currents,
outputs after the update) and are not written yet.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import equinox as eqx
import numpy as np

from jaxobs.observers.fll import SOGIFLL, SOGIFLLWIF, SOGIFLLWPF

from ._cexpr import atan2, fmax, gt, let, named, select, sqrt, var

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


_TINY = 1e-30  # jaxobs._math._TINY


def safe_norm2(x, y):
    """√(x² + y²), 0 below 1e-30 (the value of jaxobs._math.safe_norm2; its inner where only guards gradients)."""
    sq = let("sq", x * x + y * y)
    return select(let("ok", gt(sq, _TINY)), sqrt(sq), 0.0)


def safe_atan2(y, x):
    """atan2(y, x), 0 at the origin (the value of jaxobs._math.safe_atan2)."""
    return select(let("ok", gt(x * x + y * y, _TINY)), atan2(y, x), 0.0)


def fll_output(y, q, w):
    """The FLL family's outputs (fll.py ``_fll_output``): v', qv', V̂, θ̂ = atan2(qv', v'), ω̂."""
    return [y, q, safe_norm2(y, q), safe_atan2(q, y), w]


# --------------------------------------------------------------------------------------------
# models
# --------------------------------------------------------------------------------------------


@dataclass
class CModel:
    """An observer ready to be written as C: everything but the discretization rule."""

    component: str  # class name
    reference: str  # paper and equations
    kind: str  # "signal": step returns the outputs of the state before the update (base.py)
    states: list  # C names of the state variables, in the order of the flat JAX state
    state_doc: list  # one line each
    inputs: list  # C names of the step inputs u[0..JX_NU-1]
    input_doc: list
    outputs: list  # names of the outputs y[0..JX_NY-1] (the JAX output NamedTuple's fields)
    output_doc: list
    angles: tuple  # indices of the outputs that are angles (compared modulo 2π)
    gains: dict  # leaf name -> (C macro, float32 value)
    statics: dict  # static fields (floors, options) -> value, for the record
    f: list  # ẋ as expressions in the state and input variables
    out: list  # outputs as expressions in the state variables
    x0: np.ndarray  # initial state (float32)


def _gains(obs) -> dict:
    """Every array leaf of the observer as a named float32 constant ``JX_<NAME>``."""
    gains = {}
    macros = set()
    for fld in dataclasses.fields(obs):
        v = getattr(obs, fld.name)
        if eqx.is_array(v):
            if np.ndim(v) != 0:
                raise ValueError(f"{type(obs).__name__}.{fld.name}: only scalar gains can be exported, "
                                 f"got shape {np.shape(v)}")
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


_FLL_OUT_DOC = [
    "v_alpha: filtered in-phase signal v' (input units)",
    "v_beta: filtered quadrature signal qv' (input units)",
    "amplitude: V^ = sqrt(v'^2 + qv'^2) (input units)",
    "theta: phase atan2(qv', v') (rad, in (-pi, pi])",
    "omega: frequency w^ (rad/s)",
]


def _fll_model(obs, name, reference, states, state_doc, f, out, g) -> CModel:
    return CModel(
        component=name, reference=reference, kind="signal",
        states=states, state_doc=state_doc,
        inputs=["v"], input_doc=["v: the sampled single-phase signal (input units)"],
        outputs=["v_alpha", "v_beta", "amplitude", "theta", "omega"], output_doc=_FLL_OUT_DOC, angles=(3,),
        gains={k: (e.value[0], e.value[1]) for k, e in g.items()}, statics=_statics(obs), f=f, out=out,
        x0=np.asarray(obs.initial_state(), np.float32),
    )


def _sogifll(obs: SOGIFLL) -> CModel:
    g = _gains(obs)
    y, q, w, v = var("vp"), var("qvp"), var("w"), var("v")
    dy, dq = sogi_vf(y, q, v, w, g["k"])
    dw = fll_rate(v - y, q, y, g["lam"], obs.v_floor)
    return _fll_model(obs, "SOGIFLL", "paper 001 Fig. 1(a), eqs (6)-(8)", ["vp", "qvp", "w"],
                      ["v', in-phase output", "qv', quadrature output", "w^, frequency (rad/s)"],
                      [dy, dq, dw], fll_output(y, q, w), g)


def _wpf(obs: SOGIFLLWPF) -> CModel:
    g = _gains(obs)
    p, qp, y, q, w, v = var("p"), var("qp"), var("vp"), var("qvp"), var("w"), var("v")
    dp, dqp = sogi_vf(p, qp, v, w, g["k1"])
    dy, dq = sogi_vf(y, q, p, w, g["k2"])
    dw = fll_rate(p - y, q, y, g["lam"], obs.v_floor)
    return _fll_model(obs, "SOGIFLLWPF", "paper 001 Fig. 1(b) (SOGI prefilter + SOGI-FLL)",
                      ["p", "qp", "vp", "qvp", "w"],
                      ["prefilter in-phase output", "prefilter quadrature", "v', in-phase output",
                       "qv', quadrature output", "w^, frequency (rad/s)"],
                      [dp, dqp, dy, dq, dw], fll_output(y, q, w), g)


def _wif(obs: SOGIFLLWIF) -> CModel:
    g = _gains(obs)
    za, zb, y, q, w, v = var("za"), var("zb"), var("vp"), var("qvp"), var("w"), var("v")
    # Golestan's (k1, k2) = Xu's (K2, K1)
    dza, dzb, dy, dq = sogi2_vf(za, zb, y, q, v, w, K1=g["k2"], K2=g["k1"])
    if obs.fll_error == "input":
        dw = fll_rate(za, q, y, g["lam"] / g["k2"], obs.v_floor)
    else:
        dw = fll_rate(v - y, q, y, g["lam"], obs.v_floor)
    return _fll_model(obs, "SOGIFLLWIF", "paper 001 Fig. 1(c) (second-order SOGI of 000 eqs 17-18 + FLL)",
                      ["za", "zb", "vp", "qvp", "w"],
                      ["first GI, in-phase (input of the output GI)", "first GI, quadrature",
                       "v', in-phase output", "qv', quadrature output", "w^, frequency (rad/s)"],
                      [dza, dzb, dy, dq, dw], fll_output(y, q, w), g)


MODELS: dict[type, Callable] = {SOGIFLL: _sogifll, SOGIFLLWPF: _wpf, SOGIFLLWIF: _wif}


def supported() -> list[str]:
    return [c.__name__ for c in MODELS]


def model_for(observer) -> CModel:
    """The C model of ``observer``; a ``ValueError`` naming the component if there is none."""
    build = MODELS.get(type(observer))
    if build is None:
        raise ValueError(f"export: component {type(observer).__name__} is not supported yet; "
                         f"supported: {', '.join(supported())}")
    return build(observer)

