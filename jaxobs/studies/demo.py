"""The FLL-family demo: paper 001's three FLLs, Table I gains, on Tests A–E.

One ``jit(vmap)`` call per FLL runs all five tests; the table gives, per test
and FLL, the settling time and the steady ripple of the estimates.

Settling (the paper's "speed of response", 001 Sec. VI, ≈ 2.5 cycles for all
three in Test A):
- Test A: time for f̂ to enter and stay in a band of 5 % (and 2 %) of the 2 Hz step;
- Test B: time for the phase error to enter and stay within 5 % (2 %) of the 60° jump.
Test B's transient (001 Sec. VI: "the quantities estimated by the SOGI-FLL
experience rather smaller overshoots"), over the first ``steady_delay`` s after
the event: peak |f̂ − 50 Hz| (Hz); the phase error's overshoot, its largest
excursion past zero on the side opposite to the error the jump opened (deg);
and V̂'s overshoot past its final value (mean over the steady window) in the
direction of the change (p.u.; for B's sag, how far V̂ dips below 0.5).
Overshoots are 0 when there is none; the three are NaN for the other tests.
Steady ripple (Tests C–E, and A–B for completeness): peak-to-peak of f̂ (Hz),
of the wrapped phase error (deg) and of V̂ (p.u.) over a window of one second
starting one second after the event (a whole period of Test E's 1 Hz
sub-harmonic).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import jax
import numpy as np

from .. import linear, metrics
from ..observers import AbstractObserver
from ..runtime.onsignal import OnSignal
from ..runtime.progress import Progress, ProgressArg
from ..runtime.simulation import Solution, simulate
from ..signals import paper001_test, stack

__all__ = ["fll_demo", "DEMO_TESTS", "format_table", "table_i_flls"]

DEMO_TESTS = ("A", "B", "C", "D", "E")
PAPER_TEST_B = "the SOGI-FLL's are rather smaller than the WPF's and WIF's"
PAPER_SETTLE_CYCLES_A = 2.5  # 001 Sec. VI: "around 2.5 cycles of the nominal frequency"


def table_i_flls(**kw: Any) -> dict[str, AbstractObserver]:
    """The three FLLs with paper 001 Table I gains, from the closed forms.

    Args:
        **kw: The closed forms' inputs (``omega_n``, ``ts``, ...; :func:`jaxobs.linear.sogi_fll_closed_form`).

    Returns:
        name -> FLL (``"SOGI-FLL"``, ``"SOGI-FLL-WPF"``, ``"SOGI-FLL-WIF"``).
    """
    return {
        "SOGI-FLL": linear.sogi_fll_closed_form(**kw),
        "SOGI-FLL-WPF": linear.wpf_closed_form(**kw),
        "SOGI-FLL-WIF": linear.wif_closed_form(**kw),
    }


def _overshoot(x, final: float) -> float:
    """Largest excursion of ``x`` past ``final`` opposite to where it started (same units, >= 0).

    ``x[0]`` is the first sample after the event; a trace that starts above
    ``final`` overshoots by dipping below it, and vice versa.
    """
    side = np.sign(x[0] - final)
    return float(max(0.0, np.max(-side * (x - final))))


def _test_b_overshoots(f_hat, err, amp, transient, steady, f_n):
    """Test B's three overshoots (Hz, deg, p.u.); see the module docstring."""
    return dict(
        freq_peak_hz=float(np.max(np.abs(f_hat[transient] - f_n))),
        phase_overshoot_deg=_overshoot(np.degrees(err[transient]), 0.0),
        amp_overshoot_pu=_overshoot(amp[transient], float(np.mean(amp[steady]))),
    )


@eqx.filter_jit
def _run_batch(observer, signals, t1):
    return jax.vmap(lambda s: simulate(OnSignal(observer, s), t1))(signals)


def fll_demo(
    t_event: float = 0.2,
    steady_delay: float = 1.0,
    steady_len: float = 1.0,
    flls: Mapping[str, AbstractObserver] | None = None,
    progress: ProgressArg = None,
    tests: Sequence[str] = DEMO_TESTS,
) -> tuple[list[dict[str, Any]], dict[str, Solution]]:
    """Run the demo: the FLLs on paper 001's tests.

    Args:
        t_event: The tests' event time, s.
        steady_delay: The time from the event to the steady window, s.
        steady_len: The steady window's length, s.
        flls: name -> FLL (default Table I's FLLs).
        progress: One step per FLL, each named as it compiles and runs (:mod:`jaxobs.runtime.progress`).
        tests: Paper 001's tests to run (keys of :data:`jaxobs.papers.TESTS_001`; default A–E, Sec. VI).

    Returns:
        ``(rows, traces)``: rows a list of dicts {test, fll, settle_ms, settle_cycles, settle2_cycles,
        freq_peak_hz, phase_overshoot_deg, amp_overshoot_pu, freq_pp_hz, phase_pp_deg, amp_pp_pu, ok};
        traces {fll: Solution batched over tests}.
    """
    flls = table_i_flls() if flls is None else flls
    signals = stack([paper001_test(name, t_event=t_event) for name in tests])
    t1 = t_event + steady_delay + steady_len
    f_n = 50.0
    rows, traces = [], {}
    bar = Progress(progress, len(flls), "demo", unit="FLL")
    for fll_name, obs in flls.items():
        bar.stage(f"{fll_name} on Tests {', '.join(tests)} (compiling, then {t1:g} s each)")
        sol = _run_batch(obs, signals, t1)
        traces[fll_name] = sol
        bar.update()
        t = np.asarray(sol.t)[0]
        out = sol.outputs
        f_hat = np.asarray(out.obs.omega) / (2 * math.pi)
        err = np.asarray(metrics.wrap(out.obs.theta - out.truth.theta))
        amp = np.asarray(out.obs.amplitude)
        steady = (t >= t_event + steady_delay) & (t < t_event + steady_delay + steady_len)
        transient = (t >= t_event) & (t < t_event + steady_delay)
        nan3 = dict.fromkeys(("freq_peak_hz", "phase_overshoot_deg", "amp_overshoot_pu"), math.nan)
        for i, test in enumerate(tests):
            settle = {5: math.nan, 2: math.nan}
            for pct in settle:
                if test == "A":
                    settle[pct] = float(metrics.settling_time(t, f_hat[i], 52.0, pct / 100 * 2.0, t_event))
                elif test == "B":
                    settle[pct] = float(metrics.settling_time(t, np.degrees(err[i]), 0.0, pct / 100 * 60.0, t_event))
            rows.append(
                dict(
                    test=test,
                    fll=fll_name,
                    settle_ms=1e3 * settle[5],
                    settle_cycles=settle[5] * f_n,
                    settle2_cycles=settle[2] * f_n,
                    **(_test_b_overshoots(f_hat[i], err[i], amp[i], transient, steady, f_n) if test == "B" else nan3),
                    freq_pp_hz=float(np.ptp(f_hat[i][steady])),
                    phase_pp_deg=float(np.degrees(np.ptp(err[i][steady]))),
                    amp_pp_pu=float(np.ptp(amp[i][steady])),
                    ok=bool(sol.ok[i]),
                )
            )
    bar.close()
    return rows, traces


def format_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """The demo's rows as a fixed-width text table, with paper 001's figures beside ours.

    Args:
        rows: :func:`fll_demo`'s rows.

    Returns:
        The table, lines joined by newlines.
    """
    head = (
        f"{'test':<5}{'FLL':<14}{'settle 5% cyc':>14}{'2% cyc':>8}{'paper':>7}"
        f"{'f p-p Hz':>11}{'θerr p-p °':>12}{'V̂ p-p pu':>11}{'f̂ peak Hz':>11}{'θ ovs °':>9}{'V̂ ovs pu':>10}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        paper = f"{PAPER_SETTLE_CYCLES_A:.1f}" if r["test"] == "A" else ""
        cyc5 = "" if math.isnan(r["settle_cycles"]) else f"{r['settle_cycles']:.2f}"
        cyc2 = "" if math.isnan(r["settle2_cycles"]) else f"{r['settle2_cycles']:.2f}"
        flag = "" if r["ok"] else "  DIVERGED"
        lines.append(
            f"{r['test']:<5}{r['fll']:<14}{cyc5:>14}{cyc2:>8}{paper:>7}"
            f"{r['freq_pp_hz']:>11.4f}{r['phase_pp_deg']:>12.3f}{r['amp_pp_pu']:>11.4f}"
            + (
                ""
                if r["test"] != "B"
                else f"{r['freq_peak_hz']:>11.2f}{r['phase_overshoot_deg']:>9.1f}{r['amp_overshoot_pu']:>10.4f}"
            )
            + flag
        )
    lines.append(f"Test B overshoots (f̂ peak, θ ovs, V̂ ovs): paper 001 Sec. VI, {PAPER_TEST_B}.")
    return "\n".join(lines)
