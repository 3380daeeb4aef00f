"""Test configuration: every test runs in float64 (jax_enable_x64), set once here.

Comparisons with closed forms, NumPy loops and python-control need double
precision; a test that checks float32 behaviour asks for float32 arrays
explicitly.
"""

import jax

jax.config.update("jax_enable_x64", True)
