"""The SOGI flux observers of paper 000 (Xu et al., TPEL 2018): SOIFO and second-order SOIFO, whose speed is an
FLL's.  The back EMF they filter, their contract and the PLL types are :mod:`jaxobs.observers.flux`'s.

Two axes, one FLL.  The α and β back EMFs each go through their own (real-coefficient) SOGI or second-order
SOGI, and one FLL adapts both centre frequencies, its error summed over the axes and normalized by
V̂α² + V̂β² (floored at |ê|², see ``_fll_norm``).  We chose this over a complex (αβ) SOGI because it keeps paper
000's per-axis transfer functions (Table III, eqs 15–21, 29, 36), which are what the paper analyses and what we
test; and because for a balanced input the summed FLL error has no double-frequency term, so ω̂ is ripple-free in
steady state.  The linearized FLL is the same as the single-phase one (λ/2 per rad of phase error).  A SOGI
cannot tell the direction of rotation: ω̂ from the FLL is |ωe| and its sign is taken from the rotation of the
estimated flux, sign(ψ̂α ê′β − ψ̂β ê′α) with ê′ the filtered back EMF (≈ dψ/dt).

Flux outputs: SOIFO ψ̂ = qv′/ω̂ (eq 15), second-order SOIFO ψ̂ = qv′/ω̂ (eq 20), with qv′ the quadrature output
of the (second-order) SOGI on ê.

Frequency-normalized FLL gain.  000 draws an FLL with a gain Γ (Figs. 3–4) but gives no equation for it.  A
drive sweeps ωe over 100:1 (20 → 2000 r/min); with a fixed λ the FLL's characteristic polynomial
s² + (kω̂/2)s + λ/2 (001 eq 21) loses its damping at low speed, and the FLL can run away after a start-up
transient.  So the flux observers' ``lam`` is *dimensionless*: the FLL gain is λ(ω̂) = lam·ω̂², the frequency
normalization of Rodriguez et al., which keeps every root of the FLL's small-signal polynomial proportional to ω̂
and the damping independent of speed.  001's damping rule λ = k²ωn²/4 becomes lam = k²/4 (ζ = 1/√2 at every
speed); the WIF's symmetric optimum λ = 2ωc²/b becomes lam = 2(ωc/ω̂)²/b.

Names.  ``lam`` keeps the name of the FLL gain it normalizes (001's λ, which 000's Γ draws): it is the same
gain of the same loop, divided by ω̂², so it keeps the name and carries its own unit ("1", against the
FLLs' rad²/s²) in its field's metadata (:func:`jaxobs.observers.gain_fields`); a gain is (class, name).
"""

from __future__ import annotations

from typing import Any, ClassVar, Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from .. import papers
from ..core.discretize import AbstractRule
from ..core.measurements import DriveInput
from ..core.numerics import safe_atan2
from ..core.validate import as_float, check_positive
from ._cores import safe_sq_amplitude, sogi2_tustin_coefficients, sogi2_vf, sogi_vf
from ._gains import ClosedForm, gain_metadata, gain_row
from ._rules import second_order_soifo_lambda, soifo_lambda
from .base import DriveObserverState
from .flux import AbstractFluxObserver, FluxOutput

__all__ = ["SOIFO", "SecondOrderSOIFO"]


def _lam_normalized() -> dict[str, Any]:
    # lam·ω̂² is 001's λ (module doc, "Names"): dimensionless, where the FLLs' λ is in rad²/s²
    return gain_metadata(units="1", role="fll", long_name="frequency-normalized FLL gain, λ/ω̂²", symbol="000: Γ, λ/ω̂²")


def _fll_norm(ya: jax.Array, qa: jax.Array, yb: jax.Array, qb: jax.Array, e: jax.Array, v_floor: float) -> jax.Array:
    """FLL normalization max(V̂α² + V̂β², |ê|², v_floor²).

    In steady state V̂α² + V̂β² = 2|ê|² for a balanced input, so the floor |ê|² is
    inactive and the small-signal model is unchanged.  At start-up the SOGI
    outputs are still near zero while ê already has its full amplitude; without
    the floor the normalized error (ê − y)q/V̂² ~ |ê|/|q| grows without bound
    and the FLL runs away (a current-sensor offset makes the states overflow).
    |ê|² is the instantaneous amplitude of the two-axis input, available without filtering.
    """
    v2 = safe_sq_amplitude(ya, qa, 0.0) + safe_sq_amplitude(yb, qb, 0.0)
    return jnp.maximum(jnp.maximum(v2, e[0] * e[0] + e[1] * e[1]), v_floor * v_floor)


class _Design000(NamedTuple):
    """A SOGI type's closed form as its rows print it: 000's chosen filter gains and the FLL gain's rule."""

    chosen: tuple[tuple[str, str], ...]  # (gain, its value as 000 Sec. III-B prints it)
    lam_rule: str  # lam in the filter gains ("lam = k²/4")
    lam_from: str  # the rule of 001 it normalizes ("λ = k²ωn²/4 at ζ = 1/√2, ωn → 1")
    lam_source: str  # the paper's equation ("001 eq (22), normalized")


class _FLLFluxBase(AbstractFluxObserver):
    """Flux filters whose speed is an FLL's: a SOGI's centre frequency, > 0 (``omega_min`` its floor)."""

    omega_min: eqx.AbstractVar[float]

    _design: ClassVar[_Design000]  # what closed_form_design's rows print

    def start_speed(self, omega_e: ArrayLike) -> jax.Array:
        """max(|ω_e|, omega_min): a SOGI cannot tell the direction (the sign comes from the flux's rotation,
        module doc) and its centre frequency must stay positive.  The floor is the observer's own
        ``omega_min`` (1 rad/s by default), the one its outputs divide by, not a separate constant.

        Args:
            omega_e: ω_e, rad/s.

        Returns:
            The FLL's start frequency, rad/s.
        """
        return jnp.maximum(jnp.abs(omega_e), self.omega_min)

    def _closed_form_000(
        self, gains: dict[str, ArrayLike], Rs: ArrayLike, L: ArrayLike, omega_init: ArrayLike
    ) -> ClosedForm:
        """This observer, built from 000's chosen filter ``gains`` (name -> the value given) and its FLL rule, as its
        closed form: a row for each filter gain (000 Sec. III-B), then lam's (the class's ``_design``)."""
        d = self._design
        formulas = {n: (f"chosen: {n} = {v} (settling time 0.018 s)", "000 Sec. III-B") for n, v in d.chosen}
        formulas["lam"] = (f"{d.lam_rule} ({d.lam_from})", d.lam_source)
        rows = tuple(gain_row(type(self), n, getattr(self, n), *rule) for n, rule in formulas.items())
        inputs = {**gains, "Rs": Rs, "L": L, "omega_init": omega_init}
        paper = ", ".join(f"{n} = {v}" for n, v in d.chosen)
        return ClosedForm(self, inputs, rows, f"000 ({paper}), {d.lam_rule}")

    def _flux_output(
        self, w: jax.Array, y_a: jax.Array, q_a: jax.Array, y_b: jax.Array, q_b: jax.Array, e: jax.Array
    ) -> FluxOutput:
        """ψ̂ = qv′/ω̂ on each axis (ω̂ floored at ``omega_min``), θ̂ = atan2(ψ̂β, ψ̂α) and ω̂ signed by the flux's
        rotation (module doc)."""
        w_floor = jnp.maximum(w, self.omega_min)
        pa, pb = q_a / w_floor, q_b / w_floor
        cross = pa * y_b - pb * y_a
        omega = jnp.where(cross < 0, -w, w)
        return FluxOutput(psi_a=pa, psi_b=pb, theta=safe_atan2(pb, pa), omega=omega, e_a=e[0], e_b=e[1])


class SOIFO(_FLLFluxBase):
    """SOGI flux observer with FLL (000 Sec. III-A, eq 15, Fig. 3): ψ̂ = kω'/(s² + kω's + ω'²)·ê.

    State [yα, qα, yβ, qβ, ω̂].  FLL: ω̂̇ = −lam·ω̂² Σₓ (êₓ − yₓ) qₓ / Σₓ (yₓ² + qₓ²) (two SOGIs, one FLL;
    ``lam`` dimensionless, k²/4 for ζ = 1/√2).

    Args:
        Rs: Assumed stator resistance, ohm (≥ 0; :meth:`bind` sets it per scenario).
        L: Assumed inductance, H (> 0; :meth:`bind` sets it to the machine's Lq: the active flux).
        k: SOGI gain (> 0).
        lam: Frequency-normalized FLL gain λ/ω̂² (dimensionless, > 0).
        omega_init: The FLL's initial frequency, rad/s (> 0; :meth:`bind` sets it).
        ts: Sample time, s.
        rule: Discretization rule (default :class:`~jaxobs.RK4`).
        v_floor: Floor of the FLL normalization (V, > 0).
        omega_min: Floor of |ω̂| in the outputs, which divide by it, rad/s.
        omega0: Another name of ``omega_init`` (the job files' key); give one of the two.

    Raises:
        ValueError: A value out of its range, or both ``omega_init`` and ``omega0`` given.
    """

    Rs: jax.Array
    L: jax.Array
    k: jax.Array = eqx.field(metadata=gain_metadata(units="1", role="sogi", long_name="SOGI gain", symbol="000: k"))
    lam: jax.Array = eqx.field(metadata=_lam_normalized())
    omega_init: jax.Array  # initial FLL frequency, rad/s (> 0)
    ts: float = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)
    v_floor: float = eqx.field(static=True)
    omega_min: float = eqx.field(static=True)

    small_signal_model: ClassVar = ("soifo_tf", ("k", "omega_init"))  # 000 eq (15), ψ̂/e at ω' = omega_init
    _design: ClassVar[_Design000] = _Design000(
        chosen=(("k", "1.414"),),
        lam_rule="lam = k²/4",
        lam_from="λ = k²ωn²/4 at ζ = 1/√2, ωn → 1",
        lam_source="001 eq (22), normalized",
    )
    _speed_index: ClassVar[int] = 4  # the FLL's ω̂ (a SOGI's centre frequency: > 0)

    def __init__(
        self,
        Rs: ArrayLike,
        L: ArrayLike,
        k: ArrayLike,
        lam: ArrayLike,
        omega_init: ArrayLike | None = None,
        *,
        ts: float = 1e-4,
        rule: AbstractRule | None = None,
        v_floor: float = 1e-2,
        omega_min: float = 1.0,
        omega0: ArrayLike | None = None,
    ) -> None:
        omega_init = self._initial_speed(omega_init, omega0, "SOIFO")
        self._check_common(Rs, L, ts, rule, "SOIFO")
        self.k, self.lam = as_float(k), as_float(lam)  # bounds: check_gains (AbstractObserver)
        self.omega_init = check_positive("omega_init", omega_init, "SOIFO")
        self.v_floor = float(v_floor)
        self.omega_min = float(omega_min)

    @classmethod
    def closed_form_design(
        cls,
        k: float | jax.Array = papers.SOIFO_K,
        Rs: ArrayLike = 0.0,
        L: ArrayLike = 1.0,
        omega_init: ArrayLike = papers.FLL_OMEGA_N,
        **kw: Any,
    ) -> ClosedForm:
        """The SOIFO at 000's k = 1.414 with the FLL damped by 001 eq (22) frequency-normalized: lam = k²/4
        (ζ = 1/√2 at every speed, module doc).

        Args:
            k: SOGI gain (> 0).
            Rs: assumed stator resistance, ohm (>= 0; ``bind`` sets it per scenario).
            L: assumed inductance, H (> 0; ``bind`` sets it).
            omega_init: the FLL's initial frequency, rad/s (> 0; ``bind`` sets it).
            **kw: the constructor's keywords.

        Returns:
            The :class:`~jaxobs.observers.ClosedForm`: the :class:`SOIFO` and the rows k, lam.

        Raises:
            ValueError: a value out of its range.
        """
        obs = cls(Rs, L, k, soifo_lambda(k), omega_init, **kw)
        return obs._closed_form_000(dict(k=k), Rs, L, omega_init)

    @classmethod
    def closed_form(cls, **kw: Any) -> SOIFO:
        """The observer of :meth:`closed_form_design` (same arguments).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`SOIFO`.
        """
        return cls.closed_form_design(**kw).observer

    def initial_state(self) -> jax.Array:
        """[yα, qα, yβ, qβ, ω̂] = [0, 0, 0, 0, ``omega_init``].

        Returns:
            The flat state.
        """
        z = jnp.zeros_like(self.k)
        return jnp.stack([z, z, z, z, self.omega_init])

    def f(self, x: jax.Array, e: jax.Array) -> jax.Array:
        """The two SOGIs on (e_α, e_β) and their one FLL (class doc).

        Args:
            x: [yα, qα, yβ, qβ, ω̂].
            e: The back EMF (e_α, e_β), V.

        Returns:
            dx/dt.
        """
        ya, qa, yb, qb, w = x[0], x[1], x[2], x[3], x[4]
        dya, dqa = sogi_vf(ya, qa, e[0], w, self.k)
        dyb, dqb = sogi_vf(yb, qb, e[1], w, self.k)
        num = (e[0] - ya) * qa + (e[1] - yb) * qb
        lam = self.lam * w * w  # frequency-normalized FLL gain (module doc)
        return jnp.stack([dya, dqa, dyb, dqb, -lam * num / _fll_norm(ya, qa, yb, qb, e, self.v_floor)])

    def output(self, x: jax.Array, e: jax.Array) -> FluxOutput:
        """ψ̂ = qv′/ω̂ (000 eq 15), θ̂ and the signed ω̂.

        Args:
            x: The flat state.
            e: The back EMF fed over the last period, V.

        Returns:
            The :class:`~jaxobs.observers.flux.FluxOutput`.
        """
        return self._flux_output(x[4], x[0], x[1], x[2], x[3], e)


class SecondOrderSOIFO(_FLLFluxBase):
    """Second-order SOIFO with FLL (000 Sec. III-B, eq 20, Fig. 4).

    ψ̂ = K1K2ω'²s/(s⁴ + K2ω's³ + (2+K1K2)ω'²s² + K2ω'³s + ω'⁴)·ê: the second-order SOGI of
    :mod:`jaxobs.observers._cores` on each axis, sharing one FLL.

    ``discretization``:

    - ``"rule"`` (default): the continuous vector field through ``rule``
      (RK4 by default; ``Tustin()`` is the paper's trapezoidal method).  State
      [zaα, zbα, yα, qα, zaβ, zbβ, yβ, qβ, ω̂].  FLL: the detector derived for
      the SOGI-FLL-WIF (Golestan's k1 = K2, k2 = K1), ω̂̇ = −(lam·ω̂²/K1) Σₓ zaₓ qₓ / Σₓ V̂ₓ²,
      whose small-signal model is 001 eqs (31)–(32).
    - ``"paper"``: the difference equations of 000 eqs (22)–(25), coefficients
      recomputed every sample from ω̂ (direct form II, four delays per axis,
      shared by D1 and Q1).  The direct form hides the first GI's output z_a, so
      this variant's FLL uses the SOGI-FLL error (ê − v′)qv′ on the outputs, and
      ω̂ is updated by forward Euler.  State [w_α(k−1..k−4), w_β(k−1..k−4), ω̂].

    Args:
        Rs: Assumed stator resistance, ohm (≥ 0; :meth:`bind` sets it per scenario).
        L: Assumed inductance, H (> 0; :meth:`bind` sets it to the machine's Lq: the active flux).
        K1: Second-order SOGI error gain (000's K1, > 0).
        K2: Second-order SOGI damping gain (000's K2, > 0).
        lam: Frequency-normalized FLL gain λ/ω̂² (dimensionless, > 0).
        omega_init: The FLL's initial frequency, rad/s (> 0; :meth:`bind` sets it).
        ts: Sample time, s.
        rule: Discretization rule (default :class:`~jaxobs.RK4`).
        discretization: ``"rule"`` or ``"paper"``, as above.
        v_floor: Floor of the FLL normalization (V, > 0).
        omega_min: Floor of |ω̂| in the outputs, which divide by it, rad/s.
        omega0: Another name of ``omega_init`` (the job files' key); give one of the two.

    Raises:
        ValueError: A value out of its range, or both ``omega_init`` and ``omega0`` given.
    """

    Rs: jax.Array
    L: jax.Array
    K1: jax.Array = eqx.field(
        metadata=gain_metadata(units="1", role="sogi", long_name="second-order SOGI error gain", symbol="000: K1")
    )
    K2: jax.Array = eqx.field(
        metadata=gain_metadata(units="1", role="sogi", long_name="second-order SOGI damping gain", symbol="000: K2")
    )
    lam: jax.Array = eqx.field(metadata=_lam_normalized())
    omega_init: jax.Array  # initial FLL frequency, rad/s (> 0)
    ts: float = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)
    discretization: Literal["rule", "paper"] = eqx.field(static=True)
    v_floor: float = eqx.field(static=True)
    omega_min: float = eqx.field(static=True)

    small_signal_model: ClassVar = ("sosoifo_tf", ("K1", "K2", "omega_init"))  # 000 eq (20) at ω' = omega_init
    _design: ClassVar[_Design000] = _Design000(
        chosen=(("K1", "1.56"), ("K2", "3.11")),
        lam_rule="lam = K1³/(2K2)",
        lam_from="λ = 2ωc²/b, b = K2/K1, ωn → 1",
        lam_source="001 eq (34), normalized",
    )
    _speed_index: ClassVar[int] = 8  # the FLL's ω̂

    def __init__(
        self,
        Rs: ArrayLike,
        L: ArrayLike,
        K1: ArrayLike,
        K2: ArrayLike,
        lam: ArrayLike,
        omega_init: ArrayLike | None = None,
        *,
        ts: float = 1e-4,
        rule: AbstractRule | None = None,
        discretization: Literal["rule", "paper"] = "rule",
        v_floor: float = 1e-2,
        omega_min: float = 1.0,
        omega0: ArrayLike | None = None,
    ) -> None:
        omega_init = self._initial_speed(omega_init, omega0, "SecondOrderSOIFO")
        self._check_common(Rs, L, ts, rule, "SecondOrderSOIFO")
        self.K1, self.K2, self.lam = as_float(K1), as_float(K2), as_float(lam)  # bounds: check_gains
        self.omega_init = check_positive("omega_init", omega_init, "SecondOrderSOIFO")
        if discretization not in ("rule", "paper"):
            raise ValueError(f"SecondOrderSOIFO.discretization must be 'rule' or 'paper', got {discretization!r}")
        self.discretization = discretization
        self.v_floor = float(v_floor)
        self.omega_min = float(omega_min)

    @classmethod
    def closed_form_design(
        cls,
        K1: float | jax.Array = papers.SECOND_ORDER_SOIFO_K1,
        K2: float | jax.Array = papers.SECOND_ORDER_SOIFO_K2,
        Rs: ArrayLike = 0.0,
        L: ArrayLike = 1.0,
        omega_init: ArrayLike = papers.FLL_OMEGA_N,
        **kw: Any,
    ) -> ClosedForm:
        """The second-order SOIFO at 000's K1 = 1.56, K2 = 3.11 with the FLL of 001's symmetric optimum (eq 34)
        frequency-normalized, in 000's names (b = K2/K1): lam = K1³/(2 K2).

        Args:
            K1: error gain (> 0).
            K2: damping gain (> 0).
            Rs: assumed stator resistance, ohm (>= 0; ``bind`` sets it per scenario).
            L: assumed inductance, H (> 0; ``bind`` sets it).
            omega_init: the FLL's initial frequency, rad/s (> 0; ``bind`` sets it).
            **kw: the constructor's keywords (``discretization``, ...).

        Returns:
            The :class:`~jaxobs.observers.ClosedForm`: the :class:`SecondOrderSOIFO` and the rows K1, K2, lam.

        Raises:
            ValueError: a value out of its range.
        """
        obs = cls(Rs, L, K1, K2, second_order_soifo_lambda(K1, K2), omega_init, **kw)
        return obs._closed_form_000(dict(K1=K1, K2=K2), Rs, L, omega_init)

    @classmethod
    def closed_form(cls, **kw: Any) -> SecondOrderSOIFO:
        """The observer of :meth:`closed_form_design` (same arguments).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`SecondOrderSOIFO`.
        """
        return cls.closed_form_design(**kw).observer

    def initial_state(self) -> jax.Array:
        """Eight filter states (or delays) at 0, then ω̂ = ``omega_init``.

        Returns:
            The flat state.
        """
        z = jnp.zeros_like(self.K1)
        n = 8
        return jnp.concatenate([jnp.zeros((n,), z.dtype), self.omega_init[None]])

    # --- continuous form -----------------------------------------------------
    def f(self, x: jax.Array, e: jax.Array) -> jax.Array:
        """The two second-order SOGIs on (e_α, e_β) and their one FLL (class doc, ``"rule"``).

        Args:
            x: [zaα, zbα, yα, qα, zaβ, zbβ, yβ, qβ, ω̂].
            e: The back EMF (e_α, e_β), V.

        Returns:
            dx/dt.
        """
        w = x[8]
        ax = sogi2_vf(x[0], x[1], x[2], x[3], e[0], w, k_err=self.K1, k_damp=self.K2)
        bx = sogi2_vf(x[4], x[5], x[6], x[7], e[1], w, k_err=self.K1, k_damp=self.K2)
        num = x[0] * x[3] + x[4] * x[7]
        lam = self.lam * w * w  # frequency-normalized FLL gain (module doc)
        return jnp.stack([*ax, *bx, -(lam / self.K1) * num / _fll_norm(x[2], x[3], x[6], x[7], e, self.v_floor)])

    # --- paper 000 eqs (22)-(25) ---------------------------------------------
    def _paper_step(self, x: jax.Array, e: jax.Array) -> tuple[jax.Array, tuple[jax.Array, ...]]:
        w = x[8]
        a, bd, bq = sogi2_tustin_coefficients(self.K1, self.K2, jnp.maximum(w, self.omega_min), self.ts)
        outs = []
        new_hist = []
        for ax, ex in ((0, e[0]), (1, e[1])):
            hist = x[4 * ax : 4 * ax + 4]  # w[k-1], w[k-2], w[k-3], w[k-4]
            wk = ex - jnp.dot(a, hist)
            taps = jnp.concatenate([wk[None], hist])
            outs.append((jnp.dot(bd, taps), jnp.dot(bq, taps)))
            new_hist.append(jnp.concatenate([wk[None], hist[:3]]))
        (ya, qa), (yb, qb) = outs
        num = (e[0] - ya) * qa + (e[1] - yb) * qb
        w_new = w - self.ts * self.lam * w * w * num / _fll_norm(ya, qa, yb, qb, e, self.v_floor)
        return jnp.concatenate([new_hist[0], new_hist[1], w_new[None]]), (ya, qa, yb, qb)

    def step(self, state: DriveObserverState, u: DriveInput) -> tuple[DriveObserverState, FluxOutput]:
        """One sample: the rule's (:meth:`AbstractFluxObserver.step`), or 000's difference equations.

        Args:
            state: The state at the previous sample.
            u: The measurements at this sample.

        Returns:
            ``(the state at this sample, the outputs at t_k)``.
        """
        if self.discretization == "rule":
            return super().step(state, u)
        e, i = self.back_emf(state, u)
        x1, (ya, qa, yb, qb) = self._paper_step(state.x, e)
        x1 = jnp.where(state.started, x1, state.x)
        new = DriveObserverState(
            x=x1, rule=state.rule, i_prev=i, u_prev=jnp.stack([u.u_a, u.u_b]), started=jnp.asarray(True)
        )
        return new, self._flux_output(x1[8], ya, qa, yb, qb, e)

    def output(self, x: jax.Array, e: jax.Array) -> FluxOutput:
        """ψ̂ = qv′/ω̂ (000 eq 20), θ̂ and the signed ω̂.

        Args:
            x: The flat state.
            e: The back EMF fed over the last period, V.

        Returns:
            The :class:`~jaxobs.observers.flux.FluxOutput`.
        """
        return self._flux_output(x[8], x[2], x[3], x[6], x[7], e)
