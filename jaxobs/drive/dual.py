"""Dual three-phase IPMSM (paper 002's machine): the VSD transformation, parameters and the plant.

Windings.  Two three-phase sets, abc1 at 0°, 120°, 240° and abc2 at 30°, 150°,
270° electrical (set 2 shifted 30°), star-connected with *isolated* neutrals.
Phase order here: (a1, b1, c1, a2, b2, c2), angles θ_k = (0, 2π/3, 4π/3, π/6,
5π/6, 3π/2).

Vector space decomposition (Y. Zhao and T. A. Lipo, "Space vector PWM control
of dual three-phase induction machine using vector space decomposition", IEEE
Trans. Ind. Appl. 31(5), 1995, eq. (4); 002 refs [5], [6] use it).  Its rows
are cos θ_k, sin θ_k (αβ), cos 5θ_k, sin 5θ_k (xy) and the two sets' sums
(o1, o2); with the factor 1/√3 the 6×6 matrix :func:`vsd_matrix` is
orthogonal, hence power invariant.  Zhao & Lipo print the xy rows as
[1, −1/2, −1/2, −√3/2, √3/2, 0] and [0, −√3/2, √3/2, 1/2, 1/2, −1]
(tests/test_dual.py checks ours against them).  The model uses the
*amplitude-invariant* scaling, 1/3 instead of 1/√3 (:data:`VSD_AMPLITUDE`):
a balanced pair of sets of peak phase current I gives |i_αβ| = I, as the
single machine's Clarke transform does (:mod:`jaxobs.drive.machine`), so the
observers, the FOC and the single IPMSM's numbers carry over.  Power is then
P = Σ_k u_k i_k = 3 (u_αβ·i_αβ + u_xy·i_xy) + the zero sequences.

What maps where (harmonic order h of a quantity symmetric in the six
phases): h = 12n ± 1 (1, 11, 13) to αβ, h = 6n ± 1 with n odd (5, 7) to xy,
h = 3, 9 to o1o2 (Zhao & Lipo Sec. II).  The isolated neutrals block o1o2: no
zero-sequence current flows, so the state has none.

The two individual sets.  With each set's own amplitude-invariant Clarke
vector s_j (set 2's expressed in set 1's stationary frame, i.e. its own
Clarke rotated 30° forward), z_αβ = (s1 + s2)/2 and z_xy = conj(s1 − s2)/2, so
s1 = z_αβ + conj(z_xy), s2 = z_αβ − conj(z_xy) (:func:`vsd_to_sets`,
:func:`sets_to_vsd`).  With isolated neutrals these four real coordinates are
all the currents and voltages there are.

Plant (rotor frame in αβ, stationary in xy; ``x = [i_d, i_q, i_x, i_y, ω_m, θ_e]``):

    Ld di_d/dt = u_d − Rs i_d + ωe Lq i_q − e_d
    Lq di_q/dt = u_q − Rs i_q − ωe Ld i_d − e_q
    Lls di_xy/dt = u_xy − Rs i_xy − e_xy           (xy: leakage only, no EM coupling)
    J dωm/dt = Te − TL − B ωm,   dθe/dt = p ωm

The phase back EMF is that of the single machine's phase a shifted to each
phase, e_k = ωe ψf g(θe − θ_k), g(φ) = −sin φ + a5 sin 5φ − a7 sin 7φ (so set 1
alone is exactly :func:`jaxobs.drive.bemf_ab`: fundamental, negative-sequence
5th, positive-sequence 7th); its VSD image puts the fundamental in αβ and
the 5th and 7th in xy.  Torque from the power balance,
Te = 3p [ψ_pm,αβ·i_αβ + ψ_pm,xy·i_xy] + 3p (Ld − Lq) i_d i_q with ψ_pm = e/ωe:
twice the single machine's, as the dual machine is two of its sets on one
shaft.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import papers
from ..core.discretize import RK4, AbstractRule, AbstractRuleCarry, Held, check_rule
from ..core.numerics import wrap
from ..core.validate import check_nonnegative, check_positive, check_sample_time
from ._operating import OperatingPoint
from .component import AbstractComponent
from .hardware import Inverter
from .machine import PMSMParams, ab_to_dq, dq_to_ab

__all__ = [
    "PHASE_ANGLES",
    "VSD_AMPLITUDE",
    "vsd_matrix",
    "phases_to_vsd",
    "vsd_to_phases",
    "sets_to_vsd",
    "vsd_to_sets",
    "DualPMSMParams",
    "dual_ipmsm_paper002",
    "DualPMSM",
    "DualPlantInput",
    "DualPlantOutput",
]

# a1, b1, c1, a2, b2, c2 (electrical rad): set 2 is 30° ahead of set 1
PHASE_ANGLES = np.array([0.0, 2 * math.pi / 3, 4 * math.pi / 3, math.pi / 6, 5 * math.pi / 6, 3 * math.pi / 2])


def vsd_matrix() -> np.ndarray:
    """Zhao & Lipo's VSD matrix (6×6, rows α, β, x, y, o1, o2), power invariant: orthogonal, T Tᵀ = I."""
    th = PHASE_ANGLES
    one = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    rows = [np.cos(th), np.sin(th), np.cos(5 * th), np.sin(5 * th), one, one[::-1]]
    return np.stack(rows) / math.sqrt(3.0)


# amplitude invariant (the model's scaling): α = (1/3) Σ_k cos θ_k x_k; its inverse is 3 VSD_AMPLITUDEᵀ
VSD_AMPLITUDE = vsd_matrix() / math.sqrt(3.0)


def phases_to_vsd(x6: jax.Array | float) -> jax.Array:
    """Six phase quantities → VSD coordinates, amplitude invariant.

    Args:
        x6: The phase quantities, last axis (a1, b1, c1, a2, b2, c2).

    Returns:
        (α, β, x, y, o1, o2) along the last axis.
    """
    return jnp.asarray(x6) @ jnp.asarray(VSD_AMPLITUDE.T)


def vsd_to_phases(v6: jax.Array | float) -> jax.Array:
    """Inverse of :func:`phases_to_vsd`.

    Args:
        v6: The VSD values (α, β, x, y, 0+, 0−), last axis of 6.

    Returns:
        The six phase values, last axis of 6.
    """
    return jnp.asarray(v6) @ jnp.asarray(3.0 * VSD_AMPLITUDE)


def sets_to_vsd(
    a1: jax.Array, b1: jax.Array, a2: jax.Array, b2: jax.Array
) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """The two sets' Clarke vectors → VSD: z_αβ = (s1 + s2)/2, z_xy = conj(s1 − s2)/2 (module doc).

    Args:
        a1: Set 1's α component (set 1's stationary frame).
        b1: Set 1's β component.
        a2: Set 2's α component (set 1's stationary frame).
        b2: Set 2's β component.

    Returns:
        ``(α, β, x, y)``.
    """
    return (a1 + a2) / 2, (b1 + b2) / 2, (a1 - a2) / 2, (b2 - b1) / 2


def vsd_to_sets(
    a: jax.Array, b: jax.Array, x: jax.Array, y: jax.Array
) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """VSD → the two sets' Clarke vectors: s1,2 = z_αβ ± conj(z_xy).

    Args:
        a: α.
        b: β.
        x: x.
        y: y.

    Returns:
        ``(a1, b1, a2, b2)``, both sets in set 1's stationary frame.
    """
    return a + x, b - y, a - x, b + y


class DualPMSMParams(eqx.Module):
    """A dual three-phase PMSM (SI, amplitude-invariant VSD variables).

    Args:
        m: The αβ subspace as a :class:`PMSMParams`: per-phase Rs, the VSD inductances Ld, Lq, ψf (peak
            phase flux), each phase's BEMF harmonics a5, a7 (they land in xy), and the *whole* machine's J,
            B, rated torque and speed.
        Lls: The xy-subspace inductance (the leakage), H (> 0).

    Raises:
        ValueError: A value of the wrong type or out of its range.
    """

    m: PMSMParams
    Lls: jax.Array

    def __init__(self, m: PMSMParams, Lls):
        if not isinstance(m, PMSMParams):
            raise ValueError(f"DualPMSMParams.m must be a PMSMParams, got {type(m).__name__}")
        self.m = m
        self.Lls = check_positive("Lls", Lls, "DualPMSMParams")

    @property
    def p(self) -> int:
        """The pole pairs."""
        return self.m.p

    @property
    def kt(self) -> jax.Array:
        """Torque constant at i_d = 0 and zero xy current, N·m per A of |i_αβ| (peak): 3 p ψf."""
        return 3.0 * self.m.p * self.m.psi_f

    def per_set(self) -> PMSMParams:
        """Each set as a three-phase machine carrying half the rotor: the αβ parameters with half of J, B
        and the rated torque.  With both sets carrying the same currents (zero xy) its equations are the
        dual machine's, per set; the FOC's speed loop and the observers are designed on it."""
        m = self.m
        return eqx.tree_at(lambda q: (q.J, q.B, q.T_rated), m, (m.J / 2, m.B / 2, m.T_rated / 2))

    def set_self(self) -> PMSMParams:
        """One set alone (:meth:`per_set` with its self inductances): with the other set's current zero,
        ψ_s1 = (L + Lls)/2 · i_s1, so Ld,q,self = (Ld,q + Lls)/2 (the individual-set current loops)."""
        q = self.per_set()
        return eqx.tree_at(lambda r: (r.Ld, r.Lq), q, ((q.Ld + self.Lls) / 2, (q.Lq + self.Lls) / 2))


def dual_ipmsm_paper002(J: float | None = None, **overrides: Any) -> DualPMSMParams:
    """002's dual three-phase IPMSM (ASSUMED: our copy lacks its machine table; papers.IPMSM_002 per set).

    Two of the single IPMSM's sets on one shaft: per phase the single machine's Rs, Ld, Lq, ψf, so each set
    is :func:`jaxobs.drive.bench_machine` ``("ipmsm002")`` (harmonics aside) when both carry the same current;
    twice its bench inertia, friction and rated torque (60 N·m at 8.9 A per phase).  The xy inductance
    Lls = papers.DUAL_LLS_002 and the 5th/7th BEMF harmonics a5, a7 = papers.DUAL_A5_002/DUAL_A7_002 are
    fitted on 002's C-LESO numbers under individual-set control (Figs 13-14: papers.py says how).

    Args:
        J: The inertia, kg·m² (default twice papers.BENCH_J_002, the bench).
        **overrides: Keywords of the αβ :class:`PMSMParams`, and ``Lls``.

    Returns:
        The :class:`DualPMSMParams`.
    """
    kw = dict(papers.IPMSM_002)
    kw.update(a5=papers.DUAL_A5_002, a7=papers.DUAL_A7_002)
    kw.update(J=2 * papers.BENCH_J_002 if J is None else J, B=2 * kw["B"], T_rated=2 * kw["T_rated"])
    lls = overrides.pop("Lls", papers.DUAL_LLS_002)
    kw.update(overrides)
    return DualPMSMParams(PMSMParams(**kw), lls)


def pm_flux_vsd(par: DualPMSMParams, theta_e: jax.Array | float) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """The PM flux's rate per electrical rad/s, e/ωe, in VSD coordinates (α, β, x, y), V·s.

    Args:
        par: The dual machine.
        theta_e: The electrical angle, rad.

    Returns:
        ``(α, β, x, y)``, V·s.
    """
    m = par.m
    phi = theta_e - jnp.asarray(PHASE_ANGLES, dtype=jnp.result_type(theta_e, float))
    g = -jnp.sin(phi) + m.a5 * jnp.sin(5 * phi) - m.a7 * jnp.sin(7 * phi)
    v = phases_to_vsd(m.psi_f * g)
    return v[0], v[1], v[2], v[3]


def dual_torque(par: DualPMSMParams, x: jax.Array) -> jax.Array:
    """Electromagnetic torque (module doc).

    Args:
        par: The machine.
        x: The state [i_d, i_q, i_x, i_y, ω_m, θ_e].

    Returns:
        The torque, N·m.
    """
    m = par.m
    i_d, i_q, i_x, i_y, th = x[0], x[1], x[2], x[3], x[5]
    k_a, k_b, k_x, k_y = pm_flux_vsd(par, th)
    i_a, i_b = dq_to_ab(i_d, i_q, th)
    pm = k_a * i_a + k_b * i_b + k_x * i_x + k_y * i_y
    return 3.0 * m.p * (pm + (m.Ld - m.Lq) * i_d * i_q)


def dual_vf(
    par: DualPMSMParams,
    x: jax.Array,
    u_vsd: tuple[jax.Array, jax.Array, jax.Array, jax.Array],
    t_load: jax.Array | float,
) -> jax.Array:
    """The dual machine's vector field.

    Args:
        par: The machine.
        x: The state [i_d, i_q, i_x, i_y, ω_m, θ_e].
        u_vsd: ``(u_α, u_β, u_x, u_y)``, V.
        t_load: The load torque, N·m.

    Returns:
        dx/dt.
    """
    m = par.m
    i_d, i_q, i_x, i_y, w_m, th = x[0], x[1], x[2], x[3], x[4], x[5]
    w_e = m.p * w_m
    k_a, k_b, k_x, k_y = pm_flux_vsd(par, th)
    e_d, e_q = ab_to_dq(w_e * k_a, w_e * k_b, th)
    u_d, u_q = ab_to_dq(u_vsd[0], u_vsd[1], th)
    di_d = (u_d - m.Rs * i_d + w_e * m.Lq * i_q - e_d) / m.Ld
    di_q = (u_q - m.Rs * i_q - w_e * m.Ld * i_d - e_q) / m.Lq
    di_x = (u_vsd[2] - m.Rs * i_x - w_e * k_x) / par.Lls
    di_y = (u_vsd[3] - m.Rs * i_y - w_e * k_y) / par.Lls
    dw = (dual_torque(par, x) - t_load - m.B * w_m) / m.J
    return jnp.stack([di_d, di_q, di_x, di_y, dw, w_e])


class DualPlantInput(NamedTuple):
    """What drives the machine over one period: each set's applied Clarke voltage (set 1's frame).

    Attributes:
        u_a1: Set 1's α voltage, V.
        u_b1: Set 1's β voltage, V.
        u_a2: Set 2's α voltage, V.
        u_b2: Set 2's β voltage, V.
        t_load: The load torque, N·m.
    """

    u_a1: jax.Array
    u_b1: jax.Array
    u_a2: jax.Array
    u_b2: jax.Array
    t_load: jax.Array  # load torque, N·m


class DualPlantOutput(NamedTuple):
    """The machine at t_k.

    Attributes:
        i_d: The αβ subspace's rotor-frame d current, A.
        i_q: The αβ subspace's rotor-frame q current, A.
        i_x: The xy subspace's x current, A.
        i_y: The xy subspace's y current, A.
        omega_m: The mechanical speed, rad/s.
        theta_e: The electrical angle, rad, wrapped.
        i_a1: Set 1's α current (set 1's stationary frame), A.
        i_b1: Set 1's β current, A.
        i_a2: Set 2's α current (set 1's stationary frame), A.
        i_b2: Set 2's β current, A.
        torque: The electromagnetic torque, N·m.
    """

    i_d: jax.Array  # αβ subspace, rotor frame, A
    i_q: jax.Array
    i_x: jax.Array  # xy subspace, A
    i_y: jax.Array
    omega_m: jax.Array  # rad/s
    theta_e: jax.Array  # rad, wrapped
    i_a1: jax.Array  # each set's Clarke currents (set 1's stationary frame), A
    i_b1: jax.Array
    i_a2: jax.Array
    i_b2: jax.Array
    torque: jax.Array  # N·m


class DualPlantState(AbstractRuleCarry):
    """The dual plant's state: ``x`` = [i_d, i_q, i_x, i_y, ω_m, θ_e] and the rule's carry."""

    x: jax.Array  # [i_d, i_q, i_x, i_y, ω_m, θ_e], shape (6,)
    rule: Any


class DualPMSM(AbstractComponent):
    """The dual machine ``par`` behind two inverters, integrated per control period.

    Args:
        par: The :class:`DualPMSMParams`.
        inverter: The :class:`Inverter` of each set (one per set, the same).
        dead_time: The dead time of each set, s; its error is added per set inside the vector field.
        ts: The control period, s.
        n_sub: Substeps per period (an integer ≥ 1).
        rule: The integration rule (default :class:`~jaxobs.RK4`).

    Raises:
        ValueError: A value out of its range, naming the field.
    """

    par: DualPMSMParams
    inverter: Inverter
    dead_time: jax.Array
    ts: float = eqx.field(static=True)
    n_sub: int = eqx.field(static=True)
    rule: AbstractRule = eqx.field(static=True)

    def __init__(
        self,
        par: DualPMSMParams,
        inverter: Inverter | None = None,
        dead_time: jax.Array | float = 0.0,
        *,
        ts: float = 1e-4,
        n_sub: int = 2,
        rule: AbstractRule | None = None,
    ) -> None:
        if not isinstance(par, DualPMSMParams):
            raise ValueError(f"DualPMSM.par must be a DualPMSMParams, got {type(par).__name__}")
        self.par = par
        self.inverter = Inverter() if inverter is None else inverter
        self.dead_time = check_nonnegative("dead_time", dead_time, "DualPMSM")
        self.ts = check_sample_time("ts", ts, "DualPMSM")
        if isinstance(n_sub, bool) or not isinstance(n_sub, int) or n_sub < 1:
            raise ValueError(f"DualPMSM.n_sub must be an integer >= 1, got {n_sub!r}")
        self.n_sub = n_sub
        self.rule = check_rule(RK4() if rule is None else rule, "DualPMSM")

    def set_currents(self, x: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
        """Each set's Clarke currents at state ``x``.

        Args:
            x: The state [i_d, i_q, i_x, i_y, ω_m, θ_e].

        Returns:
            ``(i_a1, i_b1, i_a2, i_b2)``, A.
        """
        i_a, i_b = dq_to_ab(x[0], x[1], x[5])
        return vsd_to_sets(i_a, i_b, x[2], x[3])

    def field(self, x: jax.Array, inp: jax.Array) -> jax.Array:
        """The vector field under the inverters.

        Args:
            x: The state [i_d, i_q, i_x, i_y, ω_m, θ_e].
            inp: ``(u_a1, u_b1, u_a2, u_b2, T_L)`` (applied, limited; dead time added here).

        Returns:
            dx/dt.
        """
        i_a1, i_b1, i_a2, i_b2 = self.set_currents(x)
        d_a1, d_b1 = self.inverter.dead_time_error(self.dead_time, i_a1, i_b1)
        # set 2's own phases are 30° ahead: its dead-time error is set 1's formula in its own frame
        c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
        j_a, j_b = c * i_a2 + s * i_b2, -s * i_a2 + c * i_b2
        e_a, e_b = self.inverter.dead_time_error(self.dead_time, j_a, j_b)
        d_a2, d_b2 = c * e_a - s * e_b, s * e_a + c * e_b
        u = sets_to_vsd(inp[0] + d_a1, inp[1] + d_b1, inp[2] + d_a2, inp[3] + d_b2)
        return dual_vf(self.par, x, u, inp[4])

    def init(self, op: OperatingPoint | None = None) -> DualPlantState:
        """The machine's initial state.

        Args:
            op: An :class:`OperatingPoint` (its αβ currents i_d, i_q, speed and angle; zero xy current), or
                None: at rest at θe = 0.

        Returns:
            The plant state.
        """
        dtype = jnp.result_type(self.par.m.Rs, float)
        vals = (0.0,) * 6 if op is None else (op.i_d, op.i_q, 0.0, 0.0, op.omega_m, op.theta_e)
        x0 = jnp.stack([jnp.asarray(v, dtype) for v in vals])
        return DualPlantState(x=x0, rule=self.rule.init(self.field, x0, None))

    def output(self, x: jax.Array) -> DualPlantOutput:
        """What the dual plant shows at the state ``x``.

        Args:
            x: The state [i_d, i_q, i_x, i_y, ω_m, θ_e].

        Returns:
            The :class:`DualPlantOutput`.
        """
        i_a1, i_b1, i_a2, i_b2 = self.set_currents(x)
        return DualPlantOutput(x[0], x[1], x[2], x[3], x[4], x[5], i_a1, i_b1, i_a2, i_b2, dual_torque(self.par, x))

    def step(self, state: DualPlantState, inp: DualPlantInput) -> tuple[DualPlantState, DualPlantOutput]:
        """One control period of the dual plant under held voltages.

        Args:
            state: The :class:`DualPlantState`.
            inp: The :class:`DualPlantInput`.

        Returns:
            ``(the next state, the output at the period's start)``.
        """
        out = self.output(state.x)
        path = Held(tuple(inp))
        h = self.ts / self.n_sub
        x, rs = state.x, state.rule
        for _ in range(self.n_sub):
            x, rs = self.rule.step(self.field, x, path, h, rs)
        x = x.at[5].set(wrap(x[5]))
        return DualPlantState(x=x, rule=rs), out
