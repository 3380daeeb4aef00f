"""The gain-slider notebook's callback (notebooks/gain_sliders.py), without a browser: it redraws what the sliders
set, a move compiles nothing, changes the same artists in place and redraws only them, and the picture it leaves
is the one a full render draws, with the numbers of a direct simulation.

No test here holds a move to a time: on the shared 2-core machine a time budget fails when the machine is busy, not
when the code is slow. What made moves slow is checked instead (a recompile, new artists, a full render, a layout
pass); benchmarks/sliders.py measures a displayed move in a kernel.
"""

import importlib.util
import io
from pathlib import Path

import jax
import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")  # no display here

_PATH = Path(__file__).parents[1] / "notebooks" / "gain_sliders.py"
_spec = importlib.util.spec_from_file_location("gain_sliders", _PATH)
assert _spec is not None and _spec.loader is not None
gain_sliders = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(gain_sliders)

# XLA compilations of this process, from JAX's monitoring events (a listener cannot be removed; it only counts)
_COMPILES: list[float] = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, duration_secs, **kw: (
        _COMPILES.append(duration_secs) if event == "/jax/core/compile/backend_compile_duration" else None
    )
)

MOVES = [(0.5, 8000.0), (0.9, 20000.0), (1.4, 60000.0), (0.3, 3000.0)]


@pytest.fixture(scope="module")
def ui():
    from jaxobs import papers

    ui = gain_sliders.GainSliders()
    ui(papers.SOGI_FLL_K, papers.SOGI_FLL_LAM)  # the first call: compiled (in __init__) and drawn once
    return ui


def _pixels(ui) -> np.ndarray:
    return np.asarray(ui.fig.canvas.buffer_rgba())[..., :3].copy()


def test_callback_redraws_the_gains_it_is_given(ui):
    from jaxobs import linear, papers

    k, lam = 1.2, 1.2**2 * papers.FLL_OMEGA_N**2
    r = ui(k, lam)
    want = linear.margins(linear.sogi_fll_model(k, lam, papers.FLL_OMEGA_N).open_loop)
    assert float(r["margins"].phase_margin) == pytest.approx(float(want.phase_margin), rel=1e-9)
    assert f"phase margin {float(want.phase_margin):.1f}°" in r["title"]
    assert r["title"] in ui.title.get_text()  # the title shown is the one returned
    ref = np.asarray(ui.ax_f.lines[0].get_ydata())  # Table I's line stays; the sliders' line moved
    assert not np.allclose(np.asarray(ui.line_f.get_ydata()), ref)
    r2 = ui(papers.SOGI_FLL_K, papers.SOGI_FLL_LAM)
    np.testing.assert_allclose(np.asarray(ui.line_f.get_ydata()), ref, rtol=0, atol=1e-12)
    assert float(r2["margins"].phase_margin) < float(r["margins"].phase_margin) + 90  # numbers, not tracers


def test_a_move_compiles_nothing(ui):
    """The simulation, margins and Bode curves are traced once, in __init__; a move with other gains (Python floats,
    as the sliders give) neither retraces nor compiles."""
    assert ui.traces == 1
    before = len(_COMPILES)
    for k, lam in MOVES:
        ui(k, lam)
    assert ui.traces == 1
    assert len(_COMPILES) == before, f"{len(_COMPILES) - before} XLA compilations during {len(MOVES)} moves"
    jax.jit(lambda x: x * 3.0 + 1.0)(np.arange(3.0))  # the counter counts: a new program compiles
    assert len(_COMPILES) > before


def test_a_move_changes_the_same_artists_in_place(ui):
    """Same Line2D objects and texts, no artist added or removed, the axes' places and limits untouched (no layout
    pass), and the data changed."""
    from matplotlib.layout_engine import PlaceHolderLayoutEngine

    axes = (ui.ax_f, ui.ax_mag, ui.ax_ph)
    children = [list(ax.get_children()) for ax in axes]
    places = [ax.get_position().bounds for ax in axes]
    limits = [(ax.get_xlim(), ax.get_ylim()) for ax in axes]
    lines = (ui.line_f, ui.line_mag, ui.line_ph, ui.mark_gc)
    ui(*MOVES[0])
    data = [np.array(line.get_ydata(), copy=True) for line in lines[:3]] + [np.array(ui.mark_gc.get_xdata())]
    ui(*MOVES[1])
    assert [list(ax.get_children()) for ax in axes] == children  # the same objects, in the same order
    assert (ui.line_f, ui.line_mag, ui.line_ph, ui.mark_gc) == lines
    assert [ax.get_position().bounds for ax in axes] == places
    assert [(ax.get_xlim(), ax.get_ylim()) for ax in axes] == limits
    # tight_layout ran once, in __init__; what it leaves (matplotlib's placeholder) lays nothing out at a draw
    engine = ui.fig.get_layout_engine()
    assert engine is None or isinstance(engine, PlaceHolderLayoutEngine), engine
    moved = data[:3] + [data[3]]
    now = [np.asarray(line.get_ydata()) for line in lines[:3]] + [np.asarray(ui.mark_gc.get_xdata())]
    for was, is_ in zip(moved, now):
        assert not np.allclose(was, is_)


def test_a_move_redraws_only_what_moved(ui, monkeypatch):
    """A move draws the moving artists over the kept background: no full render of the figure, no tick or axis
    drawn (they are what a full render spent its time on)."""
    from matplotlib.axis import Axis
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    ui(*MOVES[2])  # the background is in place
    calls = {"full": 0, "axis": 0}

    def counted(name, draw):
        def wrapper(self, *args, **kwargs):
            calls[name] += 1
            return draw(self, *args, **kwargs)

        return wrapper

    monkeypatch.setattr(FigureCanvasAgg, "draw", counted("full", FigureCanvasAgg.draw))
    monkeypatch.setattr(Axis, "draw", counted("axis", Axis.draw))
    for k, lam in MOVES:
        ui(k, lam)
    assert calls == {"full": 0, "axis": 0}
    ui.fig.canvas.draw()  # the counters count: a full render draws the six axes (x and y of three)
    assert calls == {"full": 1, "axis": 6}


def test_the_picture_is_what_a_full_render_draws(ui):
    """The blitted pixels equal a full render's, exactly (the moving artists are drawn in a full render's order),
    also after the figure was rendered at another size meanwhile (as the notebook's inline display does); png()
    decodes to them."""
    from PIL import Image

    for k, lam in MOVES[:2]:
        ui(k, lam)
        blitted = _pixels(ui)
        assert np.array_equal(np.asarray(Image.open(io.BytesIO(ui.png())).convert("RGB")), blitted)
        ui.fig.canvas.draw()
        np.testing.assert_array_equal(blitted, _pixels(ui))
    ui.fig.savefig(io.BytesIO(), format="png", bbox_inches="tight", dpi=50)
    ui(*MOVES[3])
    blitted = _pixels(ui)
    assert blitted.shape[:2] == (800, 800)
    ui.fig.canvas.draw()
    np.testing.assert_array_equal(blitted, _pixels(ui))


def test_the_lines_shown_are_a_direct_simulation(ui):
    """What the figure shows after a move is the observer simulated directly with those gains, and the open loop's
    Bode curves and gain crossover computed directly."""
    import jaxobs
    from jaxobs import linear, papers

    k, lam = MOVES[1]
    ui(k, lam)
    sol = jaxobs.simulate(
        jaxobs.OnSignal(jaxobs.SOGIFLL(k=k, lam=lam), jaxobs.paper001_test("A", t_event=gain_sliders.T_EVENT)),
        gain_sliders.HORIZON,
    )
    np.testing.assert_allclose(ui.line_f.get_xdata(), np.asarray(sol.t), rtol=0, atol=0)
    np.testing.assert_allclose(ui.line_f.get_ydata(), np.asarray(sol.outputs.obs.omega) / (2 * np.pi), rtol=1e-12)
    loop = linear.sogi_fll_model(k, lam, papers.FLL_OMEGA_N).open_loop
    db, deg = linear.bode(loop, gain_sliders.OMEGA)
    np.testing.assert_allclose(ui.line_mag.get_ydata(), np.asarray(db), rtol=1e-12)
    np.testing.assert_allclose(ui.line_ph.get_ydata(), np.asarray(deg), rtol=1e-12)
    f_gc = float(linear.margins(loop).omega_gc) / (2 * np.pi)
    np.testing.assert_allclose(ui.mark_gc.get_xdata(), [f_gc, f_gc], rtol=1e-12)
    np.testing.assert_allclose(ui.mark_pm.get_xdata(), [f_gc, f_gc], rtol=1e-12)
    assert f"gain crossover {f_gc:.1f} Hz" in ui.title.get_text()


def test_dpi_out_of_range_is_refused():
    with pytest.raises(ValueError, match=r"dpi must be in \[20, 300\], got 5"):
        gain_sliders.GainSliders(dpi=5)


def test_the_benchmark_reads_cpu_time_and_tabulates_a_result():
    """benchmarks/sliders.py's bookkeeping (its kernels are not started here): a process's CPU time from /proc grows
    with work done, and the table shows each side's medians, the ratio and the load."""
    import os
    import time

    from benchmarks import sliders

    c0 = sliders._cpu_s(os.getpid())
    t0 = time.process_time()
    while time.process_time() - t0 < 0.05:
        pass
    assert sliders._cpu_s(os.getpid()) - c0 >= 0.04

    def side(wall, cpu, canvas):
        return {
            "wall_s": [wall, 2 * wall],
            "cpu_s": [cpu, cpu],
            "png_bytes": [1000, 1000],
            "median_wall_s": 1.5 * wall,
            "median_cpu_s": cpu,
            "compiles_during_moves": 0,
            "callback": {"median_wall_s": 0.01, "median_cpu_s": 0.01, "canvas": canvas},
        }

    r = {"date": "2026-12-03 10:00 UTC", "moves": 2, "before_rev": "abc1234", "before_setup_s": 14.0}
    r |= {"after_setup_s": 11.0, "uptime_start": "up, load average: 4.30", "uptime_end": "up, load average: 4.37"}
    r |= {"before": side(0.4, 0.4, "FigureCanvasBase"), "after": side(0.04, 0.05, "FigureCanvasAgg")}
    text = sliders.table(r)
    assert "before = abc1234" in text
    rows = [line.split()[:5] for line in text.splitlines() if line.startswith(("before  ", "after   "))]
    assert rows == [["before", "600", "ms", "400", "ms"], ["after", "60", "ms", "50", "ms"]]
    assert "after / before: wall 0.100, CPU 0.125" in text
    assert "closed figure's draw() renders nothing" in text
    assert "load average: 4.30" in text and "load average: 4.37" in text
