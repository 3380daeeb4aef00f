"""The pulse criterion the tests hold a stability verdict against, one copy for every test that does.

A point holds when a simulation of its loop, its speed reference pulsed by ``height`` (relative) at 0.05 s for
one time constant 1/α of the point's speed loop (``FOC.speed_gains``) and back, ends with a peak speed deviation
over the run's second half under 1 % and at most 2 % above the peak from 3/α after the pulse to the half
(docs/stability.md): independent of the envelope's running sums.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import jaxobs
from jaxobs.analysis.envelope import speed_pulse
from jaxobs.drive import RPM
from jaxobs.scenarios.families import drive_scenarios


def pulse_held(system, designs: dict, machine, foc, points, *, height: float = 0.02, horizon: float = 3.0) -> dict:
    """Whether each point holds under the pulse criterion (module doc), per design.

    Args:
        system: ``system(observer, scenario)``: the loop a design closes at a scenario.
        designs: ``{name: observer}``, one class (one program; the observer is its argument).
        machine: The machine the scenarios are built on.
        foc: The FOC, bound, whose speed gains give each point's α.
        points: ``(speed r/min, load N·m)`` pairs.
        height: The pulse, relative (negative: down).
        horizon: The simulations' length, s.

    Returns:
        ``{name: bool array, one per point}``.
    """
    horizon = float(horizon)  # a static length (an attribute read back from NetCDF is a 0-d array)
    gains = [foc.speed_gains(jnp.asarray(s * RPM)) for s, _ in points]
    width = np.array([float(kp) / (2 * float(ki)) for kp, ki in gains])  # 1/α of each point's speed loop
    sc = speed_pulse(drive_scenarios(machine, ["speed_rpm", "load_nm"], list(points)), 0.05, width, height)

    @jax.jit
    def run(obs, sc, t_early):
        def one(sc, te):
            o = jaxobs.simulate(system(obs, sc), horizon).outputs
            dev = jnp.abs(o.omega_m - o.omega_m_ref) / jnp.abs(o.omega_m_ref)
            early = jnp.max(jnp.where((o.t >= te) & (o.t < 0.5 * horizon), dev, 0.0))
            late = jnp.max(jnp.where(o.t >= 0.5 * horizon, dev, 0.0))
            return (late < 0.01) & (late <= 1.02 * early) & jnp.isfinite(late)

        return jax.vmap(one)(sc, t_early)

    t_early = jnp.asarray(0.05 + 4 * width)
    return {d: np.asarray(run(obs, sc, t_early)) for d, obs in designs.items()}
