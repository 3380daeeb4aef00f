"""The step-function contract shared by every observer (docs/architecture.md, section 2).

An observer is an immutable ``equinox.Module`` holding its gains as array
leaves, with pure ``init`` and ``step``:

    state = obs.init()
    state, out = obs.step(state, u)      # u: one input sample (or an input path)

``out`` at sample n is always the estimate *at* t_n, built only from data a
DSP has at t_n:

- signal-level observers (the FLL family) see a sample v(t_n) but not the
  signal over [t_n, t_{n+1}], so ``step`` returns the outputs of the state
  *before* the update (inputs up to n − 1 integrated up to t_n);
- drive observers (flux observers, LESOs) at t_n know the current i_n and
  the voltage applied over the period that just ended, so ``step``
  integrates that period and returns the outputs at t_n.

Either way the observer is strictly causal and its outputs line up with a
continuous-time reference sampled at t_n.

The hierarchy (abstract classes; the concrete observers are final):

- :class:`AbstractObserver`: ``ts`` (an abstract variable: a field, or a property such as a bank's), ``init``,
  ``step``.  Every observer subclasses it.
- :class:`AbstractVectorFieldObserver`: an observer given by a vector field ``f(x, u)`` on a
  flat state, integrated by its rule (the FLL family, the SOGIs); ``init``/``step`` come with it.
- :class:`AbstractDriveObserver`: an observer of a drive (fed a :class:`~jaxobs.core.measurements.DriveInput`)
  that assumes a machine and starts at a speed: ``bind``, ``init_at``, ``seed_speed``.  The flux
  observers (:class:`~jaxobs.observers.flux.AbstractFluxObserver`), the LESOs
  (:class:`~jaxobs.observers.leso.AbstractLESO`) and :class:`ObserverBank` implement it; a user's own
  drive observer does too, and then runs in :class:`jaxobs.drive.ClosedLoop` as they do.
"""

# no ``from __future__ import annotations`` here: equinox recognizes ``eqx.AbstractVar`` only in an evaluated
# annotation (a string one would make AbstractObserver.ts an ordinary field, first in every observer's fields)
import abc
import dataclasses
from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple, Protocol, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from ..core.discretize import AbstractRule, AbstractRuleCarry
from ..core.measurements import DriveInput
from ._gains import check_gains
from .speed import AbstractSpeedEstimator

__all__ = [
    "AbstractObserver",
    "AbstractVectorFieldObserver",
    "AbstractDriveObserver",
    "BoundFields",
    "ObserverState",
    "DriveObserverState",
    "ObserverBank",
    "BankOutput",
    "AssumedMachine",
]

_M = TypeVar("_M", bound=eqx.Module)


class AssumedMachine(Protocol):
    """The machine a drive observer assumes, as its :meth:`~AbstractDriveObserver.bind` reads it.

    :class:`jaxobs.drive.PMSMParams` is one; the observers sit below :mod:`jaxobs.drive`, so they name what they
    read instead of importing the class.

    Attributes:
        Rs: Stator resistance, ohm.
        Ld: d-axis inductance, H.
        Lq: q-axis inductance, H.
        psi_f: PM flux linkage, Wb.
        J: Inertia, kg·m².
        B: Viscous friction, N·m·s/rad.
        p: Pole pairs.
        sat: The saturation map, or None (a drive observer that models the map reads it; the others do not).
    """

    @property
    def Rs(self) -> jax.Array:
        """Stator resistance, ohm."""
        ...

    @property
    def Ld(self) -> jax.Array:
        """d-axis inductance, H."""
        ...

    @property
    def Lq(self) -> jax.Array:
        """q-axis inductance, H."""
        ...

    @property
    def psi_f(self) -> jax.Array:
        """PM flux linkage, Wb."""
        ...

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

    @property
    def sat(self) -> Any:
        """The saturation map (an algebraic current map i(ψ) or a flux table), or None: the constants alone."""
        ...


class AbstractObserver(eqx.Module):
    """Every observer: a sample time ``ts`` (s) and pure ``init`` / ``step``.

    ``ts`` is an abstract variable: no field is declared here, so a concrete observer implements it with a
    field of its own (every observer of the FLL, flux and LESO families) or with a property (an
    :class:`ObserverBank`'s is its primary's); a class that has neither cannot be constructed.

    Gains are fields declared with :func:`~jaxobs.observers.gain`; after every constructor
    ``__check_init__`` checks each against its declared bounds (:func:`~jaxobs.observers.check_gains`), so a
    constructor does not check a gain's range by hand.  A class a paper tunes has a closed form: the
    classmethods ``closed_form_design(**inputs) -> ClosedForm`` (the observer, its inputs and its rows: name,
    value, units, formula, source equation) and ``closed_form(**inputs)``, its observer
    (:mod:`jaxobs.observers._gains` states the convention).

    Attributes:
        ts: Sample time, s.
    """

    ts: eqx.AbstractVar[float]

    # Declared by the class, read by the applications (jaxobs.studies.registry): why a tuning job may not name it
    # ("" where it may), and the paper's small-signal model, (the jaxobs.linear function, the fields it takes
    # in order), or None where the papers give none.  A name, not the function: jaxobs.linear sits above the
    # observers (it analyses them), so an observer cannot import it.
    why_not_tunable: ClassVar[str] = ""
    small_signal_model: ClassVar[tuple[str, tuple[str, ...]] | None] = None

    def __check_init__(self) -> None:
        check_gains(self)

    @abc.abstractmethod
    def init(self, u0: Any = None) -> Any:
        """The state at sample 0.

        Args:
            u0: The first input, for rules that need it; None otherwise.

        Returns:
            The observer's state.
        """

    @abc.abstractmethod
    def step(self, state: Any, u: Any) -> tuple[Any, Any]:
        """One sample.

        Args:
            state: The state at n.
            u: The input at t_n.

        Returns:
            ``(the state at n + 1, the named outputs at t_n)``.
        """


class ObserverState(AbstractRuleCarry):
    """State of a vector-field observer: the flat state and the rule's own state.

    Attributes:
        x: The flat state, shape (n_states,).
        rule: The rule's state (multistep history) or None.
    """

    x: jax.Array  # shape (n_states,)
    rule: Any  # rule state (multistep history) or None


class AbstractVectorFieldObserver(AbstractObserver):
    """Observer whose dynamics are a vector field ``f(x, u)`` on a flat state ``x``.

    Subclasses define ``f``, ``output`` and ``initial_state``; the rule given at
    construction integrates ``f`` over each sample period ``ts``.

    Attributes:
        ts: Sample time, s.
        rule: The discretization rule.
    """

    # fields, declared here first (every vector-field observer's fields start with ts and rule; the order of
    # their dataclass fields, and so of their constructors' and exports' fields, is this)
    ts: float
    rule: AbstractRule

    @abc.abstractmethod
    def f(self, x: jax.Array, u: Any) -> jax.Array:
        """Continuous-time vector field.

        Args:
            x: The flat state.
            u: The input value.

        Returns:
            dx/dt.
        """

    @abc.abstractmethod
    def output(self, x: jax.Array) -> Any:
        """Named outputs computed from the state.

        Args:
            x: The flat state.

        Returns:
            The outputs (a NamedTuple).
        """

    @abc.abstractmethod
    def initial_state(self) -> jax.Array:
        """The flat state at t = 0."""

    def init(self, u0: Any = None) -> ObserverState:
        """The state at sample 0: :meth:`initial_state` and the rule's own.

        Args:
            u0: The first input, for rules that need it; None otherwise.

        Returns:
            The :class:`ObserverState`.
        """
        x0 = self.initial_state()
        return ObserverState(x=x0, rule=self.rule.init(self.f, x0, u0))

    def step(self, state: ObserverState, u: Any) -> tuple[ObserverState, Any]:
        """One sample: the outputs of the state at t_n, and the state integrated over [t_n, t_{n+1}].

        Args:
            state: The state at n.
            u: The input sample at t_n.

        Returns:
            ``(the state at n + 1, the named outputs at t_n)``.
        """
        out = self.output(state.x)
        x1, rule_state = self.rule.step(self.f, state.x, u, self.ts, state.rule)
        return ObserverState(x=x1, rule=rule_state), out

    def vector_field(self, t: ArrayLike, x: jax.Array, signal: Callable[[ArrayLike], Any]) -> jax.Array:
        """``f(t, x, args)`` for ``diffrax.ODETerm``.

        Args:
            t: The time, s.
            x: The flat state.
            signal: The signal, called at t.

        Returns:
            dx/dt.
        """
        return self.f(x, signal(t))


class DriveObserverState(AbstractRuleCarry):
    """State of a flux observer or a LESO: the flat state, the rule's state and the samples of the last period.

    One class for both families: each integrates the period [t_{k−1}, t_k] from the voltage applied over it
    and the currents at both ends, so each remembers the same three things.

    Attributes:
        x: The filter, LESO, FLL and PLL states (the observer's layout).
        rule: The rule's state.
        i_prev: (i_α, i_β) at the previous sample, A.
        u_prev: (u_α, u_β) applied over the period that ends now, V.
        started: False until one sample has been seen.
    """

    x: jax.Array  # filter, LESO, FLL and PLL states (the observer's layout)
    rule: Any  # rule state
    i_prev: jax.Array  # (i_α, i_β) at the previous sample, A
    u_prev: jax.Array  # (u_α, u_β) applied over the period that ends now, V
    started: jax.Array  # False until one sample has been seen


def replace_leaves(module: _M, **values: ArrayLike) -> _M:
    """``module`` with the named array fields set to ``values``, each cast to its field's dtype.

    The cast keeps a float32 observer float32 when it is bound to a float64 machine (the C export rounds
    the observer to float32 first) and keeps ``lax.scan`` carries' dtypes fixed.

    Args:
        module: The module.
        **values: field name -> value.

    Returns:
        The module with the fields set.
    """
    names = tuple(values)
    new = tuple(jnp.asarray(values[n], dtype=jnp.result_type(getattr(module, n))) for n in names)
    return eqx.tree_at(lambda m: tuple(getattr(m, n) for n in names), module, new)


@dataclasses.dataclass(frozen=True)
class BoundFields:
    """The fields a drive observer's :meth:`~AbstractDriveObserver.bind` sets, each named by its role.

    Attributes:
        resistance: The assumed stator resistance's field (R̂s), or None where the observer assumes none.
        inductance: The assumed inductance's field (a flux observer's L̂, a LESO's L̂q, the reduced-order
            observer's L̂d), or None.
        speed: The initial speed's field (rad/s), or None.
        more: Any other machine value it sets (the reduced-order observer's L̂q and ψ̂f).
    """

    resistance: str | None = None
    inductance: str | None = None
    speed: str | None = None
    more: tuple[str, ...] = ()

    @property
    def names(self) -> tuple[str, ...]:
        """The bound fields' names: resistance, inductance, speed (those present), then ``more``."""
        return (*(n for n in (self.resistance, self.inductance, self.speed) if n is not None), *self.more)


class AbstractDriveObserver(AbstractObserver):
    """An observer of a drive: fed a :class:`~jaxobs.core.measurements.DriveInput` each period, it assumes a
    machine (what the controller believes, ``est_par`` in motulator's vocabulary) and starts at a speed.

    The one way to bind a drive observer to a machine and an operating point is :meth:`bind`; studies,
    tuning jobs, recordings, the C export and the reproductions all call it.  A drive that starts steady
    starts the observer with :meth:`init_at`; an I-f start-up holds its speed estimate with
    :meth:`seed_speed` (:class:`jaxobs.drive.ClosedLoop`).
    """

    # the fields bind() sets, by role (resistance, inductance, initial speed): not gains, so a study or a job
    # does not report or tune them (jaxobs.studies.drive.drive_gains), and the C export says where they came from
    bound_fields: ClassVar["BoundFields"]
    # whether the class holds a speed estimator (jaxobs.observers.speed) that a job's [observer.speed] may choose
    takes_speed_estimator: ClassVar[bool] = False

    def speed_estimator(self) -> AbstractSpeedEstimator | None:
        """The speed and position extraction this observer holds (:mod:`jaxobs.observers.speed`), or None where
        its speed comes otherwise (an FLL, its own adaptation law).

        Returns:
            The estimator or None.
        """
        return None

    @property
    def reads_torque(self) -> bool:
        """Whether a step reads the torque reference (``DriveInput.T_ref``): a mechanical-model speed estimator.

        Returns:
            True where the drive loop must fill ``T_ref``.
        """
        est = self.speed_estimator()
        return est is not None and est.uses_torque

    @abc.abstractmethod
    def bind(self, est_par: AssumedMachine | None, omega_e: ArrayLike) -> "AbstractDriveObserver":
        """This observer assuming a machine and starting at a speed.

        Its initial speed field becomes what :meth:`init_at` would start from.  The gains are untouched; every
        value keeps its field's dtype.

        Args:
            est_par: The machine assumed (a :class:`jaxobs.drive.PMSMParams`: its Rs and the inductance the
                family's model uses); None keeps the observer's own machine and sets only the speed (a
                recording gives the speed, not the machine).
            omega_e: The electrical speed, rad/s, signed.

        Returns:
            The bound observer.
        """

    @abc.abstractmethod
    def init_at(self, omega_e: ArrayLike) -> Any:
        """The initial state of a steady start's settling phase.

        Args:
            omega_e: The speed estimate's start, rad/s.

        Returns:
            The :class:`DriveObserverState`.
        """

    def init_aligned(self, omega_e: ArrayLike, theta_e: ArrayLike) -> Any:
        """The initial state of a steady start's settling phase, aligned to the rotor.

        :meth:`init_at` with, where the observer has an angle state of its own (a LESO's PLL θ̂), that angle
        at the rotor's angle when the phase starts.  An angle derived from filter states that start at zero
        (the flux observers') has nothing to set: this default.

        Args:
            omega_e: The speed estimate's start, rad/s.
            theta_e: The rotor's electrical angle, rad.

        Returns:
            The :class:`DriveObserverState`.
        """
        return self.init_at(omega_e)

    @abc.abstractmethod
    def seed_speed(self, state: Any, omega_e: ArrayLike) -> Any:
        """``state`` with its speed estimate set: an I-f start-up holds it at the I-f frequency until the
        hand-over (a DSP knows that frequency: it is the FLL's or PLL's feed-forward).

        Args:
            state: The :class:`DriveObserverState`.
            omega_e: The speed, rad/s.

        Returns:
            The state with its speed estimate at ``omega_e``.
        """


class BankOutput(NamedTuple):
    """An :class:`ObserverBank`'s outputs at a sample.

    Attributes:
        theta: The primary observer's θ̂e (what a sensorless controller uses).
        omega: The primary observer's ω̂e.
        each: Every observer's own outputs, in order.
    """

    theta: Any  # the primary observer's θ̂e (what a sensorless controller uses)
    omega: Any  # the primary observer's ω̂e
    each: tuple[Any, ...]  # every observer's own outputs, in order


class ObserverBank(AbstractDriveObserver):
    """Several drive observers fed the same measurements; ``primary`` closes the loop when sensorless.

    Lets one drive simulation compare observers on identical data (000's
    per-observer position errors) without them disturbing each other.

    Attributes:
        observers: The drive observers (a tuple of :class:`AbstractDriveObserver`).
        primary: The index of the observer that closes the loop (static).

    Raises:
        ValueError: An entry is not a drive observer, or ``primary`` is out of range.
    """

    observers: tuple[AbstractDriveObserver, ...]
    primary: int = eqx.field(static=True, default=0)

    bound_fields: ClassVar[BoundFields] = BoundFields()  # none of its own: bind() binds its observers

    @property
    def reads_torque(self) -> bool:
        """Whether any of its observers reads the torque reference.

        Returns:
            True where the drive loop must fill ``T_ref``.
        """
        return any(o.reads_torque for o in self.observers)

    def __check_init__(self) -> None:
        for i, o in enumerate(self.observers):
            if not isinstance(o, AbstractDriveObserver):
                raise ValueError(
                    f"ObserverBank.observers[{i}] must be a drive observer (an AbstractDriveObserver: a flux "
                    f"observer, a LESO), got {type(o).__name__}"
                )
        if not 0 <= self.primary < len(self.observers):
            raise ValueError(f"ObserverBank.primary must be in [0, {len(self.observers) - 1}], got {self.primary}")

    @property
    def ts(self) -> float:
        """The primary observer's sample time, s."""
        return self.observers[self.primary].ts

    def bind(self, est_par: AssumedMachine | None, omega_e: ArrayLike) -> "ObserverBank":
        """The bank with every observer bound (:meth:`AbstractDriveObserver.bind`).

        Args:
            est_par: The machine assumed, or None (the speed only).
            omega_e: The electrical speed, rad/s, signed.

        Returns:
            The bound bank.
        """
        return eqx.tree_at(lambda b: b.observers, self, tuple(o.bind(est_par, omega_e) for o in self.observers))

    def init(self, u0: Any = None) -> tuple[Any, ...]:
        """Every observer's state at sample 0.

        Args:
            u0: Unused (each drive observer starts from its own state).

        Returns:
            The states, in order.
        """
        return tuple(o.init() for o in self.observers)

    def init_at(self, omega_e: ArrayLike) -> tuple[Any, ...]:
        """Every observer's :meth:`~AbstractDriveObserver.init_at`.

        Args:
            omega_e: The speed estimates' start, rad/s.

        Returns:
            The states, in order.
        """
        return tuple(o.init_at(omega_e) for o in self.observers)

    def init_aligned(self, omega_e: ArrayLike, theta_e: ArrayLike) -> tuple[Any, ...]:
        """Every observer's :meth:`~AbstractDriveObserver.init_aligned`.

        Args:
            omega_e: The speed estimates' start, rad/s.
            theta_e: The rotor's electrical angle, rad.

        Returns:
            The states, in order.
        """
        return tuple(o.init_aligned(omega_e, theta_e) for o in self.observers)

    def seed_speed(self, state: tuple[Any, ...], omega_e: ArrayLike) -> tuple[Any, ...]:
        """Every observer's state with its speed estimate set (:meth:`~AbstractDriveObserver.seed_speed`).

        Args:
            state: The states, in order.
            omega_e: The speed, rad/s.

        Returns:
            The states with their speed estimates at ``omega_e``.
        """
        return tuple(o.seed_speed(s, omega_e) for o, s in zip(self.observers, state))

    def step(self, state: tuple[Any, ...], u: DriveInput) -> tuple[tuple[Any, ...], BankOutput]:
        """One sample of every observer, on the same measurements.

        Args:
            state: The states at n, in order.
            u: The measurements at t_n.

        Returns:
            ``(the states at n + 1, the bank's outputs at t_n)``.
        """
        pairs = [o.step(s, u) for o, s in zip(self.observers, state)]
        outs = tuple(p[1] for p in pairs)
        return tuple(p[0] for p in pairs), BankOutput(
            theta=outs[self.primary].theta, omega=outs[self.primary].omega, each=outs
        )
