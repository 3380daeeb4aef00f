"""Observers: the SOGI-FLL family, the SOGIs, the flux observers of 000, the LESOs of 002 and the reduced-order
flux observer (Hinkkanen et al. 2018, :mod:`jaxobs.observers.rofo`), on one contract.

:class:`AbstractObserver` is every observer; :class:`AbstractVectorFieldObserver` the ones given by a vector
field (FLL family, SOGIs); :class:`AbstractDriveObserver` the drive observers (flux observers, LESOs,
:class:`ObserverBank`), bound to a machine and a speed by their one ``bind`` method.  Each observer declares its
gains with :func:`gain` (units, role, bounds, the paper's symbol; :func:`gain_fields` lists them), and each one a
paper tunes has a closed form: ``closed_form_design`` gives a :class:`ClosedForm` (the observer with its inputs
and :class:`DesignRow` s: name, value, units, formula, source) and ``closed_form`` its observer (the rules'
arithmetic: ``sogi_fll_lambda``, ...).  :func:`check_gains` enforces every gain's declared bounds, once, after
every constructor.
A LESO and a PLL-type flux observer hold their speed and position extraction as a strategy
(:class:`AbstractSpeedEstimator`: :class:`PLLSpeed`, :class:`MechanicalSpeed`; :mod:`jaxobs.observers.speed`).
"""

from ._cores import sogi2_tustin_coefficients as sogi2_tustin_coefficients
from ._gains import ClosedForm as ClosedForm
from ._gains import DesignRow as DesignRow
from ._gains import GainInfo as GainInfo
from ._gains import check_gains as check_gains
from ._gains import gain as gain
from ._gains import gain_fields as gain_fields
from ._gains import gain_metadata as gain_metadata
from ._gains import gain_row as gain_row
from ._gains import gain_table as gain_table
from ._rules import cleso_gains as cleso_gains
from ._rules import pll_gains as pll_gains
from ._rules import second_order_soifo_lambda as second_order_soifo_lambda
from ._rules import sogi_fll_lambda as sogi_fll_lambda
from ._rules import soifo_lambda as soifo_lambda
from ._rules import symmetric_optimum_pm as symmetric_optimum_pm
from ._rules import wif_symmetric_optimum as wif_symmetric_optimum
from ._rules import wpf_lambda as wpf_lambda
from .base import AbstractDriveObserver as AbstractDriveObserver
from .base import AbstractObserver as AbstractObserver
from .base import AbstractVectorFieldObserver as AbstractVectorFieldObserver
from .base import AssumedMachine as AssumedMachine
from .base import BankOutput as BankOutput
from .base import BoundFields as BoundFields
from .base import DriveObserverState as DriveObserverState
from .base import ObserverBank as ObserverBank
from .base import ObserverState as ObserverState
from .faleso import FALESO as FALESO
from .fll import SOGIFLL as SOGIFLL
from .fll import SOGIFLLWIF as SOGIFLLWIF
from .fll import SOGIFLLWPF as SOGIFLLWPF
from .fll import FLLOutput as FLLOutput
from .flux import AbstractFluxObserver as AbstractFluxObserver
from .flux import FluxOutput as FluxOutput
from .flux import LPFFlux as LPFFlux
from .flux import PureIntegratorFlux as PureIntegratorFlux
from .leso import CLESO as CLESO
from .leso import GILESO as GILESO
from .leso import AbstractLESO as AbstractLESO
from .leso import LESOOutput as LESOOutput
from .rofo import ReducedOrderFluxObserver as ReducedOrderFluxObserver
from .rofo import ROFOOutput as ROFOOutput
from .sogi import SOGI as SOGI
from .sogi import SOGI2 as SOGI2
from .sogi import QSGOutput as QSGOutput
from .soifo import SOIFO as SOIFO
from .soifo import SecondOrderSOIFO as SecondOrderSOIFO
from .speed import AbstractSpeedEstimator as AbstractSpeedEstimator
from .speed import MechanicalSpeed as MechanicalSpeed
from .speed import PLLSpeed as PLLSpeed
