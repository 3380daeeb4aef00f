"""jaxobs — a differentiable JAX simulator for tuning sensorless motor-drive observers and FLLs.

Importing it has no side effects: no environment variable or JAX option
changes.  To run a sharded batch on every CPU core, call
:func:`jaxobs.use_host_devices` before the first JAX computation.
"""

from importlib.metadata import PackageNotFoundError as _PackageNotFoundError
from importlib.metadata import version as _version

from . import drive as drive
from . import linear as linear
from . import metrics as metrics
from . import signals as signals
from ._cache import use_compile_cache as use_compile_cache
from ._loop import AbstractCheckpoint as AbstractCheckpoint
from ._loop import AutoCheckpoint as AutoCheckpoint
from ._loop import ChunkCheckpoint as ChunkCheckpoint
from ._loop import ForwardSensitivity as ForwardSensitivity
from ._loop import NoCheckpoint as NoCheckpoint
from ._loop import StepCheckpoint as StepCheckpoint
from ._time import SampleTime as SampleTime
from .discretize import AB3 as AB3
from .discretize import RK4 as RK4
from .discretize import Euler as Euler
from .discretize import Held as Held
from .discretize import Knots as Knots
from .discretize import Tustin as Tustin
from .measurements import DriveInput as DriveInput
from .metrics import lost_lock_of as lost_lock_of
from .observers import (
    CLESO as CLESO,
)
from .observers import (
    FALESO as FALESO,
)
from .observers import (
    GILESO as GILESO,
)
from .observers import (
    SOGI as SOGI,
)
from .observers import (
    SOGI2 as SOGI2,
)
from .observers import (
    SOGIFLL as SOGIFLL,
)
from .observers import (
    SOGIFLLWIF as SOGIFLLWIF,
)
from .observers import (
    SOGIFLLWPF as SOGIFLLWPF,
)
from .observers import (
    SOIFO as SOIFO,
)
from .observers import (
    FLLOutput as FLLOutput,
)
from .observers import (
    LPFFlux as LPFFlux,
)
from .observers import (
    ObserverBank as ObserverBank,
)
from .observers import (
    ObserverState as ObserverState,
)
from .observers import (
    PureIntegratorFlux as PureIntegratorFlux,
)
from .observers import (
    SecondOrderSOIFO as SecondOrderSOIFO,
)
from .sharding import batch_mesh as batch_mesh
from .sharding import init_distributed as init_distributed
from .sharding import map_batch as map_batch
from .sharding import shard_batch as shard_batch
from .sharding import use_host_devices as use_host_devices
from .signals import DriveRecording as DriveRecording
from .signals import GridSignal as GridSignal
from .signals import SampledSignal as SampledSignal
from .signals import paper001_test as paper001_test
from .signals import stack as stack
from .simulate import AbstractSave as AbstractSave
from .simulate import OnSignal as OnSignal
from .simulate import PrecisionWarning as PrecisionWarning
from .simulate import SaveAll as SaveAll
from .simulate import SaveFinal as SaveFinal
from .simulate import SignalOutput as SignalOutput
from .simulate import SignalTruth as SignalTruth
from .simulate import Solution as Solution
from .simulate import simulate as simulate
from .system import AbstractSystem as AbstractSystem

try:  # one source: the version in pyproject.toml, as installed
    __version__ = _version("jaxobs")
except _PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"
