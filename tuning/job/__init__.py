"""TOML tuning jobs: parse, validate (every error names its field), build, run, report.

The modules, lowest first: ``fields`` (JobError, typed getters), ``toml`` (safe reading), ``components``
(what can be tuned), ``spec`` (the parsed job as data), ``recordings`` and ``drive`` (their tables),
``verify`` (``[envelope]`` and the long-horizon verification after tuning), ``schema`` (the whole file),
``scenarios`` (the batched signals), ``output`` (what is written), ``run``.

A job file::

    [job]
    name = "wif-robust"
    component = "SOGIFLLWIF"        # SOGIFLL | SOGIFLLWPF | SOGIFLLWIF | SOIFO | SecondOrderSOIFO | LPFFlux
                                     # | CLESO | GILESO | FALESO
    seed = 0

    [component]                      # constructor values; frozen unless listed in [gains]
    k1 = 1.815
    k2 = 0.752
    lam = 11559.0

    [gains.lam]                      # a free gain: initial value, bounds, log parametrization
    init = 11559.0
    lower = 1000.0
    upper = 100000.0
    log = true

    [scenarios]                      # "grid" signals for the FLL family, "emf" for flux observers,
                                     # "drive" for the drive observers (LESOs, LPFFlux, the SOIFOs)
    signal = "grid"
    t_event = 0.1
    horizon = 0.4
    steady_from = 0.3
    [scenarios.grid]                 # cartesian product of named axes
    freq_step = [-2.0, 2.0]
    phase_jump_deg = [-30.0, 30.0]

    [holdout]                        # optional: a held-out set, scored but never tuned on
    [holdout.grid]
    freq_step = [-1.5, 1.5]

    [drive]                          # drive jobs only (scenarios.signal = "drive")
    loop = "sensorless"              # sensorless (the tuned observer closes the loop) | sensored
    machine = "spmsm000"             # ipmsm002 | spmsm000 (shipped drive files); default: the component's
    # file = "my_drive.toml"         # or the user's drive file (relative to the job), or its tables inline:
                                     # [drive.machine], [drive.inverter], ... (jaxobs.drive.read_drive)
    speed_schedule = 6.0             # the FOC's speed loop at min(α_s, |ωe*|/N); 0 (default): off
    [envelope]                       # drive jobs: the envelope claimed, verified after tuning (verify)
    speed_rpm = [200.0, 2000.0]      # [lo, hi]; default: the span of the tuning grid
    load_nm = [0.0, 5.0]
    horizon = 2.0                    # s, each verification run
    ideal_sensors = false            # default: through the drive file's [sensors]; true: ideal sensors

    [objective]
    terms = [{ metric = "itae_freq", weight = 1.0 }]
    aggregate = "cvar"               # mean | max | cvar
    alpha = 0.9
    penalty = 1000.0

    [solver]
    kind = "adam"                    # adam | adamw | sgd | bfgs
    learning_rate = 0.05
    steps = 60
    patience = 20
    checkpoint_every = 5
"""

from .components import COMPONENTS as COMPONENTS
from .components import ComponentInfo as ComponentInfo
from .drive import DRIVE_TABLES as DRIVE_TABLES
from .drive import check_speed_axes as check_speed_axes
from .drive import drive_source as drive_source
from .drive import job_drive as job_drive
from .fields import MAX_SCENARIOS as MAX_SCENARIOS
from .fields import MAX_STEPS as MAX_STEPS
from .fields import JobError as JobError
from .fields import axes_field as axes_field
from .fields import cap as cap
from .fields import get_field as get_field
from .fields import no_unknown as no_unknown
from .fields import show as show
from .output import rule_spec as rule_spec
from .output import write_json as write_json
from .recordings import load_recordings as load_recordings
from .recordings import parse_recording_scenarios as parse_recording_scenarios
from .run import CHECKPOINT as CHECKPOINT
from .run import build_objective as build_objective
from .run import run_job as run_job
from .schema import AXIS_RANGES as AXIS_RANGES
from .schema import available_memory as available_memory
from .schema import freq_step_range as freq_step_range
from .schema import load_job as load_job
from .schema import parse_job as parse_job
from .spec import DriveSpec as DriveSpec
from .spec import Job as Job
from .spec import RecordingSpec as RecordingSpec
from .spec import ScenarioSpec as ScenarioSpec
from .toml import read_toml as read_toml
from .verify import UNSAFE_EXIT as UNSAFE_EXIT
from .verify import EnvelopeSpec as EnvelopeSpec
from .verify import verify_designs as verify_designs
