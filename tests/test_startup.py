"""I-f start-up from standstill and the hand-over to the observer, for every drive observer.

Each run: standstill, I-f (``IfStartup.for_machine``: parked rotor, raised-cosine ramp to 20 % of rated speed,
hold, agreement, bumpless hand-over), the observer closing the loop at the switch speed, then a ramp of the
reference to the target — the sequence of 000's Fig. 20 (switch, then speed up).  LESOs on 002's IPMSM bench to
300 r/min, flux observers on 000's SPMSM bench to 1000 r/min (both half their rated speed).

The fast suite runs one observer of each family (FA-LESO; the SOIFO, which ran away to 2120 r/min with the old
hand-over); the others are ``slow``.  Measured (this design):

| observer | switch (s) | max pos. error after the switch (rad) | speed, switch → ramp | band at the end |
|---|---|---|---|---|
| C-LESO   | 0.587 | 0.218 (its steady lag 0.20) | ±3.6 % | 0.28 % |
| GI-LESO  | 0.587 | 0.128 | ±2.0 % | 0.44 % |
| FA-LESO  | 0.587 | 0.049 | ±2.7 % | 0.16 % |
| SOIFO    | 0.353 | 0.118 | ±1.2 % | 0.15 % |
| 2nd-order SOIFO | 0.353 | 0.093 | ±1.2 % | 0.15 % |
| LPF (compensated) | 0.353 | 0.016 | ±1.4 % | 0.20 % |
"""

import dataclasses
import math

import equinox as eqx
import jax
import numpy as np
import pytest

import jaxobs
from jaxobs import drive as D
from jaxobs import linear, papers
from jaxobs.metrics import wrap
from jaxobs.studies.drive import bind_observer

IPMSM = D.ipmsm_paper002(J=papers.BENCH_J_002)
SPMSM = D.spmsm_paper000(J=papers.BENCH_J_000)
# family: (machine, target r/min, reference ramp start and length (s), horizon (s), end window (s))
CASES = {"leso": (IPMSM, 300.0, 0.8, 0.4, 1.6, 0.2), "flux": (SPMSM, 1000.0, 0.5, 0.3, 1.2, 0.2)}


def _observer(name):
    if name in ("CLESO", "GILESO", "FALESO"):
        return "leso", getattr(jaxobs, name)(IPMSM.Rs, IPMSM.Lq)  # 002 Table II gains, the 15 Hz PLL
    par = SPMSM
    K1, K2 = papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2
    if name == "SOIFO":
        return "flux", jaxobs.SOIFO(par.Rs, par.Ld, papers.SOIFO_K, papers.SOIFO_K**2 / 4, 1.0)
    if name == "SecondOrderSOIFO":
        return "flux", jaxobs.SecondOrderSOIFO(par.Rs, par.Ld, K1, K2, K1**3 / (2 * K2), 1.0)
    kp, ki = linear.pll_gains(2 * math.pi * papers.FLUX_PLL_HZ)
    # the LPF with 000 eq (11)'s compensation: uncompensated its estimate leads by atan(ωc/ωe) = 0.67 rad at
    # the 400 r/min switch, and the hand-over dips to 237 r/min (−41 %) — the observer's error, not the
    # hand-over's (measured; see the README)
    return "flux", jaxobs.LPFFlux(par.Rs, par.Ld, papers.LPF_OMEGA_C, kp, ki, compensate=True)


def _run(name, load_pu=0.0):
    fam, obs = _observer(name)
    par, rpm_ref, t_a, t_ramp, t1, _ = CASES[fam]
    start = D.IfStartup.for_machine(par)
    rpm_sw = float(start.omega_switch) / par.p / D.RPM
    foc = D.FOC.imc(par, 2 * math.pi * papers.BENCH_CURRENT_HZ, 2 * math.pi * papers.BENCH_SPEED_HZ)
    drive = D.Drive(foc, startup=start, sensorless=True)
    sc = D.Scenario(
        par,
        speed_ref=D.Scenario.speed_rpm([0.0, t_a], [rpm_sw, rpm_ref], ramp=t_ramp),
        load=D.Profile.constant(load_pu * float(par.T_rated)),
        theta_e0=0.7,
    )
    sol = jax.jit(lambda s: jaxobs.simulate(D.ClosedLoop(drive, bind_observer(obs, s), s), t1))(sc)
    return fam, start, rpm_sw, sol


@pytest.mark.parametrize(
    "name",
    [
        "FALESO",
        "SOIFO",
        pytest.param("CLESO", marks=pytest.mark.slow),
        pytest.param("GILESO", marks=pytest.mark.slow),
        pytest.param("SecondOrderSOIFO", marks=pytest.mark.slow),
        pytest.param("LPF", marks=pytest.mark.slow),
    ],
)
def test_if_start_from_standstill_hands_over_to_every_observer(name):
    fam, start, rpm_sw, sol = _run(name)
    par, rpm_ref, t_a, t_ramp, t1, t_end = CASES[fam]
    o = sol.outputs
    t, mode, rpm = np.asarray(sol.t), np.asarray(o.mode), np.asarray(o.speed_rpm)
    assert sol.ok and np.all(np.isfinite(rpm))
    # 1. the hand-over happens: after the ramp and the hold, within the dwell and a little more
    assert mode[0] == 0 and mode[-1] == 1 and np.all(np.diff(mode) >= 0)
    i_sw = int(np.argmax(mode == 1))
    t_ramp_if = float(start.omega_switch / start.accel)
    assert t_ramp_if + float(start.hold) - 2e-4 <= t[i_sw] <= t_ramp_if + float(start.hold) + 0.05, t[i_sw]
    # 2. synchronism during I-f: the load angle θ_f − θ stays near its no-load value −π/2 (parked start,
    # smooth ramp: the accelerating torque is ≤ IF_ACCEL_TORQUE_PU = 0.2 of K_t I_f, cos δ ≤ 0.2 → 0.2 rad;
    # π/4 leaves room for the residual swing), never near 0 or −π where synchronism is lost
    delta = np.asarray(wrap(o.theta_e_hat - o.theta_e))[:i_sw]
    assert np.max(np.abs(delta + np.pi / 2)) < np.pi / 4, np.max(np.abs(delta + np.pi / 2))
    # 3. the observer's position error after the switch (to the end, through the reference ramp)
    err = np.abs(np.asarray(wrap(o.obs.theta - o.theta_e)))[i_sw:]
    if name == "CLESO":
        # its steady lag 2·atan(ωe/ω0) at the target (002 eq 17; 0.20 rad at 300 r/min, 002 measured 14°),
        # plus 0.05 rad for the ramp (the type-2 PLL's a/ω_b² ≈ 0.03 rad) and the loop
        bound = 2 * math.atan(par.p * rpm_ref * D.RPM / papers.LESO_OMEGA0) + 0.05
    elif name in ("GILESO", "FALESO"):
        bound = 0.15  # no steady lag at ω̂ = ωe (GI-LESO: little); the same 0.05 ramp allowance, and 0.1 rad
    elif name in ("SOIFO", "SecondOrderSOIFO"):
        bound = 0.15  # 000 Fig. 18: 0.15 / 0.13 rad on its 400 → 2000 r/min ramps (FLL lag); ours is slower
    else:
        bound = 0.05  # compensated LPF: exact at steady state; the PLL speed it compensates with lags on ramps
    assert np.max(err) < bound, (np.max(err), bound)
    # 4. no bump at the hand-over: from the switch to the reference ramp the speed stays within ±6 % of
    # the switch speed (measured ≤ 3.6 %; a speed loop through the LESOs' PLL at 10 % of rated speed
    # rang ±11 %, hence the 20 % switch speed, jaxobs.papers.IF_SWITCH_PU)
    win = (t >= t[i_sw]) & (t < t_a)
    dev = np.max(np.abs(rpm[win] / rpm_sw - 1))
    assert dev < 0.06, dev
    # 5. reaches the target and stays within 1 % of it over the last t_end seconds
    late = t >= t1 - t_end
    band = np.max(np.abs(rpm[late] / rpm_ref - 1))
    assert band < 0.01, band
    print(f"{name}: switch {t[i_sw]:.3f} s, max err {np.max(err):.4f} rad, hand-over ±{dev:.4f}, band {band:.4f}")


def test_hand_over_is_bumpless_at_the_switch_sample():
    """One FOC period at the switch: the current references continue the I-f vector seen from the given frame,
    the speed PI's output equals its q component (the k_pω ω̂ term included), and the voltage vector is what
    the I-f frame would have applied (the PI integrators rotated with their decoupling terms)."""
    par = IPMSM
    start = D.IfStartup(4.0, 100.0, 30.0, hold=0.0, dwell=1e-3)
    foc = D.FOC.imc(par, 2 * math.pi * 300, 2 * math.pi * 5).bind(par, 300.0, start)
    # at the top of the ramp, agreement already held: the next sample switches
    cs = foc.init(theta_f0=0.3)
    th_f = 0.3 + 30.0 * 1e-4  # trapezoidal step at ω_f = 30 rad/s
    cs = dataclasses.replace(
        cs, omega_f=30.0, theta_f=0.3, t_at_switch=1.0, t_agree=1.0, d_lp=-1.2, int_d=2.0, int_q=-1.5
    )
    delta = -1.2  # the I-f angle minus the given one
    theta = th_f - delta
    i_a, i_b = D.dq_to_ab(0.0, 4.0, th_f)  # the I-f current, at its reference
    k = 3000  # a speed-loop sample (k % 10 == 0)
    new, out = foc.step(cs, D.FOCInput(k, i_a, i_b, theta, 30.0, 6.0, 60.0))
    assert int(new.mode) == 1
    assert float(out.iq_ref) == pytest.approx(4.0 * math.cos(delta), rel=1e-9)
    assert float(out.id_ref) == pytest.approx(-4.0 * math.sin(delta), rel=1e-9)
    # the same sample without the switch (agreement not yet long enough): I-f frame
    _, out_f = foc.step(dataclasses.replace(cs, t_agree=0.0), D.FOCInput(k, i_a, i_b, theta, 30.0, 6.0, 60.0))
    assert float(out_f.theta) == pytest.approx(th_f)
    np.testing.assert_allclose([float(out.u_a), float(out.u_b)], [float(out_f.u_a), float(out_f.u_b)], atol=1e-9)


def test_startup_defaults_and_checks():
    for par in (IPMSM, SPMSM):
        s = D.IfStartup.for_machine(par)
        t_ramp = float(s.omega_switch / s.accel)
        swing = 2 * math.pi / math.sqrt(par.p * float(par.kt) * float(s.i_f) / float(par.J))
        assert t_ramp >= papers.IF_RAMP_SWING_PERIODS * swing - 1e-9
        peak_torque = float(par.J) * 2 * float(s.accel) / par.p  # the raised cosine peaks at 2× the mean
        assert peak_torque <= papers.IF_ACCEL_TORQUE_PU * float(par.kt) * float(s.i_f) + 1e-9
        assert float(s.omega_switch) == pytest.approx(par.p * papers.IF_SWITCH_PU * float(par.n_rated) * D.RPM)
        # the ramp: 0 at the start, ω_sw at its end, increasing, mean rate accel
        ts = np.linspace(0.0, t_ramp, 101)
        w = np.asarray(jax.vmap(s.ramp)(ts))
        assert w[0] == 0.0 and w[-1] == pytest.approx(float(s.omega_switch)) and np.all(np.diff(w) >= 0)
    for kw, field in ((dict(tol=-0.1), "tol"), (dict(dwell=0.0), "dwell"), (dict(blend=-1.0), "blend")):
        with pytest.raises(ValueError, match=field):
            D.IfStartup(4.0, 100.0, 30.0, **kw)


def _faleso_job(tmp_path, drive_extra, horizon="1.5", steady="0.9", grid=None, loop="sensorless"):
    """faleso.toml with ``drive_extra`` in [drive], the horizon and steady window set, ``grid`` its grid lines."""
    import re
    from pathlib import Path

    from jaxobs_tuning.job import load_job

    text = (Path(__file__).parents[1] / "tuning" / "presets" / "faleso.toml").read_text()
    assert 'loop = "sensorless"\n' in text
    text = text.replace('loop = "sensorless"\n', f'loop = "{loop}"\n{drive_extra}\n')
    text = re.sub(r"(?m)^horizon = .*$", f"horizon = {horizon}", text)
    text = re.sub(r"(?m)^steady_from = .*$", f"steady_from = {steady}", text)
    if grid is not None:
        text = re.sub(r"(?ms)^\[scenarios\.grid\]\n.*?(?=^\[objective\])", f"[scenarios.grid]\n{grid}\n", text)
    if loop != "sensorless":  # the claimed envelope is verified sensorless: a sensored job has none
        text = re.sub(r"(?ms)^\[envelope\][^\n]*\n.*?(?=^\[)", "", text)
    if "standstill" in drive_extra:  # the preset's held-out 25 N·m is beyond what an I-f start-up carries
        text = re.sub(r"(?ms)^\[holdout\][^\n]*\n.*?(?=^\[scenarios\])", "", text)
    path = tmp_path / "j.toml"
    path.write_text(text)
    return load_job(path)


def test_drive_job_start_option(tmp_path):
    """``[drive] start = "standstill"`` gives the job's drive the machine's I-f start-up; bad values, a start-up
    longer than the horizon and a hand-over time beside it are one-line errors at --check."""
    from jaxobs_tuning.job import JobError, job_drive

    light = "speed_rpm = [300.0, 840.0]\nload_nm = [0.0, 5.0]"

    def job(extra, horizon="1.5", grid=light):
        return _faleso_job(tmp_path, extra, horizon, steady=str(min(0.9, 0.8 * float(horizon))), grid=grid)

    assert job("").drive.start == "steady" and job_drive(job("").drive).startup is None
    assert job("", grid=None).drive.start == "steady"  # the preset's 15 N·m: fine from a steady start
    j = job('start = "standstill"')
    assert j.drive.start == "standstill"
    assert job_drive(j.drive).startup is not None
    for extra, horizon, field in (
        ('start = "rest"', "1.5", "drive.start"),
        ('start = "standstill"', "0.3", "drive.start"),
        ('start = "standstill"\nhandover = 0.1', "1.5", "drive.handover"),
    ):
        with pytest.raises(JobError, match=field):
            job(extra, horizon)


def test_standstill_job_checks_what_the_i_f_start_up_can_carry(tmp_path):
    """A standstill job is refused (one line naming the field) where its I-f start-up cannot work: a load above
    :func:`jaxobs.drive.if_load_limit` (tested at the boundary, ±0.1 %), a speed reference below the hand-over
    speed (120 r/min on the IPMSM bench), a steady window before the earliest hand-over."""
    from jaxobs.drive import IF_SUDDEN_LOAD_PU, if_handover_earliest, if_load_limit
    from jaxobs_tuning.job import JobError

    par, start = D.ipmsm_paper002(J=papers.BENCH_J_002), None
    assert bool(eqx.tree_equal(D.bench_machine("ipmsm002"), par))
    start = D.IfStartup.for_machine(par)
    # the derivation by hand: the equal-area root, K_t I_f, the raised cosine's peak acceleration, friction
    d0 = math.asin(IF_SUDDEN_LOAD_PU)
    assert 1 + math.cos(d0) == pytest.approx((math.pi - d0) * math.sin(d0), abs=2e-4)
    a_peak = 2 * float(start.accel) / par.p
    want = IF_SUDDEN_LOAD_PU * float(par.kt) * float(start.i_f) - float(par.J) * a_peak
    want -= float(par.B) * float(start.omega_switch) / par.p
    limit = if_load_limit(par)
    assert limit == pytest.approx(want) and 7.0 < limit < 9.0  # 8.27 N·m of the 30 N·m rated
    assert if_load_limit(par, dJ=1.0) == pytest.approx(limit - float(par.J) * a_peak)
    t_ho = if_handover_earliest(par)
    assert t_ho == pytest.approx(float(start.omega_switch / start.accel) + max(float(start.hold), float(start.dwell)))
    ss = 'start = "standstill"'
    ok = _faleso_job(tmp_path, ss, grid=f"speed_rpm = [300.0]\nload_nm = [{limit * 0.999:.6f}]")
    assert ok.drive.start == "standstill"
    with pytest.raises(JobError, match=r"scenarios\.grid\.load_nm.*<= 8\.27"):
        _faleso_job(tmp_path, ss, grid=f"speed_rpm = [300.0]\nload_nm = [{limit * 1.001:.6f}]")
    # a load step during the start-up counts; after the earliest hand-over it does not
    with pytest.raises(JobError, match="load_nm"):
        _faleso_job(tmp_path, ss, grid=f"speed_rpm = [300.0]\nload_nm = [{limit - 1:.4f}]\nload_step_nm = [2.0]")
    rpm_sw = float(start.omega_switch) / par.p / D.RPM
    _faleso_job(tmp_path, ss, grid=f"speed_rpm = [{rpm_sw * 1.001:.4f}]")
    with pytest.raises(JobError, match=r"speed_rpm.*hand-over speed 120"):
        _faleso_job(tmp_path, ss, grid=f"speed_rpm = [{rpm_sw * 0.999:.4f}]")
    with pytest.raises(JobError, match="speed_rpm"):  # a step below it
        _faleso_job(tmp_path, ss, grid="speed_rpm = [300.0]\nspeed_step_rpm = [-250.0]")
    _faleso_job(tmp_path, ss, steady=f"{t_ho + 1e-3:.4f}", grid="speed_rpm = [300.0]")
    with pytest.raises(JobError, match=r"scenarios\.steady_from.*standstill"):
        _faleso_job(tmp_path, ss, steady=f"{t_ho - 1e-3:.4f}", grid="speed_rpm = [300.0]")
    # the encoder may close the loop after the same start-up
    j = _faleso_job(tmp_path, ss, grid="speed_rpm = [300.0]", loop="sensored")
    assert j.drive.loop == "sensored" and j.drive.start == "standstill"


@pytest.mark.slow
@pytest.mark.parametrize("name", ["FALESO", "SOIFO", "SecondOrderSOIFO"])
def test_if_start_against_a_constant_load(name):
    """20 % of rated torque from t = 0 (the parked rotor then swings: the load shifts the load angle by
    asin(T_L/(K_t I_f)) = asin(0.4) = 0.41 rad and the swing is undamped).  Measured: hand-over on time,
    speed in the window −12 … +8.5 %, position error ≤ 0.14 rad, band ≤ 0.6 % at the end."""
    fam, start, rpm_sw, sol = _run(name, load_pu=0.2)
    par, rpm_ref, t_a, t_ramp, t1, t_end = CASES[fam]
    o = sol.outputs
    t, mode, rpm = np.asarray(sol.t), np.asarray(o.mode), np.asarray(o.speed_rpm)
    assert sol.ok and mode[-1] == 1
    i_sw = int(np.argmax(mode == 1))
    t_ramp_if = float(start.omega_switch / start.accel)
    assert t[i_sw] <= t_ramp_if + float(start.hold) + 0.05, t[i_sw]
    # synchronism: the load angle keeps 0.2 rad away from the ends of the stable range (−π, 0)
    delta = np.asarray(wrap(o.theta_e_hat - o.theta_e))[:i_sw]
    assert -np.pi + 0.2 < np.min(delta) and np.max(delta) < -0.2, (np.min(delta), np.max(delta))
    err = np.abs(np.asarray(wrap(o.obs.theta - o.theta_e)))[i_sw:]
    assert np.max(err) < 0.15, np.max(err)  # as without load (FA-LESO, SOIFOs)
    win = (t >= t[i_sw]) & (t < t_a)
    # the swing the load set off at standstill carries into the window (the closed loop then damps it)
    assert np.max(np.abs(rpm[win] / rpm_sw - 1)) < 0.15
    assert np.max(np.abs(rpm[t >= t1 - t_end] / rpm_ref - 1)) < 0.01


@pytest.mark.slow
def test_an_observer_that_never_agrees_keeps_the_drive_in_i_f():
    """The fail-safe: a SOIFO whose FLL is not seeded (it stays at 1 rad/s, its gain being lam·ω̂²) never
    agrees with the I-f frame, so the drive never hands over and the I-f keeps the rotor synchronous at the
    switch speed (measured: with seeding it switches at 0.353 s)."""

    class Unseeded(jaxobs.AbstractObserver):  # an observer, but no drive observer: no seed_speed
        obs: object

        @property
        def ts(self):
            return self.obs.ts

        def init(self, u0=None):
            return self.obs.init()

        def step(self, s, u):
            return self.obs.step(s, u)

    _, obs = _observer("SOIFO")
    start = D.IfStartup.for_machine(SPMSM)
    foc = D.FOC.imc(SPMSM, 2 * math.pi * papers.BENCH_CURRENT_HZ, 2 * math.pi * papers.BENCH_SPEED_HZ)
    sc = D.Scenario(SPMSM, speed_ref=D.Profile.constant(1000 * D.RPM))
    system = D.ClosedLoop(D.Drive(foc, startup=start, sensorless=True), Unseeded(bind_observer(obs, sc)), sc)
    sol = jax.jit(lambda: jaxobs.simulate(system, 0.6))()
    assert np.all(np.asarray(sol.outputs.mode) == 0)
    rpm = np.asarray(sol.outputs.speed_rpm)[np.asarray(sol.t) > 0.4]
    rpm_sw = float(start.omega_switch) / SPMSM.p / D.RPM
    assert np.max(np.abs(rpm / rpm_sw - 1)) < 0.02, (rpm.min(), rpm.max())


def test_standstill_jobs_score_the_position_error_from_the_hand_over_on():
    """The position-error metrics of a job skip a standstill start's I-f phase (``mode`` 0: the controller
    runs on the I-f angle, the observer sits ~90° off), but never inside the steady window: a drive that has
    not handed over by then is scored on its real error and flagged lost_sync."""
    from types import SimpleNamespace

    import jax.numpy as jnp

    from jaxobs import Solution
    from jaxobs.drive import DriveOutput
    from jaxobs.metrics import METRICS as TABLE
    from jaxobs_tuning.objective import TERM_METRICS as METRICS
    from jaxobs_tuning.objective import MetricContext

    def drive_output(**fields):  # a closed loop's outputs: the metrics take θe as the truth by its type
        return DriveOutput(**(dict.fromkeys(DriveOutput._fields) | fields))

    t = jnp.linspace(0.0, 1.0, 1001)
    err = jnp.where(t < 0.4, 1.65, 0.01)  # 95° during I-f, 0.6° after
    ctx = MetricContext(t_event=0.0, steady_from=0.7)

    def solution(outputs):  # a trajectory as simulate returns it (the metrics take a Solution)
        return Solution(t=t, outputs=outputs, final_state=None, ok=jnp.asarray(True), cost=None)

    def sol(mode):
        return solution(drive_output(theta_e=jnp.zeros_like(t), obs=SimpleNamespace(theta=err), mode=mode))

    handed = sol(jnp.where(t < 0.4, 0, 1))
    assert float(METRICS["iae_position"](handed, None, ctx)) == pytest.approx(0.01 * 0.6, rel=0.02)
    assert not bool(TABLE["lost_sync"].exact(handed, None, ctx))
    steady = sol(jnp.ones_like(t, dtype=jnp.int32))  # a steady start: every sample counts
    assert float(METRICS["iae_position"](steady, None, ctx)) == pytest.approx(1.65 * 0.4 + 0.01 * 0.6, rel=0.02)
    assert bool(TABLE["lost_sync"].exact(steady, None, ctx))
    never = solution(
        drive_output(
            theta_e=jnp.zeros_like(t),
            obs=SimpleNamespace(theta=jnp.full_like(t, 1.7)),
            mode=jnp.zeros_like(t, dtype=jnp.int32),
        )
    )
    assert float(METRICS["rms_position_steady"](never, None, ctx)) == pytest.approx(1.7, rel=1e-4)
    assert bool(TABLE["lost_sync"].exact(never, None, ctx))  # 97° in the steady window


@pytest.mark.slow
def test_a_standstill_start_above_the_load_limit_runs_backwards_and_is_flagged_lost_speed():
    """The review's case: SOIFO, 000's SPMSM, 1000 r/min reference from standstill.  Measured: 4.5 N·m (above
    jaxobs.drive.if_load_limit's 3.82, which is sufficient, not necessary) still starts; 5 N·m runs backwards
    (−320 r/min) with the observer locked to it — lost_speed flags it, lost lock does not."""
    import jax.numpy as jnp

    from jaxobs import metrics as M

    assert 3.5 < D.if_load_limit(D.bench_machine("spmsm000")) < 4.5
    _, obs = _observer("SOIFO")
    start = D.IfStartup.for_machine(SPMSM)
    foc = D.FOC.imc(SPMSM, 2 * math.pi * papers.BENCH_CURRENT_HZ, 2 * math.pi * papers.BENCH_SPEED_HZ)
    drive = D.Drive(foc, startup=start, sensorless=True)
    scs = [
        D.Scenario(SPMSM, speed_ref=D.Profile.constant(1000 * D.RPM), load=D.Profile.constant(tl)) for tl in (4.5, 5.0)
    ]
    batch = jax.tree.map(lambda *x: jnp.stack(x), *scs)
    run = jax.jit(jax.vmap(lambda s: jaxobs.simulate(D.ClosedLoop(drive, bind_observer(obs, s), s), 1.0)))
    sol = run(batch)
    o = sol.outputs
    win = sol.t[0] >= 0.7
    lost_speed = np.asarray(M.lost_speed(o.omega_m, o.omega_m_ref, win))
    lost_lock = np.asarray(M.lost_lock(o.obs.theta, o.theta_e, win, math.radians(M.LOCK_TOL_DRIVE_DEG)))
    rpm_end = np.asarray(o.speed_rpm)[:, -1]
    assert list(lost_speed) == [False, True], rpm_end
    assert rpm_end[0] == pytest.approx(1000.0, rel=0.05) and rpm_end[1] < 0.0
    assert not lost_lock[1]  # the observer tracks the rotor turning the wrong way
