"""Eager argument checks shared by every constructor.

Constructors run outside ``jit``: they check concrete values and raise a
``ValueError`` naming the field and the allowed range.  Traced values (a module
rebuilt inside ``vmap`` or ``grad``) cannot be checked eagerly and pass through;
modules rebuilt by ``jax.tree_util`` never call ``__init__`` anyway.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer
from jax.typing import ArrayLike


def _is_concrete(x: object) -> bool:
    return not isinstance(x, Tracer)


def as_float(x: ArrayLike) -> jax.Array:
    """A gain or parameter as a floating JAX array of the default float dtype.

    Args:
        x: The value (any shape).

    Returns:
        ``x`` itself where it is a floating JAX array, else ``x`` as one.
    """
    if isinstance(x, jax.Array) and jnp.issubdtype(x.dtype, jnp.floating):
        return x
    dtype = jnp.result_type(float)
    if isinstance(x, (int, float, np.ndarray, np.generic)):
        # converted by NumPy (the same rounding), then placed: no XLA kernel compiled for the conversion (a drive
        # file's check builds its parameters and runs nothing)
        return jax.device_put(np.asarray(x, dtype=dtype))
    return jnp.asarray(x, dtype=dtype)


def check_real(
    name: str,
    x: Any,
    *,
    lower: float | None = None,
    upper: float | None = None,
    lower_open: bool = True,
    owner: str = "",
) -> jax.Array:
    """Check that every element of ``x`` is finite and inside the given range.

    Args:
        name: The field's name in the error.
        x: The value (any shape; anything else, None included, is refused as not a real number).
        lower: The lower bound, or None.
        upper: The upper bound, or None.
        lower_open: Whether the lower bound is strict (``x > lower``); otherwise ``x >= lower``.
        owner: The class or function the error names.

    Returns:
        ``x`` converted to a float array.

    Raises:
        ValueError: A concrete element that is not finite or out of range, naming the field.
    """
    where = f"{owner}.{name}" if owner else name
    if _is_concrete(x):
        try:
            arr = np.asarray(x, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{where} must be a real number, got {x!r}") from None
        rng = _range_text(lower, upper, lower_open)
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{where} must be finite{rng}, got {_show(arr)}")
        if lower is not None:
            bad = arr <= lower if lower_open else arr < lower
            if np.any(bad):
                raise ValueError(f"{where} must be finite{rng}, got {_show(arr)}")
        if upper is not None and np.any(arr > upper):
            raise ValueError(f"{where} must be finite{rng}, got {_show(arr)}")
    return as_float(x)


def check_positive(name: str, x: Any, owner: str = "") -> jax.Array:
    """Check that every element of ``x`` is finite and > 0 (:func:`check_real`).

    Args:
        name: The field's name in the error.
        x: The value (any shape).
        owner: The class or function the error names.

    Returns:
        ``x`` converted to a float array.

    Raises:
        ValueError: A concrete element that is not finite or not > 0, naming the field.
    """
    return check_real(name, x, lower=0.0, lower_open=True, owner=owner)


def check_nonnegative(name: str, x: Any, owner: str = "") -> jax.Array:
    """Check that every element of ``x`` is finite and >= 0 (:func:`check_real`).

    Args:
        name: The field's name in the error.
        x: The value (any shape).
        owner: The class or function the error names.

    Returns:
        ``x`` converted to a float array.

    Raises:
        ValueError: A concrete element that is not finite or negative, naming the field.
    """
    return check_real(name, x, lower=0.0, lower_open=False, owner=owner)


def check_sample_time(name: str, ts: Any, owner: str = "") -> float:
    """Check a sample time and return it as a static Python float (a sample time fixes the scan length).

    Args:
        name: The field's name in the error.
        ts: The sample time, s.
        owner: The class or function the error names.

    Returns:
        ``ts`` as a float.

    Raises:
        ValueError: A value that is not a positive finite number, naming the field.
    """
    where = f"{owner}.{name}" if owner else name
    try:
        val = float(ts)
    except (TypeError, ValueError):
        raise ValueError(f"{where} must be a positive finite number of seconds, got {ts!r}") from None
    if not math.isfinite(val) or val <= 0:
        raise ValueError(f"{where} must be a positive finite number of seconds, got {ts!r}")
    return val


def check_seconds(label: str, value: Any, *, strict: bool = False) -> None:
    """Check a time (an event's, a start's): a finite number of seconds >= 0.

    Args:
        label: What the error names before "must be": a field (``t_event``), or a table's key (``scenarios.t_event:``).
        value: The time, s.
        strict: Also refuse a bool, and a value that is neither an int nor a float (a value read from a file).

    Raises:
        ValueError: ``<label> must be a finite number of seconds >= 0, got <value>``.
    """
    if strict and (isinstance(value, bool) or not isinstance(value, (int, float))):
        raise ValueError(f"{label} must be a finite number of seconds >= 0, got {value!r}")
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{label} must be a finite number of seconds >= 0, got {value!r}")


def _range_text(lower, upper, lower_open):
    parts = []
    if lower is not None:
        parts.append(f"{'>' if lower_open else '>='} {lower:g}")
    if upper is not None:
        parts.append(f"<= {upper:g}")
    return (" and " + " and ".join(parts)) if parts else ""


def _show(arr):
    return f"{arr.item():g}" if arr.ndim == 0 else np.array2string(arr, precision=4)


def static_float(checked: object, raw: Any) -> float:
    """A checked scalar kept as a static Python float (from the raw value, so it also works in ``jit``).

    Args:
        checked: The checked value (unused: the check has run).
        raw: The value as given (a Python number or a concrete scalar).

    Returns:
        ``raw`` as a float.
    """
    del checked
    return float(raw)


def key_part(k: Any) -> Any:
    """One entry of a pytree key path as a name's part: a field's name, a dict's key, a sequence's index (what
    :func:`jax.tree_util.tree_flatten_with_path` gives), or the entry itself for any other kind.

    Args:
        k: The key path entry.

    Returns:
        The name, key or index.
    """
    if isinstance(k, jax.tree_util.GetAttrKey):
        return k.name
    if isinstance(k, (jax.tree_util.DictKey, jax.tree_util.FlattenedIndexKey)):
        return k.key
    if isinstance(k, jax.tree_util.SequenceKey):
        return k.idx
    return k
