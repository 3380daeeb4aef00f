"""The baselines on the workloads: parameters and inputs from :mod:`benchmarks.workloads`, kernels from
:mod:`benchmarks.kernels`.

``numba_*`` return a compiled batch runner: the batch-inner kernels
(:func:`numba_fll_inner`, :func:`numba_drive` with ``inner=True``: time-major arrays, the batch the
inner SIMD loop, threads over batch blocks) and the scalar per-scenario ones (serial, or
``parallel=True``: a ``prange`` over scenarios); ``numpy_*`` run the same kernels from Python on
arrays of shape (batch,): a Python loop over time, vectorized over the batch.
"""

from __future__ import annotations

import numpy as np

from . import kernels as K
from . import workloads as W

FLL_KERNEL = {"sogi-fll": K.SOGI_FLL, "sogi-fll-wpf": K.SOGI_FLL_WPF, "sogi-fll-wif": K.SOGI_FLL_WIF}
FLL_FIELD = {"sogi-fll": K.f_sogifll, "sogi-fll-wpf": K.f_wpf, "sogi-fll-wif": K.f_wif}


def _cast(values, dtype) -> tuple:
    return tuple(dtype(v) for v in values)


def _numba(variants: dict, parallel: bool):
    if not variants:
        raise RuntimeError("numba is not installed: pip install -e '.[bench]'")
    return variants[parallel]


def numba_fll(kind: str, dtype, parallel: bool, inputs: str):
    """A compiled numba batch runner: ``run(*fll_baseline_args(kind, batch, dtype, inputs, n)) -> costs``."""
    p, x0 = W.fll_baseline_params(kind)
    run = _numba(K.NUMBA_FLL if inputs == "loop" else K.NUMBA_FLL_PRE, parallel)
    params = (FLL_KERNEL[kind], _cast(x0, dtype), _cast(p, dtype))

    def runner(*args):
        *data, n = args
        return run(*params, *data, n, W.TS, dtype)

    return runner


def numba_fll_inner(kind: str, dtype, inputs: str):
    """The batch-inner numba runner (time-major inputs, threads over batch blocks):
    ``run(*fll_inner_args(kind, batch, dtype, inputs, n)) -> costs``."""
    p, x0 = W.fll_baseline_params(kind)
    run = _numba(K.NUMBA_FLL_INNER if inputs == "loop" else K.NUMBA_FLL_INNER_PRE, True)
    params = (FLL_KERNEL[kind], _cast(x0, dtype), _cast(p, dtype))

    def runner(*args):
        *data, n = args
        return run(*params, *data, n, W.TS, dtype)

    return runner


def fll_inner_args(kind: str, batch: int, dtype, inputs: str, n: int) -> tuple:
    """The data a :func:`numba_fll_inner` runner takes: :func:`fll_baseline_args` transposed, batch last
    (``(SP (10, B), n)``, or ``(U, OM, n)`` time-major (n, B)); transposed before timing."""
    return tuple(
        np.ascontiguousarray(a.T) if isinstance(a, np.ndarray) else a
        for a in fll_baseline_args(kind, batch, dtype, inputs, n)
    )


def fll_baseline_args(kind: str, batch: int, dtype, inputs: str, n: int) -> tuple:
    """The data a :func:`numba_fll` runner takes: ``(SP, n)`` for ``"loop"``, ``(U, OM, n)`` for ``"precomputed"``."""
    if inputs == "loop":
        cols = W.fll_scenarios(batch)
        SP = np.stack([cols[k] for k in K.SIGNAL_PARAMS], axis=1)
        return (np.ascontiguousarray(SP.astype(dtype)), n)
    u, om = W.fll_samples(batch, n, dtype)
    return (u, om, n)


def numpy_fll(kind: str, batch: int, dtype, n: int) -> np.ndarray:
    """The FLL workload by NumPy (input in the loop): a Python loop over time, each step vectorized over the batch."""
    p, x0 = W.fll_baseline_params(kind)
    cols = W.fll_scenarios(batch)
    sp = tuple(np.asarray(cols[k], dtype) for k in K.SIGNAL_PARAMS)
    x0 = tuple(np.full(batch, v, dtype) for v in x0)
    return K.ab3_run(FLL_FIELD[kind], K.signal_input, x0, _cast(p, dtype), sp, n, W.TS, dtype)


def numba_drive(dtype, parallel: bool, inner: bool = False):
    """A compiled numba batch runner of the drive: ``run(w, n) -> costs``, w the per-scenario speeds (rad/s).

    The initial state of each scenario is jaxobs's steady start (:func:`benchmarks.workloads.drive_initial`),
    computed once outside the timed call.  ``inner``: the batch-inner kernel (threads over batch blocks,
    ``parallel`` must be True).
    """
    M, OB, C, P, every = W.drive_baseline_params()
    params = (_cast(P, dtype), _cast(M, dtype), _cast(OB, dtype), _cast(C, dtype))
    run = _numba(K.NUMBA_DRIVE_INNER if inner else K.NUMBA_DRIVE, parallel)
    cache = {}

    def runner(w, n):
        key = w.shape[0]
        if key not in cache:
            cache[key] = tuple(np.ascontiguousarray(a, dtype) for a in W.drive_initial(key))
        return run(*cache[key], w, *params, n, W.TS, every, dtype)

    return runner


def numpy_drive(batch: int, dtype, n: int) -> np.ndarray:
    """The drive workload by NumPy: a Python loop over time, each step vectorized over the batch."""
    M, OB, C, P, every = W.drive_baseline_params()
    w = np.asarray(W.drive_setup(batch)[3], dtype)
    X0, O0, S0 = (np.asarray(a, dtype) for a in W.drive_initial(batch))
    x, o = np.ascontiguousarray(X0.T), np.ascontiguousarray(O0.T)
    s0 = tuple(np.ascontiguousarray(S0[:, j]) for j in range(S0.shape[1]))
    z = np.zeros(batch, dtype)
    args = (_cast(P, dtype), _cast(M, dtype), _cast(OB, dtype), _cast(C, dtype), (w, z, z, z, z))
    return K.drive_run(x, o, s0, *args, n, W.TS, every, dtype)
