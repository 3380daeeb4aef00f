"""What a checkpoint must hold to be resumed: its own content digest, and a consistent state.

A checkpoint (``jaxobs_tuning.solvers``) is one npz: ``meta`` (a JSON string: format, the job's fingerprint,
iteration, best value, iterations since the best, history), ``theta``, ``best_theta``, the optimizer
state's leaves ``arr_0 ...``, and ``sha256``: the digest of all of these.  The job's fingerprint says
*which job* a checkpoint belongs to; the content digest says the file is the one the solver wrote (a torn
write, a flipped bit or a hand edit of θ or of the history is refused, not resumed into a wrong result).
It is an integrity check, not a signature: whoever can write ``--out`` can write a consistent checkpoint,
so the content is validated too (:func:`check_state`): a resumed run never starts from a NaN.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["DIGEST", "MAX_CHECKPOINT_BYTES", "check_state", "content_digest"]

DIGEST = "sha256"  # the npz entry that holds the content digest
MAX_CHECKPOINT_BYTES = 256 * 2**20  # a checkpoint larger than this is refused before it is parsed


def content_digest(arrays: Mapping[str, ArrayLike]) -> str:
    """The hex sha256 of every entry but :data:`DIGEST`, in name order: name, dtype, shape and bytes (so
    two arrays with the same bytes and another shape or dtype differ).

    Args:
        arrays: The checkpoint's entries by name.

    Returns:
        The digest, 64 hex digits.
    """
    h = hashlib.sha256()
    for name in sorted(k for k in arrays if k != DIGEST):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}\0{a.dtype.str}\0{a.shape}\0".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _int(meta: dict, key: str, lo: int) -> int:
    v = meta.get(key)
    if type(v) is not int or v < lo:
        raise ValueError(f"{key} must be an integer >= {lo}, got {str(v)[:20]}")
    return v


def _number(x) -> bool:
    return type(x) in (int, float)


def check_state(
    meta: dict,
    theta: ArrayLike,
    best_theta: ArrayLike,
    leaves: Sequence[ArrayLike],
    theta_shape: Sequence[int],
) -> None:
    """Refuse (``ValueError``, one short line) a checkpoint state a run could not have written: θ or best θ
    not finite or not of the job's shape, a non-finite optimizer state, ``best_value`` neither a finite
    number nor null (no stable design yet), ``since_best`` > ``iteration``, a history whose length is not
    the iteration or whose entries are not the solver's (iteration i at index i, a numeric value, diverged
    count >= 0, finite gains), a best value that no stable history entry has.

    Args:
        meta: The checkpoint's metadata (iteration, since_best, best_value, history).
        theta: The free gains' vector.
        best_theta: The best stable design's vector.
        leaves: The optimizer state's array leaves.
        theta_shape: The job's shape of θ.

    Raises:
        ValueError: The first thing a run could not have written.
    """
    for name, a in (("theta", theta), ("best_theta", best_theta)):
        a = np.asarray(a)
        if a.shape != tuple(theta_shape) or not np.issubdtype(a.dtype, np.floating):
            raise ValueError(f"{name} has shape {a.shape} {a.dtype}, the job's gains {tuple(theta_shape)} floats")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} is not finite")
    for i, leaf in enumerate(leaves):
        a = np.asarray(leaf)
        if np.issubdtype(a.dtype, np.inexact) and not np.all(np.isfinite(a)):
            raise ValueError(f"optimizer state arr_{i} is not finite")
    it = _int(meta, "iteration", 0)
    if _int(meta, "since_best", 0) > it:
        raise ValueError(f"since_best {meta['since_best']} exceeds the iteration {it}")
    best = meta.get("best_value")
    if best is not None and not (_number(best) and math.isfinite(best)):
        raise ValueError(f"best_value must be a finite number or null, got {str(best)[:20]}")
    hist = meta.get("history")
    if not isinstance(hist, list) or len(hist) != it:
        n = len(hist) if isinstance(hist, list) else type(hist).__name__
        raise ValueError(f"the history holds {n} entries, the iteration is {it}")
    for i, h in enumerate(hist):
        ok = (
            isinstance(h, dict)
            and h.get("iteration") == i
            and type(h.get("iteration")) is int
            and _number(h.get("value"))
            and type(h.get("diverged")) is int
            and h["diverged"] >= 0
            and isinstance(h.get("gains"), dict)
            and all(_number(v) and math.isfinite(v) for v in h["gains"].values())
        )
        if not ok:
            raise ValueError(f"history entry {i} is not a solver's entry")
    stable = [h["value"] for h in hist if h["diverged"] == 0]
    if (best is None) != (not stable) or (best is not None and best not in stable):
        raise ValueError("best_value is not the value of a stable design in the history")
