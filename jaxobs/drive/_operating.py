"""The drive's steady operating point under the FOC: where a steady-start scenario starts
(:meth:`FOC.operating_point <jaxobs.drive.FOC.operating_point>`, :meth:`FOC.init <jaxobs.drive.FOC.init>`)."""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from ._policy import policy_id, policy_iq_limit, rotate_by, torque_dq
from .machine import PMSMParams
from .weakening import VoltageFeedbackFW, id_stop, mtpv_iq, voltage_iq_range

__all__ = ["OperatingPoint", "steady_point"]


class OperatingPoint(NamedTuple):
    """A steady operating point of the drive (the true machine), to start a scenario in.

    At steady state the currents sit at their references and the speed at its
    reference; the PI integrators hold what the loop needs to stay there.  The
    controller's frame may sit ``offset`` ahead of the rotor's (a biased
    observer closing the loop): its references are then met in its own frame,
    and the rotor-frame currents below are those references rotated by ``offset``.

    Attributes:
        omega_m: The mechanical speed, rad/s.
        omega_m_ref: The speed reference at t = 0, rad/s.
        theta_e: The electrical angle at t = 0, rad.
        t_load: The load torque at t = 0, N·m.
        i_d: The rotor-frame d current, A.
        i_q: The rotor-frame q current, A.
        u_d: The rotor-frame d voltage the true machine needs there, V.
        u_q: The rotor-frame q voltage, V.
        offset: The controller's angle minus the rotor's, rad (0: encoder or unbiased).
        id_fw: Field weakening's Δi_d there (≤ 0, A): the controller's i_d* is the policy's plus it (0
            without field weakening, or below base speed).
    """

    omega_m: jax.Array  # mechanical speed, rad/s
    omega_m_ref: jax.Array  # speed reference at t = 0, rad/s
    theta_e: jax.Array  # electrical angle at t = 0, rad
    t_load: jax.Array  # load torque at t = 0, N·m
    i_d: jax.Array  # rotor-frame currents, A
    i_q: jax.Array
    u_d: jax.Array  # rotor-frame voltage the true machine needs there, V
    u_q: jax.Array
    offset: jax.Array | float = 0.0  # the controller's angle minus the rotor's, rad (0: encoder or unbiased)
    # field weakening's Δi_d there (≤ 0, A): the controller's i_d* is the policy's plus it (0 without field
    # weakening, or below base speed)
    id_fw: jax.Array | float = 0.0

    @classmethod
    def at_rest(cls, theta_e: ArrayLike) -> OperatingPoint:
        """The machine at standstill: no speed, current, load or voltage (where an I-f start-up starts, the
        rotor parked by its alignment).

        Args:
            theta_e: The electrical angle, rad.

        Returns:
            The :class:`OperatingPoint`.
        """
        theta_e = jnp.asarray(theta_e, dtype=jnp.result_type(theta_e, float))
        z = jnp.zeros_like(theta_e)
        return cls(omega_m=z, omega_m_ref=z, theta_e=theta_e, t_load=z, i_d=z, i_q=z, u_d=z, u_q=z)


def steady_point(
    *,
    est: PMSMParams,
    id_mode: str,
    outer: str,
    i_max: jax.Array,
    u_max: jax.Array,
    field_weakening: VoltageFeedbackFW | None,
    par: PMSMParams,
    omega_m: jax.Array | float,
    omega_m_ref: jax.Array | float,
    theta_e: jax.Array | float,
    t_load: jax.Array | float,
    offset: jax.Array | float = 0.0,
) -> OperatingPoint:
    """The steady state of the true machine ``par`` under this controller at speed ω_m and load T_L.

    The speed loop settles where the torque balances the load and friction,
    T_e(i_d, i_q) = T_L + B ω_m, with the controller's references i_q* and
    i_d*(i_q*) (zero, or MTPA on the assumed machine) met in its own frame,
    ``offset`` (rad) ahead of the rotor's: the rotor-frame currents are the
    references rotated by the offset, (i_d, i_q) = R(offset)(i_d*, i_q*)
    (a lagging observer, offset < 0, puts part of i_q* on the rotor's d axis,
    and i_q* grows to carry the load).  Solved by Newton's method from
    i_q* = (T_L + B ω_m)/(K_t cos offset) (exact in one step for i_d* = 0).
    With ``outer="current"`` the reference *is* i_q*.  The voltage is the true
    machine's steady rotor-frame voltage (the BEMF harmonics, which average
    out, are left out).

    With field weakening the operating point is the field-weakened one where the
    policy's would ask for more than the margin m u_max: i_d* ≤ the policy's such that
    |u| = m u_max (:class:`VoltageFeedbackFW`'s equilibrium; |u| is the same in the
    controller's frame and the rotor's), jointly with the torque balance (Newton on
    i_d* and i_q* in turn, from the policy's point), i_d* within its stop
    (:func:`~jaxobs.drive.weakening.id_stop`) and i_q* within the circle, MTPV and the
    voltage (:mod:`jaxobs.drive.weakening`, point 3; a load beyond them is not
    carried, and the drive decelerates from there).  ``id_fw`` is then i_d* less the
    policy's i_d.  Below base speed Δi_d = 0 and the point is the policy's, unchanged.

    A true machine with a saturation map (``par.sat``): the torque 1.5 p (ψd i_q − ψq i_d) and the voltage
    (Rs i_d − ωe ψq, Rs i_q + ωe ψd) are the map's flux ψ(i) at the currents, as the plant has them (its state
    starts at that flux, :meth:`jaxobs.drive.PMSM.init`); the constants' point was no steady state on the
    5.6-kW PM-SyRM of ``docs/examples/pmsyrm_5p6kw_sat.toml`` (its currents drifted at 6800 A/s in the first
    periods at 1800 r/min and rated load, and field weakening started from zero: 31 r/min of speed error).

    Args:
        est: The machine the controller assumes.
        id_mode: Its i_d policy, ``"zero"`` or ``"mtpa"``.
        outer: ``"speed"`` or ``"current"``.
        i_max: Its current-vector limit, A.
        u_max: Its voltage limit, V.
        field_weakening: Its :class:`VoltageFeedbackFW`, or None.
        par: The true machine.
        omega_m: The mechanical speed ω_m, rad/s.
        omega_m_ref: The speed reference, rad/s (i_q* in A with ``outer="current"``).
        theta_e: The electrical angle, rad.
        t_load: The load torque T_L, N·m.
        offset: The controller's angle minus the rotor's, rad.

    Returns:
        The :class:`OperatingPoint`.
    """
    w_e = par.p * omega_m

    def rotor_currents(iq, dfw=None):  # dfw: field weakening's Δi_d (None: the policy's i_d alone)
        i_d = policy_id(id_mode, est, iq)
        return rotate_by(i_d if dfw is None else i_d + dfw, iq, offset)

    sat = par.sat
    voltage, te_of = _true_machine(par, w_e)

    need = t_load + par.B * omega_m

    def solve_iq(dfw):
        if outer == "current":
            iq_max = policy_iq_limit(id_mode, est, i_max)[0]
            return jnp.clip(omega_m_ref, -iq_max, iq_max)
        # |offset| < 90° where a steady state exists; the floor keeps a wilder offset finite
        i_q = need / (1.5 * par.p * par.psi_f * jnp.maximum(jnp.cos(offset), 0.1))

        def newton(i_q):  # Newton on T_e(i_q*) − need
            te, dte = jax.jvp(lambda iq: te_of(*rotor_currents(iq, dfw)), (i_q,), (jnp.ones_like(i_q),))
            return i_q - (te - need) / dte

        i_q = _iterate(newton, i_q, 4, unrolled=sat is None)
        iq_max = policy_iq_limit(id_mode, est, i_max)[0]
        return jnp.clip(i_q, -iq_max, iq_max)

    i_q = solve_iq(None)
    i_d, i_q = rotor_currents(i_q)
    u_d, u_q = voltage(i_d, i_q)
    id_fw = 0.0
    fw = field_weakening
    if fw is not None:
        target2 = (fw.margin * u_max) ** 2

        def excess(idr, iqr):  # |u|² − (m u_max)² at the references (i_d*, i_q*)
            ud, uq = voltage(*rotate_by(idr, iqr, offset))
            return ud * ud + uq * uq - target2

        iq_pol = solve_iq(None)
        id_pol = policy_id(id_mode, est, iq_pol)
        lo = id_stop(est, id_pol, i_max)

        def solve_iq_at(idr):  # i_q* that carries the load at i_d* = idr (Newton from the policy's)
            def newton(iq):
                te, dte = jax.jvp(lambda q: te_of(*rotate_by(idr, q, offset)), (iq,), (jnp.ones_like(iq),))
                return iq - (te - need) / jnp.where(jnp.abs(dte) > 1e-12, dte, 1.0)

            return _iterate(newton, iq_pol, 4, unrolled=sat is None)

        idr, iqr = id_pol, iq_pol
        if sat is None:
            for _ in range(8):  # Newton on i_d* (|u|² is a convex quadratic in it), then i_q* for the torque
                f, df = jax.jvp(lambda d: excess(d, iqr), (idr,), (jnp.ones_like(idr),))
                idr = jnp.clip(idr - f / jnp.where(jnp.abs(df) > 1e-12, df, 1.0), lo, id_pol)
                iqr = solve_iq_at(idr)
        else:  # on a map: along the torque's curve, in a bracket (_bracketed_newton)
            idr = _bracketed_newton(lambda d: excess(d, solve_iq_at(d)), lo, id_pol)
            iqr = solve_iq_at(idr)
        # the limits the controller puts on i_q* there (jaxobs.drive.weakening, point 3)
        room = jnp.minimum(fw.limit_room(idr, i_max), mtpv_iq(est, idr))
        q_lo, q_hi = voltage_iq_range(est, idr, est.p * omega_m, u_max)
        iqr = jnp.clip(iqr, jnp.maximum(-room, q_lo), jnp.minimum(room, q_hi))
        weakened = u_d * u_d + u_q * u_q > target2
        fd, fq = rotate_by(idr, iqr, offset)
        fud, fuq = voltage(fd, fq)
        i_d, i_q = jnp.where(weakened, fd, i_d), jnp.where(weakened, fq, i_q)
        u_d, u_q = jnp.where(weakened, fud, u_d), jnp.where(weakened, fuq, u_q)
        id_fw = jnp.where(weakened, jnp.minimum(idr - id_pol, 0.0), 0.0)
    z = jnp.zeros_like(w_e)
    return OperatingPoint(
        omega_m=z + omega_m,
        omega_m_ref=z + omega_m_ref,
        theta_e=z + theta_e,
        t_load=z + t_load,
        i_d=z + i_d,
        i_q=z + i_q,
        u_d=u_d,
        u_q=u_q,
        offset=z + offset,
        id_fw=z + id_fw,
    )


def _true_machine(par: PMSMParams, w_e: jax.Array | float) -> tuple[Any, Any]:
    """The true machine's steady voltage (u_d, u_q)(i_d, i_q) at ω_e and its torque T_e(i_d, i_q): the constants'
    (the operations as they always were), or the map's flux at the currents (``par.sat``, :func:`steady_point`)."""
    sat = par.sat
    if sat is None:
        return (
            lambda i_d, i_q: (par.Rs * i_d - w_e * par.Lq * i_q, par.Rs * i_q + w_e * (par.Ld * i_d + par.psi_f)),
            lambda i_d, i_q: torque_dq(par, i_d, i_q),
        )

    def voltage(i_d, i_q):
        pd, pq = sat.flux(i_d, i_q)
        return par.Rs * i_d - w_e * pq, par.Rs * i_q + w_e * pd

    def torque(i_d, i_q):
        pd, pq = sat.flux(i_d, i_q)
        return 1.5 * par.p * (pd * i_q - pq * i_d)

    return voltage, torque


def _bracketed_newton(g: Any, lo: jax.Array, hi: jax.Array, iters: int = 12) -> jax.Array:
    """The root of ``g`` (> 0 at ``hi``, falling as its argument does) in [lo, hi] by Newton from ``hi``, a step
    outside the bracket bisecting it (the stop ``lo`` where g stays > 0).  Field weakening's i_d* on a map: the
    partial derivative at a fixed i_q* overshot to the stop and back, a 2-cycle (the PM-SyRM at 1800 r/min)."""

    def newton(c):
        x, b_lo, b_hi = c
        f, df = jax.jvp(g, (x,), (jnp.ones_like(x),))
        b_lo, b_hi = jnp.where(f > 0, b_lo, x), jnp.where(f > 0, x, b_hi)
        step = x - f / jnp.where(jnp.abs(df) > 1e-12, df, 1.0)
        inside = (step > b_lo) & (step < b_hi)
        return jnp.where(inside, step, 0.5 * (b_lo + b_hi)), b_lo, b_hi

    hi = jnp.asarray(hi)
    lo = jnp.broadcast_to(jnp.asarray(lo, hi.dtype), hi.shape)
    return _iterate(newton, (hi, lo, hi), iters, unrolled=False)[0]


def _iterate(step: Any, init: Any, n: int, *, unrolled: bool) -> Any:
    """``n`` applications of ``step`` to ``init``: a Python loop (``unrolled``) or one ``lax.fori_loop``.

    On a saturation map each step traces the map's flux (a Newton solve of its own) several times over, and the
    solves nest (field weakening's i_d* around the torque's i_q*): unrolled, the steady point of the 5.6-kW
    PM-SyRM (``docs/examples/pmsyrm_5p6kw_sat.toml``) traced 456 flux solves, 42 s of tracing per program and a
    compile past 10 GiB; in a loop each body is traced once.  The constants' path stays unrolled, the operations
    (and so the benches' numbers) as they always were.
    """
    if unrolled:
        for _ in range(n):
            init = step(init)
        return init
    return jax.lax.fori_loop(0, n, lambda _, c: step(c), init)
