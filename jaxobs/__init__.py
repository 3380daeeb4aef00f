"""jaxobs — a differentiable JAX simulator for tuning sensorless motor-drive observers and FLLs."""

from . import drive as drive, linear as linear, metrics as metrics, signals as signals
from .discretize import AB3 as AB3, Euler as Euler, Held as Held, Knots as Knots, RK4 as RK4, Tustin as Tustin
from .observers import (
    CLESO as CLESO,
    FALESO as FALESO,
    FLLOutput as FLLOutput,
    GILESO as GILESO,
    LPFFlux as LPFFlux,
    ObserverBank as ObserverBank,
    PureIntegratorFlux as PureIntegratorFlux,
    SecondOrderSOIFO as SecondOrderSOIFO,
    SOIFO as SOIFO,
    ObserverState as ObserverState,
    SOGI as SOGI,
    SOGI2 as SOGI2,
    SOGIFLL as SOGIFLL,
    SOGIFLLWIF as SOGIFLLWIF,
    SOGIFLLWPF as SOGIFLLWPF,
)
from .signals import GridSignal as GridSignal, paper001_test as paper001_test, stack as stack
from .simulate import SignalSolution as SignalSolution, simulate as simulate

__version__ = "0.1.0"
