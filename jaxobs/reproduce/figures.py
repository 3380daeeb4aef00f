"""The reproduced experiments drawn in their paper's layout (:func:`jaxobs.plot.paper_figure`): one column
per method as the paper's (a), (b), (c) ..., estimated over actual and the error, with units.

Each figure is a row of a table (:data:`FLUX_FIGURES`): the experiment's trace key (as
:func:`jaxobs.reproduce.flux.run_flux_experiments` names it), the file, the paper's figure, the methods drawn,
the panels, and the time window.  The panels of paper 000's figures:

- ``position``: θ̂e over θe (rad, wrapped to [0, 2π)) and the error θ̂e − θe (rad): Figs 12, 15, 17;
- ``dynamic``: the speed estimate over the speed (r/min) and the error (rad): Figs 18–20 (and 002's Figs 16–17;
  ``weakening`` adds the drive's i_d over its reference between them, A: 002's ramp on a 330 V link);
- ``flux``: ψ̂α, ψ̂β over the rotor's ψf cos θe, ψf sin θe (Wb), θ̂e over θe and the error: Figs 16, 21–23.

Paper 001's Tests 1–3 and A–E (:func:`fll_figure`): a column per FLL, f̂ over f (Hz), V̂ over V (p.u.) and
the phase error (deg), around the test's event.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..metrics import wrap
from ..plot import Panel, Series, drive_events, fll_event_text, paper_figure
from ._run import Run

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["FLUX_FIGURES", "LESO_FIGURES", "drive_figure", "flux_figure", "flux_figures", "fll_figure"]

_ALL = ("integrator", "LPF", "SOIFO", "second-order SOIFO")
_THREE = ("LPF", "SOIFO", "second-order SOIFO")
_SOSO = ("second-order SOIFO",)

# (trace key, file, paper's figure, methods, panels, window): the window (s) is (start, stop), a negative
# start counting back from the run's end
FLUX_FIGURES = (
    ("steady 2000 r/min", "fig12_position_2000rpm.png", "Fig. 12", _ALL, "position", (-0.02, None)),
    ("steady 400 r/min", "fig15_position_400rpm.png", "Fig. 15", _ALL, "position", (-0.05, None)),
    ("steady 20 r/min", "fig16_17_flux_position_20rpm.png", "Figs 16–17", _SOSO, "flux", (-2.0, None)),
    ("speed 400-2000-400 r/min", "fig18_speed_variation.png", "Fig. 18", _THREE, "dynamic", (0.8, None)),
    ("load step 10 N·m at 2000 r/min", "fig19_load_step_2000rpm.png", "Fig. 19", _THREE, "dynamic", (0.3, None)),
    (
        "load step 10 N·m at 2000 r/min, dead time 1 µs",
        "fig19_load_step_2000rpm_dead_time.png",
        "Fig. 19",
        _THREE,
        "dynamic",
        (0.3, None),
    ),
    (
        "I-f start, 20 -> 200 r/min, 0.5 N·m step",
        "fig20_if_start_low_speed.png",
        "Fig. 20",
        _SOSO,
        "dynamic",
        (0, None),
    ),
    ("du_alpha = 5 V at 1000 r/min", "fig21_du_alpha_5V.png", "Fig. 21", _THREE, "flux", (-0.06, None)),
    (
        "du_alpha = 5 V at 1000 r/min, dead time 1 µs",
        "fig21_du_alpha_5V_dead_time.png",
        "Fig. 21",
        _THREE,
        "flux",
        (-0.06, None),
    ),
    ("di_beta = 1.5 A at 1000 r/min", "fig22_di_beta_1.5A.png", "Fig. 22", _THREE, "flux", (-0.06, None)),
    (
        "di_beta = 1.5 A at 1000 r/min, dead time 1 µs",
        "fig22_di_beta_1.5A_dead_time.png",
        "Fig. 22",
        _THREE,
        "flux",
        (-0.06, None),
    ),
    ("Rs_est = 0.4 Rs0, 10 N·m, 1000 r/min", "fig23_rs_mismatch.png", "Fig. 23", _THREE, "flux", (-0.06, None)),
)


# Paper 002's Figs 16-17 (the FA-LESO closing the loop; each LESO's estimate beside it), as FLUX_FIGURES
_LESO = ("C-LESO", "GI-LESO", "FA-LESO")
LESO_FIGURES = (
    (
        "speed ramp 300-600-840-600-300 r/min",
        "leso_fig16_speed_ramp_layout.png",
        "Fig. 16",
        _LESO,
        "dynamic",
        (0.4, None),
    ),
    ("load step 0-80 % at 600 r/min", "leso_fig17_load_step_layout.png", "Fig. 17", _LESO, "dynamic", (0.4, None)),
    # the ramp on a 330 V link, where the field weakening acts at 840 r/min (its i_d drawn beneath), the FA-LESO
    # closing the loop on a 2.5 Hz speed loop (jaxobs.reproduce.leso, SENSORLESS_FW_SPEED_HZ); the only LESO
    # closing it, so its column alone
    (
        "speed ramp 300-600-840-600-300 r/min, 330 V dc link, speed loop 2.5 Hz",
        "leso_fig16_speed_ramp_330V_layout.png",
        "Fig. 16",
        ("FA-LESO",),
        "weakening",
        (0.4, None),
    ),
)


def _panels(sol, i, kind, mask, p, psi_f):
    o = sol.outputs.obs.each[i]
    th = np.asarray(sol.outputs.theta_e)[mask]
    th_hat = np.asarray(o.theta)[mask]
    err = Panel("θ̂e − θe (rad)", (Series("error", np.asarray(wrap(th_hat - th))),), zero=True)
    angle = Panel(
        "θ̂e, θe (rad)",
        (Series("θe", np.mod(th, 2 * math.pi), actual=True), Series("θ̂e", np.mod(th_hat, 2 * math.pi))),
    )
    if kind == "position":
        return [angle, err]
    if kind in ("dynamic", "weakening"):
        speed = Panel(
            "speed (r/min)",
            (
                Series("actual", np.asarray(sol.outputs.speed_rpm)[mask], actual=True),
                Series("estimated", np.asarray(o.omega)[mask] / p * 30 / math.pi),
            ),
        )
        if kind == "dynamic":
            return [speed, err]
        # the field weakening's work: the drive's i_d beside its reference (the same in every column)
        i_d = Panel(
            "i_d, i_d* (A)",
            (
                Series("i_d*", np.asarray(sol.outputs.id_ref)[mask], actual=True),
                Series("i_d", np.asarray(sol.outputs.i_d)[mask]),
            ),
            zero=True,
        )
        return [speed, i_d, err]  # the error last, as in every kind (drive_figure shares the others' scales)
    flux = Panel(
        "ψ̂α, ψ̂β (Wb)",
        (
            Series("ψα", psi_f * np.cos(th), actual=True),
            Series("ψβ", psi_f * np.sin(th), actual=True),
            Series("ψ̂α", np.asarray(o.psi_a)[mask]),
            Series("ψ̂β", np.asarray(o.psi_b)[mask]),
        ),
    )
    return [flux, angle, err]


def drive_figure(
    sol: Run,
    names: Sequence[str],
    methods: Sequence[str],
    kind: str,
    window: tuple[float, float | None],
    title: str,
    p: int,
    psi_f: float | None = None,
    path: str | Path | None = None,
) -> Figure:
    """A drive run in its paper's layout: a column for each of ``methods``, the panels of ``kind``.

    The events of the window are named.  Any bank's run: paper 000's flux observers, paper 002's LESOs (whose
    outputs have ``theta`` and ``omega`` too: ``position`` and ``dynamic``).

    Args:
        sol: the run (its observers an :class:`~jaxobs.ObserverBank`).
        names: the bank's observers' names, in its order.
        methods: the observers drawn, a column each.
        kind: the panels (module doc; ``flux`` needs ``psi_f``).
        window: (start, stop) s; a negative start counts back from the end, stop None: the end.
        title: the figure's title.
        p: pole pairs.
        psi_f: the rotor flux, Wb (``flux`` only).
        path: where to save it (None: not saved).

    Returns:
        The figure.
    """
    start, stop = window
    t = np.asarray(sol.t)
    t0 = t[-1] + start if start < 0 else start
    t1 = t[-1] if stop is None else stop
    mask = (t >= t0) & (t <= t1)
    columns = [(m, _panels(sol, names.index(m), kind, mask, p, psi_f)) for m in methods]
    events = drive_events(t[mask], sol.outputs._replace(**_sliced(sol.outputs, mask)), float(t0))
    shared = tuple(range(len(columns[0][1]) - 1))  # every panel but the error's
    return paper_figure(t[mask], columns, title, path, events=events, shared=shared)


def flux_figure(
    sol: Run, spec: tuple, names: Sequence[str], p: int, psi_f: float, path: str | Path | None = None
) -> Figure:
    """Draw one row of :data:`FLUX_FIGURES`.

    Args:
        sol: the run.
        spec: the row of :data:`FLUX_FIGURES`.
        names: the observers of its bank (:data:`jaxobs.reproduce.flux.OBSERVER_NAMES`).
        p: pole pairs.
        psi_f: the rotor flux, Wb.
        path: where to save it (None: not saved).

    Returns:
        The figure.
    """
    key, _, fig, methods, kind, window = spec
    return drive_figure(sol, names, methods, kind, window, f"Paper 000 {fig} (ours): {key}", p, psi_f, path)


def _sliced(out, mask):
    """The fields :func:`jaxobs.plot.drive_events` reads, cut to the drawn window."""
    return {k: np.asarray(getattr(out, k))[mask] for k in ("load", "omega_m_ref", "mode")}


def flux_figures(traces: Mapping[str, Run], names: Sequence[str], p: int, psi_f: float, out: Path) -> list[Path]:
    """Every row of :data:`FLUX_FIGURES` whose experiment ran, drawn to ``out``.

    Args:
        traces: experiment → run.
        names: the observers of the runs' bank.
        p: pole pairs.
        psi_f: the rotor flux, Wb.
        out: the folder.

    Returns:
        The paths written.
    """
    paths = []
    for spec in FLUX_FIGURES:
        if spec[0] in traces:
            path = Path(out) / spec[1]
            flux_figure(traces[spec[0]], spec, names, p, psi_f, path)
            paths.append(path)
    return paths


def fll_figure(
    traces: Mapping[str, Any],
    i: int,
    test: str,
    t_event: float,
    path: str | Path | None = None,
    span: float | None = None,
) -> Figure:
    """Paper 001's Test ``test`` in its layout, drawn from 50 ms before its event to ``span`` s after.

    Args:
        traces: {FLL name: run batched over tests} (as :func:`jaxobs.studies.demo.fll_demo` returns them).
        i: the test's index in the batch.
        test: the test's name.
        t_event: the event's time, s.
        path: where to save it (None: not saved).
        span: s after the event (default 0.3 s for a step, 1.2 s for a steady disturbance).

    Returns:
        The figure.
    """
    span = (0.3 if test in ("1", "2", "3", "A", "B") else 1.2) if span is None else span
    columns, t_shown = [], None
    for name, sol in traces.items():
        t = np.asarray(sol.t[i])
        mask = (t >= t_event - 0.05) & (t <= t_event + span)
        out = sol.outputs
        err = np.degrees(np.asarray(wrap(out.obs.theta[i] - out.truth.theta[i])))
        f = Panel(
            # mathtext's hat: DejaVu's combining circumflex (U+0302) hides in the f's hook, so "f̂" drew as "f"
            r"$\hat{\mathrm{f}}$, f (Hz)",
            (
                Series("f", np.asarray(out.truth.omega[i])[mask] / (2 * math.pi), actual=True),
                Series(r"$\hat{\mathrm{f}}$", np.asarray(out.obs.omega[i])[mask] / (2 * math.pi)),
            ),
        )
        v = Panel(
            "V̂, V (p.u.)",
            (
                Series("V", np.asarray(out.truth.amplitude[i])[mask], actual=True),
                Series("V̂", np.asarray(out.obs.amplitude[i])[mask]),
            ),
        )
        columns.append((name, [f, v, Panel("θ̂ − θ (deg)", (Series("error", err[mask]),), zero=True)]))
        t_shown = t[mask]
    title = f"Paper 001 Test {test} (ours): {fll_event_text(test)} at t = {t_event:g} s"
    return paper_figure(
        np.asarray(t_shown), columns, title, path, events=[(t_event, fll_event_text(test))], shared=(0, 1, 2)
    )
