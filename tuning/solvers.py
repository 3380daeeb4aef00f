"""Solvers: optax loops (with early stopping and checkpoints) and optimistix BFGS.

The optax loop is a Python loop over *iterations* (each one a compiled
value-and-gradient of the whole scenario batch), so that it can report
progress, stop early and checkpoint.  A checkpoint holds θ, the optimizer
state, the best point so far and the history, all as float64 arrays: resuming
from it replays exactly the computation an uninterrupted run would have done.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax
import optimistix as optx

__all__ = ["SolverConfig", "TuneResult", "run_solver", "make_optax"]


@dataclass(frozen=True)
class SolverConfig:
    kind: str = "adam"  # adam | adamw | sgd | bfgs
    learning_rate: float = 0.05
    steps: int = 100
    patience: int = 25  # early stop after this many iterations without relative improvement > tol
    tol: float = 1e-6
    schedule: str = "constant"  # constant | cosine
    checkpoint_every: int = 5
    progress_every: int = 1


@dataclass
class TuneResult:
    theta: jax.Array
    value: float
    iterations: int
    history: list = field(default_factory=list)
    stopped: str = ""


def make_optax(cfg: SolverConfig):
    lr = cfg.learning_rate
    if cfg.schedule == "cosine":
        lr = optax.cosine_decay_schedule(cfg.learning_rate, max(cfg.steps, 1))
    if cfg.kind == "adam":
        return optax.adam(lr)
    if cfg.kind == "adamw":
        return optax.adamw(lr)
    if cfg.kind == "sgd":
        return optax.sgd(lr)
    raise ValueError(f"solver.kind must be one of adam, adamw, sgd, bfgs, got {cfg.kind!r}")


def _progress(i, total, value, best, stream=sys.stderr):
    width = 24
    done = int(width * min(i, total) / max(total, 1))
    stream.write(f"tune [{'#' * done}{'.' * (width - done)}] {i:>4}/{total} objective {value:.6g} best {best:.6g}\n")
    stream.flush()


def _save_checkpoint(path: Path, it, theta, opt_state, best_theta, best_value, history, since_best):
    leaves = jax.tree.leaves(opt_state)
    tmp = path.with_suffix(".tmp.npz")
    arrays = {f"arr_{i}": np.asarray(x) for i, x in enumerate(leaves)}  # np.savez's names for positional arrays
    np.savez(tmp, theta=np.asarray(theta), best_theta=np.asarray(best_theta), **arrays)
    os.replace(tmp, path)
    meta = dict(iteration=it, best_value=best_value, since_best=since_best, history=history, n_leaves=len(leaves))
    tmpj = path.with_suffix(".tmp.json")
    tmpj.write_text(json.dumps(meta))
    os.replace(tmpj, path.with_suffix(".json"))


def _load_checkpoint(path: Path, opt_state_template):
    meta = json.loads(path.with_suffix(".json").read_text())
    data = np.load(path)
    leaves = [jnp.asarray(data[f"arr_{i}"]) for i in range(meta["n_leaves"])]
    treedef = jax.tree.structure(opt_state_template)
    opt_state = jax.tree.unflatten(treedef, leaves)
    return meta, jnp.asarray(data["theta"]), jnp.asarray(data["best_theta"]), opt_state


def run_solver(
    objective, theta0, cfg: SolverConfig, checkpoint: Path | None = None, resume: bool = False, quiet: bool = False
) -> TuneResult:
    """Minimize ``objective`` from θ0 with the configured solver."""
    t_start = time.time()
    if cfg.kind == "bfgs":
        fn = lambda th, _: objective.value(th)  # noqa: E731
        sol = optx.minimise(fn, optx.BFGS(rtol=cfg.tol, atol=cfg.tol), theta0, max_steps=cfg.steps, throw=False)
        value = float(objective.value(sol.value))
        steps = int(sol.stats.get("num_steps", cfg.steps))
        return TuneResult(
            theta=sol.value,
            value=value,
            iterations=steps,
            history=[dict(iteration=steps, value=value, time_s=time.time() - t_start)],
            stopped=str(sol.result),
        )

    opt = make_optax(cfg)
    theta = theta0
    opt_state = opt.init(theta)
    best_theta, best_value, since_best, history, start = theta, math.inf, 0, [], 0
    if resume and checkpoint is not None and checkpoint.exists():
        meta, theta, best_theta, opt_state = _load_checkpoint(checkpoint, opt_state)
        start, best_value, since_best, history = (
            meta["iteration"],
            meta["best_value"],
            meta["since_best"],
            meta["history"],
        )

    @jax.jit
    def update(theta, opt_state, grad):
        updates, opt_state = opt.update(grad, opt_state, theta)
        return optax.apply_updates(theta, updates), opt_state

    stopped = "budget"
    it = start
    for it in range(start, cfg.steps):
        value, grad = objective.value_and_grad(theta)
        value = float(value)
        history.append(dict(iteration=it, value=value, time_s=time.time() - t_start))
        improved = (not math.isfinite(best_value)) or value < best_value - cfg.tol * abs(best_value)
        if improved:
            best_value, best_theta, since_best = value, theta, 0
        else:
            since_best += 1
        if not quiet and (it % cfg.progress_every == 0 or it == cfg.steps - 1):
            _progress(it + 1, cfg.steps, value, best_value)
        if since_best >= cfg.patience:
            stopped = "early stop"
            it += 1
            break
        theta, opt_state = update(theta, opt_state, grad)
        if checkpoint is not None and (it + 1) % cfg.checkpoint_every == 0:
            _save_checkpoint(checkpoint, it + 1, theta, opt_state, best_theta, best_value, history, since_best)
    else:
        it = cfg.steps
    # the last update is scored too: keep whichever point is best
    value = float(objective.value(theta))
    if value < best_value:
        best_value, best_theta = value, theta
    return TuneResult(theta=best_theta, value=best_value, iterations=it, history=history, stopped=stopped)
