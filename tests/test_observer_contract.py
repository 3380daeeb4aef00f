"""The one drive-observer contract: every observer subclasses AbstractObserver; a drive observer is
bound to a machine and a speed by its one ``bind`` and starts with ``init_at`` / ``seed_speed``.

The old bindings (drive_study.bind_observer's body, jaxobs_tuning.export.bind_to_drive,
jaxobs_tuning.job._bind_recording,
the reproductions' constructors) are written out here as they were, and ``bind`` is checked against them,
clamp included, with the two deliberate differences named where they are tested."""

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs
from jaxobs import drive as D
from jaxobs import linear, papers
from jaxobs.observers import (
    AbstractDriveObserver,
    AbstractFluxObserver,
    AbstractLESO,
    AbstractObserver,
    AbstractVectorFieldObserver,
    BoundFields,
    DriveObserverState,
)
from jaxobs.reproduce import flux as RF
from jaxobs.reproduce import leso as RL
from jaxobs.studies.drive import bind_observer, drive_gains

SPMSM = D.bench_machine("spmsm000")
IPMSM = D.bench_machine("ipmsm002")
KP, KI = linear.pll_gains(2 * math.pi * 20.0)

FLL_FLUX = {
    "SOIFO": lambda: jaxobs.SOIFO(0.0, 1.0, 1.4, 0.5, 100.0),
    "SecondOrderSOIFO": lambda: jaxobs.SecondOrderSOIFO(
        0.0, 1.0, papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2, 0.6, 100.0
    ),
}
PLL_FLUX = {
    "PureIntegratorFlux": lambda: jaxobs.PureIntegratorFlux(0.0, 1.0, KP, KI),
    "LPFFlux": lambda: jaxobs.LPFFlux(0.0, 1.0, 100.0, KP, KI),
}
LESOS = {
    "CLESO": lambda: jaxobs.CLESO(0.0, 1.0),
    "GILESO": lambda: jaxobs.GILESO(0.0, 1.0),
    "FALESO": lambda: jaxobs.FALESO(0.0, 1.0),
}


def _leaves_equal(a, b):
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    return len(la) == len(lb) and all(
        jnp.asarray(x).dtype == jnp.asarray(y).dtype and bool(jnp.all(x == y)) for x, y in zip(la, lb)
    )


def _old_bind_observer(obs, sc):
    """jaxobs.studies.drive.bind_observer before the contract (family guessed by hasattr)."""
    est, w_e = sc.est_par, sc.est_par.p * sc.omega_m0
    if hasattr(obs, "Lq"):
        return eqx.tree_at(lambda o: (o.Rs, o.Lq, o.omega0_pll), obs, (est.Rs, est.Lq, w_e))
    # L̂q where the old binding took L̂d: the flux observers estimate the active flux (jaxobs.observers.flux,
    # "Salient machines"); the two agree on a non-salient assumed machine, and this test's scales make it salient
    return eqx.tree_at(lambda o: (o.Rs, o.L, o.omega_init), obs, (est.Rs, est.Lq, jnp.maximum(jnp.abs(w_e), 1.0)))


def _scenario(par, rpm, scale=(1.0, 1.0, 1.0)):
    """A scenario at ``rpm`` whose assumed machine has Rs, Ld, Lq scaled by ``scale``."""
    est = eqx.tree_at(
        lambda m: (m.Rs, m.Ld, m.Lq), par, tuple(getattr(par, k) * s for k, s in zip(("Rs", "Ld", "Lq"), scale))
    )
    return D.Scenario(par, est_par=est, omega_m0=rpm * D.RPM)


def test_every_observer_subclasses_the_one_abstract_observer():
    for cls in (jaxobs.SOGIFLL, jaxobs.SOGIFLLWPF, jaxobs.SOGIFLLWIF, jaxobs.SOGI, jaxobs.SOGI2):
        assert issubclass(cls, AbstractVectorFieldObserver) and issubclass(cls, AbstractObserver)
    for cls in (*(c().__class__ for c in {**FLL_FLUX, **PLL_FLUX, **LESOS}.values()), jaxobs.ObserverBank):
        assert issubclass(cls, AbstractDriveObserver) and issubclass(cls, AbstractObserver)
    # one state class for both drive families
    assert type(FLL_FLUX["SOIFO"]().init()) is type(LESOS["CLESO"]().init()) is DriveObserverState


@pytest.mark.parametrize("name", [*FLL_FLUX, *LESOS])
@pytest.mark.parametrize("rpm", [1000.0, -300.0, 0.0, 0.05])
def test_bind_equals_the_old_study_binding(name, rpm):
    """bind(est_par, p̂·ω_m0) is what drive_study.bind_observer set, the flux observers' max(|ω|, 1) clamp
    included (1 rad/s is their omega_min's default), for the FLL flux observers and the LESOs."""
    par = SPMSM if name in FLL_FLUX else IPMSM
    sc = _scenario(par, rpm, (1.3, 0.8, 1.2))
    obs = {**FLL_FLUX, **LESOS}[name]()
    assert _leaves_equal(bind_observer(obs, sc), _old_bind_observer(obs, sc))
    assert _leaves_equal(obs.bind(sc.est_par, sc.est_par.p * sc.omega_m0), _old_bind_observer(obs, sc))


@pytest.mark.parametrize("name", list(PLL_FLUX))
def test_a_pll_flux_observer_starts_at_the_signed_speed(name):
    """Behaviour change: the old study binding gave a PLL flux observer max(|ω|, 1) (the FLL's clamp), while its
    own init_at started the PLL at the signed ω.  bind now agrees with init_at: signed, unclamped (a PLL's
    speed is signed and may be zero).  Above 1 rad/s forwards, nothing changes."""
    obs = PLL_FLUX[name]()
    fwd = _scenario(SPMSM, 1000.0)
    assert _leaves_equal(bind_observer(obs, fwd), _old_bind_observer(obs, fwd))
    for rpm in (-300.0, 0.05):
        sc = _scenario(SPMSM, rpm)
        w = float(sc.est_par.p * sc.omega_m0)
        bound = bind_observer(obs, sc)
        assert float(bound.omega_init) == w != float(_old_bind_observer(obs, sc).omega_init)


@pytest.mark.parametrize("name", [*FLL_FLUX, *PLL_FLUX, *LESOS])
def test_the_bound_speed_is_where_init_at_starts(name):
    """One definition of the start speed: bind's initial-speed field, init() of the bound observer, init_at and
    seed_speed all agree, at any speed."""
    obs = {**FLL_FLUX, **PLL_FLUX, **LESOS}[name]()
    for w in (-50.0, 0.0, 0.3, 700.0):
        bound = obs.bind(SPMSM, w)
        assert _leaves_equal(bound.init(), obs.init_at(w))
        assert _leaves_equal(bound.init_at(w), obs.init_at(w))
        assert _leaves_equal(obs.seed_speed(obs.init(), w), obs.init_at(w))


@pytest.mark.parametrize("name", [*FLL_FLUX, *PLL_FLUX, *LESOS])
def test_init_aligned_sets_only_a_pll_angle(name):
    """A steady start's settling phase starts the observer at the rotor's angle where it has an angle state of its
    own (a LESO's PLL θ̂, wrapped), and is init_at elsewhere (a flux observer's angle comes from its filters)."""
    obs = {**FLL_FLUX, **PLL_FLUX, **LESOS}[name]()
    aligned, at = obs.init_aligned(300.0, 7.0), obs.init_at(300.0)
    if name in LESOS:
        assert float(aligned.x[obs.n_leso]) == pytest.approx(7.0 - 2 * math.pi)
        assert _leaves_equal(eqx.tree_at(lambda s: s.x, aligned, aligned.x.at[obs.n_leso].set(0.0)), at)
    else:
        assert _leaves_equal(aligned, at)


def test_bind_sets_only_its_bound_fields_and_keeps_dtypes():
    obs32 = jax.tree.map(lambda x: x.astype(jnp.float32) if eqx.is_inexact_array(x) else x, FLL_FLUX["SOIFO"]())
    bound = obs32.bind(SPMSM, 314.0)
    fields = type(obs32).bound_fields
    changed = {f for f in fields.names if float(getattr(bound, f)) != float(getattr(obs32, f))}
    assert changed == {"Rs", "L", "omega_init"} == set(fields.names)
    assert (fields.resistance, fields.inductance, fields.speed) == ("Rs", "L", "omega_init")
    assert all(x.dtype == jnp.float32 for x in jax.tree.leaves(bound))
    assert float(bound.L) == pytest.approx(float(SPMSM.Ld)) and float(bound.k) == float(obs32.k)
    assert LESOS["CLESO"]().bind(IPMSM, 1.0).Lq == IPMSM.Lq  # a LESO takes Lq (its model's inductance)
    # est_par None: a recording gives the speed, not the machine (old jaxobs_tuning.job._bind_recording)
    leso = LESOS["FALESO"]()
    only = leso.bind(None, -42.0)
    assert float(only.omega0_pll) == -42.0 and float(only.Rs) == float(leso.Rs) and float(only.Lq) == 1.0
    soifo = FLL_FLUX["SOIFO"]()
    assert float(soifo.bind(None, -0.5).omega_init) == 1.0 and float(soifo.bind(None, -0.5).L) == 1.0


def test_the_export_binding_now_clamps():
    """Behaviour change (a bug fix): jaxobs_tuning.export.bind_to_drive set a flux observer's omega0 to ω_e unclamped
    (0 at standstill: a SOGI centre frequency SOIFO refuses); bind clamps it as the studies did.  At the
    recordings' speeds (1000 r/min) the two agree."""
    obs = FLL_FLUX["SOIFO"]()

    def old_export(o, machine, rpm):  # jaxobs_tuning.export.bind_to_drive before the contract
        we = float(rpm) * math.pi / 30 * int(machine.p)
        vals = (machine.Rs, machine.Ld, we)
        vals = tuple(jnp.asarray(v, jnp.result_type(getattr(o, n))) for n, v in zip(("Rs", "L", "omega_init"), vals))
        return eqx.tree_at(lambda x: (x.Rs, x.L, x.omega_init), o, vals)

    assert _leaves_equal(obs.bind(SPMSM, 1000.0 * math.pi / 30 * int(SPMSM.p)), old_export(obs, SPMSM, 1000.0))
    assert float(old_export(obs, SPMSM, 0.0).omega_init) == 0.0 and float(obs.bind(SPMSM, 0.0).omega_init) == 1.0


def test_the_reproductions_banks_are_their_old_constructions():
    est, w = D.bench_machine("spmsm000", Rs=0.9), 2 * math.pi * 100.0
    kp, ki = linear.pll_gains(2 * math.pi * papers.FLUX_PLL_HZ)
    k, K1, K2 = RF.K_SOIFO, RF.K1, RF.K2
    old = jaxobs.ObserverBank(
        (
            jaxobs.PureIntegratorFlux(est.Rs, est.Ld, kp, ki, omega0=w),
            jaxobs.LPFFlux(est.Rs, est.Ld, papers.LPF_OMEGA_C, kp, ki, omega0=w),
            jaxobs.SOIFO(est.Rs, est.Ld, k, k**2 / 4, omega0=w),
            jaxobs.SecondOrderSOIFO(est.Rs, est.Ld, K1, K2, K1**3 / (2 * K2), omega0=w),
        ),
        primary=3,
    )
    assert _leaves_equal(RF.flux_bank(est, w), old)
    est, w = D.bench_machine("ipmsm002", Lq=1.5 * float(IPMSM.Lq)), 2 * math.pi * 25.0
    kp, ki = linear.pll_gains(2 * math.pi * papers.LESO_PLL_HZ)
    old = jaxobs.ObserverBank(
        (
            jaxobs.CLESO(est.Rs, est.Lq, RL.W0, kp, ki, w),
            jaxobs.GILESO(est.Rs, est.Lq, RL.W0, RL.K_R, RL.WC_GI, kp, ki, w),
            jaxobs.FALESO(est.Rs, est.Lq, RL.K1_FA, RL.K2_FA, kp, ki, w),
        ),
        primary=2,
    )
    assert _leaves_equal(RL.leso_bank(est, w), old)


def test_drive_gains_leave_out_the_bound_fields():
    """A flux observer's omega_init is its start speed (bound), a C-LESO's omega0 its bandwidth (a gain)."""
    assert "omega_init" not in drive_gains(FLL_FLUX["SOIFO"]()) and set(drive_gains(FLL_FLUX["SOIFO"]())) == {
        "k",
        "lam",
    }
    assert set(drive_gains(LESOS["CLESO"]())) == {"omega0", "kp_pll", "ki_pll"}
    assert issubclass(type(FLL_FLUX["SOIFO"]()), AbstractFluxObserver)
    assert issubclass(type(LESOS["CLESO"]()), AbstractLESO)


def test_bank_refuses_a_signal_observer_and_binds_every_member():
    with pytest.raises(ValueError, match=r"ObserverBank.observers\[0\] must be a drive observer"):
        jaxobs.ObserverBank((jaxobs.SOGIFLL(1.4, 1000.0),))
    with pytest.raises(ValueError, match="is not a drive observer"):
        bind_observer(jaxobs.SOGIFLL(1.4, 1000.0), _scenario(SPMSM, 100.0))
    bank = jaxobs.ObserverBank((FLL_FLUX["SOIFO"](), LESOS["CLESO"]()), primary=1)
    bound = bank.bind(SPMSM, 200.0)
    assert all(_leaves_equal(b, o.bind(SPMSM, 200.0)) for b, o in zip(bound.observers, bank.observers))
    assert bound.ts == bank.observers[1].ts


# --- a user's own drive observer in the closed loop ------------------------------------------------------------


class _CurrentAngleOut(NamedTuple):
    theta: jax.Array
    omega: jax.Array


class _CurrentAngleState(NamedTuple):
    theta_prev: jax.Array
    omega: jax.Array
    started: jax.Array


class CurrentAngle(AbstractDriveObserver):
    """A user's toy drive observer: θ̂e from the measured current's angle (with i_d = 0 the current leads θe by
    90°), ω̂e a first-order filter of its increments.  Only meaningful in a sensored drive."""

    omega0: jax.Array  # start speed, rad/s
    alpha: jax.Array  # speed filter bandwidth, rad/s
    ts: float = eqx.field(static=True, default=1e-4)

    bound_fields = BoundFields(speed="omega0")

    def bind(self, est_par, omega_e):
        return eqx.tree_at(lambda o: o.omega0, self, jnp.asarray(omega_e, dtype=self.omega0.dtype))

    def init(self, u0=None):
        z = jnp.zeros_like(self.omega0)
        return _CurrentAngleState(theta_prev=z, omega=self.omega0, started=jnp.asarray(False))

    def init_at(self, omega_e):
        return self.bind(None, omega_e).init()

    def seed_speed(self, state, omega_e):
        return state._replace(omega=jnp.asarray(omega_e, dtype=state.omega.dtype))

    def step(self, state, u):
        th = jaxobs.metrics.wrap(jnp.arctan2(u.i_b, u.i_a) - jnp.pi / 2)
        rate = jaxobs.metrics.wrap(th - state.theta_prev) / self.ts
        w = jnp.where(state.started, state.omega + self.alpha * self.ts * (rate - state.omega), state.omega)
        return _CurrentAngleState(theta_prev=th, omega=w, started=jnp.asarray(True)), _CurrentAngleOut(th, state.omega)


def _foc(par):
    return D.FOC.imc(par, 2 * math.pi * papers.BENCH_CURRENT_HZ, 2 * math.pi * papers.BENCH_SPEED_HZ)


def test_a_user_drive_observer_runs_in_the_closed_loop():
    """Steady start: ClosedLoop starts it with init_at at the true speed; it tracks the rotor (sensored).
    I-f start-up: ClosedLoop holds its speed at the I-f frequency with seed_speed while mode is 0."""
    user = CurrentAngle(jnp.asarray(0.0), jnp.asarray(200.0))
    load = D.Profile.constant(0.5 * float(SPMSM.T_rated))  # i_q > 0: the current has an angle
    sc = D.Scenario(SPMSM, speed_ref=D.Profile.constant(1000 * D.RPM), load=load, omega_m0=1000 * D.RPM)
    out = jaxobs.simulate(D.ClosedLoop(D.Drive(_foc(SPMSM), settle=0.0), bind_observer(user, sc), sc), 0.02).outputs
    w_e = float(SPMSM.p * 1000 * D.RPM)
    assert float(out.obs.omega[0]) == pytest.approx(w_e, rel=1e-12)  # init_at, not init()'s bound omega0 alone
    err = np.abs(np.asarray(jaxobs.metrics.wrap(out.obs.theta - out.theta_e)))[10:]
    assert np.max(err) < 0.05 and abs(float(out.obs.omega[-1]) / w_e - 1) < 0.01

    start = D.IfStartup.for_machine(SPMSM)
    drive = D.Drive(_foc(SPMSM), startup=start, sensorless=True)
    sol = jaxobs.simulate(D.ClosedLoop(drive, user, sc), 0.02)
    mode, omega = np.asarray(sol.outputs.mode), np.asarray(sol.outputs.obs.omega)
    assert np.all(mode == 0)  # still ramping
    k = np.arange(1, mode.size)
    # the output at k is the speed the loop seeded after step k − 1: the I-f frequency ramp((k − 1) ts)
    want = np.asarray(jax.vmap(start.ramp)(jnp.asarray((k - 1) * drive.ts)))
    np.testing.assert_allclose(omega[1:], want, rtol=0, atol=1e-9)
    assert np.max(want) > 0
