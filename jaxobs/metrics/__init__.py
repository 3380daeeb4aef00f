"""Metrics: the functions that score a trajectory, and the one metric table.

- :mod:`jaxobs.metrics._core`: metrics on simulated trajectories, exact and smooth (``settling_time``, ``rms``,
  ``smooth_settling_time``, ...), each a function of arrays;
- :mod:`jaxobs.metrics._lock`: lost lock and lost speed, the flags of a run, and the position error of a
  :class:`~jaxobs.Solution` (``lost_lock``, ``lost_lock_of``, ``lost_speed``, ``position_error``);
- :mod:`jaxobs.metrics._table`: :data:`METRICS`, one :class:`Metric` per quantity a study, a tuning job or an
  envelope reports (SI units; flags are boolean metrics, the stability margin a system metric), display units as
  a presentation transform, and :data:`ALIASES`, the old names read on input (:func:`canonical`).
"""

from . import _core, _lock
from ._core import *  # noqa: F403
from ._lock import *  # noqa: F403
from ._table import ALIASES as ALIASES
from ._table import DISPLAY as DISPLAY
from ._table import DIVERGED as DIVERGED
from ._table import METRICS as METRICS
from ._table import Alias as Alias
from ._table import Metric as Metric
from ._table import MetricContext as MetricContext
from ._table import MetricNameWarning as MetricNameWarning
from ._table import canonical as canonical
from ._table import scored_position_error as scored_position_error

__all__ = [
    "ALIASES",
    "DISPLAY",
    "DIVERGED",
    "METRICS",
    "Alias",
    "Metric",
    "MetricContext",
    "MetricNameWarning",
    "canonical",
    "scored_position_error",
]
__all__ += _core.__all__  # the forms a type checker follows
__all__ += _lock.__all__
