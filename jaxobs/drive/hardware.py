"""Inverter (average-value model) and sensors.

Inverter: the commanded stationary-frame voltage is limited to the circle
|u| ≤ U_dc/√3 (the linear range of space-vector modulation).  Its ``pwm`` is
``"averaged"`` (the default): the voltage is held over the period and the dead
time adds, per phase, Δu_x = −U_dc·T_d·f_pwm·sgn(i_x) (x = a, b, c), taken
back to αβ with the amplitude-invariant Clarke transform; or ``"carrier"``:
the plant integrates the switched voltage of a triangular carrier's comparison
between its switching instants, dead time on the edges (:mod:`jaxobs.drive.pwm`).
A device drop u_device lowers each leg's voltage by u_device·sgn(i_x) in both.  ``i_smooth > 0``
replaces sgn by tanh(i/i_smooth) so gradients flow; ``i_smooth = 0`` is the
exact sign.  The one-sample computation delay lives in the closed-loop scan:
the voltage applied over [t_k, t_{k+1}] is the one computed at t_{k−1}.

Sensors: measured = (1 + gain error)·true + offset + white noise, per axis,
for the stationary-frame currents and for the voltage the observer is told
was applied (000 Sec. IV-C: Δu_α = 5 V, Δi_β = 1.5 A).  Noise comes from a PRNG
key folded with the sample index, so a run is reproducible and vmappable.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer

from ..core.measurements import DriveInput
from ..core.numerics import safe_norm2
from ..core.validate import as_float, check_nonnegative, check_positive, check_real
from ..core.validate import static_float as _static_float
from .component import AbstractComponent

__all__ = ["PWM_MODELS", "Inverter", "InverterInput", "Sensors", "SensorInput", "clarke_abc_to_ab", "ab_to_abc"]

_Tracer = jax.core.Tracer  # pyright: ignore[reportAttributeAccessIssue]  # jax.core: not in jax's stubs

_S3 = math.sqrt(3.0)
PWM_MODELS = ("averaged", "carrier")  # Inverter.pwm's choices
VOLTAGE_LIMITS = ("circle", "hexagon")  # Inverter.voltage_limit's choices


def ab_to_abc(
    a: jax.Array | float, b: jax.Array | float
) -> tuple[jax.Array | float, jax.Array | float, jax.Array | float]:
    """The phase values of a stationary-frame (α, β) vector (amplitude-invariant inverse Clarke).

    Args:
        a: α.
        b: β.

    Returns:
        ``(a, b, c)``.
    """
    return a, -0.5 * a + 0.5 * _S3 * b, -0.5 * a - 0.5 * _S3 * b


def clarke_abc_to_ab(xa: jax.Array, xb: jax.Array, xc: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Amplitude-invariant Clarke transform.

    Args:
        xa: Phase a.
        xb: Phase b.
        xc: Phase c.

    Returns:
        ``(α, β)``.
    """
    return (2.0 / 3.0) * (xa - 0.5 * (xb + xc)), (xb - xc) / _S3


class InverterInput(NamedTuple):
    """The commanded stationary-frame voltage.

    Attributes:
        u_a: u_α, V.
        u_b: u_β, V.
    """

    u_a: jax.Array
    u_b: jax.Array


class SensorInput(NamedTuple):
    """The true quantities a sensor set measures at sample ``k``.

    Attributes:
        k: The sample index (the noise is a function of the key and k).
        u_a: The α voltage applied over the period that starts at t_k, V.
        u_b: The β voltage, V.
        i_a: The stationary-frame α current at t_k, A.
        i_b: The β current at t_k, A.
    """

    k: jax.Array  # sample index (the noise is a function of the key and k)
    u_a: jax.Array  # voltage applied over the period that starts at t_k, V
    u_b: jax.Array
    i_a: jax.Array  # stationary-frame currents at t_k, A
    i_b: jax.Array


class Inverter(AbstractComponent):
    """Average-value two-level inverter with dc-link limit and dead time.

    As a step component it is stateless: ``step(None, InverterInput)`` returns the
    voltage it can apply (the command limited to |u| ≤ U_dc/√3).  The dead-time
    error depends on the instantaneous current, so the plant adds it inside its
    vector field (:class:`~jaxobs.drive.PMSM`).

    With ``pwm="carrier"`` the plant integrates the switched voltage instead (:mod:`jaxobs.drive.pwm`): one
    carrier period per control period, so ``f_pwm`` must be the sampling frequency (checked by
    :class:`~jaxobs.drive.PMSM`).

    Args:
        udc: The dc-link voltage, V (> 0).
        f_pwm: The switching frequency, Hz (> 0).
        i_smooth: The tanh width for the dead-time sign, A (0: the exact sign).
        pwm: ``"averaged"`` (default) or ``"carrier"``.
        u_device: The conducting device's voltage drop, V (≥ 0; default 0).
        voltage_limit: ``"circle"`` (default: |u| ≤ U_dc/√3, the linear range) or ``"hexagon"`` (the whole
            space-vector hexagon, up to 2U_dc/3 at its vertices; overmodulation by minimum phase error, see
            :meth:`limit`).

    Raises:
        ValueError: A value out of its range, naming the field.
    """

    udc: jax.Array  # dc-link voltage, V (> 0)
    f_pwm: jax.Array  # switching frequency, Hz (> 0)
    i_smooth: float = eqx.field(static=True)  # tanh width for the dead-time sign, A (0: exact sign)
    # device drop, V (≥ 0), static: a drop of zero leaves the averaged plant's traced program as it was without
    # drops (a traced zero would add terms, and XLA's fusion then moves the last bits)
    u_device: float = eqx.field(static=True)
    pwm: str = eqx.field(static=True)  # "averaged" or "carrier"
    voltage_limit: str = eqx.field(static=True)  # "circle" or "hexagon"

    def __init__(self, udc=540.0, f_pwm=10e3, i_smooth=0.0, pwm="averaged", u_device=0.0, voltage_limit="circle"):
        self.udc = check_positive("udc", udc, "Inverter")
        self.f_pwm = check_positive("f_pwm", f_pwm, "Inverter")
        self.i_smooth = _static_float(check_nonnegative("i_smooth", i_smooth, "Inverter"), i_smooth)
        self.u_device = _static_float(check_nonnegative("u_device", u_device, "Inverter"), u_device)
        if pwm not in PWM_MODELS:
            raise ValueError(f"Inverter.pwm must be one of {PWM_MODELS}, got {pwm!r}")
        self.pwm = pwm
        if voltage_limit not in VOLTAGE_LIMITS:
            raise ValueError(f"Inverter.voltage_limit must be one of {VOLTAGE_LIMITS}, got {voltage_limit!r}")
        self.voltage_limit = voltage_limit

    @property
    def u_max(self) -> jax.Array:
        """The linear range of space-vector modulation, u_dc/√3, V."""
        return self.udc / _S3

    @property
    def u_vertex(self) -> jax.Array:
        """The largest |u| the inverter applies: 2U_dc/3 at the hexagon's vertices (U_dc/√3 under the circle)."""
        return 2.0 * self.udc / 3.0 if self.voltage_limit == "hexagon" else self.u_max

    def limit(self, u_a: jax.Array, u_b: jax.Array) -> tuple[jax.Array, jax.Array]:
        """Scale the voltage vector back onto the circle |u| ≤ U_dc/√3, or onto the hexagon (direction kept).

        The hexagon is max_x v_x − min_x v_x ≤ U_dc over the phase voltages (what min-max injection can apply:
        U_dc/√3 across its edges' middles, 2U_dc/3 at its vertices).  A vector beyond it is scaled back onto it
        along its own direction: minimum phase error overmodulation.  DECISION: minimum phase error rather than
        minimum magnitude error (the nearest point of the hexagon), because the current controller's angle and
        the decoupling it computes stay right; the lost magnitude is what its anti-windup sees.

        Args:
            u_a: u_α, V.
            u_b: u_β, V.

        Returns:
            The limited ``(u_α, u_β)``, V.
        """
        if self.voltage_limit == "hexagon":
            va, vb, vc = ab_to_abc(u_a, u_b)
            span = jnp.maximum(jnp.maximum(va, vb), vc) - jnp.minimum(jnp.minimum(va, vb), vc)
            scale = jnp.where(span > self.udc, self.udc / jnp.maximum(span, 1e-12), 1.0)
            return u_a * scale, u_b * scale
        mag = safe_norm2(u_a, u_b)
        scale = jnp.where(mag > self.u_max, self.u_max / jnp.maximum(mag, 1e-12), 1.0)
        return u_a * scale, u_b * scale

    def init(self, op: object = None) -> None:
        """No state (the operating point does not matter to an average-value model).

        Args:
            op: The operating point (unused).

        Returns:
            None.
        """
        return None

    def step(self, state: None, inp: InverterInput) -> tuple[None, InverterInput]:
        """The commanded voltage within the inverter's limit.

        Args:
            state: None (the inverter has no state).
            inp: The :class:`InverterInput`.

        Returns:
            ``(None, the limited InverterInput)``.
        """
        return state, InverterInput(*self.limit(inp.u_a, inp.u_b))

    def sign(self, i: jax.Array | float) -> jax.Array:
        """The current's sign the dead time and the device drop act by: sgn(i), or tanh(i/i_smooth).

        Args:
            i: A phase current, A.

        Returns:
            The (smoothed) sign.
        """
        if self.i_smooth > 0:
            return jnp.tanh(i / self.i_smooth)
        return jnp.sign(i)

    def dead_time_error(
        self, dead_time: jax.Array | float, i_a: jax.Array | float, i_b: jax.Array | float
    ) -> tuple[jax.Array, jax.Array]:
        """Stationary-frame voltage error of the dead time at the current i_ab.

        Args:
            dead_time: The dead time, s.
            i_a: The α current, A.
            i_b: The β current, A.

        Returns:
            ``(Δu_α, Δu_β)``, V.
        """
        du = self.udc * dead_time * self.f_pwm
        ia, ib, ic = ab_to_abc(i_a, i_b)
        return clarke_abc_to_ab(-du * self.sign(ia), -du * self.sign(ib), -du * self.sign(ic))

    @property
    def has_device_drop(self) -> bool:
        """False where the device drop is zero (the averaged plant then skips it)."""
        return self.u_device != 0.0

    def device_drop_error(self, i_a: jax.Array | float, i_b: jax.Array | float) -> tuple[jax.Array, jax.Array]:
        """Stationary-frame voltage error of the device drops at the current i_ab: −u_device·sgn(i_x) per leg.

        Args:
            i_a: The α current, A.
            i_b: The β current, A.

        Returns:
            ``(Δu_α, Δu_β)``, V.
        """
        ia, ib, ic = ab_to_abc(i_a, i_b)
        d = self.u_device
        return clarke_abc_to_ab(-d * self.sign(ia), -d * self.sign(ib), -d * self.sign(ic))


def _statically_zero(x) -> bool:
    if isinstance(x, _Tracer):  # traced: could be anything
        return False
    return bool(np.all(np.asarray(x) == 0))


def _pair(x):
    """(α, β) as an array of the default float dtype: Python numbers by NumPy (no XLA kernel compiled to stack
    them), anything else (traced values) by JAX."""
    dtype = as_float(0.0).dtype
    if isinstance(x, (tuple, list)) and all(isinstance(v, (int, float, np.generic)) for v in x):
        return np.asarray(x, dtype=dtype)
    return jnp.asarray(x, dtype=dtype)


class Sensors(AbstractComponent):
    """Per-axis offsets, gain errors and white noise of the current and voltage measurements.

    As a step component its state is the PRNG key of its noise (``init(op, key=key)``),
    and ``step(key, SensorInput) -> (key, DriveInput)`` gives the measured
    voltage and current an observer is told; the noise of sample k is drawn
    from ``fold_in(key, k)``, so a run is reproducible, vmappable and the same
    whatever the loop's blocking.

    Args:
        i_offset: The current offsets (Δi_α, Δi_β), A.
        u_offset: The voltage offsets (Δu_α, Δu_β), V.
        i_gain_error: The current gain errors (ε_α, ε_β): the gains are 1 + ε (ε > −1).
        i_noise: The current noise standard deviation, A (≥ 0).
        u_noise: The voltage noise standard deviation, V (≥ 0).

    Raises:
        ValueError: A value out of its range, naming the field.
    """

    i_offset: jax.Array  # (Δi_α, Δi_β), A
    u_offset: jax.Array  # (Δu_α, Δu_β), V
    i_gain: jax.Array  # (1 + ε_α, 1 + ε_β) on the current
    i_noise: jax.Array  # current noise standard deviation, A
    u_noise: jax.Array  # voltage noise standard deviation, V
    # Whether ``measure`` draws noise at all (static, from the constructor's arguments): without noise the loop
    # skips the PRNG (docs/performance.md).  Traced noise levels count as noisy.  Change noise levels through the
    # constructor, not ``tree_at``.
    noisy: bool = eqx.field(static=True)

    def __init__(self, i_offset=(0.0, 0.0), u_offset=(0.0, 0.0), i_gain_error=(0.0, 0.0), i_noise=0.0, u_noise=0.0):
        own = "Sensors"
        self.i_offset = check_real("i_offset", _pair(i_offset), owner=own)
        self.u_offset = check_real("u_offset", _pair(u_offset), owner=own)
        gain_error = check_real("i_gain_error", _pair(i_gain_error), lower=-1.0, owner=own)
        self.i_gain = 1.0 + gain_error if isinstance(gain_error, Tracer) else as_float(1.0 + np.asarray(gain_error))
        self.i_noise = check_nonnegative("i_noise", i_noise, own)
        self.u_noise = check_nonnegative("u_noise", u_noise, own)
        self.noisy = not _statically_zero(i_noise) or not _statically_zero(u_noise)
        for name in ("i_offset", "u_offset", "i_gain"):
            if getattr(self, name).shape[-1:] != (2,):
                raise ValueError(f"{own}.{name} must have two entries (α, β), got shape {getattr(self, name).shape}")

    def init(self, op: object = None, *, key: jax.Array | None = None) -> jax.Array:
        """The sensors' state, whatever the operating point: the noise key.

        Args:
            op: An :class:`OperatingPoint` or None (unused).
            key: The noise key (default ``PRNGKey(0)``).

        Returns:
            The key.

        Raises:
            ValueError: ``op`` is neither an operating point nor None.
        """
        if op is not None and not isinstance(op, tuple):  # a key passed where init(key) used to take it
            raise ValueError(
                f"Sensors.init: op must be an OperatingPoint or None (the key is keyword-only), got {type(op).__name__}"
            )
        return jax.random.PRNGKey(0) if key is None else key

    def step(self, key: jax.Array, inp: SensorInput) -> tuple[jax.Array, DriveInput]:
        """The measured quantities at one sample.

        Args:
            key: The sensors' noise key.
            inp: The :class:`SensorInput`.

        Returns:
            ``(the key, the DriveInput as measured)``.
        """
        return key, DriveInput(*self.measure(key, inp.k, inp.u_a, inp.u_b, inp.i_a, inp.i_b))

    def measure(
        self,
        key: jax.Array,
        k: jax.Array | int,
        u_a: jax.Array | float,
        u_b: jax.Array | float,
        i_a: jax.Array | float,
        i_b: jax.Array | float,
    ) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
        """Measured (u_α, u_β, i_α, i_β) at sample ``k``.

        Args:
            key: The sensors' noise key.
            k: The sample index.
            u_a: The true α voltage, V.
            u_b: The true β voltage, V.
            i_a: The true α current, A.
            i_b: The true β current, A.

        Returns:
            ``(u_α, u_β, i_α, i_β)`` as measured.
        """
        if not self.noisy:
            return (
                u_a + self.u_offset[0],
                u_b + self.u_offset[1],
                self.i_gain[0] * i_a + self.i_offset[0],
                self.i_gain[1] * i_b + self.i_offset[1],
            )
        kk = jax.random.fold_in(key, k)
        n = jax.random.normal(kk, (4,), dtype=jnp.result_type(u_a, float))
        um_a = u_a + self.u_offset[0] + self.u_noise * n[0]
        um_b = u_b + self.u_offset[1] + self.u_noise * n[1]
        im_a = self.i_gain[0] * i_a + self.i_offset[0] + self.i_noise * n[2]
        im_b = self.i_gain[1] * i_b + self.i_offset[1] + self.i_noise * n[3]
        return um_a, um_b, im_a, im_b
