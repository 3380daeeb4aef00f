"""Scenario families: what a study or a tuning job runs a design on, and the one place a design is bound.

A family (:class:`AbstractFamily`) declares its axes (one :class:`~jaxobs.core.quantities.Axis` each), builds
a batch of scenarios from named points (:meth:`~AbstractFamily.build`) and makes the system one design
runs on one scenario (:meth:`~AbstractFamily.system`): an observer on a signal, or an observer closing
the drive's loop, bound to the scenario's assumed machine.

    fam = GridSignals(t_event=0.1, freq=50.0)
    batch = fam.build(("freq_step", "dc"), [(1.0, 0.0), (-1.0, 0.05)])
    sol = jaxobs.simulate(fam.system(fll, jax.tree.map(lambda x: x[0], batch)), 0.4)

The families:

- :class:`GridSignals`: single-phase grid voltages with an event (the FLL family), axes
  :data:`jaxobs.scenarios.GRID_SIGNAL_AXES`;
- :class:`EMFSignals`: two-axis back EMFs (the flux observers without a drive), axes
  :data:`jaxobs.scenarios.EMF_SIGNAL_AXES`;
- :class:`DriveScenarios`: the sensorless drive, each scenario started steady (its speed, its load, the
  observer settled before t = 0), axes :data:`DRIVE_STUDY_AXES` (of :data:`jaxobs.drive.DRIVE_AXES`);
- :class:`RecordedSignals`: recorded signals with their truth columns, given whole (one per file).

Each family is built by its own class: its constructor, or :meth:`~AbstractFamily.from_toml` from its TOML
table (a job's ``[scenarios]``, a study file's ``[study]``: the keys it owns, :attr:`~AbstractFamily.options`,
each checked with a ``ValueError`` naming the field) and what the run gives it (the design's nominal frequency,
the drive it closes).  A tuning job's ``scenarios.signal`` names its family: :data:`FAMILIES` maps the name to
the class, once.  Recordings of a family's signals are :meth:`AbstractFamily.recorded`: a
:class:`RecordedSignals` that holds what the recordings are (their columns, whether a design binds to them), the
files read by :func:`jaxobs.signals.read_recorded`.
"""

from __future__ import annotations

from ._base import AbstractFamily, DriveSetting, RecordedSignals, StudyPlan
from .drive import DRIVE_STUDY_AXES, DriveScenarios, bind_observer, drive_scenarios
from .signals import MAX_FREQ_STEP_FRACTION, EMFSignals, GridSignals

__all__ = [
    "AbstractFamily",
    "DRIVE_STUDY_AXES",
    "DriveScenarios",
    "DriveSetting",
    "EMFSignals",
    "FAMILIES",
    "GridSignals",
    "MAX_FREQ_STEP_FRACTION",
    "RecordedSignals",
    "StudyPlan",
    "bind_observer",
    "drive_scenarios",
]


# the base's first name, kept for code written against it: a family is not a batch of scenarios (docs/architecture.md,
# "Scenario, family, sampler")
AbstractScenarios = AbstractFamily

# a job file's ``scenarios.signal`` -> its family (the one place the name is read)
FAMILIES: dict[str, type[AbstractFamily]] = {f.signal: f for f in (GridSignals, EMFSignals, DriveScenarios)}
