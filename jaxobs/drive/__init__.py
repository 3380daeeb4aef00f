"""The PMSM drive: machine, inverter, sensors, FOC, I-f start-up, scenarios, closed-loop scan."""

from .control import FOC as FOC
from .control import ControllerState as ControllerState
from .control import IfStartup as IfStartup
from .hardware import Inverter as Inverter
from .hardware import Sensors as Sensors
from .machine import (
    RPM as RPM,
)
from .machine import (
    PMSMParams as PMSMParams,
)
from .machine import (
    ab_to_dq as ab_to_dq,
)
from .machine import (
    bemf_ab as bemf_ab,
)
from .machine import (
    bemf_dq as bemf_dq,
)
from .machine import (
    dq_to_ab as dq_to_ab,
)
from .machine import (
    ipmsm_paper002 as ipmsm_paper002,
)
from .machine import (
    plant_vf as plant_vf,
)
from .machine import (
    spmsm_paper000 as spmsm_paper000,
)
from .machine import (
    torque as torque,
)
from .scenario import GRID_AXES as GRID_AXES
from .scenario import Batch as Batch
from .scenario import Profile as Profile
from .scenario import Scenario as Scenario
from .scenario import grid as grid
from .simulate import (
    Drive as Drive,
)
from .simulate import (
    DriveInput as DriveInput,
)
from .simulate import (
    DriveSolution as DriveSolution,
)
from .simulate import (
    plant_field as plant_field,
)
from .simulate import (
    simulate_drive as simulate_drive,
)
from .simulate import (
    simulate_plant_open_loop as simulate_plant_open_loop,
)
