"""The runtime: the one time loop, its checkpoints, batches over devices, chunks and the program cache.

- :mod:`jaxobs.runtime.simulation`: ``simulate``, its ``Solution`` and the saving strategies;
- :mod:`jaxobs.runtime.onsignal`: an observer on a signal as a system (``OnSignal``, ``OnRows``);
- :mod:`jaxobs.runtime.sharding`: a batch over devices (``batch_mesh``, ``shard_batch``, ``map_batch``);
- :mod:`jaxobs.runtime.runner`: ``run_scenarios``, one runner over chunks, devices and processes;
- :mod:`jaxobs.runtime.chunkstore`: where the runner sends each chunk's values;
- :mod:`jaxobs.runtime.programs`: traced programs kept across processes (``kept_jit``);
- :mod:`jaxobs.runtime.cache`: JAX's persistent compilation cache;
- :mod:`jaxobs.runtime.progress`: progress of long calls.
"""

from ._loop import AbstractCheckpoint as AbstractCheckpoint
from ._loop import AbstractReverseCheckpoint as AbstractReverseCheckpoint
from ._loop import AutoCheckpoint as AutoCheckpoint
from ._loop import ChunkCheckpoint as ChunkCheckpoint
from ._loop import ForwardSensitivity as ForwardSensitivity
from ._loop import NoCheckpoint as NoCheckpoint
from ._loop import StepCheckpoint as StepCheckpoint
from .onsignal import OnSignal as OnSignal
from .onsignal import SignalOutput as SignalOutput
from .onsignal import SignalTruth as SignalTruth
from .simulation import AbstractSave as AbstractSave
from .simulation import PrecisionWarning as PrecisionWarning
from .simulation import SaveAll as SaveAll
from .simulation import SaveFinal as SaveFinal
from .simulation import Solution as Solution
from .simulation import simulate as simulate
