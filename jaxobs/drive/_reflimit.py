"""|i| ≤ i_max at every sample: the current reference's margin below i_max and the current loop's error limit
(``FOC(current_margin=..., error_limit=...)``; a drive file sets both, :mod:`jaxobs.drive.drivefile`; the papers'
benches run without them, bit for bit as before).

The references alone never leave the circle |i*| ≤ i_max (:class:`~jaxobs.drive.FOC`), but the current follows
them through the discrete loop: the voltage computed from the samples at t_k acts n periods later (the use delay,
1.5 by default, :mod:`jaxobs.drive.latency`), and the IMC loop, designed at a 60° phase margin with that delay,
overshoots a step of its reference.  Per unit, with the R–L pole cancelled (k_p = α_c L̂), the sampled current
obeys i_{k+1} − i_k = α_c T_s Σ_j w_j (i*_{k−j} − i_{k−j}), w_j the share of period k that the voltage of
sample k − j covers (its one period of PWM centred n periods after its sample): a step overshoots by
o = 5.68 % at the default α_c T_s = (π/6)/1.5 (:func:`step_overshoot`).  A standstill start's speed loop steps
i* onto the circle (0.73 → 1.0 × i_max on the traction IPMSM of ``docs/examples/traction_ipmsm.toml``: 1.0104 ×
i_max for 3 periods; 0.947 → 1.0 on the PM-SyRM of ``docs/examples/pmsyrm_5p6kw_sat.toml``: 1.0034).

Two limits, as a drive's current controller has them:

- *The error limit* (``error_limit`` E, per unit of i_max; :data:`ERROR_LIMIT_PU` = 0.1): the current PIs see
  the error vector i* − i at most E i_max long, its direction kept (:func:`limit_error`).  A step then becomes a
  ramp of α_c T_s E i_max per period (0 → i_max in about 30 periods, 3 ms at 10 kHz: a tenth of the speed
  loop's time constant at the derived α_s ≤ α_c/10), and the overshoot at its end is that of a step of E,
  about o E: the in-flight voltages of a ramp that meets its end with the error at E.  Steady operation and
  small-signal steps (|i* − i| < E i_max) are untouched.
- *The reference margin* (``current_margin`` h, per unit): the references' circle lies at (1 − h) i_max, with
  h = :data:`MARGIN_SAFETY` × o × E (:func:`reference_margin`; 0.71 % at the defaults): 25 % over the model's
  overshoot for what the model leaves out (the PIs' integral, the decoupling's error at speed, a saturated
  machine's inductance along the way).  Measured (``tests/test_current_limit.py``): the traction IPMSM's start
  overshot its reference by 0.548 % of i_max with E = 0.1 (the model's o E: 0.568 %).

The margin costs h of the torque at the current limit (0.71 %); a margin for the unlimited loop's whole step
overshoot, o/(1 + o) = 5.4 %, would have cost the traction IPMSM its rated torque at rated speed.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..core.numerics import safe_norm2

__all__ = ["ERROR_LIMIT_PU", "MARGIN_SAFETY", "limit_error", "reference_margin", "step_overshoot"]

ERROR_LIMIT_PU = 0.1  # E: the current error the PIs see, at most a tenth of i_max (module doc)
MARGIN_SAFETY = 1.25  # the reference margin: 25 % over the model's overshoot o E (module doc)
_HORIZON = 400  # periods of the model's step response: its poles lie within |z| ≤ 0.75 at α_c T_s n ≤ 60°'s


def step_overshoot(alpha_c_ts: float, use_delay: float) -> float:
    """The overshoot (per unit of the step, ≥ 0) of the sampled current after a step of its reference, on the IMC
    loop with the R–L pole cancelled and the use delay n (module doc): the model's step response over 400 periods
    (one triangular solve, no loop in Python).

    Args:
        alpha_c_ts: α_c T_s, rad (> 0).
        use_delay: n, periods from the sample to the centre of the PWM period its voltage drives (≥ 0.5, a
            multiple of 0.5: :attr:`jaxobs.drive.Latency.use_delay`).

    Returns:
        o, the step overshoot (0 where the response does not overshoot).

    Raises:
        ValueError: ``alpha_c_ts`` not in (0, 2] or ``use_delay`` not a multiple of 0.5 in [0.5, 4].
    """
    if not (0.0 < alpha_c_ts <= 2.0):
        raise ValueError(f"step_overshoot: alpha_c_ts must be in (0, 2] rad, got {alpha_c_ts!r}")
    if not (0.5 <= use_delay <= 4.0 and float(2 * use_delay).is_integer()):
        raise ValueError(f"step_overshoot: use_delay must be a multiple of 0.5 in [0.5, 4] periods, got {use_delay!r}")
    # w_j: the overlap of [n − ½ − j, n + ½ − j] (the voltage of sample k − j, in period units from t_k) with [0, 1]
    lags = np.arange(int(math.ceil(use_delay)) + 1)
    w = np.clip(np.minimum(use_delay + 0.5 - lags, 1.0) - np.maximum(use_delay - 0.5 - lags, 0.0), 0.0, 1.0)
    # i_{k+1} = i_k + a Σ w_j (r − i)_{k−j}: in z⁻¹, I (1 − z⁻¹ + a Σ w_j z^(−j−1)) = a Σ w_j z^(−j−1) R
    b = np.concatenate([[0.0], alpha_c_ts * w])
    den = b.copy()
    den[0], den[1] = 1.0, den[1] - 1.0
    # the filter's step response, den * i = b * 1 over the horizon, as one lower-triangular Toeplitz solve
    # (scipy.signal.lfilter's result; importing scipy.signal costs 1.6 s of a plain drive check)
    k = np.arange(_HORIZON)
    lag = k[:, None] - k[None, :]
    toeplitz = np.where((lag >= 0) & (lag < den.size), den[np.clip(lag, 0, den.size - 1)], 0.0)
    i = np.linalg.solve(toeplitz, np.convolve(b, np.ones(_HORIZON))[:_HORIZON])
    return max(float(np.max(i)) - 1.0, 0.0)


def reference_margin(alpha_c_ts: float, use_delay: float, error_limit: float = ERROR_LIMIT_PU) -> float:
    """h = :data:`MARGIN_SAFETY` × o × E: the references' circle at (1 − h) i_max (module doc).

    Args:
        alpha_c_ts: α_c T_s, rad.
        use_delay: The use delay n, periods.
        error_limit: E, the current loop's error limit, per unit of i_max (in (0, 0.5]).

    Returns:
        h, per unit of i_max.

    Raises:
        ValueError: A value out of its range.
    """
    if not (0.0 < error_limit <= 0.5):
        raise ValueError(f"reference_margin: error_limit must be in (0, 0.5] (per unit of i_max), got {error_limit!r}")
    return MARGIN_SAFETY * step_overshoot(alpha_c_ts, use_delay) * error_limit


def limit_error(e_d: jax.Array, e_q: jax.Array, e_max: jax.Array | float) -> tuple[jax.Array, jax.Array]:
    """The current error vector (e_d, e_q) at most ``e_max`` long, its direction kept (module doc).

    Args:
        e_d: i_d* − i_d, A.
        e_q: i_q* − i_q, A.
        e_max: The longest error, A (> 0).

    Returns:
        The limited ``(e_d, e_q)``, A.
    """
    mag = safe_norm2(e_d, e_q)
    scale = jnp.minimum(1.0, e_max / jnp.maximum(mag, 1e-12))
    return e_d * scale, e_q * scale
