"""Voltage-feedback field weakening for the FOC (:class:`VoltageFeedbackFW`, ``FOC(field_weakening=...)``).

The standard closed-loop scheme (Kim & Sul, IEEE Trans. Ind. Appl. 33(1), 1997; the same structure as 002's
ref. [32], Hu et al. 2021, which adds the xy subspace of a dual three-phase machine): an integrator adds a
negative d-current Δi_d when the current PIs' voltage reference |u*| exceeds a margin m of the inverter's
limit u_max, and gives it back when |u*| falls below it,

    dΔi_d/dt = α_fw (m u_max − |u*|) / (L̂d max(|ω̂e|, ω_min)),

so i_d* = max(i_d,policy + Δi_d, i_d,lo).  Above base speed |u*| ≈ |ω̂e| (ψ̂f + L̂d i_d), whose slope in i_d is
ω̂e L̂d: dividing by it makes the loop from Δi_d to |u*| a first-order loop of bandwidth α_fw at every speed
(ω_min only bounds the gain near standstill).  It is off by default (``field_weakening=None``: i_d* is the
policy's, 0 or MTPA).

The reference the FOC then asks for (:meth:`VoltageFeedbackFW.references`; constant inductances, the assumed
machine L̂d, L̂q, ψ̂f, R̂s):

1. *Where i_d stops.*  i_d,lo = max(−i_max, min(−ψ̂f/L̂d, i_d,policy)): never beyond the current circle (at any
   speed, standstill included), and never past the characteristic current −ψ̂f/L̂d, where the d flux
   ψd = ψ̂f + L̂d i_d reaches zero (more negative i_d raises |ψd| again and the voltage with it).  The
   integrator itself is clipped to [i_d,lo − i_d,policy, 0]: it cannot wind up against that stop.  Below
   ω_gate = (m u_max − R̂s i_max)/√(ψ̂f² + (L̂q i_max)²) (:meth:`VoltageFeedbackFW.gate_speed`) no current in the
   circle needs field weakening, and the stop is the policy's i_d: a current PI's momentary saturation at
   standstill (L̂ di/dt, not the back EMF) no longer drives Δi_d through the gain's ω_min floor (it asked for
   i_d* = −11.2 A on the 9.1 A lab IPMSM after a 0 → 2000 r/min step; ``tests/test_weakening.py``).
2. *The same torque on the weakened d axis.*  The speed loop asks for a torque (the policy's at i_q,cmd);
   at the weakened i_d* the q current that gives it is i_q = i_q,cmd (ψ̂f + (L̂d − L̂q) i_d,policy)/(ψ̂f +
   (L̂d − L̂q) i_d*), so the speed loop's gain does not change when the field is weakened (the divisor is
   > 0 for i_d* ≥ −ψ̂f/L̂d on any machine: ≥ ψ̂f L̂q/L̂d).
3. *The limits of i_q* at that i_d*: the current circle |i_q| ≤ √(i_max² − i_d*²); the MTPV line; and the
   voltage: the steady |u| of (i_d*, i_q) at ω̂e at most u_max (a quadratic in i_q with R̂s included).
   MTPV with constant inductances (the maximum torque on the flux circle |ψ| = const): ψd² − ψq² −
   ψ̂f L̂q ψd/(L̂q − L̂d) = 0 (checked by brute force in ``tests/test_weakening.py``).  For L̂q ≥ L̂d it lies at
   ψd < 0, beyond −ψ̂f/L̂d, so the stop of point 1 keeps the reference on the MTPA side of it and only an
   inverse-salient machine (L̂d > L̂q, MTPV at ψd > 0) has |ψq| ≤ √(ψd² + ψ̂f L̂q ψd/(L̂d − L̂q)) as a bound.
   Stopping at −ψ̂f/L̂d on a salient machine gives up the torque between it and its MTPV line at very high
   speed (a few % at 1.5× base speed on the traction IPMSM of ``docs/examples/traction_ipmsm.toml``): a
   decision for a reference that is monotonic in Δi_d and needs no search.
4. *The torque realised* by (i_d*, i_q*) goes back to the speed loop, whose integrator stops when that torque,
   not only the current circle's, falls short of what it asks (:meth:`jaxobs.drive.FOC.step`).

The voltage limit of point 3 is u_max itself, above the loop's target m u_max: the Δi_d loop keeps |u*| at
m u_max while it can, and the cap only acts when i_d* has reached its stop (a cap at m u_max would fight the
Δi_d loop: any model error would then walk i_d* back and the torque down).

The margin m leaves the current PIs room to regulate.  Its default, :data:`FW_MARGIN` = 0.95, is the rule
m = 1 − 0.05: 5 % of u_max left for the current loop's transient voltage, about L̂ α_c Δi for a step Δi of a
few % of i_max at the benches' α_c (motulator 0.18's synchronous-machine current control takes 0.9 of its
own limit); ``[control] fw_margin`` sets it.

*Bounded* (``bounded=True``; what a drive file builds, off by default so the papers' benches run as they
always did).  Two changes to the Δi_d loop, for a machine whose q flux dominates (a PM-SyRM: L̂q ≈ 5 L̂d):

- it sees min(|u*|, u_max): the current PIs' transient demand beyond the inverter (k_p e of a current step, up
  to kilovolts) is no flux to weaken, and fed whole it drove Δi_d from −3.7 A to the −i_max stop in 8 ms on the
  5.6-kW PM-SyRM of ``docs/examples/pmsyrm_5p6kw_sat.toml``, leaving no room for i_q;
- its gain divides by max(d|u|/dΔi_d, L̂d max(|ω̂e|, ω_min)), the slope of the steady voltage of the reference
  itself (:meth:`VoltageFeedbackFW.path_slope`): where i_q* falls as i_d* does (the torque kept on a salient
  machine, or the circle's room) that slope is ω̂e (ψd L̂d + ψq L̂q di_q/di_d)/|ψ|, 15× ω̂e L̂d on that PM-SyRM's
  circle at 2136 r/min, and the loop designed at α_fw ran at about 15 α_fw, against the current loop, in a limit
  cycle; the max keeps the gain at or below the unbounded design's.

With them the PM-SyRM's top point (2136 r/min, 33.5 N·m) is held at 0.996 × i_max where it collapsed to 758 r/min
drawing 1.072 × i_max (with the FOC's ``d_priority`` and ``flux_map``, :class:`~jaxobs.drive.FOC`).

|u*| is the current PIs' reference before the controller's own limit, available at the end of a period, so
Δi_d acts from the next period on (a one-period lag, negligible against 1/α_fw).  A steady start above base
speed starts at this loop's equilibrium, |u*| = m u_max (:meth:`jaxobs.drive.FOC.operating_point` solves
i_d* with the torque balance; :meth:`jaxobs.drive.FOC.init` starts the integrator there).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..core.numerics import safe_norm2
from ..core.validate import check_positive, check_real
from .machine import PMSMParams

__all__ = [
    "FW_MARGIN",
    "VoltageFeedbackFW",
    "capability_curve",
    "capability_torque",
    "id_stop",
    "map_flux_at",
    "map_speed_flux",
    "mtpv_iq",
    "mtpv_iq_np",
    "voltage_iq_range",
]

FW_MARGIN = 0.95  # the default margin m (module doc: 5 % of u_max left to the current PIs)


class VoltageFeedbackFW(eqx.Module):
    """Voltage-feedback field weakening (module doc).

    Args:
        alpha_fw: The bandwidth of the Δi_d loop, rad/s (> 0).
        margin: m, the fraction of u_max the voltage reference is held below, in (0, 1].
        omega_min: The electrical speed floor of the gain's ω̂e, rad/s (> 0).
        bounded: The loop sees min(|u*|, u_max) and divides by the reference path's slope (module doc,
            "Bounded"); False: the unbounded design.

    Raises:
        ValueError: A value out of its range, naming the field.
    """

    alpha_fw: jax.Array  # bandwidth of the Δi_d loop, rad/s (> 0)
    margin: jax.Array  # m: the fraction of u_max the voltage reference is held below, in (0, 1]
    omega_min: jax.Array  # electrical speed floor of the gain's ω̂e, rad/s (> 0)
    bounded: bool = eqx.field(static=True)  # the loop sees min(|u*|, u_max) and the reference path's slope

    def __init__(self, alpha_fw=2 * jnp.pi * 20.0, margin=FW_MARGIN, omega_min=10.0, bounded=False):
        own = "VoltageFeedbackFW"
        self.alpha_fw = check_positive("alpha_fw", alpha_fw, own)
        self.margin = check_real("margin", margin, lower=0.0, upper=1.0, owner=own)
        self.omega_min = check_positive("omega_min", omega_min, own)
        if not isinstance(bounded, bool):
            raise ValueError(f"{own}.bounded must be True or False, got {bounded!r}")
        self.bounded = bounded

    def update(
        self,
        id_fw: jax.Array | float,
        u_ref_mag: jax.Array | float,
        u_max: jax.Array | float,
        omega_e: jax.Array | float,
        Ld: jax.Array | float,
        i_max: jax.Array | float,
        ts: float,
        lo: jax.Array | float | None = None,
        slope: jax.Array | float | None = None,
    ) -> jax.Array:
        """Δi_d for the next period from this period's |u*| and ω̂e.

        With ``bounded`` (module doc, "Bounded"): |u*| is taken at most u_max, and the gain's slope is
        max(``slope``, L̂d max(|ω̂e|, ω_min)) where ``slope`` is given (:meth:`path_slope`).

        Args:
            id_fw: This period's Δi_d, A.
            u_ref_mag: |u*|, V.
            u_max: The voltage limit, V.
            omega_e: ω̂e, rad/s.
            Ld: The assumed d-axis inductance, H.
            i_max: The current-vector limit, A.
            ts: The control period, s.
            lo: The least Δi_d, A (≤ 0): i_d,lo − i_d,policy (module doc, point 1); None: −i_max.
            slope: d|u|/dΔi_d along the reference, V/A (:meth:`path_slope`), or None: L̂d max(|ω̂e|, ω_min).

        Returns:
            Δi_d, A, in [lo, 0].
        """
        design = Ld * jnp.maximum(jnp.abs(omega_e), self.omega_min)
        if self.bounded:
            u_ref_mag = jnp.minimum(u_ref_mag, u_max)
            design = design if slope is None else jnp.maximum(slope, design)
        gain = self.alpha_fw / design
        lo = -i_max if lo is None else lo
        return jnp.clip(id_fw + gain * (self.margin * u_max - u_ref_mag) * ts, lo, 0.0)

    def references(
        self,
        est: PMSMParams,
        id_policy: jax.Array,
        iq_cmd: jax.Array,
        id_fw: jax.Array,
        omega_e: jax.Array,
        u_max: jax.Array | float,
        i_max: jax.Array | float,
    ) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
        """The current reference the speed loop's demand gets under field weakening (module doc, points 1–3).

        Args:
            est: The machine the controller assumes (:class:`~jaxobs.drive.PMSMParams`).
            id_policy: The policy's i_d for ``iq_cmd``, A.
            iq_cmd: The speed loop's q current under the policy, A.
            id_fw: Δi_d, A (≤ 0).
            omega_e: ω̂e, rad/s.
            u_max: The voltage limit, V.
            i_max: The current-vector limit, A.

        Returns:
            ``(i_d*, i_q*, capped, lo)``: the reference, A; whether a limit of point 3 cut i_q below the torque's
            (the torque the speed loop asked for is then not realised); the least Δi_d for :meth:`update`, A.
        """
        id_lo = id_stop(est, id_policy, i_max)
        # below the speed where every current within the circle (i_d ≤ 0) fits m u_max at steady state, field
        # weakening is never needed: the stop is the policy's i_d there (module doc, point 1)
        id_lo = jnp.where(jnp.abs(omega_e) < self.gate_speed(est, u_max, i_max), id_policy, id_lo)
        id_ref = jnp.maximum(id_policy + id_fw, id_lo)
        dl = est.Ld - est.Lq
        k_pol = est.psi_f + dl * id_policy
        k_ref = est.psi_f + dl * id_ref  # ≥ ψ̂f min(1, L̂q/L̂d) > 0 above the stop (module doc, point 2)
        weak = id_ref < id_policy
        iq_w = jnp.where(weak, iq_cmd * k_pol / jnp.where(weak, k_ref, 1.0), iq_cmd)
        room = jnp.minimum(self.limit_room(id_ref, i_max), mtpv_iq(est, id_ref))
        q_lo, q_hi = voltage_iq_range(est, id_ref, omega_e, u_max)
        iq_ref = jnp.clip(iq_w, jnp.maximum(-room, q_lo), jnp.minimum(room, q_hi))
        return id_ref, iq_ref, iq_ref != iq_w, id_lo - id_policy

    def path_slope(
        self,
        est: PMSMParams,
        id_policy: jax.Array,
        iq_cmd: jax.Array,
        id_fw: jax.Array,
        omega_e: jax.Array,
        u_max: jax.Array | float,
        i_max: jax.Array | float,
    ) -> jax.Array:
        """d|u|/dΔi_d (V/A): the slope of the steady voltage of :meth:`references`' current on ``est`` at ω̂e as
        Δi_d moves, i_q* moving with it (the torque kept, or the circle's room), for the ``bounded`` gain (module
        doc, "Bounded"); forward-mode derivative of the reference itself, 0 where a stop holds it.

        Args:
            est: The assumed machine.
            id_policy: The policy's i_d, A.
            iq_cmd: The speed loop's q current, A.
            id_fw: Δi_d, A.
            omega_e: ω̂e, rad/s.
            u_max: The voltage limit, V.
            i_max: The current-vector limit, A.

        Returns:
            The slope, V/A.
        """

        def volt(dfw):
            i_d, i_q = self.references(est, id_policy, iq_cmd, dfw, omega_e, u_max, i_max)[:2]
            return safe_norm2(
                est.Rs * i_d - omega_e * est.Lq * i_q, est.Rs * i_q + omega_e * (est.psi_f + est.Ld * i_d)
            )

        return jax.jvp(volt, (id_fw,), (jnp.ones_like(id_fw),))[1]

    def gate_speed(self, est: PMSMParams, u_max: jax.Array | float, i_max: jax.Array | float) -> jax.Array:
        """ω_gate = (m u_max − R̂s i_max) / √(ψ̂f² + (L̂q i_max)²), rad/s: below it no current within the circle with
        i_d ≤ 0 needs more than m u_max at steady state (its flux is at most that root), so field weakening is
        held at zero there (module doc, point 1); 0 where R̂s i_max ≥ m u_max.

        Args:
            est: The assumed machine.
            u_max: The voltage limit, V.
            i_max: The current-vector limit, A.

        Returns:
            ω_gate, rad/s (electrical).
        """
        psi_hi = jnp.sqrt(est.psi_f**2 + (est.Lq * i_max) ** 2)
        return jnp.maximum(self.margin * u_max - est.Rs * i_max, 0.0) / psi_hi

    @staticmethod
    def limit_room(id_ref: jax.Array | float, i_max: jax.Array | float) -> jax.Array:
        """√(i_max² − i_d*²): the q current the circle leaves, A (0 on and beyond the circle, with a finite
        gradient there: the root of a masked argument).

        Args:
            id_ref: The d current reference, A.
            i_max: The current limit, A.

        Returns:
            The room for i_q, A.
        """
        return _safe_sqrt(i_max * i_max - id_ref * id_ref)

    @staticmethod
    def limit_iq(iq_ref: jax.Array | float, id_ref: jax.Array | float, i_max: jax.Array | float) -> jax.Array:
        """i_q* within the current circle left by i_d*.

        Args:
            iq_ref: i_q*, A.
            id_ref: i_d*, A.
            i_max: The current-vector limit, A.

        Returns:
            The limited i_q*, A.
        """
        room = _safe_sqrt(i_max * i_max - id_ref * id_ref)
        return jnp.clip(iq_ref, -room, room)


def _safe_sqrt(x):
    """√x for x > 0, else 0, differentiable everywhere (√ of a masked argument: no inf·0 in the gradient)."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def id_stop(est: PMSMParams, id_policy: jax.Array | float, i_max: jax.Array | float) -> jax.Array:
    """i_d,lo = max(−i_max, min(−ψ̂f/L̂d, i_d,policy)): where field weakening stops (module doc, point 1), A.

    Args:
        est: The assumed machine.
        id_policy: The policy's i_d, A.
        i_max: The current-vector limit, A.

    Returns:
        i_d,lo, A.
    """
    return jnp.maximum(-i_max, jnp.minimum(-est.psi_f / est.Ld, id_policy))


def mtpv_iq(est: PMSMParams, id_ref: jax.Array | float) -> jax.Array:
    """The largest |i_q| (A) at ``id_ref`` on the MTPA side of the MTPV line (module doc, point 3): unbounded
    (inf) where L̂q ≥ L̂d (the stop at −ψ̂f/L̂d keeps i_d* on that side); √(ψd² + ψ̂f L̂q ψd/(L̂d − L̂q))/L̂q on an
    inverse-salient machine, 0 at ψd ≤ 0.

    Args:
        est: The assumed machine.
        id_ref: i_d*, A.

    Returns:
        The bound, A.
    """
    psi_d = est.psi_f + est.Ld * id_ref
    inverse = est.Ld > est.Lq
    gap = jnp.where(inverse, est.Ld - est.Lq, 1.0)
    q2 = psi_d * psi_d + est.psi_f * est.Lq * psi_d / gap
    bound = _safe_sqrt(q2) / est.Lq
    bound = jnp.where(psi_d > 0, bound, 0.0)
    return jnp.where(inverse, bound, jnp.inf)


def mtpv_iq_np(est: PMSMParams, i_d: np.ndarray) -> np.ndarray:
    """:func:`mtpv_iq` in NumPy on concrete values (a check's number: no XLA kernel compiled), A.

    Args:
        est: The assumed machine.
        i_d: The d currents, A.

    Returns:
        The bound at each ``i_d`` (inf where L̂q ≥ L̂d), A.
    """
    Ld, Lq, psi = float(est.Ld), float(est.Lq), float(est.psi_f)
    i_d = np.asarray(i_d, float)
    if Ld <= Lq:
        return np.full(i_d.shape, np.inf)
    psi_d = psi + Ld * i_d
    q2 = psi_d * psi_d + psi * Lq * psi_d / (Ld - Lq)
    return np.where(psi_d > 0, np.sqrt(np.maximum(q2, 0.0)) / Lq, 0.0)


def voltage_iq_range(
    est: PMSMParams, id_ref: jax.Array | float, omega_e: jax.Array | float, u_lim: jax.Array | float
) -> tuple[jax.Array, jax.Array]:
    """The q currents (A) whose steady voltage at ``id_ref`` and ω̂e stays within ``u_lim``: the interval where
    (R̂s i_d − ω̂e L̂q i_q)² + (R̂s i_q + ω̂e (ψ̂f + L̂d i_d))² ≤ u_lim² (module doc, point 3).  Where no i_q fits
    (even i_q = 0 needs more), the least-voltage i_q alone; unbounded at standstill without resistance.

    Args:
        est: The assumed machine.
        id_ref: i_d*, A.
        omega_e: ω̂e, rad/s.
        u_lim: The voltage limit, V.

    Returns:
        ``(low, high)``, A.
    """
    psi_d = est.psi_f + est.Ld * id_ref
    a = est.Rs * est.Rs + (omega_e * est.Lq) ** 2
    b = 2.0 * est.Rs * omega_e * (psi_d - est.Lq * id_ref)
    c = (est.Rs * id_ref) ** 2 + (omega_e * psi_d) ** 2 - u_lim * u_lim
    ok = a > 1e-30
    a_s = jnp.where(ok, a, 1.0)
    disc = b * b - 4.0 * a_s * c
    root = _safe_sqrt(disc)
    centre = -b / (2.0 * a_s)
    half = root / (2.0 * a_s)
    lo = jnp.where(ok, centre - half, -jnp.inf)
    hi = jnp.where(ok, centre + half, jnp.inf)
    return lo, hi


def capability_torque(
    est: PMSMParams, omega_e: float, u_max: float, i_max: float, margin: float = FW_MARGIN, n: int = 4001
) -> tuple[float, float, float]:
    """The steady torque (N·m) the field-weakened reference can hold at ω_e on ``est``: the largest torque of
    (i_d, i_q) with i_d from the policy-free range [i_d,lo, 0] (i_d,lo at its stop, :func:`id_stop` with
    i_d,policy = 0) and i_q within the circle, MTPV and the steady voltage ``margin`` × u_max (the Δi_d loop's
    target), on a grid of ``n`` d currents (NumPy: a check's number, not traced); one speed of
    :func:`capability_curve` on the constant inductances.

    Args:
        est: The machine (:class:`~jaxobs.drive.PMSMParams`).
        omega_e: The electrical speed, rad/s.
        u_max: The voltage limit, V.
        i_max: The current limit, A.
        margin: The fraction of u_max the steady voltage may use.
        n: Grid points.

    Returns:
        ``(torque, i_d, i_q)`` at the best point (N·m, A, A).
    """
    te, i_d, i_q, _ = _constant_curve(est, np.asarray([omega_e], float), u_max, i_max, margin, n)
    return float(te[0]), float(i_d[0]), float(i_q[0])


def capability_curve(
    machine: PMSMParams,
    omega_e: np.ndarray,
    u_max: float,
    i_max: float,
    margin: float = FW_MARGIN,
    n: int = 4001,
    *,
    weakening: bool = True,
    id_mode: str = "zero",
) -> dict[str, np.ndarray]:
    """The torque–speed capability of a drive whose FOC runs this module's reference on ``machine``: at each
    electrical speed the largest steady torque of a current the reference may ask for whose steady voltage is at
    most ``margin`` × u_max (the Δi_d loop's target, module doc; without field weakening the same margin, the
    room the current PIs need to regulate).  All speeds at once (NumPy broadcasting over speed × currents, no
    loop per speed).

    The currents the reference may ask for: with field weakening, i_d in [i_d,lo, 0] with i_d,lo = max(−i_max,
    −ψ̂f/L̂d) (:func:`id_stop`), |i| ≤ i_max and, on an inverse-salient machine, within :func:`mtpv_iq`;
    without it, the policy's i_d for each i_q (zero or MTPA, ``id_mode``) within the circle.

    The voltage and the torque are the plant's: with the constant inductances L̂d, L̂q, ψ̂f where ``machine`` has
    no saturation map (with field weakening i_q on the voltage bound in closed form, :func:`voltage_iq_range`,
    over ``n`` d currents; without it ``n`` q currents); with the map's flux ψ(i) where it has one
    (``machine.sat``: 241 × 241 currents with field weakening, ``n`` q currents without; every point is a feasible
    current, so the grid's best is a lower bound of the true maximum, within one grid step).  A q-axis
    saturation (``machine.q_sat``) is not applied: the curve is the unsaturated one.  Where no current fits the
    voltage (the flux alone needs more), the torque is NaN.

    Args:
        machine: The machine (its ``Ld``, ``Lq``, ``psi_f`` are the controller's constants; ``sat`` the plant's
            map, or None).
        omega_e: The electrical speeds, rad/s (any shape; ≥ 0).
        u_max: The voltage limit, V (the FOC's: u_dc/√3).
        i_max: The current limit, A.
        margin: The fraction of u_max the steady voltage may use.
        n: Grid points (constant inductances; the map without field weakening).
        weakening: Whether the FOC weakens the field (:class:`VoltageFeedbackFW`).
        id_mode: The FOC's i_d policy, ``"zero"`` or ``"mtpa"`` (used without field weakening).

    Returns:
        ``torque`` (N·m), ``i_d``, ``i_q`` (A) and ``u`` (the steady |u| there, V), each shaped as ``omega_e``.
    """
    w = np.asarray(omega_e, float)
    flat = w.reshape(-1)
    if weakening and machine.sat is None:
        te, i_d, i_q, u = _constant_curve(machine, flat, u_max, i_max, margin, n)
    elif weakening:  # the map: a grid over the currents field weakening may ask for, refined
        te, i_d, i_q, u = _map_weakening_curve(machine, flat, u_max, i_max, margin)
    else:  # the policy's currents
        i_q = np.linspace(0.0, float(i_max), int(n))
        i_d = _policy_id_np(machine, id_mode, i_q)
        keep = i_d * i_d + i_q * i_q <= float(i_max) ** 2 * (1 + 1e-12)
        te, i_d, i_q, u = _points_curve(machine, flat, u_max, margin, i_d[keep], i_q[keep])
    return {k: v.reshape(w.shape) for k, v in (("torque", te), ("i_d", i_d), ("i_q", i_q), ("u", u))}


def _policy_id_np(est: PMSMParams, id_mode: str, i_q: np.ndarray) -> np.ndarray:
    """The policy's i_d for each i_q (NumPy; the FOC's ``policy_id``: zero, or MTPA on the constants)."""
    dl = float(est.Lq) - float(est.Ld)
    if id_mode != "mtpa" or abs(dl) <= 1e-12:
        return np.zeros_like(i_q)
    a = float(est.psi_f) / (2 * dl)
    return a - np.sign(dl) * np.sqrt(a * a + i_q * i_q)


def _constant_curve(est, w, u_max, i_max, margin, n):
    """:func:`capability_curve` on constant inductances: (torque, i_d, i_q, |u|) per speed of the 1-d ``w``."""
    Ld, Lq, psi, Rs, p = float(est.Ld), float(est.Lq), float(est.psi_f), float(est.Rs), est.p
    i_max = float(i_max)
    i_d = np.linspace(max(-i_max, -psi / Ld), 0.0, int(n))[None, :]  # (1, n) against the speeds (k, 1)
    wk = w[:, None]
    psi_d = psi + Ld * i_d
    a = Rs * Rs + (wk * Lq) ** 2
    b = 2.0 * Rs * wk * (psi_d - Lq * i_d)
    c = (Rs * i_d) ** 2 + (wk * psi_d) ** 2 - (margin * u_max) ** 2
    disc = b * b - 4.0 * a * c
    a_s = np.where(a > 0, a, 1.0)
    root = np.sqrt(np.maximum(disc, 0.0))
    hi = np.where(a > 0, (-b + root) / (2.0 * a_s), np.inf)  # standstill without resistance: no voltage bound
    lo = np.where(a > 0, (-b - root) / (2.0 * a_s), -np.inf)
    room = np.sqrt(np.maximum(i_max**2 - i_d * i_d, 0.0))
    room = np.minimum(room, mtpv_iq_np(est, i_d))
    i_q = np.clip(hi, 0.0, room)
    fits = ((a == 0) | (disc >= 0)) & (i_q >= lo)  # some i_q ≥ 0 within the limits meets the voltage
    torque = np.where(fits, 1.5 * p * (psi + (Ld - Lq) * i_d) * i_q, -np.inf)
    k = np.argmax(torque, axis=1)
    rows = np.arange(len(w))
    idb, iqb = np.broadcast_to(i_d, torque.shape)[rows, k], i_q[rows, k]
    u = np.hypot(Rs * idb - w * Lq * iqb, Rs * iqb + w * (psi + Ld * idb))
    best = torque[rows, k]
    return np.where(np.isfinite(best), best, np.nan), idb, iqb, u


@eqx.filter_jit
def _map_flux(sat, i_d, i_q):
    return sat.flux(i_d, i_q)


def map_speed_flux(machine: PMSMParams, i_max: float, weakening: bool, n: int = 201) -> float | None:
    """The flux (Vs) a drive's no-load speed bound turns into voltage on ``machine``'s saturation map: the least
    |ψ(i_d, 0)| of the map over the d currents the FOC may ask for at no load, i_d in [i_d,lo, 0] with field
    weakening (i_d,lo = max(−i_max, −ψ̂f/L̂d), the FOC's stop: :func:`id_stop`), i_d = 0 without; ``n`` points (the
    map's flux is monotonic along i_d, so the grid's least is the stop's, or 0 where ψd crosses zero).  None
    without a map (the rule is then the constants', ψf − Ld i_max: :func:`jaxobs.drive.drivefile.speed_limit`).

    Args:
        machine: The machine (its ``sat`` the map, its ``psi_f`` and ``Ld`` the controller's constants).
        i_max: The current limit, A.
        weakening: Whether the FOC weakens the field.
        n: Grid points.

    Returns:
        The flux, Vs, or None.
    """
    if machine.sat is None:
        return None
    lo = max(-float(i_max), min(-float(machine.psi_f) / float(machine.Ld), 0.0)) if weakening else 0.0
    i_d = np.linspace(lo, 0.0, int(n))
    pd, pq = (np.asarray(v, float) for v in _map_flux(machine.sat, jnp.asarray(i_d), jnp.asarray(np.zeros_like(i_d))))
    return float(np.min(np.hypot(pd, pq)))


def map_flux_at(machine: PMSMParams, i_d: float, i_q: float) -> tuple[float, float] | None:
    """(ψd, ψq) (Vs) of ``machine``'s saturation map at one current, or None without a map (a check's number).

    Args:
        machine: The machine.
        i_d: The d current, A.
        i_q: The q current, A.

    Returns:
        ``(ψd, ψq)``, Vs, or None.
    """
    if machine.sat is None:
        return None
    pd, pq = _map_flux(machine.sat, jnp.asarray(np.array([i_d], float)), jnp.asarray(np.array([i_q], float)))
    return float(np.asarray(pd)[0]), float(np.asarray(pq)[0])


def _points_curve(machine, w, u_max, margin, i_d, i_q, flux=None):
    """The best of the candidate currents at each speed of the 1-d ``w``: (torque, i_d, i_q, |u|); ``i_d``, ``i_q``
    1-d (the same candidates at every speed) or (speeds, candidates); the flux the map's where ``machine`` has
    one (or ``flux``, its (ψd, ψq) there), else the constants'."""
    if flux is not None:
        pd, pq = flux
    elif machine.sat is None:
        pd = float(machine.psi_f) + float(machine.Ld) * i_d
        pq = float(machine.Lq) * i_q
    else:
        flux = _map_flux(machine.sat, jnp.asarray(i_d.reshape(-1)), jnp.asarray(i_q.reshape(-1)))
        pd, pq = (np.asarray(v).reshape(i_d.shape) for v in flux)
    Rs = float(machine.Rs)
    torque = np.broadcast_to(1.5 * machine.p * (pd * i_q - pq * i_d), (len(w), i_d.shape[-1]))
    wk = w[:, None]
    u = np.hypot(Rs * i_d - wk * pq, Rs * i_q + wk * pd)  # (speeds, currents)
    fits = u <= margin * u_max
    k = np.argmax(np.where(fits, torque, -np.inf), axis=1)
    rows = np.arange(len(w))
    te = np.where(fits[rows, k], torque[rows, k], np.nan)
    pick = (lambda x: x[rows, k]) if i_d.ndim == 2 else (lambda x: x[k])
    return te, pick(i_d), pick(i_q), u[rows, k]


def _map_weakening_curve(machine, w, u_max, i_max, margin, n=241, block=32):
    """:func:`capability_curve` on the map with field weakening: ``n`` d currents in [i_d,lo, 0] × ``n`` q currents
    from 0 to the room the circle (and the assumed machine's MTPV line) leaves, spaced as s² (fine where the
    high speeds' small q currents lie, the circle itself included); the map's flux once for all of them (it does
    not depend on the speed), then the voltage at ``block`` speeds at a time (memory, not a loop per speed)."""
    i_max = float(i_max)
    i_d = np.linspace(float(id_stop(machine, 0.0, i_max)), 0.0, n)
    room = np.sqrt(np.maximum(i_max * i_max - i_d * i_d, 0.0))
    if float(machine.Ld) > float(machine.Lq):  # the reference's MTPV bound is the assumed machine's
        room = np.minimum(room, mtpv_iq_np(machine, i_d))
    gd, gq = np.meshgrid(i_d, np.linspace(0.0, 1.0, n) ** 2)
    gd, gq = gd.reshape(-1), (gq * room[None, :]).reshape(-1)
    pd, pq = (np.asarray(v) for v in _map_flux(machine.sat, jnp.asarray(gd), jnp.asarray(gq)))
    parts = [_points_curve(machine, w[k : k + block], u_max, margin, gd, gq, (pd, pq)) for k in range(0, len(w), block)]
    return tuple(np.concatenate(x) for x in zip(*parts))
