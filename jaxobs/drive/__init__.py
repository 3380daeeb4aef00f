"""The PMSM drive: machine, plant, inverter, sensors, FOC, I-f start-up, scenarios, the closed loop and the
simulated benches (:mod:`jaxobs.drive.bench`), a drive declared in a TOML file (:func:`load_drive`), and
paper 002's dual three-phase IPMSM (:mod:`jaxobs.drive.dual`, :mod:`jaxobs.drive.dual_loop`).

Every dynamic piece is a step component (``init``/``step``): :class:`PMSM`,
:class:`Inverter`, :class:`Sensors`, :class:`FOC`, and the system that wires
them with an observer, :class:`ClosedLoop`, which ``jaxobs.simulate`` runs.
"""

from ..core.measurements import DriveInput as DriveInput
from ._zerospeed import low_speed_load_step as low_speed_load_step
from ._zerospeed import reversal as reversal
from ._zerospeed import standstill_hold as standstill_hold
from .bench import IF_SUDDEN_LOAD_PU as IF_SUDDEN_LOAD_PU
from .bench import SHIPPED_DRIVES as SHIPPED_DRIVES
from .bench import bench_drive as bench_drive
from .bench import bench_machine as bench_machine
from .bench import drive_speed_limit_rpm as drive_speed_limit_rpm
from .bench import if_handover_earliest as if_handover_earliest
from .bench import if_load_limit as if_load_limit
from .bench import ipmsm_paper002 as ipmsm_paper002
from .bench import shipped_drive as shipped_drive
from .bench import spmsm_paper000 as spmsm_paper000
from .component import AbstractComponent as AbstractComponent
from .control import FOC as FOC
from .control import ControllerState as ControllerState
from .control import FOCInput as FOCInput
from .control import FOCOutput as FOCOutput
from .control import IfStartup as IfStartup
from .control import OperatingPoint as OperatingPoint
from .drivefile import DriveFile as DriveFile
from .drivefile import drive_from_table as drive_from_table
from .drivefile import load_drive as load_drive
from .drivefile import read_drive as read_drive
from .drivefile import speed_limit as speed_limit
from .dual import DualPMSM as DualPMSM
from .dual import DualPMSMParams as DualPMSMParams
from .dual import dual_ipmsm_paper002 as dual_ipmsm_paper002
from .dual import sets_to_vsd as sets_to_vsd
from .dual import vsd_matrix as vsd_matrix
from .dual import vsd_to_sets as vsd_to_sets
from .dual_loop import DualClosedLoop as DualClosedLoop
from .dual_loop import DualDrive as DualDrive
from .dual_loop import DualFOC as DualFOC
from .dual_loop import DualOutput as DualOutput
from .dual_loop import dual_bench_drive as dual_bench_drive
from .hardware import Inverter as Inverter
from .hardware import InverterInput as InverterInput
from .hardware import SensorInput as SensorInput
from .hardware import Sensors as Sensors
from .latency import AtSample as AtSample
from .latency import AtUse as AtUse
from .latency import Latency as Latency
from .latency import PeriodStart as PeriodStart
from .latency import PWMCentre as PWMCentre
from .loop import SETTLE_PERIODS as SETTLE_PERIODS
from .loop import ClosedLoop as ClosedLoop
from .loop import Drive as Drive
from .loop import DriveOutput as DriveOutput
from .loop import LoopInput as LoopInput
from .loop import LoopState as LoopState
from .machine import RPM as RPM
from .machine import PMSMParams as PMSMParams
from .machine import QSaturation as QSaturation
from .machine import ab_to_dq as ab_to_dq
from .machine import bemf_ab as bemf_ab
from .machine import bemf_dq as bemf_dq
from .machine import dq_to_ab as dq_to_ab
from .machine import lq_apparent as lq_apparent
from .machine import lq_incremental as lq_incremental
from .machine import plant_vf as plant_vf
from .machine import psi_f_from_ke as psi_f_from_ke
from .machine import psi_f_from_kt as psi_f_from_kt
from .machine import torque as torque
from .plant import PMSM as PMSM
from .plant import PlantInput as PlantInput
from .plant import PlantOutput as PlantOutput
from .plant import PlantState as PlantState
from .plant import plant_field as plant_field
from .scenario import DRIVE_AXES as DRIVE_AXES
from .scenario import Batch as Batch
from .scenario import ParameterDrift as ParameterDrift
from .scenario import Profile as Profile
from .scenario import Scenario as Scenario
from .scenario import grid as grid
from .scenario import scenario_batch as scenario_batch
from .scenario import stack_scenarios as stack_scenarios
from .weakening import VoltageFeedbackFW as VoltageFeedbackFW
