"""The PMSM drive: plant vs diffrax, power balance, sensored FOC, batching, gradients, validation."""

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs
from jaxobs import drive as D
from jaxobs import linear, metrics, papers
from jaxobs.studies.drive import bind_observer

TS = 1e-4


# --------------------------------------------------------------------------
# plant against a tight diffrax solution
# --------------------------------------------------------------------------


def _open_loop_case(n=400):
    t = TS * np.arange(n)
    ua, ub = 60 * np.cos(2 * np.pi * 20 * t), 60 * np.sin(2 * np.pi * 20 * t)
    return jnp.asarray(ua), jnp.asarray(ub), jnp.full(n, 2.0)


def _scan_plant(par, inv, ua, ub, tl, n_sub, rule, dead_time=0.0):
    """The plant component alone under held voltages: its states at every t_k (the user's own scan)."""
    plant = D.PMSM(par, inv, dead_time, ts=TS, n_sub=n_sub, rule=rule)

    def step(state, u):
        state, _ = plant.step(state, u)
        return state, state.x

    _, xs = jax.lax.scan(step, plant.init(), D.PlantInput(ua, ub, tl))
    return jnp.concatenate([plant.init().x[None], xs], axis=0)


def _diffrax_plant(par, inv, ua, ub, tl, dead_time):
    n = ua.shape[0]
    u = jnp.stack([ua, ub, tl], 1)

    def vf(t, x, args):
        idx = jnp.clip(jnp.floor(t / TS + 1e-9).astype(int), 0, n - 1)  # voltage held over each period
        return D.plant_field(par, inv, dead_time, x, u[idx])

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(vf),
        diffrax.Dopri8(),
        0.0,
        n * TS,
        1e-5,
        jnp.zeros(4),
        stepsize_controller=diffrax.PIDController(rtol=1e-12, atol=1e-12, jump_ts=jnp.asarray(TS * np.arange(1, n))),
        saveat=diffrax.SaveAt(ts=jnp.asarray(TS * np.arange(n + 1))),
        max_steps=100_000,
    )
    return np.asarray(sol.ys)


@pytest.mark.parametrize("rule, order", [(jaxobs.Euler(), 1), (jaxobs.RK4(), 4)], ids=["Euler", "RK4"])
def test_scan_plant_converges_to_diffrax_at_the_rules_order(rule, order):
    """IPMSM with 5th/7th BEMF harmonics under held rotating voltages, 40 ms.  Max error over
    (i_d, i_q, ωm) against Dopri8 at rtol 1e-12: RK4 3.1e-7, 1.9e-8, 1.4e-9 for 1, 2, 4
    substeps (slope 3.9); Euler 0.83, 0.40, 0.20 (slope 1.0)."""
    par = D.ipmsm_paper002(inertia="motor", a5=0.03, a7=0.02)
    inv = D.Inverter()
    ua, ub, tl = _open_loop_case()
    ref = _diffrax_plant(par, inv, ua, ub, tl, 0.0)
    errs = []
    for n_sub in (1, 2, 4):
        xs = np.asarray(_scan_plant(par, inv, ua, ub, tl, n_sub, rule))
        errs.append(np.max(np.abs(xs[:, :3] - ref[:, :3])))
    slope = -np.polyfit(np.log([1, 2, 4]), np.log(errs), 1)[0]
    assert abs(slope - order) <= 0.3, (slope, errs)
    if order == 4:
        assert errs[1] < 1e-7  # the drive's default (RK4, 2 substeps): stated tolerance 1e-7 A, rad/s


def test_dead_time_plant_matches_diffrax():
    """With the (smoothed) dead-time error, RK4 with 8 substeps still follows the reference."""
    par = D.spmsm_paper000(inertia="motor")
    inv = D.Inverter(i_smooth=0.5)
    ua, ub, tl = _open_loop_case()
    ref = _diffrax_plant(par, inv, 2 * ua, 2 * ub, 0 * tl, 2e-6)
    xs = np.asarray(_scan_plant(par, inv, 2 * ua, 2 * ub, 0 * tl, 8, jaxobs.RK4(), dead_time=2e-6))
    assert np.max(np.abs(xs[:, :3] - ref[:, :3])) < 1e-5


# --------------------------------------------------------------------------
# closed loop, sensored
# --------------------------------------------------------------------------

PAR = D.spmsm_paper000(inertia="motor")
FOC = D.FOC.imc(PAR, alpha_c=2 * math.pi * 300, alpha_s=2 * math.pi * 20)
DRIVE = D.Drive(FOC)


@pytest.fixture(scope="module")
def speed_and_load_run():
    sc = D.Scenario(
        PAR, speed_ref=D.Scenario.speed_rpm([0.0, 0.01], [0, 2000]), load=D.Scenario.load_steps([0.0, 0.3], [0.0, 10.0])
    )
    return jaxobs.simulate(D.ClosedLoop(DRIVE, None, sc), 0.6)


def test_sensored_speed_step_then_load_step(speed_and_load_run):
    """SPMSM of 000, α_c = 2π·300, α_s = 2π·20 rad/s (I-P speed loop).  Measured: the 0 → 2000 r/min
    step settles (2 %) in 44.7 ms with no overshoot — the double pole at −α_s predicts
    5.83/α_s = 46.4 ms; the 10 N·m step dips 841 r/min (J is only 3.78e-4 kg·m²: 26,000 rad/s²
    until i_q catches up) and recovers within 2 % in 41 ms."""
    sol = speed_and_load_run
    t, rpm = np.asarray(sol.t), np.asarray(sol.outputs.speed_rpm)
    first = t < 0.3
    settle = float(metrics.settling_time(t[first], rpm[first], 2000.0, 40.0, 0.01))
    overshoot = rpm[first].max() / 2000 - 1
    assert settle == pytest.approx(5.83 / (2 * math.pi * 20), rel=0.10), settle
    assert overshoot < 0.005
    settle_load = float(metrics.settling_time(t, rpm, 2000.0, 40.0, 0.3))
    dip = 2000 - rpm[~first].min()
    assert 0.030 <= settle_load <= 0.050, settle_load
    assert 700 <= dip <= 950, dip
    # in steady state the load is carried: Te = TL + Bω, i_q = TL/K_t
    assert float(sol.outputs.i_q[-1]) == pytest.approx(10.0 / float(PAR.kt), rel=1e-3)
    assert bool(sol.ok)


def test_power_balance_at_steady_state(speed_and_load_run):
    """Electrical input = copper loss + mechanical output within 0.5 % (last 100 ms, 2000 r/min, 10 N·m).

    Input power per period is (3/2) u·ī with u the held applied voltage and ī the trapezoid
    mean of the sampled currents at both ends of the period (error O((ωe Ts)²) ≈ 3e-4)."""
    sol = speed_and_load_run
    ua, ub = np.asarray(sol.outputs.u_a), np.asarray(sol.outputs.u_b)
    ia, ib = np.asarray(sol.outputs.i_a), np.asarray(sol.outputs.i_b)
    sl = slice(-1000, -1)
    p_in = 1.5 * (ua[sl] * 0.5 * (ia[sl] + ia[1:][sl]) + ub[sl] * 0.5 * (ib[sl] + ib[1:][sl]))
    p_cu = 1.5 * float(PAR.Rs) * (ia[sl] ** 2 + ib[sl] ** 2)
    p_mech = np.asarray(sol.outputs.torque)[sl] * np.asarray(sol.outputs.omega_m)[sl]
    balance = (p_in.mean() - p_cu.mean() - p_mech.mean()) / p_in.mean()
    assert abs(balance) < 0.005, balance
    assert p_mech.mean() == pytest.approx(10.0 * 2000 * math.pi / 30, rel=0.01)


def test_current_loop_time_constant_matches_imc():
    """Locked rotor, i_q* step 0 → 5 A.  The equivalent time constant of a type-1 loop,
    ∫(1 − i_q/i_q*) dt, is 1/α_c for the IMC design whatever the computation delay (the
    delay shortens the 10–90 % rise instead: 0.68/α_c·ln 9 at α_c = 2π·300, 10 kHz)."""
    par = D.spmsm_paper000(J=1e3)
    for fc in (200.0, 300.0):
        ac = 2 * math.pi * fc
        foc = D.FOC.imc(par, alpha_c=ac, alpha_s=2 * math.pi * 20, outer="current")
        sc = D.Scenario(par, speed_ref=D.Profile([0.0, 0.002], [0.0, 5.0], kind="step"))
        sol = jaxobs.simulate(D.ClosedLoop(D.Drive(foc), None, sc), 0.03)
        t, iq = np.asarray(sol.t), np.asarray(sol.outputs.i_q)
        after = t >= 0.002
        tau = np.sum(1 - iq[after] / 5.0) * TS
        assert tau * ac == pytest.approx(1.0, abs=0.10), (fc, tau * ac)
        assert iq[-1] == pytest.approx(5.0, rel=1e-4)


def test_mtpa_and_ipmsm_torque():
    par = D.ipmsm_paper002(inertia="motor")
    foc = D.FOC.imc(par, alpha_c=2 * math.pi * 300, alpha_s=2 * math.pi * 10, id_mode="mtpa")
    sc = D.Scenario(
        par,
        speed_ref=D.Profile.constant(600 * D.RPM),
        load=D.Scenario.load_steps([0.0, 0.05], [0.0, 20.0]),
        omega_m0=600 * D.RPM,
    )
    sol = jaxobs.simulate(D.ClosedLoop(D.Drive(foc), None, sc), 0.6)
    i_d, i_q = float(sol.outputs.i_d[-1]), float(sol.outputs.i_q[-1])
    dl = float(par.Lq - par.Ld)
    a = float(par.psi_f) / (2 * dl)
    assert i_d == pytest.approx(a - math.sqrt(a * a + i_q * i_q), rel=2e-3)  # on the MTPA curve
    assert i_d < -0.1
    assert float(sol.outputs.torque[-1]) == pytest.approx(20.0 + float(par.B) * 600 * D.RPM, rel=1e-3)


def test_if_startup_switches_over():
    par = D.spmsm_paper000(inertia="motor")
    start = D.IfStartup(i_f=6.0, accel=2 * math.pi * 20 / 0.2, omega_switch=3 * 20 * D.RPM)  # 20 r/min
    drv = D.Drive(FOC, startup=start)
    sc = D.Scenario(par, speed_ref=D.Scenario.speed_rpm([0.0, 0.4], [20, 200], ramp=0.2))
    sol = jaxobs.simulate(D.ClosedLoop(drv, None, sc), 1.0)
    mode = np.asarray(sol.outputs.mode)
    t = np.asarray(sol.t)
    t_switch = t[np.argmax(mode == 1)]
    assert mode[0] == 0 and mode[-1] == 1
    # measured 70.7 ms: no sooner than the ramp to 20 r/min (10 ms at the mean acceleration) and the agreement's
    # 20 ms dwell; 0.5 ms (5 samples) for last-bit differences elsewhere moving the agreement's instant
    assert t_switch == pytest.approx(0.0707, abs=5e-4)
    assert float(sol.outputs.speed_rpm[-1]) == pytest.approx(200.0, abs=1.0)


def test_sensor_offsets_and_noise_are_applied():
    sens = D.Sensors(i_offset=(0.0, 1.5), u_offset=(5.0, 0.0), i_noise=0.1)
    um_a, um_b, im_a, im_b = sens.measure(jax.random.PRNGKey(0), 3, 10.0, 20.0, 1.0, 2.0)
    assert float(um_a) == 15.0 and float(um_b) == 20.0
    assert float(im_b) != 3.5 and abs(float(im_b) - 3.5) < 1.0
    # the same key and sample index give the same noise
    assert float(sens.measure(jax.random.PRNGKey(0), 3, 10.0, 20.0, 1.0, 2.0)[3]) == float(im_b)


def test_dead_time_voltage_error():
    inv = D.Inverter(udc=540.0, f_pwm=10e3)
    du_a, du_b = inv.dead_time_error(2e-6, 10.0, 0.0)  # i_a > 0, i_b = i_c < 0
    # phase a: −ΔU, b and c: +ΔU  →  αβ: (−(4/3)ΔU, 0) with ΔU = Udc Td fpwm = 10.8 V
    assert float(du_a) == pytest.approx(-4 / 3 * 10.8)
    assert float(du_b) == pytest.approx(0.0, abs=1e-12)
    smooth = D.Inverter(i_smooth=0.5).dead_time_error(2e-6, 10.0, 0.0)
    assert float(smooth[0]) == pytest.approx(float(du_a), rel=1e-6)


# --------------------------------------------------------------------------
# batches and gradients
# --------------------------------------------------------------------------


def test_jit_vmap_over_256_scenarios():
    base = D.Scenario(PAR, load=D.Profile.constant(5.0))
    batch = D.grid(
        base, speed_rpm=np.linspace(200, 2000, 16), dRs=np.linspace(-0.5, 0.5, 4), dL=np.linspace(-0.2, 0.2, 4)
    )
    assert batch.size == 256 and batch.shape == (16, 4, 4) and batch.dims == ("speed_rpm", "dRs", "dL")
    run = jax.jit(jax.vmap(lambda s: jaxobs.simulate(D.ClosedLoop(DRIVE, None, s), 0.3)))
    sol = run(batch.scenarios)
    assert sol.outputs.omega_m.shape == (256, 3000)
    assert bool(jnp.all(sol.ok))
    w_end = np.asarray(sol.outputs.omega_m[:, -1]).reshape(batch.shape)
    np.testing.assert_allclose(
        w_end, np.broadcast_to(np.linspace(200, 2000, 16)[:, None, None] * D.RPM, batch.shape), rtol=2e-3
    )
    # the grid is labelled: element (i, j, k) has the i-th speed, j-th dRs, k-th dL
    est_rs = np.asarray(batch.scenarios.est_par.Rs).reshape(batch.shape)
    np.testing.assert_allclose(est_rs[3, :, 1], float(PAR.Rs) * (1 + np.linspace(-0.5, 0.5, 4)))


def test_grad_of_speed_error_wrt_speed_pi_gain_matches_finite_differences():
    sc = D.Scenario(
        PAR,
        speed_ref=D.Scenario.speed_rpm([0.0, 0.005], [0, 1000]),
        load=D.Scenario.load_steps([0.0, 0.06], [0.0, 4.0]),
    )

    def loss(kp_w):
        drv = eqx.tree_at(lambda d: d.foc.kp_w, DRIVE, kp_w)
        sol = jaxobs.simulate(D.ClosedLoop(drv, None, sc), 0.1)
        return jnp.mean((sol.outputs.omega_m - sol.outputs.omega_m_ref) ** 2)

    k0 = FOC.kp_w
    g = float(jax.jit(jax.grad(loss))(k0))  # one program (eagerly: the forward and backward passes apart)
    f = jax.jit(loss)
    h = 1e-6 * float(k0)
    fd = (float(f(k0 + h)) - float(f(k0 - h))) / (2 * h)
    assert np.isfinite(g)
    assert g == pytest.approx(fd, rel=1e-4)


# --------------------------------------------------------------------------
# validation
# --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(Ld=0.0), "PMSMParams.Ld"),
        (dict(Lq=-1e-3), "PMSMParams.Lq"),
        (dict(Rs=-0.1), "PMSMParams.Rs"),
        (dict(J=0.0), "PMSMParams.J"),
        (dict(J=-1.0), "PMSMParams.J"),
        (dict(p=2.5), "PMSMParams.p"),
        (dict(p=0), "PMSMParams.p"),
        (dict(p=-3), "PMSMParams.p"),
        (dict(p="3"), "PMSMParams.p"),
        (dict(psi_f=float("nan")), "PMSMParams.psi_f"),
    ],
)
def test_bad_machine_parameters(kwargs, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        D.spmsm_paper000(**kwargs)


def test_bad_sample_times_and_settings():
    with pytest.raises(ValueError, match=r"FOC\.ts"):
        D.FOC.imc(PAR, 1000.0, 100.0, ts=0.0)
    with pytest.raises(ValueError, match=r"FOC\.ts"):
        D.FOC.imc(PAR, 1000.0, 100.0, ts=-1e-4)
    with pytest.raises(ValueError, match="alpha_c"):
        D.FOC.imc(PAR, -1.0, 100.0)
    with pytest.raises(ValueError, match=r"Drive\.n_sub"):
        D.Drive(FOC, n_sub=0)
    with pytest.raises(ValueError, match="grid axis 'spin'"):
        D.grid(D.Scenario(PAR), spin=[1.0])
    with pytest.raises(ValueError, match="observer"):
        D.ClosedLoop(D.Drive(FOC, sensorless=True), None, D.Scenario(PAR))
    assert D.spmsm_paper000(inertia="motor", p=3.0).p == 3


# --------------------------------------------------------------------------
# steady starts (no transient nobody asked for)
# --------------------------------------------------------------------------


def test_encoder_drive_started_at_speed_stays_within_half_a_percent_from_t0():
    """300 and 1000 r/min, 0 and 5 N·m, constant reference and load: |ω − ω*| ≤ 0.5 % of ω* over the whole
    horizon.  Measured: ≤ 1.3e-4 of ω* (the old zero start braked to −24 % of the reference at 1000 r/min, 5 N·m)."""
    base = D.Scenario(PAR, omega_m0=1.0, theta_e0=0.4)
    batch = D.grid(base, speed_rpm=[300.0, 1000.0], load_nm=[0.0, 5.0])
    sc = batch.scenarios  # D.grid starts each scenario at its speed_rpm (omega_m0), whatever the base's
    np.testing.assert_allclose(np.asarray(sc.omega_m0), np.asarray(sc.speed_ref.values[:, 0]), rtol=1e-12)
    sol = jax.jit(jax.vmap(lambda s: jaxobs.simulate(D.ClosedLoop(DRIVE, None, s), 0.3)))(sc)
    w, w_ref = np.asarray(sol.outputs.omega_m), np.asarray(sol.outputs.omega_m_ref)
    rel = np.max(np.abs(w - w_ref), axis=1) / w_ref[:, 0]
    assert np.all(rel <= 5e-3), rel
    # and it is steady, not merely in the band: the loaded cases carry their load current from t = 0
    iq0 = np.asarray(sol.outputs.i_q)[:, 0].reshape(batch.shape)
    np.testing.assert_allclose(iq0[:, 1], 5.0 / float(PAR.kt), rtol=1e-9)
    np.testing.assert_allclose(iq0[:, 0], 0.0, atol=1e-12)


def test_sensorless_drive_starts_locked():
    """FA-LESO + PLL closing the loop from t = 0 (no hand-over) at 600 r/min and 10 N·m on the IPMSM (MTPA off):
    after the settling phase before t = 0 its position error stays under 0.1° and the speed within 0.1 %."""
    par = D.ipmsm_paper002(inertia="motor")
    foc = D.FOC.imc(par, alpha_c=2 * math.pi * 300, alpha_s=2 * math.pi * 5)
    w_e = par.p * 600 * D.RPM
    obs = jaxobs.FALESO(par.Rs, par.Lq, omega0_pll=w_e)  # 002 Table II gains, the default 15 Hz PLL
    sc = D.Scenario(par, speed_ref=D.Profile.constant(600 * D.RPM), load=D.Profile.constant(10.0), omega_m0=600 * D.RPM)
    sol = jaxobs.simulate(D.ClosedLoop(D.Drive(foc, sensorless=True), obs, sc), 0.2)
    o = sol.outputs
    err = np.degrees(np.asarray(metrics.wrap(o.obs.theta - o.theta_e)))
    assert np.max(np.abs(err)) < 0.1, np.max(np.abs(err))
    assert np.max(np.abs(np.asarray(o.omega_m) / (600 * D.RPM) - 1)) < 1e-3
    # the drive's truth is θe (metrics.position_error, what the objective and the report plot)
    np.testing.assert_array_equal(np.degrees(np.asarray(metrics.position_error(sol))), err)


def _bench(name):
    """A bench of the drive jobs (jaxobs.drive.bench): its machine and its sensorless drive."""
    par = D.bench_machine(name)
    return par, D.bench_drive(par)


def _steady_start_run(name, horizon=0.1):
    """The observer ``name`` closing the loop from t = 0 at 300 and 1000 r/min, 0 and 5 N·m (constant)."""
    if name == "LPFFlux":
        par, drive = _bench("spmsm000")
        kp, ki = linear.pll_gains(2 * math.pi * papers.FLUX_PLL_HZ)
        obs = jaxobs.LPFFlux(par.Rs, par.Ld, papers.LPF_OMEGA_C, float(kp), float(ki))
    else:
        par, drive = _bench("ipmsm002")
        obs = getattr(jaxobs, name)(par.Rs, par.Lq)
    # D.grid starts each scenario at its speed_rpm
    sc = D.grid(D.Scenario(par, theta_e0=0.4), speed_rpm=[300.0, 1000.0], load_nm=[0.0, 5.0]).scenarios
    sol = jax.jit(jax.vmap(lambda s: jaxobs.simulate(D.ClosedLoop(drive, bind_observer(obs, s), s), horizon)))(sc)
    o = sol.outputs
    rel = np.max(np.abs(np.asarray(o.omega_m) / np.asarray(o.omega_m_ref) - 1), axis=1)
    err = np.degrees(np.asarray(metrics.wrap(o.obs.theta - o.theta_e)))
    return rel, err


# measured (float64, 0.1 s): max |ω/ω* − 1| over (300, 0), (300, 5), (1000, 0), (1000, 5) r/min, N·m, and the
# position error at t = 0 -> the end; started on the encoder's operating point instead (the steady start without
# the observer's error) the LPF dips 6.6 % at 300 r/min and loses the 5 N·m case (79 %), the C-LESO 2.2 %, the
# GI-LESO 0.80 %:
# LPFFlux  ≤ 6e-5, 46.7° (300) and 17.7° (1000) constant; CLESO ≤ 1e-5, −11.4° and −36.9° constant;
# GILESO ≤ 2.5e-3, −5.0 -> −4.3° and −17.2 -> −15.0° (its generalized integrator, ωc = π rad/s, is still
# settling after the 0.2 s phase: the error drifts on, −13.0° at 1 s, and the speed follows by ≤ 0.26 %;
# −18.1° at 1000 r/min before the settling phase started its PLL at the rotor's angle, init_aligned);
# FALESO ≤ 4e-5, 0.0° (no bias without a mismatch).
STEADY_START_LAG_DEG = {"LPFFlux": (46.7, 17.7), "CLESO": (-11.4, -36.9), "GILESO": (-5.0, -17.2), "FALESO": (0, 0)}


@pytest.mark.parametrize(
    "name",
    [
        "LPFFlux",
        "CLESO",
        pytest.param("GILESO", marks=pytest.mark.slow),
        pytest.param("FALESO", marks=pytest.mark.slow),
    ],
)
def test_sensorless_steady_start_holds_the_speed_within_half_a_percent_from_t0(name):
    """Every drive observer that closes the loop from t = 0 starts where it settles, the operating point under its
    own steady angle error (ClosedLoop.init, FOC.operating_point's offset): |ω − ω*| ≤ 0.5 % of ω* from t = 0
    at 300 and 1000 r/min, 0 and 5 N·m, and the position error at t = 0 is the observer's steady lag."""
    rel, err = _steady_start_run(name)
    assert np.all(rel <= 5e-3), rel
    lag300, lag1000 = STEADY_START_LAG_DEG[name]
    np.testing.assert_allclose(err[:, 0], [lag300, lag300, lag1000, lag1000], atol=0.2)
    if name in ("LPFFlux", "CLESO", "FALESO"):  # settled in the 0.2 s phase: the error stays where it started
        np.testing.assert_allclose(err[:, -1], err[:, 0], atol=0.05)


def test_settled_for_gives_the_observer_ten_electrical_periods_at_the_lowest_speed():
    """Drive.settled_for(ω_e): the steady start's settling phase covers SETTLE_PERIODS (10) electrical periods at
    ω_e, the flux observers' time constants scaling with 1/ω_e (docs/stability.md); never shorter than the
    drive's own settle; the rest of the drive unchanged; bad speeds named."""
    par, drive = _bench("spmsm000")
    w_e = par.p * 20 * D.RPM  # 20 r/min: 2π rad/s
    longer = drive.settled_for(w_e)
    assert D.SETTLE_PERIODS == 10.0 and longer.settle == pytest.approx(10 * 2 * math.pi / w_e, rel=1e-12)
    assert (longer.foc, longer.sensorless, longer.handover, longer.n_sub) == (drive.foc, True, 0.0, drive.n_sub)
    assert drive.settled_for(par.p * 2000 * D.RPM) is drive  # 0.01 s needed: the 0.2 s default stays
    for bad in (0.0, -1.0, float("nan"), 0.5):  # 0.5 rad/s would need 126 s (> 60 s)
        with pytest.raises(ValueError, match="omega_e_min"):
            drive.settled_for(bad)


def test_operating_point_under_an_angle_offset_carries_the_load_in_the_controllers_frame():
    """FOC.operating_point with the controller's frame 30° behind the rotor's (a lagging observer): the references
    (i_d* = 0, i_q*) rotated by −30° carry the load, and FOC.init's integrators produce the machine's voltage in
    that frame (zero errors: integrator + decoupling = the voltage)."""
    par, drive = _bench("ipmsm002")
    foc = drive.foc.bind(par, 1e3)
    w, off = 600 * D.RPM, math.radians(-30.0)
    op = foc.operating_point(par, w, w, 0.0, 10.0, off)
    torque = 1.5 * par.p * (par.psi_f * op.i_q + (par.Ld - par.Lq) * op.i_d * op.i_q)
    assert float(torque) == pytest.approx(10.0 + float(par.B) * w, rel=1e-9)
    c, s = math.cos(off), math.sin(off)
    i_dc, i_qc = c * op.i_d + s * op.i_q, -s * op.i_d + c * op.i_q  # the controller's frame
    assert float(i_dc) == pytest.approx(0.0, abs=1e-9)  # i_d* = 0 in its own frame
    cs = foc.init(op)
    assert float(cs.iq_ref) == pytest.approx(float(i_qc), rel=1e-12)
    w_e, u_dc, u_qc = par.p * w, c * op.u_d + s * op.u_q, -s * op.u_d + c * op.u_q
    assert float(cs.int_d - w_e * par.Lq * i_qc) == pytest.approx(float(u_dc), rel=1e-9)
    assert float(cs.int_q + w_e * (par.Ld * i_dc + par.psi_f)) == pytest.approx(float(u_qc), rel=1e-9)
    # without an offset it is the rotor frame's operating point
    op0 = foc.operating_point(par, w, w, 0.0, 10.0)
    assert float(op0.offset) == 0.0 and float(op0.i_d) == pytest.approx(0.0, abs=1e-12)


def test_ok_is_false_for_a_non_finite_observer_or_plant_signal():
    """``sol.ok`` (SaveAll and SaveFinal) is False when the observer's estimate is NaN — even in a sensored
    drive, where it never feeds back and the plant runs on — or when the plant's signals are (a NaN inertia,
    which the constructors would refuse, set under jit); True for the healthy run beside them."""
    par = D.ipmsm_paper002(inertia="motor")
    drive = D.Drive(D.FOC.imc(par, 2 * math.pi * 300, 2 * math.pi * 5), settle=0.0)  # sensored
    obs = jaxobs.FALESO(par.Rs, par.Lq)
    sc = D.Scenario(par, omega_m0=600 * D.RPM, speed_ref=D.Profile.constant(600 * D.RPM))

    @jax.jit
    def run(k1, J):
        o = eqx.tree_at(lambda o: o.k1, obs, k1)
        s = eqx.tree_at(lambda s: s.par.J, sc, J)
        loop = D.ClosedLoop(drive, o, s)
        full = jaxobs.simulate(loop, 0.003)
        return full.ok, jaxobs.simulate(loop, 0.003, save=jaxobs.SaveFinal()).ok, jnp.isfinite(full.outputs.omega_m)

    k1, J = jnp.asarray(float(obs.k1)), jnp.asarray(float(sc.par.J))
    assert [bool(x) for x in run(k1, J)[:2]] == [True, True]
    ok_all, ok_final, plant_finite = run(jnp.nan, J)  # the observer diverges, the plant does not
    assert bool(jnp.all(plant_finite)) and not bool(ok_all) and not bool(ok_final)
    ok_all, ok_final, _ = run(k1, jnp.nan)
    assert not bool(ok_all) and not bool(ok_final)


def test_one_scenario_builder_starts_at_speed_and_checks_its_axes():
    """D.grid and the studies share scenario_batch: speed_rpm also sets omega_m0 (a steady start), the
    mismatch axes set the assumed machine from the true one, a noise axis makes the sensors noisy, a seed
    axis or the batch seed gives the keys; unknown axes and values out of range are named."""
    base = D.Scenario(PAR, load=D.Profile.constant(5.0))
    batch = D.grid(base, speed_rpm=[300.0, 600.0], dLd=[0.1], dLq=[-0.2], i_noise=[0.0, 0.5])
    sc = batch.scenarios
    np.testing.assert_allclose(np.asarray(sc.omega_m0), np.repeat([300.0, 600.0], 2) * D.RPM, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(sc.speed_ref.values[:, 0]), np.asarray(sc.omega_m0), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(sc.load.values[:, 0]), 5.0)
    np.testing.assert_allclose(np.asarray(sc.est_par.Ld), float(PAR.Ld) * 1.1, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(sc.est_par.Lq), float(PAR.Lq) * 0.8, rtol=1e-12)
    assert sc.sensors.noisy and list(np.asarray(sc.sensors.i_noise)) == [0.0, 0.5, 0.0, 0.5]
    steps = D.scenario_batch(base, ("speed_rpm", "speed_step_rpm"), [(300.0, 60.0)], seed=4, t_event=0.1)
    np.testing.assert_allclose(np.asarray(steps.speed_ref.values[0]), np.array([300.0, 360.0]) * D.RPM)
    np.testing.assert_array_equal(np.asarray(steps.speed_ref.times[0]), [0.0, 0.1])
    np.testing.assert_array_equal(steps.key[0], jax.random.fold_in(jax.random.PRNGKey(4), 0))
    seeded = D.scenario_batch(base, ("seed",), [(3.0,), (5.0,)])
    np.testing.assert_array_equal(seeded.key[1], jax.random.PRNGKey(5))
    with pytest.raises(ValueError, match=r"grid axis dRs must be in \[-0.95, 10\]"):
        D.grid(base, dRs=[-2.0])
    with pytest.raises(ValueError, match="give dL or dLd/dLq"):
        D.grid(base, dL=[0.1], dLq=[0.1])


def test_an_observer_at_another_period_than_the_drive_is_refused():
    """An observer built at its default ts (1e-4 s) closing a 20 kHz drive stepped the wrong interval every period
    and ran silently wrong (the whole speed as its speed error); the closed loop refuses it in one line naming both
    periods, and takes it built at the drive's."""
    par = D.ipmsm_paper002(inertia="motor")
    foc = D.FOC.imc(par, alpha_c=2 * math.pi * 300, alpha_s=2 * math.pi * 5, ts=5e-5)
    drive = D.Drive(foc, sensorless=True)
    sc = D.Scenario(par, speed_ref=D.Profile.constant(600 * D.RPM), omega_m0=600 * D.RPM)
    with pytest.raises(ValueError, match=r"observer runs at ts = 0.0001 s, the drive at 5e-05 s: they must agree"):
        D.ClosedLoop(drive, jaxobs.FALESO(par.Rs, par.Lq), sc)
    assert D.ClosedLoop(drive, jaxobs.FALESO(par.Rs, par.Lq, ts=drive.ts), sc).observer.ts == drive.ts


def test_the_d_priority_voltage_limit_has_finite_derivatives():
    """A drive file with field weakening keeps u_d* first (``d_priority``): beyond the limit u_d* is clipped to
    ±u_max and u_q* gets no room.  That room's square root was taken at 0, whose infinite slope times the clip's zero
    tangent made the voltage's derivative, and every derivative of the run after it, NaN."""
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "docs" / "examples" / "pmsyrm_5p6kw_sat.toml"
    drive = D.read_drive(path).drive_for(sensorless=True)
    assert isinstance(drive, D.Drive)
    foc = drive.foc
    assert foc.d_priority
    cs = eqx.tree_at(lambda s: s.int_d, foc.init(), -3.0 * foc.u_max)  # u_d* far beyond the limit: clipped

    def voltage(i_a):
        zero, w_e, w_m = jnp.asarray(0.0), jnp.asarray(300.0), jnp.asarray(150.0)
        inp = D.FOCInput(jnp.asarray(1), i_a, zero, zero, w_e, w_m, w_m)  # k = 1: the speed loop holds
        _, out = foc.step(cs, inp)
        return jnp.stack([out.u_a, out.u_b])

    u, du = jax.jvp(voltage, (jnp.asarray(2.0),), (jnp.asarray(1.0),))
    assert float(jnp.hypot(u[0], u[1])) == pytest.approx(float(foc.u_max), rel=1e-6)  # on the limit, all of it u_d
    assert np.all(np.isfinite(np.asarray(du)))
