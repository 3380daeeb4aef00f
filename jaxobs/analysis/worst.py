"""The worst case by gradients: the operating point in a box of speed, load and resistance mismatch where a
design is least stable (:func:`worst_case`): a grid, then a multi-start projected gradient ascent with a
backtracking (Armijo) line search of the largest non-neutral Lyapunov exponent (:func:`_ascend`), each worst
verified by Floquet and simulation.

Why the ascent is written here and not an optimistix minimiser: (1) the search is confined to a box (the axes'
ranges) and optimistix's minimisers take no bounds, so a bounded search would run through a squashing
reparametrisation that bends the line search's geometry near the faces, where worst cases lie; (2) each round
tries three step lengths for every start in one batched evaluation (one program call of many long simulations),
where ``optx.BacktrackingArmijo`` tries one step per call and would take up to three times the sequential
simulations; (3) the exponent is a maximum over modes, not smooth everywhere, and the search keeps the best point
it has evaluated rather than its last iterate."""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import SaveAll, simulate
from ..drive import Drive, PMSMParams
from ..observers import AbstractObserver
from ..scenarios.families import DRIVE_STUDY_AXES, DriveScenarios
from .envelope_runs import speed_limit_rpm
from .stability import Stability, floquet, lyapunov

__all__ = ["WORST_AXES", "worst_case"]

# the box's axes a gradient search moves: the operating point and the assumed resistance
WORST_AXES = ("speed_rpm", "load_nm", "dRs")
# the step sizes one line-search round tries per start, as fractions of the start's trust length (in one batch)
_TRIALS = (1.0, 1.0 / 3.0, 1.0 / 9.0)
_ARMIJO = 1e-4  # sufficient increase: f(u') ≥ f(u) + c ∇f·(u' − u), c of Armijo's rule


def _point(base, par: PMSMParams, x):
    """``base`` (one scenario, its speed reference a step at its ``t_event``) moved to x = (speed r/min, load
    N·m, dRs), traceably: the reference held at the speed (both values of the step), the load constant."""
    w = x[0] * jnp.pi / 30
    return eqx.tree_at(
        lambda s: (s.speed_ref.values, s.load.values, s.omega_m0, s.est_par.Rs),
        base,
        (jnp.full_like(base.speed_ref.values, w), jnp.full_like(base.load.values, x[1]), w, par.Rs * (1 + x[2])),
    )


@eqx.filter_jit
def _exponent_and_grad(drive, obs, base, par, xs, kw: tuple):
    """The Lyapunov exponent (1/s) at each point of ``xs`` (B × 3) and its gradient in the point, by forward mode
    (one tangent per axis; no reverse pass through the linearized run, whose compilation took minutes).  One
    program per design class and batch size: the points are its argument."""

    def expo(x):
        sc = _point(base, par, x)
        return lyapunov(DriveScenarios(par, drive).system(obs, sc), **dict(kw)).exponent

    def value_and_jac(x):
        eye = jnp.eye(x.shape[0], dtype=x.dtype)
        return jax.vmap(lambda t: jax.jvp(expo, (x,), (t,)), out_axes=(None, 0))(eye)

    return jax.vmap(value_and_jac)(xs)


@eqx.filter_jit
def _verify_points(drive, obs, base, par, xs, signs, fkw: tuple, horizon: float, block: int):
    """At each point of ``xs``: :func:`floquet`'s verdict, and per sign of ``signs`` a ``horizon`` s simulation whose
    speed reference steps by ``sign`` (relative) at the base's ``t_event``: its peak |ωm − ωm*|/|ωm*| (against the
    reference of the moment) per block of ``block`` samples (points × signs × blocks)."""
    family = DriveScenarios(par, drive)

    def one(x):
        sc = _point(base, par, x)
        fv = floquet(family.system(obs, sc), **dict(fkw))

        def run(sign):
            vals = sc.speed_ref.values.at[1:].multiply(1.0 + sign)
            moved = eqx.tree_at(lambda s: s.speed_ref.values, sc, vals)
            o = simulate(family.system(obs, moved), horizon, save=SaveAll()).outputs
            dev = jnp.abs(o.omega_m - o.omega_m_ref) / jnp.abs(o.omega_m_ref)
            dev = jnp.where(jnp.isfinite(dev), dev, jnp.inf)
            n = (dev.shape[0] // block) * block
            return dev[:n].reshape(-1, block).max(axis=1)

        return tuple(fv), jax.vmap(run)(signs)

    return jax.vmap(one)(xs)


def _simulated_rate(peaks, block_s: float, t_from: float, floor: float = 1e-5, ceil: float = 0.3) -> float:
    """The growth rate (1/s) of a simulated deviation: the least-squares slope of log(peak per block) over the
    blocks from ``t_from`` s until the first that passes ``ceil`` (saturation), those above ``floor`` (the noise)."""
    p = np.asarray(peaks, float)
    t = (np.arange(p.size) + 0.5) * block_s
    over = np.flatnonzero(~(p < ceil))
    end = over[0] if over.size else p.size
    keep = (t >= t_from) & (np.arange(p.size) < end) & (p > floor)
    if keep.sum() < 3:
        return float("inf") if over.size and over[0] * block_s < t_from + 3 * block_s else float("nan")
    return float(np.polyfit(t[keep], np.log(p[keep]), 1)[0])


def _ascend(evaluate, u, v, g, iters: int):
    """Multi-start projected gradient ascent in the unit cube with a parallel backtracking (Armijo) line search
    (:func:`worst_case` has the rule).  ``evaluate(points)`` gives the values and gradients at the rows of
    ``points``; ``u``, ``v``, ``g``: the starts, their values and gradients (each start a row).  Returns the best
    point evaluated, its value, and each start's value per round (iters + 1, starts)."""
    u, v, g = u.copy(), v.copy(), g.copy()
    n_starts, dim = u.shape
    trust = np.full(n_starts, 0.25)
    active = np.ones(n_starts, bool)
    best_u, best_v = u[np.argmax(v)].copy(), float(np.max(v))
    path = [v.copy()]
    fr = np.asarray(_TRIALS)
    for _ in range(iters):
        if not active.any():
            path.append(v.copy())
            continue
        # the projected gradient: a component pushing out of the box at a face the start lies on is dropped
        # before the direction is normalized (else it takes the step's length and the clip then wastes it)
        gp = np.where(((u <= 0.0) & (g < 0)) | ((u >= 1.0) & (g > 0)), 0.0, g)
        d = gp / np.maximum(np.linalg.norm(gp, axis=1, keepdims=True), 1e-300)
        trial = np.clip(u[:, None, :] + (trust[:, None] * fr)[:, :, None] * d[:, None, :], 0.0, 1.0)
        tv, tg = evaluate(trial.reshape(-1, dim))
        tv, tg = tv.reshape(n_starts, len(fr)), tg.reshape(n_starts, len(fr), -1)
        gain = np.einsum("sj,stj->st", g, trial - u[:, None, :])
        ok = (tv >= v[:, None] + _ARMIJO * gain) & (gain > 0)
        for s in np.flatnonzero(active):
            if tv[s].max() > best_v:
                best_u, best_v = trial[s, int(np.argmax(tv[s]))].copy(), float(tv[s].max())
            if ok[s].any():
                j = int(np.argmax(np.where(ok[s], tv[s], -np.inf)))
                step = np.linalg.norm(trial[s, j] - u[s])
                u[s], v[s], g[s] = trial[s, j], tv[s, j], tg[s, j]
                trust[s] = min(1.0, 2.0 * trust[s] * fr[j]) if j == 0 else trust[s] * fr[j]
                active[s] = step >= 1e-3
            else:
                trust[s] /= 27.0
                active[s] = trust[s] >= 1e-3 and np.linalg.norm(trial[s, 0] - u[s]) >= 1e-3
        path.append(v.copy())
    return best_u, best_v, np.stack(path)


def _box_bounds(box: Mapping[str, Any], machine: PMSMParams, drive: Drive) -> tuple[np.ndarray, np.ndarray]:
    """The box's low and high ends over :data:`WORST_AXES` (an axis left out held at 0), checked."""
    if not isinstance(box, dict):
        raise ValueError(f"worst_case: box must be a dict {{axis: (low, high)}}, got {type(box).__name__}")
    if "speed_rpm" not in box:
        raise ValueError("worst_case: box must give speed_rpm = (low, high), r/min")
    unknown = set(box) - set(WORST_AXES)
    if unknown:
        raise ValueError(f"worst_case: box has unknown axes {sorted(unknown)}; allowed: {', '.join(WORST_AXES)}")
    # each axis within what a drive study allows (the speed up to the drive's limit, a positive resistance)
    allowed = {"speed_rpm": (1.0, speed_limit_rpm(machine, drive)), "load_nm": DRIVE_STUDY_AXES["load_nm"].range,
               "dRs": DRIVE_STUDY_AXES["dRs"].range}  # fmt: skip
    lo, hi = np.zeros(len(WORST_AXES)), np.zeros(len(WORST_AXES))
    for i, a in enumerate(WORST_AXES):
        if a not in box:
            continue
        v = box[a]
        if not isinstance(v, (tuple, list)) or len(v) != 2:
            raise ValueError(f"worst_case: box[{a!r}] must be a (low, high) pair, got {v!r}"[:200])
        try:
            lo[i], hi[i] = float(v[0]), float(v[1])
        except (TypeError, ValueError):
            raise ValueError(f"worst_case: box[{a!r}] must be two numbers, got {v!r}"[:200]) from None
        a_lo, a_hi = allowed[a]
        if not (math.isfinite(lo[i]) and math.isfinite(hi[i]) and a_lo <= lo[i] <= hi[i] <= a_hi):
            raise ValueError(
                f"worst_case: box[{a!r}] must be finite with {a_lo:.4g} <= low <= high <= {a_hi:.4g}, got "
                f"({lo[i]:g}, {hi[i]:g})"
            )
    return lo, hi


def _verify_options(verify: Mapping[str, float] | Literal[False] | None) -> dict[str, float]:
    """The verification's options (:func:`worst_case`'s defaults updated by ``verify``), checked."""
    ver = {"horizon": 1.0, "perturb": 0.02, "settle": 0.05, "window": 0.2}
    if verify is not None and verify is not False:
        unknown = set(verify) - set(ver)
        if unknown:
            raise ValueError(f"worst_case: verify has unknown keys {sorted(unknown)}; allowed: {', '.join(ver)}")
        ver.update(verify)
    if verify is not False and not (0.5 <= float(ver["horizon"]) <= 10.0 and 0.0 < float(ver["perturb"]) <= 0.2):
        raise ValueError("worst_case: verify horizon must be in [0.5, 10] s and perturb in (0, 0.2]")
    return ver


class _Evaluator:
    """The exponent and its gradient in the unit cube at a batch of points (:func:`_exponent_and_grad`, in
    batches of ``batch`` padded, so one program serves every call); counts the points evaluated."""

    def __init__(
        self, drive: Drive, obs: AbstractObserver, base: Any, machine: PMSMParams, lo: np.ndarray,
        hi: np.ndarray, kw: tuple, batch: int,
    ) -> None:  # fmt: skip
        self.drive, self.obs, self.base, self.machine, self.kw, self.batch = drive, obs, base, machine, kw, batch
        self.lo, self.span = lo, hi - lo
        self.free = self.span > 0
        self.n_eval = 0

    def __call__(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exponent and its gradient in the unit cube at the rows of ``u``, in batches of ``batch`` (padded)."""
        self.n_eval += len(u)
        vals, grads = [], []
        for i in range(0, len(u), self.batch):
            part = u[i : i + self.batch]
            pad = np.concatenate([part, np.repeat(part[-1:], self.batch - len(part), axis=0)])
            xs = jnp.asarray(self.lo + self.span * pad)
            v, g = jax.device_get(_exponent_and_grad(self.drive, self.obs, self.base, self.machine, xs, self.kw))
            vals.append(np.asarray(v)[: len(part)])
            grads.append(np.asarray(g)[: len(part)] * self.span)
        v, g = np.concatenate(vals), np.concatenate(grads)
        v = np.where(np.isnan(v), -np.inf, v)  # a failed evaluation is never the worst
        return v, np.where(np.isfinite(g), g, 0.0) * self.free


def _starts(
    evaluate: _Evaluator, grid: int, k_grid: int, n_random: int, seed: int
) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The grid (its points and values), and the starts: its ``k_grid`` worst points and ``n_random`` random
    interior ones (their points, values and gradients)."""
    axes_u = [np.linspace(0.0, 1.0, grid) if f else np.zeros(1) for f in evaluate.free]
    grid_u = np.stack(np.meshgrid(*axes_u, indexing="ij"), axis=-1).reshape(-1, len(WORST_AXES))
    grid_v, grid_g = evaluate(grid_u)
    order = np.argsort(-grid_v, kind="stable")[:k_grid]
    rng = np.random.default_rng(seed)
    rand_u = rng.uniform(0.05, 0.95, size=(n_random, len(WORST_AXES))) * evaluate.free
    u, v, g = grid_u[order], grid_v[order], grid_g[order]
    if n_random:
        rv, rg = evaluate(rand_u)
        u, v, g = np.concatenate([u, rand_u]), np.concatenate([v, rv]), np.concatenate([g, rg])
    return grid_u, grid_v, (u, v, g)


def _verify_found(
    found: Mapping[str, dict[str, Any]], evaluate: _Evaluator, ver: Mapping[str, float], t_step: float
) -> None:
    """Add each found point's Floquet verdict and simulated growth rates up and down to its dict (in place)."""
    drive = evaluate.drive
    t_blk = 0.05
    blk = max(int(round(t_blk / drive.ts)), 1)
    xs = jnp.asarray(evaluate.lo + evaluate.span * np.stack([f["u"] for f in found.values()]))
    signs = jnp.asarray([float(ver["perturb"]), -float(ver["perturb"])])
    fkw = tuple(sorted({"settle": float(ver["settle"]), "window": float(ver["window"])}.items()))
    fv, peaks = jax.device_get(
        _verify_points(drive, evaluate.obs, evaluate.base, evaluate.machine, xs, signs, fkw, float(ver["horizon"]), blk)
    )
    fv = Stability(*fv)
    for i, f in enumerate(found.values()):
        f["floquet"] = float(fv.exponent[i])
        f["floquet_resolution"] = float(fv.resolution[i])
        f["sim_rate_up"], f["sim_rate_down"] = (
            _simulated_rate(peaks[i, j], blk * drive.ts, t_step + 0.1) for j in range(2)
        )


def worst_case(
    obs: AbstractObserver,
    *,
    machine: PMSMParams,
    drive: Drive,
    box: Mapping[str, tuple[float, float]],
    grid: int = 3,
    k_grid: int = 2,
    n_random: int = 2,
    iters: int = 6,
    stability: Mapping[str, float] | None = None,
    verify: Mapping[str, float] | Literal[False] | None = None,
    seed: int = 0,
) -> dict[str, Any]:
    """The operating point in ``box`` where ``obs`` is least stable: a grid, then a multi-start projected gradient
    ascent with a backtracking (Armijo) line search of the largest non-neutral Lyapunov exponent (1/s).

    The search runs in the box scaled to the unit cube.  ``grid`` points per free axis (ends included) are
    evaluated first; the ``k_grid`` worst of them and ``n_random`` uniform interior points (``seed``) start the
    search.  Each round every start tries the projected steps u' = clip(u + s t d) along its projected gradient's
    direction d (unit length in the cube; a component pushing out through a face the start lies on dropped) for
    s in 1, 1/3, 1/9 of its trust length t (first 0.25), all starts' trials in one batch; it moves to the best
    trial that meets Armijo's rule f(u') ≥ f(u) + 10⁻⁴ ∇f·(u' − u), its t doubled after a full step and cut to
    the step taken after a shorter one, and cuts t by 27 where none does; a start stops when its projected step is
    under 10⁻³ (a corner whose gradient points out, or a local maximum).  Every evaluation (grid, starts and
    trials) is one program compiled once per design class: the points are its argument, a fixed batch (starts ×
    trials, the grid padded to it); the gradient is forward mode through the linearized run.

    The ascent is hand-written, not :mod:`optimistix`: measured on the built landscape of
    tests/test_envelope.py (a resonance peak inside the unit square, two starts), ``optimistix.BFGS`` (rtol 10⁻³,
    the box by clipping) reaches the peak in 11 and 12 sequential steps per start where this search takes 6 rounds,
    each one batch of every start's 3 trials; ``optimistix.GradientDescent`` (learning rate 0.05) had not reached
    it after 200 steps.  Each sequential step is a call of the linearized run, and an optimistix solve traces the
    objective inside its own loop (this program compiles for minutes); its worst cases on the slow tests' boxes
    were not measured.

    The grid's worst and the search's worst are then each verified (one more program): :func:`floquet`'s exponent
    and resolution, and simulations whose speed reference steps by ±``perturb`` (relative) at 0.05 s, whose
    growth rate is the slope of the log peak speed deviation per 0.05 s block from 0.15 s on
    (:func:`_simulated_rate`: until the deviation passes 30 %, above 10⁻⁵).

    Args:
        obs: a drive observer closing ``drive``'s loop sensorless.
        machine: the true and nominal machine.
        drive: a sensorless drive started steady (``startup`` None); its settle lengthened to the box's lowest
            speed (:meth:`~jaxobs.drive.Drive.settled_for`).
        box: ``{axis: (low, high)}`` over :data:`WORST_AXES` (speed r/min ≥ 1, load N·m, dRs relative); an axis
            left out is held at 0 (speed: required).
        grid: grid points per free axis (≥ 2).
        k_grid: the grid's worst points that start the search (≥ 0).
        n_random: random interior starts (≥ 0; k_grid + n_random ≥ 1).
        iters: line-search rounds (≥ 0).
        stability: :func:`~jaxobs.analysis.stability.lyapunov`'s options (default warmup 0.05, n_dirs 2, settle and
            window 0.1 and 0.2 s or one electrical period of the box's lowest speed where that is longer).
        verify: None for the defaults ``{"horizon": 1.0, "perturb": 0.02, "settle": 0.05, "window": 0.2}`` (the
            simulations' s and relative step, :func:`floquet`'s settle and window: short, since at a point that
            grows at +7 /s a 0.2 s settle and 0.5 s window let the orbit leave the operating point, and the rate
            came out 2.69 ± 0.25 /s where the simulations grow at 5.7–6.7), or False to skip it.
        seed: the random starts.

    Returns:
        A dict of NumPy and plain values: ``grid_x`` (points × 3), ``grid_exponent``; ``grid_worst`` and
        ``search_worst``, each ``{"x": {axis: value}, "exponent", and where verified "floquet", "floquet_resolution",
        "sim_rate_up", "sim_rate_down"}``; ``path`` (iters + 1, starts: each start's exponent per round),
        ``starts_x``, ``evaluations`` (points evaluated) and ``seconds`` (wall, compilation included).

    Raises:
        ValueError: a box axis unknown or not a finite (low, high) with low ≤ high, speed missing or below
            1 r/min, or a count out of range.
    """
    t_start = time.perf_counter()
    lo, hi = _box_bounds(box, machine, drive)
    for name, v, least in (("grid", grid, 2), ("k_grid", k_grid, 0), ("n_random", n_random, 0), ("iters", iters, 0)):
        if isinstance(v, bool) or not isinstance(v, int) or v < least:
            raise ValueError(f"worst_case: {name} must be an integer >= {least}, got {v!r}")
    n_starts = k_grid + n_random
    if n_starts < 1:
        raise ValueError("worst_case: k_grid + n_random must be >= 1")
    ver = _verify_options(verify)
    # the objective's settle and window cover at least one electrical period of the box's lowest speed: a shorter
    # window fits the exponent to part of the orbit's own oscillation (docs/performance.md, tests/test_envelope.py)
    t_e = 60.0 / (machine.p * float(lo[0]))
    defaults = {"settle": max(0.1, t_e), "warmup": 0.05, "window": max(0.2, t_e), "n_dirs": 2}
    kw = tuple(sorted({**defaults, **(stability or {})}.items()))
    # a steady start at every point of the box: the observer settled over SETTLE_PERIODS electrical periods of its
    # lowest speed (Drive.settled_for, as envelope's; a shorter settle let the run leave its operating point)
    drive = drive.settled_for(machine.p * float(lo[0]) * math.pi / 30)
    t_step = 0.05  # the verifying runs' reference step, s
    base = jax.tree.map(
        lambda v: v[0],
        DriveScenarios(machine, drive, t_event=t_step).build(["speed_rpm", "speed_step_rpm"], [(float(lo[0]), 0.0)]),
    )
    evaluate = _Evaluator(drive, obs, base, machine, lo, hi, kw, n_starts * len(_TRIALS))
    grid_u, grid_v, (u, v, g) = _starts(evaluate, grid, k_grid, n_random, seed)
    starts_u = u.copy()
    best_u, best_v, path = _ascend(evaluate, u, v, g, iters)
    grid_i = int(np.argmax(grid_v))
    found = {
        "grid_worst": {"u": grid_u[grid_i], "exponent": float(grid_v[grid_i])},
        "search_worst": {"u": best_u, "exponent": best_v},
    }
    if verify is not False:
        _verify_found(found, evaluate, ver, t_step)
    span = hi - lo
    for f in found.values():
        f["x"] = dict(zip(WORST_AXES, (lo + span * f.pop("u")).tolist()))
    return {
        "grid_x": lo + span * grid_u,
        "grid_exponent": grid_v,
        **found,
        "path": path,
        "starts_x": lo + span * starts_u,
        "evaluations": evaluate.n_eval,
        "seconds": time.perf_counter() - t_start,
    }
