"""Observers: the SOGI-FLL family (and, as they land, flux observers, LESOs and PLLs)."""

from ._cores import sogi2_tustin_coefficients as sogi2_tustin_coefficients
from .base import AbstractObserver as AbstractObserver
from .base import BankOutput as BankOutput
from .base import ObserverBank as ObserverBank
from .base import ObserverState as ObserverState
from .fll import SOGIFLL as SOGIFLL
from .fll import SOGIFLLWIF as SOGIFLLWIF
from .fll import SOGIFLLWPF as SOGIFLLWPF
from .fll import FLLOutput as FLLOutput
from .flux import SOIFO as SOIFO
from .flux import FluxOutput as FluxOutput
from .flux import LPFFlux as LPFFlux
from .flux import PureIntegratorFlux as PureIntegratorFlux
from .flux import SecondOrderSOIFO as SecondOrderSOIFO
from .leso import CLESO as CLESO
from .leso import FALESO as FALESO
from .leso import GILESO as GILESO
from .leso import LESOOutput as LESOOutput
from .sogi import SOGI as SOGI
from .sogi import SOGI2 as SOGI2
from .sogi import QSGOutput as QSGOutput
