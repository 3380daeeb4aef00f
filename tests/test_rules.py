"""Discretization rules: order of accuracy, and agreement with diffrax and python-control."""

import math

import control
import diffrax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs
from jaxobs import papers
from jaxobs.core.discretize import Held, Knots, diffrax_rk4_step

OMEGA_C = 2 * math.pi * 50.0  # SOGI centre
OMEGA_IN = 2 * math.pi * 55.0  # input frequency (off-centre, so the response is not trivial)
T_END = 0.1


def _input(t):
    return jnp.sin(OMEGA_IN * t) + 0.3 * jnp.cos(3 * OMEGA_IN * t + 0.4)


def _reference_state(k, t_end):
    """Tight diffrax solution of the linear SOGI driven by the continuous input."""
    sogi = jaxobs.SOGI(k=k, omega=OMEGA_C)
    term = diffrax.ODETerm(sogi.vector_field)
    sol = diffrax.diffeqsolve(
        term,
        diffrax.Dopri8(),
        0.0,
        t_end,
        1e-5,
        jnp.zeros(2),
        args=_input,
        stepsize_controller=diffrax.PIDController(rtol=1e-13, atol=1e-15),
        max_steps=200_000,
    )
    return np.asarray(sol.ys[-1])


@pytest.mark.parametrize(
    "rule, order",
    [(jaxobs.Euler(), 1), (jaxobs.Tustin(), 2), (jaxobs.AB3(), 3), (jaxobs.RK4(), 4)],
    ids=["Euler", "Tustin", "AB3", "RK4"],
)
def test_rule_order_on_linear_sogi(rule, order):
    """Fitted log-slope of the error at T_END vs a tight diffrax reference is the rule's order ± 0.3."""
    k = papers.SOIFO_K
    ref = _reference_state(k, T_END)
    hs = [4e-4, 2e-4, 1e-4, 5e-5]
    errs = []
    for h in hs:
        sogi = jaxobs.SOGI(k=k, omega=OMEGA_C, ts=h, rule=rule)
        sol = jaxobs.simulate(jaxobs.OnSignal(sogi, _input, knots=True), T_END)
        errs.append(np.linalg.norm(np.asarray(sol.final_state.x) - ref))
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert abs(slope - order) <= 0.3, (type(rule).__name__, slope, errs)
    assert rule.order == order


def test_rk4_equals_diffrax_erk_step():
    """Our hot-loop RK4 and the classic tableau run through diffrax's ERK machinery agree."""
    obs = jaxobs.linear.wif_closed_form()
    x = jnp.array([0.1, -0.2, 0.9, 0.3, 320.0])
    u = Knots(u0=jnp.array(0.7), um=jnp.array(0.75), u1=jnp.array(0.8))
    ours, _ = jaxobs.RK4().step(obs.f, x, u, 1e-4, None)
    ref = diffrax_rk4_step(obs.f, x, u, 1e-4)
    np.testing.assert_allclose(np.asarray(ours), np.asarray(ref), rtol=1e-14, atol=1e-14)


def test_euler_is_diffrax_euler_step():
    obs = jaxobs.linear.sogi_fll_closed_form()
    x = jnp.array([0.5, -0.4, 314.0])
    ours, _ = jaxobs.Euler().step(obs.f, x, jnp.array(0.3), 1e-4, None)
    np.testing.assert_allclose(np.asarray(ours), np.asarray(x + 1e-4 * obs.f(x, 0.3)), rtol=1e-15)


def test_tustin_is_the_bilinear_transform():
    """On the linear SOGI, the Tustin rule reproduces python-control's Tustin discretization."""
    k, h = 1.2, 1e-4
    sogi = jaxobs.SOGI(k=k, omega=OMEGA_C, ts=h, rule=jaxobs.Tustin())
    n = 2000
    sol = jaxobs.simulate(jaxobs.OnSignal(sogi, lambda t: jnp.sin(OMEGA_IN * t), knots=True), n * h)
    g = control.tf([k * OMEGA_C, 0], [1, k * OMEGA_C, OMEGA_C**2])
    gd = control.sample_system(g, h, method="tustin")
    t = np.arange(n) * h
    y = control.forced_response(gd, T=t, U=np.sin(OMEGA_IN * t)).outputs
    np.testing.assert_allclose(np.asarray(sol.outputs.obs.v_alpha), y, atol=1e-11)


def test_held_input_is_zero_order_hold():
    assert Held(3.0).at(0.7) == 3.0
    kn = Knots(u0=1.0, um=2.0, u1=5.0)
    assert kn.at(0.0) == 1.0 and kn.at(0.5) == 2.0 and kn.at(1.0) == 5.0
    # the interpolant is the quadratic through the three knots
    s = 0.25
    expected = 1.0 * 2 * (s - 0.5) * (s - 1) + 2.0 * (-4) * s * (s - 1) + 5.0 * 2 * s * (s - 0.5)
    assert float(kn.at(jnp.asarray(s))) == pytest.approx(expected)


def test_ab3_startup_uses_history_after_two_steps():
    """After two RK4 start-up steps AB3 is the explicit 001 formula on the stored history."""
    obs = jaxobs.linear.sogi_fll_closed_form(rule=jaxobs.AB3())
    rule = obs.rule
    x = obs.initial_state() + jnp.array([0.3, 0.1, 0.0])
    st = rule.init(obs.f, x, 1.0)
    xs, fs = [x], []
    for u in (1.0, 0.9, 0.8):
        fs.append(obs.f(xs[-1], u))
        x1, st = rule.step(obs.f, xs[-1], u, 1e-4, st)
        xs.append(x1)
    manual = xs[2] + 1e-4 / 12 * (23 * fs[2] - 16 * fs[1] + 5 * fs[0])
    np.testing.assert_allclose(np.asarray(xs[3]), np.asarray(manual), rtol=1e-15)


def test_tustin_newton_iters_validated():
    with pytest.raises(ValueError, match="newton_iters"):
        jaxobs.Tustin(newton_iters=0)
