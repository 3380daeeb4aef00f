"""Carrier-comparison PWM of a two-level inverter: the switching instants of one carrier period and the
voltage of each sub-interval between them (:class:`~jaxobs.drive.PMSM` integrates them when its inverter's
``pwm`` is ``"carrier"``).

The carrier is symmetric (centre-aligned) and triangular, one period per control period (single update: the
duty cycles load at the period's start, at the carrier's peak).  Normalised to ±1 it falls from +1 at t = 0 to
−1 at T/2 and rises back to +1 at T.  Each phase's reference is the commanded α-β voltage taken to the phases
with min-max zero-sequence injection, v_x* = v_x − (max + min)/2 (the carrier-based equivalent of space-vector
modulation: its linear range is the inverter's circle |u| ≤ U_dc/√3); its modulation index m_x = v_x*/(U_dc/2)
is clipped to [−1, 1].  The upper switch of phase x is on while m_x > carrier: from r_x = (1 − m_x) T/4 to
f_x = T − r_x.  Each period thus starts and ends in the zero vector 000, and its middle is the zero vector 111:
the period's start (the carrier's peak) is the centre of a zero vector, where the current ripple crosses its
mean, the instant the drive samples (:class:`~jaxobs.drive.PeriodStart`, the only sampling carrier PWM takes).

Dead time T_d: both switches of a leg are off for T_d after each commanded edge, and the phase current's
freewheeling diode sets the leg.  With i_x > 0 (out of the leg) the lower diode conducts, so the rising edge
comes T_d late and the falling edge on time; with i_x < 0 the rising edge is on time and the falling edge comes
T_d late.  So the rising edge moves by T_d (1 + s)/2 and the falling edge by T_d (1 − s)/2, s = sgn(i_x) (or
tanh(i_x/i_smooth), :class:`~jaxobs.drive.Inverter`): the pulse shrinks by s T_d, the averaged model's
Δu_x = −U_dc T_d f_pwm sgn(i_x) (:meth:`Inverter.dead_time_error`).  A leg that does not switch (|m_x| = 1)
has no dead time.  DECISION: the sign is the phase current's at the period's start (the sample instant);
near a zero crossing the ripple can change the sign within the period, which this ignores (it moves at most
T_d of one edge, the averaged model's error of one period).  Edges shifted past the period's end are clipped
to it (motulator carries them into the next period; the difference is at most T_d of a pulse at |m_x| near 1).
Device drops: the conducting switch or diode lowers the leg's voltage by u_device in the current's direction,
v_x = U_dc (S_x − ½) − u_device s_x, s_x the same sign.

The six edges sorted give :data:`N_INTERVALS` = 7 sub-intervals (some of zero length), a fixed count, so a
period is a fixed sequence of steps (``lax.scan``- and ``vmap``-friendly).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .hardware import ab_to_abc, clarke_abc_to_ab

__all__ = ["N_INTERVALS", "carrier_intervals", "modulation_indices", "switching_instants"]

N_INTERVALS = 7  # sub-intervals per carrier period: three legs, two edges each, sorted


def modulation_indices(u_a: jax.Array | float, u_b: jax.Array | float, udc: jax.Array | float) -> jax.Array:
    """The phases' modulation indices under min-max zero-sequence injection.

    Args:
        u_a: The commanded u_α, V.
        u_b: The commanded u_β, V.
        udc: The dc-link voltage, V.

    Returns:
        ``m``, shape (..., 3): m_x = v_x*/(U_dc/2) clipped to [−1, 1], v_x* = v_x − (max + min)/2.
    """
    v = jnp.stack(ab_to_abc(u_a, u_b), axis=-1)
    v0 = 0.5 * (jnp.max(v, axis=-1, keepdims=True) + jnp.min(v, axis=-1, keepdims=True))
    return jnp.clip((v - v0) / (0.5 * jnp.asarray(udc)[..., None]), -1.0, 1.0)


def switching_instants(
    m: jax.Array, period: jax.Array | float, dead_time: jax.Array | float, s: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """Each phase's rising and falling edge within one carrier period, dead time included.

    Args:
        m: The modulation indices, shape (3,) (:func:`modulation_indices`).
        period: The carrier period T, s.
        dead_time: T_d, s.
        s: The phase currents' signs (or their smoothed signs) in [−1, 1], shape (3,).

    Returns:
        ``(rise, fall)``, each shape (3,), s from the period's start, within [0, T].
    """
    r = 0.25 * (1.0 - m) * period
    switches = (m > -1.0) & (m < 1.0)  # a leg held at one rail does not switch: no dead time
    td = jnp.where(switches, dead_time, 0.0)
    rise = r + 0.5 * td * (1.0 + s)
    fall = period - r + 0.5 * td * (1.0 - s)
    rise = jnp.clip(rise, 0.0, period)
    fall = jnp.clip(jnp.maximum(fall, rise), 0.0, period)  # a pulse shorter than T_d vanishes
    return rise, fall


# a sorting network for six values (12 compare-exchanges, Knuth TAOCP 5.3.4): XLA's sort op under vmap on CPU
# calls a comparator per element and cost more than the seven RK4 steps it orders
_NETWORK6 = ((1, 2), (4, 5), (0, 2), (3, 5), (0, 1), (3, 4), (1, 4), (0, 3), (2, 5), (1, 3), (2, 4), (2, 3))


def _sorted6(v):
    v = list(v)
    for i, j in _NETWORK6:
        v[i], v[j] = jnp.minimum(v[i], v[j]), jnp.maximum(v[i], v[j])
    return v


def carrier_intervals(
    udc: jax.Array | float,
    period: jax.Array | float,
    dead_time: jax.Array | float,
    u_device: jax.Array | float,
    u_a: jax.Array | float,
    u_b: jax.Array | float,
    s: jax.Array,
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The sub-intervals of one carrier period and the stationary-frame voltage over each.

    Args:
        udc: The dc-link voltage, V.
        period: The carrier period T, s.
        dead_time: T_d, s.
        u_device: The device drop, V.
        u_a: The commanded u_α (already within the inverter's limit), V.
        u_b: The commanded u_β, V.
        s: The phase currents' signs (or smoothed signs), shape (3,).

    Returns:
        ``(h, v_a, v_b)``, each shape (7,): the sub-intervals' lengths (s, summing to T) and the voltage
        (u_α, u_β) the legs apply over each, V.
    """
    h, v_a, v_b = _switched(udc, period, dead_time, u_device, u_a, u_b, s)
    # Divided by one (1 + 0·h, which XLA does not fold; the same device as jaxobs.core.trig's sincos): XLA's
    # fusion counts a division as expensive and does not copy it, with everything it reads, into each consumer.
    # Without it XLA's CPU backend copied this whole function (the modulation indices, the edges, the sorting
    # network, the switch states) into every RK4 stage of the period, 28 kernels with n_sub = 1, 56 with 2, each
    # emitted once per state component: where every scenario of a batch has its own voltage (a closed loop),
    # the lab drive's carrier loop ran at 0.090 of the averaged one's rate, 0.242 with it (benchmarks/README.md,
    # "Carrier PWM: cost and ripple").  x / 1 is x exactly.
    one = 1.0 + 0.0 * h
    return h / one, v_a / one, v_b / one


def _switched(udc, period, dead_time, u_device, u_a, u_b, s):
    """:func:`carrier_intervals` without its division by one (benchmarks/pwm_carrier.py times both)."""
    m = modulation_indices(u_a, u_b, udc)
    rise, fall = switching_instants(m, period, dead_time, s)
    edges = _sorted6([rise[0], rise[1], rise[2], fall[0], fall[1], fall[2]])
    zero = jnp.zeros((1,), rise.dtype)
    bounds = jnp.concatenate([zero, jnp.stack(edges), zero + period])
    h = jnp.diff(bounds)
    mid = 0.5 * (bounds[:-1] + bounds[1:])
    on = (rise[None, :] <= mid[:, None]) & (mid[:, None] < fall[None, :])  # (7, 3): upper switch on
    pole = udc * (on.astype(h.dtype) - 0.5) - u_device * s[None, :]
    v_a, v_b = clarke_abc_to_ab(pole[:, 0], pole[:, 1], pole[:, 2])
    return h, v_a, v_b
