"""Baselines of the benchmark workloads: the same steps as jaxobs, written by hand in plain Python.

One source, two back ends, no generated code:

- **NumPy**: every kernel below is a plain Python function whose operations
  work on scalars *and* on NumPy arrays.  Called from Python on arrays of shape
  (batch,) — states (S, batch) — it is the NumPy baseline: a Python loop over
  time, each step vectorized over the batch.
- **numba**: :func:`numba.extending.register_jitable` lets ``numba.njit`` code
  call the same functions, compiled per scenario on scalars (the small kernels
  inlined into their caller, the time loops compiled as functions of their
  own).  The numba baselines are the batch loops of each module, compiled twice by
  :func:`njit_variants`: serial, and ``parallel=True`` (a ``prange`` over
  scenarios, every core).

Where NumPy and numba spell an operation differently the kernels call a
helper (:func:`sel`, :func:`maximum`, :func:`minimum`): ``np.where`` /
``np.maximum`` / ``np.minimum`` from Python, a scalar select through
:func:`numba.extending.overload` under numba.

Both must compute what jaxobs computes, operation for operation, so that the
throughput comparison is of one algorithm: tests/test_bench.py checks them
against :func:`jaxobs.simulate` (of :class:`jaxobs.OnSignal` and :class:`jaxobs.drive.ClosedLoop`) in float64.
Literals are cast to the working dtype ``F`` (``np.float32`` or ``np.float64``,
passed in: numba compiles one version per dtype), so a float32 run stays in
float32 as jaxobs does; the rule's step fractions (h/2, h/6, h/12) are rounded
to ``F`` once, from the float64 step.

numba is optional (the ``bench`` extra): without it this module still imports,
the kernels run as plain Python and :func:`njit_variants` returns ``{}``.

Speed, with public numba API only.  The earlier version (source strings run
through ``exec``) turned numba's reference counting off with the private
``_nrt=False`` option.  Instead: the time loops (:func:`ab3_run`,
:func:`drive_run`) own their state arrays and keep the integrator's update in
their own body, so no array is handed to a function with branches once per
step (each such call cost an atomic incref/decref pair per array: the
SOGI-FLL ran 2–4× slower); the FLL state size comes from a tuple's length,
so the loops over it unroll.  Measured side by side with the exec'd version
(FLLs and drive, float32 and float64): serial 0–6 % slower, ``parallel=True``
the same within this 2-core machine's noise.

The kernels by family: :mod:`.fll` (the FLL family, paper 001), :mod:`.drive` (the sensorless PMSM
drive, paper 000), each with its scalar kernels, numba batch loops and batch-inner kernels; :mod:`.common`
the helpers, constants and jit decorators both use.  Every public name is re-exported here, so callers
write ``from benchmarks import kernels as K; K.NUMBA_FLL_INNER``.
"""

from __future__ import annotations

from .common import (
    HALF_SQRT3,
    PI,
    SQRT3,
    TINY,
    TWO_PI,
    compiled,
    inlined,
    maximum,
    minimum,
    njit_inner,
    njit_variants,
    numba,
    prange,
    sel,
)
from .drive import (
    NUMBA_DRIVE,
    NUMBA_DRIVE_INNER,
    drive_batch,
    drive_block,
    drive_inner,
    drive_run,
    drive_step,
    drive_steps,
    obs_f,
    plant_f,
    wrap,
)
from .fll import (
    CHUNK,
    NUMBA_FLL,
    NUMBA_FLL_INNER,
    NUMBA_FLL_INNER_CACHED,
    NUMBA_FLL_INNER_PRE,
    NUMBA_FLL_PRE,
    NUMBA_TRIAD,
    SIGNAL_PARAMS,
    SOGI_FLL,
    SOGI_FLL_WIF,
    SOGI_FLL_WPF,
    ab3_block,
    ab3_col,
    ab3_run,
    cached_rows,
    f_sogifll,
    f_wif,
    f_wpf,
    fll_batch,
    fll_batch_pre,
    fll_inner,
    fll_inner_cached,
    fll_inner_pre,
    rows3,
    rows5,
    rule_steps,
    sampled_col,
    sampled_input,
    sampled_rows,
    signal,
    signal_col,
    signal_input,
    signal_rows,
    steps_sogifll,
    steps_wif,
    steps_wpf,
    triad,
)

__all__ = [
    "CHUNK",
    "HALF_SQRT3",
    "NUMBA_DRIVE",
    "NUMBA_DRIVE_INNER",
    "NUMBA_FLL",
    "NUMBA_FLL_INNER",
    "NUMBA_FLL_INNER_CACHED",
    "NUMBA_FLL_INNER_PRE",
    "NUMBA_FLL_PRE",
    "NUMBA_TRIAD",
    "PI",
    "SIGNAL_PARAMS",
    "SOGI_FLL",
    "SOGI_FLL_WIF",
    "SOGI_FLL_WPF",
    "SQRT3",
    "TINY",
    "TWO_PI",
    "ab3_block",
    "ab3_col",
    "ab3_run",
    "cached_rows",
    "compiled",
    "drive_batch",
    "drive_block",
    "drive_inner",
    "drive_run",
    "drive_step",
    "drive_steps",
    "f_sogifll",
    "f_wif",
    "f_wpf",
    "fll_batch",
    "fll_batch_pre",
    "fll_inner",
    "fll_inner_cached",
    "fll_inner_pre",
    "inlined",
    "maximum",
    "minimum",
    "njit_inner",
    "njit_variants",
    "numba",
    "obs_f",
    "plant_f",
    "prange",
    "rows3",
    "rows5",
    "rule_steps",
    "sampled_col",
    "sampled_input",
    "sampled_rows",
    "sel",
    "signal",
    "signal_col",
    "signal_input",
    "signal_rows",
    "steps_sogifll",
    "steps_wif",
    "steps_wpf",
    "triad",
    "wrap",
]
