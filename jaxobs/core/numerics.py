"""Numerically safe elementary functions: finite values *and* finite gradients everywhere.

``sqrt`` and ``atan2`` have infinite or undefined derivatives at the origin,
which every observer and controller visits at t = 0 (zero initial states).  A
NaN there poisons a whole gradient even when the loss does not look at that
sample, because 0·NaN = NaN in reverse mode.  These versions use the
"double where": the unsafe point is replaced *before* the call, so both the
value and the derivative are finite; away from the origin they are exact.
"""

from __future__ import annotations

import jax.numpy as jnp

_TINY = 1e-30


def safe_norm2(x, y):
    """√(x² + y²), exact unless x² + y² < 1e-30, with a zero gradient at the origin."""
    sq = x * x + y * y
    ok = sq > _TINY
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, sq, 1.0)), 0.0)


def safe_atan2(y, x):
    """atan2(y, x), 0 at the origin with a zero gradient there."""
    ok = (x * x + y * y) > _TINY
    return jnp.where(ok, jnp.arctan2(jnp.where(ok, y, 0.0), jnp.where(ok, x, 1.0)), 0.0)


def wrap(a):
    """Angle wrapped to (−π, π] (electrical angles and angle errors).

    Args:
        a: The angle, rad.

    Returns:
        The wrapped angle, rad.
    """
    return jnp.pi - jnp.mod(jnp.pi - a, 2 * jnp.pi)
