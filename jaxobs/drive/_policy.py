"""The FOC's i_d policy (zero or MTPA) and its maps between torque and current, with the rotor-frame helpers the
controller (:mod:`jaxobs.drive.control`) and its steady operating point share.

Torque to current under MTPA.  The speed PI's output is the torque command T* in
units of the magnet's current, i_lin = T*/K̂_t (K̂_t = 1.5 p ψ̂f): its gains above
(jaxobs.drive.control) place the double pole at −α_s on any machine.  With i_d* = 0 that is i_q* itself.
Under MTPA on a salient machine the torque per i_q grows with the load (the
reluctance term (L̂d − L̂q) i_d i_q), so i_q* = i_lin would raise the loop's gain
with the load (1.8× at rated load on a machine with Lq = 4 Ld whose reluctance
carries 23 % of the rated torque); instead i_q* is the MTPA current whose torque on
the assumed machine is K̂_t i_lin (:meth:`jaxobs.drive.FOC.mtpa_iq`, Newton's method), and the
loop keeps its designed bandwidth at every load (``tests/test_mtpa_speed_loop.py``,
a +1 % step at 500 r/min: 1.008–1.011 α_s from no load to 1.5× rated load, where
i_q* = i_lin measured 1.069, 1.117 and 1.141 α_s at half, full and 1.5× rated).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..core.trig import sincos
from .machine import PMSMParams, rotate

__all__ = ["policy_id", "policy_iq_limit", "policy_iq_lin", "policy_mtpa_iq", "policy_torque", "rotate_by", "torque_dq"]


def rotate_by(x_d: jax.Array | float, x_q: jax.Array | float, angle: jax.Array | float) -> tuple[jax.Array, jax.Array]:
    """(x_d, x_q) seen from a frame ``angle`` behind: R(angle)·(x_d, x_q).

    Args:
        x_d: The d component.
        x_q: The q component.
        angle: The angle, rad.

    Returns:
        The rotated ``(x_d, x_q)``.
    """
    return rotate(x_d, x_q, *sincos(angle))


def torque_dq(par: PMSMParams, i_d: jax.Array | float, i_q: jax.Array | float) -> jax.Array:
    """Mean electromagnetic torque (no BEMF harmonics), N·m.

    Args:
        par: The machine.
        i_d: The d current, A.
        i_q: The q current, A.

    Returns:
        The torque, N·m.
    """
    return 1.5 * par.p * (par.psi_f * i_q + (par.Ld - par.Lq) * i_d * i_q)


def policy_id(id_mode: str, est: PMSMParams, iq: jax.Array | float) -> jax.Array:
    """The policy's i_d* for i_q (A): zero, or MTPA ψf/(2(Lq − Ld)) − √(ψf²/(4(Lq − Ld)²) + i_q²) (0 for Ld = Lq).

    Args:
        id_mode: ``"zero"`` or ``"mtpa"``.
        est: The machine the controller assumes.
        iq: The q current, A.

    Returns:
        i_d*, A.
    """
    if id_mode == "zero":
        return jnp.zeros_like(iq)
    dl = est.Lq - est.Ld
    safe = jnp.where(jnp.abs(dl) > 1e-12, dl, 1.0)
    a = est.psi_f / (2 * safe)
    mtpa = a - jnp.sign(safe) * jnp.sqrt(a * a + iq * iq)
    return jnp.where(jnp.abs(dl) > 1e-12, mtpa, 0.0)


def policy_torque(id_mode: str, est: PMSMParams, iq: jax.Array | float) -> jax.Array:
    """The mean torque (N·m) of i_q and the policy's i_d(i_q) on ``est``.

    Args:
        id_mode: ``"zero"`` or ``"mtpa"``.
        est: The machine the controller assumes.
        iq: The q current, A.

    Returns:
        The torque, N·m.
    """
    return torque_dq(est, policy_id(id_mode, est, iq), iq)


def policy_mtpa_iq(id_mode: str, est: PMSMParams, iq_lin: jax.Array) -> jax.Array:
    """The i_q* (A) whose torque under the policy's i_d(i_q*) is K̂_t·``iq_lin`` (:meth:`FOC.mtpa_iq`).

    Args:
        id_mode: ``"zero"`` or ``"mtpa"``.
        est: The machine the controller assumes.
        iq_lin: The speed loop's output, A (K̂_t units).

    Returns:
        i_q*, A.
    """
    if id_mode == "zero":
        return iq_lin
    target = est.kt * iq_lin
    iq = iq_lin
    for _ in range(6):
        te, dte = jax.jvp(lambda x: policy_torque(id_mode, est, x), (iq,), (jnp.ones_like(iq),))
        iq = iq - (te - target) / jnp.where(dte > 0, dte, 1.0)
    return iq


def policy_iq_lin(id_mode: str, est: PMSMParams, iq: jax.Array) -> jax.Array:
    """The speed loop's output that asks for the current i_q under the policy (:meth:`FOC.iq_lin`).

    Args:
        id_mode: ``"zero"`` or ``"mtpa"``.
        est: The machine the controller assumes.
        iq: The q current, A.

    Returns:
        The speed loop's output, A (K̂_t units).
    """
    if id_mode == "zero":
        return iq
    return policy_torque(id_mode, est, iq) / est.kt


def policy_iq_limit(id_mode: str, est: PMSMParams, i_max: jax.Array) -> tuple[jax.Array, jax.Array]:
    """The current limits of the speed loop under the policy (:meth:`FOC.iq_limit`).

    Args:
        id_mode: ``"zero"`` or ``"mtpa"``.
        est: The machine the controller assumes.
        i_max: The current-vector limit, A.

    Returns:
        ``(|i_q*| on the policy's curve at |i| = i_max, the speed loop's output limit in K̂_t units)``, A.
    """
    if id_mode == "zero":
        return i_max, i_max
    dl = est.Lq - est.Ld
    salient = jnp.abs(dl) > 1e-12
    safe = jnp.where(salient, dl, 1.0)
    i_d = (est.psi_f - jnp.sqrt(est.psi_f**2 + 8 * safe * safe * i_max**2)) / (4 * safe)
    iq = jnp.where(salient, jnp.sqrt(jnp.maximum(i_max**2 - i_d * i_d, 0.0)), i_max)
    return iq, policy_iq_lin(id_mode, est, iq)


def rotation_emf(
    est: PMSMParams, w_e: jax.Array | float, i_d: jax.Array | float, i_q: jax.Array | float, flux_map: bool = False
) -> tuple[jax.Array, jax.Array]:
    """The current loop's decoupling terms (ω̂e ψq, ω̂e ψd), V: on the constants, ω̂e L̂q i_q and ω̂e (L̂d i_d + ψ̂f);
    with ``flux_map`` and a map on ``est`` (``est.sat``), its flux at the current (:class:`~jaxobs.drive.FOC`).

    Args:
        est: The machine the controller assumes.
        w_e: ω̂e, rad/s.
        i_d: The d current, A.
        i_q: The q current, A.
        flux_map: Whether the map's flux is used where ``est`` has one.

    Returns:
        ``(ω̂e ψq, ω̂e ψd)``, V.
    """
    if flux_map and est.sat is not None:
        psi_d, psi_q = est.sat.flux(i_d, i_q)
        return w_e * psi_q, w_e * psi_d
    return w_e * est.Lq * i_q, w_e * (est.Ld * i_d + est.psi_f)
