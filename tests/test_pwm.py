"""Carrier-comparison PWM (jaxobs.drive.pwm, PMSM under Inverter(pwm="carrier")): the period average, the dead
time's edges, the sub-interval integration against diffrax, vmap, a sensored closed loop on two machines, and
the drive file's keys."""

import math
from pathlib import Path

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs
from jaxobs import drive as D
from jaxobs.drive.plant import PlantState
from jaxobs.drive.pwm import N_INTERVALS, carrier_intervals, modulation_indices, switching_instants

TS = 1e-4
LAB = Path(__file__).parents[1] / "docs" / "examples" / "ipmsm_2p2kw_lab.toml"


def _random_voltages(n, udc, seed=0):
    rng = np.random.default_rng(seed)
    mag = udc / math.sqrt(3) * np.sqrt(rng.uniform(0, 1, n))  # uniform over the disc |u| ≤ U_dc/√3
    ang = rng.uniform(-math.pi, math.pi, n)
    return jnp.asarray(mag * np.cos(ang)), jnp.asarray(mag * np.sin(ang))


def test_period_average_is_the_commanded_voltage():
    """Without dead time and drops the switched voltage averages, over the carrier period, to the commanded one
    (min-max injection keeps every |m_x| ≤ 1 inside the circle, and Clarke drops the zero sequence): stated error
    1e-12 of U_dc (rounding; measured 1.1e-13 over 500 vectors up to the circle's edge).  Seven sub-intervals,
    none negative, summing to T."""
    udc = 540.0
    ua, ub = _random_voltages(500, udc)
    h, va, vb = jax.vmap(lambda a, b: carrier_intervals(udc, TS, 0.0, 0.0, a, b, jnp.ones(3)))(ua, ub)
    assert h.shape == (500, N_INTERVALS)
    assert float(jnp.min(h)) >= 0.0
    np.testing.assert_allclose(np.asarray(h.sum(1)), TS, rtol=1e-12)
    err = max(float(jnp.max(jnp.abs((h * va).sum(1) / TS - ua))), float(jnp.max(jnp.abs((h * vb).sum(1) / TS - ub))))
    assert err < 1e-12 * udc, err
    # the edges by carrier comparison: min-max injection puts the largest and smallest phase at ±m, the same
    # distance from the rails, and each phase's pulse is centred on the period
    m = modulation_indices(ua, ub, udc)
    np.testing.assert_allclose(np.asarray(m.max(1) + m.min(1)), 0.0, atol=1e-12)
    rise, fall = jax.vmap(lambda mm: switching_instants(mm, TS, 0.0, jnp.ones(3)))(m)
    np.testing.assert_allclose(np.asarray(rise + fall), TS, rtol=1e-12)
    np.testing.assert_allclose(np.asarray((fall - rise) / TS), np.asarray((1 + m) / 2), atol=1e-12)


def test_dead_time_shifts_each_edge_by_the_current_sign_and_matches_the_averaged_error():
    """i > 0: the rising edge comes T_d late, the falling edge on time; i < 0: the falling edge comes T_d late.  A
    leg held at a rail (|m| = 1) does not switch and gets none.  Over the period the error is the averaged model's
    −U_dc T_d f_pwm sgn(i_x) per phase (Inverter.dead_time_error), and the device drop's −u_device sgn(i_x)
    (Inverter.device_drop_error), to rounding."""
    td = 2e-6
    m = jnp.asarray([0.3, -0.2, 1.0])
    s = jnp.asarray([1.0, -1.0, -1.0])
    r0, f0 = switching_instants(m, TS, 0.0, s)
    r1, f1 = switching_instants(m, TS, td, s)
    np.testing.assert_allclose(np.asarray(r1 - r0), [td, 0.0, 0.0], atol=1e-18)
    np.testing.assert_allclose(np.asarray(f1 - f0), [0.0, td, 0.0], atol=1e-18)
    # the sign's direction matters: the opposite signs move the opposite edges
    r2, f2 = switching_instants(m, TS, td, -s)
    np.testing.assert_allclose(np.asarray(r2 - r0), [0.0, td, 0.0], atol=1e-18)
    np.testing.assert_allclose(np.asarray(f2 - f0), [td, 0.0, 0.0], atol=1e-18)

    udc, u_dev = 540.0, 1.5
    inv = D.Inverter(udc, 1 / TS, u_device=u_dev)
    i_a, i_b = 3.0, -1.0  # phase currents 3, −2.37, −0.63 A
    ia, ib, ic = D.hardware.ab_to_abc(i_a, i_b)
    sg = jnp.sign(jnp.asarray([ia, ib, ic]))
    ua, ub = 80.0, 40.0  # well inside the linear range: every leg switches, no pulse vanishes
    h0, va0, vb0 = carrier_intervals(udc, TS, 0.0, 0.0, ua, ub, sg)
    h, va, vb = carrier_intervals(udc, TS, td, u_dev, ua, ub, sg)
    du = ((h * va).sum() / TS - ua, (h * vb).sum() / TS - ub)
    dt_a, dt_b = inv.dead_time_error(td, i_a, i_b)
    dd_a, dd_b = inv.device_drop_error(i_a, i_b)
    np.testing.assert_allclose(np.asarray(du), [float(dt_a + dd_a), float(dt_b + dd_b)], atol=1e-10)
    assert abs(float(dt_a)) > 5.0  # an error that matters: U_dc T_d f_pwm = 10.8 V per phase


def _schedule(udc, ua, ub):
    """Each period's sub-interval bounds (absolute, s) and voltages without dead time (state-independent)."""
    h, va, vb = jax.vmap(lambda a, b: carrier_intervals(udc, TS, 0.0, 0.0, a, b, jnp.ones(3)))(ua, ub)
    n = ua.shape[0]
    starts = TS * np.arange(n)[:, None] + np.concatenate([np.zeros((n, 1)), np.cumsum(np.asarray(h), 1)[:, :-1]], 1)
    return starts.ravel(), np.asarray(va).ravel(), np.asarray(vb).ravel()


def _carrier_diffrax(par, udc, ua, ub, x0):
    starts, va, vb = _schedule(udc, ua, ub)
    n = ua.shape[0]
    s_j, va_j, vb_j = jnp.asarray(starts), jnp.asarray(va), jnp.asarray(vb)

    def vf(t, x, args):
        j = jnp.clip(jnp.searchsorted(s_j, t + 1e-13, side="right") - 1, 0, s_j.shape[0] - 1)
        return D.machine.plant_vf(par, x, (va_j[j], vb_j[j]), 0.0)

    jumps = np.unique(np.round(starts[1:], 13))
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(vf),
        diffrax.Dopri8(),
        0.0,
        n * TS,
        1e-6,
        x0,
        stepsize_controller=diffrax.PIDController(rtol=1e-12, atol=1e-12, jump_ts=jnp.asarray(jumps)),
        saveat=diffrax.SaveAt(ts=jnp.asarray(TS * np.arange(n + 1))),
        max_steps=200_000,
    )
    return np.asarray(sol.ys)


def _scan(plant, x0, ua, ub):
    def step(state, u):
        state, _ = plant.step(state, D.PlantInput(u[0], u[1], 0.0))
        return state, state.x

    _, xs = jax.lax.scan(step, PlantState(x0, None), jnp.stack([ua, ub], 1))
    return np.concatenate([np.asarray(x0)[None], np.asarray(xs)], 0)


def test_sub_interval_integration_matches_diffrax_and_samples_the_mean():
    """The salient IPMSM of 002 (Ld 6 mH, Lq 12 mH) from i_dq = (−1, 3) A at 20 Hz: 200 periods (20 ms) of a
    20 Hz, 150 V rotating command on 540 V at 10 kHz.  The carrier plant (RK4 per sub-interval) against Dopri8 at
    rtol 1e-12 on the same switched voltage (jumps at every switching instant): max error over (i_d, i_q, ω_m) at
    the period ends measured 3.5e-7 (n_sub 1), 1.7e-8 (n_sub 2, the drive's default) and 8e-9 (n_sub 4, the
    reference's own floor): stated 1e-6 and 1e-7.  The states at the sample instants (the carrier's peak) stay
    within 1 % of the in-period ripple (i_q's peak to peak, 1.26 A) of the averaged plant's (measured 6.2e-4 A,
    0.05 %): the sample sees the mean, not the ripple."""
    par = D.ipmsm_paper002(inertia="motor")
    udc, n = 540.0, 200
    t = TS * (np.arange(n) + 0.5)
    ua, ub = jnp.asarray(150 * np.cos(2 * np.pi * 20 * t)), jnp.asarray(150 * np.sin(2 * np.pi * 20 * t))
    x0 = jnp.asarray([-1.0, 3.0, 2 * np.pi * 20 / float(par.p), 0.0])
    ref = _carrier_diffrax(par, udc, ua, ub, x0)
    errs = []
    for n_sub in (1, 2):
        plant = D.PMSM(par, D.Inverter(udc, 1 / TS, pwm="carrier"), 0.0, ts=TS, n_sub=n_sub)
        xs = _scan(plant, x0, ua, ub)
        xs[:, 3] = np.unwrap(xs[:, 3])
        errs.append(float(np.max(np.abs(xs[:, :3] - ref[:, :3]))))
    assert errs[0] < 1e-6 and errs[1] < 1e-7, errs

    # the sample at the carrier's peak against the averaged plant, measured against the ripple within a period
    carrier = D.PMSM(par, D.Inverter(udc, 1 / TS, pwm="carrier"), 0.0, ts=TS, n_sub=1)
    averaged = D.PMSM(par, D.Inverter(udc, 1 / TS), 0.0, ts=TS, n_sub=2)
    xc, xa = _scan(carrier, x0, ua, ub), _scan(averaged, x0, ua, ub)
    _, inside, _ = carrier.carrier_substeps(PlantState(jnp.asarray(xc[100]), None), D.PlantInput(ua[100], ub[100], 0.0))
    ripple = float(np.ptp(np.asarray(inside)[:, 1]))  # i_q's peak to peak within period 100
    gap = float(np.max(np.abs(xc[:, :2] - xa[:, :2])))
    assert ripple > 0.1, ripple  # there is a ripple to see
    assert gap < 0.01 * ripple, (gap, ripple)


def test_vmap_over_a_batch_equals_one_at_a_time():
    """One carrier period, vmapped over voltages, dead times and currents, gives each element's own result."""
    par = D.spmsm_paper000(inertia="motor")
    ua, ub = _random_voltages(8, 540.0, seed=1)
    td = jnp.linspace(0.0, 3e-6, 8)
    iq = jnp.linspace(-5.0, 5.0, 8)

    def one(a, b, d, q):
        plant = D.PMSM(par, D.Inverter(540.0, 1 / TS, pwm="carrier"), d, ts=TS)
        st = PlantState(jnp.stack([0.3, q, 50.0, 0.7]), None)
        return plant.step(st, D.PlantInput(a, b, 1.0))[0].x

    batch = jax.jit(jax.vmap(one))(ua, ub, td, iq)
    for k in range(8):
        np.testing.assert_allclose(np.asarray(batch[k]), np.asarray(one(ua[k], ub[k], td[k], iq[k])), rtol=1e-12)
    assert float(jnp.std(batch[:, 1])) > 0.0


def test_the_period_is_cut_once_not_in_every_rk4_stage():
    """The switching instants (the sorting network's minima) are computed once a period, however many RK4 steps
    integrate it: a vmapped step with a voltage per scenario, n_sub 1 and 2 compile to the same count.  Before
    carrier_intervals divided its results by one, XLA's CPU fusion copied them into every RK4 stage: 72 minima at
    n_sub 1 and 128 at 2, and the lab drive's carrier loop ran at 0.090 of the averaged loop's rate (0.242 now)."""
    par = D.spmsm_paper000(inertia="motor")
    x = jnp.zeros((16, 4)) + jnp.asarray([1.0, 2.0, 100.0, 0.3])
    ua = jnp.linspace(-200.0, 200.0, 16)
    counts = []
    for n_sub in (1, 2):
        plant = D.PMSM(par, D.Inverter(540.0, 1 / TS, pwm="carrier"), 1e-6, ts=TS, n_sub=n_sub)
        step = jax.vmap(lambda x, a, b, plant=plant: plant.step(PlantState(x, None), D.PlantInput(a, b, 0.0))[0].x)
        hlo = jax.jit(step).lower(x, ua, -ua).compile().as_text() or ""
        counts.append(hlo.count(" minimum("))
    assert counts[0] == counts[1], counts
    assert 12 <= counts[0] < 40, counts  # the network's 12 minima (and the clips'), not 12 per stage


# the lab drive's carrier loop (1 µs dead time, n_sub 2) at samples 1, 60 and 199, by the code before
# carrier_intervals divided by one; after it they agree to 2e-15 relative (XLA fuses the same arithmetic
# differently)
_PINNED = {
    "omega_m": [[31.415768663314825, 31.343729777835946, 31.33841923379203],
                [157.07941114555285, 157.00739318748757, 156.9948471196796]],
    "i_d": [[-0.8278710216984315, -0.8689964824093631, -0.825757390761504],
            [-0.838597269811641, -0.9978913563941699, -1.1544790650265393]],
    "i_q": [[5.5675803753226925, 5.543399655068356, 5.592989749014287],
            [5.5659118925864925, 5.520473925456016, 5.548270799162909]],
    "u_a": [[-31.04329913239753, -70.48732221234705, -30.68744969716831],
            [-159.74772326522535, 234.94254433443692, 97.05143175603999]],
}  # fmt: skip


def test_carrier_closed_loop_trajectory_is_pinned():
    """The lab drive's encoder loop with carrier PWM, 300 and 1500 r/min at 14 N·m, over 25 ms: its speed,
    currents and voltage where they were (to 1e-12 of each signal's scale)."""
    f = D.read_drive(LAB)
    sc = D.grid(D.Scenario(f.machine, dead_time=1e-6), speed_rpm=[300.0, 1500.0], load_nm=[14.0]).scenarios
    drive = _carrier(f.drive_for(sensorless=False))
    out = jax.jit(jax.vmap(lambda s: jaxobs.simulate(D.ClosedLoop(drive, None, s), 0.025).outputs))(sc)
    for name, want in _PINNED.items():
        got = np.asarray(getattr(out, name))[:, [1, 60, 199]]
        want = np.asarray(want)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.max(np.abs(want)), err_msg=name)


def test_carrier_plant_refuses_what_it_cannot_model():
    par = D.spmsm_paper000(inertia="motor")
    with pytest.raises(ValueError, match="PMSM.ts"):
        D.PMSM(par, D.Inverter(540.0, 1e4, pwm="carrier"), ts=TS / 2)  # a half-period plant
    with pytest.raises(ValueError, match="PMSM.rule"):
        D.PMSM(par, D.Inverter(540.0, 1e4, pwm="carrier"), ts=TS, rule=jaxobs.AB3())
    with pytest.raises(ValueError, match="Inverter.pwm"):
        D.Inverter(pwm="svm")
    with pytest.raises(ValueError, match="u_device"):
        D.Inverter(u_device=-1.0)


def _closed_loop(drive, par, rpm, loads, horizon):
    sc = D.Scenario(
        par,
        omega_m0=rpm * D.RPM,
        speed_ref=D.Scenario.speed_rpm([0.0], [rpm]),
        load=D.Scenario.load_steps([0.0, 0.1], loads),
        dead_time=1e-6,
    )
    return jaxobs.simulate(D.ClosedLoop(drive, None, sc), horizon)


def _carrier(drive):
    inv = drive.inverter
    return eqx.tree_at(lambda d: d.inverter, drive, D.Inverter(inv.udc, inv.f_pwm, pwm="carrier"))


def closed_loop_metrics(bench, horizon=0.3):
    """(max |ω_carrier − ω_averaged| (r/min), max |ω_carrier − ω*| over the last 50 ms (r/min), mean i_q over the
    last 20 ms carrier / averaged, ok) of the encoder loop on ``bench``."""
    if bench == "spmsm000":
        par = D.spmsm_paper000(inertia="motor")
        foc = D.FOC.imc(par, alpha_c=2 * math.pi * 300, alpha_s=2 * math.pi * 20)
        avg = D.Drive(foc, D.Inverter(540.0, 1 / TS))
        rpm, loads = 1000.0, [0.0, 5.0]
    else:  # the file's 4 Hz speed loop recovers from a load step in ~0.4 s: steady at the rated load, a 2 N·m step
        f = D.read_drive(LAB)
        par, avg = f.machine, f.drive_for(sensorless=False)
        rpm, loads = 1000.0, [12.0, 14.0]
    sol_a = _closed_loop(avg, par, rpm, loads, horizon)
    sol_c = _closed_loop(_carrier(avg), par, rpm, loads, horizon)
    t = np.asarray(sol_c.t)
    w_c, w_a = np.asarray(sol_c.outputs.speed_rpm), np.asarray(sol_a.outputs.speed_rpm)
    late, end = t > horizon - 0.05, t > horizon - 0.02
    iq_c, iq_a = np.mean(np.asarray(sol_c.outputs.i_q)[end]), np.mean(np.asarray(sol_a.outputs.i_q)[end])
    return float(np.max(np.abs(w_c - w_a))), float(np.max(np.abs(w_c[late] - rpm))), iq_c / iq_a, bool(sol_c.ok)


@pytest.mark.parametrize("bench", ["spmsm000", "ipmsm_lab"])
def test_sensored_closed_loop_holds_with_carrier_pwm(bench):
    """The encoder loop with carrier PWM (1 µs dead time) holds its speed through a load step as the averaged
    plant's does: 000's SPMSM bench (α_c = 2π·300, α_s = 2π·20 rad/s, 10 kHz, 1000 r/min, 0 → 5 N·m at 0.1 s) and
    the 2.2-kW lab IPMSM's drive file (8 kHz, 1000 r/min, 12 → 14 N·m, rated, at 0.1 s).  Measured: the carrier
    run within 2.9 and 0.044 r/min of the averaged run at every sample; over the last 50 ms within 0.71 and
    4.2 r/min of the reference (the file's 4 Hz speed loop is still recovering: the averaged run is too); the
    load current 1.0034 and 1.0003 times the averaged run's."""
    gap, late, iq_ratio, ok = closed_loop_metrics(bench)
    assert ok
    assert gap < 5.0, gap  # r/min: the carrier run follows the averaged one at every sample
    assert late < 0.005 * 1000.0, late  # the speed back within 0.5 % of the reference over the last 50 ms
    assert iq_ratio == pytest.approx(1.0, abs=0.02)  # the load carried by the same current


def _lab_table():
    from jaxobs.io.safetoml import read_toml

    return read_toml(LAB, "drive file")[0]


def test_drive_file_pwm_keys():
    """``[inverter] pwm`` and ``device_drop_v``: the default stays averaged (and prints nothing new); carrier needs
    f_pwm_hz = f_sample_hz and sampling at the period's start; bad values are one-line refusals naming the key."""
    raw = _lab_table()
    f = D.drive_from_table(raw, "lab")
    assert f.drive.inverter.pwm == "averaged" and "pwm" not in f.derived
    assert float(f.drive.inverter.u_device) == 0.0
    f = D.drive_from_table({**raw, "inverter": {**raw["inverter"], "pwm": "carrier", "device_drop_v": 1.2}}, "lab")
    assert f.drive.inverter.pwm == "carrier" and float(f.drive.inverter.u_device) == 1.2
    assert f.derived["pwm"].value == "carrier"
    for extra, match in (
        ({"pwm": "carrier", "sampling": "centre"}, "inverter.pwm"),
        ({"pwm": "carrier", "f_pwm_hz": 4000.0}, "inverter.pwm"),
        ({"pwm": "svm"}, "inverter.pwm"),
        ({"device_drop_v": -0.5}, "inverter.device_drop_v"),
        ({"device_drop_v": 1e3}, "inverter.device_drop_v"),
    ):
        with pytest.raises(ValueError, match=match):
            D.drive_from_table({**raw, "inverter": {**raw["inverter"], **extra}}, "lab")


def test_hexagon_limit_keeps_the_direction_and_reaches_the_vertices():
    """``voltage_limit="hexagon"``: U_dc/√3 across the edges' middles (30°), 2U_dc/3 at the vertices (0°); a vector
    beyond is scaled onto the hexagon along its own direction (minimum phase error), one inside is untouched, and
    carrier PWM applies any of them on average (every |m_x| ≤ 1).  The default circle is unchanged."""
    udc = 540.0
    hexa, circ = D.Inverter(udc, 1 / TS, voltage_limit="hexagon"), D.Inverter(udc, 1 / TS)
    ang = jnp.linspace(-math.pi, math.pi, 721)
    big = 1000.0
    ua, ub = hexa.limit(big * jnp.cos(ang), big * jnp.sin(ang))
    mag = np.hypot(np.asarray(ua), np.asarray(ub))
    # the hexagon's radius in each direction: U_dc/√3 / cos(φ), φ the angle from the nearest edge's normal
    phi = np.mod(np.asarray(ang), math.pi / 3) - math.pi / 6
    np.testing.assert_allclose(mag, udc / math.sqrt(3) / np.cos(phi), rtol=1e-12)
    np.testing.assert_allclose(np.arctan2(np.asarray(ub), np.asarray(ua)), np.asarray(ang), atol=1e-12)  # direction
    assert mag.max() == pytest.approx(2 * udc / 3, rel=1e-12) and mag.min() == pytest.approx(udc / math.sqrt(3))
    assert float(hexa.u_vertex) == pytest.approx(360.0) and float(circ.u_vertex) == pytest.approx(udc / math.sqrt(3))
    small = hexa.limit(jnp.asarray(200.0), jnp.asarray(-100.0))
    assert (float(small[0]), float(small[1])) == (200.0, -100.0)
    cu = circ.limit(big * jnp.cos(ang), big * jnp.sin(ang))
    np.testing.assert_allclose(np.hypot(np.asarray(cu[0]), np.asarray(cu[1])), udc / math.sqrt(3), rtol=1e-12)
    h, va, vb = jax.vmap(lambda a, b: carrier_intervals(udc, TS, 0.0, 0.0, a, b, jnp.ones(3)))(ua, ub)
    np.testing.assert_allclose(np.asarray((h * va).sum(1) / TS), np.asarray(ua), atol=1e-9)
    np.testing.assert_allclose(np.asarray((h * vb).sum(1) / TS), np.asarray(ub), atol=1e-9)
    with pytest.raises(ValueError, match="Inverter.voltage_limit"):
        D.Inverter(voltage_limit="square")
    raw = _lab_table()
    f = D.drive_from_table({**raw, "inverter": {**raw["inverter"], "voltage_limit": "hexagon"}}, "lab")
    assert f.drive.inverter.voltage_limit == "hexagon" and f.derived["u_vertex"].value == pytest.approx(360.0)
    assert "u_vertex" not in D.drive_from_table(raw, "lab").derived
    with pytest.raises(ValueError, match="inverter.voltage_limit"):
        D.drive_from_table({**raw, "inverter": {**raw["inverter"], "voltage_limit": "square"}}, "lab")


@pytest.mark.parametrize("extra, key", [({"pwm": "carrier"}, "pwm"), ({"device_drop_v": 1.0}, "device_drop_v")])
def test_a_dual_drive_file_refuses_carrier_pwm_and_device_drops(extra, key):
    """The dual machine's plant (jaxobs.drive.dual) runs the averaged inverter: a [dual] file asking for more is
    refused in one line, not run without it."""
    from jaxobs.io.safetoml import read_toml

    raw = read_toml(LAB.parent / "ipmsm002_dual_330v.toml", "drive file")[0]
    D.drive_from_table(raw, "dual")  # the file as shipped is accepted
    with pytest.raises(ValueError, match=f"inverter.{key}"):
        D.drive_from_table({**raw, "inverter": {**raw["inverter"], **extra}}, "dual")


def test_the_plant_takes_the_dead_times_sign_from_the_current_at_the_period_start():
    """DECISION (jaxobs.drive.pwm): the edges of a period move by the sign of each phase current at its start.  At
    θe = 0 with i_d = +4 A (phase a +4 A, b and c −2 A) a 3 µs dead time shortens phase a's pulse and lengthens b's
    and c's: the period's mean α voltage falls by (4/3)·U_dc·T_d/T = 21.6 V, so over one period (L = 5 mH) i_α
    ends about 0.432 A lower.  Measured: carrier −0.4284 A, the averaged plant −0.4286 A (within 2 %); the
    opposite current reverses it."""
    par = D.spmsm_paper000(inertia="motor")
    x0 = jnp.asarray([4.0, 0.0, 0.0, 0.0])
    cmd = D.PlantInput(jnp.asarray(50.0), jnp.asarray(0.0), 0.0)
    ends = {}
    for td in (0.0, 3e-6):
        for pwm in ("carrier", "averaged"):
            plant = D.PMSM(par, D.Inverter(540.0, 1 / TS, pwm=pwm), td, ts=TS, n_sub=4)
            ends[pwm, td] = np.asarray(plant.step(PlantState(x0, None), cmd)[0].x)
    d_car = ends["carrier", 3e-6][0] - ends["carrier", 0.0][0]  # i_d = i_α at θe ≈ 0
    d_avg = ends["averaged", 3e-6][0] - ends["averaged", 0.0][0]
    assert d_car < 0.0 and d_avg < 0.0  # the error opposes the current
    assert d_car == pytest.approx(d_avg, rel=0.02), (d_car, d_avg)  # the same mean error over the period
    # the opposite current: the error reverses
    plant = D.PMSM(par, D.Inverter(540.0, 1 / TS, pwm="carrier"), 3e-6, ts=TS, n_sub=4)
    plant0 = D.PMSM(par, D.Inverter(540.0, 1 / TS, pwm="carrier"), 0.0, ts=TS, n_sub=4)
    xn = x0.at[0].set(-4.0)
    up = plant.step(PlantState(xn, None), cmd)[0].x[0] - plant0.step(PlantState(xn, None), cmd)[0].x[0]
    assert float(up) == pytest.approx(-d_car, rel=0.02)
