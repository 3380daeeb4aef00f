"""|i| ≤ i_max at every sample of a drive file's derived controller, on two machines that are not the papers' benches:
the saturated 5.6-kW PM-SyRM with its flux map (``docs/examples/pmsyrm_5p6kw_sat.toml``) and GEM's traction IPMSM
(``docs/examples/traction_ipmsm.toml``), each through a standstill start to rated speed under load, a speed step
from rated speed into field weakening (to the top point of ``drive check --simulate``) and a load step there
(``jaxobs.analysis.drive_points.peak_ratios``: sensored, every sample of the true current).

Exactly: |i| ≤ i_max at every sample, to float rounding (TOL). The references stay within i_ref_max = (1 − h) i_max
and the current PIs see an error of at most 0.1 i_max (``jaxobs.drive._reflimit``: h = 1.25 × the designed loop's
step overshoot 5.68 % × 0.1 = 0.71 %). Measured peaks |i|/i_max (start, speed step, load step): PM-SyRM 0.9952,
0.9865, 0.9925 (its top point 2207 r/min, 1.5 × the map's base speed; its steady starts the map's); traction 0.9984,
0.9628, 0.8807. Before the margin and the error limit: PM-SyRM 1.0034 (its start: i* stepped 0.947 → 1.0 × i_max
when the speed loop reached the circle, the current 0.34 % over it 5 periods later), traction 1.0104 (its start's
step of i* from 0.73 to 1.0 × i_max, 1.010 for 3 periods): the discrete current loop's step overshoot, the voltage
computed from the samples at t_k acting 1.5 periods later.
Earlier still (before bounded field weakening, u_d priority at the voltage limit and the current loop on the
flux map) the PM-SyRM start drew 1.102 × i_max (its q current loop rang on the secant inductance, 6× the
saturated incremental one).
"""

from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs.drive as D
from jaxobs.analysis.drive_points import check_points, peak_ratios
from jaxobs.drive._reflimit import ERROR_LIMIT_PU, MARGIN_SAFETY, limit_error, reference_margin, step_overshoot

EXAMPLES = Path(__file__).parents[1] / "docs" / "examples"
TOL = 1e-9  # float rounding: |i| ≤ i_max exactly (module doc)
T_EVENT = 0.02  # s: the speed or load step
START_SHARE = 0.6  # a standstill start's load at most 60 % of the standstill capability: 40 % left to accelerate
# horizon per machine, s: long enough for the start to reach rated speed (J ω / surplus torque, doubled)
MACHINES = {"pmsyrm_5p6kw_sat": 1.2, "traction_ipmsm": 2.5}


def _scenarios(f: D.DriveFile) -> tuple[list[D.Scenario], list[float]]:
    """Start, speed step into field weakening, load step at the top speed; and the speed each must end at."""
    m = f.machine
    (_, n_r, t_r), (_, n_top, t_top) = check_points(f)
    start_load = min(t_r, START_SHARE * float(f.capability([0.0])["torque"][0]))
    step_load = 0.5 * t_top / 0.95  # half the capability at the top speed: the rest accelerates

    def sc(n0, n1, t0, t1, w0):
        return D.Scenario(m, speed_ref=D.Scenario.speed_rpm([0.0, T_EVENT], [n0, n1]),
                          load=D.Scenario.load_steps([0.0, T_EVENT], [t0, t1]), omega_m0=w0 * D.RPM)  # fmt: skip

    scs = [sc(n_r, n_r, start_load, start_load, 0.0), sc(n_r, n_top, step_load, step_load, n_r),
           sc(n_top, n_top, 0.0, t_top, n_top)]  # fmt: skip
    return scs, [n_r, n_top, n_top]


@pytest.mark.slow
@pytest.mark.parametrize("name", list(MACHINES))
def test_the_current_stays_within_i_max_through_start_field_weakening_step_and_load_step(name):
    f = D.read_drive(EXAMPLES / f"{name}.toml")
    assert f.derived["field_weakening"].value  # both run into field weakening
    scs, ends = _scenarios(f)
    r = peak_ratios(f, scs, MACHINES[name])
    i_max = float(f.derived["i_max"].value)
    i_ref = float(f.derived["i_ref_max"].value)
    assert 0.99 * i_max < i_ref < i_max
    assert np.all(r["ref_ratio"] <= i_ref / i_max + 1e-6), r["ref_ratio"]  # the references: within i_ref_max
    assert np.all(r["id_ref_min"] >= -i_max * (1.0 + 1e-6)), r["id_ref_min"]  # no i_d* beyond i_max
    assert np.all(r["i_ratio"] <= 1.0 + TOL), r["i_ratio"]  # the true current, every sample
    assert np.all(r["u_ratio"] <= 1.0 + 1e-6), r["u_ratio"]  # the applied voltage within u_dc/√3
    np.testing.assert_allclose(r["last_rpm"], ends, rtol=0.02)  # each reached its speed: the runs mean something


def test_peak_ratios_refuses_an_empty_batch():
    f = D.read_drive(EXAMPLES / "traction_ipmsm.toml")
    with pytest.raises(ValueError, match="non-empty"):
        peak_ratios(f, [], 0.1)


def _loop(alpha_c_ts, n, r, e_max=np.inf):
    """The module's loop model step by step (a plain recurrence; n = 1.5: the voltage of sample k over period k + 1;
    n = 1.0: half over period k, half over k + 1), its error limited to e_max: the sampled currents."""
    x = np.zeros(len(r) + 2)
    e = np.zeros(len(r) + 2)
    for k in range(len(r)):
        e[k] = np.clip(r[k] - x[k], -e_max, e_max)
        push = e[k - 1] if n == 1.5 else 0.5 * (e[k] + e[k - 1])
        x[k + 1] = x[k] + alpha_c_ts * (push if k >= 1 or n != 1.5 else 0.0)
    return x


@pytest.mark.parametrize("n", [1.0, 1.5])
def test_the_step_overshoot_is_the_loop_models_own(n):
    a = np.radians(30.0) / n  # the derived α_c: 60° phase margin with n periods of delay
    x = _loop(a, n, np.ones(400))
    assert step_overshoot(a, n) == pytest.approx(x.max() - 1.0, rel=1e-9)
    assert step_overshoot(np.radians(30.0) / 1.5, 1.5) == pytest.approx(0.0567801, abs=1e-6)  # the module doc's 5.68 %
    assert step_overshoot(0.05, 1.5) == 0.0  # a slow loop does not overshoot


def test_the_error_limit_keeps_the_overshoot_within_the_margin():
    """The module's rule: with the error limited to E, a step's overshoot is at most o E (from rest, from 0.73 of
    the circle, from the opposite side), within the margin h = 1.25 o E; without the limit, o times the step."""
    a, n = np.radians(30.0) / 1.5, 1.5
    o, e = step_overshoot(a, n), ERROR_LIMIT_PU
    for r0 in (0.0, 0.73, -1.0):
        x = _loop(a, n, np.full(800, 1.0 - r0), e) + r0
        assert x.max() - 1.0 <= o * e * 1.001, (r0, x.max())
    assert reference_margin(a, n) == pytest.approx(MARGIN_SAFETY * o * e)
    assert _loop(a, n, np.full(400, 0.27)).max() + 0.73 == pytest.approx(1.0 + 0.27 * o, rel=1e-9)
    with pytest.raises(ValueError, match="error_limit"):
        reference_margin(a, n, 0.0)
    with pytest.raises(ValueError, match="use_delay"):
        step_overshoot(a, 1.2)


def test_limit_error_keeps_the_direction_and_caps_the_length():
    e_d, e_q = limit_error(jnp.asarray([3.0, 0.1]), jnp.asarray([4.0, 0.0]), 1.0)
    np.testing.assert_allclose(np.asarray(e_d), [0.6, 0.1])
    np.testing.assert_allclose(np.asarray(e_q), [0.8, 0.0])


def test_drive_files_set_the_margin_and_the_benches_do_not():
    f = D.read_drive(EXAMPLES / "traction_ipmsm.toml")
    assert isinstance(f.drive, D.Drive)
    foc = f.drive.foc
    assert foc.current_margin == pytest.approx(reference_margin(foc.ts * f.foc_kw["alpha_c"], 1.5))
    assert 0.007 < foc.current_margin < 0.0072 and foc.error_limit == ERROR_LIMIT_PU
    assert float(foc.i_ref) == pytest.approx(240.0 * (1 - foc.current_margin))
    assert float(f.derived["i_ref_max"].value) == pytest.approx(float(foc.i_ref))
    for name in D.SHIPPED_DRIVES:  # the papers' benches: the references on i_max itself, as published
        b = D.shipped_drive(name).drive
        assert isinstance(b, D.Drive)
        assert b.foc.current_margin == 0.0 and b.foc.error_limit == 0.0
        assert b.foc.i_ref is b.foc.i_max
    with pytest.raises(ValueError, match="current_margin"):
        D.FOC.imc(f.machine, 1000.0, 10.0, current_margin=0.6)
