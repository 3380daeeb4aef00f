"""The reduced-order flux observer with speed estimation for synchronous machines: the observer of Hinkkanen,
Saarakkala, Awan, Mölsä, Tuovinen, "Observers for sensorless synchronous motor drives: framework for design and
analysis", IEEE Trans. Ind. Appl. 54(6), 2018 (below "Hinkkanen 2018"), the default sensorless observer of
motulator (Aalto University's open motor-drive simulator).

Sources.  The paper's text is not in ``/work/shared/papers``, so no equation number of it is quoted here.  The
equations below were reconstructed from the structure the paper is known for (a stator-flux observer in
estimated rotor coordinates whose gain decouples the flux from the angle error, the auxiliary flux, a speed-
dependent gain), checked against what motulator 0.18.0 implements (``motulator.drive.control._sm_observers``:
``FluxObserver``, ``SpeedFluxObserver``, ``default_sensorless_k_o``, ``default_alpha_o``; and
``motulator.drive.control._common``: ``hold_equivalent``, ``matched_pole``), and the linearised error
dynamics are derived here (each step below) and tested (tests/test_rofo.py).  The defaults that are motulator's
rather than the paper's are marked so.  No motulator code is copied.

Model, in rotor coordinates (dq), amplitude-invariant:

    dψs/dt = us − Rs is − jωm ψs,        ψs = Ld id + j Lq iq + ψf.

Observer, in estimated rotor coordinates (angle θ̂, rotating at ω̂c), with ψ̂s its state:

    e     = L̂d id + ψ̂f + j L̂q iq − ψ̂s                (the current model's flux minus the estimate)
    ψ̂a    = ψ̂f + (L̂d − L̂q) id − j (L̂d − L̂q) iq     (the auxiliary flux, ψ̂f + (L̂d − L̂q) is*)
    ε     = −Im{e/ψ̂a}                                 (the position error signal, rad electrical)
    dψ̂s/dt = us − R̂s is − jω̂c ψ̂s + k1 e + k2 e*,   k2 = k1 ψ̂a/ψ̂a*
    dθ̂/dt = ω̂c = ω̂m + kθ ε,       dω̂m/dt = kω ε.

Why the auxiliary flux (derived here).  With the angle error θ̃ = θ − θ̂ and the flux error ψ̃ = ψs − ψ̂s (both in
the estimated coordinates, exact machine parameters), the currents measured in the estimated frame are
is e^{jθ̃}, and to first order in θ̃

    e ≈ ψ̃ − jθ̃ ψa,    so    ε = −Im{e/ψa} = θ̃ − Im{ψ̃/ψa}:

ψa is the direction in which an angle error shows in the flux.  On a non-salient machine it is ψf; on a salient
one it moves with the load (the observer uses both Ld and Lq).

Why k2 = k1 ψ̂a/ψ̂a* (derived here).  Then k1 e + k2 e* = 2 k1 ψ̂a Re{e/ψ̂a}, and Re{−jθ̃} = 0: the correction does
not see the angle error.  Writing ψ̃ = ψa (x + jy), the flux error obeys (ψa held, ω̂c ≈ ωm)

    dx/dt = ωm y − 2 k1 x,    dy/dt = −ωm x:    characteristic polynomial s² + 2 k1 s + ωm²,

and the angle and speed errors are driven by y through ε = θ̃ − y:

    dθ̃/dt = ω̃m − kθ ε,    dω̃m/dt = −kω ε:    s² + kθ s + kω  (a triangular system: the poles are the union).

The gain k1 = σ0 + ζ∞|ω̂m| (the speed-dependent gain; its form is motulator's ``default_sensorless_k_o``):
at standstill the flux poles are 0 and −2σ0, at high speed they have the damping ratio k1/|ωm| → ζ∞.  motulator
puts 2σ0 at the mean of the machine's current-model poles, σ0 = R̂s(1/L̂d + 1/L̂q)/4, and ζ∞ = 0.2; here
σ0 = c_σ · R̂s(1/L̂d + 1/L̂q)/2 with the dimensionless gain c_σ (closed form 1/2), so that one design holds on any
machine the observer is bound to.  The speed gains place the poles of s² + kθ s + kω at a double pole −α_o,
kθ = 2α_o, kω = α_o², α_o = 2π·50 rad/s (motulator's ``default_alpha_o`` without an inertia).

Discretisation (exact where stated; the drive observers' sampling convention, :mod:`jaxobs.observers.base`).  At
t_k the observer knows i_k and the voltage u_{k−1} applied over [t_{k−1}, t_k]; its step integrates that period
and returns θ̂, ω̂ and ψ̂s at t_k.  Over the period the voltage is constant in stator coordinates (the PWM's
average) and the resistive drop R̂s i_{k−1} is held in the observer's coordinates, which turn at ω̂c held; then
the flux integrates exactly (the hold equivalent motulator uses):

    ψ̂⁺      = ψ̂s + T_s (k1 e + k2 e*)                      (the correction, forward Euler at t_{k−1})
    ψ̂s(t_k) = Φ (ψ̂⁺ + T_s u) − Γ R̂s is,   Φ = e^{−jω̂c T_s},   Γ = (1 − Φ)/(jω̂c) = T_s sinc(ω̂c T_s/2) e^{−jω̂c T_s/2}

(u, is at t_{k−1} in the coordinates of θ̂(t_{k−1})), θ̂ += T_s ω̂c (exact for ω̂c held) and ω̂m += T_s kω ε
(forward Euler).  The closed form's speed gains use the matched pole α' = (1 − e^{−α_o T_s})/T_s, which puts the
forward-Euler speed loop's double pole at z = e^{−α_o T_s} exactly (motulator's ``matched_pole``).  Decision:
at the first sample (no period integrated yet) the flux estimate is set to the current model's, L̂ i + ψ̂f at θ̂,
so that the observer starts without a flux error where the drive starts with a current.

The speed estimator as a strategy.  The type-2 loop above is the default of the observer's ``speed`` (a
:class:`~jaxobs.observers.speed.PLLSpeed` on kθ and kω, which this class shows the strategy as its ``kp_pll`` and
``ki_pll``; its update keeps the products in the order above, so its results are those of the loop written inline
bit for bit).  A :class:`~jaxobs.observers.speed.MechanicalSpeed` takes its place (``speed=``, or a job's
``[observer.speed] kind = "mechanical"``), as it does behind the LESOs and the LPF flux observer: the same ε drives
the mechanical model directly, with its own gains m1, m2, m3 (the fields ``k1``, ``k2``, ``k3`` of
:class:`~jaxobs.observers.speed.MechanicalSpeed`; not the flux gain k1 above), the torque reference T* the controller
held over the period (``DriveInput.T_ref``, 0 where none is given) and the assumed Ĵ, B̂ and p (``bind``):

    dθ̂/dt = ω̂c = ω̂m + m1 ε
    dω̂m/dt = (p/Ĵ)(T* − T̂L) − (B̂/Ĵ) ω̂m + m2 ε
    dT̂L/dt = −(Ĵ/p) m3 ε

Decision: ε feeds the model as it is, an angle in rad (ε = θ̃ − Im{ψ̃/ψa} above, not a sine to be normalised: it is
already the linear error signal the model's placement assumes, ε ≈ θe − θ̂), and the flux coordinates turn at ω̂c,
the model's angle rate, as they turn at the type-2 loop's.  Linearised as above (exact parameters, a constant load,
B̂ = 0), the errors e_θ = θ̃, e_ω = ω̃m and e_T = TL − T̂L obey

    de_θ/dt = e_ω − m1 ε,   de_ω/dt = −(p/Ĵ) e_T − m2 ε,   de_T/dt = (Ĵ/p) m3 ε,   ε = e_θ − y,

a triangular system again: the poles are the flux's (s² + 2k1 s + ωm²) and those of s³ + m1 s² + m2 s + m3, which
:meth:`jaxobs.observers.speed.MechanicalSpeed.closed_form` puts at a triple −α_o.  What
the model adds is the torque: a speed change the controller commands reaches ω̂m through T* without waiting for ε,
and a load step is the one thing ε must still find (through T̂L).  The step advances the model by forward Euler over
the period (ε at t_{k−1}, T* held over it; :meth:`~jaxobs.observers.speed.AbstractSpeedEstimator.euler`), the flux by
the hold equivalent above at ω̂c.  T* is the reference, not the machine's torque: the current loop's lag and an
inertia error are disturbances of the e_ω row, which T̂L absorbs as it absorbs the load.  The state is then
[ψ̂d, ψ̂q, θ̂, ω̂m, T̂L].

A machine with a flux map (derived here).  Bound to a machine whose ``sat`` is an algebraic current map i(ψ)
(:class:`jaxobs.drive.saturation.AlgebraicSaturation`), the observer's current model is that map, not the constants
L̂d, L̂q, ψ̂f (a drive file's rated-secant ones).  The constants are right at one point only: with them, a current
change δi moves the model's flux by L̂_sec δi while the machine's moves by L_inc δi (the incremental inductance; on
the 5.6-kW PM-SyRM at rated current L_q,inc = 0.051 H against L_q,sec = 0.102 H), so every current transient shows
as a flux error, half of which falls on jψ̂a, the direction ε reads as an angle error: a closed sensorless loop then
feeds its own current ripple back into its angle (measured there: a matched map, 1440 r/min, rated load, 8.8°
steady peak error with the map against 0.00° on a linear machine with the same constants).  With the map, e is
the map's flux at the measured current minus ψ̂s, taken by one Newton step from ψ̂s (the map is explicit in ψ, so
no inversion runs per sample; the step is exact to first order in e, which is the order the design above is
linearised in):

    e = L_inc(ψ̂s) (is − i(ψ̂s)),   L_inc = (∂i/∂ψ)⁻¹,

and the auxiliary flux is the direction an angle error moves e in, re-derived for a map: rotating the measured
current by θ̃ moves the model's flux by L_inc (jθ̃ is) and the machine's (in the estimated frame) by jθ̃ ψs, so

    ψa = ψs + j L_inc (j is)   (ψs = ψ̂s + e, the model's flux),

which is ψ̂f + (L̂d − L̂q) is* for constant inductances.  The secant ψ/i sets the steady point (the flux itself),
the incremental ∂ψ/∂i every deviation from it (the error and its direction): the choice a map makes for itself.
The flux gain σ0 keeps the bound L̂d, L̂q (a design constant, not a model).  A table map (FluxTable, the plant
integrated in currents) and a machine without a map keep the constants (no leaf added: bit for bit as before).

Position and speed.  θ̂ is the observer's own state (the coordinates it works in), so ``init_aligned`` starts it
at the rotor's angle; ω̂m is electrical, signed and passes through zero (nothing in the step divides by it).  At
standstill the flux poles are 0 and −2σ0: the angle is not observable from the back EMF there, as for every
model-based observer.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, NamedTuple, Self

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from ..core.discretize import AbstractRule
from ..core.measurements import DriveInput
from ..core.numerics import wrap
from ..core.validate import as_float, check_nonnegative, check_positive, check_sample_time
from ._gains import ClosedForm, DesignRow, gain_metadata, gain_row
from .base import AbstractDriveObserver, AssumedMachine, BoundFields, DriveObserverState, replace_leaves
from .speed import AbstractSpeedEstimator, speed_from_spec

__all__ = [
    "ROFOOutput",
    "ReducedOrderFluxObserver",
    "ROFO_ALPHA_O_HZ",
    "ROFO_ZETA_INF",
    "ROFO_C_SIGMA",
    "matched_pole",
    "speed_gains",
]

# The closed form's values, motulator 0.18.0's defaults for a sensorless drive without an inertia (module doc):
ROFO_ALPHA_O_HZ = 50.0  # the speed estimate's double pole, Hz (motulator: default_alpha_o, 2π·50 rad/s)
ROFO_ZETA_INF = 0.2  # the flux poles' damping ratio at high speed (motulator: default_sensorless_k_o, 0.2|ω̂m|)
ROFO_C_SIGMA = 0.5  # σ0 over the mean machine pole R̂s(1/L̂d + 1/L̂q)/2 (motulator: σ0 = 0.25 R̂s(1/L̂d + 1/L̂q))


class ROFOOutput(NamedTuple):
    """The reduced-order flux observer's outputs at a sample.

    Attributes:
        theta: θ̂e, rad (wrapped).
        omega: ω̂e, rad/s (signed).
        psi_d: The stator flux estimate ψ̂s in the estimated rotor coordinates, d, Wb.
        psi_q: ψ̂s, q, Wb.
    """

    theta: jax.Array  # θ̂e, rad (wrapped)
    omega: jax.Array  # ω̂e, rad/s (signed)
    psi_d: jax.Array  # stator flux estimate in estimated rotor coordinates, d, Wb
    psi_q: jax.Array  # and q, Wb


def _sinc(x: jax.Array) -> jax.Array:
    """sin(x)/x with its limit 1 − x²/6 near 0 (finite value and gradient at 0)."""
    small = jnp.abs(x) < 1e-4
    xs = jnp.where(small, 1.0, x)
    return jnp.where(small, 1.0 - x * x / 6.0, jnp.sin(xs) / xs)


def matched_pole(alpha: float, ts: float) -> float:
    """The pole α' = (1 − e^{−α T_s})/T_s: forward-Euler gains designed for −α' put the pole at z = e^{−α T_s}.

    Args:
        alpha: The continuous-time pole, rad/s (> 0).
        ts: The sample time, s.

    Returns:
        α', rad/s.
    """
    return -math.expm1(-alpha * ts) / ts


def speed_gains(alpha_o_hz: float, ts: float) -> tuple[float, float]:
    """The closed form's speed gains (kθ, kω) = (2α', α'²), α' the matched pole of α_o = 2π·``alpha_o_hz``.

    Args:
        alpha_o_hz: The speed estimate's double pole α_o/2π, Hz (> 0).
        ts: The sample time, s (> 0).

    Returns:
        ``(k_theta in 1/s, k_omega in 1/s²)`` as Python floats.

    Raises:
        ValueError: A value out of its range.
    """
    a = float(check_positive("alpha_o_hz", alpha_o_hz, "ReducedOrderFluxObserver.closed_form"))
    am = matched_pole(2 * math.pi * a, check_sample_time("ts", ts, "ReducedOrderFluxObserver.closed_form"))
    return 2.0 * am, am * am


class ReducedOrderFluxObserver(AbstractDriveObserver):
    """Reduced-order (stator) flux observer with speed estimation, in estimated rotor coordinates (Hinkkanen 2018;
    module doc).  State [ψ̂d, ψ̂q, θ̂, ω̂m, ...] (the speed estimator's states after the flux's); runs on salient
    (Ld ≠ Lq) and non-salient machines.

    Args:
        Rs: Assumed stator resistance, ohm (≥ 0; :meth:`bind` sets it).
        Ld: Assumed d-axis inductance, H (> 0; :meth:`bind` sets it).
        Lq: Assumed q-axis inductance, H (> 0; :meth:`bind` sets it).
        psi_f: Assumed PM flux, Wb (> 0; :meth:`bind` sets it).
        c_sigma: The zero-speed flux gain σ0 over the mean machine pole R̂s(1/L̂d + 1/L̂q)/2 (dimensionless, > 0).
        zeta_inf: The flux gain's slope in |ω̂m|, the flux poles' damping ratio at high speed (> 0).
        k_theta: The angle gain kθ, rad/s (> 0).
        k_omega: The speed gain kω, rad/s² (> 0).
        omega_init: The speed estimate's start, rad/s (signed; :meth:`bind` sets it).
        ts: Sample time, s.
        psi_floor: Floor of |ψ̂a| in the error signal's division, Wb (> 0).
        omega0: Another name of ``omega_init`` (the flux observers' job-file key); give one of the two.
        rule: None only: the step is its own update (a job or an export that rebuilds a component passes it).
        speed: The speed extraction: an estimator, or a record (:func:`~jaxobs.observers.speed.speed_from_spec`);
            default :class:`~jaxobs.observers.speed.PLLSpeed` on ``k_theta``, ``k_omega`` (the type-2 loop of the
            module doc), or a :class:`~jaxobs.observers.speed.MechanicalSpeed` in its place.

    Raises:
        ValueError: A value out of its range, both ``omega_init`` and ``omega0`` given, or a rule.
    """

    Rs: jax.Array
    Ld: jax.Array
    Lq: jax.Array
    psi_f: jax.Array
    c_sigma: jax.Array = eqx.field(
        metadata=gain_metadata(
            units="1",
            role="flux",
            long_name="zero-speed flux gain over the mean machine pole Rs(1/Ld + 1/Lq)/2",
            symbol="Hinkkanen 2018: σ0 (ours: c_σ = σ0/(R̂s(1/L̂d + 1/L̂q)/2))",
        )
    )
    zeta_inf: jax.Array = eqx.field(
        metadata=gain_metadata(
            units="1",
            role="flux",
            long_name="flux gain slope in |speed| (the flux poles' damping at high speed)",
            symbol="Hinkkanen 2018: k1 = σ0 + ζ∞|ω̂m|",
        )
    )
    # the speed estimate is a type-2 tracking loop on ε (θ̂̇ = ω̂ + kθ ε, ω̂̇ = kω ε): a PLL's role
    k_theta: jax.Array = eqx.field(
        metadata=gain_metadata(
            units="s-1", role="pll", long_name="angle estimation gain", symbol="kθ (closed form: 2α')"
        )
    )
    k_omega: jax.Array = eqx.field(
        metadata=gain_metadata(
            units="s-2", role="pll", long_name="speed estimation gain", symbol="kω (closed form: α'²)"
        )
    )
    omega_init: jax.Array  # the speed estimate's start, rad/s (signed)
    speed: AbstractSpeedEstimator  # θ̂, ω̂m from ε: the type-2 loop on kθ, kω (PLLSpeed) or a mechanical model
    ts: float = eqx.field(static=True)
    psi_floor: float = eqx.field(static=True)
    # the assumed machine's algebraic current map i(ψ) (bind sets it from est_par.sat; None: the constants, no leaf)
    flux_map: Any = None
    # no discretization rule: the step is its own update (module doc: the hold equivalent, exact where stated);
    # jobs and the export read ``rule`` of every component, and None says so (the export's "none")
    rule: ClassVar[None] = None
    # a job may tune it (why_not_tunable ""); jaxobs.linear holds no small-signal model of it (its linearised
    # poles are in the module doc and tests/test_rofo.py), as for the LPF
    why_not_tunable: ClassVar[str] = ""
    small_signal_model: ClassVar[None] = None
    takes_speed_estimator: ClassVar[bool] = True

    # bind() sets these, by role (tuning/export reads them so); the machine's Lq and ψf besides
    bound_fields: ClassVar[BoundFields] = BoundFields(
        resistance="Rs", inductance="Ld", speed="omega_init", more=("Lq", "psi_f")
    )

    def __init__(
        self,
        Rs: ArrayLike,
        Ld: ArrayLike,
        Lq: ArrayLike,
        psi_f: ArrayLike,
        c_sigma: ArrayLike,
        zeta_inf: ArrayLike,
        k_theta: ArrayLike,
        k_omega: ArrayLike,
        omega_init: ArrayLike | None = None,
        *,
        ts: float = 1e-4,
        psi_floor: float = 1e-4,
        omega0: ArrayLike | None = None,
        rule: AbstractRule | None = None,
        speed: AbstractSpeedEstimator | dict[str, Any] | None = None,
    ) -> None:
        name = "ReducedOrderFluxObserver"
        if rule is not None:
            raise ValueError(
                f"{name}.rule must be None (its step is an exact hold-equivalent update, not a rule's "
                f"integration), got {type(rule).__name__}"
            )
        if omega0 is not None:
            if omega_init is not None:
                raise ValueError(f"{name}: give the initial speed once, as omega_init (omega0 is the same field)")
            omega_init = omega0
        self.Rs = check_nonnegative("Rs", Rs, name)
        self.Ld = check_positive("Ld", Ld, name)
        self.Lq = check_positive("Lq", Lq, name)
        self.psi_f = check_positive("psi_f", psi_f, name)
        # the gains' declared bounds (> 0) are checked by check_gains (AbstractObserver.__check_init__)
        self.c_sigma, self.zeta_inf = as_float(c_sigma), as_float(zeta_inf)
        self.k_theta, self.k_omega = as_float(k_theta), as_float(k_omega)
        self.omega_init = jnp.asarray(0.0 if omega_init is None else omega_init, dtype=self.Rs.dtype)
        self.ts = check_sample_time("ts", ts, name)
        if not (math.isfinite(float(psi_floor)) and float(psi_floor) > 0):
            raise ValueError(f"{name}.psi_floor must be finite and > 0 Wb, got {psi_floor!r}")
        self.psi_floor = float(psi_floor)
        self.speed = speed_from_spec(speed, f"{name}.speed", self.ts)
        self.flux_map = None  # bind sets the assumed machine's current map (module doc)

    @classmethod
    def closed_form_design(
        cls,
        alpha_o_hz: float = ROFO_ALPHA_O_HZ,
        zeta_inf: ArrayLike = ROFO_ZETA_INF,
        c_sigma: ArrayLike = ROFO_C_SIGMA,
        Rs: ArrayLike = 0.0,
        Ld: ArrayLike = 1.0,
        Lq: ArrayLike = 1.0,
        psi_f: ArrayLike = 1.0,
        omega_init: ArrayLike = 0.0,
        ts: float = 1e-4,
        **kw: Any,
    ) -> ClosedForm:
        """Pole placement (module doc, derived from the linearised error dynamics of Hinkkanen 2018's observer):

        - flux: k1 = σ0 + ζ∞|ω̂m| with σ0 = c_σ R̂s(1/L̂d + 1/L̂q)/2, c_σ = 1/2 (the poles of s² + 2k1 s + ωm²
          at 0 and −R̂s(1/L̂d + 1/L̂q)/2 at standstill, damping ζ∞ = 0.2 at high speed);
        - speed: s² + kθ s + kω = (s + α')², kθ = 2α', kω = α'², α' = (1 − e^{−α_o T_s})/T_s, α_o = 2π·50 rad/s
          (the forward-Euler speed loop's double pole at z = e^{−α_o T_s}).

        The values are motulator 0.18.0's defaults for a sensorless drive without an inertia
        (``default_sensorless_k_o``, ``default_alpha_o``, ``matched_pole``); the paper's text is not in the
        project's papers, so the rows cite the paper without an equation number.  The machine's defaults are
        placeholders (``bind`` sets them): the gains do not depend on them, the row σ0 does.

        Args:
            alpha_o_hz: The speed estimate's double pole α_o/2π, Hz (> 0).
            zeta_inf: The flux poles' damping ratio at high speed (> 0).
            c_sigma: σ0 over the mean machine pole (> 0).
            Rs: Assumed stator resistance, ohm (≥ 0; ``bind`` sets it).
            Ld: Assumed d-axis inductance, H (> 0; ``bind`` sets it).
            Lq: Assumed q-axis inductance, H (> 0; ``bind`` sets it).
            psi_f: Assumed PM flux, Wb (> 0; ``bind`` sets it).
            omega_init: The speed estimate's start, rad/s (``bind`` sets it).
            ts: Sample time, s (the matched pole depends on it).
            **kw: The constructor's keywords.

        Returns:
            The :class:`~jaxobs.observers.ClosedForm`: the :class:`ReducedOrderFluxObserver` and the rows
            c_sigma, zeta_inf, k_theta, k_omega, σ0 at the assumed machine and the matched pole α'.

        Raises:
            ValueError: A value out of its range.
        """
        k_theta, k_omega = speed_gains(alpha_o_hz, ts)
        obs = cls(Rs, Ld, Lq, psi_f, c_sigma, zeta_inf, k_theta, k_omega, omega_init, ts=ts, **kw)
        # no equation numbers: the paper's text is not in the project's papers (module doc); each row names the
        # motulator 0.18 default it takes
        flux = "Hinkkanen et al. 2018 (k1 = σ0 + ζ∞|ω|); motulator 0.18 default_sensorless_k_o"
        speed = "Hinkkanen et al. 2018 (pole placement); motulator 0.18 default_alpha_o, matched_pole"
        sigma0 = obs.c_sigma * 0.5 * obs.Rs * (1.0 / obs.Ld + 1.0 / obs.Lq)
        rows = (
            gain_row(cls, "c_sigma", obs.c_sigma, "chosen: c_σ = 1/2 (σ0 = Rs(1/Ld + 1/Lq)/4)", flux),
            gain_row(cls, "zeta_inf", obs.zeta_inf, "chosen: ζ∞ = 0.2 (high-speed flux-pole damping)", flux),
            gain_row(cls, "k_theta", obs.k_theta, "kθ = 2α' (double pole at −α')", speed),
            gain_row(cls, "k_omega", obs.k_omega, "kω = α'²", speed),
            DesignRow("sigma0", sigma0, "s-1", "σ0 = c_σ Rs(1/Ld + 1/Lq)/2 (poles 0, −2σ0 at ω = 0)", flux),
            DesignRow("alpha_matched", obs.k_theta / 2, "s-1", "α' = (1 − e^(−α_o Ts))/Ts, α_o = 2π·alpha_o_hz", speed),
        )
        inputs = dict(
            alpha_o_hz=alpha_o_hz,
            zeta_inf=zeta_inf,
            c_sigma=c_sigma,
            Rs=Rs,
            Ld=Ld,
            Lq=Lq,
            psi_f=psi_f,
            omega_init=omega_init,
            ts=ts,
        )
        source = (
            "Hinkkanen, Saarakkala, Awan, Mölsä, Tuovinen, IEEE TIA 54(6) 2018, pole placement; "
            "motulator 0.18 defaults (c_σ = 1/2, ζ∞ = 0.2, α_o = 2π·50)"
        )
        return ClosedForm(obs, inputs, rows, source)

    @classmethod
    def closed_form(cls, **kw: Any) -> ReducedOrderFluxObserver:
        """The observer of :meth:`closed_form_design` (same arguments; Hinkkanen 2018's observer, motulator's
        defaults).

        Args:
            **kw: :meth:`closed_form_design`'s arguments.

        Returns:
            The :class:`ReducedOrderFluxObserver`.
        """
        return cls.closed_form_design(**kw).observer

    # --- the speed estimator's host (jaxobs.observers.speed.SpeedHost): the type-2 loop's gains ---------------
    @property
    def kp_pll(self) -> jax.Array:
        """kθ, the type-2 loop's angle gain as the :class:`~jaxobs.observers.speed.PLLSpeed` strategy reads it, 1/s."""
        return self.k_theta

    @property
    def ki_pll(self) -> jax.Array:
        """kω, the type-2 loop's speed gain as the :class:`~jaxobs.observers.speed.PLLSpeed` strategy reads it, 1/s²."""
        return self.k_omega

    def speed_estimator(self) -> AbstractSpeedEstimator:
        """The speed extraction this observer holds (``speed``).

        Returns:
            The :class:`~jaxobs.observers.speed.AbstractSpeedEstimator`.
        """
        return self.speed

    # --- the drive-observer contract ------------------------------------------------------------------------
    def bind(self, est_par: AssumedMachine | None, omega_e: ArrayLike) -> Self:
        """This observer assuming ``est_par``'s Rs, Ld, Lq and ψf (and its speed estimator the machine's mechanics),
        its speed estimate starting at the signed ω_e (:meth:`AbstractDriveObserver.bind`); with an algebraic
        current map (``est_par.sat``) its current model is the map (module doc).

        Args:
            est_par: The machine assumed, or None (the speed only).
            omega_e: The electrical speed, rad/s, signed.

        Returns:
            The bound observer.
        """
        if est_par is None:
            return replace_leaves(self, omega_init=omega_e)
        new = replace_leaves(self, Rs=est_par.Rs, Ld=est_par.Ld, Lq=est_par.Lq, psi_f=est_par.psi_f, omega_init=omega_e)
        sat = est_par.sat
        if sat is not None and sat.state_is_flux:  # an algebraic current map i(ψ): the current model (module doc)
            new = eqx.tree_at(lambda o: o.flux_map, new, sat, is_leaf=lambda x: x is None)
        speed = self.speed.bind(est_par)  # a mechanical model takes the assumed Ĵ, B̂, p; a PLL has none
        return new if speed is self.speed else eqx.tree_at(lambda o: o.speed, new, speed)

    def initial_state(self, omega_e: ArrayLike | None = None, theta_e: ArrayLike | None = None) -> jax.Array:
        """[ψ̂d, ψ̂q, θ̂, ω̂m, ...] = [ψ̂f, 0, θ_e or 0, ω_e or omega_init, 0, ...] (the speed estimator's own states
        at 0).

        Args:
            omega_e: The speed estimate's start, rad/s (None: ``omega_init``).
            theta_e: The angle estimate's start, rad (None: 0).

        Returns:
            The flat state.
        """
        dt = self.Rs.dtype
        w = self.omega_init if omega_e is None else jnp.asarray(omega_e, dt)
        th = jnp.zeros((), dt) if theta_e is None else wrap(jnp.asarray(theta_e, dt))
        flux = jnp.stack([jnp.asarray(self.psi_f, dt), jnp.zeros((), dt)])
        return jnp.concatenate([flux, self.speed.initial_state(th, w).astype(dt)])

    def _init_from(self, x0: jax.Array) -> DriveObserverState:
        z2 = jnp.zeros((2,), x0.dtype)
        return DriveObserverState(x=x0, rule=None, i_prev=z2, u_prev=z2, started=jnp.asarray(False))

    def init(self, u0: Any = None) -> DriveObserverState:
        """The state at sample 0: :meth:`initial_state`, nothing seen yet.

        Args:
            u0: Unused (the first sample sets the flux from the current model).

        Returns:
            The :class:`DriveObserverState`.
        """
        return self._init_from(self.initial_state())

    def init_at(self, omega_e: ArrayLike) -> DriveObserverState:
        """The initial state with the speed estimate at ω_e (θ̂ = 0, ψ̂s = ψ̂f).

        Args:
            omega_e: ω_e, rad/s.

        Returns:
            The :class:`DriveObserverState`.
        """
        return self._init_from(self.initial_state(omega_e))

    def init_aligned(self, omega_e: ArrayLike, theta_e: ArrayLike) -> DriveObserverState:
        """:meth:`init_at` with θ̂ at the rotor's θ_e: the angle is this observer's own state.

        Args:
            omega_e: ω_e, rad/s.
            theta_e: θ_e, rad.

        Returns:
            The :class:`DriveObserverState`.
        """
        return self._init_from(self.initial_state(omega_e, theta_e))

    def seed_speed(self, state: DriveObserverState, omega_e: ArrayLike) -> DriveObserverState:
        """``state`` with ω̂m set to ω_e (an I-f start-up holds it at the I-f frequency).

        Args:
            state: The :class:`DriveObserverState`.
            omega_e: ω_e, rad/s.

        Returns:
            The state with its speed estimate set.
        """
        return eqx.tree_at(lambda s: s.x, state, state.x.at[3].set(omega_e))

    # --- the observer -----------------------------------------------------------------------------------------
    def flux_gain(self, omega: ArrayLike) -> jax.Array:
        """k1 = σ0 + ζ∞|ω̂m|, σ0 = c_σ R̂s(1/L̂d + 1/L̂q)/2, 1/s.

        Args:
            omega: ω̂m, rad/s.

        Returns:
            k1, 1/s.
        """
        sigma0 = self.c_sigma * 0.5 * self.Rs * (1.0 / self.Ld + 1.0 / self.Lq)
        return sigma0 + self.zeta_inf * jnp.abs(omega)

    def current_model(
        self, i_d: jax.Array, i_q: jax.Array, psi: tuple[jax.Array, jax.Array] | None = None
    ) -> tuple[tuple[jax.Array, jax.Array], tuple[jax.Array, jax.Array]]:
        """The current model's flux L̂d id + ψ̂f + j L̂q iq and the auxiliary flux ψ̂f + (L̂d − L̂q) is* (d, q each);
        with a current map (``flux_map``), the map's flux at the current by one Newton step from ``psi`` and
        ψa = ψs + j L_inc (j is) (module doc).

        Args:
            i_d: id in the estimated rotor coordinates, A.
            i_q: iq, A.
            psi: (ψ̂d, ψ̂q), Wb, the Newton step's start with a map (None: ``psi_f``, 0); not read without one.

        Returns:
            ``((ψd, ψq), (ψad, ψaq))``, Wb.
        """
        if self.flux_map is not None:
            if psi is None:
                psi = (jnp.broadcast_to(self.psi_f, jnp.shape(i_d)), jnp.zeros_like(i_d))
            return self._map_model(psi, i_d, i_q)
        dl = self.Ld - self.Lq
        return (self.Ld * i_d + self.psi_f, self.Lq * i_q), (self.psi_f + dl * i_d, -dl * i_q)

    def _map_model(self, psi, i_d, i_q):
        """The map's flux at (i_d, i_q) by one Newton step from ψ̂ = ``psi`` and the auxiliary flux (module doc)."""
        m = self.flux_map
        j_d, j_q = m.current(psi[0], psi[1])
        g = m.inverse_inductance(psi[0], psi[1])  # ∂i/∂ψ; its inverse is L_inc
        det = g[..., 0, 0] * g[..., 1, 1] - g[..., 0, 1] * g[..., 1, 0]
        l_dd, l_dq, l_qd, l_qq = g[..., 1, 1] / det, -g[..., 0, 1] / det, -g[..., 1, 0] / det, g[..., 0, 0] / det
        dd, dq = i_d - j_d, i_q - j_q
        f_d, f_q = psi[0] + l_dd * dd + l_dq * dq, psi[1] + l_qd * dd + l_qq * dq
        # ψa = ψs + j L_inc (j is): L (j i) = (−L_dd iq + L_dq id, −L_qd iq + L_qq id), then times j
        return (f_d, f_q), (f_d - l_qq * i_d + l_qd * i_q, f_q - l_dd * i_q + l_dq * i_d)

    def error_signals(
        self, psi: tuple[jax.Array, jax.Array], i_d: jax.Array, i_q: jax.Array
    ) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array, jax.Array, jax.Array]:
        """The flux error e, the auxiliary flux ψ̂a and the position error ε = −Im{e/ψ̂a} (module doc).

        Args:
            psi: (ψ̂d, ψ̂q), Wb.
            i_d: id in the estimated rotor coordinates, A.
            i_q: iq, A.

        Returns:
            ``(e_d, e_q, ψad, ψaq, Re{e/ψ̂a}, ε)``.
        """
        (pid, piq), (pad, paq) = self.current_model(i_d, i_q, psi)
        ed, eq = pid - psi[0], piq - psi[1]
        na = jnp.maximum(pad * pad + paq * paq, self.psi_floor**2)
        # e/ψa = e ψa*/|ψa|²
        re = (ed * pad + eq * paq) / na
        im = (eq * pad - ed * paq) / na
        return ed, eq, pad, paq, re, -im

    def _advance(self, x: jax.Array, u_ab: jax.Array, i_ab: jax.Array, torque: ArrayLike = 0.0) -> jax.Array:
        """The state at t_k from the state at t_{k−1}, the current i_{k−1}, the voltage and the torque reference
        over the period."""
        psi_d, psi_q, th = x[0], x[1], x[2]
        c, s = jnp.cos(th), jnp.sin(th)
        i_d, i_q = c * i_ab[0] + s * i_ab[1], -s * i_ab[0] + c * i_ab[1]
        u_d, u_q = c * u_ab[0] + s * u_ab[1], -s * u_ab[0] + c * u_ab[1]
        _, _, pad, paq, re, eps = self.error_signals((psi_d, psi_q), i_d, i_q)
        # k1 e + k2 e* with k2 = k1 ψa/ψa*: 2 k1 ψa Re{e/ψa} (module doc)
        g = 2.0 * self.flux_gain(x[3]) * re
        # the speed estimator over the period: ω̂c = dθ̂/dt (the default: ω̂m + kθ ε, ω̂m += (T_s kω) ε; module doc)
        wc, xs = self.speed.euler(self, x[2:], eps, torque, self.ts)
        pd = psi_d + self.ts * (g * pad + u_d)
        pq = psi_q + self.ts * (g * paq + u_q)
        # Φ = e^{−jx}², Γ = T_s sinc(x) e^{−jx}, x = ω̂c T_s/2 (hold equivalent, module doc)
        half = 0.5 * wc * self.ts
        ch, sh = jnp.cos(half), jnp.sin(half)
        cp, sp = ch * ch - sh * sh, 2.0 * ch * sh  # Φ = cp − j sp
        gam = self.ts * _sinc(half)
        rd, rq = gam * self.Rs * i_d, gam * self.Rs * i_q
        new_d = cp * pd + sp * pq - (ch * rd + sh * rq)
        new_q = -sp * pd + cp * pq - (-sh * rd + ch * rq)
        return jnp.concatenate([jnp.stack([new_d, new_q]), xs.at[0].set(wrap(xs[0]))])

    def _current_model_state(self, x: jax.Array, i_ab: jax.Array) -> jax.Array:
        """``x`` with ψ̂s set to the current model's flux at θ̂ (the first sample's start, module doc)."""
        c, s = jnp.cos(x[2]), jnp.sin(x[2])
        (pid, piq), _ = self.current_model(c * i_ab[0] + s * i_ab[1], -s * i_ab[0] + c * i_ab[1], (x[0], x[1]))
        return jnp.concatenate([jnp.stack([pid, piq]), x[2:]])

    def step(self, state: DriveObserverState, meas: DriveInput) -> tuple[DriveObserverState, ROFOOutput]:
        """One sample: the period that ends now by the hold equivalent (module doc), or, at the first sample, the
        current model's flux.

        Args:
            state: The state at the previous sample.
            meas: The measurements at this sample.

        Returns:
            ``(the state at this sample, the outputs at t_k)``.
        """
        i = jnp.stack([meas.i_a, meas.i_b])
        tq = meas.T_ref  # the torque reference over the period (a mechanical speed model reads it); none given: 0
        tq = jnp.zeros((), state.x.dtype) if tq is None else jnp.asarray(tq, state.x.dtype)
        x1 = jnp.where(
            state.started,
            self._advance(state.x, state.u_prev, state.i_prev, tq),
            self._current_model_state(state.x, i),
        )
        new = DriveObserverState(
            x=x1, rule=None, i_prev=i, u_prev=jnp.stack([meas.u_a, meas.u_b]), started=jnp.asarray(True)
        )
        return new, ROFOOutput(theta=x1[2], omega=x1[3], psi_d=x1[0], psi_q=x1[1])
