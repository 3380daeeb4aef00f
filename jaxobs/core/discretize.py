"""Discretization rules shared by every component.

A rule turns a vector field ``f(x, u) -> dx/dt`` (state ``x`` a flat array, input
``u`` any PyTree) into a fixed-step update over one sample period ``h``.  Rules
are objects passed to components, as diffrax passes solvers; no component
hard-codes one.

How the input behaves inside a period is the caller's choice, given as an
*input path*:

- :class:`Held` — zero-order hold: the sample taken at the start of the period
  is used for the whole period.  This is what a DSP does, and the default.
- :class:`Knots` — the continuous input known at the start, middle and end of
  the period (quadratic interpolation between them; exact at the stage times
  of every rule here).  Used to measure a rule's order against a continuous
  reference, and by the plant, whose inputs are known in continuous time.

Where diffrax has the method, its solver step is used or checked against:
:class:`Euler` calls ``diffrax.Euler``; :class:`RK4` equals the classic tableau
run through diffrax's explicit Runge--Kutta machinery (``diffrax.AbstractERK``,
see :func:`diffrax_rk4_step`) step for step, but keeps the plain formula in
the hot loop for speed.  diffrax has no implicit trapezoidal rule and no
multistep methods, so :class:`Tustin` and :class:`AB3` are written here.

diffrax is imported where a step first traces (:func:`_diffrax`), not with this module: importing it (and
optimistix, lineax with it) costs about half a second, which a program that never steps a rule — ``jaxobs drive
check`` reading a drive file — should not pay (``tests/test_cli.py`` checks what that command imports).
"""

from __future__ import annotations

import abc
import functools
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import PyTree

__all__ = [
    "Held",
    "Knots",
    "AbstractRule",
    "AbstractRuleCarry",
    "AbstractMultistepState",
    "Euler",
    "Tustin",
    "AB3",
    "RK4",
    "check_rule",
]

VectorField = Callable[[jax.Array, Any], jax.Array]
Step = float | jax.Array  # a period h, s, or a fraction s of one
Input = Any  # a component's input over a period: an AbstractInputPath, or a bare sample (any PyTree), held
RuleState = Any  # a rule's own state: an AbstractMultistepState, or None for one-step rules


# --------------------------------------------------------------------------
# input paths
# --------------------------------------------------------------------------


class AbstractInputPath(eqx.Module):
    """The input over one sample period, evaluated at a fraction ``s`` in [0, 1]."""

    @abc.abstractmethod
    def at(self, s: Step) -> Any:
        """The input at the fraction ``s`` of the period.

        Args:
            s: The fraction, in [0, 1].

        Returns:
            The input there (a PyTree like the samples).
        """


class Held(AbstractInputPath):
    """Zero-order hold of one sample.

    Attributes:
        u: The sample.
    """

    u: Any

    def at(self, s: Step) -> Any:
        """The held sample, whatever ``s``.

        Args:
            s: The fraction of the period (unused).

        Returns:
            The sample.
        """
        del s
        return self.u


class Knots(AbstractInputPath):
    """Input known at the start (``u0``), middle (``um``) and end (``u1``) of the period.

    ``at(s)`` is the quadratic through the three knots; at s = 0, 1/2, 1 the
    Lagrange weights are exactly (1, 0, 0), (0, 1, 0), (0, 0, 1) in floating
    point, so RK4 and Tustin see the exact knot values.

    Attributes:
        u0: The input at the period's start.
        um: The input at its middle.
        u1: The input at its end.
    """

    u0: Any
    um: Any
    u1: Any

    def at(self, s: Step) -> Any:
        """The quadratic through the three knots at the fraction ``s`` (a knot itself at s = 0, 1/2, 1).

        Args:
            s: The fraction of the period, in [0, 1].

        Returns:
            The input there.
        """
        if isinstance(s, (int, float)):
            if s == 0:
                return self.u0
            if s == 0.5:
                return self.um
            if s == 1:
                return self.u1
        w0 = 2.0 * (s - 0.5) * (s - 1.0)
        wm = -4.0 * s * (s - 1.0)
        w1 = 2.0 * s * (s - 0.5)
        return jax.tree.map(lambda a, b, c: w0 * a + wm * b + w1 * c, self.u0, self.um, self.u1)


def as_path(u: Input) -> AbstractInputPath:
    """A bare input sample means zero-order hold.

    Args:
        u: An :class:`AbstractInputPath`, or a bare sample.

    Returns:
        ``u``, or :class:`Held` of it.
    """
    return u if isinstance(u, AbstractInputPath) else Held(u)


# --------------------------------------------------------------------------
# rules
# --------------------------------------------------------------------------


class AbstractRule(eqx.Module):
    """A one-step (or multistep) integration rule.

    ``init(f, x0, u)`` returns the rule's own state (multistep history, or
    ``None``); ``step(f, x, u, h, rule_state)`` returns the state after one
    period ``h`` and the new rule state.

    Attributes:
        order: The global order of accuracy for smooth inputs given as :class:`Knots` (a class constant).
    """

    order: ClassVar[int]

    def init(self, f: VectorField, x0: jax.Array, u: Input) -> RuleState:
        """The rule's own state before the first period (None: a one-step rule has none).

        Args:
            f: The vector field ``f(x, u)``.
            x0: The initial state.
            u: The first input.

        Returns:
            The rule's state.
        """
        del f, x0, u
        return None

    @abc.abstractmethod
    def step(
        self, f: VectorField, x: jax.Array, u: Input, h: Step, rule_state: RuleState
    ) -> tuple[jax.Array, RuleState]:
        """One period of the rule.

        Args:
            f: The vector field ``f(x, u)``.
            x: The state.
            u: The input over the period (an :class:`AbstractInputPath`, or a bare sample: held).
            h: The period, s.
            rule_state: The rule's own state.

        Returns:
            (the state after the period, the rule's new state).
        """


def _diffrax():
    """diffrax, imported on first use (module doc)."""
    import diffrax

    return diffrax


def _diffrax_term(f: VectorField, path: AbstractInputPath, h):
    # diffrax integrates over t in [0, h]; the input path is parametrized by s = t / h.
    return _diffrax().ODETerm(lambda t, y, args: f(y, path.at(t / h)))


class Euler(AbstractRule):
    """Forward Euler, x₊ = x + h f(x, u(0)) — by ``diffrax.Euler``."""

    order: ClassVar[int] = 1

    def step(
        self, f: VectorField, x: jax.Array, u: Input, h: Step, rule_state: RuleState
    ) -> tuple[jax.Array, RuleState]:
        """One period of this rule (:meth:`AbstractRule.step`).

        Args:
            f: The vector field ``f(x, u)``.
            x: The state.
            u: The input over the period (an :class:`AbstractInputPath`, or a bare sample: held).
            h: The period, s.
            rule_state: The rule's own state.

        Returns:
            (the state after the period, the rule's new state).
        """
        path = as_path(u)
        x1, _, _, _, _ = _diffrax().Euler().step(_diffrax_term(f, path, h), 0.0, h, x, None, None, False)
        return x1, rule_state


@functools.cache
def _diffrax_classic_rk4() -> type:
    """The classic fourth-order Runge--Kutta tableau in diffrax's ERK machinery (a class built on first use, with
    diffrax: module doc)."""
    dfx = _diffrax()
    rk4_tableau = dfx.ButcherTableau(
        a_lower=(np.array([0.5]), np.array([0.0, 0.5]), np.array([0.0, 0.0, 1.0])),
        b_sol=np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6]),
        # The classic RK4 has no embedded pair; diffrax wants an error row, so give
        # it the trivial one (our rules never adapt the step).
        b_error=np.array([0.0, 0.0, 0.0, 0.0]),
        c=np.array([0.5, 0.5, 1.0]),
    )

    class _DiffraxClassicRK4(dfx.AbstractERK):
        tableau: ClassVar[Any] = rk4_tableau
        interpolation_cls: ClassVar[Callable[..., Any]] = dfx.LocalLinearInterpolation

        def order(self, terms):
            return 4

    return _DiffraxClassicRK4


class RK4(AbstractRule):
    """Classic fourth-order Runge--Kutta (stages at 0, ½, ½, 1 of the period).

    The same tableau run through ``diffrax.AbstractERK`` (:func:`diffrax_rk4_step`)
    gives identical steps — tested — but its generic stage loop is several times slower inside a vmapped scan
    (docs/performance.md), so the hot loop uses the plain formula.
    """

    order: ClassVar[int] = 4

    def step(
        self, f: VectorField, x: jax.Array, u: Input, h: Step, rule_state: RuleState
    ) -> tuple[jax.Array, RuleState]:
        """One period of this rule (:meth:`AbstractRule.step`).

        Args:
            f: The vector field ``f(x, u)``.
            x: The state.
            u: The input over the period (an :class:`AbstractInputPath`, or a bare sample: held).
            h: The period, s.
            rule_state: The rule's own state.

        Returns:
            (the state after the period, the rule's new state).
        """
        return rk4_step(f, x, as_path(u), h), rule_state


def diffrax_rk4_step(f: VectorField, x: jax.Array, u: Input, h: Step) -> jax.Array:
    """One classic RK4 step through diffrax's ERK machinery (the reference for :class:`RK4`).

    Args:
        f: The vector field ``f(x, u)``.
        x: The state.
        u: The input (a path, or a bare sample: held).
        h: The step, s.

    Returns:
        The state after the step.
    """
    solver = _diffrax_classic_rk4()()
    term = _diffrax_term(f, as_path(u), h)
    state = solver.init(term, 0.0, h, x, None)
    x1, _, _, _, _ = solver.step(term, 0.0, h, x, None, state, False)
    return x1


def rk4_step(f: VectorField, x: jax.Array, path: AbstractInputPath, h: Step) -> jax.Array:
    """Plain classic RK4 step (used to start AB3, which has no history yet).

    Args:
        f: The vector field ``f(x, u)``.
        x: The state.
        path: The input over the period.
        h: The step, s.

    Returns:
        The state after the step.
    """
    k1 = f(x, path.at(0.0))
    k2 = f(x + 0.5 * h * k1, path.at(0.5))
    k3 = f(x + 0.5 * h * k2, path.at(0.5))
    k4 = f(x + h * k3, path.at(1.0))
    return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


class Tustin(AbstractRule):
    """Implicit trapezoidal rule (Tustin / bilinear for linear systems).

    x₊ = x + h/2 [f(x, u(0)) + f(x₊, u(1))].

    For a linear vector field this is exactly the bilinear transform
    s → (2/h)(z − 1)/(z + 1), so the SOGI discretized this way has the
    coefficients a Tustin design gives (paper 000 eqs 22–25 for the
    second-order SOGI).  For a nonlinear field (an FLL) the implicit equation is
    solved by ``newton_iters`` Newton iterations from an explicit Euler
    predictor; the Jacobian is taken by forward-mode AD (states are small).
    The predictor error is O(h²) and each Newton iteration squares it, so one
    iteration already keeps the rule second order; the default of two leaves
    the residual far below the rule's own truncation error.  A linear field is
    solved exactly by the first iteration.

    Attributes:
        newton_iters: Newton iterations per step (an integer ≥ 1; static).
    """

    newton_iters: int = eqx.field(static=True, default=2)
    order: ClassVar[int] = 2

    def __check_init__(self):
        if not (isinstance(self.newton_iters, int) and self.newton_iters >= 1):
            raise ValueError(f"Tustin.newton_iters must be an integer >= 1, got {self.newton_iters!r}")

    def step(
        self, f: VectorField, x: jax.Array, u: Input, h: Step, rule_state: RuleState
    ) -> tuple[jax.Array, RuleState]:
        """One period of this rule (:meth:`AbstractRule.step`).

        Args:
            f: The vector field ``f(x, u)``.
            x: The state.
            u: The input over the period (an :class:`AbstractInputPath`, or a bare sample: held).
            h: The period, s.
            rule_state: The rule's own state.

        Returns:
            (the state after the period, the rule's new state).
        """
        path = as_path(u)
        f0 = f(x, path.at(0.0))
        u1 = path.at(1.0)
        const = x + 0.5 * h * f0

        def residual(y):
            return y - const - 0.5 * h * f(y, u1)

        y = x + h * f0
        eye = jnp.eye(x.shape[0], dtype=x.dtype)
        for _ in range(self.newton_iters):
            # J_r = I - h/2 ∂f/∂y
            jac = eye - 0.5 * h * jax.jacfwd(lambda z: f(z, u1))(y)
            y = y - solve_small(jac, residual(y))
        return y, rule_state


def solve_small(a: jax.Array, b: jax.Array) -> jax.Array:
    """Solve a x = b for a small dense ``a`` by unrolled Gauss elimination.

    The Newton matrices here are I − (h/2)·J with h‖J‖ ≪ 1, i.e. strongly
    diagonally dominant, so elimination without pivoting is stable.  Unrolled
    elementwise code vectorizes across a vmapped batch, where a batched LAPACK call per scenario is far slower on
    CPU (docs/performance.md).  Falls back to
    ``jnp.linalg.solve`` above 12 states.

    Args:
        a: The matrix, (n, n).
        b: The right-hand side, (n,).

    Returns:
        x.
    """
    n = a.shape[0]
    if n > 12:
        return jnp.linalg.solve(a, b)
    rows = [a[i] for i in range(n)]
    rhs = [b[i] for i in range(n)]
    for i in range(n):
        piv = rows[i][i]
        for j in range(i + 1, n):
            m = rows[j][i] / piv
            rows[j] = rows[j] - m * rows[i]
            rhs[j] = rhs[j] - m * rhs[i]
    x: list[Any] = [None] * n  # each set below, last first
    for i in reversed(range(n)):
        acc = rhs[i]
        for j in range(i + 1, n):
            acc = acc - rows[i][j] * x[j]
        x[i] = acc / rows[i][i]
    return jnp.stack(x)


class AbstractMultistepState(eqx.Module):
    """A rule state whose first ``startup_steps`` steps differ from the rest (a multistep rule's start-up): the
    loop peels them off and runs the rest in the state's branch-free ``steady()`` form (:mod:`jaxobs.runtime._loop`,
    point 2).

    Attributes:
        startup_steps: The start-up's steps (a class attribute).
    """

    startup_steps: eqx.AbstractClassVar[int]

    @abc.abstractmethod
    def steady(self) -> AbstractMultistepState:
        """The same state, declared past its start-up (valid once ``startup_steps`` steps have been taken)."""

    @abc.abstractmethod
    def started(self) -> AbstractMultistepState:
        """The state in its general form again: undoes :meth:`steady`."""


class AB3State(AbstractMultistepState):
    """The AB3 rule's history: f at the two previous samples, and the samples taken while it starts up.

    Attributes:
        f1: f at the previous sample (x's shape).
        f2: f two samples back (x's shape).
        n: The samples taken so far (int32 scalar); None once past the start-up ("steady").
    """

    f1: jax.Array  # f at the previous sample,     shape = x.shape
    f2: jax.Array  # f two samples back,           shape = x.shape
    n: jax.Array | None  # samples taken so far (int32 scalar); None once past the start-up ("steady")

    startup_steps: ClassVar[int] = 2

    def steady(self) -> AB3State:
        """The same state, declared past its start-up: its step is plain AB3, with no branch.

        Only valid once ``startup_steps`` steps have been taken; the simulation
        loop (:mod:`jaxobs.runtime._loop`) converts the carry after running them.
        """
        return AB3State(f1=self.f1, f2=self.f2, n=None)

    def started(self) -> AB3State:
        """The state in its general form again (the sample count saturates at ``startup_steps``)."""
        if self.n is not None:
            return self
        return AB3State(f1=self.f1, f2=self.f2, n=jnp.asarray(self.startup_steps, dtype=jnp.int32))


class AB3(AbstractRule):
    """Third-order Adams--Bashforth, the integrator of paper 001 Sec. VI.

    001 approximates each integrator 1/s by (T_s/12)(23z⁻¹ − 16z⁻² + 5z⁻³)/(1 − z⁻¹),
    i.e. y[n] = y[n−1] + (T_s/12)(23 x[n−1] − 16 x[n−2] + 5 x[n−3]) with x the
    integrator's input.  Written on the whole state this is

        x₊ = x + h/12 (23 f(x, u) − 16 f₋₁ + 5 f₋₂).

    The first two periods have no history; they are taken with RK4 so that the
    start-up does not spoil the third order (a zero or Euler start leaves an
    O(h²) error for ever).  The branch is a ``lax.cond`` on the sample count,
    which stays unbatched — and so a real branch — when the whole simulation
    is vmapped.  The simulation loops take those two steps on their own and
    then run the state's :meth:`AB3State.steady` form, which has no branch.
    """

    order: ClassVar[int] = 3

    def init(self, f: VectorField, x0: jax.Array, u: Input) -> AB3State:
        """The empty history: zeros, no sample taken.

        Args:
            f: The vector field (unused).
            x0: The initial state.
            u: The first input (unused).

        Returns:
            The :class:`AB3State`.
        """
        z = jnp.zeros_like(x0)
        return AB3State(f1=z, f2=z, n=jnp.asarray(0, dtype=jnp.int32))

    def step(self, f: VectorField, x: jax.Array, u: Input, h: Step, rule_state: AB3State) -> tuple[jax.Array, AB3State]:
        """One period of this rule (:meth:`AbstractRule.step`).

        Args:
            f: The vector field ``f(x, u)``.
            x: The state.
            u: The input over the period (an :class:`AbstractInputPath`, or a bare sample: held).
            h: The period, s.
            rule_state: The rule's own state.

        Returns:
            (the state after the period, the rule's new state).
        """
        path = as_path(u)
        f0 = f(x, path.at(0.0))

        def ab3(_):
            return x + (h / 12.0) * (23.0 * f0 - 16.0 * rule_state.f1 + 5.0 * rule_state.f2)

        def start(_):
            return rk4_step(f, x, path, h)

        if rule_state.n is None:  # steady: the loop has taken the start-up steps already
            return ab3(None), AB3State(f1=f0, f2=rule_state.f1, n=None)
        x1 = jax.lax.cond(rule_state.n >= 2, ab3, start, None)
        new_state = AB3State(f1=f0, f2=rule_state.f1, n=jnp.minimum(rule_state.n + 1, 2))
        return x1, new_state


class AbstractRuleCarry(eqx.Module):
    """The state of a component that a rule steps: its flat vector ``x`` beside the rule's own state.

    Every such state subclasses it (the observers' :class:`~jaxobs.observers.ObserverState` and
    :class:`~jaxobs.observers.DriveObserverState`, the plants' ``PlantState`` and ``DualPlantState``), so that
    :func:`ab3_steady_from_start` finds the AB3 components of a carry by their class, not by attribute names.

    Attributes:
        x: The flat state.
        rule: The rule's state (an :class:`AB3State`, or None for one-step rules).
    """

    x: jax.Array
    rule: Any


def _is_ab3_component(node) -> bool:
    """A component's state: its vector ``x`` beside the :class:`AB3State` of the rule that steps it."""
    return isinstance(node, AbstractRuleCarry) and isinstance(node.rule, AB3State)


def ab3_steady_from_start(c0: PyTree, c1: PyTree, c2: PyTree, h: float) -> PyTree | None:
    """The carry at sample 0 with every AB3 component's history replaced by one under which two *steady* AB3
    steps from its x₀ land on the x₁ and x₂ that the RK4 start-up took it to.

    Why: a loop whose inputs are scan rows cannot start its steady loop at sample 2 without slicing its
    inputs (``xs[2:]``, a copy of the whole horizon, :mod:`jaxobs.runtime._loop` point 6).  With the start-up's
    values F₀ = f(x₀, u₀), F₁ = f(x₁, u₁) (``c2``'s history) the steady step
    x₊ = x + h/12 (23 f − 16 f₋₁ + 5 f₋₂) reproduces x₁ and x₂ exactly in real arithmetic when

        f₋₁ = A = (12/h (x₂ − x₁) − 23 F₁ + 16 F₀) / 5,    f₋₂ = B = (12/h (x₁ − x₀) − 23 F₀ + 16 A) / 5;

    in floating point to the rounding of x (the increment x₁ − x₀ is formed and added back, an error of an
    ulp of x; tests/test_perf.py compares with the peeled loop to 1e-12 in float64).

    Args:
        c0: The carry at sample 0.
        c1: The carry after the start-up's first step.
        c2: The carry after its second step.
        h: The step every AB3 component takes per sample (an observer on a signal: its ``ts``).

    Returns:
        The carry, or ``None`` when it holds an AB3 state that is not a component's ``(x, rule)`` pair (then
        the caller peels the start-up).
    """
    n_ab3 = sum(1 for x in jax.tree.leaves(c0, is_leaf=lambda n: isinstance(n, AB3State)) if isinstance(x, AB3State))
    n_comp = sum(1 for x in jax.tree.leaves(c0, is_leaf=_is_ab3_component) if _is_ab3_component(x))
    if n_ab3 == 0 or n_ab3 != n_comp:
        return None

    def fill(s0, s1, s2):
        if not _is_ab3_component(s0):
            return s0
        x0, x1, x2 = s0.x, s1.x, s2.x
        F1, F0 = s2.rule.f1, s2.rule.f2
        k = jnp.asarray(12.0 / h, jnp.result_type(x0))
        A = (k * (x2 - x1) - 23.0 * F1 + 16.0 * F0) / 5.0
        B = (k * (x1 - x0) - 23.0 * F0 + 16.0 * A) / 5.0
        return eqx.tree_at(lambda n: n.rule, s0, AB3State(f1=A, f2=B, n=None))

    return jax.tree.map(fill, c0, c1, c2, is_leaf=_is_ab3_component)


def check_rule(rule: object, owner: str) -> AbstractRule:
    """A component's ``rule`` must be a discretization rule object.

    Args:
        rule: The rule.
        owner: The component's name in the error.

    Returns:
        ``rule``.

    Raises:
        ValueError: ``rule`` is not an :class:`AbstractRule`.
    """
    if not isinstance(rule, AbstractRule):
        raise ValueError(
            f"{owner}.rule must be a discretization rule (jaxobs.Euler(), Tustin(), AB3(), RK4()), got {rule!r}"
        )
    return rule
