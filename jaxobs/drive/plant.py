"""The PMSM plant as a step-function component: one control period of the machine under a held voltage.

``PMSM(par, inverter, dead_time, ts=..., n_sub=..., rule=...)`` has the
contract of every drive component (:mod:`jaxobs.drive.component`): ``init(op)`` and
``step(state, PlantInput) -> (state, PlantOutput)``.  Like the signal-level
observers, ``step`` returns what the sensors see *at* t_k (the state before the
update) and integrates the machine over [t_k, t_{k+1}] in ``n_sub`` substeps of
its discretization rule, under the voltage applied over that period (already
limited by the inverter; the dead-time error of the instantaneous current is
added inside the vector field) and the load torque at t_k.

The vector field :meth:`PMSM.field` (:func:`plant_field`) is the same function
``diffrax.diffeqsolve`` runs as the high-accuracy reference (tests/test_drive.py).
State x = [i_d (A), i_q (A), ω_m (rad/s, mechanical), θ_e (rad, electrical)];
θ_e is wrapped to (−π, π] after every period.  A machine with an algebraic saturation map (``PMSMParams.sat``,
:mod:`jaxobs.drive.saturation`) is integrated in its flux linkages instead, x = [ψd (Vs), ψq (Vs), ω_m, θ_e]:
its map gives the current as an explicit function of the flux, so the vector field needs no inversion; the
outputs are the currents as before, and :meth:`PMSM.init` starts from the flux of the operating point's
currents (the map inverted by Newton's method, once).  A map given as tables (``FluxTable``) keeps the
state in currents (:mod:`jaxobs.drive.machine`).

Carrier PWM (an inverter with ``pwm="carrier"``, :mod:`jaxobs.drive.pwm`): the period is cut at the six
switching instants of the carrier comparison (dead time on the edges) into seven sub-intervals, each under its
switched voltage held, and each sub-interval is integrated by one step of the plant's rule (``n_sub`` steps per
sub-interval); the speed and angle in the same state, as under the averaged inverter.  Within a sub-interval
the voltage is constant in the stationary frame, but the machine is not linear time-invariant there (the rotor
turns, and a salient machine's stationary-frame inductance turns with it), so the rule is RK4 on the nonlinear
field rather than a matrix exponential; the longest sub-interval is at most half a period, and its error
against diffrax's Dopri8 (tests/test_pwm.py) is stated there.  The output at t_k is the state at the period's
start, the carrier's peak, the centre of the zero vector 000: where the current ripple crosses its mean.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from ..core.discretize import RK4, AbstractRule, AbstractRuleCarry, Held, check_rule
from ..core.numerics import wrap
from ..core.trig import sincos
from ..core.validate import check_nonnegative, check_sample_time
from ._operating import OperatingPoint
from .component import AbstractComponent
from .hardware import Inverter, ab_to_abc
from .machine import PMSMParams, dq_to_ab, mapped_torque, plant_vf, rotate, state_currents, torque
from .pwm import N_INTERVALS, carrier_intervals

__all__ = ["PMSM", "PlantInput", "PlantOutput", "PlantState", "plant_field"]

_Tracer = jax.core.Tracer  # pyright: ignore[reportAttributeAccessIssue]  # jax.core: not in jax's stubs


def plant_field(
    par: PMSMParams, inverter: Inverter, dead_time: jax.Array | float, x: jax.Array, inp: jax.Array
) -> jax.Array:
    """Plant vector field with the inverter's dead-time error.

    Args:
        par: The machine.
        inverter: The inverter.
        dead_time: The dead time, s.
        x: The plant state [i_d, i_q, ωm, θe].
        inp: ``(u_α, u_β, T_L)``: the applied (limited) voltage, V, and the load torque, N·m.

    Returns:
        dx/dt.
    """
    sc = sincos(x[3])  # one sine and cosine of θe for the currents' and the voltage's transforms
    i_a, i_b = rotate(*state_currents(par, x), *sc)
    du_a, du_b = inverter.dead_time_error(dead_time, i_a, i_b)
    if inverter.has_device_drop:  # statically zero by default: the field stays what it was without drops
        dd_a, dd_b = inverter.device_drop_error(i_a, i_b)
        du_a, du_b = du_a + dd_a, du_b + dd_b
    return plant_vf(par, x, (inp[0] + du_a, inp[1] + du_b), inp[2], sc=sc)


class PlantInput(NamedTuple):
    """What drives the machine over one period.

    Attributes:
        u_a: The applied stationary-frame voltage u_α (inverter-limited, before the dead-time error), V.
        u_b: u_β, V.
        t_load: The load torque, N·m.
    """

    u_a: jax.Array  # applied stationary-frame voltage (inverter-limited, before the dead-time error), V
    u_b: jax.Array
    t_load: jax.Array  # load torque, N·m


class PlantOutput(NamedTuple):
    """The machine at t_k.

    Attributes:
        i_d: The rotor-frame d current, A.
        i_q: The rotor-frame q current, A.
        omega_m: The mechanical speed, rad/s.
        theta_e: The electrical angle, rad (the state's: wrapped to (−π, π] after every period).
        i_a: The stationary-frame α current, A.
        i_b: The stationary-frame β current, A.
        torque: The electromagnetic torque, N·m.
    """

    i_d: jax.Array  # rotor-frame currents, A
    i_q: jax.Array
    omega_m: jax.Array  # mechanical speed, rad/s
    theta_e: jax.Array  # electrical angle, rad (the state's: wrapped to (−π, π] after every period)
    i_a: jax.Array  # stationary-frame currents, A
    i_b: jax.Array
    torque: jax.Array  # electromagnetic torque, N·m


class PlantState(AbstractRuleCarry):
    """The machine's state between two periods.

    Attributes:
        x: [i_d, i_q, ω_m, θ_e], shape (4,).
        rule: The integration rule's own state (None for one-step rules).
    """

    x: jax.Array  # [i_d, i_q, ω_m, θ_e], shape (4,)
    rule: Any  # the integration rule's own state (None for one-step rules)


class PMSM(AbstractComponent):
    """The machine ``par`` behind an inverter with dead time ``dead_time``, integrated per control period.

    Args:
        par: The machine (:class:`PMSMParams`).
        inverter: The inverter (default :class:`Inverter`).
        dead_time: The dead time, s (≥ 0).
        ts: The control period, s.
        n_sub: Substeps per period (an integer ≥ 1); under carrier PWM, per sub-interval.
        rule: The integration rule (default :class:`~jaxobs.RK4`); under carrier PWM a one-step rule.

    Raises:
        ValueError: A value out of its range, naming the field; under carrier PWM, a switching frequency other
            than 1/ts or a multistep rule.
    """

    par: PMSMParams
    inverter: Inverter
    dead_time: jax.Array  # s
    ts: float = eqx.field(static=True)  # control period, s
    n_sub: int = eqx.field(static=True)  # substeps per period
    rule: AbstractRule = eqx.field(static=True)

    def __init__(
        self,
        par: PMSMParams,
        inverter: Inverter | None = None,
        dead_time: jax.Array | float = 0.0,
        *,
        ts: float = 1e-4,
        n_sub: int = 2,
        rule: AbstractRule | None = None,
    ) -> None:
        if not isinstance(par, PMSMParams):
            raise ValueError(f"PMSM.par must be a PMSMParams, got {type(par).__name__}")
        self.par = par
        self.inverter = Inverter() if inverter is None else inverter
        self.dead_time = check_nonnegative("dead_time", dead_time, "PMSM")
        self.ts = check_sample_time("ts", ts, "PMSM")
        if isinstance(n_sub, bool) or not isinstance(n_sub, int) or n_sub < 1:
            raise ValueError(f"PMSM.n_sub must be an integer >= 1, got {n_sub!r}")
        self.n_sub = n_sub
        self.rule = check_rule(RK4() if rule is None else rule, "PMSM")
        if self.inverter.pwm == "carrier":
            f_pwm = self.inverter.f_pwm
            if not isinstance(f_pwm, _Tracer) and abs(float(f_pwm) * self.ts - 1.0) > 1e-9:
                raise ValueError(
                    f"PMSM.ts: carrier PWM integrates one carrier period per step (single update): ts must be "
                    f"1/inverter.f_pwm = {1.0 / float(f_pwm):.6g} s, got {self.ts:.6g} s (a half-period plant, "
                    "PWM-centre sampling, is not supported)"
                )
            if type(self.rule).init is not AbstractRule.init:
                raise ValueError(
                    f"PMSM.rule: carrier PWM steps sub-intervals of varying length: a one-step rule, got "
                    f"{type(self.rule).__name__}"
                )

    def field(self, x: jax.Array, inp: jax.Array) -> jax.Array:
        """The vector field.

        Args:
            x: The state [i_d, i_q, ω_m, θ_e].
            inp: ``(u_α, u_β, T_L)``.

        Returns:
            dx/dt.
        """
        return plant_field(self.par, self.inverter, self.dead_time, x, inp)

    def init(self, op: OperatingPoint | None = None) -> PlantState:
        """The machine's initial state.

        Args:
            op: An :class:`OperatingPoint` (its currents i_d, i_q, speed ω_m and angle θ_e; an I-f start-up's
                is ``OperatingPoint.at_rest(θe0)``), or None: at rest at θe = 0.

        Returns:
            The plant state.
        """
        dtype = jnp.result_type(self.par.Rs, float)
        vals = (0.0, 0.0, 0.0, 0.0) if op is None else (op.i_d, op.i_q, op.omega_m, op.theta_e)
        if self.par.sat is not None and self.par.sat.state_is_flux:  # the flux linkage of the op's currents
            vals = (*self.par.sat.flux(vals[0], vals[1]), *vals[2:])
        x0 = jnp.stack([jnp.asarray(v, dtype) for v in vals])
        return PlantState(x=x0, rule=self.rule.init(self.field, x0, None))

    def output(self, x: jax.Array) -> PlantOutput:
        """What the plant shows at the state ``x`` (currents, speed, angle, torque).

        Args:
            x: The state.

        Returns:
            The :class:`PlantOutput`.
        """
        if self.par.sat is not None:  # a map: the torque from its fluxes (the state: fluxes or currents)
            i_d, i_q = state_currents(self.par, x)
            i_a, i_b = dq_to_ab(i_d, i_q, x[3])
            return PlantOutput(i_d, i_q, x[2], x[3], i_a, i_b, mapped_torque(self.par, x))
        i_d, i_q, w_m, th = x[0], x[1], x[2], x[3]
        i_a, i_b = dq_to_ab(i_d, i_q, th)
        return PlantOutput(i_d, i_q, w_m, th, i_a, i_b, torque(self.par, i_d, i_q, th))

    def _applied_field(self, x, inp):
        """The machine's field under the switched voltage (no averaged dead-time error: it is on the edges)."""
        return plant_vf(self.par, x, (inp[0], inp[1]), inp[2])

    def carrier_substeps(self, state: PlantState, inp: PlantInput) -> tuple[jax.Array, jax.Array, Any]:
        """One period under carrier PWM, sub-interval by sub-interval (``pwm="carrier"``).

        Args:
            state: The plant state at the period's start.
            inp: The commanded (limited) voltage and the load torque.

        Returns:
            ``(t, xs, rule_state)``: the boundaries' times from the period's start, shape (8,), s; the state at
            each, shape (8, 4) (θ_e unwrapped); the rule's state at the end.
        """
        inv = self.inverter
        i_a, i_b = dq_to_ab(*state_currents(self.par, state.x), state.x[3])  # a map's state may be its flux
        s = jnp.stack([inv.sign(i) for i in ab_to_abc(i_a, i_b)])  # the phase currents' signs at t_k
        h, v_a, v_b = carrier_intervals(inv.udc, self.ts, self.dead_time, inv.u_device, inp.u_a, inp.u_b, s)
        x, rs = state.x, state.rule
        xs = [x]
        for j in range(N_INTERVALS):  # seven sub-intervals: a fixed, unrolled sequence
            path = Held((v_a[j], v_b[j], inp.t_load))
            hj = h[j] / self.n_sub
            for _ in range(self.n_sub):
                x, rs = self.rule.step(self._applied_field, x, path, hj, rs)
            xs.append(x)
        t = jnp.concatenate([jnp.zeros((1,), h.dtype), jnp.cumsum(h)])
        return t, jnp.stack(xs), rs

    def step(self, state: PlantState, inp: PlantInput) -> tuple[PlantState, PlantOutput]:
        """One control period of the plant under the held (or carrier-modulated) voltage.

        Args:
            state: The :class:`PlantState`.
            inp: The :class:`PlantInput`.

        Returns:
            ``(the next state, the output at the period's start)``.
        """
        out = self.output(state.x)
        if self.inverter.pwm == "carrier":
            _, xs, rs = self.carrier_substeps(state, inp)
            x = xs[-1]
            return PlantState(x=x.at[3].set(wrap(x[3])), rule=rs), out
        path = Held((inp.u_a, inp.u_b, inp.t_load))
        h = self.ts / self.n_sub
        x, rs = state.x, state.rule
        for _ in range(self.n_sub):
            x, rs = self.rule.step(self.field, x, path, h, rs)
        x = x.at[3].set(wrap(x[3]))
        return PlantState(x=x, rule=rs), out
