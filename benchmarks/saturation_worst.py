"""The worst case over a saturation mismatch by gradients (``python -m benchmarks.saturation_mismatch --ascent N``):
per design, a multi-start projected gradient ascent of the steady rms position error over dsat, its derivatives
checked against central differences, the designs ranked by what the mismatch costs them.

The objective is the steady rms electrical position error (the study's ``rms_position_steady``, degrees): a mean
over the steady window, bounded while the drive holds lock, where the peak is one sample's and its gradient is that
sample's.  dsat moves the true machine's map as the study's dsat axis does (a_dd, a_qq, a_dq scaled by 1 + dsat),
traced, at each grid speed; the derivative d rms / d dsat is forward mode (``jax.jvp``: one tangent, dsat) through
the whole run, the observer's settling phase included.

A derivative is only a guide where the metric is a smooth function of dsat at the scale of a step.  It is not where
the drive rides its voltage limit: the current controller's anti-windup freezes its integrators in the periods
where |u*| > u_max (jaxobs.drive.control), a switch, so a run whose voltage touches the limit moves by a jump
whenever a tiny change of dsat moves a period across it, and a loop in a limit cycle against the limit amplifies
those jumps (central differences of SOIFO's steady rms at 1440 r/min, dsat 0, grow as 1/h: −6.6, −83, −467 °/unit
at h = 1e-2, 1e-3, 1e-4, where the exact derivative of the smooth piece is −2.3).  So at every start the forward-
mode derivative is compared with the central difference of step :data:`FD_STEP`; a start where they differ by more
than :data:`SMOOTH_RTOL` (relative) plus :data:`SMOOTH_ATOL` is "rough": its derivative is printed and not
climbed, and the design's worst there is the grid's.  A scenario that loses lock (the study's definition: the
estimate 90° electrical off in the steady window, or not finite) is itself the worst case: reported as lost at its
dsat, never as a gradient (the ascent gives it −∞, so no step is taken into it).

The ascent is :func:`jaxobs.analysis.worst._ascend`, the project's multi-start projected gradient ascent with a
batched backtracking (Armijo) line search (:func:`jaxobs.analysis.worst.worst_case` has the rule), on the points
(dsat, speed) scaled to the unit square, the speed's gradient 0 (each start keeps its speed).  Every evaluation of
a design is one program (jitted once per observer class) on a fixed batch of :data:`BATCH` rows, padded.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

FD_STEP = 1e-3  # the central difference's step on dsat
SMOOTH_RTOL = 0.1  # a smooth start: |AD − FD| ≤ SMOOTH_RTOL·max(|AD|, |FD|) + SMOOTH_ATOL
SMOOTH_ATOL = 0.05  # deg per unit dsat: below it a slope is flat (0.05° over the whole box's 2.5)
BATCH = 12  # rows per program call (a start and its ±FD_STEP, or the line search's 3 trials: 3 rows per start)
V_LIMIT_TOL = 1e-6  # a period at the voltage limit: |u| ≥ (1 − V_LIMIT_TOL) u_max


def _program():
    """The jitted evaluation: per row (scenario, dsat) the steady rms, peak and |mean| position errors (deg), the
    lost-lock flag and the share of periods at the voltage limit, and their forward-mode derivatives in dsat."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from jaxobs import simulate
    from jaxobs.metrics import METRICS, MetricContext

    @eqx.filter_jit
    def run(family, design, scs, vs, horizon: float):
        ctx = MetricContext(t_event=0.0, steady_from=horizon / 2)
        u_max = family.drive.foc.u_max

        def one(sc, v):
            def f(v):
                k = 1.0 + v
                m = sc.par.sat
                s = eqx.tree_at(
                    lambda s: (s.par.sat.a_dd, s.par.sat.a_qq, s.par.sat.a_dq), sc, (m.a_dd * k, m.a_qq * k, m.a_dq * k)
                )
                sol = simulate(family.system(design, s), horizon)
                o = sol.outputs
                at_limit = jnp.hypot(o.u_a, o.u_b) >= (1.0 - V_LIMIT_TOL) * u_max
                errs = [jnp.degrees(METRICS[k](sol, s, ctx)) for k in ("rms_position_steady",
                        "peak_position_steady", "bias_position")]  # fmt: skip
                lost = METRICS["lost_lock"](sol, s, ctx)
                return jnp.stack([*errs, lost.astype(v.dtype), jnp.mean(at_limit.astype(v.dtype))])

            return jax.jvp(f, (v,), (jnp.ones_like(v),))

        return jax.vmap(one)(scs, vs)

    return run


class Evaluator:
    """One design's evaluations at rows (dsat, speed index), in batches of ``batch`` rows (padded, so one program
    serves every call); every row evaluated is logged.

    Args:
        family: The study's :class:`~jaxobs.scenarios.families.drive.DriveScenarios`.
        design: The observer.
        speeds_rpm: The speeds the starts sit at.
        load_nm: The load.
        horizon: The runs' length, s (scored from half of it).
        batch: Rows per program call.
    """

    def __init__(self, family: Any, design: Any, speeds_rpm, load_nm: float, horizon: float, batch: int) -> None:
        import jax

        self.family, self.design, self.horizon, self.batch = family, design, float(horizon), int(batch)
        self.speeds = [float(r) for r in speeds_rpm]
        # the study's scenarios at dsat 0 (its builder), one per speed; dsat is applied traced in the program
        self.base = family.build(["dsat", "speed_rpm", "load_nm"], [(0.0, r, load_nm) for r in self.speeds])
        self._run = _program()
        self._take = jax.jit(lambda idx: jax.tree.map(lambda x: x[idx], self.base))
        self.log: list[dict] = []

    def rows(self, dsat, speed_i) -> tuple[np.ndarray, np.ndarray]:
        """Values (rows × 5: rms, peak, |mean| deg, lost, share at the voltage limit) and their d/d dsat."""
        import jax
        import jax.numpy as jnp

        dsat, speed_i = np.asarray(dsat, float), np.asarray(speed_i, int)
        vals, ders = [], []
        for i in range(0, len(dsat), self.batch):
            d, s = dsat[i : i + self.batch], speed_i[i : i + self.batch]
            pad = self.batch - len(d)
            d, s = np.concatenate([d, np.repeat(d[-1:], pad)]), np.concatenate([s, np.repeat(s[-1:], pad)])
            out = self._run(self.family, self.design, self._take(jnp.asarray(s)), jnp.asarray(d), self.horizon)
            v, g = (np.asarray(x)[: self.batch - pad] for x in jax.device_get(out))
            vals.append(v)
            ders.append(g)
        v, g = np.concatenate(vals), np.concatenate(ders)
        for j in range(len(dsat)):
            lost = bool(v[j, 3] > 0.5 or not np.isfinite(v[j, 0]))
            self.log.append({"dsat": float(dsat[j]), "speed_rpm": self.speeds[int(speed_i[j])],
                             "rms_deg": float(v[j, 0]), "peak_deg": float(v[j, 1]), "lost_lock": lost})  # fmt: skip
        return v, g

    def unit(self, box: tuple[float, float]):
        """The evaluation :func:`jaxobs.analysis.worst._ascend` calls: rows (dsat, speed) in the unit square to the
        rms (−∞ where lock is lost or a value is not finite) and its gradient there (the speed's 0)."""
        lo, span, ns = box[0], box[1] - box[0], max(len(self.speeds) - 1, 1)

        def evaluate(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            v, g = self.rows(lo + span * u[:, 0], np.rint(u[:, 1] * ns))
            held = (v[:, 3] < 0.5) & np.isfinite(v[:, 0]) & np.isfinite(g[:, 0])
            grad = np.stack([np.where(held, g[:, 0] * span, 0.0), np.zeros(len(u))], axis=1)
            return np.where(held, v[:, 0], -np.inf), grad

        return evaluate


def smooth(ad: float, fd: float) -> bool:
    """Whether a forward-mode derivative agrees with its central difference (:data:`SMOOTH_RTOL`, :data:`SMOOTH_ATOL`).

    Args:
        ad: The derivative by forward mode.
        fd: The central difference.

    Returns:
        True where they agree (both finite).
    """
    return bool(
        np.isfinite(ad) and np.isfinite(fd) and abs(ad - fd) <= SMOOTH_RTOL * max(abs(ad), abs(fd)) + SMOOTH_ATOL
    )


def check(ev: Evaluator, dsat, speed_i) -> list[dict]:
    """The values at each point (dsat, speed index) and d rms / d dsat by forward mode and by central differences
    of step :data:`FD_STEP` (one batch: each point and its ±step), each marked smooth or rough."""
    d, s = np.asarray(dsat, float), np.asarray(speed_i, int)
    v, g = ev.rows(np.concatenate([d, d + FD_STEP, d - FD_STEP]), np.concatenate([s, s, s]))
    n, out = len(d), []
    for j in range(n):
        fd = (v[n + j, 0] - v[2 * n + j, 0]) / (2 * FD_STEP)
        lost = bool(v[j, 3] > 0.5 or not np.isfinite(v[j, 0]))
        out.append({"dsat": float(d[j]), "speed_rpm": ev.speeds[int(s[j])], "rms_deg": float(v[j, 0]),
                    "peak_deg": float(v[j, 1]), "bias_deg": float(v[j, 2]), "lost_lock": lost,
                    "at_v_limit": float(v[j, 4]), "ad": float(g[j, 0]), "fd": float(fd),
                    "smooth": (not lost) and smooth(float(g[j, 0]), float(fd)),
                    "minimum": _kink(v[2 * n + j, 0], v[j, 0], v[n + j, 0], float(g[j, 0]))})  # fmt: skip
    return out


def _kink(below: float, at: float, above: float, ad: float) -> bool:
    """A minimum with a kink: the one-sided differences fall then rise and bracket the derivative (the rms where the
    error's mean crosses 0 at the matched machine: |x| has no slope there, and the central difference is not one)."""
    left, right = (at - below) / FD_STEP, (above - at) / FD_STEP
    return bool(left < 0.0 < right and left <= ad <= right)


def climb(ev: Evaluator, grid: dict, dsat, box: tuple[float, float], iters: int) -> dict:
    """One design's worst case by gradients: its held grid points in ``box`` checked (:func:`check`), the smooth ones
    climbed by :func:`jaxobs.analysis.worst._ascend` for ``iters`` rounds, the best point checked again.

    Args:
        ev: The design's :class:`Evaluator`.
        grid: The design's study grid (``lost_lock`` by dsat × speed).
        dsat: The grid's dsat values.
        box: The ascent's dsat range.
        iters: The line-search rounds.

    Returns:
        ``starts`` (:func:`check`'s rows), ``worst`` (the best held point the ascent evaluated, checked; None without
        a smooth start), ``lost`` (every (dsat, r/min) evaluated that lost lock), ``seconds``.
    """
    from jaxobs.analysis.worst import _ascend

    t0 = time.time()
    pts = [(v, j) for i, v in enumerate(dsat) for j in range(len(ev.speeds))
           if box[0] <= v <= box[1] and not grid["lost_lock"][i][j]]  # fmt: skip
    starts = check(ev, [p[0] for p in pts], [p[1] for p in pts]) if pts else []
    ok = [k for k, s in enumerate(starts) if s["smooth"]]
    worst = None
    if ok and iters > 0:
        span, ns = box[1] - box[0], max(len(ev.speeds) - 1, 1)
        u = np.array([[(starts[k]["dsat"] - box[0]) / span, pts[k][1] / ns] for k in ok])
        v = np.array([starts[k]["rms_deg"] for k in ok])
        g = np.array([[starts[k]["ad"] * span, 0.0] for k in ok])
        best_u, _, _ = _ascend(ev.unit(box), u, v, g, iters)
        worst = check(ev, [box[0] + span * best_u[0]], [int(round(best_u[1] * ns))])[0]
    lost = sorted({(r["dsat"], r["speed_rpm"]) for r in ev.log if r["lost_lock"]})
    return {"starts": starts, "worst": worst, "lost": lost, "evaluations": len(ev.log), "seconds": time.time() - t0}


def sensitivity(found: dict, grid: dict, dsat, speeds_rpm) -> dict:
    """One design's worst held rms (the grid's and the ascent's), where, and its sensitivity: the largest rise of the
    rms over its dsat = 0 value at the same speed (a speed lost at dsat = 0 left out); the scenarios lost by the
    mismatch (lost at dsat != 0 where dsat = 0 held at that speed, in the grid or in the ascent)."""
    rms, lost = np.array(grid["rms_deg"]), np.array(grid["lost_lock"])
    i0 = list(dsat).index(0.0)
    held0 = {float(r): float(rms[i0, j]) for j, r in enumerate(speeds_rpm) if not lost[i0, j]}
    cands = [(float(rms[i, j]), float(v), float(r), "grid") for i, v in enumerate(dsat)
             for j, r in enumerate(speeds_rpm) if not lost[i, j] and float(r) in held0]  # fmt: skip
    w = found["worst"]
    if w is not None and not w["lost_lock"] and w["speed_rpm"] in held0:
        cands.append((w["rms_deg"], w["dsat"], w["speed_rpm"], "gradient"))
    grid_lost = {(float(dsat[i]), float(speeds_rpm[j])) for i, j in zip(*np.nonzero(lost), strict=True)}
    by_mism = sorted(p for p in grid_lost | set(found["lost"]) if p[0] != 0.0 and p[1] in held0)
    if not cands:
        return {
            "worst_rms_deg": math.nan,
            "at": None,
            "by": None,
            "sensitivity_deg": math.nan,
            "lost_by_mismatch": by_mism,
        }
    top = max(cands, key=lambda c: c[0] - held0[c[2]])
    grid_top = max((c for c in cands if c[3] == "grid"), key=lambda c: c[0] - held0[c[2]])
    return {"worst_rms_deg": top[0], "at": {"dsat": top[1], "speed_rpm": top[2]}, "by": top[3],
            "sensitivity_deg": top[0] - held0[top[2]], "grid_sensitivity_deg": grid_top[0] - held0[grid_top[2]],
            "lost_by_mismatch": by_mism}  # fmt: skip


def rank_by_gradient(sens: dict) -> list[str]:
    """The designs, most sensitive first: a design the mismatch makes lose lock first (by its lost scenarios), then by
    the sensitivity (its worst held rms over the rms at dsat = 0 at the same speed).

    Args:
        sens: name -> :func:`sensitivity`'s dict.

    Returns:
        The names, most sensitive first.
    """

    def key(name: str) -> tuple[int, float]:
        s = sens[name]
        return (-len(s["lost_by_mismatch"]), -s["sensitivity_deg"] if math.isfinite(s["sensitivity_deg"]) else 0.0)

    return sorted(sens, key=key)
