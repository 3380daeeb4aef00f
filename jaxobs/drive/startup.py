"""I-f start-up from standstill: the current vector turned open loop up to a switch speed, then handed over to
the position the controller is given (:class:`~jaxobs.drive.FOC` runs it, :class:`IfStartup` holds its settings).

The design and its reasons:

1. *Parked start.*  The current vector of amplitude I_f is held along θ_f + 90°,
   and θ_f starts at θ_e0 − 90°: the rotor starts on its no-load equilibrium (its
   d axis on the current vector).  A real drive gets there by a d-axis alignment
   (pre-positioning) phase, which friction and eddy currents settle; the model
   has almost no damping (B ≈ 0), so we start where that phase ends.  Started
   90° off instead (θ_f = 0 with the rotor at 0) the rotor swung
   ±90° for the whole start-up (−41 … 126 r/min around a 0 … 60 r/min ramp on the
   IPMSM bench) and no observer could be handed a rotor moving like that.
2. *Smooth ramp.*  The rotor follows θ_f through the torque-angle "spring"
   T = K_t I_f cos(θ_f − θ), which is undamped (natural frequency
   √(p K_t I_f/J), 5–12 Hz on the benches).  A linear frequency ramp steps the
   acceleration at its start and end and excites that swing; the default
   raised-cosine ramp ω_f = ω_sw (τ − sin 2πτ/2π), τ = t/T_r, T_r = ω_sw/accel,
   has a continuous acceleration (peak 2× the mean ``accel``) and leaves it
   nearly at rest.
3. *Hold and agreement.*  At ω_switch the drive waits at least ``hold`` seconds
   (the observer converges: the flux observers' SOGIs have a bandwidth ∝ ω̂) and
   then until the position and speed it is given *agree* with the I-f frame for
   ``dwell`` seconds: |ω̂ − ω_f| ≤ speed_tol·ω_f, and the offset Δ = θ_f − θ̂ (the
   load angle when θ̂ = θ) steady, |Δ − Δ̄| ≤ tol with Δ̄ its low-pass over
   ``dwell``.  An observer that never agrees keeps the drive in I-f (synchronous,
   open loop): a fail-safe, visible as ``mode`` staying 0.  (With the speed
   seeding of ClosedLoop the speed test holds by construction and the angle test
   decides: an unconverged flux estimate wanders against θ_f.)  Forward rotation
   only: ω_switch > 0.
4. *Bumpless hand-over.*  At the switch the controller moves to the given frame
   θ̂ with nothing stepping: the current references continue the I-f vector seen
   from θ̂ (i_q = I_f cos Δ, i_d = −I_f sin Δ); the speed integrator is pre-loaded
   so that the I-P output k_pω(b ω* − ω̂) + ∫ equals I_f cos Δ (without the
   k_pω ω̂ term the switch would step i_q by −k_pω ω̂: −5.8 A on the
   IPMSM bench at 60 r/min); the current PIs' integrators are rotated into θ̂
   with their decoupling terms, so the voltage vector is continuous; the held
   i_q* until the next speed-loop sample is I_f cos Δ, not I_f.
5. *Blend.*  Over ``blend`` seconds after the switch the d-current reference
   goes linearly from −I_f sin Δ (up to I_f at no load: the I-f vector
   magnetizes) to the controller's i_d policy; the speed loop then carries the
   torque on the estimated q axis alone.

:class:`~jaxobs.drive.ClosedLoop` also holds the observer's speed estimate at
the I-f frequency while the I-f runs (``seed_speed``), see there.
"""

from __future__ import annotations

import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import papers
from ..core.validate import check_nonnegative, check_positive, check_real
from .machine import RPM, PMSMParams

__all__ = ["IfStartup"]


class IfStartup(eqx.Module):
    """I-f start-up from standstill, then a hand-over to the given position (module doc, steps 1–5).

    :meth:`for_machine` gives the defaults we use for a machine (``jaxobs.papers``, IF_*).

    Args:
        i_f: The current amplitude during start-up, A (> 0).
        accel: The mean ramp rate of the electrical frequency, rad/s² (> 0).
        omega_switch: The electrical speed at which control switches to the given position, rad/s (> 0).
        hold: The least time spent at ``omega_switch`` before switching (lets an observer converge), s.
        blend: After the switch, the time over which the d-current goes from the I-f vector's to the i_d
            policy, s.
        tol: Agreement: |Δ − Δ̄| of the offset Δ = θ_f − θ̂ (the load angle), rad (in (0, 3.15]).
        speed_tol: Agreement: |ω̂ − ω_f| / ω_f (> 0).
        dwell: The time agreement must hold (and Δ̄ is Δ low-passed over it), s (> 0).
        smooth: A raised-cosine ramp (continuous acceleration); False: linear.

    Raises:
        ValueError: A value out of its range, naming the field.
    """

    i_f: jax.Array  # current amplitude during start-up, A (> 0)
    accel: jax.Array  # mean ramp rate of the electrical frequency, rad/s² (> 0)
    omega_switch: jax.Array  # electrical speed at which control switches to the given position, rad/s
    hold: jax.Array  # least time spent at omega_switch before switching (lets an observer converge), s
    blend: jax.Array  # after the switch: the d-current goes from the I-f vector's to the i_d policy, s
    tol: jax.Array  # agreement: |Δ − Δ̄| of the offset Δ = θ_f − θ̂ (the load angle), rad
    speed_tol: jax.Array  # agreement: |ω̂ − ω_f| / ω_f
    dwell: jax.Array  # agreement must hold this long (and Δ̄ is Δ low-passed over it), s (> 0)
    smooth: bool = eqx.field(static=True)  # raised-cosine ramp (continuous acceleration); False: linear

    def __init__(
        self,
        i_f: jax.Array | float,
        accel: jax.Array | float,
        omega_switch: jax.Array | float,
        hold: jax.Array | float = 0.0,
        *,
        blend: jax.Array | float = 0.05,
        tol: jax.Array | float = 0.2,
        speed_tol: jax.Array | float = 0.1,
        dwell: jax.Array | float = 0.02,
        smooth: bool = True,
    ) -> None:
        own = "IfStartup"
        self.i_f = check_positive("i_f", i_f, own)
        self.accel = check_positive("accel", accel, own)
        self.omega_switch = check_positive("omega_switch", omega_switch, own)
        self.hold = check_nonnegative("hold", hold, own)
        self.blend = check_nonnegative("blend", blend, own)
        self.tol = check_real("tol", tol, lower=0.0, upper=3.15, owner=own)
        self.speed_tol = check_positive("speed_tol", speed_tol, own)
        self.dwell = check_positive("dwell", dwell, own)
        self.smooth = bool(smooth)

    @classmethod
    def for_machine(
        cls, par: PMSMParams, *, rpm_switch: float | None = None, i_f: float | None = None, **kw: Any
    ) -> IfStartup:
        """The start-up we design for ``par`` (the machine the controller assumes), ASSUMED rules of thumb.

        - I_f = papers.IF_CURRENT_PU × the rated current: enough torque to accelerate and to carry a
          light load, small enough not to heat or saturate (I-f runs at a load angle near 90° at no load);
        - switch at papers.IF_SWITCH_PU × rated speed (``rpm_switch`` to override), where every observer
          here has converged within the hold and a sensorless speed loop at α_s = 2π·5 rad/s is stable
          through it (the flux observers cannot start at 0 Hz: 000 Sec. IV; see below);
        - mean acceleration such that the ramp's *peak* torque (2× the mean for the raised cosine) is
          papers.IF_ACCEL_TORQUE_PU of K_t I_f, the rest being margin for load and swing; and slower still
          if that ramp would last less than papers.IF_RAMP_SWING_PERIODS periods of the undamped swing
          2π/√(p K_t I_f/J): a raised cosine as short as one period still rings (measured: ±25 % of the
          switch speed on the SPMSM bench, ramp 0.11 s, swing period 84 ms);
        - hold papers.IF_HOLD s at the switch speed.

        A sensorless speed loop closed through a frequency-normalized FLL (SOIFO types: natural frequency
        ≈ ω̂e/2) needs the switch speed high enough that the FLL is faster than the speed loop: we measured
        a limit cycle (230–610 r/min) with α_s = 2π·5 rad/s after a switch at 200 r/min (10 %) on the SPMSM
        bench, and ±1 % at 400 r/min (ω_e,sw ≥ 4 α_s).  Through a LESO's 15 Hz PLL the loop rang ±11 % at
        60 r/min (10 %) on the IPMSM bench and ±3 % at 120 r/min.  Hence 20 % by default.

        Args:
            par: The machine the controller assumes.
            rpm_switch: The switch speed, r/min (default papers.IF_SWITCH_PU × rated speed).
            i_f: The start-up current, A (default papers.IF_CURRENT_PU × the rated current).
            **kw: Other :class:`IfStartup` keywords.

        Returns:
            The :class:`IfStartup`.
        """
        p = par.p
        # PMSMParams.kt and .i_rated in NumPy, the same float operations (no XLA kernel compiled for them)
        kt_arr = 1.5 * p * np.asarray(par.psi_f)
        i_rated, kt, J = float(np.asarray(par.T_rated) / kt_arr), float(kt_arr), float(par.J)
        i_f = papers.IF_CURRENT_PU * i_rated if i_f is None else float(i_f)
        rpm = papers.IF_SWITCH_PU * float(par.n_rated) if rpm_switch is None else float(rpm_switch)
        accel_m = papers.IF_ACCEL_TORQUE_PU * kt * i_f / (2 * J)  # mean mechanical, rad/s²
        swing_period = 2 * math.pi / math.sqrt(p * kt * i_f / J)
        accel_m = min(accel_m, rpm * RPM / (papers.IF_RAMP_SWING_PERIODS * swing_period))
        kw.setdefault("hold", papers.IF_HOLD)
        return cls(i_f, p * accel_m, p * rpm * RPM, **kw)

    def ramp(self, t: jax.Array | float) -> jax.Array:
        """The I-f electrical frequency.

        Args:
            t: The time from the start, s.

        Returns:
            The frequency, rad/s.
        """
        tau = jnp.clip(t * self.accel / self.omega_switch, 0.0, 1.0)
        if self.smooth:
            tau = tau - jnp.sin(2 * jnp.pi * tau) / (2 * jnp.pi)
        return self.omega_switch * tau
