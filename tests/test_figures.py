"""The figures compare what they exist for: one scale per comparison, the worst case beside the
mean, readable labels.  Built from small synthetic Datasets: no simulation."""

from typing import NamedTuple

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest
import xarray as xr
from matplotlib.colors import LogNorm

from jaxobs import plot


# a drive solution as the figures read it (jaxobs.reproduce.figures, jaxobs.plot): hand-made, a known answer
class _Obs(NamedTuple):
    theta: np.ndarray
    omega: np.ndarray | None = None


class _Each(NamedTuple):  # a bank of observers' outputs (.each)
    each: tuple


class _Out(NamedTuple):
    theta_e: np.ndarray
    speed_rpm: np.ndarray
    omega_m_ref: np.ndarray
    load: np.ndarray
    mode: np.ndarray
    obs: _Each
    i_d: np.ndarray | None = None
    id_ref: np.ndarray | None = None


class _Sol(NamedTuple):
    t: np.ndarray
    outputs: _Out


def _study(values_by_design: dict) -> xr.Dataset:
    """A study-shaped Dataset: dims (design, freq_step, dc, harmonics_scale)."""
    coords = {"freq_step": [-1.0, 1.0], "dc": [0.0, 0.1, 0.2], "harmonics_scale": [0.0, 1.0]}
    arr = np.stack([np.broadcast_to(v, (2, 3, 2)) for v in values_by_design.values()])
    ds = xr.Dataset(
        {"ripple_freq": (("design", *coords), arr, {"units": "Hz"})},
        coords={"design": list(values_by_design), **coords},
    )
    for k in coords:
        ds[k].attrs["units"] = "Hz" if k == "freq_step" else "1"
    return ds


def _heatmap(ds):
    da = ds["ripple_freq"]
    return plot._study_heatmap(
        ds, da, "Hz", "ripple", ["freq_step", "dc", "harmonics_scale"], list(ds["design"].values)
    )


def test_heatmap_shows_the_worst_case_beside_the_mean_on_one_scale():
    # the worst case hides in harmonics_scale = 1: the mean halves it
    worst = np.zeros((2, 3, 2))
    worst[..., 1] = 2.0
    fig = _heatmap(_study({"a": 0.5 + worst, "b": np.full((2, 3, 2), 0.4)}))
    panels = [ax for ax in fig.axes if ax.images]
    assert len(panels) == 4  # (mean, worst) x (a, b)
    titles = [ax.get_title() for ax in panels]
    assert titles == ["a: mean", "b: mean", "a: worst (max)", "b: worst (max)"]
    norms = {id(ax.images[0].norm) for ax in panels}
    assert len(norms) == 1  # one colour scale for every panel of the metric
    a_worst = panels[2].images[0].get_array()
    assert np.allclose(a_worst, 2.5) and np.allclose(panels[0].images[0].get_array(), 1.5)
    for ax in panels:  # readable: ≥ 9 pt ticks, and each cell's value written in it
        assert min(t.get_fontsize() for t in ax.get_xticklabels() + ax.get_yticklabels()) >= 9
        assert len(ax.texts) == 6 and all(t.get_fontsize() >= 9 for t in ax.texts)


def test_heatmap_scale_is_log_where_designs_differ_by_decades():
    fig = _heatmap(_study({"a": np.full((2, 3, 2), 0.01), "b": np.full((2, 3, 2), 1.0)}))
    assert isinstance(fig.axes[0].images[0].norm, LogNorm)
    fig = _heatmap(_study({"a": np.full((2, 3, 2), 0.15), "b": np.full((2, 3, 2), 0.115)}))
    norm = fig.axes[0].images[0].norm
    assert not isinstance(norm, LogNorm) and norm.vmin == 0.115 and norm.vmax == 0.15


def test_bode_grid_resolves_the_gi_leso_resonance_and_traces_stay_distinct():
    """002 Fig. 4: the GI-LESO's ±50 Hz resonance (poles −8.8 ± j316 rad/s) is sampled finely enough that
    the drawn line (straight between points) is within 0.005 dB of the response at every midpoint (the
    plain 1200-point log grid: 0.04 dB; the ±1.1 dB swing there is the response, not a sampling spike);
    the C-LESO, which lies under the GI-LESO, has its own line style."""
    import jax

    from jaxobs import linear, papers

    jax.config.update("jax_enable_x64", True)
    we = papers.LESO_TABLE_II_OMEGA_E
    gi = linear.gileso_tf(papers.LESO_OMEGA0, papers.GILESO_K_R, papers.GILESO_OMEGA_C, we)
    wpos = np.logspace(0, 4.5, 1200)
    coarse = np.concatenate([-wpos[::-1], wpos])
    fine = plot.resonance_grid({"gi": gi}, coarse)
    assert set(coarse) <= set(fine) and np.all(np.diff(fine) > 0)

    def line_error(w):  # dB between the drawn line and the response, at the midpoints near +ω̂e and −ω̂e
        err = 0.0
        for side in (1, -1):
            ws = w[np.abs(w - side * we) < 40.0]
            mag = np.asarray(linear.bode(gi, ws)[0])
            mid = np.asarray(linear.bode(gi, (ws[1:] + ws[:-1]) / 2)[0])
            err = max(err, float(np.max(np.abs(mid - (mag[1:] + mag[:-1]) / 2))))
        return err

    assert line_error(fine) < 0.005, line_error(fine)
    assert line_error(coarse) > 0.02  # the refinement is what resolves it (a test that can fail)
    fig = plot.bode_figure({"C-LESO": linear.cleso_tf(papers.LESO_OMEGA0), "GI-LESO": gi}, coarse, "t", hz=True)
    lines = fig.axes[0].get_lines()[:2]
    assert lines[0].get_linestyle() != lines[1].get_linestyle()
    assert lines[0].get_linewidth() > lines[1].get_linewidth()  # the one beneath is wider: it shows
    assert fig.axes[1].get_xlabel() == "frequency (Hz)"
    assert plot.bode_figure({"gi": gi}, wpos, "t", hz=False).axes[1].get_xlabel() == "ω (rad/s)"


def test_drive_events_are_found_and_named():
    """Every event of a drive run from its outputs: the load applied and removed (leso_load_step.png's 0.6 s
    and 0.9 s), a speed-reference ramp and a step with their targets, the I-f hand-over (position_error_figure
    marks and names each)."""
    from types import SimpleNamespace

    t = np.arange(0, 1.2, 1e-3)
    load = np.where((t >= 0.6) & (t < 0.9), 24.0, 0.0)
    rpm = np.where(t < 0.2, 300.0, np.where(t < 0.4, 300.0 + (t - 0.2) / 0.2 * 300.0, 600.0))
    rpm = np.where(t >= 1.0, 500.0, rpm)
    mode = (t >= 0.1).astype(int)
    out = SimpleNamespace(load=load, omega_m_ref=rpm * np.pi / 30, mode=mode)
    ev = plot.drive_events(t, out)
    names = [w for _, w in ev]
    assert names == [
        "I-f hand-over to the observer",
        "speed ref. ramp to 600 r/min",
        "load applied: 0 → 24 N·m",
        "load removed: 24 → 0 N·m",
        "speed ref. step to 500 r/min",
    ], names
    times = [te for te, _ in ev]
    assert np.allclose(times, [0.1, 0.2, 0.6, 0.9, 1.0], atol=1.5e-3)
    assert [w for _, w in plot.drive_events(t, out, t_from=0.5)][0].startswith("load applied")


def test_paper_figure_layout():
    """The papers' layout (jaxobs.plot.paper_figure): one column per method headed (a), (b), ...; in each the
    same panels, every y label with its unit; the actual trace black and dashed under the estimate; the
    shared rows on one scale, the error's on its own and through zero (a steady −0.157 rad reads as its
    distance from zero); every event a line in each panel, named once, in the top one."""
    t = np.linspace(0.0, 0.1, 201)
    cols = []
    for name, bias in (("SOIFO", -0.157), ("LPF", 0.6)):
        th = np.mod(628.0 * t, 2 * np.pi)
        cols.append(
            (
                name,
                [
                    plot.Panel("θ̂e, θe (rad)", (plot.Series("θe", th, actual=True), plot.Series("θ̂e", th + bias))),
                    plot.Panel("θ̂e − θe (rad)", (plot.Series("error", np.full_like(t, bias)),), zero=True),
                ],
            )
        )
    fig = plot.paper_figure(t, cols, "title", events=[(0.05, "load applied: 0 → 10 N·m")], shared=(0,))
    axes = np.array(fig.axes).reshape(2, 2)
    assert [ax.get_title() for ax in axes[0]] == ["(a) SOIFO", "(b) LPF"]
    assert all(ax.get_ylabel().endswith("(rad)") for ax in axes.ravel())
    actual = axes[0, 0].get_lines()[0]
    assert actual.get_color() == "k" and actual.get_linestyle() == "--"
    assert axes[0, 0].get_ylim() == axes[0, 1].get_ylim()
    lo, hi = axes[1, 0].get_ylim()
    assert lo < -0.157 and hi > 0.0 and hi - lo < 0.3, (lo, hi)
    lo, hi = axes[1, 1].get_ylim()
    assert lo < 0.0 < 0.6 < hi, (lo, hi)
    named = [[tx.get_text() for tx in ax.texts] for ax in axes.ravel()]
    assert named == [["load applied: 0 → 10 N·m"], ["load applied: 0 → 10 N·m"], [], []]
    with pytest.raises(ValueError, match="same panels"):
        plot.paper_figure(t, [cols[0], ("x", cols[1][1][:1])], "title")


def test_a_one_column_figure_wraps_its_title_inside_the_figure():
    """002's 330 V ramp is drawn for the FA-LESO alone (one column, 6.5 in wide): its long title wraps instead
    of running off both edges."""
    t = np.linspace(0.0, 1.0, 101)
    panel = plot.Panel("θ̂e − θe (rad)", (plot.Series("error", 0.01 * t),), zero=True)
    title = "Paper 002 Fig. 16 (ours): speed ramp 300-600-840-600-300 r/min, 330 V dc link, speed loop 2.5 Hz, "
    fig = plot.paper_figure(t, [("FA-LESO", [panel])], title + "the FA-LESO closing the loop")
    fig.draw_without_rendering()
    (sup,) = [tx for tx in fig.texts if tx.get_text().startswith("Paper 002")]
    assert "\n" in sup.get_text()
    box, whole = sup.get_window_extent(), fig.bbox
    assert box.x0 >= whole.x0 and box.x1 <= whole.x1, (box, whole)


def test_the_weakening_layout_draws_i_d_under_its_reference():
    """jaxobs.reproduce.figures' ``weakening`` panels: the speed estimate over the speed, the drive's i_d over
    i_d* (A), then the error, as 002's ramp on a 330 V link is drawn (LESO_FIGURES)."""
    from jaxobs.reproduce.figures import LESO_FIGURES, drive_figure

    t = np.linspace(0.0, 1.0, 1001)
    w = 2 * np.pi * 50 * np.ones_like(t)
    i_d = np.minimum(0.0, -6.0 * (t - 0.5))
    each = (_Obs(100 * np.pi * t - 0.05, w),) * 3
    out = _Out(100 * np.pi * t, w / 5 * 30 / np.pi, w / 5, 0 * t, 1 + 0 * t, _Each(each), i_d=i_d, id_ref=i_d + 0.1)
    spec = [s for s in LESO_FIGURES if s[4] == "weakening"]
    assert len(spec) == 1 and spec[0][3] == ("FA-LESO",)
    fig = drive_figure(_Sol(t, out), ("C-LESO", "GI-LESO", "FA-LESO"), *spec[0][3:], "title", p=5)
    assert [ax.get_ylabel() for ax in fig.axes] == ["speed (r/min)", "i_d, i_d* (A)", "θ̂e − θe (rad)"]
    assert fig.axes[1].get_ylim()[0] < -3.0 and fig.axes[1].get_ylim()[1] >= 0.0


def test_log_colour_bar_labels_both_ends():
    """A log heat-map scale is labelled on 1-2-5 values and at both ends (a bar from 0.013 up had no label
    below 0.1; 0.07 0.08 0.09 0.1 crowded where it had)."""
    fig = _heatmap(_study({"a": np.full((2, 3, 2), 0.0134), "b": np.full((2, 3, 2), 1.52)}))
    (bar,) = [ax for ax in fig.axes if not ax.images and ax.get_ylabel().startswith("ripple")]
    fig.draw_without_rendering()
    labels = [(tk.get_position()[1], tk.get_text()) for tk in bar.yaxis.get_majorticklabels() if tk.get_text()]
    values = [float(txt) for _, txt in labels]
    assert values == [0.014, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 1.5], values
    assert not [tk for tk in bar.yaxis.get_minorticklabels() if tk.get_text()]
    assert plot._log_ticks(0.013, 0.09) == [0.013, 0.02, 0.05, 0.09]
    assert plot._log_ticks(1e-4, 10.0) == [1e-4, 1e-3, 1e-2, 0.1, 1.0, 10.0]  # beyond 3 decades: 1 per decade


def test_the_row_labels_of_a_heat_map_stay_inside_the_figure():
    fig = _heatmap(_study({"a": np.full((2, 3, 2), 0.1), "b": np.full((2, 3, 2), 0.2)}))
    fig.draw_without_rendering()
    for ax in fig.axes:
        if ax.images and ax.get_ylabel():
            assert ax.yaxis.label.get_window_extent().x0 >= 0.0, ax.get_ylabel()


def test_an_observer_that_sweeps_is_clipped_and_a_steady_lead_kept():
    """000's speed ramp: the pure integrator saws ±90° (its circle through the origin), the LPF leads 37°
    steadily, the SOIFOs err by 10°.  The integrator leaves the y-range (drawn faint, named clipped); the LPF
    stays: it has not lost track, and the SOIFOs read on ±43°, not on ±100°."""
    t = np.linspace(0.0, 1.0, 2001)
    th = 2 * np.pi * 30 * t
    saw = np.radians(90.0) * (2 * ((8 * t) % 1.0) - 1.0)
    errs = (saw, np.radians(37.0), np.radians(-10.0) * np.ones_like(t), np.radians(-9.0) * np.ones_like(t))
    each = tuple(_Obs(th + e) for e in errs)
    ref = np.full_like(t, 400 * np.pi / 30)
    out = _Out(th, ref * 30 / np.pi, ref, 0 * t, 1 + 0 * t, _Each(each))
    names = ("integrator", "LPF", "SOIFO", "second-order SOIFO")
    fig = plot.position_error_figure(_Sol(t, out), names, "title")
    ax_e = fig.axes[1]
    lo, hi = ax_e.get_ylim()
    assert hi == pytest.approx(1.15 * 37.0, rel=1e-3) and lo == -hi
    legend = [tx.get_text() for tx in ax_e.get_legend().get_texts()]
    assert legend[0].startswith("integrator (clipped") and legend[1:] == list(names[1:])
    assert ax_e.get_lines()[0].get_alpha() < 0.5


def test_two_sided_bode_axis_is_labelled_every_other_decade():
    """002 Fig. 4's symlog axis (Hz): −1000 … 1000 every other decade in plain numbers, the decades between
    unlabelled, so no two labels meet."""
    import matplotlib.pyplot as plt

    from jaxobs.plot._bode import _two_sided_ticks

    fig, ax = plt.subplots(figsize=(7.5, 3))
    x = np.concatenate([-np.logspace(-3, 3.7, 50)[::-1], np.logspace(-3, 3.7, 50)])
    ax.plot(x, np.zeros_like(x))
    ax.set_xscale("symlog", linthresh=1e-3)
    _two_sided_ticks(ax, 1e-3, 10**3.7)
    fig.draw_without_rendering()
    labels = [tk for tk in ax.get_xticklabels() if tk.get_text()]
    assert [tk.get_text() for tk in labels] == ["−1000", "−10", "−0.1", "0", "0.1", "10", "1000"]
    boxes = [tk.get_window_extent() for tk in labels]
    assert all(a.x1 < b.x0 for a, b in zip(boxes, boxes[1:]))
    plt.close(fig)


def _envelope() -> xr.Dataset:
    """An envelope-shaped Dataset (jaxobs.analysis.envelope): 3 speeds x 2 loads; "tuned" lost lock at 10 r/min
    and load 0 (no steady error), is not resolved stable at 10 r/min and load 5, and its peak error is over the
    bound at 100 r/min and load 5."""
    speeds, loads = [10.0, 100.0, 1000.0], [0.0, 5.0]
    ones = np.ones((2, 3, 2))
    sync, stable, err = ones.copy(), ones.copy(), np.full((2, 3, 2), 2.0)
    sync[1, 0, 0], stable[1, 0, 1], err[1, 1, 1] = 0.0, 0.0, 45.0
    err[1, 0, 0] = np.nan
    holds = sync * stable * (np.nan_to_num(err, nan=99.0) <= 30.0)
    dims = ("design", "speed_rpm", "load_nm")
    data = {
        "margin": (dims, np.where(stable > 0, 5.0, -1.0)),
        "peak_position_late": (dims, np.radians(err)),
        "mean_position_late": (dims, np.where(np.isnan(err), np.nan, np.radians(0.5))),
        "ripple_position_late": (dims, np.where(np.isnan(err), np.nan, np.radians(0.2))),
        "holds": (dims, holds.astype(np.int8)),
        "stable": (dims, stable.astype(np.int8)),
        "synchronous": (dims, sync.astype(np.int8)),
    }
    coords = {"design": ["closed_form", "tuned"], "speed_rpm": speeds, "load_nm": loads}
    return xr.Dataset(data, coords=coords, attrs={"bound_deg": 30.0})


def test_envelope_fail_marks_have_a_legend_of_their_own_and_lost_cells_are_hatched(tmp_path):
    """The marks, the outline and the lost-lock cells are explained by a legend independent of the colour bars
    (white is 0 on the centred scales, so it cannot also mean "lost lock")."""
    fig = plot.envelope_figure(_envelope(), tmp_path / "e.png")
    (legend,) = fig.legends
    labels = [t.get_text() for t in legend.get_texts()]
    assert [lab.split(":")[0] for lab in labels] == ["outline", "fails", "fails", "fails", "no value"]
    assert "not synchronous" in labels[1] and "not resolved stable" in labels[2] and "over the bound" in labels[3]
    assert "lost lock" in labels[4] and "<= 30 deg" in labels[0]
    assert "white" not in fig._suptitle.get_text()
    panels = [ax for ax in fig.axes if ax.get_xscale() == "log"]  # the maps (not their colour bars)
    assert all(any(p.get_hatch() == "///" for p in ax.patches) for ax in panels)  # under every panel's cells
    # the tuned design's marks: x at (10, 0), o at (10, 5), + at (100, 5)
    tuned = [ax for ax in panels if ax.get_title().startswith("tuned")][0]
    marks = {ln.get_marker(): (list(ln.get_xdata()), list(ln.get_ydata())) for ln in tuned.lines if ln.get_marker()}
    assert marks["x"] == ([10.0], [0.0]) and marks["o"] == ([10.0], [5.0]) and marks["+"] == ([100.0], [5.0])
    assert tuned.get_title() == "tuned\nholds at 3/6 points"
    assert [ax for ax in panels if ax.get_title()][0].get_title().startswith("closed form")  # in words


def test_heat_map_labels_are_the_axes_long_names_one_line_each():
    """Each row's label is its axis's long name and unit on one line (the row, mean or worst, is the panel's
    title); the title names the hidden axes in words, never by their code names."""
    ds = _study({"a": np.full((2, 3, 2), 0.1), "b": np.full((2, 3, 2), 0.2)})
    ds["dc"].attrs["long_name"] = "dc offset (p.u. of the fundamental)"
    ds["freq_step"].attrs["long_name"] = "frequency step at the event"
    ds["harmonics_scale"].attrs["long_name"] = "harmonic distortion (multiple of 001 Test C's spectrum)"
    fig = _heatmap(ds)
    labels = [ax.get_ylabel() for ax in fig.axes if ax.images and ax.get_ylabel()]
    assert labels == ["dc offset (p.u. of the fundamental)"] * 2
    assert {ax.get_xlabel() for ax in fig.axes if ax.images and ax.get_xlabel()} == {"frequency step at the event (Hz)"}
    title = fig._suptitle.get_text()
    assert "over the harmonic distortion\n" in title and "harmonics_scale" not in title
