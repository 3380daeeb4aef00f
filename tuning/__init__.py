"""Tuning jobs: objectives, gain parametrizations, optimizers (optax, optimistix), TOML jobs, CLI, results.

```python
from jaxobs_tuning import load_job, run_job
from jaxobs_tuning import Objective, tune, CVaR
    # in Python: tune(Objective(..., aggregation=CVaR(0.9)), optax.adam(0.1), scenarios=batch)
from jaxobs_tuning import load_result, tuned_component     # a run's result.json back as a component
```
"""

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
