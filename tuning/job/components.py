"""The tunable components: a view of :data:`jaxobs.studies.registry.REGISTRY` (its entries a job may name).

A component's constructor is its class, its free gains the class's gain fields, its closed form the class's
``closed_form_design`` (its gains: :func:`jaxobs.studies.registry.closed_form_gains`; its source line:
``ClosedForm.source``); the signals, machines and a job's initial values are the registry's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from jaxobs import papers
from jaxobs.studies.registry import REGISTRY, Registered, closed_form_gains

W_N = papers.FLL_OMEGA_N


@dataclass(frozen=True)
class ComponentInfo:
    """A tunable component: its registry entry, read as a job reads it (the entry's facts read once, when built).

    Attributes:
        entry: The :class:`jaxobs.studies.registry.Registered` entry.
        ctor: The component's class (its constructor).
        gains: The names of its tunable gains.
        defaults: A job's constructor values before its ``[component]`` and ``[gains]`` tables.
        signal: The scenario signal a job runs it on by default (``"grid"``, ``"emf"`` or ``"drive"``).
        signals: The scenario signals this component runs on, its default first.
        machines: The machines a sensorless drive job may run it on, the default first (empty: no drive jobs).
    """

    entry: Registered
    ctor: type = field(init=False)
    gains: tuple[str, ...] = field(init=False)
    defaults: dict = field(init=False)
    signal: str = field(init=False)
    signals: tuple[str, ...] = field(init=False)
    machines: tuple[str, ...] = field(init=False)

    def __post_init__(self) -> None:
        e = self.entry
        facts = dict(ctor=e.cls, gains=e.gains, defaults=e.defaults, signal=e.signal, signals=e.signals)
        for name, value in {**facts, "machines": e.machines}.items():
            object.__setattr__(self, name, value)  # a frozen dataclass's fields, set once

    @property
    def closed_form_source(self) -> str:
        """The class's closed form's source, in one line (``ClosedForm.source``)."""
        return self.entry.closed_form_source

    def closed_form(self, component: object) -> dict:
        """The closed-form gains at a component's nominal frequency (the FLLs'), or the paper's.

        Args:
            component: An instance whose ``omega_n`` the closed form takes, or None.

        Returns:
            name -> float.
        """
        return closed_form_gains(self.entry.name, component)


COMPONENTS = {name: ComponentInfo(e) for name, e in REGISTRY.items() if e.tunable}
