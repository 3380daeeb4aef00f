"""Observers: the SOGI-FLL family (and, as they land, flux observers, LESOs and PLLs)."""

from .base import AbstractObserver as AbstractObserver, ObserverState as ObserverState
from .fll import FLLOutput as FLLOutput, SOGIFLL as SOGIFLL, SOGIFLLWIF as SOGIFLLWIF, SOGIFLLWPF as SOGIFLLWPF
from .sogi import QSGOutput as QSGOutput, SOGI as SOGI, SOGI2 as SOGI2
