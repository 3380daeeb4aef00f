"""Test waveforms for signal-level observers, as scan-friendly functions of time, and recordings.

The contract in ``_base`` (AbstractSignal: what a signal declares; FunctionSignal: a plain function of time);
waveforms in ``_waveforms`` (GridSignal, EMFSignal, paper001_test, stack); recorded signals and their
CSV reader in ``_recordings`` (SampledSignal, DriveRecording, read_recording); drive logs as recorded: their
declared layout in ``_layout`` (RecordingLayout), their delimited text streamed into disk-backed columns in
``_logfile``, their checks in ``_logchecks``, the reader in ``_logs`` (read_drive_log, LogData); one recording
file as a family's scenarios, ``_read`` (read_recorded).

A :class:`GridSignal` is a PyTree whose leaves (amplitude, frequency, event
time, step sizes, harmonic magnitudes, …) may carry a leading batch axis; it is
called as ``sig(t)`` inside a scan or ``vmap``.  Every disturbance switches on
at ``t_event`` (one rule for all of them, so that a test is "settle, then
disturb"):

    θ(t) = ω₀ t + φ₀ + [t ≥ tₑ] (2π Δf (t − tₑ) + Δφ)
    v(t) = V₀ (1 − [t ≥ tₑ] sag) cos θ
           + [t ≥ tₑ] ( Σₕ Vₕ cos(h θ) + dc + V_sub cos(2π f_sub t) )

``sag`` is the *depth* of the sag (the amplitude falls by ``sag·V₀``).  Paper 001
writes "a 0.75 p.u. voltage sag" (Test 3) and "a 0.5 p.u. voltage sag" (Test B)
without saying whether the figure is the depth or the retained voltage; we read
it as the depth (Test 3 leaves 0.25 p.u.), the harder of the two readings.

Tests 1–3 (model accuracy, 001 Sec. V) and A–E (performance, 001 Sec. VI) are
built by :func:`paper001_test`.
"""

from ..core.sampletime import SampleTime as SampleTime
from ._base import AbstractSignal as AbstractSignal
from ._base import FunctionSignal as FunctionSignal
from ._layout import RecordingLayout as RecordingLayout
from ._layout import RecordingWarning as RecordingWarning
from ._logs import LogData as LogData
from ._logs import read_drive_log as read_drive_log
from ._read import read_recorded as read_recorded
from ._recordings import MAX_CSV_BYTES as MAX_CSV_BYTES
from ._recordings import DriveRecording as DriveRecording
from ._recordings import RecordingColumnError as RecordingColumnError
from ._recordings import SampledSignal as SampledSignal
from ._recordings import read_recording as read_recording
from ._waveforms import PAPER001_TESTS as PAPER001_TESTS
from ._waveforms import EMFSignal as EMFSignal
from ._waveforms import GridSignal as GridSignal
from ._waveforms import paper001_test as paper001_test
from ._waveforms import stack as stack
