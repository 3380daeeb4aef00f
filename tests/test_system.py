"""The one contract and the one loop: a user's own lax.scan of a system equals jaxobs.simulate, element for element.

Also: every drive piece is a step component, the save strategies agree, and
simulate's checks (horizon, memory, strategy objects) give one-line errors.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs
from jaxobs import drive as D
from jaxobs import papers

PAR = D.spmsm_paper000(inertia="motor")
FOC = D.FOC.imc(PAR, alpha_c=2 * math.pi * 300, alpha_s=2 * math.pi * 20)


def _user_scan(system, n):
    """What a user writes: scan the system's own step over the sample indices."""
    return jax.jit(lambda s: jax.lax.scan(s.step, s.init(), jnp.arange(n)))(system)


def _assert_trees_equal(a, b):
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    assert jax.tree.structure(a) == jax.tree.structure(b)
    for x, y in zip(la, lb):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_user_scan_of_the_closed_loop_equals_simulate_exactly():
    """Encoder drive, speed ramp and a load step inside the horizon: every output, every sample, bit for bit."""
    sc = D.Scenario(
        PAR,
        speed_ref=D.Scenario.speed_rpm([0.0, 0.002], [0, 600], ramp=0.01),
        load=D.Scenario.load_steps([0.0, 0.02], [0.0, 3.0]),
        sensors=D.Sensors(i_noise=0.05, u_offset=(1.0, 0.0)),
    )
    system = D.ClosedLoop(D.Drive(FOC), None, sc)
    n = 300
    final, outs = _user_scan(system, n)
    sol = jaxobs.simulate(system, n * system.ts)
    assert isinstance(sol.outputs, D.DriveOutput) and sol.outputs.omega_m.shape == (n,)
    _assert_trees_equal(outs, sol.outputs)
    _assert_trees_equal(final, sol.final_state)
    np.testing.assert_array_equal(np.asarray(sol.t), np.asarray(outs.t))
    assert bool(sol.ok) and float(jnp.max(outs.omega_m)) > 10.0  # it really ran up to speed


def test_user_scan_of_a_sensorless_closed_loop_equals_simulate_exactly():
    """An observer closing the loop (FA-LESO + PLL on the IPMSM, observer from the hand-over on)."""
    par = D.ipmsm_paper002(inertia="motor")
    foc = D.FOC.imc(par, alpha_c=2 * math.pi * 300, alpha_s=2 * math.pi * 10)
    w_e = par.p * 300 * D.RPM
    obs = jaxobs.FALESO(
        par.Rs, par.Lq, papers.FALESO_K1, papers.FALESO_K2, *jaxobs.linear.pll_gains(2 * math.pi * 15), w_e
    )
    sc = D.Scenario(par, speed_ref=D.Profile.constant(300 * D.RPM), omega_m0=300 * D.RPM)
    system = D.ClosedLoop(D.Drive(foc, sensorless=True, handover=0.005), obs, sc)
    n = 200
    final, outs = _user_scan(system, n)
    sol = jaxobs.simulate(system, n * system.ts)
    _assert_trees_equal(outs, sol.outputs)
    _assert_trees_equal(final, sol.final_state)


def test_user_scan_of_an_observer_on_a_signal_equals_simulate_exactly():
    """SOGI-FLL-WIF with AB3 (its RK4 start-up steps included) on paper 001's Test B: sag and phase jump."""
    obs = jaxobs.linear.wif_closed_form()
    system = jaxobs.OnSignal(obs, jaxobs.paper001_test("B", t_event=0.01))
    n = 400
    final, outs = _user_scan(system, n)
    sol = jaxobs.simulate(system, n * obs.ts)
    assert isinstance(sol.outputs, jaxobs.SignalOutput)
    _assert_trees_equal(outs, sol.outputs)
    _assert_trees_equal(final, sol.final_state)


def test_drive_pieces_are_step_components():
    """PMSM, Sensors, Inverter and FOC share one base (AbstractComponent) and one init convention, init(op)
    with keyword-only extras, and step with named inputs and outputs."""
    op = D.OperatingPoint.at_rest(0.0)._replace(omega_m=jnp.asarray(100.0))
    plant = D.PMSM(PAR, ts=1e-4)
    ps, y = plant.step(plant.init(op), D.PlantInput(jnp.asarray(10.0), jnp.asarray(0.0), jnp.asarray(0.0)))
    assert float(y.omega_m) == 100.0 and ps.x.shape == (4,)
    assert bool(jnp.all(plant.init().x == 0)) and float(plant.init(D.OperatingPoint.at_rest(0.7)).x[3]) == 0.7
    sens = D.Sensors(u_offset=(5.0, 0.0))
    key, meas = sens.step(sens.init(op, key=jax.random.PRNGKey(1)), D.SensorInput(3, 10.0, 20.0, 1.0, 2.0))
    assert isinstance(meas, jaxobs.DriveInput) and float(meas.u_a) == 15.0
    inv = D.Inverter(udc=100.0)
    _, u = inv.step(inv.init(), D.InverterInput(jnp.asarray(1000.0), jnp.asarray(0.0)))
    assert float(u.u_a) == pytest.approx(100.0 / math.sqrt(3))
    foc = FOC.bind(PAR, inv.u_max)
    for component in (plant, sens, inv, foc):
        assert isinstance(component, D.AbstractComponent)
    cs, c = foc.step(foc.init(), D.FOCInput(0, 0.0, 0.0, 0.0, 0.0, 0.0, 10.0))
    assert isinstance(c, D.FOCOutput) and float(cs.int_w) > 0.0  # I-P: the speed error enters the integrator
    with pytest.raises(TypeError, match="'est' and 'u_max'"):  # a FOC is whole when built: no half-built one
        D.FOC(1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 10.0)


def test_save_strategies_agree():
    """SaveFinal(cost) = ts·Σ cost over SaveAll's trajectory; SaveAll(cost) gives the same cost."""
    obs = jaxobs.linear.sogi_fll_closed_form()
    system = jaxobs.OnSignal(obs, jaxobs.paper001_test("A", t_event=0.01))

    def cost(o):
        return (o.obs.omega - o.truth.omega) ** 2

    full = jaxobs.simulate(system, 0.03, save=jaxobs.SaveAll(cost=cost))
    fin = jaxobs.simulate(system, 0.03, save=jaxobs.SaveFinal(cost=cost))
    ref = obs.ts * np.sum((np.asarray(full.outputs.obs.omega) - np.asarray(full.outputs.truth.omega)) ** 2)
    np.testing.assert_allclose(float(fin.cost), ref, rtol=1e-12)
    np.testing.assert_allclose(float(full.cost), ref, rtol=1e-12)
    assert fin.outputs is None and fin.t is None and bool(fin.ok)
    _assert_trees_equal(fin.final_state, full.final_state)


def test_simulate_rejects_bad_horizons_and_strategies():
    system = jaxobs.OnSignal(jaxobs.linear.sogi_fll_closed_form(), jaxobs.paper001_test("A"))
    for t1, match in (
        (float("inf"), "t1 must be finite"),
        (float("nan"), "t1 must be finite"),
        (0.0, "at least one sample"),
        (1e-5, "at least one sample"),
        (1e9, "more than 2"),
    ):
        with pytest.raises(ValueError, match=match):
            jaxobs.simulate(system, t1)
    with pytest.raises(ValueError, match="GiB"):  # 2e9 samples would not fit: refused before anything runs
        jaxobs.simulate(system, 2.0e5)
    with pytest.raises(ValueError, match="save must be"):
        jaxobs.simulate(system, 0.01, save="all")
    with pytest.raises(ValueError, match="checkpoint must be a checkpoint strategy"):
        jaxobs.simulate(system, 0.01, checkpoint="auto")
    with pytest.raises(ValueError, match="ForwardSensitivity serves loops without per-step outputs"):
        jaxobs.simulate(system, 0.01, checkpoint=jaxobs.ForwardSensitivity())
    with pytest.raises(ValueError, match="system must be a jaxobs.AbstractSystem.*OnSignal"):
        jaxobs.simulate(jaxobs.linear.sogi_fll_closed_form(), 0.01)
    with pytest.raises(ValueError, match="OnSignal.signal"):
        jaxobs.OnSignal(jaxobs.linear.sogi_fll_closed_form(), 3.0)
    with pytest.raises(ValueError, match="ClosedLoop.scenario"):
        D.ClosedLoop(D.Drive(FOC), None, PAR)


def test_final_ok_reads_the_final_state_only():
    """Solution.final_ok (the tuning objective's divergence flag): the final state finite, per scenario under
    vmap; a run that blows up is not final_ok, one that does not is, and with SaveFinal it equals ok."""
    sigs = jaxobs.stack([jaxobs.paper001_test("A", t_event=0.05) for _ in range(2)])
    # forward Euler at 1 kHz: k = 40 blows up (test_tuning's diverging candidates), k = 0.7 does not
    good, bad = (jaxobs.SOGIFLL(k=k, lam=12000.0, rule=jaxobs.Euler(), ts=1e-3) for k in (0.7, 40.0))

    def flags(obs, save):
        sol = jax.vmap(lambda s: jaxobs.simulate(jaxobs.OnSignal(obs, s), 0.2, save=save))(sigs)
        return np.asarray(jax.vmap(lambda x: x.final_ok)(sol)), np.asarray(sol.ok)

    for obs, want in ((good, True), (bad, False)):
        fin, ok = flags(obs, jaxobs.SaveAll())
        assert fin.shape == (2,) and np.all(fin == want) and np.all(ok == want)
        fin, ok = flags(obs, jaxobs.SaveFinal())
        assert np.array_equal(fin, ok)
