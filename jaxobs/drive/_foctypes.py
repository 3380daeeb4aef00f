"""The FOC's interface: its state between periods, what it is given and what it gives each period, and the I-f
start-up's part of a period (:class:`~jaxobs.drive.FOC`)."""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax

__all__ = ["ControllerState", "FOCInput", "FOCOutput", "IfPhase"]


class ControllerState(eqx.Module):
    """The FOC's state between two periods.

    Attributes:
        int_d: The d current-PI integrator, V.
        int_q: The q current-PI integrator, V.
        int_w: The speed-PI integrator, A.
        iq_ref: The speed loop's output held between its samples, A.
        theta_f: The I-f angle, rad.
        omega_f: The I-f electrical frequency, rad/s.
        t_at_switch: The time spent at the switch-over frequency, s.
        mode: 0: I-f start-up, 1: closed loop on the given position.
        d_lp: I-f: the offset θ_f − θ̂ low-passed over the dwell, rad.
        t_agree: I-f: how long the given position has agreed with the I-f frame, s.
        t_closed: The time since the switch, s.
        id_hand: The d-current at the switch (in the given frame), A.
        id_fw: Field weakening's Δi_d (≤ 0; 0 without field weakening), A.
        kp_w: The speed loop's k_pω at its last sample (a scheduled gain's bumpless change), A/(rad/s).
    """

    int_d: jax.Array  # current-PI integrators, V
    int_q: jax.Array
    int_w: jax.Array  # speed-PI integrator, A
    iq_ref: jax.Array  # speed-loop output held between its samples, A
    theta_f: jax.Array  # I-f angle, rad
    omega_f: jax.Array  # I-f electrical frequency, rad/s
    t_at_switch: jax.Array  # time spent at the switch-over frequency, s
    mode: jax.Array  # 0: I-f start-up, 1: closed loop on the given position
    d_lp: jax.Array  # I-f: the offset θ_f − θ̂ low-passed over the dwell, rad
    t_agree: jax.Array  # I-f: how long the given position has agreed with the I-f frame, s
    t_closed: jax.Array  # time since the switch, s
    id_hand: jax.Array  # the d-current at the switch (in the given frame), A
    id_fw: jax.Array  # field weakening's Δi_d (≤ 0; 0 without field weakening), A
    kp_w: jax.Array  # the speed loop's k_pω at its last sample (a scheduled gain's bumpless change), A/(rad/s)


class FOCInput(NamedTuple):
    """What the controller is given at sample ``k``.

    Attributes:
        k: The sample index (the speed loop runs when k % speed_every == 0).
        i_a: The measured stationary-frame α current, A.
        i_b: The measured β current, A.
        theta: The electrical angle the controller uses (encoder or observer), rad.
        omega_e: The electrical speed it uses (decoupling, delay compensation), rad/s.
        omega_m: The mechanical speed the speed loop uses, rad/s.
        omega_m_ref: The speed reference, rad/s (i_q* in A when ``outer="current"``).
    """

    k: jax.Array  # sample index (the speed loop runs when k % speed_every == 0)
    i_a: jax.Array  # measured stationary-frame currents, A
    i_b: jax.Array
    theta: jax.Array  # electrical angle the controller uses (encoder or observer), rad
    omega_e: jax.Array  # electrical speed it uses (decoupling, delay compensation), rad/s
    omega_m: jax.Array  # mechanical speed the speed loop uses, rad/s
    omega_m_ref: jax.Array  # speed reference, rad/s (i_q* in A when outer="current")


class FOCOutput(NamedTuple):
    """What the controller gives each period.

    Attributes:
        u_a: The α voltage to apply over the next period (before the inverter's limit), V.
        u_b: The β voltage, V.
        id_ref: The d current reference, A.
        iq_ref: The q current reference, A.
        theta: The angle the current loop used (given position, or the I-f angle in start-up), rad.
    """

    u_a: jax.Array  # voltage to apply over the next period (before the inverter's limit), V
    u_b: jax.Array
    id_ref: jax.Array  # current references, A
    iq_ref: jax.Array
    theta: jax.Array  # the angle the current loop used (given position, or the I-f angle in start-up), rad


class IfPhase(NamedTuple):
    """The I-f start-up's part of one period (FOC._if_phase); without a start-up the state's values."""

    omega_f: jax.Array
    theta_f: jax.Array
    mode: jax.Array
    int_w0: jax.Array  # the speed integrator, pre-loaded at the switch
    iq_held: jax.Array  # the held i_q*, I_f cos Δ at the switch
    t_at_switch: jax.Array
    d_lp: jax.Array
    t_agree: jax.Array
    t_closed: jax.Array
    id_hand: jax.Array
    switch: jax.Array | None = None  # the switch happens this period (None: no start-up)
    sd: jax.Array | None = None  # sin Δ, Δ = θ_f − θ̂
    cd: jax.Array | None = None  # cos Δ
