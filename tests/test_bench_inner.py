"""The batch-inner numba kernels (benchmarks.kernels, the bench's reference) compute what jaxobs computes.

Small batches and horizons, but each numba kernel compiles for 10-100 s (the three FLL kernels of the
precomputed test took 104 s on the quiet 2-core machine): the whole module runs in the slow suite, which CI
runs (`make test-slow`); skipped only where numba (the `bench` extra) is missing.
"""

import numpy as np
import pytest

from benchmarks import baselines as B
from benchmarks import workloads as W

numba = pytest.importorskip("numba", reason="numba is the benchmark extra: pip install -e '.[bench]'")

pytestmark = pytest.mark.slow  # numba compilation, see the module docstring


@pytest.mark.parametrize("inputs", ["loop", "precomputed"])
def test_fll_inner_equals_jaxobs(inputs):
    """Every FLL of the family, float64, 5 scenarios (blocks of 2 and 3 over two threads), 2100 steps (past the
    frequency step, phase jump and sag at 0.2 s, where the scenarios part)."""
    n, batch = 2100, 5
    for kind in W.FLL_KINDS:
        fn, args = W.jax_fll(kind, batch, inputs, n * W.TS, shard=False)
        ref = np.asarray(fn(args))
        got = B.numba_fll_inner(kind, np.float64, inputs)(*B.fll_inner_args(kind, batch, np.float64, inputs, n))
        np.testing.assert_allclose(got, ref, rtol=1e-10)
        # the scenarios differ after the event: a kernel that mixed them up would fail
        assert np.ptp(ref) > 1e-3 * np.max(np.abs(ref))


def test_drive_inner_equals_jaxobs():
    """The closed-loop drive, float64, 3 scenarios, 600 steps (past the observer hand-over at 0.05 s)."""
    n, batch = 600, 3
    fn, args = W.jax_drive(batch, n * W.TS, shard=False)
    ref = np.asarray(fn(args))
    w = np.asarray(W.drive_setup(batch)[3])
    got = B.numba_drive(np.float64, True, inner=True)(w, n)
    np.testing.assert_allclose(got, ref, rtol=1e-10)
    assert np.ptp(ref) > 0
