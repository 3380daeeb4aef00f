"""The export itself: :func:`export_observer` generates the C of an observer's step
(:mod:`jaxobs_tuning.export.codegen`), checks it in Python, computes its golden vectors
(:mod:`jaxobs_tuning.export.golden`) and writes the five files."""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jaxobs import DriveInput
from jaxobs.observers.base import AbstractDriveObserver, AbstractObserver
from jaxobs.runtime.progress import Progress

from ..outdir import atomic_path, atomic_write_text
from .codegen import CStep, gain_macro, generate, is_angle, leaf_name, reference, rule_doc, statics, write_c
from .golden import (
    MAX_STEPS,
    MIN_STEPS,
    assumed_machine,
    drive_recording,
    drive_test_signal,
    fll_test_signal,
    float32_observer,
    golden_outputs,
    is_drive,
    observer_rule,
    record_start,
    signal_frequency_hz,
    signal_speed,
    zero_input,
)
from .harness import TOLERANCE, harness_text

EXPORT_FILES = ("observer.h", "observer.c", "test_main.c", "golden.csv", "coefficients.json")


def export_observer(
    observer: AbstractObserver,
    out_dir: str | os.PathLike[str],
    *,
    n_steps: int = 12_000,
    signal: ArrayLike | str | None = None,
    source: str = "",
    notes: Sequence[str] = (),
    progress: bool | str | Callable[[int, int | None], object] | None = None,
    record_drive: dict | None = None,
) -> dict:
    """Write ``observer`` as C99 float32 with its golden vectors into ``out_dir``; returns coefficients.json's content.

    Args:
        observer: any observer that follows the step contract (jaxobs.observers.base), a user's own
            included: the C is generated from the jaxpr of its ``step``; its gains are rounded to
            float32, as the C holds them.  A drive observer reads (u_a, u_b, i_a, i_b) per step, any
            other one sample ``v``.
        out_dir: folder for observer.h, observer.c, test_main.c, golden.csv, coefficients.json.
        n_steps: length of the default test signal (:func:`fll_test_signal` for a signal-level
            observer, :func:`drive_recording` for drive observers), >= 10 000.
        signal: instead of the default, the inputs per step, shape (n,) or (n, JX_NU) (drive
            observers: columns u_a, u_b, i_a, i_b, e.g. :func:`drive_recording` at another speed),
            or ``"synthetic"`` for a drive observer: :func:`drive_test_signal` on the observer's
            own Rs and L.  The default recording runs on its bench (:func:`jaxobs.drive.bench_machine`): export the
            observer bound to it (``observer.bind``) to get that machine's Rs and L in the C.
        source: where the design comes from (a result file, a closed form), for the header.
        record_drive: the drive a drive observer's default recording runs on instead of its bench:
            :func:`drive_recording`'s ``machine``, ``rpm``, ``drive`` and ``label`` (a drive file's).
        notes: lines recorded in the header and coefficients.json (e.g. defaults used).
        progress: its three stages (C generated, the test record, the golden vectors), each named as
            it runs (:mod:`jaxobs.runtime.progress`: ``True`` a tqdm bar on stderr, or a callable).

    Returns:
        coefficients.json's content.

    Raises:
        ValueError: A step the export cannot write (a primitive without C, a torque-reading speed
            estimator), a bad ``n_steps`` or ``signal``, or non-finite golden outputs.
    """
    notes = list(notes)
    bar = Progress(progress, 3, "export", unit="stage")
    bar.stage("generating the C from the jaxpr of the step")
    obs32 = float32_observer(observer)
    kind = "drive" if is_drive(obs32) else "signal"
    state0, step = _generate_checked(obs32, kind)
    component = type(obs32).__name__
    header, source_c = write_c(obs32, step, kind, source or f"{component} as given", notes, observer_rule(obs32))
    bar.update()
    bar.stage("the test record" + (" (compiling and running the sensored drive)" if kind == "drive" else ""))
    u, signal_doc = _test_record(observer, obs32, len(step.input_names), n_steps, signal, record_drive)
    bar.update()
    bar.stage(f"golden vectors: the float32 JAX step over {u.shape[0]} samples (compiling)")
    y = golden_outputs(obs32, state0, step, u)
    bar.update()
    bar.close()
    if not np.all(np.isfinite(y)):
        raise ValueError(
            f"export: the JAX step of {component} gave non-finite outputs on the test signal "
            "(an unstable design?): no golden vectors written"
        )

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    # each file to a temp file, then renamed (jaxobs_tuning.outdir): a symlink there is replaced, never followed
    atomic_write_text(out / "observer.h", header)
    atomic_write_text(out / "observer.c", source_c)
    atomic_write_text(out / "test_main.c", harness_text())
    columns = step.input_names + step.output_names
    with atomic_path(out / "golden.csv") as tmp:
        np.savetxt(
            tmp, np.concatenate([u, y], axis=1), fmt="%.9g", delimiter=",", header=",".join(columns), comments=""
        )
    coeffs = _coefficients(observer, obs32, step, kind, source, notes)
    coeffs["golden"] = {
        "steps": int(u.shape[0]),
        "signal": signal_doc,
        "columns": columns,
        "tolerance": TOLERANCE,
        "error": "max |y_C - y_golden| / (1 + |y_golden|), angles modulo 2 pi",
    }
    atomic_write_text(out / "coefficients.json", json.dumps(coeffs, indent=1, ensure_ascii=False) + "\n")
    return coeffs


def _generate_checked(obs32: AbstractObserver, kind: str) -> tuple[Any, CStep]:
    """The float32 observer's initial state and its step generated as C, checked in Python (:func:`_self_check`).

    Raises:
        ValueError: A speed estimator that reads the torque reference, which the C step does not take.
    """
    if isinstance(obs32, AbstractDriveObserver) and obs32.reads_torque:  # kind "drive"
        raise ValueError(
            "export: a mechanical-model speed estimator (jaxobs.observers.speed.MechanicalSpeed) needs the torque "
            "reference each period, which the exported step does not take; export the observer with its PLL"
        )
    # the four measurements (u_a, u_b, i_a, i_b): DriveInput's T_ref is None here, no input of the C step
    names = list(DriveInput._fields[:4])
    with jax.enable_x64(False):
        u0 = zero_input(obs32)
        state0 = obs32.init(u0)
        step = generate(obs32, state0, u0, input_names=names if kind == "drive" else ["v"])
    _self_check(obs32, step, state0)
    return state0, step


def _test_record(
    observer: AbstractObserver,
    obs32: AbstractObserver,
    nu: int,
    n_steps: int,
    signal: ArrayLike | str | None,
    record_drive: dict | None,
) -> tuple[np.ndarray, str]:
    """The inputs per step the golden vectors are computed on (:func:`export_observer`'s ``signal``), and their
    description.

    Raises:
        ValueError: A bad ``n_steps`` or ``signal``.
    """
    drive = isinstance(obs32, AbstractDriveObserver)
    if signal is None or (isinstance(signal, str) and signal == "synthetic" and drive):
        if not (isinstance(n_steps, int) and n_steps >= MIN_STEPS):
            raise ValueError(f"export: n_steps must be an integer >= {MIN_STEPS}, got {n_steps!r}")
        if n_steps > MAX_STEPS:  # a bound on the work and on golden.csv's size
            raise ValueError(f"export: n_steps must be <= {MAX_STEPS}, got {n_steps}")
    if signal is None and not drive:
        f0 = signal_frequency_hz(obs32)  # an FLL's nominal frequency, else 50 Hz
        u, signal_doc = fll_test_signal(obs32.ts, n_steps, f0)
    elif signal is None:
        drive_obs = cast(AbstractDriveObserver, observer)  # obs32's class
        u, signal_doc = drive_recording(drive_obs, n_steps, start=record_start(obs32), **(record_drive or {}))
    elif isinstance(signal, str) and signal == "synthetic" and isinstance(obs32, AbstractDriveObserver):
        rs, ls = assumed_machine(obs32)
        u, signal_doc = drive_test_signal(
            obs32.ts, n_steps, omega=signal_speed(obs32), Rs=rs, L=ls, start=record_start(obs32)
        )
    elif isinstance(signal, str):
        raise ValueError(f"export: signal must be an array (or 'synthetic' for a drive observer), got {signal!r}")
    else:
        u = np.asarray(signal, np.float32)
        u = u[:, None] if u.ndim == 1 else u
        if u.ndim != 2 or u.shape[1] != nu or u.shape[0] < 1 or not np.all(np.isfinite(u)):
            raise ValueError(f"export: signal must be finite, shape (n,) or (n, {nu}), got shape {np.shape(signal)}")
        signal_doc = f"user signal, {u.shape[0]} steps"
    return u, signal_doc


# the step convention per kind of observer, as coefficients.json states it
_STEP_DOC = {
    "signal": "jx_step returns the outputs of the state before the sample is integrated (signal-level observer)",
    "drive": "jx_step integrates the period that just ended and returns the outputs after it (drive "
    "observer); the first call only records u and i",
}


def _coefficients(
    observer: AbstractObserver, obs32: AbstractObserver, step: CStep, kind: str, source: str, notes: list[str]
) -> dict:
    """coefficients.json's content but its "golden" entry: the design, gains (float32 and as given), state,
    inputs, outputs and operation counts."""
    component = type(obs32).__name__
    gains = {}
    for g in step.gains:
        for i, v in enumerate(g.value.flat):
            key = g.name if g.shape == () else f"{g.name}_{i}"
            given = np.asarray(_leaf_at(observer, g.name)).flat[i]
            gains[key] = {
                "c_name": gain_macro(g, None if g.shape == () else i),
                "value": float(v),
                "given": float(given),
            }
    state = [
        {"name": n, "c": f"s->{leaf.name}" + ("" if leaf.shape == () else f"[{i}]"), "initial": v.item()}
        for leaf in step.state
        for i, (n, v) in enumerate(zip(leaf.scalars(), np.asarray(leaf.value).flat))
    ]
    ops = {"steady": step.ops_steady}
    if step.has_branch:
        ops["worst"] = step.ops_worst
    return {
        "component": component,
        "reference": reference(obs32),
        "design": source or f"{component} as given",
        "notes": notes,
        "dtype": "float32",
        "ts": obs32.ts,
        "rule": rule_doc(observer_rule(obs32)),
        "step": _STEP_DOC[kind],
        "gains": gains,
        "static": statics(obs32),
        "state": state,
        "inputs": step.input_names,
        "outputs": step.output_names,
        "angle_outputs": [n for n in step.output_names if is_angle(n)],
        "ops_per_step": ops,
    }


@eqx.filter_jit
def _one_step(observer, state, u):
    return observer.step(state, u)


def _self_check(obs32, step: CStep, state0, n_points: int = 8):
    """The emitted statements, run in Python on float32 numpy scalars, against the JAX step at random states
    and inputs (floats around the initial state, flags and counters through a few values): a code
    generator bug fails here, with or without a C compiler, and before anything is written."""
    rng = np.random.default_rng(0)
    leaves, tree = jax.tree.flatten(state0)
    n_in = len(step.input_names)
    for k in range(n_points):
        state = []
        for leaf in leaves:
            a = np.asarray(leaf)
            if a.dtype == np.bool_:
                a = np.full(a.shape, k % 2 == 1)
            elif a.dtype.kind in "iu":
                a = np.full(a.shape, k % 3, a.dtype)
            else:
                a = (a + rng.normal(size=a.shape) * np.maximum(1.0, 0.1 * np.abs(a))).astype(a.dtype)
            state.append(a)
        u = (rng.normal(size=n_in) * 10.0).astype(np.float32)
        with jax.enable_x64(False):
            uj = DriveInput(*(jnp.float32(v) for v in u)) if is_drive(obs32) else jnp.float32(u[0])
            new, out = _one_step(obs32, jax.tree.unflatten(tree, [jnp.asarray(a) for a in state]), uj)
        got_state, got_y = step.run(state, u)
        want = [np.asarray(a, np.float64).reshape(-1) for a in [*jax.tree.leaves(new), *jax.tree.leaves(out)]]
        got = [np.asarray(a, np.float64).reshape(-1) for a in [*got_state, got_y]]
        names = [n for leaf in step.state for n in leaf.scalars()] + step.output_names
        want, got = np.concatenate(want), np.concatenate(got)
        bad = ~(np.abs(got - want) <= 1e-4 * (1 + np.abs(want)))
        if np.any(bad):
            i = int(np.argmax(bad))
            raise AssertionError(
                f"export: the generated C of {type(obs32).__name__} differs from the JAX step at {names[i]}: "
                f"{got[i]!r} vs {want[i]!r} (a code generator bug; nothing written)"
            )


def _leaf_at(observer, name: str):
    """The observer's array leaf whose path name (codegen.leaf_name) is ``name``."""
    params, _ = eqx.partition(observer, eqx.is_array)
    for path, leaf in jax.tree_util.tree_flatten_with_path(params)[0]:
        if leaf_name(path) == name:
            return leaf
    raise KeyError(name)
