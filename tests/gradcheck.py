"""Shared by the gradient tests: central differences on a module's named fields."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest


def assert_field_grads_match_fd(loss, module, names, *args, rel=1e-4, abs=0.0, h_rel=1e-6):
    """``eqx.filter_grad(loss)(module, *args)`` on each field in ``names`` equals a central difference
    with step ``h_rel``·|field| (the loss is jit-compiled once for the differences)."""
    grads = eqx.filter_grad(loss)(module, *args)
    f = eqx.filter_jit(loss)
    for name in names:
        g = float(getattr(grads, name))
        x0 = float(getattr(module, name))
        h = h_rel * x0
        up = eqx.tree_at(lambda o: getattr(o, name), module, jnp.asarray(x0 + h))
        dn = eqx.tree_at(lambda o: getattr(o, name), module, jnp.asarray(x0 - h))
        fd = (float(f(up, *args)) - float(f(dn, *args))) / (2 * h)
        assert np.isfinite(g), (name, g)
        assert g == pytest.approx(fd, rel=rel, abs=abs), (name, g, fd)
