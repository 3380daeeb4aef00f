"""The closed loop's linearization along its own orbit, for :func:`jaxobs.analysis.stability.floquet`: the steady
start and its neutral directions, the tangent blocks (``jax.vmap`` of ``jax.jvp`` through one speed-loop period of
``ClosedLoop.step``), and the window's multipliers two ways.

- :func:`full_multipliers`: the whole monodromy matrix M = ∂x(t0 + N h)/∂x(t0), every state direction (n of them)
  carried through the window, and all its eigenvalues.
- :func:`dominant_multipliers`: matrix-free, the few largest |μ| only, by subspace (orthogonal) iteration on
  products M·V (a block of ``block`` + 1 directions carried through the window per pass), with Rayleigh–Ritz each
  pass (Golub & Van Loan, Matrix Computations, 4th ed., §7.3.2 and §8.2; Saad, Numerical Methods for Large
  Eigenvalue Problems, 2nd ed., ch. 5).  The block rides through the settle as well (re-orthonormalized every
  speed-loop period, as :func:`~jaxobs.analysis.stability.lyapunov`'s directions do): on the way to a periodic orbit
  the settle's transition is M's own powers, so the block reaches the window already turned onto the dominant
  modes, and one or two passes usually meet the tolerance.

Both project out the neutral directions (the rotation ∂x/∂θe0, and under the dual drive's "individual" mode the
speed integrators' split) and mask the components the step only copies, the same way: their nonzero multipliers are
the same numbers (``floquet``'s docstring, and tests/test_stability.py checks them against each other).
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from ..drive import ClosedLoop, DualClosedLoop

__all__ = ["Multipliers", "multipliers", "free_is_cheaper", "MATRIX", "STEP_OVERHEAD"]

MATRIX = ("auto", "full", "free")  # multipliers' choice: by cost, the whole matrix, matrix-free


class Multipliers(NamedTuple):
    """The window's non-neutral multipliers, as ``floquet`` reads them (each batched under ``vmap``)."""

    log_mu: jax.Array  # log|μ| of the multipliers found (all n, or the block's Ritz values), unsorted
    off: jax.Array  # how far the neutral direction came back from itself: |log|vᵀMv|| + |P M v|/|v|, 1
    resid: jax.Array  # the top Ritz pair's residual ‖M y − θ y‖/(|θ| ‖y‖) (0 for the whole matrix's eigenvalues)
    finite: jax.Array  # the products (and so the multipliers) are finite (bool)
    dev: jax.Array  # the peak relative speed deviation over the window
    passes: jax.Array  # window passes made (1 for the whole matrix; the mask's one-period probe not counted)


def _split(state):
    """(the state's float leaves as one vector, a function back to the whole state given the rest)."""
    dyn, rest = eqx.partition(state, eqx.is_inexact_array)
    vec, unravel = ravel_pytree(dyn)
    return vec, rest, unravel


def _set_split(system, x0):
    """Directions besides the rotation that the loop holds neutral, as tangents at its start (n × k, or None):
    under the dual drive's "individual" mode the split of the speed integrators between the sets.  Both sets'
    FOCs integrate the same speed error; a difference between their integrators splits i_q* between the sets (an
    xy current), whose torque is the same to first order, so nothing restores it: a multiplier 1 (margin 0,
    whatever the design).  Carried through the settle from that start it becomes the neutral eigenvector (the
    other modes decay), and the verdicts take it out as they take out the rotation."""
    if not (isinstance(system, DualClosedLoop) and system.drive.mode == "individual"):
        return None
    dyn, _ = eqx.partition(x0, eqx.is_inexact_array)
    zeros = jax.tree.map(jnp.zeros_like, dyn)
    one = jnp.ones_like(x0.ctrl.main.int_w)
    split = eqx.tree_at(lambda s: (s.ctrl.main.int_w, s.ctrl.second.int_w), zeros, (one, -one))
    return ravel_pytree(split)[0][:, None]


def _start(system: ClosedLoop | DualClosedLoop):
    """The loop's steady start (its float vector and the rest), the neutral direction ∂x0/∂θe0 (one ``jvp``
    through ``init``), the other neutral directions at the start (:func:`_set_split`, or None), and the step
    on the float vector: (vec, rest, k) -> (vec, (rest, output))."""

    def initial(theta0):
        return eqx.tree_at(lambda m: m.scenario.theta_e0, system, theta0).init()

    th0 = system.scenario.theta_e0
    x0, dx0 = jax.jvp(initial, (th0,), (jnp.ones_like(th0),))
    vec0, rest0, unravel = _split(x0)
    is_float = jax.tree.map(eqx.is_inexact_array, x0)
    neutral, _ = ravel_pytree(eqx.filter(dx0, is_float))

    def step_vec(vec, rest, k):
        """One period on the float part; the rest (noise key, flags) rides along, constant for the tangents."""
        new, out = system.step(eqx.combine(unravel(vec), rest), k)
        v, r, _ = _split(new)
        return v, (r, out)

    return vec0, rest0, neutral, _set_split(system, x0), step_vec


def _tangent_block(step_vec, blk: int, ref):
    """One speed-loop period (``blk`` samples), block ``j``: the state and the tangent columns (n × d), the peak
    relative speed deviation from ``ref``, and the tangents after the first sample."""

    def block(vec, rest, t, j):
        def one(c, i):
            v, r, tt = c
            v1, t1, (r1, out) = jax.vmap(
                lambda d: jax.jvp(lambda vv: step_vec(vv, r, j * blk + i), (v,), (d,), has_aux=True),
                in_axes=1,
                out_axes=(None, 1, None),
            )(tt)
            dev = jnp.abs(out.omega_m - out.omega_m_ref) / jnp.maximum(ref, 1e-6)
            return (v1, r1, t1), (dev, t1)

        (vec, rest, t), (dev, tts) = jax.lax.scan(one, (vec, rest, t), jnp.arange(blk))
        return vec, rest, t, jnp.max(dev), tts[0]

    return block


def _window(block, vec, rest, x, n_settle: int, n_blocks):
    """The columns ``x`` (n × d) through ``n_blocks`` speed-loop periods from block ``n_settle`` (a ``while_loop``:
    each point its own count): the product normalized by one scalar a period (its log accumulated: a product of
    thousands of Jacobians), the log scale, the mask of the components the step does more than copy (a row of the
    first sample's Jacobian other than the unit one, read off the columns: exact for the identity, almost surely
    for dense random columns) and the peak speed deviation."""

    def body(c):
        j, vec, rest, w, log_s, mask, dev = c
        vec, rest, w1, d, first = block(vec, rest, w, n_settle + j)
        mask = jnp.where(j == 0, jnp.any(first != w, axis=1), mask)
        nrm = jnp.sqrt(jnp.sum(w1 * w1))
        nrm = jnp.where((nrm > 0) & jnp.isfinite(nrm), nrm, 1.0)
        return j + 1, vec, rest, w1 / nrm, log_s + jnp.log(nrm), mask, jnp.maximum(dev, d)

    z = jnp.zeros((), vec.dtype)
    init = (jnp.zeros((), jnp.int32), vec, rest, x, z, jnp.ones((x.shape[0],), bool), z)
    _, _, _, w, log_s, mask, dev = jax.lax.while_loop(lambda c: c[0] < n_blocks, body, init)
    return w, log_s, mask, dev


def _projector(vs, keep):
    """x -> P K x: the components the step only copies masked (K), then every neutral direction (the columns of
    ``vs``, masked) projected out (P = I − Q Qᵀ, Q an orthonormal basis of them); P and K commute.  Also Q and the
    masked, unit rotation direction."""
    vn = vs[:, 0] * keep
    vn = vn / jnp.maximum(jnp.linalg.norm(vn), 1e-300)
    q = vn[:, None] if vs.shape[1] == 1 else jnp.linalg.qr(vs * keep[:, None])[0]

    def proj(x):
        x = x * keep[:, None]
        return x - q @ (q.T @ x)

    return proj, q, vn


def _off(wv, vn, log_s):
    """How far the neutral direction came back from itself, |log|vᵀMv|| + |P M v|, from M v = e^log_s · ``wv``."""
    along = jnp.dot(vn, wv)
    return jnp.abs(jnp.log(jnp.maximum(jnp.abs(along), 1e-300)) + log_s) + jnp.linalg.norm(wv - along * vn) * jnp.exp(
        log_s
    )


def _full(start, ref, blk: int, n_settle: int, n_win) -> Multipliers:
    """Every multiplier of the window: the whole transition matrix over ``n_win`` speed-loop periods of ``blk``
    samples after ``n_settle`` (every state direction, from the identity), masked and projected, and its
    eigenvalues (n of them: the neutral ones and the masked components read 0).  ``start``: :func:`_start`'s."""
    vec0, rest0, neutral0, split, step_vec = start
    n = vec0.shape[0]
    block = _tangent_block(step_vec, blk, ref)

    # the settle: the neutral direction alone, from t = 0 (so it is ∂x/∂θe0 exactly)
    def settle_block(carry, j):
        vec, rest, t, _, _ = block(carry[0], carry[1], carry[2], j)
        return (vec, rest, t), None

    t0 = neutral0[:, None] if split is None else jnp.concatenate([neutral0[:, None], split], axis=1)
    (vec, rest, vs), _ = jax.lax.scan(settle_block, (vec0, rest0, t0), jnp.arange(n_settle))
    w, log_s, mask, dev = _window(block, vec, rest, jnp.eye(n, dtype=vec0.dtype), n_settle, n_win)
    keep = mask.astype(w.dtype)
    _, q, vn = _projector(vs, keep)
    w = w * keep[:, None] * keep[None, :]
    p = jnp.eye(n, dtype=w.dtype) - q @ q.T
    mu = jnp.linalg.eigvals(p @ w @ p)
    log_mu = jnp.log(jnp.maximum(jnp.abs(mu), 1e-300)) + log_s
    z = jnp.zeros((), w.dtype)
    return Multipliers(log_mu, _off(w @ vn, vn, log_s), z, jnp.all(jnp.isfinite(w)), dev, jnp.ones((), jnp.int32))


# The cost of one sample of the tangent block with d directions, in units of one direction: STEP_OVERHEAD + d.  The
# primal step (shared by the directions under vmap), the scan's and the small ops' fixed costs make the overhead:
# measured on the 2-core CPU for 000's SPMSM with the second-order SOIFO (32 states, a batch of 10 points, 0.2 s),
# CPU time 0.103 s with 2 directions, 0.139 with 5, 0.171 with 9, 0.209 with 13, 0.303 with 33: 0.092 + 0.0064 d,
# so about 14 directions' worth.
STEP_OVERHEAD = 14.0


def free_is_cheaper(n: int, n_neutral: int, block: int, iters: int, settle: float, window: float) -> bool:
    """Whether :func:`_dominant` costs less than :func:`_full` at its worst (``iters`` passes), by the cost model
    above: the settle carries ``n_neutral`` directions (the full path) or ``n_neutral`` + ``block`` (matrix-free),
    the window n (the identity) or ``block`` + 1 per pass.

    Args:
        n: the state's dimension.
        n_neutral: the neutral directions the settle carries either way.
        block: the Ritz block's directions.
        iters: the most window passes.
        settle: s, the settle.
        window: s, the least window (the points' own are longer: whole electrical periods).

    Returns:
        True where settle (a + n_neutral + block) + iters window (a + block + 1) < settle (a + n_neutral) +
        window (a + n), a = :data:`STEP_OVERHEAD`.
    """
    a = STEP_OVERHEAD
    free = settle * (a + n_neutral + block) + iters * window * (a + block + 1)
    return free < settle * (a + n_neutral) + window * (a + n)


def _ritz(x, y, at_first, rtol):
    """Rayleigh–Ritz on the basis ``x`` (orthonormal columns in the range of P K; at the first pass its column 0 is
    the neutral direction, out of the basis) and the products ``y`` = P K M x: the Ritz values θ (eigenvalues of
    H = xᵀ y) and whether the top one's relative residual ‖y s − θ x s‖/(|θ| ‖x s‖) meets ``rtol``, and that
    residual.  The residual is a stopping rule and an uncertainty, never differentiated (``stop_gradient``;
    eigenvectors have no derivative in JAX)."""
    b = x.at[:, 0].set(jnp.where(at_first, 0.0, x[:, 0]))  # H is then block-triangular: θ = 0 and the rest's
    h = b.T @ y
    ok = jnp.all(jnp.isfinite(h))
    h = jnp.where(ok, h, 0.0)
    theta = jnp.linalg.eigvals(h)
    th, s = jnp.linalg.eig(jax.lax.stop_gradient(h))
    i = jnp.argmax(jnp.abs(th))
    si = s[:, i]
    r = jax.lax.stop_gradient(y) @ si - th[i] * (jax.lax.stop_gradient(b) @ si)
    rel = jnp.linalg.norm(r) / jnp.maximum(jnp.abs(th[i]) * jnp.linalg.norm(b @ si), 1e-300)
    rel = jnp.where(ok, rel, jnp.inf)
    return theta, rel, (rel <= rtol) | ~ok


def _dominant(start, ref, blk: int, n_settle: int, n_win, block: int, iters: int, rtol: float) -> Multipliers:
    """The dominant multipliers of the window, matrix-free: subspace iteration on M·V by ``jvp``.

    The settle carries the neutral direction (as :func:`full_multipliers` does) and ``block`` random directions,
    re-orthonormalized against it every speed-loop period.  A one-period probe (dense random columns) finds the
    components the step only copies at the window's first sample.  Then at most ``iters`` window passes, each
    carrying ``block`` + 1 orthonormal directions V (in the range of P K) through the window: Y = P K M V,
    Rayleigh–Ritz on H = Vᵀ Y (its eigenvalues θ are the multipliers' estimates), V ← qr(Y).  The first pass
    carries the neutral direction in V's first column instead (M v gives ``off``), a random one after it.  The
    passes stop where the top Ritz pair's relative residual ‖M y − θ y‖/(|θ| ‖y‖) is at most ``rtol``: θ is then an
    exact eigenvalue of a matrix within rtol·|θ| of M (rtol·|θ| moves a simple multiplier by about that much, its
    rate by rtol/T), and ``resid`` reports it.  Under ``vmap`` a batch makes as many passes as its slowest point.
    ``start``: :func:`_start`'s; ``block`` + 1 Ritz values come back."""
    vec0, rest0, neutral0, split, step_vec = start
    n, dt = vec0.shape[0], vec0.dtype
    tb = _tangent_block(step_vec, blk, ref)
    k_set, k_probe, k_fresh = jax.random.split(jax.random.PRNGKey(0), 3)
    neutrals = neutral0[:, None] if split is None else jnp.concatenate([neutral0[:, None], split], axis=1)
    nn = neutrals.shape[1]

    # the settle: the neutral directions as in _full (∂x/∂θe0 exactly), and the block turning onto the dominant
    # modes: masked (the components the step only copies hold a multiplier 1 that would take the block over; found at
    # the first sample from the dense random start, as lyapunov finds them) and orthonormalized against the neutral
    # ones each period (QR: the quotient's dominant subspace)
    def settle_block(carry, j):
        vec, rest, t, m = carry
        vec, rest, t, _, first = tb(vec, rest, t, j)
        m = jnp.where(j == 0, jnp.any(first[:, nn:] != carry[2][:, nn:], axis=1), m)
        q = jnp.linalg.qr(jnp.concatenate([t[:, :nn], t[:, nn:] * m[:, None]], axis=1))[0]
        return (vec, rest, jnp.concatenate([t[:, :nn], q[:, nn:]], axis=1), m), None

    t0 = jnp.concatenate([neutrals, jax.random.normal(k_set, (n, block), dt)], axis=1)
    m0 = jnp.ones((n,), bool)
    (vec, rest, t, _), _ = jax.lax.scan(settle_block, (vec0, rest0, t0, m0), jnp.arange(n_settle))
    probe = jax.random.normal(k_probe, (n, block + 1), dt)
    _, _, mask, _ = _window(tb, vec, rest, probe, n_settle, 1)
    keep = mask.astype(dt)
    proj, _, vn = _projector(t[:, :nn], keep)
    x0 = jnp.concatenate([vn[:, None], jnp.linalg.qr(proj(t[:, nn:]))[0]], axis=1)
    fresh = proj(jax.random.normal(k_fresh, (n, 1), dt))[:, 0]

    def body(c):
        j, x, _, _, mvn, ls0, *_ = c
        w, log_s, _, dev = _window(tb, vec, rest, x, n_settle, n_win)
        y = proj(w)
        first = j == 0
        mvn = jnp.where(first, w[:, 0] * keep, mvn)  # K M v (v masked), as full_multipliers' w @ vn
        ls0 = jnp.where(first, log_s, ls0)
        theta, rel, done = _ritz(x, y, first, rtol)
        ok = jnp.all(jnp.isfinite(w)) & jnp.isfinite(log_s)
        nxt = y.at[:, 0].set(jnp.where(first, fresh, y[:, 0]))  # M v is not in the range of P: a fresh column
        x = jnp.linalg.qr(jnp.where(ok, nxt, x))[0]
        return j + 1, x, done | ~ok, theta, mvn, ls0, log_s, rel, ok, dev

    z = jnp.zeros((), dt)
    th0 = jnp.zeros((block + 1,), jnp.result_type(dt, jnp.complex64))
    init = (jnp.zeros((), jnp.int32), x0, jnp.zeros((), bool), th0, vn, z, z, z, jnp.ones((), bool), z)
    j, _, _, theta, mvn, ls0, log_s, rel, ok, dev = jax.lax.while_loop(lambda c: (c[0] < iters) & ~c[2], body, init)
    log_mu = jnp.log(jnp.maximum(jnp.abs(theta), 1e-300)) + log_s
    return Multipliers(log_mu, _off(mvn, vn, ls0), rel, ok & jnp.all(jnp.isfinite(mvn)), dev, j)


def multipliers(
    system: ClosedLoop | DualClosedLoop,
    blk: int,
    n_settle: int,
    n_win: jax.Array,
    *,
    matrix: str = "auto",
    block: int = 6,
    iters: int = 5,
    rtol: float = 1e-6,
    wanted: int = 1,
    spans: tuple[float, float] = (0.2, 0.2),
) -> Multipliers:
    """The window's non-neutral multipliers: the whole matrix's or the dominant ones, matrix-free.

    Args:
        system: the loop, its speed already moved onto whole periods (a steady start).
        blk: samples per speed-loop period.
        n_settle: speed-loop periods before the window.
        n_win: speed-loop periods of the window (traced: each point its own).
        matrix: "full" (every state direction), "free" (subspace iteration) or "auto": "free" where
            :func:`free_is_cheaper` and ``wanted`` ≤ ``block``.
        block: the matrix-free block's directions besides the neutral slot.
        iters: the matrix-free path's most window passes.
        rtol: the top Ritz pair's relative residual that ends its passes.
        wanted: how many of the largest multipliers the caller reads.
        spans: (settle, least window) in s, for the choice's cost (:func:`free_is_cheaper`).

    Returns:
        The :class:`Multipliers`.
    """
    start = _start(system)
    ref = jnp.abs(system.scenario.speed_ref(0.0))
    n, nn = start[0].shape[0], 1 if start[3] is None else 1 + start[3].shape[1]
    if matrix == "free" or (matrix == "auto" and wanted <= block and free_is_cheaper(n, nn, block, iters, *spans)):
        return _dominant(start, ref, blk, n_settle, n_win, block, iters, rtol)
    return _full(start, ref, blk, n_settle, n_win)
