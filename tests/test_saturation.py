"""The optional q-axis saturation of the PMSM plant (jaxobs.drive.QSaturation): off by default and then the
same machine, a monotonic flux when on, consistent q inductances, differentiable, bad input refused."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxobs import drive as D

PAR = D.bench_machine("ipmsm002")


def test_off_by_default_and_the_same_pytree_as_before():
    """A machine without q_sat has no extra leaf, and its inductances are Lq itself (not a limit)."""
    assert PAR.q_sat is None
    assert len(jax.tree_util.tree_leaves(PAR)) == 10
    assert D.lq_apparent(PAR, 8.0) is PAR.Lq and D.lq_incremental(PAR, 8.0) is PAR.Lq
    # the vector field of the linear machine, written out: what plant_vf computed before the option existed
    x = jnp.array([-1.5, 7.0, 60.0, 0.3])
    u = (20.0, 150.0)
    f = np.asarray(D.plant_vf(PAR, x, u, 10.0))
    we = PAR.p * x[2]
    ud = np.cos(0.3) * u[0] + np.sin(0.3) * u[1]
    uq = -np.sin(0.3) * u[0] + np.cos(0.3) * u[1]
    did = (ud - PAR.Rs * x[0] + we * PAR.Lq * x[1]) / PAR.Ld
    diq = (uq - PAR.Rs * x[1] - we * PAR.Ld * x[0] - we * PAR.psi_f) / PAR.Lq
    te = 1.5 * PAR.p * (PAR.psi_f * x[1] + (PAR.Ld - PAR.Lq) * x[0] * x[1])
    np.testing.assert_allclose(f, [did, diq, (te - 10.0 - PAR.B * x[2]) / PAR.J, we], rtol=1e-6)


def test_saturated_inductances_flux_and_torque():
    """Lq down 20 % at the rated current (QSaturation.at); dψq/di_q is the incremental inductance the q
    equation uses (> 0 at any current: ψq rises monotonically); the torque's reluctance term uses ψq."""
    i_r = float(PAR.i_rated)
    par = D.bench_machine("ipmsm002", q_sat=D.QSaturation.at(0.8, i_r))
    assert float(D.lq_apparent(par, i_r)) == pytest.approx(0.8 * float(PAR.Lq), rel=1e-6)
    assert float(D.lq_apparent(par, -i_r)) == pytest.approx(0.8 * float(PAR.Lq), rel=1e-6)
    assert float(D.lq_apparent(par, 0.0)) == pytest.approx(float(PAR.Lq), rel=1e-7)
    i = jnp.linspace(-10 * i_r, 10 * i_r, 401)
    psi = jax.vmap(lambda c: D.lq_apparent(par, c) * c)(i)
    dpsi = jax.vmap(jax.grad(lambda c: D.lq_apparent(par, c) * c))(i)
    np.testing.assert_allclose(dpsi, jax.vmap(lambda c: D.lq_incremental(par, c))(i), rtol=1e-5)
    assert bool(jnp.all(jnp.diff(psi) > 0)) and bool(jnp.all(dpsi > 0))
    assert float(D.lq_incremental(par, i_r)) == pytest.approx(0.8**3 * float(PAR.Lq), rel=1e-5)  # n = 2
    te = D.torque(par, -2.0, i_r, 0.0)
    lq = 0.8 * float(PAR.Lq)
    assert float(te) == pytest.approx(
        1.5 * PAR.p * (float(PAR.psi_f) * i_r + (float(PAR.Ld) - lq) * -2.0 * i_r), rel=1e-6
    )
    # the q equation divides by the incremental inductance
    x = jnp.array([0.0, i_r, 0.0, 0.0])
    f_lin, f_sat = D.plant_vf(PAR, x, (0.0, 100.0), 0.0), D.plant_vf(par, x, (0.0, 100.0), 0.0)
    assert float(f_sat[1]) == pytest.approx(float(f_lin[1]) / 0.8**3, rel=1e-5)


def test_saturation_is_differentiable_in_its_parameters():
    def lq(i_sat, n):
        return D.lq_apparent(D.bench_machine("ipmsm002", q_sat=D.QSaturation(i_sat, n)), 8.0)

    g = jax.grad(lq, argnums=(0, 1))(12.0, 2.0)
    assert float(g[0]) > 0 and np.isfinite(float(g[1]))  # a higher i_sat saturates less


@pytest.mark.parametrize(
    "make, field",
    [
        (lambda: D.QSaturation(0.0), "i_sat"),
        (lambda: D.QSaturation(10.0, 0.5), "n"),
        (lambda: D.QSaturation.at(1.2, 8.0), "ratio"),
        (lambda: D.QSaturation.at(0.8, -1.0), "i_q"),
        (lambda: D.bench_machine("ipmsm002", q_sat=0.8), "q_sat"),
    ],
)
def test_bad_saturation_input_is_a_value_error_naming_the_field(make, field):
    with pytest.raises(ValueError, match=field):
        make()


def test_saturated_plant_conserves_power():
    """Input power = copper loss + d/dt of the stored magnetic energy + mechanical power, with the incremental
    Lq in the energy and the apparent one in the torque (a wrong torque or inductance breaks the balance)."""
    par = D.bench_machine("ipmsm002", q_sat=D.QSaturation.at(0.7, float(PAR.i_rated)))
    for x, u in (([-2.0, 9.0, 50.0, 0.4], (30.0, 120.0)), ([1.0, -14.0, 80.0, -2.0], (-60.0, 20.0))):
        x = jnp.array(x)
        did, diq, _, we = (float(v) for v in D.plant_vf(par, x, u, 0.0))
        c, s = np.cos(float(x[3])), np.sin(float(x[3]))
        ud, uq = c * u[0] + s * u[1], -s * u[0] + c * u[1]
        i_d, i_q = float(x[0]), float(x[1])
        p_in = 1.5 * (ud * i_d + uq * i_q)
        loss = 1.5 * float(par.Rs) * (i_d**2 + i_q**2)
        dw = 1.5 * (float(par.Ld) * i_d * did + float(D.lq_incremental(par, i_q)) * i_q * diq)
        p_mech = float(D.torque(par, i_d, i_q, x[3])) * float(x[2])
        assert p_in == pytest.approx(loss + dw + p_mech, rel=1e-4), (p_in, loss, dw, p_mech)


@pytest.mark.parametrize("rpm, load, was", [(900.0, 29.7, 343.0), (1800.0, 29.7, 6797.0)])
def test_a_steady_start_on_the_map_is_steady(rpm, load, was):
    """The saturated PM-SyRM (``docs/examples/pmsyrm_5p6kw_sat.toml``) started steady, sensored: its operating point
    is the map's (torque and voltage from its flux at the currents, field weakening's equilibrium on it at 1800
    r/min), so the first samples' current hardly moves (measured 0.21 and 1.4 A/s); from the constants' point it
    drifted at ``was`` A/s, and at 1800 r/min the speed fell 31 r/min while field weakening found its i_d."""
    from pathlib import Path

    from jaxobs.runtime import simulate

    f = D.read_drive(Path(__file__).parents[1] / "docs" / "examples" / "pmsyrm_5p6kw_sat.toml")
    sc = D.Scenario(f.machine, speed_ref=D.Profile.constant(rpm * D.RPM), omega_m0=rpm * D.RPM,
                    load=D.Profile.constant(load))  # fmt: skip
    out = simulate(D.ClosedLoop(f.drive_for(sensorless=False), None, sc), 0.01).outputs
    i_d, i_q = np.asarray(out.i_d), np.asarray(out.i_q)
    di_dt = np.hypot(np.diff(i_d[:11]), np.diff(i_q[:11])) / f.ts
    assert di_dt.max() < 20.0 < was / 10, di_dt.max()
    assert np.max(np.abs(np.asarray(out.speed_rpm) - rpm)) < 0.01
