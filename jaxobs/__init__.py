"""jaxobs — a differentiable JAX simulator for tuning sensorless motor-drive observers and FLLs.

The names below are the user API (``__all__``); everything else lives in the
subpackages (:mod:`jaxobs.drive`, :mod:`jaxobs.observers`, :mod:`jaxobs.linear`,
:mod:`jaxobs.metrics`, :mod:`jaxobs.signals`, :mod:`jaxobs.scenarios`,
:mod:`jaxobs.sharding`, :mod:`jaxobs.papers`) or in private implementation
modules (``jaxobs._simulate``, ``jaxobs._loop``, ``jaxobs._discretize``, ...).

Importing it has no side effects: no environment variable or JAX option
changes.  To run a sharded batch on every CPU core, call
:func:`jaxobs.use_host_devices` before the first JAX computation; to keep
compiled programs across processes, :func:`jaxobs.use_compile_cache`.
"""

from importlib.metadata import PackageNotFoundError as _PackageNotFoundError
from importlib.metadata import version as _version

# subpackages a notebook user reaches for by name
from . import drive as drive
from . import linear as linear
from . import metrics as metrics
from . import observers as observers
from . import papers as papers
from . import scenarios as scenarios
from . import sharding as sharding
from . import signals as signals

# running a process: compile cache, devices, several processes
from ._cache import use_compile_cache as use_compile_cache

# discretization rules (strategy objects every observer and the plant take)
from ._discretize import AB3 as AB3
from ._discretize import RK4 as RK4
from ._discretize import AbstractRule as AbstractRule
from ._discretize import Euler as Euler
from ._discretize import Tustin as Tustin

# checkpoint strategies of the loop (how gradients through a long horizon are computed)
from ._loop import AbstractCheckpoint as AbstractCheckpoint
from ._loop import AbstractReverseCheckpoint as AbstractReverseCheckpoint
from ._loop import AutoCheckpoint as AutoCheckpoint
from ._loop import ChunkCheckpoint as ChunkCheckpoint
from ._loop import ForwardSensitivity as ForwardSensitivity
from ._loop import NoCheckpoint as NoCheckpoint
from ._loop import StepCheckpoint as StepCheckpoint

# what a drive observer is given each period
from ._measurements import DriveInput as DriveInput

# the one loop over a system, and what to save
from ._simulate import AbstractSave as AbstractSave
from ._simulate import OnSignal as OnSignal
from ._simulate import PrecisionWarning as PrecisionWarning
from ._simulate import SaveAll as SaveAll
from ._simulate import SaveFinal as SaveFinal
from ._simulate import SignalOutput as SignalOutput
from ._simulate import SignalTruth as SignalTruth
from ._simulate import Solution as Solution
from ._simulate import simulate as simulate
from ._system import AbstractSystem as AbstractSystem
from ._time import SampleTime as SampleTime
from ._traced import ProgramCache as ProgramCache
from ._traced import kept_jit as kept_jit
from ._traced import set_program_cache as set_program_cache
from .metrics import lost_lock_of as lost_lock_of

# observers: the FLL family (001), the flux observers (000), the LESOs (002), the reduced-order flux observer
# (Hinkkanen et al. 2018), and the contract
from .observers import CLESO as CLESO
from .observers import FALESO as FALESO
from .observers import GILESO as GILESO
from .observers import SOGI as SOGI
from .observers import SOGI2 as SOGI2
from .observers import SOGIFLL as SOGIFLL
from .observers import SOGIFLLWIF as SOGIFLLWIF
from .observers import SOGIFLLWPF as SOGIFLLWPF
from .observers import SOIFO as SOIFO
from .observers import AbstractDriveObserver as AbstractDriveObserver
from .observers import AbstractObserver as AbstractObserver
from .observers import LPFFlux as LPFFlux
from .observers import ObserverBank as ObserverBank
from .observers import PureIntegratorFlux as PureIntegratorFlux
from .observers import ReducedOrderFluxObserver as ReducedOrderFluxObserver
from .observers import SecondOrderSOIFO as SecondOrderSOIFO
from .sharding import batch_axes as batch_axes
from .sharding import batch_mesh as batch_mesh
from .sharding import init_distributed as init_distributed
from .sharding import map_batch as map_batch
from .sharding import shard_batch as shard_batch
from .sharding import use_host_devices as use_host_devices

# test signals and recordings
from .signals import AbstractSignal as AbstractSignal
from .signals import DriveRecording as DriveRecording
from .signals import EMFSignal as EMFSignal
from .signals import GridSignal as GridSignal
from .signals import SampledSignal as SampledSignal
from .signals import paper001_test as paper001_test
from .signals import stack as stack

__all__ = [
    # modules
    "drive",
    "linear",
    "metrics",
    "observers",
    "papers",
    "scenarios",
    "sharding",
    "signals",
    # the loop
    "simulate",
    "AbstractSystem",
    "OnSignal",
    "Solution",
    "SignalOutput",
    "SignalTruth",
    "AbstractSave",
    "SaveAll",
    "SaveFinal",
    "PrecisionWarning",
    "SampleTime",
    "AbstractCheckpoint",
    "AbstractReverseCheckpoint",
    "AutoCheckpoint",
    "NoCheckpoint",
    "StepCheckpoint",
    "ChunkCheckpoint",
    "ForwardSensitivity",
    # discretization rules
    "AbstractRule",
    "Euler",
    "Tustin",
    "AB3",
    "RK4",
    # observers
    "AbstractObserver",
    "AbstractDriveObserver",
    "DriveInput",
    "SOGI",
    "SOGI2",
    "SOGIFLL",
    "SOGIFLLWPF",
    "SOGIFLLWIF",
    "PureIntegratorFlux",
    "LPFFlux",
    "SOIFO",
    "SecondOrderSOIFO",
    "CLESO",
    "GILESO",
    "FALESO",
    "ReducedOrderFluxObserver",
    "ObserverBank",
    # signals
    "AbstractSignal",
    "GridSignal",
    "EMFSignal",
    "SampledSignal",
    "DriveRecording",
    "paper001_test",
    "stack",
    # metrics
    "lost_lock_of",
    # devices, processes, compile cache
    "use_host_devices",
    "init_distributed",
    "batch_mesh",
    "shard_batch",
    "batch_axes",
    "map_batch",
    "use_compile_cache",
    "kept_jit",
    "ProgramCache",
    "set_program_cache",
    "__version__",
]

try:  # one source: the version in pyproject.toml, as installed
    __version__ = _version("jaxobs")
except _PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"
