"""jaxobs — a differentiable JAX simulator for tuning sensorless motor-drive observers and FLLs.

The names below are the user API (``__all__``); everything else lives in the
subpackages, each a layer of the library (docs/architecture.md):

- :mod:`jaxobs.core`: the foundations (discretization rules, measurements, the system contract, quantities);
- :mod:`jaxobs.signals`, :mod:`jaxobs.drive`: the test signals and recordings, the plant and the closed loop;
- :mod:`jaxobs.observers`: the observers and their contract;
- :mod:`jaxobs.runtime`: the one time loop (``simulation``, ``onsignal``), its checkpoints, batches over
  devices (``sharding``), the study runner (``runner``, ``chunkstore``) and the program caches
  (``programs``, ``cache``);
- :mod:`jaxobs.metrics`, :mod:`jaxobs.linear`, :mod:`jaxobs.analysis`: scoring, linear analysis, stability;
- :mod:`jaxobs.scenarios`, :mod:`jaxobs.studies`: scenario families and samplers, studies over them;
- :mod:`jaxobs.io`, :mod:`jaxobs.plot`, :mod:`jaxobs.reproduce`, :mod:`jaxobs.papers`: files, figures, the
  papers' reproductions.

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
from . import runtime as runtime
from . import scenarios as scenarios
from . import signals as signals

# discretization rules (strategy objects every observer and the plant take)
from .core.discretize import AB3 as AB3
from .core.discretize import RK4 as RK4
from .core.discretize import AbstractRule as AbstractRule
from .core.discretize import Euler as Euler
from .core.discretize import Tustin as Tustin

# what a drive observer is given each period
from .core.measurements import DriveInput as DriveInput
from .core.sampletime import SampleTime as SampleTime
from .core.system import AbstractSystem as AbstractSystem
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

# checkpoint strategies of the loop (how gradients through a long horizon are computed)
from .runtime import AbstractCheckpoint as AbstractCheckpoint
from .runtime import AbstractReverseCheckpoint as AbstractReverseCheckpoint
from .runtime import AutoCheckpoint as AutoCheckpoint
from .runtime import ChunkCheckpoint as ChunkCheckpoint
from .runtime import ForwardSensitivity as ForwardSensitivity
from .runtime import NoCheckpoint as NoCheckpoint
from .runtime import StepCheckpoint as StepCheckpoint

# running a process: compile cache, devices, several processes
from .runtime.cache import use_compile_cache as use_compile_cache
from .runtime.programs import ProgramCache as ProgramCache
from .runtime.programs import kept_jit as kept_jit
from .runtime.programs import set_program_cache as set_program_cache
from .runtime.sharding import batch_axes as batch_axes
from .runtime.sharding import batch_mesh as batch_mesh
from .runtime.sharding import init_distributed as init_distributed
from .runtime.sharding import map_batch as map_batch
from .runtime.sharding import shard_batch as shard_batch
from .runtime.sharding import use_host_devices as use_host_devices

# the one loop over a system, and what to save
from .runtime.simulation import AbstractSave as AbstractSave
from .runtime.simulation import OnSignal as OnSignal
from .runtime.simulation import PrecisionWarning as PrecisionWarning
from .runtime.simulation import SaveAll as SaveAll
from .runtime.simulation import SaveFinal as SaveFinal
from .runtime.simulation import SignalOutput as SignalOutput
from .runtime.simulation import SignalTruth as SignalTruth
from .runtime.simulation import Solution as Solution
from .runtime.simulation import simulate as simulate

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
    "runtime",
    "scenarios",
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
