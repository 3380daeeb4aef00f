"""Tuning jobs: objectives, gain parametrizations, optimizers (optax, optimistix), TOML jobs, CLI, results.

    from tuning import load_job, run_job
"""

from .job import COMPONENTS as COMPONENTS, JobError as JobError, load_job as load_job, parse_job as parse_job, run_job as run_job
from .objective import METRICS as METRICS, Objective as Objective, Term as Term, aggregate as aggregate
from .params import GainSpec as GainSpec, Parametrization as Parametrization
from .solvers import SolverConfig as SolverConfig, run_solver as run_solver
