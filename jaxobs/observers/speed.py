"""Speed and position extraction as a strategy a drive observer holds: a PLL, or a mechanical-model observer.

A position observer (a LESO of 002, a flux observer of 000) gives a phase error ε ≈ sin(θe − θ̂) from its own
estimate (a back EMF, a flux) and the extracted angle θ̂.  What turns ε into θ̂ and ω̂ is a separate part with
states of its own, appended to the observer's state after the observer's filter states:

- :class:`PLLSpeed`: the type-2 PLL the observers always had, states [θ̂, ω̂]:

      θ̂̇ = ω̂ + k_p ε,     ω̂̇ = k_i ε                      (jaxobs.observers._cores.pll_vf)

  Its gains are the host observer's ``kp_pll`` and ``ki_pll`` (the names the tuning tools, the studies and
  the C export know), so a PLL strategy holds no leaves of its own.

- :class:`MechanicalSpeed`: a mechanical-model speed observer, states [θ̂, ω̂, T̂L], driven by the torque
  reference T* the controller commands (:attr:`jaxobs.core.measurements.DriveInput.T_ref`) and the assumed inertia
  Ĵ, friction B̂ and pole pairs p (ω in electrical rad/s):

      θ̂̇ = ω̂ + k1 ε
      ω̂̇ = (p/Ĵ)(T* − T̂L) − (B̂/Ĵ) ω̂ + k2 ε
      T̂̇L = −(Ĵ/p) k3 ε

  The structure is the one of the mechanical-model speed observer with a load-torque estimate in Hinkkanen,
  Saarakkala, Awan, Mölsä, Tuovinen, "Observers for sensorless synchronous motor drives: framework for design
  and analysis", IEEE Trans. Ind. Appl. 54(6), 2018 (its speed-estimation section), written here on the
  phase error of our detectors.  Closed form (our derivation): with ε ≈ θe − θ̂, a constant load and B̂ = 0,
  the errors e_θ = θe − θ̂, e_ω = ωe − ω̂, e_T = TL − T̂L obey

      ė_θ = e_ω − k1 e_θ,   ė_ω = −(p/Ĵ) e_T − k2 e_θ,   ė_T = (Ĵ/p) k3 e_θ

  so their characteristic polynomial is s³ + k1 s² + k2 s + k3, independent of Ĵ and p (they scale the
  load-torque state only).  A triple pole at −α_o gives k1 = 3α_o, k2 = 3α_o², k3 = α_o³
  (:meth:`MechanicalSpeed.closed_form`).  B̂ > 0 adds −B̂/Ĵ to the e_ω row: a damping term, left out of
  the placement.  With T* = 0 (a signal-level use, or a drive that gives no torque reference) the
  observer is a type-3 PLL whose third state is the acceleration −(p/Ĵ)T̂L: it tracks a speed ramp
  without a steady angle error, and keeps ramping where ε fades (through zero speed, where a LESO's back EMF
  vanishes); with T* it carries the speed through on the torque model.

An inertia error Ĵ = J(1 + δ) leaves the error polynomial unchanged for a constant torque (the load state
absorbs it) but turns every step of T* into a disturbance (δ/(1 + δ))·T*/Ĵ of the acceleration: the
drive study axis ``dJ`` (jaxobs.drive.DRIVE_AXES) moves the true inertia with the assumed one kept, which is
that case.
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar, Protocol

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from ..core.validate import check_nonnegative, check_positive
from ._cores import pll_vf
from ._gains import gain_metadata

__all__ = [
    "AbstractSpeedEstimator",
    "PLLSpeed",
    "MechanicalSpeed",
    "mechanical_gains",
    "alpha_o_out_of_range",
    "speed_from_spec",
    "SPEED_KINDS",
    "MECHANICAL_GAINS",
    "SpeedHost",
    "MachineInertia",
]

# what a job's [observer.speed] ``kind`` names (tuning/job/schema.py)
SPEED_KINDS = ("pll", "mechanical")
# a mechanical model's gains a record may set beside its α_o, and a job may tune (``[gains.speed.k1]``)
MECHANICAL_GAINS = ("k1", "k2", "k3")


class SpeedHost(Protocol):
    """The observer that holds a speed estimator, as the estimator reads it: its PLL gains (a PLL's are its host's).

    Attributes:
        kp_pll: The PLL's proportional gain, 1/s.
        ki_pll: The PLL's integral gain, 1/s².
    """

    @property
    def kp_pll(self) -> jax.Array:
        """The PLL's proportional gain, 1/s."""
        ...

    @property
    def ki_pll(self) -> jax.Array:
        """The PLL's integral gain, 1/s²."""
        ...


class MachineInertia(Protocol):
    """The assumed machine's mechanics, as a mechanical-model speed observer binds them (a
    :class:`jaxobs.drive.PMSMParams` has them).

    Attributes:
        J: Inertia, kg·m².
        B: Viscous friction, N·m·s/rad.
        p: Pole pairs.
    """

    @property
    def J(self) -> jax.Array:
        """Inertia, kg·m²."""
        ...

    @property
    def B(self) -> jax.Array:
        """Viscous friction, N·m·s/rad."""
        ...

    @property
    def p(self) -> int:
        """Pole pairs."""
        ...


class AbstractSpeedEstimator(eqx.Module):
    """What turns an observer's phase error ε ≈ sin(θe − θ̂) into θ̂ and ω̂ (module doc).

    The states are [θ̂, ω̂, ...]: the angle (rad) and the electrical speed (rad/s) first, then the
    strategy's own (``n_states`` in all).
    """

    n_states: eqx.AbstractClassVar[int]
    # whether vf reads the torque reference: a drive loop computes T* for the observer only then
    uses_torque: eqx.AbstractClassVar[bool]

    def initial_state(self, theta0: ArrayLike, omega0: ArrayLike) -> jax.Array:
        """The states at the start: [θ̂0, ω̂0, 0, ...].

        Args:
            theta0: θ̂0, rad.
            omega0: ω̂0, rad/s.

        Returns:
            The ``n_states`` states.
        """
        head = jnp.stack([jnp.asarray(theta0), jnp.asarray(omega0)])
        return jnp.concatenate([head, jnp.zeros((self.n_states - 2,), head.dtype)])

    @abc.abstractmethod
    def vf(self, host: SpeedHost, xs: jax.Array, err: jax.Array, torque: ArrayLike) -> jax.Array:
        """The states' rates.

        Args:
            host: The observer holding this strategy (a PLL reads its ``kp_pll`` and ``ki_pll``).
            xs: The strategy's states [θ̂, ω̂, ...].
            err: The phase error ε, ≈ sin(θe − θ̂).
            torque: The torque reference T*, N·m (0 where none is given).

        Returns:
            d(xs)/dt.
        """

    def euler(
        self, host: SpeedHost, xs: jax.Array, err: jax.Array, torque: ArrayLike, ts: float
    ) -> tuple[jax.Array, jax.Array]:
        """One forward-Euler step of :meth:`vf` over ``ts`` (an observer whose own update is exact elsewhere, the
        reduced-order flux observer, advances its speed estimator so).

        Args:
            host: The observer holding this strategy.
            xs: The strategy's states [θ̂, ω̂, ...] at the period's start.
            err: The phase error ε over the period.
            torque: The torque reference T* over the period, N·m.
            ts: The period, s.

        Returns:
            ``(θ̂̇, the states after ts)``: the angle's rate over the period (the host's coordinates turn at it) and
            the states, θ̂ not wrapped.
        """
        d = self.vf(host, xs, err, torque)
        return d[0], xs + ts * d

    def bind(self, est_par: MachineInertia) -> AbstractSpeedEstimator:
        """This strategy assuming ``est_par`` (a :class:`jaxobs.drive.PMSMParams`); a PLL has nothing to bind.

        Args:
            est_par: The machine assumed.

        Returns:
            The bound strategy.
        """
        return self


class PLLSpeed(AbstractSpeedEstimator):
    """The type-2 PLL (module doc): θ̂̇ = ω̂ + k_p ε, ω̂̇ = k_i ε, with the host's ``kp_pll`` and ``ki_pll``."""

    n_states: ClassVar[int] = 2
    uses_torque: ClassVar[bool] = False

    def vf(self, host: SpeedHost, xs: jax.Array, err: jax.Array, torque: ArrayLike) -> jax.Array:
        """The PLL's rates on the host's ``kp_pll``, ``ki_pll``.

        Args:
            host: The observer holding the PLL.
            xs: [θ̂, ω̂].
            err: The phase error ε.
            torque: Unused (a PLL has no mechanical model).

        Returns:
            [θ̂̇, ω̂̇].
        """
        dth, dw = pll_vf(xs[0], xs[1], err, host.kp_pll, host.ki_pll)
        return jnp.stack([dth, dw])

    def euler(
        self, host: SpeedHost, xs: jax.Array, err: jax.Array, torque: ArrayLike, ts: float
    ) -> tuple[jax.Array, jax.Array]:
        """:meth:`AbstractSpeedEstimator.euler`, its products in the order the reduced-order flux observer's own
        type-2 loop always took them (θ̂ + T_s(ω̂ + k_p ε), ω̂ + (T_s k_i) ε), so that its results stay bit for bit.

        Args:
            host: The observer holding the PLL.
            xs: [θ̂, ω̂].
            err: The phase error ε.
            torque: Unused.
            ts: The period, s.

        Returns:
            ``(θ̂̇, [θ̂, ω̂] after ts)``.
        """
        dth = xs[1] + host.kp_pll * err
        return dth, jnp.stack([xs[0] + ts * dth, xs[1] + ts * host.ki_pll * err])


def mechanical_gains(alpha_o: float) -> tuple[float, float, float]:
    """The mechanical speed observer's gains placing its three error poles at −α_o (module doc).

    s³ + k1 s² + k2 s + k3 = (s + α_o)³  ⇒  k1 = 3α_o, k2 = 3α_o², k3 = α_o³.

    Args:
        alpha_o: α_o, rad/s (> 0).

    Returns:
        ``(k1, k2, k3)`` in 1/s, 1/s², 1/s³.
    """
    return 3.0 * alpha_o, 3.0 * alpha_o**2, alpha_o**3


class MechanicalSpeed(AbstractSpeedEstimator):
    """Mechanical-model speed observer with a load-torque estimate (module doc), states [θ̂, ω̂, T̂L].

    Args:
        k1: The angle gain, 1/s (> 0).
        k2: The speed gain, 1/s² (> 0).
        k3: The load-torque gain, 1/s³ (> 0).
        J: The assumed inertia Ĵ, kg·m² (> 0; ``bind`` sets it from the assumed machine).
        B: The assumed viscous friction B̂, N·m·s/rad (≥ 0; ``bind`` sets it).
        p: The pole pairs (a positive integer; ``bind`` sets it).

    Raises:
        ValueError: A value out of its range.
    """

    k1: jax.Array = eqx.field(
        metadata=gain_metadata(units="s-1", role="speed", long_name="mechanical observer angle gain", symbol="ours: k1")
    )
    k2: jax.Array = eqx.field(
        metadata=gain_metadata(units="s-2", role="speed", long_name="mechanical observer speed gain", symbol="ours: k2")
    )
    k3: jax.Array = eqx.field(
        metadata=gain_metadata(units="s-3", role="speed", long_name="mechanical observer load gain", symbol="ours: k3")
    )
    J: jax.Array  # assumed inertia, kg·m²
    B: jax.Array  # assumed viscous friction, N·m·s/rad
    p: int = eqx.field(static=True)  # pole pairs
    n_states: ClassVar[int] = 3
    uses_torque: ClassVar[bool] = True

    def __init__(
        self, k1: ArrayLike, k2: ArrayLike, k3: ArrayLike, J: ArrayLike = 1e-3, B: ArrayLike = 0.0, p: int = 1
    ) -> None:
        self.k1 = check_positive("k1", k1, "MechanicalSpeed")
        self.k2 = check_positive("k2", k2, "MechanicalSpeed")
        self.k3 = check_positive("k3", k3, "MechanicalSpeed")
        self.J = check_positive("J", J, "MechanicalSpeed")
        self.B = check_nonnegative("B", B, "MechanicalSpeed")
        if isinstance(p, bool) or int(p) != p or int(p) < 1:
            raise ValueError(f"MechanicalSpeed: p (pole pairs) must be a positive integer, got {p!r}")
        self.p = int(p)

    @classmethod
    def closed_form(cls, alpha_o: float, J: ArrayLike = 1e-3, B: ArrayLike = 0.0, p: int = 1) -> MechanicalSpeed:
        """The observer with its three error poles at −α_o: k1 = 3α_o, k2 = 3α_o², k3 = α_o³ (module doc).

        Args:
            alpha_o: The observer's bandwidth α_o, rad/s (> 0).
            J: The assumed inertia, kg·m² (> 0).
            B: The assumed viscous friction, N·m·s/rad (≥ 0).
            p: The pole pairs.

        Returns:
            The :class:`MechanicalSpeed`.

        Raises:
            ValueError: A value out of its range.
        """
        a = float(check_positive("alpha_o", alpha_o, "MechanicalSpeed.closed_form"))
        return cls(*mechanical_gains(a), J=J, B=B, p=p)

    def bind(self, est_par: MachineInertia) -> MechanicalSpeed:
        """This observer with the assumed machine's Ĵ, B̂ and p.

        Args:
            est_par: The machine assumed (a :class:`jaxobs.drive.PMSMParams`).

        Returns:
            The bound observer (every value in its field's dtype).
        """
        dt = jnp.result_type(self.J)
        J, B = jnp.asarray(est_par.J, dtype=dt), jnp.asarray(est_par.B, dtype=dt)
        if int(est_par.p) == self.p:
            return eqx.tree_at(lambda m: (m.J, m.B), self, (J, B))
        return MechanicalSpeed(self.k1, self.k2, self.k3, J=J, B=B, p=int(est_par.p))

    def vf(self, host: SpeedHost, xs: jax.Array, err: jax.Array, torque: ArrayLike) -> jax.Array:
        """The mechanical model's rates (module doc).

        Args:
            host: Unused (the gains are this observer's own).
            xs: [θ̂, ω̂, T̂L].
            err: The phase error ε.
            torque: The torque reference T*, N·m.

        Returns:
            [θ̂̇, ω̂̇, T̂̇L].
        """
        w, tl = xs[1], xs[2]
        dth = w + self.k1 * err
        dw = (self.p / self.J) * (torque - tl) - (self.B / self.J) * w + self.k2 * err
        dtl = -(self.J / self.p) * self.k3 * err
        return jnp.stack([dth, dw, dtl])


def alpha_o_out_of_range(alpha_o: float, ts: float | None) -> str | None:
    """Why a mechanical speed observer's bandwidth α_o does not fit its host's period, or None where it does.

    α_o T_s < 1: the host steps the observer explicitly once per period, and its three poles at −α_o map to
    z = 1 − α_o T_s (Euler) or near it (RK4): from α_o T_s = 1 on, z ≤ 0 and the steps alternate in sign, so the
    triple pole asked for is no longer the one run (Euler diverges from α_o T_s = 2, RK4 from 2.79).  The designs
    in docs/through-zero.md lie far below: α_o = 2π·10 to 2π·50 rad/s at 100–125 µs, α_o T_s ≤ 0.04.

    Args:
        alpha_o: α_o, rad/s.
        ts: The host observer's period, s; None: not checked.

    Returns:
        The message's tail ("must be in (0, 1/T_s) = … got …"), or None.
    """
    if ts is None or float(alpha_o) * float(ts) < 1.0:
        return None
    return (
        f"must be in (0, 1/T_s) = (0, {1.0 / float(ts):.6g}) rad/s at the observer's period "
        f"T_s = {float(ts):.6g} s, got {alpha_o!r}"
    )


def speed_from_spec(
    spec: AbstractSpeedEstimator | dict[str, Any] | None, owner: str = "speed", ts: float | None = None
) -> AbstractSpeedEstimator:
    """A speed estimator from what a constructor was given: None (a PLL), an estimator, or a job's record
    ``{"kind": "pll"}`` / ``{"kind": "mechanical", "alpha_o": α_o}`` (rad/s; Ĵ, B̂ and p come from ``bind``),
    where a mechanical record may also set any of ``k1``, ``k2``, ``k3`` (a job's tuned gains), each in place of
    its closed form at α_o.

    A record keeps a job's values plain numbers and strings (result files, the C export's sources), while the
    observer it builds holds the strategy object.

    Args:
        spec: The estimator, its record, or None.
        owner: The class or field named in errors.
        ts: The host observer's period, s: a record's α_o must then lie in (0, 1/T_s) (below).

    Returns:
        The :class:`AbstractSpeedEstimator`.

    Raises:
        ValueError: An unknown kind or key, or α_o or a gain out of its range.
    """
    if spec is None:
        return PLLSpeed()
    if isinstance(spec, AbstractSpeedEstimator):
        return spec
    if not isinstance(spec, dict):
        raise ValueError(
            f"{owner} must be a speed estimator (PLLSpeed, MechanicalSpeed) or a record with a kind, got "
            f"{type(spec).__name__}"
        )
    kind = spec.get("kind", "pll")
    allowed = {"pll": ("kind",), "mechanical": ("kind", "alpha_o", *MECHANICAL_GAINS)}
    if kind not in allowed:
        raise ValueError(f"{owner}.kind must be one of {', '.join(SPEED_KINDS)}, got {kind!r}")
    extra = sorted(set(spec) - set(allowed[kind]))
    if extra:
        raise ValueError(f"{owner}: unknown key(s) {', '.join(extra)} for kind {kind!r}; allowed: {allowed[kind]}")
    if kind == "pll":
        return PLLSpeed()
    if "alpha_o" not in spec:
        raise ValueError(f"{owner}.alpha_o: a mechanical speed observer needs its bandwidth α_o (rad/s, > 0)")
    closed = MechanicalSpeed.closed_form(spec["alpha_o"])
    bad = alpha_o_out_of_range(spec["alpha_o"], ts)
    if bad:
        raise ValueError(f"{owner}.alpha_o {bad}")
    given = {k: spec[k] for k in MECHANICAL_GAINS if k in spec}
    if not given:
        return closed
    return MechanicalSpeed(**{"k1": closed.k1, "k2": closed.k2, "k3": closed.k3, **given})
