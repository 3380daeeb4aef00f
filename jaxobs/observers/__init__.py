"""Observers: the SOGI-FLL family (and, as they land, flux observers, LESOs and PLLs)."""

from .base import AbstractObserver as AbstractObserver, BankOutput as BankOutput, ObserverBank as ObserverBank, ObserverState as ObserverState
from .fll import FLLOutput as FLLOutput, SOGIFLL as SOGIFLL, SOGIFLLWIF as SOGIFLLWIF, SOGIFLLWPF as SOGIFLLWPF
from .sogi import QSGOutput as QSGOutput, SOGI as SOGI, SOGI2 as SOGI2
from .flux import FluxOutput as FluxOutput, LPFFlux as LPFFlux, PureIntegratorFlux as PureIntegratorFlux, SecondOrderSOIFO as SecondOrderSOIFO, SOIFO as SOIFO
from .leso import CLESO as CLESO, FALESO as FALESO, GILESO as GILESO, LESOOutput as LESOOutput
