"""The reproductions' simulations, their traced programs kept across processes (time to result).

A reproduction runs a few dozen drive simulations, each its own program: in a second ``jaxobs reproduce
leso`` the persistent compilation cache found every compilation, yet 14 s of its 36 s went to tracing
them again (``python -m benchmarks.first_second``).  :func:`run_kept` runs one through
:func:`jaxobs.kept_jit`, which keeps the traced and lowered program (the command line turns it on with
the compile cache; from Python, :func:`jaxobs.use_compile_cache` does).  Its key is what the program bakes
in: the horizon and the system's values that are not arrays (its Python numbers and static fields), the
arrays' shapes and the source of jaxobs.  The run gives the same numbers bit for bit as ``simulate``
(tests/test_traced.py).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
from jax import export

from ..core.measurements import DriveInput
from ..core.system import AbstractSystem
from ..drive.control import FOCOutput
from ..drive.dual import DualPlantOutput
from ..drive.dual_loop import DualFOCOutput, DualOutput
from ..drive.loop import DriveOutput
from ..drive.plant import PlantOutput
from ..observers.base import BankOutput
from ..observers.fll import FLLOutput
from ..observers.flux import FluxOutput
from ..observers.leso import LESOOutput
from ..observers.sogi import QSGOutput
from ..runtime.programs import kept_jit
from ..runtime.simulation import SignalOutput, SignalTruth, simulate

__all__ = ["Run", "run_kept"]


class Run(NamedTuple):
    """What a reproduction reads of a simulation (:class:`jaxobs.Solution`'s fields of the same names)."""

    t: jax.Array
    outputs: Any
    ok: jax.Array


# a kept program's outputs are serialized with it: jax.export writes a NamedTuple only once its type is registered
# (once per process, here at import, before any program is exported or read back)
for _cls in (
    DriveOutput,
    FOCOutput,
    PlantOutput,
    DriveInput,
    BankOutput,
    FluxOutput,
    LESOOutput,
    FLLOutput,
    QSGOutput,
    SignalOutput,
    SignalTruth,
    DualOutput,
    DualFOCOutput,
    DualPlantOutput,
):
    export.register_namedtuple_serialization(_cls, serialized_name=f"{_cls.__module__}.{_cls.__qualname__}")


def _simulated(system, t1: float):
    sol = simulate(system, t1)
    return sol.t, sol.outputs, sol.ok


_simulated_kept = kept_jit(_simulated)


def run_kept(system: AbstractSystem, t1: float) -> Run:
    """``simulate(system, t1)`` as a :class:`Run`, its program kept across processes (module doc).

    Args:
        system: The system to simulate.
        t1: The horizon, s.

    Returns:
        The run's times, outputs and ok flag.
    """
    return Run(*_simulated_kept(system, float(t1)))
