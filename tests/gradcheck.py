"""Shared by the gradient tests: central differences on a module's named fields."""

import equinox as eqx
import numpy as np
import pytest


def assert_field_grads_match_fd(loss, module, names, *args, rel=1e-4, abs=0.0, h_rel=1e-6):
    """``eqx.filter_grad(loss)(module, *args)`` on each field in ``names`` equals a central difference
    with step ``h_rel``·|field|.

    Two compilations in all: the gradient, and the loss for the differences.  A shifted field keeps the
    leaf's own dtype and weak type (``leaf + h``): a leaf rebuilt from a Python float (``jnp.asarray``) is
    strongly typed, so each field shifted that way changed the loss's signature and compiled it again (one
    compilation per field, 5-10 s each for a drive loop).  The gradient is compiled as one program rather
    than run eagerly (which compiles the loop's forward and backward passes apart, and every small
    operation around them on its own)."""
    grads = eqx.filter_jit(eqx.filter_grad(loss))(module, *args)
    f = eqx.filter_jit(loss)
    for name in names:
        g = float(getattr(grads, name))
        leaf = getattr(module, name)
        x0 = float(leaf)
        h = h_rel * x0
        up = eqx.tree_at(lambda o: getattr(o, name), module, leaf + h)
        dn = eqx.tree_at(lambda o: getattr(o, name), module, leaf - h)
        fd = (float(f(up, *args)) - float(f(dn, *args))) / (2 * h)
        assert np.isfinite(g), (name, g)
        assert g == pytest.approx(fd, rel=rel, abs=abs), (name, g, fd)
