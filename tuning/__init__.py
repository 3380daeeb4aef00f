"""Tuning jobs: objectives, gain parametrizations, optimizers (optax, optimistix), TOML jobs, CLI, results.

from tuning import load_job, run_job
from tuning import load_result, tuned_component     # a run's result.json back as a component
"""

from .job import COMPONENTS as COMPONENTS
from .job import JobError as JobError
from .job import load_job as load_job
from .job import parse_job as parse_job
from .job import run_job as run_job
from .objective import METRICS as METRICS
from .objective import Objective as Objective
from .objective import Term as Term
from .objective import aggregate as aggregate
from .params import GainSpec as GainSpec
from .params import Parametrization as Parametrization
from .results import load_result as load_result
from .results import tuned_component as tuned_component
from .solvers import SolverConfig as SolverConfig
from .solvers import run_solver as run_solver
