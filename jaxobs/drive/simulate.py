"""Closed-loop drive simulation: PMSM + inverter + sensors + FOC (+ observer) as one ``lax.scan``.

One scan step is one control period T_s (10 kHz by default), as on a DSP:

1. sample: the true stationary-frame current at t_k goes through the sensors;
   the observer is told the voltage applied over [t_k, t_{k+1}] (computed at
   t_{k−1}: the one-sample computation delay), plus the voltage-sensor errors;
2. the observer steps on (u_ab, i_ab) and reports θ̂e, ω̂e at t_k;
3. the controller uses the encoder (``sensorless=False``) or the observer's
   θ̂e, ω̂e (from ``handover`` on; the encoder before, while the observer
   converges — or an I-f start-up) and computes the voltage to apply over
   [t_{k+1}, t_{k+2}];
4. the plant integrates over [t_k, t_{k+1}] in ``n_sub`` substeps of a
   discretization rule, under the applied voltage (limited, plus the dead-time
   error of the instantaneous current) and the load at t_k.

The plant's vector field :func:`plant_field` is the same function
``diffrax.diffeqsolve`` runs as the reference.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._loop import run_loop
from .._validate import check_sample_time
from ..discretize import RK4, AbstractRule, Held
from ..observers.base import check_rule
from .control import FOC, IfStartup
from .hardware import Inverter
from .machine import PMSMParams, dq_to_ab, plant_vf, torque
from .scenario import Scenario

__all__ = ["Drive", "DriveInput", "DriveSolution", "simulate_drive", "plant_field", "simulate_plant_open_loop"]


class DriveInput(NamedTuple):
    """What a drive observer is given each period: measured stationary-frame voltage and current."""

    u_a: jax.Array
    u_b: jax.Array
    i_a: jax.Array
    i_b: jax.Array


def plant_field(par: PMSMParams, inverter: Inverter, dead_time, x, inp):
    """Plant vector field with the inverter's dead-time error; ``inp = (u_α, u_β, T_L)`` (applied, limited)."""
    i_a, i_b = dq_to_ab(x[0], x[1], x[3])
    du_a, du_b = inverter.dead_time_error(dead_time, i_a, i_b)
    return plant_vf(par, x, (inp[0] + du_a, inp[1] + du_b), inp[2])


class Drive(eqx.Module):
    """The drive hardware and controller: FOC, inverter, plant integration, optional I-f start-up."""

    foc: FOC
    inverter: Inverter
    startup: IfStartup | None
    n_sub: int = eqx.field(static=True)  # plant substeps per control period
    rule: AbstractRule = eqx.field(static=True)  # plant integration rule
    sensorless: bool = eqx.field(static=True)
    handover: float = eqx.field(static=True)  # sensorless: encoder until this time (s), observer after

    def __init__(self, foc, inverter=None, *, startup=None, n_sub=2, rule=None, sensorless=False, handover=0.0):
        if not isinstance(foc, FOC):
            raise ValueError(f"Drive.foc must be a FOC, got {type(foc).__name__}")
        self.foc = foc
        self.inverter = Inverter() if inverter is None else inverter
        self.startup = startup
        if not (isinstance(n_sub, int) and n_sub >= 1):
            raise ValueError(f"Drive.n_sub must be an integer >= 1, got {n_sub!r}")
        self.n_sub = n_sub
        self.rule = check_rule(RK4() if rule is None else rule, "Drive")
        self.sensorless = bool(sensorless)
        if not (handover >= 0.0):
            raise ValueError(f"Drive.handover must be >= 0 s, got {handover!r}")
        self.handover = float(handover)

    @property
    def ts(self) -> float:
        return self.foc.ts


class DriveSolution(eqx.Module):
    t: jax.Array  # sample times t_k, s
    theta_e: jax.Array  # true electrical angle, rad, wrapped to (−π, π]
    theta_e_hat: jax.Array  # angle the controller used (encoder, observer or I-f), rad
    omega_m: jax.Array  # true mechanical speed, rad/s
    omega_m_hat: jax.Array  # speed the speed loop used, rad/s
    omega_m_ref: jax.Array  # speed reference, rad/s
    i_d: jax.Array  # true rotor-frame currents, A
    i_q: jax.Array
    i_a: jax.Array  # true stationary-frame currents, A
    i_b: jax.Array
    u_a: jax.Array  # applied stationary-frame voltage (before the dead-time error), V
    u_b: jax.Array
    torque: jax.Array  # electromagnetic torque, N·m
    load: jax.Array  # load torque, N·m
    id_ref: jax.Array
    iq_ref: jax.Array
    mode: jax.Array  # 0: I-f start-up, 1: closed loop
    obs: Any  # observer outputs (None without an observer)
    ok: jax.Array  # bool: every state finite over the horizon
    cost: jax.Array | None = None  # ts·Σ cost(sample) when a running cost was given
    final: Any = None  # the loop's final carry (plant state x, rule, ctrl, obs, u)

    @property
    def speed_rpm(self):
        return self.omega_m * 60 / (2 * jnp.pi)


_TRAJECTORY_FIELDS = (
    "theta_e", "theta_e_hat", "omega_m", "omega_m_hat", "omega_m_ref", "i_d", "i_q", "i_a", "i_b",
    "u_a", "u_b", "torque", "load", "id_ref", "iq_ref", "mode", "obs",
)


def _wrap(a):
    return jnp.pi - jnp.mod(jnp.pi - a, 2 * jnp.pi)


# Loop unrolling of the drive (jaxobs._loop).  1: the drive step is large, and
# unrolling it made XLA's CPU fusion duplicate work (forward 3.1 → 1.3 M
# scenario-steps/s at 2) and its reverse-mode compile blow up (> 200 s).
DEFAULT_UNROLL = 1


@eqx.filter_jit
def simulate_drive(
    drive: Drive,
    scenario: Scenario,
    t1: float,
    observer=None,
    *,
    save: Literal["all", "final"] = "all",
    cost: Callable | None = None,
    inputs: Literal["loop", "precomputed"] = "loop",
    checkpoint: str = "auto",
    unroll: int = DEFAULT_UNROLL,
) -> DriveSolution:
    """Simulate the closed loop from t = 0 to ``t1`` (static) for one scenario (vmap for a batch).

    Args:
        save: ``"all"`` returns every sample; ``"final"`` returns a solution whose
            trajectory fields are None (only ``ok``, ``cost`` and ``final``), so long
            horizons keep no trajectory.
        cost: optional running cost ``cost(sample) -> scalar``; ``sample`` is a
            :class:`DriveSolution` of one sample's scalars; ``sol.cost`` = ts·Σ cost.
        inputs: ``"loop"`` evaluates the speed-reference and load profiles inside
            each step; ``"precomputed"`` before the loop (two arrays of n samples).
        checkpoint, unroll: how the loop is differentiated and unrolled
            (:mod:`jaxobs._loop`); results are identical.
    """
    if save not in ("all", "final"):
        raise ValueError(f"save must be 'all' or 'final', got {save!r}")
    if inputs not in ("loop", "precomputed"):
        raise ValueError(f"inputs must be 'loop' or 'precomputed', got {inputs!r}")
    ts = check_sample_time("ts", drive.ts, "Drive")
    n = int(round(t1 / ts))
    if n < 1:
        raise ValueError(f"t1 must be at least one control period ({ts:g} s), got {t1!r}")
    if drive.sensorless and observer is None:
        raise ValueError("a sensorless drive needs an observer (pass observer=...)")
    par, est = scenario.par, scenario.est_par
    foc, inv = drive.foc, drive.inverter
    h = ts / drive.n_sub
    dtype = jnp.result_type(par.Rs, float)
    x0 = jnp.stack([jnp.zeros((), dtype), jnp.zeros((), dtype), scenario.omega_m0.astype(dtype), scenario.theta_e0.astype(dtype)])

    def field(x, inp):
        return plant_field(par, inv, scenario.dead_time, x, inp)

    carry0 = dict(
        x=x0,
        rule=drive.rule.init(field, x0, None),
        ctrl=foc.init(drive.startup),
        obs=None if observer is None else observer.init(),
        u=(jnp.zeros((), dtype), jnp.zeros((), dtype)),
    )

    def body(carry, xk):
        k, w_ref, t_load = xk
        t = k * ts
        x = carry["x"]
        i_d, i_q, w_m, th = x[0], x[1], x[2], x[3]
        i_a, i_b = dq_to_ab(i_d, i_q, th)
        u_a, u_b = carry["u"]
        um_a, um_b, im_a, im_b = scenario.sensors.measure(scenario.key, k, u_a, u_b, i_a, i_b)
        if observer is not None:
            obs_state, obs_out = observer.step(carry["obs"], DriveInput(um_a, um_b, im_a, im_b))
        else:
            obs_state, obs_out = None, None
        if drive.sensorless:
            # before the hand-over time the encoder runs the drive while the observer converges
            use_obs = t >= drive.handover
            th_c = jnp.where(use_obs, obs_out.theta, th)
            w_e_c = jnp.where(use_obs, obs_out.omega, par.p * w_m)
            w_m_c = w_e_c / par.p
        else:
            th_c, w_e_c, w_m_c = th, par.p * w_m, w_m
        ctrl, (ua_next, ub_next), (id_ref, iq_ref) = foc.step(
            carry["ctrl"], k, im_a, im_b, th_c, w_e_c, w_m_c, w_ref, est, inv.u_max, drive.startup
        )
        ua_next, ub_next = inv.limit(ua_next, ub_next)
        inp = Held((u_a, u_b, t_load))
        rs = carry["rule"]
        xn = x
        for _ in range(drive.n_sub):
            xn, rs = drive.rule.step(field, xn, inp, h, rs)
        xn = xn.at[3].set(_wrap(xn[3]))
        th_used = jnp.where(ctrl.mode == 1, th_c, ctrl.theta_f)
        out = dict(
            theta_e=_wrap(th),
            theta_e_hat=_wrap(th_used),
            omega_m=w_m,
            omega_m_hat=w_m_c,
            omega_m_ref=w_ref,
            i_d=i_d,
            i_q=i_q,
            i_a=i_a,
            i_b=i_b,
            u_a=u_a,
            u_b=u_b,
            torque=torque(par, i_d, i_q, th),
            load=t_load,
            id_ref=id_ref,
            iq_ref=iq_ref,
            mode=ctrl.mode,
            obs=obs_out,
        )
        new = dict(x=xn, rule=rs, ctrl=ctrl, obs=obs_state, u=(ua_next, ub_next))
        if cost is not None:
            new["acc"] = carry["acc"] + cost(DriveSolution(t=t, ok=jnp.asarray(True), **out))
        return new, (out if save == "all" else None)

    if cost is not None:
        carry0["acc"] = jnp.zeros((), dtype)
    def profiles(ks):
        tt = ks * ts
        return ks, scenario.speed_ref(tt), scenario.load(tt)

    ks = jnp.arange(n)
    # "loop": the profiles are evaluated a block of steps at a time inside the loop (jaxobs._loop, point 5)
    xs, xs_map = (ks, profiles) if inputs == "loop" else (profiles(ks), None)
    final, out = run_loop(body, carry0, xs, n, unroll=unroll, checkpoint=checkpoint, xs_map=xs_map)
    total = None if cost is None else ts * final["acc"]
    if save == "final":
        # the plant state, controller and observer states stay non-finite once they are
        ok = jnp.all(jnp.isfinite(final["x"])) & jnp.all(jnp.isfinite(jnp.stack(final["u"])))
        nones = {f: None for f in _TRAJECTORY_FIELDS}
        return DriveSolution(t=None, ok=ok, cost=total, final=final, **nones)
    ok = jnp.all(jnp.stack([jnp.all(jnp.isfinite(out[f])) for f in ("omega_m", "i_d", "i_q", "u_a", "u_b")]))
    return DriveSolution(t=ts * jnp.arange(n, dtype=dtype), ok=ok, cost=total, final=final, **out)


@eqx.filter_jit
def simulate_plant_open_loop(par: PMSMParams, inverter: Inverter, u_a, u_b, t_load, ts: float, n_sub: int, rule: AbstractRule, dead_time=0.0, x0=None):
    """Plant alone under given per-period voltages (held) and load: the states at every t_k.

    Used to check the scan plant against ``diffrax.diffeqsolve`` on :func:`plant_field`.
    """
    h = ts / n_sub
    dtype = jnp.result_type(par.Rs, float)
    x0 = jnp.zeros((4,), dtype) if x0 is None else x0

    def field(x, inp):
        return plant_field(par, inverter, dead_time, x, inp)

    def body(carry, inp):
        x, rs = carry
        for _ in range(n_sub):
            x, rs = rule.step(field, x, Held(inp), h, rs)
        return (x, rs), x

    (_, _), xs = jax.lax.scan(body, (x0, rule.init(field, x0, None)), (u_a, u_b, t_load))
    return jnp.concatenate([x0[None], xs], axis=0)



