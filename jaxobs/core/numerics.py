"""Numerically safe elementary functions: finite values *and* finite gradients everywhere.

``sqrt`` and ``atan2`` have infinite or undefined derivatives at the origin,
which every observer and controller visits at t = 0 (zero initial states).  A
NaN there poisons a whole gradient even when the loss does not look at that
sample, because 0·NaN = NaN in reverse mode.  These versions use the
"double where": the unsafe point is replaced *before* the call, so both the
value and the derivative are finite; away from the origin they are exact.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

_TINY = 1e-30

Real = jax.Array | np.ndarray | float  # a real value or array (compared with a bound)


def safe_norm2(x: Real, y: Real) -> jax.Array:
    """√(x² + y²), exact unless x² + y² < 1e-30, with a zero gradient at the origin.

    Args:
        x: The first component.
        y: The second component.

    Returns:
        The norm, 0 at the origin.
    """
    sq = x * x + y * y
    ok = sq > _TINY
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, sq, 1.0)), 0.0)


def safe_sqrt(x: Real) -> jax.Array:
    """√x for x > 0, 0 elsewhere (x ≤ 0, e.g. a room clamped to 0), with a zero gradient there.

    Args:
        x: The radicand.

    Returns:
        The root, 0 where ``x`` ≤ 0.
    """
    ok = x > 0.0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, x, 1.0)), 0.0)


def safe_atan2(y: Real, x: Real) -> jax.Array:
    """atan2(y, x), 0 at the origin with a zero gradient there.

    Args:
        y: The ordinate.
        x: The abscissa.

    Returns:
        The angle, rad, in (−π, π].
    """
    ok = (x * x + y * y) > _TINY
    return jnp.where(ok, jnp.arctan2(jnp.where(ok, y, 0.0), jnp.where(ok, x, 1.0)), 0.0)


def wrap(a: ArrayLike) -> jax.Array:
    """Angle wrapped to (−π, π] (electrical angles and angle errors).

    Args:
        a: The angle, rad.

    Returns:
        The wrapped angle, rad.
    """
    return jnp.pi - jnp.mod(jnp.pi - a, 2 * jnp.pi)
