"""Voltage-feedback field weakening for the FOC (:class:`VoltageFeedbackFW`, ``FOC(field_weakening=...)``).

The standard closed-loop scheme (Kim & Sul, IEEE Trans. Ind. Appl. 33(1), 1997; the same structure as 002's
ref. [32], Hu et al. 2021, which adds the xy subspace of a dual three-phase machine): an integrator adds a
negative d-current Δi_d when the current PIs' voltage reference |u*| exceeds a margin m of the inverter's
limit u_max, and gives it back when |u*| falls below it,

    dΔi_d/dt = α_fw (m u_max − |u*|) / (L̂d max(|ω̂e|, ω_min)),   −i_max ≤ Δi_d ≤ 0,

so i_d* = i_d,policy + Δi_d, and the q-current is limited to the rest of the current circle,
|i_q*| ≤ √(i_max² − i_d*²).  Above base speed |u*| ≈ |ω̂e| (ψ̂f + L̂d i_d), whose slope in i_d is ω̂e L̂d:
dividing by it makes the loop from Δi_d to |u*| a first-order loop of bandwidth α_fw at every speed
(ω_min only bounds the gain near standstill, where the scheme never acts).  The margin m < 1 leaves the
current PIs room to regulate.  It is off by default (``field_weakening=None``: i_d* is the policy's, 0 or MTPA).

|u*| is the current PIs' reference before the controller's own limit, available at the end of a period, so
Δi_d acts from the next period on (a one-period lag, negligible against 1/α_fw).  A steady start above base
speed starts at this loop's equilibrium, |u*| = m u_max (:meth:`jaxobs.drive.FOC.operating_point` solves
Δi_d with the torque balance; :meth:`jaxobs.drive.FOC.init` starts the integrator there).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .._validate import check_positive, check_real

__all__ = ["VoltageFeedbackFW"]


class VoltageFeedbackFW(eqx.Module):
    """Voltage-feedback field weakening (module doc).

    Args:
        alpha_fw: The bandwidth of the Δi_d loop, rad/s (> 0).
        margin: m, the fraction of u_max the voltage reference is held below, in (0, 1].
        omega_min: The electrical speed floor of the gain's ω̂e, rad/s (> 0).

    Raises:
        ValueError: A value out of its range, naming the field.
    """

    alpha_fw: jax.Array  # bandwidth of the Δi_d loop, rad/s (> 0)
    margin: jax.Array  # m: the fraction of u_max the voltage reference is held below, in (0, 1]
    omega_min: jax.Array  # electrical speed floor of the gain's ω̂e, rad/s (> 0)

    def __init__(self, alpha_fw=2 * jnp.pi * 20.0, margin=0.95, omega_min=10.0):
        own = "VoltageFeedbackFW"
        self.alpha_fw = check_positive("alpha_fw", alpha_fw, own)
        self.margin = check_real("margin", margin, lower=0.0, upper=1.0, owner=own)
        self.omega_min = check_positive("omega_min", omega_min, own)

    def update(self, id_fw, u_ref_mag, u_max, omega_e, Ld, i_max, ts):
        """Δi_d for the next period from this period's |u*| and ω̂e.

        Args:
            id_fw: This period's Δi_d, A.
            u_ref_mag: |u*|, V.
            u_max: The voltage limit, V.
            omega_e: ω̂e, rad/s.
            Ld: The assumed d-axis inductance, H.
            i_max: The current-vector limit, A.
            ts: The control period, s.

        Returns:
            Δi_d, A, in [−i_max, 0].
        """
        gain = self.alpha_fw / (Ld * jnp.maximum(jnp.abs(omega_e), self.omega_min))
        return jnp.clip(id_fw + gain * (self.margin * u_max - u_ref_mag) * ts, -i_max, 0.0)

    @staticmethod
    def limit_iq(iq_ref, id_ref, i_max):
        """i_q* within the current circle left by i_d*.

        Args:
            iq_ref: i_q*, A.
            id_ref: i_d*, A.
            i_max: The current-vector limit, A.

        Returns:
            The limited i_q*, A.
        """
        room = jnp.sqrt(jnp.maximum(i_max * i_max - id_ref * id_ref, 0.0))
        return jnp.clip(iq_ref, -room, room)
