"""Firmware export: an observer as C99 float32, checked against golden vectors from the JAX step.

    jaxobs export RESULT.json --out DIR        the tuned design of a ``jaxobs tune`` result
    jaxobs export --design wif --out DIR       a closed-form design (sogi-fll, wpf, wif)

writes to DIR:

- ``observer.h`` / ``observer.c``: ``jx_state``, ``jx_init(&s)``, ``jx_step(&s, u, y)``,
  ``JX_NU`` / ``JX_NY`` inputs and outputs per step.  The step is the JAX step itself,
  generated from the jaxpr of ``observer.step`` (:mod:`jaxobs_tuning.export.codegen`): the rule,
  the back EMF, the drive observers' memory of the previous sample and the step
  convention of :mod:`jaxobs.observers.base` are whatever the Python does, so any
  observer that follows the contract exports, a user's own included.  ``jx_state`` is the
  JAX state leaf by leaf, the gains are float32 macros ``JX_<NAME>``.  The header's
  comment gives the operation count per step (that of the emitted C);
- ``golden.csv``: a header line, then per step the ``JX_NU`` inputs and the ``JX_NY``
  outputs of the JAX step run in float32 (``lax.scan`` of ``observer.step``) over a
  test record of ≥ 10 000 samples: for an FLL a unit sine at ωn with a +2 Hz step at
  one third and a +40° phase jump at two thirds (:func:`fll_test_signal`); for a drive
  observer the u and i recorded in a sensored FOC drive of its family's machine (000's SPMSM
  for the flux observers, 002's IPMSM for the LESOs) with a speed step and a load step
  (:func:`drive_recording`; the CLI binds the observer to that machine's Rs, L and speed), or
  with ``--record synthetic`` the synthesized PMSM signal of :func:`drive_test_signal` (a +10 %
  speed step and a +30° angle jump on the observer's own Rs, L), or a recording passed as
  ``signal``;
- ``coefficients.json``: the gains, static options, rule, initial state, the step
  convention and the operation count;
- ``test_main.c``: the harness: replays golden.csv through ``jx_step`` and fails if
  max |y_C − y_golden| / (1 + |y_golden|) > 1e-4 at any step (angles compared modulo 2π).

:func:`compile_and_check` compiles the harness with the system C compiler
(``cc -std=c99 -O2 -Wall -Werror -pedantic``) and returns that error; the tests do
it for every observer family and rule and for the default job's result.  A drive
observer (flux observers, LESOs) reads (u_a, u_b, i_a, i_b) per step, any other
observer one sample ``v``; outputs named ``theta...`` are angles.

The C cannot be bit-identical to XLA's float32 (XLA contracts multiply-adds into FMAs
and rewrites divisions by constants), so the check is a tolerance, and the golden
records avoid the few instants where an output is discontinuous in the state: see
:func:`drive_test_signal` (the first period of the drive records, shaped the same way in
:func:`drive_recording`: unshaped, a pure integrator's θ̂ misses by 5e-2 rad and a Tustin
SOIFO's signed ω̂ flips, error 2).  Before writing, the export runs the emitted
statements in Python (float32 numpy) at random states and compares them with the JAX
step, so a code generator bug fails at export time, with or without a C compiler.
"""

from __future__ import annotations

from .command import add_export_parser as add_export_parser
from .command import cli_export as cli_export
from .files import EXPORT_FILES as EXPORT_FILES
from .files import export_observer as export_observer
from .golden import MIN_STEPS as MIN_STEPS
from .golden import drive_recording as drive_recording
from .golden import drive_test_signal as drive_test_signal
from .golden import fll_test_signal as fll_test_signal
from .harness import CFLAGS as CFLAGS
from .harness import TOLERANCE as TOLERANCE
from .harness import compile_and_check as compile_and_check
from .lower import SUPPORTED as SUPPORTED
from .sources import DESIGNS as DESIGNS
from .sources import observer_from_design as observer_from_design
from .sources import observer_from_result as observer_from_result
from .sources import parse_rule as parse_rule

__all__ = [
    "export_observer",
    "observer_from_result",
    "observer_from_design",
    "parse_rule",
    "compile_and_check",
    "fll_test_signal",
    "drive_test_signal",
    "drive_recording",
    "add_export_parser",
    "cli_export",
    "DESIGNS",
    "TOLERANCE",
    "MIN_STEPS",
    "CFLAGS",
    "EXPORT_FILES",
    "SUPPORTED",
]
