"""The user API: ``jaxobs.__all__`` is what a notebook user reads."""

import importlib
import pkgutil
import types

import jaxobs


def test_all_resolves_and_is_the_public_namespace():
    assert len(jaxobs.__all__) == len(set(jaxobs.__all__))
    for name in jaxobs.__all__:
        assert hasattr(jaxobs, name), name
    public = {n for n in dir(jaxobs) if not n.startswith("_")}
    # every public module-level name is in __all__, except subpackages Python binds on import
    extra = {n for n in public - set(jaxobs.__all__) if not isinstance(getattr(jaxobs, n), types.ModuleType)}
    assert extra == set(), extra
    for internal in ("Held", "Knots", "ObserverState", "measurements", "system", "discretize"):
        assert internal not in jaxobs.__all__


def test_no_module_is_shadowed_by_a_function():
    """A public submodule is reachable as itself: ``jaxobs.simulate`` is the function, and its module is
    the private ``jaxobs.runtime.simulation``."""
    for info in pkgutil.iter_modules(jaxobs.__path__):
        if info.name.startswith("_") or info.name == "__main__":
            continue
        mod = importlib.import_module(f"jaxobs.{info.name}")
        assert getattr(jaxobs, info.name) is mod, info.name
    assert callable(jaxobs.simulate) and not isinstance(jaxobs.simulate, types.ModuleType)
