"""The gain-slider notebook's callback (notebooks/gain_sliders.py), without a browser: it redraws what the sliders
set, and a move of a slider after the first call (which compiles) takes under 0.3 s."""

import importlib.util
import time
from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")  # the callback draws its figure; no display here

_PATH = Path(__file__).parents[1] / "notebooks" / "gain_sliders.py"
_spec = importlib.util.spec_from_file_location("gain_sliders", _PATH)
gain_sliders = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(gain_sliders)

BUDGET_S = 0.3


@pytest.fixture(scope="module")
def ui():
    from jaxobs import papers

    ui = gain_sliders.GainSliders()
    ui(papers.SOGI_FLL_K, papers.SOGI_FLL_LAM)  # the first call: compiled (in __init__) and drawn once
    yield ui
    import matplotlib.pyplot as plt

    plt.close(ui.fig)


def test_callback_redraws_the_gains_it_is_given(ui):
    from jaxobs import linear, papers

    k, lam = 1.2, 1.2**2 * papers.FLL_OMEGA_N**2
    r = ui(k, lam)
    want = linear.margins(linear.sogi_fll_model(k, lam, papers.FLL_OMEGA_N).open_loop)
    assert float(r["margins"].phase_margin) == pytest.approx(float(want.phase_margin), rel=1e-9)
    assert f"phase margin {float(want.phase_margin):.1f}°" in r["title"]
    ref = np.asarray(ui.ax_f.lines[0].get_ydata())  # Table I's line stays; the sliders' line moved
    assert not np.allclose(np.asarray(ui.line_f.get_ydata()), ref)
    r2 = ui(papers.SOGI_FLL_K, papers.SOGI_FLL_LAM)
    np.testing.assert_allclose(np.asarray(ui.line_f.get_ydata()), ref, rtol=0, atol=1e-12)
    assert float(r2["margins"].phase_margin) < float(r["margins"].phase_margin) + 90  # numbers, not tracers


def test_callback_after_the_first_compile_is_under_budget(ui):
    """The median of 5 moves. Its CPU time (this process's, all threads) is what is held to 0.3 s: on the shared
    CI cores the wall time also holds the time spent waiting for a core (0.62-0.75 s wall at 0.14-0.15 s CPU at
    load 17 on 2 cores); the wall time is printed beside it."""
    cpu, wall = [], []
    for i in range(5):
        c0, t0 = time.process_time(), time.perf_counter()
        ui(0.5 + 0.2 * i, 8000.0 + 4000.0 * i)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    print(f"\ngain-slider callback: median {np.median(cpu) * 1e3:.0f} ms CPU, {np.median(wall) * 1e3:.0f} ms wall")
    assert np.median(cpu) < BUDGET_S, (cpu, wall)
