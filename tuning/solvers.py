"""Solvers: optax loops (with early stopping and checkpoints) and optimistix minimisers, as objects.

``tune(objective, optimizer, scenarios=batch)`` minimises an :class:`~jaxobs_tuning.base.AbstractObjective` on a
scenario batch (an argument of every evaluation, never held by the objective).  It takes an optax
``GradientTransformation`` (``optax.adam(0.1)``), an optimistix minimiser (``optx.BFGS(rtol, atol)``) or a
solver object that holds one with its stopping rule (:class:`OptaxSolver`, :class:`OptimistixSolver`); each
solver runs its own loop (``solver.run``).
A TOML job names its optimizer and schedule, and :mod:`jaxobs_tuning.strategies` maps the names to these objects.

The optax loop is a Python loop over *iterations* (each one a compiled
value-and-gradient of the whole scenario batch), so that it can report
progress, stop early and checkpoint.  A checkpoint holds θ, the optimizer
state, the best point so far and the history, all as float64 arrays: resuming
from it replays exactly the computation an uninterrupted run would have done.
"""

from __future__ import annotations

import abc
import io
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
import optimistix as optx

from jaxobs.io.provenance import read_file
from jaxobs.runtime.progress import Progress

from .base import AbstractObjective
from .checkpoint import DIGEST, MAX_CHECKPOINT_BYTES, check_state, content_digest
from .minimisers import best_iterate, evaluations, gradient_free, minimiser_reason
from .outdir import atomic_write_bytes

__all__ = [
    "AbstractSolver",
    "OptaxSolver",
    "OptimistixSolver",
    "as_solver",
    "tune",
    "CheckpointError",
    "TuneResult",
    "decide_status",
    "STATUSES",
]


@dataclass
class TuneResult:
    """What a solver found.

    Attributes:
        theta: The best design that diverged in no tuning scenario (``None`` when no design tried was stable:
            ``status == "diverged"``, or when the objective overflowed: ``"overflow"``).
        value: Its objective.
        iterations: The iterations run.
        history: One entry per point evaluated (iteration, objective, diverged scenarios, gains).
        status: One of ``converged | budget | no_improvement | diverged | overflow``.
        reason: Why, in words.
        best_iteration: The iteration of the best design, or None.
        timing: ``{"solver_s": seconds}``.
    """

    theta: jax.Array | None
    value: float
    iterations: int
    history: list = field(default_factory=list)
    status: str = ""
    reason: str = ""
    best_iteration: int | None = None
    timing: dict = field(default_factory=dict)

    @property
    def stopped(self) -> str:
        """An alias of ``status``."""
        return self.status


STATUSES = ("converged", "budget", "no_improvement", "diverged", "overflow")


def _entry(objective, it, value, diverged, theta) -> dict:
    return dict(iteration=int(it), value=float(value), diverged=int(diverged), gains=objective.param.values(theta))


def decide_status(
    history: list, finished: bool, tol: float, finished_reason: str, budget_reason: str, best: int | None = None
) -> tuple[str, str, int | None]:
    """The status of a run from its history.

    The best design is the least objective among the points that diverged in no scenario; none:
    ``diverged``; the initial point best (no relative improvement > ``tol``): ``no_improvement``; else
    ``converged`` if the solver ``finished`` by its own test, ``budget`` if it ran out of steps.

    Args:
        history: The run's entries (iteration, objective, diverged scenarios, gains).
        finished: Whether the solver stopped by its own test.
        tol: The relative improvement that counts.
        finished_reason: The reason given for ``converged``.
        budget_reason: The reason given for ``budget``.
        best: The solver's own choice of best stable entry.

    Returns:
        ``(status, reason, best entry index)``.
    """
    stable = [i for i, h in enumerate(history) if h["diverged"] == 0]
    n_div = sum(1 for h in history if h["diverged"] > 0)
    if not stable:
        worst = min(h["diverged"] for h in history) if history else 0
        return (
            "diverged",
            f"every design tried ({len(history)}) diverged in at least {worst} tuning scenario(s): nothing is tuned",
            None,
        )
    if best is None or history[best]["diverged"]:
        best = min(stable, key=lambda i: (history[i]["value"], i))
    h0 = history[0]
    note = f"; {n_div} of {len(history)} designs tried diverged and were never candidates" if n_div else ""
    if h0["diverged"] == 0 and (best == 0 or history[best]["value"] >= h0["value"] - tol * abs(h0["value"])):
        return "no_improvement", f"no design improved on the initial one{note}", best
    if finished:
        return "converged", finished_reason + note, best
    return "budget", budget_reason + note, best


def _bar(solver: AbstractSolver, quiet: bool) -> Progress:
    """The solver's tqdm bar on stderr when it is a terminal (none when ``quiet``), announcing the first
    compilation."""
    bar = Progress("auto" if not quiet else False, solver.steps, f"tune ({solver.name})", unit="step")
    bar.stage("compiling the objective and its gradient (once; tens of seconds for a drive)")
    return bar


def _evaluate(objective: AbstractObjective, theta, scenarios, plain: bool = False):
    """(value, gradient, diverged, overflowed) at ``theta`` on ``scenarios``; ``plain``: without the derivative
    (a gradient-free minimiser's: no gradient, nothing overflows)."""
    if plain:
        value, ndiv = objective.plain_value_diverged(theta, scenarios)
        return value, None, ndiv, 0
    return objective.value_grad_diverged_overflowed(theta, scenarios)


def _overflow_result(history: list, it: int, n_over: int, seconds: float) -> TuneResult:
    """The outcome of a run whose objective overflowed at iteration ``it``: status ``overflow``, nothing tuned
    (checked at every iteration; the run stops there, and no other outcome replaces it)."""
    return TuneResult(
        theta=None,
        value=math.nan,
        iterations=it,
        history=history,
        status="overflow",
        reason=(
            f"the objective overflows at iteration {it}: its value or gradient is not finite in {n_over} "
            "scenarios whose simulation is finite"
        ),
        best_iteration=None,
        timing=dict(solver_s=seconds),
    )


def _show(bar: Progress, i: int, solver: AbstractSolver, value, best, diverged, first: bool) -> None:
    """One iteration done; the objective, the best stable value and the diverged scenarios every
    ``solver.progress_every`` iterations."""
    post: dict[str, str | int] = {}
    if i % solver.progress_every == 0 or i == solver.steps:
        post = dict(objective=f"{value:.6g}", best=f"{best:.6g}")
        if diverged:
            post["diverged"] = int(diverged)
    if first:  # compiled: the description returns to the solver's name
        bar.stage("")
    bar.update(1, **post)


class CheckpointError(ValueError):
    """A checkpoint that ``--resume`` cannot use (corrupt, or another job's); ``str()`` is one line."""


_replace = os.replace  # the rename that publishes a checkpoint (a test kills runs here)

# Testing hook: when set, OptaxSolver.run calls it with the iteration's number before each iteration (before
# its evaluation).  The test suite sets it to raise KeyboardInterrupt at iteration i, as a Ctrl-C at that point
# would, to stop runs at chosen iterations without timing a signal (tests/test_interrupt.py).
_at_iteration = None


def _save_checkpoint(path: Path, it, theta, opt_state, best_theta, best_value, history, since_best, fingerprint):
    """One file, written to a temp file and renamed: θ, the optimizer state, the best point, and the
    metadata (iteration, history, the job's fingerprint) as a JSON string inside the same npz, and the
    sha256 of all of it (:mod:`jaxobs_tuning.checkpoint`).  ``best_value`` is null until a stable design is found."""
    leaves = jax.tree.leaves(opt_state)
    arrays = {f"arr_{i}": np.asarray(x) for i, x in enumerate(leaves)}  # np.savez's names for positional arrays
    meta = dict(
        format=CHECKPOINT_FORMAT,
        job_sha256=fingerprint,
        iteration=it,
        best_value=best_value if math.isfinite(best_value) else None,  # strict JSON: no Infinity
        since_best=since_best,
        history=history,
        n_leaves=len(leaves),
    )
    entries: dict[str, Any] = dict(  # Any: np.savez's stub types its keywords as its options (allow_pickle)
        meta=np.asarray(json.dumps(meta, allow_nan=False)),
        theta=np.asarray(theta),
        best_theta=np.asarray(best_theta),
        **arrays,
    )
    buf = io.BytesIO()
    stored: dict[str, Any] = {**entries, DIGEST: np.asarray(content_digest(entries))}  # Any: as entries
    np.savez(buf, **stored)
    # a random, O_EXCL|O_NOFOLLOW temp name beside the checkpoint, renamed by _replace (looked up now: tests
    # patch it to kill a run between the write and the rename)
    atomic_write_bytes(path, buf.getvalue(), replace=_replace)


CHECKPOINT_FORMAT = "jaxobs-checkpoint-2"  # 2: a content digest, best_value null (not Infinity) before a best


def _load_checkpoint(path: Path, opt_state_template, fingerprint: str | None, theta_shape=None):
    """(meta, θ, best θ, optimizer state) of a checkpoint, or a one-line :class:`CheckpointError`.

    Read as a regular file of at most :data:`~jaxobs_tuning.checkpoint.MAX_CHECKPOINT_BYTES` (a FIFO cannot block
    the run).  The content digest is checked first, then the job's fingerprint, before any array is
    interpreted: another job's checkpoint (other gains, so other array shapes) is reported as "belongs to
    another job", never as a corrupt file.  Then the state itself (:func:`jaxobs_tuning.checkpoint.check_state`:
    finite θ and best θ of ``theta_shape``, a history as long as the iteration, ...)."""

    def corrupt(e):
        return CheckpointError(
            f"--resume: checkpoint {str(path)!r} is corrupt or unreadable ({type(e).__name__}: {str(e)[:80]}); "
            "delete it or run without --resume and with --force"
        )

    try:
        raw = read_file(path, MAX_CHECKPOINT_BYTES)
    except ValueError as e:  # missing between the test and the read, a FIFO, a device, too large
        raise CheckpointError(f"--resume: checkpoint {e}; delete it or run without --resume and with --force") from None
    try:
        data = np.load(io.BytesIO(raw), allow_pickle=False)
    except Exception as e:  # a torn, truncated, foreign or special file: one line, never a traceback
        raise corrupt(e) from None
    with data:
        try:
            # a deflated npz could expand far beyond the file: the entries' sizes are read before their bytes
            if sum(i.file_size for i in data.zip.infolist()) > MAX_CHECKPOINT_BYTES:
                raise ValueError(f"its arrays hold more than {MAX_CHECKPOINT_BYTES} bytes")
            entries = {k: data[k] for k in data.files}
            if DIGEST not in entries or str(entries[DIGEST]) != content_digest(entries):
                raise ValueError("its content digest does not match (edited or damaged)")
            meta = json.loads(str(entries["meta"]), parse_constant=_no_constant)
            if not isinstance(meta, dict) or meta.get("format") != CHECKPOINT_FORMAT:
                raise ValueError(f"not a {CHECKPOINT_FORMAT} checkpoint")
        except Exception as e:
            raise corrupt(e) from None
        if fingerprint is not None and meta.get("job_sha256") != fingerprint:
            got = str(meta.get("job_sha256"))[:12]
            raise CheckpointError(
                f"--resume: checkpoint {str(path)!r} belongs to another job "
                f"(sha256 {got}…, this job {fingerprint[:12]}…)"
            )
        try:
            leaves = [jnp.asarray(data[f"arr_{i}"]) for i in range(int(meta["n_leaves"]))]
            theta, best_theta = jnp.asarray(data["theta"]), jnp.asarray(data["best_theta"])
            for key in ("iteration", "best_value", "since_best", "history"):
                meta[key]  # noqa: B018 - present, or KeyError
            treedef = jax.tree.structure(opt_state_template)
            opt_state = jax.tree.unflatten(treedef, leaves)
            shapes = [np.shape(x) for x in jax.tree.leaves(opt_state_template)]
            if [tuple(x.shape) for x in leaves] != [tuple(s) for s in shapes] or theta.shape != best_theta.shape:
                raise ValueError("array shapes differ from the job's")
            check_state(meta, theta, best_theta, leaves, theta.shape if theta_shape is None else theta_shape)
        except Exception as e:
            raise corrupt(e) from None
    meta["best_value"] = math.inf if meta["best_value"] is None else meta["best_value"]
    return meta, theta, best_theta, opt_state


def _no_constant(name: str):
    raise ValueError(f"{name} is not JSON")


class AbstractSolver(abc.ABC):
    """A tuning run's optimizer with its stopping rule; ``run`` owns the loop.

    Every solver records one history entry per point it evaluates and picks its best design with
    :func:`decide_status` (the least objective among the designs that diverged in no scenario).
    Attributes:
        name: Shown in progress and reports.
        steps: The iteration budget.
        tol: The relative improvement that counts.
        progress_every: Iterations between progress figures.
    """

    name: str
    steps: int
    tol: float
    progress_every: int

    @abc.abstractmethod
    def run(
        self,
        objective: AbstractObjective,
        theta0: jax.Array,
        *,
        scenarios: Any = None,
        checkpoint: Path | None = None,
        resume: bool = False,
        quiet: bool = False,
        fingerprint: str | None = None,
    ) -> TuneResult:
        """Minimise ``objective`` from θ0.

        Args:
            objective: The :class:`~jaxobs_tuning.base.AbstractObjective` (``value_grad_diverged_overflowed(θ,
                scenarios)``, ``param``).
            theta0: The initial θ.
            scenarios: The batch every evaluation takes (None: an objective without data).
            checkpoint: One npz file, rewritten atomically every ``checkpoint_every`` iterations, holding
                ``fingerprint``.
            resume: Continue from ``checkpoint``; a checkpoint of another job, or a corrupt one, raises
                :class:`CheckpointError` (one line); no checkpoint at all: one line on stderr and a fresh start.
            quiet: No progress lines.
            fingerprint: The job's sha256, kept in the checkpoint.

        Returns:
            The :class:`TuneResult`.
        """


def _check_budget(owner: str, steps, tol, progress_every) -> None:
    for fld, v in (("steps", steps), ("progress_every", progress_every)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise ValueError(f"{owner}.{fld} must be an integer >= 1, got {v!r}")
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0 <= tol < math.inf:
        raise ValueError(f"{owner}.tol must be a finite number >= 0, got {tol!r}")


@dataclass(frozen=True)
class OptaxSolver(AbstractSolver):
    """An optax ``GradientTransformation`` run as a Python loop over iterations, each a compiled
    value-and-gradient of the whole batch, with early stopping and checkpoints.

    Attributes:
        optimizer: The optax ``GradientTransformation``.
        steps: The iteration budget (≥ 1).
        patience: Stop after this many iterations without a relative improvement > ``tol`` (≥ 1).
        tol: The relative improvement that counts.
        checkpoint_every: Iterations between checkpoints, when :meth:`run` is given a file (≥ 1).
        progress_every: Iterations between progress figures.
        name: Shown in progress and reports.
    """

    optimizer: optax.GradientTransformation
    steps: int = 100
    patience: int = 25
    tol: float = 1e-6
    checkpoint_every: int = 5
    progress_every: int = 1
    name: str = "optax"

    def __post_init__(self):
        if not isinstance(self.optimizer, optax.GradientTransformation):
            raise ValueError(f"OptaxSolver.optimizer must be an optax GradientTransformation, got {self.optimizer!r}")
        _check_budget("OptaxSolver", self.steps, self.tol, self.progress_every)
        for fld in ("patience", "checkpoint_every"):
            v = getattr(self, fld)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"OptaxSolver.{fld} must be an integer >= 1, got {v!r}")

    def run(
        self,
        objective: AbstractObjective,
        theta0: jax.Array,
        *,
        scenarios: Any = None,
        checkpoint: Path | None = None,
        resume: bool = False,
        quiet: bool = False,
        fingerprint: str | None = None,
    ) -> TuneResult:
        """Minimise ``objective`` from θ0, with checkpoints.

        Testing hook: the module's ``_at_iteration``, when set, is called with each iteration's number before
        that iteration; what it raises ends the run there.

        Args:
            objective: The :class:`~jaxobs_tuning.base.AbstractObjective` (``value_grad_diverged_overflowed(θ,
                scenarios)``, ``param``).
            theta0: The initial θ.
            scenarios: The batch every evaluation takes (None: an objective without data).
            checkpoint: One npz file, rewritten atomically every ``checkpoint_every`` iterations, holding
                ``fingerprint``.
            resume: Continue from ``checkpoint``; a checkpoint of another job, or a corrupt one, raises
                :class:`CheckpointError` (one line); no checkpoint at all: one line on stderr and a fresh start.
            quiet: No progress lines.
            fingerprint: The job's sha256, kept in the checkpoint.

        Returns:
            The :class:`TuneResult`.

        Raises:
            CheckpointError: ``resume`` with a checkpoint of another job, or a corrupt one.
        """
        t_start = time.time()
        opt = self.optimizer
        theta = theta0
        opt_state = opt.init(theta)
        best_theta, best_value, since_best, history, start = theta, math.inf, 0, [], 0
        if resume and checkpoint is not None and not checkpoint.exists():
            print(f"jaxobs: --resume: no checkpoint {str(checkpoint)!r}: starting fresh", file=sys.stderr, flush=True)
        elif resume and checkpoint is not None:
            meta, theta, best_theta, opt_state = _load_checkpoint(checkpoint, opt_state, fingerprint, np.shape(theta0))
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

        early = False
        it = start
        bar = _bar(self, quiet)
        if start:
            bar.update(start)
        overflow = None  # (iteration, scenarios) where the objective overflowed: the run stops, nothing tuned
        for it in range(start, self.steps):
            if _at_iteration is not None:
                _at_iteration(it)
            value, grad, ndiv, nover = _evaluate(objective, theta, scenarios)
            value = float(value)
            history.append(_entry(objective, it, value, ndiv, theta))
            if nover:
                overflow = (it, nover)
                break
            # a design that diverges in some scenario is never a candidate, whatever its (penalized) value
            improved = (
                ndiv == 0
                and math.isfinite(value)  # a NaN objective is never a best (it would compare false forever)
                and ((not math.isfinite(best_value)) or value < best_value - self.tol * abs(best_value))
            )
            if improved:
                best_value, best_theta, since_best = value, theta, 0
            else:
                since_best += 1
            _show(bar, it + 1, self, value, best_value, ndiv, it == start)
            if since_best >= self.patience:
                early = True
                it += 1
                break
            theta, opt_state = update(theta, opt_state, grad)
            if checkpoint is not None and (it + 1) % self.checkpoint_every == 0:
                _save_checkpoint(
                    checkpoint, it + 1, theta, opt_state, best_theta, best_value, history, since_best, fingerprint
                )
        else:
            it = self.steps
        bar.close()
        if overflow is not None:
            return _overflow_result(history, *overflow, time.time() - t_start)
        if not early:  # the last update is scored too: keep it if it is stable and better
            value, _, ndiv, nover = _evaluate(objective, theta, scenarios)
            history.append(_entry(objective, it, float(value), ndiv, theta))
            if nover:
                return _overflow_result(history, it, nover, time.time() - t_start)
            if ndiv == 0 and float(value) < best_value:
                best_value, best_theta = float(value), theta
        # the loop's best (first to reach best_value, the early-stop test's choice)
        best_idx = next((i for i, h in enumerate(history) if h["diverged"] == 0 and h["value"] == best_value), None)
        status, reason, best = decide_status(
            history,
            early,
            self.tol,
            f"converged: no relative improvement > {self.tol:g} in {self.patience} iterations",
            f"budget: {self.steps} steps used, still improving",
            best_idx,
        )
        return TuneResult(
            theta=None if best is None else best_theta,
            value=math.nan if best is None else history[best]["value"],
            iterations=it,
            history=history,
            status=status,
            reason=reason,
            best_iteration=None if best is None else history[best]["iteration"],
            timing=dict(solver_s=time.time() - t_start),
        )


@dataclass(frozen=True)
class OptimistixSolver(AbstractSolver):
    """An optimistix minimiser (``optx.BFGS(rtol, atol)``, ...) run step by step (init / step /
    terminate), so that every accepted iterate is recorded and progress is shown; it stops by its own
    test or after ``steps`` steps.  Each recorded iterate is scored once more for its diverged count.
    No checkpoints (a run is short).

    Attributes:
        minimiser: The optimistix minimiser.
        steps: The step budget.
        tol: The relative improvement :func:`decide_status` counts.
        progress_every: Steps between progress figures.
        name: Shown in progress and reports.
    """

    minimiser: optx.AbstractMinimiser
    steps: int = 100
    tol: float = 1e-6
    progress_every: int = 1
    name: str = "optimistix"

    def __post_init__(self):
        if not isinstance(self.minimiser, optx.AbstractMinimiser):
            raise ValueError(f"OptimistixSolver.minimiser must be an optimistix minimiser, got {self.minimiser!r}")
        _check_budget("OptimistixSolver", self.steps, self.tol, self.progress_every)

    def run(
        self,
        objective: AbstractObjective,
        theta0: jax.Array,
        *,
        scenarios: Any = None,
        checkpoint: Path | None = None,
        resume: bool = False,
        quiet: bool = False,
        fingerprint: str | None = None,
    ) -> TuneResult:
        """Minimise ``objective`` from θ0 by the minimiser's own steps (no checkpoints).

        Args:
            objective: The :class:`~jaxobs_tuning.base.AbstractObjective`.
            theta0: The initial θ.
            scenarios: The batch every evaluation takes (None: an objective without data).
            checkpoint: Not used: an optimistix run keeps no checkpoint.
            resume: Not used.
            quiet: No progress lines.
            fingerprint: Not used.

        Returns:
            The :class:`TuneResult`.
        """
        t_start = time.time()
        solver = self.minimiser
        # the objective and its scenarios are optimistix's args: inputs of the compiled step, not its constants;
        # a gradient-free minimiser takes the objective without its derivative (jaxobs_tuning.minimisers)
        free = gradient_free(solver)
        fn = lambda th, args: ((args[0].plain_value if free else args[0].value)(th, args[1]), None)  # noqa: E731
        data = (objective, scenarios)
        tags = frozenset()
        f_struct = jax.ShapeDtypeStruct((), theta0.dtype)
        state = solver.init(fn, theta0, data, {}, f_struct, None, tags)
        step = eqx.filter_jit(lambda y, st, args: solver.step(fn, y, args, {}, st, tags))
        terminate = eqx.filter_jit(lambda y, st, args: solver.terminate(fn, y, args, {}, st, tags))
        y = theta0
        bar = _bar(self, quiet)
        value, _, ndiv, nover = _evaluate(objective, y, scenarios, free)
        history = [_entry(objective, 0, value, ndiv, y)]
        if nover:
            bar.close()
            return _overflow_result(history, 0, nover, time.time() - t_start)
        bar.stage(f"compiling {type(solver).__name__}'s step")
        best_value = float(value) if ndiv == 0 else math.inf
        result, n = optx.RESULTS.nonlinear_max_steps_reached, 0
        for n in range(1, self.steps + 1):
            done, res = terminate(y, state, data)
            if bool(done):
                result, n = res, n - 1
                break
            y_new, state, _ = step(y, state, data)
            y_new = best_iterate(solver, y_new, state)
            if not bool(jnp.all(y_new == y)):  # an accepted step: record the new iterate
                y = y_new
                value, _, ndiv, nover = _evaluate(objective, y, scenarios, free)
                history.append(_entry(objective, n, value, ndiv, y))
                if nover:
                    bar.close()
                    return _overflow_result(history, n, nover, time.time() - t_start)
                if ndiv == 0:
                    best_value = min(best_value, float(value))
            _show(bar, n, self, history[-1]["value"], best_value, history[-1]["diverged"], n == 1)
        else:
            done, res = terminate(y, state, data)
            if bool(done):
                result = res
        bar.close()
        finished, sentence = minimiser_reason(result, type(solver).__name__)
        evals = evaluations(solver, state, int(jnp.size(theta0)))
        sentence += "" if evals is None else f" ({evals} objective evaluations)"
        status, reason, best = decide_status(history, finished, self.tol, sentence, sentence)
        if not finished and status == "converged":  # pragma: no cover - decide_status returns budget then
            status = "budget"
        return TuneResult(
            theta=None if best is None else objective.param.to_theta(history[best]["gains"]),
            value=math.nan if best is None else history[best]["value"],
            iterations=n,
            history=history,
            status=status,
            reason=reason if status != "budget" or "budget" in reason else f"{sentence} ({reason})",
            best_iteration=None if best is None else history[best]["iteration"],
            timing=dict(solver_s=time.time() - t_start, **({} if evals is None else {"evaluations": evals})),
        )


def as_solver(optimizer: AbstractSolver | optax.GradientTransformation | optx.AbstractMinimiser) -> AbstractSolver:
    """A solver object for ``optimizer``.

    Args:
        optimizer: A solver itself, an optax ``GradientTransformation`` (in an :class:`OptaxSolver` with its
            default stopping rule) or an optimistix minimiser (in an :class:`OptimistixSolver`).

    Returns:
        The :class:`AbstractSolver`.

    Raises:
        ValueError: ``optimizer`` is none of these.
    """
    if isinstance(optimizer, AbstractSolver):
        return optimizer
    if isinstance(optimizer, optax.GradientTransformation):
        return OptaxSolver(optimizer)
    if isinstance(optimizer, optx.AbstractMinimiser):
        return OptimistixSolver(optimizer)
    raise ValueError(
        "tune: optimizer must be an optax GradientTransformation (optax.adam(0.1)), an optimistix minimiser "
        f"(optimistix.BFGS(rtol=1e-6, atol=1e-6)) or a solver (OptaxSolver, OptimistixSolver), got {optimizer!r}"
    )


def tune(
    objective: AbstractObjective,
    optimizer: AbstractSolver | optax.GradientTransformation | optx.AbstractMinimiser,
    theta0: jax.Array | None = None,
    *,
    scenarios: Any = None,
    checkpoint: Path | None = None,
    resume: bool = False,
    quiet: bool = False,
    fingerprint: str | None = None,
) -> TuneResult:
    """Minimise ``objective`` with ``optimizer``; the best design is the best one that diverged in no scenario
    (:func:`decide_status`).

    Args:
        objective: The :class:`~jaxobs_tuning.base.AbstractObjective` (a
            :class:`~jaxobs_tuning.objective.Objective`).
        optimizer: A solver, an optax ``GradientTransformation`` or an optimistix minimiser (:func:`as_solver`).
        theta0: The initial θ (default ``objective.param.theta0()``).
        scenarios: The batch every evaluation takes (None: an objective without data).
        checkpoint: See :meth:`OptaxSolver.run`.
        resume: See :meth:`OptaxSolver.run`.
        quiet: No progress lines.
        fingerprint: See :meth:`OptaxSolver.run`.

    Returns:
        The :class:`TuneResult`.
    """
    if not isinstance(objective, AbstractObjective):
        raise ValueError(
            f"tune: objective must be a jaxobs_tuning.AbstractObjective (an Objective), got {type(objective).__name__}"
        )
    solver = as_solver(optimizer)
    start = objective.param.theta0() if theta0 is None else theta0
    return solver.run(
        objective,
        start,
        scenarios=scenarios,
        checkpoint=checkpoint,
        resume=resume,
        quiet=quiet,
        fingerprint=fingerprint,
    )
