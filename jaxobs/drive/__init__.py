"""The PMSM drive: machine, inverter, sensors, FOC, I-f start-up, scenarios, closed-loop scan."""

from .control import FOC as FOC, ControllerState as ControllerState, IfStartup as IfStartup
from .hardware import Inverter as Inverter, Sensors as Sensors
from .machine import (
    RPM as RPM,
    PMSMParams as PMSMParams,
    ab_to_dq as ab_to_dq,
    bemf_ab as bemf_ab,
    bemf_dq as bemf_dq,
    dq_to_ab as dq_to_ab,
    ipmsm_paper002 as ipmsm_paper002,
    plant_vf as plant_vf,
    spmsm_paper000 as spmsm_paper000,
    torque as torque,
)
from .scenario import GRID_AXES as GRID_AXES, Batch as Batch, Profile as Profile, Scenario as Scenario, grid as grid
from .simulate import (
    Drive as Drive,
    DriveInput as DriveInput,
    DriveSolution as DriveSolution,
    plant_field as plant_field,
    simulate_drive as simulate_drive,
    simulate_plant_open_loop as simulate_plant_open_loop,
)
