"""The SOGI-FLL family of paper 001 (Golestan et al., IEEE TPEL 2018).

All three take a single-phase signal v(t) = V cos θ and estimate the in-phase
and quadrature components, amplitude V̂, phase θ̂ = atan2(qv', v') (001 eq 10)
and frequency ω̂ (rad/s).  Gains are named as in paper 001 (k, k1, k2, λ=lam),
so tuning jobs can name them; each is declared with its units and symbol (:func:`jaxobs.observers.gain`).
Each class's ``closed_form_design`` is its paper's tuning rule (001 eqs 22, 29, 34) with its rows;
``closed_form`` is its observer.

State layout (flat arrays, integrators in the order of 001 Table II):

- SOGIFLL:    [v', qv', ω̂]                      (3 integrators)
- SOGIFLLWPF: [p, qp, v', qv', ω̂]               (5 integrators; p = prefilter)
- SOGIFLLWIF: [z_a, z_b, v', qv', ω̂]            (5 integrators; z = first GI)
"""

from __future__ import annotations

from typing import Any, ClassVar, Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from .. import papers
from ..core.discretize import AB3, AbstractRule, check_rule
from ..core.numerics import safe_atan2, safe_norm2
from ..core.validate import as_float, check_positive, check_real, check_sample_time
from ..core.validate import static_float as _static_float
from ._cores import fll_rate, sogi2_vf, sogi_vf
from ._gains import ClosedForm, DesignRow, gain_metadata, gain_row
from ._rules import sogi_fll_lambda, symmetric_optimum_pm, wif_symmetric_optimum, wpf_lambda
from .base import AbstractVectorFieldObserver

__all__ = ["FLLOutput", "SOGIFLL", "SOGIFLLWPF", "SOGIFLLWIF"]


class FLLOutput(NamedTuple):
    """An FLL's outputs at a sample.

    Attributes:
        v_alpha: The filtered in-phase signal v' (input units).
        v_beta: The filtered quadrature signal qv' (input units).
        amplitude: V̂ = sqrt(v'² + qv'²).
        theta: θ̂ = atan2(qv', v'), rad, in (−π, π].
        omega: ω̂, rad/s.
    """

    v_alpha: jax.Array  # filtered in-phase signal v' (input units)
    v_beta: jax.Array  # filtered quadrature signal qv' (input units)
    amplitude: jax.Array  # V̂ = sqrt(v'² + qv'²)
    theta: jax.Array  # θ̂ = atan2(qv', v'), rad, in (−π, π]
    omega: jax.Array  # ω̂, rad/s


def _lam() -> dict[str, Any]:
    return gain_metadata(units="rad2 s-2", role="fll", long_name="FLL gain", symbol="001: λ")


def _sogi_gain(role: str, long_name: str, symbol: str) -> dict[str, Any]:
    return gain_metadata(units="1", role=role, long_name=long_name, symbol=symbol)


def _fll_output(y: jax.Array, q: jax.Array, w: jax.Array) -> FLLOutput:
    return FLLOutput(v_alpha=y, v_beta=q, amplitude=safe_norm2(y, q), theta=safe_atan2(q, y), omega=w)


class SOGIFLL(AbstractVectorFieldObserver):
    """Standard SOGI-FLL, 001 Fig. 1(a), eqs (6)–(8).

        v̇'  = ω̂ [k (v − v') − qv']                       (6)
        q̇v' = ω̂ v'                                        (7)
        ω̂̇   = −(λ / V̂²) (v − v') qv'                        (8)

    Small-signal model (001 eqs 18–20): ω̂/ω = (λ/2)/(s² + (kωn/2) s + λ/2);
    damping rule λ = k² ωn² / 4 for ζ = 1/√2 (eq 22).

    Args:
        k: SOGI gain (> 0).
        lam: FLL gain λ (> 0, rad²/s²).
        omega_n: Nominal frequency and initial ω̂ (rad/s, > 0).
        ts: Sample time (s).
        rule: Discretization rule (default :class:`~jaxobs.AB3`, as 001 uses).
        v_floor: Floor of V̂ in the FLL normalization (input units, > 0).

    Raises:
        ValueError: A value out of its range.
    """

    k: jax.Array = eqx.field(metadata=_sogi_gain("sogi", "SOGI gain", "001: k"))
    lam: jax.Array = eqx.field(metadata=_lam())
    omega_n: jax.Array
    ts: float = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)
    v_floor: float = eqx.field(static=True)

    small_signal_model: ClassVar = ("sogi_fll_model", ("k", "lam", "omega_n"))  # 001 eqs (18)–(20)

    def __init__(
        self,
        k: ArrayLike,
        lam: ArrayLike,
        omega_n: ArrayLike = papers.FLL_OMEGA_N,
        *,
        ts: float = 1e-4,
        rule: AbstractRule | None = None,
        v_floor: float = 1e-3,
    ) -> None:
        self.k, self.lam = as_float(k), as_float(lam)  # bounds: check_gains (AbstractObserver)
        self.omega_n = check_positive("omega_n", omega_n, "SOGIFLL")
        self.ts = check_sample_time("ts", ts, "SOGIFLL")
        self.rule = check_rule(AB3() if rule is None else rule, "SOGIFLL")
        self.v_floor = _static_float(check_positive("v_floor", v_floor, "SOGIFLL"), v_floor)

    @classmethod
    def closed_form_design(
        cls,
        k: ArrayLike = papers.SOGI_FLL_K,
        omega_n: ArrayLike = papers.FLL_OMEGA_N,
        zeta: float = papers.FLL_ZETA,
        **kw: Any,
    ) -> ClosedForm:
        """The SOGI-FLL tuned by 001 eq (22): λ = k² ωn² / (8 ζ²) (Table I: k = 1/√2, λ = 12337).

        Args:
            k: SOGI gain (> 0; 001 chooses 1/√2).
            omega_n: nominal frequency, rad/s (> 0).
            zeta: damping ratio of the FLL's small-signal model (> 0).
            **kw: the constructor's keywords (``ts``, ``rule``, ``v_floor``).

        Returns:
            The :class:`~jaxobs.observers.ClosedForm`: the :class:`SOGIFLL` and the rows k, lam.

        Raises:
            ValueError: a value out of its range.
        """
        check_positive("k", k, "SOGIFLL.closed_form")
        check_positive("zeta", zeta, "SOGIFLL.closed_form")
        obs = cls(k=k, lam=sogi_fll_lambda(as_float(k), as_float(omega_n), zeta), omega_n=omega_n, **kw)
        rows = (
            gain_row(cls, "k", obs.k, "k chosen (001: k = 1/√2)", "001 Sec. II-B"),
            gain_row(cls, "lam", obs.lam, "λ = k²ωn²/(8ζ²)", "001 eq (22)"),
        )
        return ClosedForm(obs, dict(k=k, omega_n=omega_n, zeta=zeta), rows, "001 eq (22), Table I")

    @classmethod
    def closed_form(cls, **kw: Any) -> SOGIFLL:
        """The observer of :meth:`closed_form_design` (same arguments).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`SOGIFLL`.
        """
        return cls.closed_form_design(**kw).observer

    def f(self, x: jax.Array, u: ArrayLike) -> jax.Array:
        """The vector field (class doc).

        Args:
            x: [v', qv', ω̂].
            u: The input sample v.

        Returns:
            dx/dt.
        """
        y, q, w = x[0], x[1], x[2]
        dy, dq = sogi_vf(y, q, u, w, self.k)
        dw = fll_rate(u - y, q, y, self.lam, self.v_floor)
        return jnp.stack([dy, dq, dw])

    def output(self, x: jax.Array) -> FLLOutput:
        """The outputs of a state: v', qv', V̂, θ̂ and ω̂ (the SOGI's).

        Args:
            x: The flat state.

        Returns:
            The :class:`FLLOutput`.
        """
        return _fll_output(x[0], x[1], x[2])

    def initial_state(self) -> jax.Array:
        """Every integrator at 0, ω̂ at ``omega_n``.

        Returns:
            The flat state.
        """
        z = jnp.zeros_like(self.omega_n)
        return jnp.stack([z, z, self.omega_n])


class SOGIFLLWPF(AbstractVectorFieldObserver):
    """SOGI-FLL with a SOGI prefilter, 001 Fig. 1(b).

    A SOGI (gain k1; only its in-phase output p is used) tuned at the FLL's ω̂
    prefilters v, and a SOGI-FLL (k2, λ) runs on p:

        ṗ   = ω̂ [k1 (v − p) − qp],      q̇p = ω̂ p
        v̇'  = ω̂ [k2 (p − v') − qv'],    q̇v' = ω̂ v'
        ω̂̇   = −(λ / V̂²) (p − v') qv'

    On envelopes the prefilter is the lag (k1ωn/2)/(s + k1ωn/2) on the phase seen
    by the SOGI-FLL while the FLL integrator sits after it, which gives the
    characteristic polynomial s³ + (k1+k2)ωn/2 s² + k1k2ωn²/4 s + k1λωn/4 of
    001 eqs (24)–(25).  Tuning (eq 29): k1 = k2 = √2, λ = 2(ζ+1)ωn²/(2ζ+1)³.

    Args:
        k1: Prefilter SOGI gain (> 0).
        k2: SOGI gain of the SOGI-FLL (> 0).
        lam: FLL gain λ (> 0, rad²/s²).
        omega_n: Nominal frequency and initial ω̂ (rad/s, > 0).
        ts: Sample time (s).
        rule: Discretization rule (default :class:`~jaxobs.AB3`, as 001 uses).
        v_floor: Floor of V̂ in the FLL normalization (input units, > 0).

    Raises:
        ValueError: A value out of its range.
    """

    k1: jax.Array = eqx.field(metadata=_sogi_gain("prefilter", "prefilter SOGI gain", "001: k1"))
    k2: jax.Array = eqx.field(metadata=_sogi_gain("sogi", "SOGI gain of the SOGI-FLL", "001: k2"))
    lam: jax.Array = eqx.field(metadata=_lam())
    omega_n: jax.Array
    ts: float = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)
    v_floor: float = eqx.field(static=True)

    small_signal_model: ClassVar = ("wpf_model", ("k1", "k2", "lam", "omega_n"))  # 001 eqs (24)–(25)

    def __init__(
        self,
        k1: ArrayLike,
        k2: ArrayLike,
        lam: ArrayLike,
        omega_n: ArrayLike = papers.FLL_OMEGA_N,
        *,
        ts: float = 1e-4,
        rule: AbstractRule | None = None,
        v_floor: float = 1e-3,
    ) -> None:
        self.k1, self.k2, self.lam = as_float(k1), as_float(k2), as_float(lam)  # bounds: check_gains
        self.omega_n = check_positive("omega_n", omega_n, "SOGIFLLWPF")
        self.ts = check_sample_time("ts", ts, "SOGIFLLWPF")
        self.rule = check_rule(AB3() if rule is None else rule, "SOGIFLLWPF")
        self.v_floor = _static_float(check_positive("v_floor", v_floor, "SOGIFLLWPF"), v_floor)

    @classmethod
    def closed_form_design(
        cls, omega_n: ArrayLike = papers.FLL_OMEGA_N, zeta: float = papers.FLL_ZETA, **kw: Any
    ) -> ClosedForm:
        """The SOGI-FLL-WPF tuned by 001 eq (29): k1 = k2 = √2 (eq 26), λ = 2 (ζ + 1) ωn² / (2ζ + 1)³
        (Table I: λ = 23948).

        Args:
            omega_n: nominal frequency, rad/s (> 0).
            zeta: damping ratio of the FLL's small-signal model (> 0).
            **kw: the constructor's keywords (``ts``, ``rule``, ``v_floor``).

        Returns:
            The :class:`~jaxobs.observers.ClosedForm`: the :class:`SOGIFLLWPF` and the rows k1, k2, lam.

        Raises:
            ValueError: a value out of its range.
        """
        check_positive("zeta", zeta, "SOGIFLLWPF.closed_form")
        lam = wpf_lambda(as_float(omega_n), zeta)
        obs = cls(k1=papers.WPF_K1, k2=papers.WPF_K2, lam=lam, omega_n=omega_n, **kw)
        rows = (
            gain_row(cls, "k1", obs.k1, "k1 = √2 (prefilter ζ = 1/√2)", "001 eq (26)"),
            gain_row(cls, "k2", obs.k2, "k2 = k1 (amplitude poles coincide)", "001 Sec. III-B"),
            gain_row(cls, "lam", obs.lam, "λ = 2(ζ+1)ωn²/(2ζ+1)³", "001 eq (29)"),
        )
        return ClosedForm(obs, dict(omega_n=omega_n, zeta=zeta), rows, "001 eq (29), Table I")

    @classmethod
    def closed_form(cls, **kw: Any) -> SOGIFLLWPF:
        """The observer of :meth:`closed_form_design` (same arguments).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`SOGIFLLWPF`.
        """
        return cls.closed_form_design(**kw).observer

    def f(self, x: jax.Array, u: ArrayLike) -> jax.Array:
        """The vector field (class doc).

        Args:
            x: [p, qp, v', qv', ω̂].
            u: The input sample v.

        Returns:
            dx/dt.
        """
        p, qp, y, q, w = x[0], x[1], x[2], x[3], x[4]
        dp, dqp = sogi_vf(p, qp, u, w, self.k1)
        dy, dq = sogi_vf(y, q, p, w, self.k2)
        dw = fll_rate(p - y, q, y, self.lam, self.v_floor)
        return jnp.stack([dp, dqp, dy, dq, dw])

    def output(self, x: jax.Array) -> FLLOutput:
        """The outputs of a state: v', qv', V̂, θ̂ and ω̂ (the SOGI-FLL's, after the prefilter).

        Args:
            x: The flat state.

        Returns:
            The :class:`FLLOutput`.
        """
        return _fll_output(x[2], x[3], x[4])

    def initial_state(self) -> jax.Array:
        """Every integrator at 0, ω̂ at ``omega_n``.

        Returns:
            The flat state.
        """
        z = jnp.zeros_like(self.omega_n)
        return jnp.stack([z, z, z, z, self.omega_n])


class SOGIFLLWIF(AbstractVectorFieldObserver):
    """SOGI-FLL with an in-loop SOGI filter, 001 Fig. 1(c): the second-order SOGI + FLL.

    The filter is the second-order SOGI of paper 000 (eqs 17–18), see
    :mod:`jaxobs.observers._cores`.  Mapping its envelope dynamics onto 001
    eq (30) gives Golestan's k1 = Xu's K2 (the damping term) and k2 = K1:

        ża = ω̂ [k1 (k2 (v − v') − za) − zb],   żb = ω̂ za
        v̇' = ω̂ (za − qv'),                       q̇v' = ω̂ v'

    The frequency detector — derived so that the small-signal model is exactly
    001 eqs (31)–(32).  In the frame ψ = ∫ω̂ let u = θ − ψ be the input phase and
    φ = θ̂ − ψ the output phase.  The filter acts linearly on envelopes:
    φ = H u, H = a/(s² + b s + a), a = k1k2ωn²/4, b = k1ωn/2.  Since θ̂ = ψ + φ,
    asking θ̂/θ = T = (a s + d)/(s³ + b s² + a s + d), d = k1λωn/4 (eq 31), fixes
    ψ = (T − H)/(1 − H) θ = d/(s D + d) θ with D = s² + b s + a, i.e.

        ω̂ = s ψ = (d/a) · H u = (d/a) φ   ⇒   ω̂̇ = (d/a) φ̇.

    The output GI integrates za on envelopes with gain ω̂/2, so its phase moves
    as φ̇ = (ω̂/2)·Im(Za V'*)/|V'|², and averaging the product za·qv' gives
    Im(Za V'*) = −2⟨za qv'⟩.  With d/a = λ/(k2 ωn) and ω̂ ≈ ωn:

        ω̂̇ = −(λ / k2) · za · qv' / V̂²                    (fll_error="input")

    — the same form as the SOGI-FLL's eq (8), whose error k(v − v') is likewise
    the input of the output GI (there λ/k · k(v − v') = λ (v − v')).  In steady
    state za/v' = 1/G_GI(jω) = j(ω² − ω̂²)/(ω ω̂), so ⟨za qv'⟩ is a direct
    frequency-error detector: ω̂̇ = (λ/k2)(ω² − ω̂²)/(2ωω̂) ≈ (λ/(k2ωn))(ω − ω̂),
    positive when ω > ω̂.

    The tempting alternative, the SOGI-FLL's error (v − v')·qv' on the WIF's
    outputs (``fll_error="residual"``), drives ω̂̇ = c (1 − H) u with c = λ/2 and
    gives ω̂/ω = c (s + b)/(s³ + b s² + (a + c) s + c b): the same constant term
    but an s-coefficient λ/2 too large (17 % with Table I's gains) and an extra
    zero, so it does not have 001's small-signal model.  It is kept for comparison
    (tests/test_fll.py checks both models against simulation).

    Tuning (eq 34, symmetric optimum): k1 = 2bωc/ωn, k2 = 2ωc/ωn, λ = 2ωc²/b.

    Args:
        k1: In-loop filter damping gain (001's k1, 000's K2; > 0).
        k2: In-loop filter gain (001's k2, 000's K1; > 0).
        lam: FLL gain λ (> 0, rad²/s²).
        omega_n: Nominal frequency and initial ω̂ (rad/s, > 0).
        ts: Sample time (s).
        rule: Discretization rule (default :class:`~jaxobs.AB3`, as 001 uses).
        v_floor: Floor of V̂ in the FLL normalization (input units, > 0).
        fll_error: The frequency detector: ``"input"`` (the derived one, 001's small-signal model) or
            ``"residual"`` (the SOGI-FLL's error on the outputs, for comparison).

    Raises:
        ValueError: A value out of its range.
    """

    # 001 eq (30): k1 sets the envelope's damping term, k2 the loop gain (000's K2 and K1)
    k1: jax.Array = eqx.field(metadata=_sogi_gain("sogi", "in-loop filter damping gain", "001: k1"))
    k2: jax.Array = eqx.field(metadata=_sogi_gain("sogi", "in-loop filter gain", "001: k2"))
    lam: jax.Array = eqx.field(metadata=_lam())
    omega_n: jax.Array
    ts: float = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)
    v_floor: float = eqx.field(static=True)
    fll_error: Literal["input", "residual"] = eqx.field(static=True)

    small_signal_model: ClassVar = ("wif_model", ("k1", "k2", "lam", "omega_n"))  # 001 eqs (31)–(32)

    def __init__(
        self,
        k1: ArrayLike,
        k2: ArrayLike,
        lam: ArrayLike,
        omega_n: ArrayLike = papers.FLL_OMEGA_N,
        *,
        ts: float = 1e-4,
        rule: AbstractRule | None = None,
        v_floor: float = 1e-3,
        fll_error: Literal["input", "residual"] = "input",
    ) -> None:
        self.k1, self.k2, self.lam = as_float(k1), as_float(k2), as_float(lam)  # bounds: check_gains
        self.omega_n = check_positive("omega_n", omega_n, "SOGIFLLWIF")
        self.ts = check_sample_time("ts", ts, "SOGIFLLWIF")
        self.rule = check_rule(AB3() if rule is None else rule, "SOGIFLLWIF")
        self.v_floor = _static_float(check_positive("v_floor", v_floor, "SOGIFLLWIF"), v_floor)
        if fll_error not in ("input", "residual"):
            raise ValueError(f"SOGIFLLWIF.fll_error must be 'input' or 'residual', got {fll_error!r}")
        self.fll_error = fll_error

    @classmethod
    def closed_form_design(
        cls,
        omega_c: ArrayLike = papers.WIF_OMEGA_C,
        b: ArrayLike = papers.WIF_B,
        omega_n: ArrayLike = papers.FLL_OMEGA_N,
        **kw: Any,
    ) -> ClosedForm:
        """The SOGI-FLL-WIF tuned by the symmetric optimum, 001 eq (34): k1 = 2bωc/ωn, k2 = 2ωc/ωn,
        λ = 2ωc²/b; its phase margin is atan((b² − 1)/(2b)) (eq 39).

        Args:
            omega_c: crossover of the FLL loop, rad/s (> 0; 001: 2π·18.8).
            b: the symmetric optimum's factor (> 1; 001: 1 + √2, ζ = 1/√2, PM = 45°).
            omega_n: nominal frequency, rad/s (> 0).
            **kw: the constructor's keywords (``ts``, ``rule``, ``v_floor``, ``fll_error``).

        Returns:
            The :class:`~jaxobs.observers.ClosedForm`: the :class:`SOGIFLLWIF` (Table I: k1 = 1.815,
            k2 = 0.752, λ = 11559) and the rows k1, k2, lam and the phase margin.

        Raises:
            ValueError: a value out of its range.
        """
        check_real("b", b, lower=1.0, owner="SOGIFLLWIF.closed_form")
        check_positive("omega_c", omega_c, "SOGIFLLWIF.closed_form")
        k1, k2, lam = wif_symmetric_optimum(as_float(b), as_float(omega_c), as_float(omega_n))
        obs = cls(k1=k1, k2=k2, lam=lam, omega_n=omega_n, **kw)
        rows = (
            gain_row(cls, "k1", obs.k1, "k1 = 2bωc/ωn", "001 eq (34)"),
            gain_row(cls, "k2", obs.k2, "k2 = 2ωc/ωn", "001 eq (34)"),
            gain_row(cls, "lam", obs.lam, "λ = 2ωc²/b", "001 eq (34)"),
            DesignRow(
                "phase_margin_deg",
                jnp.degrees(symmetric_optimum_pm(as_float(b))),
                "degree",
                "PM = atan((b²−1)/(2b))",
                "001 eq (39)",
            ),
        )
        return ClosedForm(obs, dict(omega_c=omega_c, b=b, omega_n=omega_n), rows, "001 eq (34), Table I")

    @classmethod
    def closed_form(cls, **kw: Any) -> SOGIFLLWIF:
        """The observer of :meth:`closed_form_design` (same arguments).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`SOGIFLLWIF`.
        """
        return cls.closed_form_design(**kw).observer

    def f(self, x: jax.Array, u: ArrayLike) -> jax.Array:
        """The vector field (class doc).

        Args:
            x: [z_a, z_b, v', qv', ω̂].
            u: The input sample v.

        Returns:
            dx/dt.
        """
        za, zb, y, q, w = x[0], x[1], x[2], x[3], x[4]
        dza, dzb, dy, dq = sogi2_vf(za, zb, y, q, u, w, k_err=self.k2, k_damp=self.k1)
        if self.fll_error == "input":
            dw = fll_rate(za, q, y, self.lam / self.k2, self.v_floor)
        else:
            dw = fll_rate(u - y, q, y, self.lam, self.v_floor)
        return jnp.stack([dza, dzb, dy, dq, dw])

    def output(self, x: jax.Array) -> FLLOutput:
        """The outputs of a state: v', qv', V̂, θ̂ and ω̂ (the second GI's).

        Args:
            x: The flat state.

        Returns:
            The :class:`FLLOutput`.
        """
        return _fll_output(x[2], x[3], x[4])

    def initial_state(self) -> jax.Array:
        """Every integrator at 0, ω̂ at ``omega_n``.

        Returns:
            The flat state.
        """
        z = jnp.zeros_like(self.omega_n)
        return jnp.stack([z, z, z, z, self.omega_n])
