"""The recordings reader: one recording file as the scenarios a family runs.

A grid voltage is a :class:`~jaxobs.signals.SampledSignal` (:meth:`~jaxobs.signals.SampledSignal.from_csv`); a
drive's u and i a :class:`~jaxobs.signals.DriveRecording`, read as a drive log (:func:`read_drive_log`: its layout,
timing and consistency checks), resampled after its layout's conversions where its rate is not the observer's.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any, Literal, overload

from ..core.sampletime import TS_REL_TOL
from ._layout import ColumnSpec, RecordingLayout
from ._logchecks import MachineConstants
from ._logs import read_drive_log
from ._recordings import DriveRecording, SampledSignal

__all__ = ["read_recorded"]


@overload
def read_recorded(
    path: str | os.PathLike[str],
    columns: Sequence[ColumnSpec],
    truth: Sequence[ColumnSpec],
    *,
    drive: Literal[False],
    **kw: Any,
) -> SampledSignal: ...


@overload
def read_recorded(
    path: str | os.PathLike[str],
    columns: Sequence[ColumnSpec],
    truth: Sequence[ColumnSpec],
    *,
    drive: bool,
    layout: RecordingLayout | None = None,
    machine: MachineConstants | None = None,
    windows: tuple[int, int] | None = None,
    voltages: int | None = None,
    **kw: Any,
) -> SampledSignal | DriveRecording | list[DriveRecording]: ...


def read_recorded(
    path: str | os.PathLike[str],
    columns: Sequence[ColumnSpec],
    truth: Sequence[ColumnSpec],
    *,
    drive: bool,
    layout: RecordingLayout | None = None,
    machine: MachineConstants | None = None,
    windows: tuple[int, int] | None = None,
    voltages: int | None = None,
    **kw: Any,
) -> SampledSignal | DriveRecording | list[DriveRecording]:
    """One recording file as scenarios.

    Args:
        path: the CSV file.
        columns: a grid voltage's column (``columns[0]``), or the voltage then the current columns, two each
            (u_α, u_β, i_α, i_β, or in ``layout``'s frames) or three each (``abc``).
        truth: the phase, frequency and amplitude columns (grid), or the encoder's angle and speed.
        drive: whether the file is a drive's u and i (a drive observer's), not a grid voltage (an FLL's).
        layout: what a drive log's columns hold (:class:`RecordingLayout`; default the sidecar ``<path>.toml``,
            else the observers' own form).
        machine: a :class:`~jaxobs.drive.PMSMParams` for the log's power and timing checks, or None.
        windows: ``(count, n)``: ``count`` windows of ``n`` samples spread evenly over a drive log, each a
            scenario starting at its own speed; None: the whole file.
        voltages: How many of a drive log's ``columns`` are its voltages, the currents following (2 or 3 each, as
            the layout's frames take them); None: half of them.
        **kw: the time base (``time_column``, ``sample_rate``, ``ts``) and ``max_bytes``.

    Returns:
        A :class:`SampledSignal` (a grid voltage), a :class:`DriveRecording` (u and i), or a list of ``count`` of
        them (``windows``).

    Raises:
        ValueError: what :func:`read_drive_log` or ``from_csv`` refuses, in one line; windows on a log sampled at
            another rate than ``ts`` (a log at another rate is read with its layout and resampled:
            :meth:`LogData.resampled`).
    """
    if not drive:
        return SampledSignal.from_csv(path, columns=columns[0], truth=truth, **kw)
    ts = kw.get("ts")
    nv = len(columns) // 2 if voltages is None else int(voltages)  # 2 + 2 columns, 3 + 3 (abc), 2 + 3, 3 + 2
    log = read_drive_log(
        path,
        voltages=columns[:nv],
        currents=columns[nv:],
        theta_e=truth[0],
        omega_e=truth[1] if len(truth) > 1 else None,
        time_column=kw.get("time_column"),
        sample_rate=kw.get("sample_rate"),
        layout=layout,
        machine=machine,
        max_bytes=kw.get("max_bytes"),
    )
    if ts is None or abs(log.ts - ts) <= TS_REL_TOL * ts:  # the one sample-interval tolerance
        if windows is None:
            return log.recording()
        count, n = windows
        if log.n < n:
            raise ValueError(f"recording {str(path)!r}: {log.n} samples, fewer than a window's {n}")
        starts = [round(i * (log.n - n) / max(count - 1, 1)) for i in range(count)]
        return [log.recording(a, n) for a in starts]
    # another rate: the log as read, its layout's conversions made, resampled (its checks have run on it as it is)
    if windows is not None:
        raise ValueError(
            f"recording {str(path)!r}: sampled at {1 / log.ts:.6g} Hz, not at the observer's {1 / ts:.6g} Hz: "
            "windows are cut at the log's own rate (resample it, or set ts)"
        )
    return log.resampled(ts)
