"""What every kernel module shares: numba optional, the NumPy/numba helpers, the jit decorators.

:func:`inlined` and :func:`compiled` register a plain function for numba callers and leave it plain
Python; :func:`njit_variants` and :func:`njit_inner` compile the batch loops.  :func:`sel`,
:func:`maximum` and :func:`minimum` are ``np.where`` / ``np.maximum`` / ``np.minimum`` from Python and a
scalar select (:func:`numba.extending.overload`) under numba.
"""

from __future__ import annotations

import math

import numpy as np

try:
    import numba
    from numba.extending import overload, register_jitable
except ImportError:  # numba is the optional `bench` extra
    numba = None

prange = range if numba is None else numba.prange

TWO_PI = 2.0 * math.pi
PI = math.pi
SQRT3 = math.sqrt(3.0)
HALF_SQRT3 = 0.5 * math.sqrt(3.0)
TINY = 1e-30


def _jitable(inline: str):
    """Register a plain function for numba callers (``inline``: "always" or "never"); it stays plain Python."""

    def register(fn):
        if numba is not None:
            register_jitable(inline=inline)(fn)
        return fn

    return register


inlined = _jitable("always")  # compiled into the numba caller
compiled = _jitable("never")  # a numba function of its own (the per-scenario time loops)


def njit_variants(fn) -> dict:
    """``{False: njit(fn), True: njit(fn, parallel=True)}``: serial, and a ``prange`` over every core."""
    if numba is None:
        return {}
    return {False: numba.njit(fn), True: numba.njit(parallel=True)(fn)}


def njit_inner(fn) -> dict:
    """``{True: njit(fn, parallel=True, error_model="numpy")}``: the batch-inner kernels run on every core.

    ``error_model="numpy"``: a float division by zero gives inf/nan as in NumPy and JAX instead of raising
    (numba's default, Python's semantics, checks every divisor: a branch in the batch loop that stops
    LLVM from vectorizing it).  The divisors here are floored (v_floor², ω_min), never zero.
    """
    if numba is None:
        return {}
    return {True: numba.njit(parallel=True, error_model="numpy")(fn)}


# ---------------------------------------------------------------------------
# helpers: NumPy from Python, scalar selects under numba
# ---------------------------------------------------------------------------


def sel(c, a, b):
    """``a`` where ``c``, else ``b``."""
    return np.where(c, a, b)


def maximum(a, b):
    return np.maximum(a, b)


def minimum(a, b):
    return np.minimum(a, b)


if numba is not None:

    @overload(sel, inline="always")
    def _sel_scalar(c, a, b):
        # an if statement: `a if c else b` inlined here trips numba's IR checks (NumbaIRAssumptionWarning)
        def impl(c, a, b):
            if c:
                return a
            return b

        return impl

    @overload(maximum, inline="always")
    def _maximum_scalar(a, b):
        return lambda a, b: max(a, b)  # NaN-free inputs here; same as np.maximum

    @overload(minimum, inline="always")
    def _minimum_scalar(a, b):
        return lambda a, b: min(a, b)
