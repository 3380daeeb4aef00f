"""The C99 operations the export writes: the ``<math.h>`` function or the operator of each elementwise
primitive (:mod:`jaxobs_tuning.export.lower`), and what each computes on numpy scalars, so that the emitted
statements run in Python (:func:`jaxobs_tuning.export.ir.evaluate`) as the C does."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["UNARY_CALLS", "BINARY_CALLS", "BINARY_OPS", "COMPARE", "LOGIC", "NUMPY", "round_away"]

UNARY_CALLS = {  # primitive -> C99 <math.h> function (float32 name; the double one drops the "f")
    "sqrt": "sqrtf",
    "exp": "expf",
    "exp2": "exp2f",
    "log": "logf",
    "log1p": "log1pf",
    "expm1": "expm1f",
    "sin": "sinf",
    "cos": "cosf",
    "tan": "tanf",
    "asin": "asinf",
    "acos": "acosf",
    "atan": "atanf",
    "sinh": "sinhf",
    "cosh": "coshf",
    "tanh": "tanhf",
    "asinh": "asinhf",
    "acosh": "acoshf",
    "atanh": "atanhf",
    "abs": "fabsf",
    "floor": "floorf",
    "ceil": "ceilf",
    "cbrt": "cbrtf",
    "erf": "erff",
}
BINARY_CALLS = {"atan2": "atan2f", "pow": "powf", "rem": "fmodf", "max": "fmaxf", "min": "fminf"}
BINARY_OPS = {"add": ("+", "add"), "add_any": ("+", "add"), "sub": ("-", "add"), "mul": ("*", "mul")}
BINARY_OPS["div"] = ("/", "div")
COMPARE = {"eq": "==", "ne": "!=", "lt": "<", "le": "<=", "gt": ">", "ge": ">="}
LOGIC = {"and": "&&", "or": "||"}

NUMPY = {  # the C operators and <math.h> functions on numpy scalars (float32 in, float32 out)
    "+": np.add,
    "-": np.subtract,
    "*": np.multiply,
    "/": np.divide,
    "==": np.equal,
    "!=": np.not_equal,
    "<": np.less,
    "<=": np.less_equal,
    ">": np.greater,
    ">=": np.greater_equal,
    "&&": np.logical_and,
    "||": np.logical_or,
    "sqrtf": np.sqrt,
    "expf": np.exp,
    "exp2f": np.exp2,
    "logf": np.log,
    "log1pf": np.log1p,
    "expm1f": np.expm1,
    "sinf": np.sin,
    "cosf": np.cos,
    "tanf": np.tan,
    "asinf": np.arcsin,
    "acosf": np.arccos,
    "atanf": np.arctan,
    "sinhf": np.sinh,
    "coshf": np.cosh,
    "tanhf": np.tanh,
    "asinhf": np.arcsinh,
    "acoshf": np.arccosh,
    "atanhf": np.arctanh,
    "fabsf": np.abs,
    "floorf": np.floor,
    "ceilf": np.ceil,
    "cbrtf": np.cbrt,
    "erff": lambda x: type(x)(math.erf(x)),
    "atan2f": np.arctan2,
    "powf": np.power,
    "fmodf": np.fmod,
    "fmaxf": np.fmax,
    "fminf": np.fmin,
}


def round_away(x: np.floating) -> np.floating:
    """C's ``roundf`` on a numpy scalar: halves away from zero.

    Args:
        x: The scalar.

    Returns:
        It rounded, in its dtype.
    """
    t = np.trunc(x)
    return t + np.sign(x) if abs(x - t) >= 0.5 else t
