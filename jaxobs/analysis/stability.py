"""Closed-loop stability of a drive design at an operating point, from the simulated, sampled loop itself.

:func:`lyapunov` linearizes :meth:`ClosedLoop.step <jaxobs.drive.ClosedLoop.step>` along its own
trajectory (``jax.jvp``, forward mode) and measures how fast small perturbations grow or decay: the
largest Lyapunov exponent of the closed loop (1/s), with the rotor angle's neutral direction taken out.
Nothing here is a model of the drive; the same step that :func:`jaxobs.simulate` runs (plant under RK4,
one-sample delay, 1 kHz speed loop, inverter limits, the observer's own discretization) is linearized.
:func:`linear_speed_loop` is the papers' small-signal view beside it (module end, and docs/stability.md).

Why a Lyapunov exponent and not Floquet multipliers.  At a constant speed the loop is, in the rotor frame,
periodic with the speed loop's period (``speed_every`` samples); but its state is not in the rotor frame:
the plant's angle, the observer's stationary-frame filters and the held αβ voltage rotate with θe.  A
monodromy matrix would need the rotation's action on every observer's state (family-specific
knowledge).  The Lyapunov exponents need none: they are the growth rates of the state transition
matrix Φ(t) along the orbit, whatever frame the state is in, and for a relative equilibrium they equal
log|μ|/T of the rotor-frame Floquet multipliers μ.

The neutral direction.  A common rotation of the rotor angle and of everything that turns with it maps
the closed loop's orbit onto another orbit of the same loop (the machine, FOC and observers are
rotation-equivariant), so that direction neither grows nor decays: multiplier 1, exponent 0 — it would
mask every stable design.  It is found without knowing the state's layout: the derivative of the
settled state with respect to the scenario's initial angle θe0 (one ``jvp`` through ``init`` and the
settling run).  That vector is carried as the first column of the QR iterations (it stays the neutral
direction under Φ), and the exponents of the columns after it are those of the quotient: the
non-neutral ones.  State components the step only copies (the I-f start-up's bookkeeping when there is
no start-up) are another trivially neutral block; they are found by the step's Jacobian (a column and a
row equal to the unit vector) and masked out.

Estimate.  ``n_dirs`` tangent directions (plus the neutral one) are propagated by ``jvp`` and
re-orthonormalized (QR) every speed-loop period; the exponent is the least-squares slope of the
accumulated log growth over ``window`` seconds, after ``settle`` seconds that bring the loop to its
steady orbit (from the steady start) and ``warmup`` seconds that align the directions with the
dominant modes.  The slope averages the bounded wobble of a non-normal or oscillatory mode; its error
falls like 1/window.

Resolution: the verdict near 0.  The accumulated log growth over the window is λt plus a bounded wobble (the
oscillation of a lightly damped pair, the transient of directions not yet aligned, a slow beat between
modes), so a finite window's slope is off by an amount a single fit does not show.  The window measures it
itself: ``resolution`` is the spread of the top exponent's slopes fitted to the window's three thirds (and
its two halves, :func:`slope_fit`).  Checked on 000's closed-form second-order SOIFO at 8 speeds from 300 to
1000 r/min (the 5 Hz speed loop, boundary near 411 r/min), sliding windows against the slope of a 2 s
window: the estimate's error was within its resolution in 97–100 % of windows; near the boundary the 0.4 s
window's errors were 0.1–0.2 /s against a resolution of 0.35–0.8 /s, the 1 s window's ≤ 0.08 /s against
0.07–0.16 /s.  An exponent within ``resolution`` of −tol is *marginal*: the window cannot tell a slowly
decaying mode from a slowly growing one, and the verdict says so (``marginal``; ``stable`` is False) rather
than deciding by the wobble's phase.  A longer window resolves it.  ``stable`` needs margin − resolution >
tol; ``marginal`` and ``stable`` exclude each other, and a point that is neither is unstable.

Off the orbit.  Where the orbit's speed deviation after the settle reaches :data:`OFF_ORBIT_DEV` the
linearized run has left its operating point (``off_orbit``): the point is unstable, but the exponent is the
growth along the departed trajectory, where the departure has begun to saturate it, and the resolution
does not cover the gap.  So ``resolution`` is NaN there and ``rate_bound`` = max(exponent − resolution, 0)
is a lower bound on the point's rate.  000's second-order SOIFO at 300 r/min, no load, R̂s 30 % low, after
a 0.2 s settle: 23 % off its speed and +6.06 /s (bound 4.53) over the default 0.2 s Floquet window, 72 % off
and +2.69 /s (bound 2.43) over a 0.5 s one; from its settled start (no settle, a 0.1 s window) 4 % off, on the
orbit, +7.15 ± 0.30 /s.

Everything is inside one ``jit``: vmap it over operating points
(:func:`stability_sweep`) and differentiate it with respect to the gains (reverse mode through the
scan; the QR and the log are smooth where the exponents are distinct).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from ..drive import ClosedLoop, DualClosedLoop, Scenario
from ..linear import TransferFunction, sogi_fll_model, wif_model
from .monodromy import MATRIX, _start, multipliers

__all__ = ["Stability", "lyapunov", "stability_sweep", "LinearVerdict", "linear_speed_loop", "fll_frequency_soifo"]
__all__ += ["fll_frequency_sosoifo", "slope_fit", "floquet", "OFF_ORBIT_DEV"]


class Stability(NamedTuple):
    """The verdict of :func:`lyapunov` (each field batched under ``vmap``)."""

    exponent: jax.Array  # largest non-neutral Lyapunov exponent, 1/s (> 0: perturbations grow)
    exponents: jax.Array  # the n_dirs largest non-neutral exponents, 1/s, largest first
    margin: jax.Array  # −exponent, 1/s: the decay rate of the slowest mode (> tol: stable)
    stable: jax.Array  # margin − resolution > tol and the orbit held its speed (bool): resolved stable
    speed_dev: jax.Array  # max |ωm − ωm*| / |ωm*| over warmup + window (the orbit itself, after the settle), 1
    resolution: jax.Array  # 1/s: spread of the exponent over the window's thirds, its uncertainty (module doc)
    marginal: jax.Array  # the orbit held its speed but |margin − tol| ≤ resolution: neither verdict (bool)
    off_orbit: jax.Array  # the orbit left its operating point: speed_dev ≥ OFF_ORBIT_DEV after the settle (bool)
    rate_bound: jax.Array  # off the orbit: a lower bound on the growth rate, 1/s (module doc); NaN on it


# The speed deviation (relative, after the settle) past which the linearized run no longer follows the operating
# point's orbit; below it the orbit "held its speed" (stable and marginal need it).  0.1: above an orbit's own
# ripple and slow growth, below a departed run's deviation (module doc, docs/performance.md).
OFF_ORBIT_DEV = 0.1


def _orbit(lam, res, speed_dev):
    """(resolution, off_orbit, rate_bound) from the top exponent ``lam``, its resolution ``res`` and the orbit's
    speed deviation: off the orbit the resolution is NaN (no ±) and the rate a bound, max(lam − res, 0)."""
    off = ~(speed_dev < OFF_ORBIT_DEV)
    bound = jnp.where(jnp.isfinite(lam) & jnp.isfinite(res), jnp.maximum(lam - res, 0.0), jnp.inf)
    return jnp.where(off, jnp.nan, res), off, jnp.where(off, bound, jnp.nan)


def _check(fn: str, system, spans) -> None:
    """The checks both verdicts make: a steady ClosedLoop or DualClosedLoop (:func:`_check_dual`), and each
    (name, value, lowest) span in [lowest, 100] s."""
    if isinstance(system, DualClosedLoop):
        _check_dual(fn, system, dict((name, v) for name, v, _ in spans).get("settle", 0.0))
    elif not isinstance(system, ClosedLoop):
        raise ValueError(
            f"{fn}: system must be a jaxobs.drive.ClosedLoop or DualClosedLoop, got {type(system).__name__}"
        )
    if system.drive.startup is not None:
        raise ValueError(f"{fn}: system.drive.startup must be None (an operating point, started steady)")
    for name, v, lo in spans:
        if not (lo <= float(v) <= 100.0):
            raise ValueError(f"{fn}: {name} must be in [{lo:g}, 100] s, got {v!r}")


def _check_dual(fn: str, system: DualClosedLoop, settle) -> None:
    """The dual drive's verdict: its state is the whole :class:`~jaxobs.drive.dual_loop.DualLoopState` (both
    sets' currents, the xy PIs, under "individual" set 2's FOC, the observer on set 1's or the αβ measurements),
    its sampled period the :class:`~jaxobs.drive.DualFOC`'s speed loop (its FOC's ``speed_every``), its
    electrical period that of ``machine.p`` (the 5th/7th harmonics and set 2's 30° all repeat over it).  A
    sensorless one must hand over to the observer within the settle (``drive.handover`` ≤ ``settle``): the
    window then sees the loop the observer closes, not the encoder's."""
    if system.drive.sensorless and float(system.drive.handover) > float(settle):
        raise ValueError(
            f"{fn}: a sensorless DualClosedLoop needs drive.handover <= settle ({float(settle):g} s), "
            f"got {system.drive.handover!r}"
        )


def _speed_every(system) -> int:
    """Control periods per speed-loop period: the sampled loop's own period (a ClosedLoop's or a DualClosedLoop's)."""
    foc = system.drive.ctrl.foc if isinstance(system, DualClosedLoop) else system.drive.foc
    return foc.speed_every


def lyapunov(
    system: ClosedLoop | DualClosedLoop,
    *,
    settle: float = 0.2,
    warmup: float = 0.1,
    window: float = 0.4,
    n_dirs: int = 3,
    tol: float = 0.0,
    seed: int = 0,
) -> Stability:
    """The largest non-neutral Lyapunov exponent of ``system``'s closed loop at its operating point.

    The scenario's profiles should be constant over the run (an operating point); the loop starts in its
    steady state (no I-f start-up: ``drive.startup`` must be None).

    Args:
        system: a :class:`~jaxobs.drive.ClosedLoop` or a :class:`~jaxobs.drive.DualClosedLoop` (its state and
            periods: :func:`_check_dual`).
        settle: s (module doc), rounded to whole speed-loop periods.
        warmup: s, likewise.
        window: s, likewise.
        n_dirs: tangent directions tracked besides the neutral one (≥ 1; 2 or more resolves a complex pair
            smoothly).
        tol: 1/s, the margin a stable verdict needs.
        seed: the initial directions.

    Returns:
        The :class:`Stability` verdict.

    Raises:
        ValueError: a system that is not a steady closed loop, or a span or count out of its range.
    """
    _check("lyapunov", system, (("settle", settle, 0.0), ("warmup", warmup, 0.0), ("window", window, 1e-3)))
    if isinstance(n_dirs, bool) or not isinstance(n_dirs, int) or not 1 <= n_dirs <= 16:
        raise ValueError(f"lyapunov: n_dirs must be an integer in [1, 16], got {n_dirs!r}")
    ts, blk = system.ts, _speed_every(system)
    n_settle, n_warm, n_win = (max(int(round(v / (ts * blk))), 0) for v in (settle, warmup, window))
    n_win = max(n_win, 6)  # three thirds of at least two periods each (the resolution)

    vec0, rest0, neutral, split, step_vec = _start(system)
    n = vec0.shape[0]
    rand = jax.random.normal(jax.random.PRNGKey(seed), (n, n_dirs), dtype=vec0.dtype)
    neutrals = neutral[:, None] if split is None else jnp.concatenate([neutral[:, None], split], axis=1)
    q0 = jnp.concatenate([neutrals, rand], axis=1)
    ref = jnp.abs(system.scenario.speed_ref(0.0))

    # One scan, one copy of the linearized step (settle, warm-up and window alike: compile time).  The
    # neutral column is propagated from t = 0, so it is d x_k/dθe0 exactly; QR every block keeps the
    # columns orthonormal; their growth counts after the settle and the warm-up.
    def block(carry, j):
        vec, rest, q, mask = carry

        def one(c, i):
            v, r, t, m = c
            k = j * blk + i
            v1, t1, (r1, out) = jax.vmap(
                lambda tt: jax.jvp(lambda vv: step_vec(vv, r, k), (v,), (tt,), has_aux=True),
                in_axes=1,
                out_axes=(None, 1, None),
            )(t)
            # components the step only copies (a unit row of its Jacobian: the I-f start-up's bookkeeping
            # without a start-up, constants) are a trivially neutral block: found at the first step, where
            # no random column keeps its value through a real update (almost surely), and masked out
            m = jnp.where(k == 0, jnp.any(t1[:, 1:] != t[:, 1:], axis=1), m)
            # the orbit's speed deviation counts after the settle: a start that dips and recovers within it
            # (a biased observer's steady start at low speed under load) is judged on the orbit it reaches
            dev = jnp.abs(out.omega_m - out.omega_m_ref) / jnp.maximum(ref, 1e-6)
            dev = jnp.where(j >= n_settle, dev, 0.0)
            return (v1, r1, t1 * m[:, None], m), dev

        (vec, rest, w, mask), dev = jax.lax.scan(one, (vec, rest, q, mask), jnp.arange(blk))
        q, r = jnp.linalg.qr(w)
        grow = jnp.log(jnp.abs(jnp.diagonal(r))[neutrals.shape[1] :])
        return (vec, rest, q, mask), (grow, jnp.max(dev))

    mask0 = jnp.ones((n,), bool)
    _, (grow, dev) = jax.lax.scan(block, (vec0, rest0, q0, mask0), jnp.arange(n_settle + n_warm + n_win))
    # least-squares slope of the accumulated log growth over the window (per direction), 1/s
    slope, resolution = slope_fit(jnp.cumsum(grow, axis=0)[n_settle + n_warm :], blk * ts)
    finite = jnp.all(jnp.isfinite(slope))
    slope = jnp.where(finite, slope, jnp.inf)
    top = jnp.argmax(slope)
    lam = slope[top]
    # the top exponent's resolution: an uncertainty of the estimate, not a property a tuner should move
    res = jnp.where(finite, jax.lax.stop_gradient(resolution[top]), jnp.inf)
    speed_dev = jnp.where(jnp.isfinite(lam), jnp.max(dev), jnp.inf)
    held = speed_dev < OFF_ORBIT_DEV
    res_on, off, bound = _orbit(lam, res, speed_dev)
    return Stability(
        exponent=lam,
        exponents=-jnp.sort(-slope),
        margin=-lam,
        stable=(-lam - res > tol) & held,
        speed_dev=speed_dev,
        resolution=res_on,
        marginal=(jnp.abs(-lam - tol) <= res) & held & finite,
        off_orbit=off,
        rate_bound=bound,
    )


def _periodic_window(
    system: ClosedLoop | DualClosedLoop, window: float, n_max: int, h: float
) -> tuple[ClosedLoop | DualClosedLoop, jax.Array, jax.Array]:
    """:func:`floquet`'s window: ``system`` with its speed moved so that m electrical periods are N whole
    speed-loop periods of ``h`` s, N (at most ``n_max``), and whether N periods cover the m electrical ones."""
    # the window: m electrical periods, the fewest lasting ``window``; N whole speed-loop periods; the speed
    # moved so that they coincide, ω' = ω · m T_e / (N h)
    sc = system.scenario
    w_ref = jnp.abs(sc.speed_ref(0.0))
    t_e = 2.0 * jnp.pi / jnp.maximum(system.pole_pairs * w_ref, 1e-9)
    m = jnp.maximum(jnp.ceil(window / t_e - 1e-9), 1.0)
    n_win = jnp.maximum(jnp.round(m * t_e / h), 1.0)
    covered = n_win <= n_max
    n_win = jnp.minimum(n_win, float(n_max))
    scale = jnp.where(covered, m * t_e / (n_win * h), 1.0)
    system = eqx.tree_at(
        lambda s: (s.scenario.speed_ref.values, s.scenario.omega_m0),
        system,
        (sc.speed_ref.values * scale, sc.omega_m0 * scale),
    )

    return system, n_win, covered


def floquet(
    system: ClosedLoop | DualClosedLoop,
    *,
    settle: float = 0.2,
    window: float = 0.2,
    max_window: float = 2.0,
    n_report: int = 3,
    tol: float = 0.0,
    matrix: str = "auto",
    block: int = 6,
    iters: int = 5,
    rtol: float = 1e-6,
) -> Stability:
    """The largest non-neutral Floquet multiplier of ``system``'s closed loop over whole electrical periods.

    Where :func:`lyapunov` fits the growth of a few tracked directions (and cannot resolve a slow mode from
    its neighbours within a finite window: the FA-LESO's integral state, −k1 k2/(k2² + ωe²) ≈ −0.05 to
    −0.1 /s for 002's Table II), this forms the
    whole state transition matrix M over an exact period of the orbit and takes its eigenvalues.

    Why whole periods make M a monodromy matrix without knowing the state's frames.  At a constant speed the
    loop's orbit turns with θe; the state (αβ filters, the held voltage, angles) is the same after every
    electrical period T_e, provided the sampled loop's own period (the speed loop's ``speed_every`` samples,
    h) fits it.  So the window is the fewest electrical periods m that last at least ``window`` seconds, N =
    round(m T_e/h) speed-loop periods, and the speed is moved to where m T_e' = N h exactly: a relative change
    of at most h/(2 window) (0.25 % for 0.2 s and the 1 kHz speed loop).  On that periodic orbit
    M = ∂x(t0 + m T_e')/∂x(t0) is the monodromy matrix; its eigenvalues μ are the Floquet multipliers and
    log|μ|/(m T_e') the Lyapunov exponents, each exactly, however close two of them are.

    The neutral multiplier.  The orbit from θe0 + δ is the same orbit shifted (rotation equivariance, or a
    phase along it where harmonics or the dead time break the symmetry), so v = ∂x(t0)/∂θe0 (one ``jvp``
    through ``init`` and the settle) has M v = v.  In a basis [v, v⊥] M is block-triangular, so the
    eigenvalues of P M P with P = I − v vᵀ/vᵀv are those of M less the neutral 1 (and a 0): no eigenvector
    matching.  Components the step only copies are masked as in :func:`lyapunov`.

    ``resolution`` (1/s) says how periodic the orbit really was: δ = |log|vᵀMv/vᵀv|| + |P M v|/|v| (0 on an
    exact periodic orbit) may move the top multiplier μ by about δ, its rate by log(1 + δ/|μ|)/(m T_e'); larger
    where the settle left the loop off its orbit or where the profiles are not constant; inf where one
    electrical period is longer than ``max_window`` (the point is then ``marginal``: not resolved).
    ``stable``, ``marginal`` and ``speed_dev`` as in :func:`lyapunov` (the deviation over the window);
    ``exponents`` are the ``n_report`` largest non-neutral log|μ|/(m T_e'), largest first.

    Cost: by default (``matrix="full"``, and ``"auto"`` where it is cheaper) every state component is a tangent
    direction (n of them, ``jax.vmap`` of ``jax.jvp``), over the point's own window (a ``while_loop``: under ``vmap``
    a batch runs as long as its longest window, so batch points of similar speed together, as
    :func:`jaxobs.analysis.envelope.envelope` does), after a settle that carries one (the neutral).  M is
    accumulated with a scalar normalization each block (a product of thousands of Jacobians).

    Matrix-free (``matrix="free"``): the verdict needs only the largest |μ|.  Subspace iteration with
    Rayleigh–Ritz (:func:`jaxobs.analysis.monodromy._dominant`): a block of ``block`` + 1 directions (``block``
    random ones, turned onto the dominant modes through the settle) is carried through the window, at most
    ``iters`` times, and the Ritz values of the small projected matrix are the multipliers' estimates; the passes
    stop where the top Ritz pair's relative residual ‖M y − θ y‖/(|θ| ‖y‖) is at most ``rtol``.  That residual
    is added to δ/|μ| in ``resolution`` (θ is an exact eigenvalue of a matrix within that much of M), so a pass
    count that falls short widens the resolution instead of moving the verdict silently.  ``exponents`` are the
    block's Ritz values: the top one to ``rtol``, the next ones converge more slowly (their neighbours' ratio).
    What cannot be matrix-free is nothing the verdict reads: ``off`` needs M v for the neutral v only (the first
    pass carries it), the mask the first sample's Jacobian's rows (a dense random probe for one period reads them).
    ``"auto"`` takes the matrix-free path where its worst case (``iters`` passes) costs less by
    :func:`jaxobs.analysis.monodromy.free_is_cheaper`: each sample of d directions costs about 14 + d directions
    (the primal step and the loop's fixed costs, measured on the CPU), so with the defaults the whole matrix is
    the cheaper below about 100 states (000's drive with the second-order SOIFO has 32: the full path) and
    where ``n_report`` > ``block``.  ``"full"`` forces the reference.

    Differentiable in the gains by forward mode (``jax.jacfwd``; reverse mode does not pass a ``while_loop``) where
    the top non-neutral multiplier is simple, either path (matrix-free at 600 r/min, 000's second-order SOIFO:
    d(exponent)/d(lam) −83.73530 against central differences' −83.73530); ``eigvals`` runs on the CPU.

    Args:
        system: a :class:`~jaxobs.drive.ClosedLoop` or a :class:`~jaxobs.drive.DualClosedLoop`: the dual loop's
            whole state, its speed loop's period, the dual machine's electrical period (:func:`_check_dual`).
        settle: s, before the window (the neutral direction carried through it).
        window: s, the least window: the fewest whole electrical periods that last it.
        max_window: s, the longest window (a longer electrical period: not resolved).
        n_report: how many exponents ``exponents`` reports (1 to 16).
        tol: 1/s, the margin a stable verdict needs.
        matrix: "auto" (by cost), "full" (the whole monodromy matrix: the reference) or "free" (matrix-free).
        block: the matrix-free block's directions besides the neutral slot (1 to 32, ≥ ``n_report``).
        iters: the matrix-free path's most window passes (1 to 32).
        rtol: the top Ritz pair's relative residual that ends the passes, in (0, 1).

    Returns:
        The :class:`Stability` verdict.

    Raises:
        ValueError: a system that is not a steady closed loop, or a span, count or option out of its range.
    """
    _check("floquet", system, (("settle", settle, 0.0), ("window", window, 1e-3), ("max_window", max_window, 1e-3)))
    if float(max_window) < float(window):
        raise ValueError(f"floquet: max_window must be >= window ({window!r} s), got {max_window!r}")
    if isinstance(n_report, bool) or not isinstance(n_report, int) or not 1 <= n_report <= 16:
        raise ValueError(f"floquet: n_report must be an integer in [1, 16], got {n_report!r}")
    _check_free(matrix, block, iters, rtol, n_report)
    ts, blk = system.ts, _speed_every(system)
    h = ts * blk
    n_settle = max(int(round(settle / h)), 0)
    n_max = max(int(round(max_window / h)), 2)
    system, n_win, covered = _periodic_window(system, window, n_max, h)
    mult = multipliers(
        system,
        blk,
        n_settle,
        n_win,
        matrix=matrix,
        block=block,
        iters=iters,
        rtol=rtol,
        wanted=n_report,
        spans=(n_settle * h, float(window)),
    )
    period = n_win * h
    rates = -jnp.sort(-mult.log_mu) / period
    lam = rates[0]
    finite = jnp.isfinite(lam) & mult.finite
    lam = jnp.where(finite, lam, jnp.inf)
    # the resolution: an error δ in M (the orbit off periodic by that much) moves a multiplier by up to about δ,
    # so the top non-neutral one is at most |μ| + δ: its rate at most log(|μ| + δ)/T, log(1 + δ/|μ|)/T above
    # the estimate.  ≈ δ/T for a slow mode (|μ| near 1); for a fast one the same δ is a larger share of its
    # tiny μ (docs/performance.md).  An uncertainty of the estimate, not a property a tuner should move.
    # The matrix-free path's top Ritz value is an exact eigenvalue of a matrix within resid·|μ| of M: its
    # relative residual adds to δ/|μ| (0 for the whole matrix's eigenvalues; at most rtol where the passes met it).
    rel = mult.off * jnp.exp(-jnp.clip(lam, -700.0 / period, 700.0 / period) * period) + mult.resid
    res = jnp.where(finite & covered, jax.lax.stop_gradient(jnp.log1p(rel) / period), jnp.inf)
    speed_dev = jnp.where(finite, mult.dev, jnp.inf)
    held = speed_dev < OFF_ORBIT_DEV
    res_on, off, bound = _orbit(lam, res, speed_dev)
    return Stability(
        exponent=lam,
        exponents=jnp.where(finite, rates[:n_report], jnp.inf),
        margin=-lam,
        stable=(-lam - res > tol) & held,
        speed_dev=speed_dev,
        resolution=res_on,
        marginal=(jnp.abs(-lam - tol) <= res) & held & finite,
        off_orbit=off,
        rate_bound=bound,
    )


def _check_free(matrix, block, iters, rtol, n_report) -> None:
    """floquet's choice of path and the matrix-free one's options."""
    if matrix not in MATRIX:
        raise ValueError(f"floquet: matrix must be one of {', '.join(MATRIX)}, got {matrix!r}")
    for name, v, lo in (("block", block, 1), ("iters", iters, 1)):
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= 32:
            raise ValueError(f"floquet: {name} must be an integer in [{lo}, 32], got {v!r}")
    if not (isinstance(rtol, (int, float)) and not isinstance(rtol, bool) and 0.0 < float(rtol) < 1.0):
        raise ValueError(f"floquet: rtol must be a number in (0, 1), got {rtol!r}")
    if matrix == "free" and n_report > block:
        raise ValueError(f"floquet: with matrix='free', n_report must be <= block ({block}), got {n_report!r}")


def _weighted_slope(acc, t, w):
    """Least-squares slope of each column of ``acc`` against ``t`` over the samples where ``w`` is 1."""
    n = w.sum()
    tc = t - (w * t).sum() / n
    return ((w * tc)[:, None] * (acc - (w[:, None] * acc).sum(axis=0) / n)).sum(axis=0) / (w * tc * tc).sum()


def slope_fit(acc: jax.Array, dt: float) -> tuple[jax.Array, jax.Array]:
    """Least-squares slopes of ``acc`` (samples × columns, sampled every ``dt`` s) and their resolutions.

    The resolution is how far
    apart this window's own estimates of the exponent are (module doc): the larger of the spread (max − min)
    of the slopes fitted to its three thirds and the difference of those fitted to its two halves.  (Both
    are blind to a wobble whose period divides a sixth of the window, the same in every part; the full
    window's slope is then off by at most 12A/(ωT²) for a wobble A sin ωt over T s, and ω ≥ 12π/T there,
    so by at most A/(πT): 0.006 /s for A = 0.02 over 1 s.)

    Args:
        acc: the accumulated log growth, samples × columns.
        dt: s between samples.

    Returns:
        (slope, resolution), each per column, in units of ``acc`` per second.
    """
    n = acc.shape[0]
    t = jnp.arange(n, dtype=acc.dtype) * dt
    idx = jnp.arange(n)

    def parts(k):
        return jnp.stack([_weighted_slope(acc, t, ((idx * k) // n == i).astype(acc.dtype)) for i in range(k)])

    slope = _weighted_slope(acc, t, jnp.ones((n,), acc.dtype))
    thirds, halves = parts(3), parts(2)
    spread = jnp.maximum(thirds.max(axis=0) - thirds.min(axis=0), jnp.abs(halves[1] - halves[0]))
    return slope, spread


def stability_sweep(
    make_system: Callable[[Scenario], ClosedLoop | DualClosedLoop],
    scenarios: Scenario,
    *,
    method: str = "lyapunov",
    **kw: Any,
) -> Stability:
    """:func:`lyapunov` (or, ``method="floquet"``, :func:`floquet`) at every scenario of a batch, one ``jit(vmap)``.

    For ``floquet`` a batch runs as long as its slowest point's period: batch points of similar speed together.

    Args:
        make_system: scenario -> the closed loop (bind the observer to the scenario there).
        scenarios: the batch (a leading axis on every leaf).
        method: "lyapunov" or "floquet".
        **kw: that function's keyword arguments.

    Returns:
        The :class:`Stability` verdicts, batched.

    Raises:
        ValueError: an unknown method.
    """
    if method not in ("lyapunov", "floquet"):
        raise ValueError(f"stability_sweep: method must be 'lyapunov' or 'floquet', got {method!r}")
    fn = lyapunov if method == "lyapunov" else floquet
    return jax.jit(jax.vmap(lambda sc: fn(make_system(sc), **kw)))(scenarios)


# --------------------------------------------------------------------------
# the papers' small-signal view, with the speed loop closed through the FLL
# --------------------------------------------------------------------------


class LinearVerdict(NamedTuple):
    """The papers' small-signal verdict beside the speed loop's (:func:`linear_speed_loop`)."""

    observer_poles: jax.Array  # poles of the FLL's ω̂/ω alone (the papers' model), rad/s
    loop_poles: jax.Array  # poles of the speed loop closed through ω̂ (ideal current loop), rad/s
    observer_stable: jax.Array  # the papers' verdict: every observer pole in the left half-plane
    loop_stable: jax.Array  # the composed loop's verdict


def fll_frequency_soifo(k: ArrayLike, lam: ArrayLike, omega_e: ArrayLike) -> TransferFunction:
    """ω̂/ω of the SOIFO's FLL at ω_e: 001 eqs (18)–(20), λ/2 / (s² + (kω_e/2)s + λ/2).

    Args:
        k: the SOGI's damping gain.
        lam: the frequency-normalized FLL gain: λ = lam·ω_e² (jaxobs.observers.flux).
        omega_e: the electrical speed, rad/s.

    Returns:
        The transfer function ω̂/ω.
    """
    return sogi_fll_model(k, lam * omega_e**2, omega_e).frequency


def fll_frequency_sosoifo(K1: ArrayLike, K2: ArrayLike, lam: ArrayLike, omega_e: ArrayLike) -> TransferFunction:
    """ω̂/ω of the second-order SOIFO's FLL at ω_e: the SOGI-FLL-WIF model, 001 eqs (30)–(32).

    Args:
        K1: the observer's first gain (the model's k2).
        K2: its second gain (the model's k1).
        lam: the frequency-normalized FLL gain: λ = lam·ω_e² (jaxobs.observers.flux, SecondOrderSOIFO).
        omega_e: the electrical speed, rad/s.

    Returns:
        The transfer function ω̂/ω.
    """
    return wif_model(K2, K1, lam * omega_e**2, omega_e).frequency


def linear_speed_loop(
    fll: TransferFunction, *, J: ArrayLike, kt: ArrayLike, kp_w: ArrayLike, ki_w: ArrayLike
) -> LinearVerdict:
    """The speed loop closed through the observer's speed estimate ω̂ = G(s) ω, linear and continuous.

    Mechanics J s ω_m = K_t i_q (J kg·m², K_t N·m/A), current loop ideal (i_q = i_q*), the FOC's I-P
    speed controller i_q* = −k_pω ω̂ + (k_iω/s)(ω* − ω̂); so the characteristic polynomial is
    J s² D(s) + K_t (k_pω s + k_iω) N(s) with G = N/D.  With G = 1 (the encoder) its roots are the
    design's double pole at −α_s.  The papers stop at D(s): every positive gain passes; the product
    does not when G's bandwidth (∝ ω_e with the normalized FLL) comes near α_s.

    Args:
        fll: G(s) = ω̂/ω, the observer's speed estimate (:func:`fll_frequency_soifo`, ...).
        J: the inertia, kg·m².
        kt: the torque constant K_t, N·m/A.
        kp_w: the speed controller's proportional gain k_pω.
        ki_w: its integral gain k_iω.

    Returns:
        The :class:`LinearVerdict`: the observer's poles and the composed loop's, and their verdicts.
    """
    num, den = fll.num, fll.den
    a = J * jnp.convolve(jnp.stack([jnp.ones_like(den[0]), 0.0 * den[0], 0.0 * den[0]]), den)
    b = kt * jnp.convolve(jnp.stack([kp_w + 0.0 * den[0], ki_w + 0.0 * den[0]]), num)
    b = jnp.concatenate([jnp.zeros((a.shape[0] - b.shape[0],), b.dtype), b])
    loop = TransferFunction(jnp.ones((1,), a.dtype), a + b)
    obs_p, loop_p = jnp.asarray(fll.poles()), jnp.asarray(loop.poles())  # _roots' jax arrays, typed
    return LinearVerdict(
        observer_poles=obs_p,
        loop_poles=loop_p,
        observer_stable=jnp.all(obs_p.real < 0),
        loop_stable=jnp.all(loop_p.real < 0),
    )
