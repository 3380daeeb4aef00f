"""Tuning jobs: objectives, gain parametrizations, optimizers (optax, optimistix), TOML jobs, CLI, results.

```python
from jaxobs_tuning import load_job, run_job
from jaxobs_tuning import Objective, tune, CVaR
    # in Python: tune(Objective(..., aggregation=CVaR(0.9)), optax.adam(0.1), scenarios=batch)
from jaxobs_tuning import load_result, tuned_component     # a run's result.json back as a component
```
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

# name -> the module that defines it: imported on first use (PEP 562), so that the console script's
# `jaxobs --help` (jaxobs_tuning.cli_entry) does not import JAX; `from jaxobs_tuning import X` is unchanged
_LAZY = {
    "AbstractAggregation": ".aggregations",
    "CVaR": ".aggregations",
    "Mean": ".aggregations",
    "SmoothMax": ".aggregations",
    "AbstractObjective": ".base",
    "COMPONENTS": ".job",
    "JobError": ".job",
    "load_job": ".job",
    "parse_job": ".job",
    "run_job": ".job",
    "TERM_METRICS": ".objective",
    "Objective": ".objective",
    "Term": ".objective",
    "GainSpec": ".params",
    "Parametrization": ".params",
    "load_result": ".results",
    "tuned_component": ".results",
    "AbstractSolver": ".solvers",
    "OptaxSolver": ".solvers",
    "OptimistixSolver": ".solvers",
    "tune": ".solvers",
}
__all__ = [
    "AbstractAggregation",
    "CVaR",
    "Mean",
    "SmoothMax",
    "AbstractObjective",
    "COMPONENTS",
    "JobError",
    "load_job",
    "parse_job",
    "run_job",
    "TERM_METRICS",
    "Objective",
    "Term",
    "GainSpec",
    "Parametrization",
    "load_result",
    "tuned_component",
    "AbstractSolver",
    "OptaxSolver",
    "OptimistixSolver",
    "tune",
]

if TYPE_CHECKING:  # the names as a type checker and an editor see them
    from .aggregations import AbstractAggregation as AbstractAggregation
    from .aggregations import CVaR as CVaR
    from .aggregations import Mean as Mean
    from .aggregations import SmoothMax as SmoothMax
    from .base import AbstractObjective as AbstractObjective
    from .job import COMPONENTS as COMPONENTS
    from .job import JobError as JobError
    from .job import load_job as load_job
    from .job import parse_job as parse_job
    from .job import run_job as run_job
    from .objective import TERM_METRICS as TERM_METRICS
    from .objective import Objective as Objective
    from .objective import Term as Term
    from .params import GainSpec as GainSpec
    from .params import Parametrization as Parametrization
    from .results import load_result as load_result
    from .results import tuned_component as tuned_component
    from .solvers import AbstractSolver as AbstractSolver
    from .solvers import OptaxSolver as OptaxSolver
    from .solvers import OptimistixSolver as OptimistixSolver
    from .solvers import tune as tune


def __getattr__(name: str) -> Any:
    """A public name, its module imported on first use.

    Args:
        name: The attribute asked for.

    Returns:
        The name's value (kept in the package's namespace after the first use).

    Raises:
        AttributeError: Not a public name of the package.
    """
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})
