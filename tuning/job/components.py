"""The tunable components: a view of :data:`jaxobs.studies.registry.REGISTRY` (its entries a job may name).

A component's constructor is its class, its free gains the class's gain fields, its closed form the class's
``closed_form_design`` (its gains: :func:`jaxobs.studies.registry.closed_form_gains`; its source line:
``ClosedForm.source``); the signals, machines and a job's initial values are the registry's.

A job whose ``[observer.speed]`` is a mechanical model may also tune that model's gains, ``speed.k1``, ``speed.k2``,
``speed.k3`` (the ``k1``, ``k2``, ``k3`` of :class:`jaxobs.observers.speed.MechanicalSpeed`; ``[gains.speed.k1]``
in a job file): their closed form is the triple pole at the record's ``alpha_o``
(:func:`jaxobs.observers.speed.mechanical_gains`), and a constructor takes them inside the ``speed`` record
(:meth:`ComponentInfo.values_with`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from jaxobs import papers
from jaxobs.observers.speed import MECHANICAL_GAINS, mechanical_gains
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

    def defaults_at(self, ts: float | None) -> dict:
        """A job's constructor values before its tables at the period the component runs at (a drive job's: its
        drive file's), the closed-form defaults that depend on it designed there
        (:meth:`jaxobs.studies.registry.Registered.defaults_at`).

        Args:
            ts: The period, s (None: the class's default).

        Returns:
            name -> value, with ``ts`` set where given.
        """
        out = self.entry.defaults_at(ts)
        if ts is not None:
            out["ts"] = float(ts)
        return out

    @property
    def closed_form_source(self) -> str:
        """The class's closed form's source, in one line (``ClosedForm.source``)."""
        return self.entry.closed_form_source

    def closed_form(self, component: object, values: Mapping[str, object] | None = None) -> dict:
        """The closed-form gains at a component's nominal frequency (the FLLs'), or the paper's; with a job's
        values whose ``speed`` record is a mechanical model, its gains ``speed.k1``, ``speed.k2``, ``speed.k3`` too
        (the triple pole at the record's ``alpha_o``, module doc).

        Args:
            component: An instance whose ``omega_n`` the closed form takes, or None.
            values: The job's constructor values (their ``speed`` record), or None.

        Returns:
            name -> float.
        """
        cf = closed_form_gains(self.entry.name, component)
        rec = None if values is None else values.get("speed")
        if isinstance(rec, dict) and rec.get("kind") == "mechanical":
            cf.update({f"speed.{k}": v for k, v in zip(MECHANICAL_GAINS, mechanical_gains(float(rec["alpha_o"])))})
        return cf

    def values_with(self, values: Mapping[str, object], gains: Mapping[str, float]) -> dict:
        """The constructor values ``values`` with the gains ``gains`` set: a plain name as a value, a dotted one
        (``speed.k1``) inside the record it names (module doc).

        Args:
            values: The constructor values (a job's ``values``).
            gains: name -> value.

        Returns:
            The constructor values, ``values`` itself untouched.
        """
        out = dict(values)
        for name, v in gains.items():
            head, _, leaf = name.partition(".")
            if leaf:
                rec = out[head]
                assert isinstance(rec, Mapping), f"{head}: a dotted gain names a record"  # the job's parser checks it
                out[head] = {**rec, leaf: float(v)}
            else:
                out[name] = v
        return out


COMPONENTS = {name: ComponentInfo(e) for name, e in REGISTRY.items() if e.tunable}
