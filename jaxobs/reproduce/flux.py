"""Paper 000's experiments (Sec. IV) on the simulated SPMSM drive: ``jaxobs reproduce flux``.

Set-up, and the choices our copy of the paper leaves open:

- Machine: 000 Table II.  The bench inertia is not given; Table II's
  J = 3.78e-4 kg·m² is the motor's, and with it a 10 N·m step decelerates the
  rotor at 26,000 rad/s² (an 840 r/min dip even with an encoder).  The bench
  couples a load machine, so we ASSUME a total J = 10 × 3.78e-4 kg·m².
- Control: IMC current loop α_c = 2π·300 rad/s at 10 kHz, I-P speed loop
  α_s = 2π·5 rad/s at 1 kHz (below the FLL's bandwidth at 400 r/min; a 10 Hz
  speed loop oscillated there when closed through the FLL's ω̂).
- Observers (Fig. 5 settings): LPF ωc = 100 rad/s (no compensation), SOIFO
  k = 1.414, second-order SOIFO K1 = 1.56, K2 = 3.11, both with FLLs; the pure
  integrator and the LPF with a type-2 PLL (ω_b = 2π·20 rad/s, ζ = 1/√2) for
  speed.  FLL gains (dimensionless, see :mod:`jaxobs.observers.flux`): SOIFO
  lam = k²/4 (ζ = 1/√2), second-order SOIFO the symmetric optimum of 001 with
  b = K2/K1: lam = K1³/(2K2).
- Every experiment runs the drive sensorless on the second-order SOIFO (000's
  proposed observer) after a hand-over from the encoder once the observers
  have converged, with all four observers fed the same measurements
  (an :class:`~jaxobs.ObserverBank`), so their errors are compared on
  identical data.  The position error is θ̂e − θe wrapped to (−π, π].
- "Position error" in the paper is one number per trace, read off scope
  plots; we report the peak |θ̂e − θe| over the window ("max_abs") and compare
  it with the paper's, and also the mean and the peak-to-peak ripple.
- "Imbalance" between the estimated α and β fluxes (Sec. IV-C) is read as
  the dc offset of the estimated flux circle, |mean(ψ̂_ab)| over whole periods.
- The sampling delay (Sec. IV-B: the second-order SOIFO's steady error "is caused by the sampling
  period delay"): the steady experiments (Figs 10–17) run with :data:`DSP_000`, the TMS320F28335's
  timing as we ASSUME it (000 describes none): currents sampled at the PWM centre, one period of
  computation, the duty cycles loaded at the next period, no delay compensation (000 describes
  none), and θ̂ compared with the encoder while the voltage computed from it acts (the scope's view).
  The error is then −(2 + ½) ωe Ts (jaxobs.drive.latency; tests/test_latency.py); the rows
  ``delay_samples`` give −mean/(ωe Ts) beside the paper's error in samples.  The other experiments
  keep the historical timing (sampling at the period start, compensated, compared at the sample).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, NamedTuple

import equinox as eqx
import numpy as np
from jax.typing import ArrayLike

from .. import drive as D
from .. import linear, papers
from ..metrics import wrap
from ..observers import (
    SOIFO,
    LPFFlux,
    ObserverBank,
    PureIntegratorFlux,
    SecondOrderSOIFO,
)
from ..runtime.progress import Progress, ProgressArg
from ._run import Run, run_kept
from .compare import annotate

__all__ = [
    "FLUX_EXPERIMENTS",
    "OBSERVER_NAMES",
    "FluxExperiment",
    "Measure",
    "flux_bank",
    "format_rows",
    "run_flux_experiment",
    "run_flux_experiments",
]

OBSERVER_NAMES = ("integrator", "LPF", "SOIFO", "second-order SOIFO")
# 000's gains (Fig. 5 and Sec. IV), under the paper's names; jaxobs.papers is their home.
K_SOIFO, K1, K2 = papers.SOIFO_K, papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2


# 000's DSP as we model it (module doc): PWM-centre sampling, one period of computation, compared in use;
# with FOC advance 0 (no compensation)
DSP_000 = D.Latency(D.PWMCentre(), 1, D.AtUse())
DSP_000_ADVANCE = 0.0
# The inverter's dead time of the hardware variants (000 gives none; 1 µs, uncompensated, ASSUMED): the load
# step and the dc offsets also run with it, to show what the inverter does to the paper's numbers
DEAD_TIME = 1e-6
DEAD_TIME_SUFFIX = ", dead time 1 µs"
LPF_FIT = 360.0  # rad/s: the LPF corner that fits 000's two steady LPF errors with the delay (not Fig. 5's 100)


def flux_bank(
    est: D.PMSMParams,
    omega_e: float,
    *,
    lam_soifo: ArrayLike = linear.soifo_lambda(K_SOIFO),
    lam_sosoifo: ArrayLike = linear.second_order_soifo_lambda(K1, K2),
    K1_: float = K1,
    K2_: float = K2,
    k: float = K_SOIFO,
    primary: int = 3,
    lpf_omega_c: float = papers.LPF_OMEGA_C,
) -> ObserverBank:
    """The four observers of 000 with the Fig. 5 settings, bound by their one binding (``ObserverBank.bind``).

    Args:
        est: the machine they assume.
        omega_e: their start, rad/s.
        lam_soifo: the SOIFO's FLL gain.
        lam_sosoifo: the second-order SOIFO's FLL gain.
        K1_: the second-order SOIFO's K1.
        K2_: its K2.
        k: the SOIFO's gain.
        primary: the index in :data:`OBSERVER_NAMES` of the one that closes the loop (default the second-order
            SOIFO).
        lpf_omega_c: the LPF's corner, rad/s (default Fig. 5's).

    Returns:
        The bound :class:`~jaxobs.ObserverBank`.
    """
    kp, ki = linear.pll_gains(2 * math.pi * papers.FLUX_PLL_HZ)
    # Rs = 0, L = 1 and omega_init = 1 rad/s are placeholders: bind() sets the assumed machine and the start speed
    # eqx.AbstractVar ts (a property here) reads as a field to pyright's dataclass transform
    bank = ObserverBank(  # pyright: ignore[reportCallIssue]
        (
            PureIntegratorFlux(0.0, 1.0, kp, ki),
            LPFFlux(0.0, 1.0, lpf_omega_c, kp, ki),
            SOIFO(0.0, 1.0, k, lam_soifo, omega_init=1.0),
            SecondOrderSOIFO(0.0, 1.0, K1_, K2_, lam_sosoifo, omega_init=1.0),
        ),
        primary=primary,
    )
    return bank.bind(est, omega_e)


def _window(t, start, stop):
    return (t >= start) & (t < stop)


def _obs_metrics(sol, i, mask):
    o = sol.outputs.obs.each[i]
    err = np.asarray(wrap(o.theta - sol.outputs.theta_e))[mask]
    pa, pb = np.asarray(o.psi_a)[mask], np.asarray(o.psi_b)[mask]
    finite = bool(np.all(np.isfinite(err)))
    return dict(
        max_abs=float(np.max(np.abs(err))) if finite else math.nan,
        mean=float(np.mean(err)) if finite else math.nan,
        ripple=float(np.ptp(err)) if finite else math.nan,
        flux_offset=float(np.hypot(np.mean(pa), np.mean(pb))) if finite else math.nan,
    )


def _rows(experiment, sol, mask, metrics_wanted, paper):
    rows = []
    for i, name in enumerate(OBSERVER_NAMES):
        m = _obs_metrics(sol, i, mask)
        for metric, unit in metrics_wanted:
            rows.append(
                dict(
                    experiment=experiment,
                    observer=name,
                    metric=metric,
                    unit=unit,
                    paper=paper.get((name, metric)),
                    ours=m[metric],
                )
            )
    return rows


def _delay_rows(experiment, sol, mask, rpm, paper, p=3, ts=1e-4):
    """The SOIFOs' steady error in samples of ωe·Ts, −mean/(ωe Ts), beside the paper's error in samples
    (the line 000's explanation predicts: our model gives 2.5, jaxobs.drive.latency)."""
    w_ts = p * rpm * D.RPM * ts
    rows = []
    for i, name in enumerate(OBSERVER_NAMES):
        if name not in ("SOIFO", "second-order SOIFO"):
            continue
        m = _obs_metrics(sol, i, mask)
        ref = paper.get((name, "max_abs"))
        rows.append(
            dict(
                experiment=experiment,
                observer=name,
                metric="delay_samples",
                unit="ωe·Ts",
                paper=None if ref is None else ref / w_ts,
                ours=-m["mean"] / w_ts,
            )
        )
    return rows


def _periods(rpm, n, p=3):
    return n * 2 * math.pi / (p * rpm * D.RPM)


class Measure(NamedTuple):
    """What one experiment's rows measure: every observer's ``metrics`` over a window of its run."""

    window: tuple[float, float]  # s: [start, stop)
    metrics: tuple[tuple[str, str], ...]  # (metric, unit) of :func:`_obs_metrics`
    label: str = ""  # appended to the experiment's name in the rows
    delay: bool = False  # also the SOIFOs' steady error in samples (:func:`_delay_rows`)
    observers: tuple[str, ...] = OBSERVER_NAMES  # the observers whose rows are kept


class FluxExperiment(NamedTuple):
    """One of 000's experiments: its scenario on the bench, what is measured and the paper's values.

    :func:`run_flux_experiment` runs any one; :data:`FLUX_EXPERIMENTS` is the table of them.
    """

    name: str  # the rows' experiment
    figure: str  # where 000 shows it
    rpm0: int  # r/min, the start (and the observers' start speed unless ``omega0``)
    t1: float  # s, the horizon
    handover: float  # s, the encoder's hand-over to the observer
    speed_ref: Callable[[], D.Profile]  # the speed reference, rad/s
    measures: tuple[Measure, ...]  # the rows' windows and metrics
    paper: Mapping[tuple[str, str], float]  # (observer, metric) -> the paper's value
    load: Callable[[], D.Profile] | None = None  # N·m (None: no load)
    sensors: Callable[[], D.Sensors] | None = None  # the measurement errors (None: ideal)
    rs_scale: float | None = None  # the observers assume this × Rs (None: the true machine)
    startup: Callable[[D.PMSMParams], D.IfStartup] | None = None  # an I-f start (None: started steady)
    omega0: Callable[[D.PMSMParams], float] | None = None  # rad/s, the observers' start (None: at rpm0)
    alpha_s: float = 2 * math.pi * papers.BENCH_SPEED_HZ  # rad/s, the speed loop's bandwidth
    dead_time: float = 0.0  # s, the inverter's
    lpf_omega_c: float = papers.LPF_OMEGA_C  # rad/s, the LPF's corner
    speed_schedule: float = 0.0  # the FOC's speed schedule N (0: the fixed loop)
    speed_rows: str | None = None  # "range": the drive's min and max speed over the first window; "final"
    speed_paper: float | None = None  # r/min, the paper's speed for ``speed_rows``
    quick: bool = True  # runs under ``quick``


def _steady_window(rpm: int, t1: float, n: int) -> tuple[float, float]:
    """The last ``n`` electrical periods at ``rpm`` before ``t1``."""
    return (t1 - _periods(rpm, n), t1)


def _if_startup(par: D.PMSMParams) -> D.IfStartup:
    """Fig. 20's I-f start to 20 r/min."""
    we_sw = par.p * 20 * D.RPM
    return D.IfStartup(i_f=4.0, accel=we_sw / 0.5, omega_switch=we_sw, hold=4.0)


_ERR = (("max_abs", "rad"),)
_ERR_MEAN = (("max_abs", "rad"), ("mean", "rad"))
_DC = (("flux_offset", "Wb"), ("ripple", "rad"))
_STEADY_PAPER = {
    2000: {("LPF", "max_abs"): 0.4, ("SOIFO", "max_abs"): 0.15, ("second-order SOIFO", "max_abs"): 0.13},
    400: {
        ("integrator", "max_abs"): 6.0,
        ("LPF", "max_abs"): 1.2,
        ("SOIFO", "max_abs"): 0.035,
        ("second-order SOIFO", "max_abs"): 0.03,
    },
}
_DC_PAPER = {
    "du_alpha = 5 V at 1000 r/min": {
        ("LPF", "flux_offset"): 0.05,
        ("SOIFO", "flux_offset"): 0.03,
        ("second-order SOIFO", "flux_offset"): 0.0,
        ("LPF", "ripple"): 0.65,
        ("SOIFO", "ripple"): 0.25,
        ("second-order SOIFO", "ripple"): 0.0,
    },
    "di_beta = 1.5 A at 1000 r/min": {
        ("LPF", "flux_offset"): 0.03,
        ("SOIFO", "flux_offset"): 0.017,
        ("second-order SOIFO", "flux_offset"): 0.005,
        ("LPF", "ripple"): 0.6,
        ("SOIFO", "ripple"): 0.22,
        ("second-order SOIFO", "ripple"): 0.0,
    },
}
_DC_SENSORS = {
    "du_alpha = 5 V at 1000 r/min": lambda: D.Sensors(u_offset=(5.0, 0.0)),
    "di_beta = 1.5 A at 1000 r/min": lambda: D.Sensors(i_offset=(0.0, 1.5)),
}
_DEAD_TIMES = (("", 0.0), (DEAD_TIME_SUFFIX, DEAD_TIME))


def _constant(rpm: int) -> Callable[[], D.Profile]:
    return lambda: D.Profile.constant(rpm * D.RPM)


FLUX_EXPERIMENTS: tuple[FluxExperiment, ...] = (
    # --- A. steady state, no load (Figs. 10-17)
    *(
        FluxExperiment(
            f"steady {rpm} r/min", "Figs. 10-17", rpm, t1, hand, _constant(rpm),
            (Measure(_steady_window(rpm, t1, 5), _ERR_MEAN, delay=True),), _STEADY_PAPER[rpm],
        )
        for rpm, t1, hand in ((2000, 0.6, 0.2), (400, 1.6, 0.8))
    ),
    # The LPF's corner that fits both of the paper's LPF errors with the delay (docs/papers.md): its
    # lead atan(ωc/ω1) less the delay's lag gives 0.4 rad at 2000 r/min and 1.2 at 400 for ωc ≈ 360
    *(
        FluxExperiment(
            f"steady {rpm} r/min, LPF ωc = {LPF_FIT:g} rad/s", "Figs. 10-17 (docs/papers.md)", rpm, t1, hand,
            _constant(rpm), (Measure(_steady_window(rpm, t1, 5), _ERR, observers=("LPF",)),),
            {("LPF", "max_abs"): paper}, lpf_omega_c=LPF_FIT, quick=False,
        )
        for rpm, t1, hand, paper in ((2000, 0.6, 0.2, 0.4), (400, 1.6, 0.8, 1.2))
    ),
    # At 20 r/min (ωe = 6.3 rad/s) the FLLs' bandwidth (∝ ωe) is below the bench's 5 Hz speed loop:
    # sensorless with the speed loop scheduled inside it, FOC(speed_schedule=6), the observers settled
    # over 10 periods first (_simulate: Drive.settled_for; docs/stability.md "20 r/min").
    FluxExperiment(
        "steady 20 r/min", "docs/stability.md", 20, 3.0, 0.0, _constant(20),
        (Measure((3.0 - 1.0, 3.0), _ERR_MEAN, delay=True),), {}, speed_schedule=6.0, speed_rows="range",
        speed_paper=20.0, quick=False,
    ),
    # --- B. speed variation 400 <-> 2000 r/min (Fig. 18)
    FluxExperiment(
        "speed 400-2000-400 r/min", "Fig. 18", 400, 3.0, 0.8,
        lambda: D.Scenario.speed_rpm([0.0, 1.0, 2.0], [400, 2000, 400], ramp=0.5), (Measure((1.0, 3.0), _ERR),),
        {("LPF", "max_abs"): 1.2, ("SOIFO", "max_abs"): 0.15, ("second-order SOIFO", "max_abs"): 0.13},
    ),
    # --- C. load step 0 -> 10 N·m at 2000 r/min (Fig. 19), on the ideal inverter and with a dead time
    *(
        FluxExperiment(
            "load step 10 N·m at 2000 r/min" + suffix, "Fig. 19", 2000, 0.8, 0.2, _constant(2000),
            (Measure((0.4, 0.8), _ERR),),
            {("LPF", "max_abs"): 1.3, ("SOIFO", "max_abs"): 0.25, ("second-order SOIFO", "max_abs"): 0.20},
            load=lambda: D.Scenario.load_steps([0.0, 0.4], [0.0, 10.0]), dead_time=dt,
        )
        for suffix, dt in _DEAD_TIMES
    ),
    # --- D. dc disturbances at 1000 r/min (Figs. 21-22)
    *(
        FluxExperiment(
            label + suffix, "Figs. 21-22", 1000, 1.0, 0.4, _constant(1000),
            (Measure(_steady_window(1000, 1.0, 10), _DC),), _DC_PAPER[label], sensors=_DC_SENSORS[label],
            dead_time=dt,
        )
        for label in _DC_PAPER
        for suffix, dt in _DEAD_TIMES
    ),
    # --- E. Rs mismatch: the observers assume 0.4 Rs0, 10 N·m at 1000 r/min (Fig. 23)
    FluxExperiment(
        "Rs_est = 0.4 Rs0, 10 N·m, 1000 r/min", "Fig. 23", 1000, 1.0, 0.4, _constant(1000),
        (Measure(_steady_window(1000, 1.0, 10), (*_ERR_MEAN, ("ripple", "rad"))),),
        # "the estimated rotor position does not fluctuate" (Sec. IV-C): no ripple, of the proposed observers
        {("SOIFO", "ripple"): 0.0, ("second-order SOIFO", "ripple"): 0.0},
        load=lambda: D.Scenario.load_steps([0.0, 0.2], [0.0, 10.0]), rs_scale=0.4,
    ),
    # --- F. I-f start to 20 r/min, sensorless to 200 r/min, load step (Fig. 20).  The speed loop closes through
    # the FLL's ω̂, whose bandwidth at 20 r/min is ~5 rad/s: α_s = 2π·1 rad/s, and a load step the paper does
    # not size, 0.5 N·m.
    FluxExperiment(
        "I-f start, 20 -> 200 r/min, 0.5 N·m step", "Fig. 20", 0, 10.0, 0.0,
        lambda: D.Scenario.speed_rpm([0.0, 5.0], [20, 200], ramp=1.0),
        (Measure((4.0, 10.0), _ERR), Measure((7.0, 10.0), _ERR, label=" (last 3 s)")), {},
        load=lambda: D.Scenario.load_steps([0.0, 8.0, 9.0], [0.0, 0.5, 0.0]), startup=_if_startup,
        omega0=lambda par: par.p * 20 * D.RPM, alpha_s=2 * math.pi * 1.0, speed_rows="final", speed_paper=200.0,
        quick=False,
    ),
)  # fmt: skip


def _simulate(exp: FluxExperiment, par: D.PMSMParams) -> Run:
    """``exp``'s run: the bench sensorless on the second-order SOIFO, all four observers on its measurements."""
    est = par if exp.rs_scale is None else eqx.tree_at(lambda m: m.Rs, par, exp.rs_scale * par.Rs)
    startup = None if exp.startup is None else exp.startup(par)
    w0 = par.p * exp.rpm0 * D.RPM if exp.omega0 is None else exp.omega0(par)
    sc = D.Scenario(
        par,
        est_par=est,
        speed_ref=exp.speed_ref(),
        load=None if exp.load is None else exp.load(),
        sensors=None if exp.sensors is None else exp.sensors(),
        omega_m0=exp.rpm0 * D.RPM if startup is None else 0.0,
        dead_time=exp.dead_time,
    )
    # 000's sampling delay (module doc), in every experiment
    drive = D.bench_drive(
        par, handover=exp.handover, startup=startup, alpha_s=exp.alpha_s, latency=DSP_000, advance=DSP_000_ADVANCE,
        speed_schedule=exp.speed_schedule,
    )  # fmt: skip
    if startup is None:  # the observers settled over 10 electrical periods first (10 s at 20 r/min)
        drive = drive.settled_for(par.p * exp.rpm0 * D.RPM)
    return run_kept(D.ClosedLoop(drive, flux_bank(est, w0, lpf_omega_c=exp.lpf_omega_c), sc), exp.t1)


def run_flux_experiment(exp: FluxExperiment, par: D.PMSMParams) -> tuple[list[dict[str, Any]], Run]:
    """Run one of 000's experiments and measure it.

    Args:
        exp: the experiment (a record of :data:`FLUX_EXPERIMENTS`).
        par: the bench's machine (:func:`jaxobs.drive.bench_machine` "spmsm000").

    Returns:
        (rows, run): its rows {experiment, observer, metric, unit, paper, ours}, not yet annotated, and its run.
    """
    sol = _simulate(exp, par)
    t = np.asarray(sol.t)
    rows = []
    for ms in exp.measures:
        mask = _window(t, *ms.window)
        name = exp.name + ms.label
        rows += [r for r in _rows(name, sol, mask, ms.metrics, exp.paper) if r["observer"] in ms.observers]
        if ms.delay:
            rows += _delay_rows(name, sol, mask, exp.rpm0, exp.paper)
    if exp.speed_rows == "range":
        rpm_t = np.asarray(sol.outputs.speed_rpm)[_window(t, *exp.measures[0].window)]
        for metric, v in (("min_speed", rpm_t.min()), ("max_speed", rpm_t.max())):
            rows.append(
                dict(experiment=exp.name, observer="drive", metric=metric, unit="r/min", paper=exp.speed_paper,
                     ours=float(v))
            )  # fmt: skip
    elif exp.speed_rows == "final":
        rpm = np.asarray(sol.outputs.speed_rpm)
        rows.append(
            dict(experiment=exp.name, observer="second-order SOIFO", metric="final_speed", unit="r/min",
                 paper=exp.speed_paper, ours=float(rpm[-1]))
        )  # fmt: skip
    return rows, sol


def run_flux_experiments(
    quick: bool = False, progress: ProgressArg = None
) -> tuple[list[dict[str, Any]], dict[str, Run]]:
    """Run 000's experiments (:data:`FLUX_EXPERIMENTS`, in order).

    Args:
        quick: skip the 20 r/min and start-up runs (several simulated seconds each) and the LPF corner's fit.
        progress: one step per experiment, each named as it compiles and runs (:mod:`jaxobs.runtime.progress`:
            ``True`` a tqdm bar on stderr, or a callable ``progress(done, total)``).

    Returns:
        (rows, traces): rows {experiment, observer, metric, unit, paper, ours, tolerance, within, explanation}
        (:mod:`jaxobs.reproduce.compare`), and each experiment's run by name.
    """
    par = D.bench_machine("spmsm000")
    rows, traces = [], {}
    bar = Progress(progress, None, "reproduce flux", unit="experiment")
    for exp in FLUX_EXPERIMENTS:
        if quick and not exp.quick:
            continue
        bar.stage(f"{exp.name} ({exp.t1:g} s)")
        exp_rows, traces[exp.name] = run_flux_experiment(exp, par)
        bar.update()
        rows += exp_rows
    for name, sol in traces.items():
        rows.append(
            dict(experiment=name, observer="drive", metric="finite", unit="bool", paper=None, ours=bool(sol.ok))
        )
    bar.close()
    return annotate(rows, EXPLANATIONS), traces


def format_rows(rows: Sequence[Mapping[str, Any]]) -> str:
    """The rows as a fixed-width table; each text column as wide as its longest entry plus a space.

    Args:
        rows: the rows {experiment, observer, metric, unit, paper, ours}.

    Returns:
        The table.
    """
    cols = ("experiment", "observer", "metric", "unit")
    width = {c: max([len(c)] + [len(str(r[c])) for r in rows]) + 1 for c in cols}
    head = "".join(f"{c:<{width[c]}}" for c in cols) + f"{'paper':>9}{'ours':>11}"
    out = [head, "-" * len(head)]
    for r in rows:
        paper = "" if r["paper"] is None else f"{r['paper']:.3g}"
        ours = r["ours"]
        ours = str(ours) if isinstance(ours, bool) else f"{ours:.4g}"
        out.append("".join(f"{str(r[c]):<{width[c]}}" for c in cols) + f"{paper:>9}{ours:>11}")
    return "\n".join(out)


# Why our number differs from the paper's, for the rows outside their tolerance (jaxobs.reproduce.compare);
# each cause is measured, by the companion rows named or in docs/papers.md ("Paper 000 ... paper vs ours")
_S2000, _S400, _RAMP = "steady 2000 r/min", "steady 400 r/min", "speed 400-2000-400 r/min"
_LPF_SOIFO, _METRICS_DC = ("LPF", "SOIFO"), ("flux_offset", "ripple")
_STEP, _DU, _DI = "load step 10 N·m at 2000 r/min", "du_alpha = 5 V at 1000 r/min", "di_beta = 1.5 A at 1000 r/min"
_LPF_CORNER = (
    "the LPF's corner: with the delay both of the paper's LPF errors (0.4 rad at 2000 r/min, 1.2 at 400) fit "
    f"ωc ≈ {LPF_FIT:g} rad/s (rows 'LPF ωc = {LPF_FIT:g} rad/s'), not Fig. 5's 100 rad/s, whose lead "
    "atan(ωc/ω1) = 0.158 rad at 2000 r/min nearly cancels the delay's 0.157 rad lag"
)
_LPF_STEP = (
    "the LPF's corner and a lighter bench, together: with ωc = 360 rad/s (which fits the paper's steady LPF "
    "errors) and 3x Table II's J instead of 10x the LPF peaks at 0.96 rad (the SOIFOs 0.39 / 0.35); with "
    "the LPF closing the loop on 5x J at 0.88, oscillating as the paper's does (the SOIFOs 0.26 / 0.24); "
    "each alone stays under 0.5 rad (docs/papers.md, Paper 000 (e)); the paper gives neither its corner nor its "
    "inertia.  Unexplained: the last 0.34 rad (1.3 against 0.96 at best): no combination measured reaches 1.3 "
    "and keeps the drive (closing on 3x J loses it)"
)
_INERTIA = (
    "the step's dynamic error rides on the 0.157 rad delay: the assumed bench inertia (10x Table II's J) "
    "and ideal inverter make it small; 3x J gives 0.39 rad, a 1 µs dead time 0.164 (row ', dead time 1 µs'), "
    "2 µs 0.198"
)
_OFFSET_RIPPLE = (
    "an offset d on the LPF's circle of radius r swings the angle by 2 asin(d/r): 0.05 Wb on 0.334 Wb "
    "(0.35 attenuated) is 0.30 rad p-p, so the paper's 0.65 with its 0.05 Wb needs more: the inverter's "
    "6th-harmonic ripple adds to it (1 µs dead time: 0.41, row ', dead time 1 µs'; 2 µs: 0.47)"
)
_DI_OFFSET = (
    "the drive regulates the measured current, so the machine carries the −1.5 A: the observers see only "
    "its Rs·Δi (1.2 V); the inverter turns that dc current into a dc voltage error the observers integrate "
    "(rows ', dead time 1 µs': offsets 0.078 / 0.042 Wb, ripples 0.48 / 0.26 rad): the right way, overshooting. "
    "Unexplained: no one dead time fits both, without it offsets and ripples are 2.5-7x low, with 1 µs the "
    "ripples fit and the offsets are 2.5x high; the paper's inverter (its dead time, its compensation) is not given"
)
EXPLANATIONS = {
    (_S2000, "LPF", "max_abs"): _LPF_CORNER,
    (_S400, "LPF", "max_abs"): _LPF_CORNER,
    (_RAMP, "LPF", "max_abs"): _LPF_CORNER,
    (_S400, "integrator", "max_abs"): (
        "the integrator starts from zero, as the paper's after its open-loop start: its circle then passes "
        "through the origin and its error swings ±π/2 (ours: π/2 + the delay).  The paper's 6.0 rad sweeps "
        "nearly 2π: its circle has drifted off the origin, an integrated dc offset in ê (the 'vertically "
        "eccentric' circles of Figs 13-14); ours has none here, and with Δuα = 5 V its error sweeps 2π too"
    ),
    (_RAMP, "second-order SOIFO", "max_abs"): (
        "our delay is 2.5 samples (0.157 rad at 2000 r/min) where the paper's steady 0.13 rad is 2.07: the "
        "assumed DSP timing adds 0.027 rad; the rest is the FLL's lag as the ramp starts (Fig. 18 (c) here)"
    ),
    (_STEP, "LPF", "max_abs"): _LPF_STEP,
    (_STEP + DEAD_TIME_SUFFIX, "LPF", "max_abs"): _LPF_STEP,
    (_STEP, "SOIFO", "max_abs"): _INERTIA,
    (_STEP + DEAD_TIME_SUFFIX, "SOIFO", "max_abs"): _INERTIA,
    (_DU, "LPF", "ripple"): _OFFSET_RIPPLE,
    (_DU + DEAD_TIME_SUFFIX, "LPF", "ripple"): _OFFSET_RIPPLE,
    (_DU, "SOIFO", "ripple"): (
        "the SOIFO's offset (0.027 Wb, paper 0.03) swings its angle by 0.16 rad p-p; the paper's 0.25 has "
        "the inverter's ripple on top: with a 1 µs dead time 0.28 (row ', dead time 1 µs')"
    ),
    (_DU + DEAD_TIME_SUFFIX, "second-order SOIFO", "ripple"): (
        "the dead time's 5th/7th-harmonic voltage passes the second-order SOIFO too (eq (21)'s factor at "
        "h = 5, 7): 0.12 rad p-p with 1 µs, where the paper shows none; its inverter is compensated or "
        "faster than this assumption, which overstates the ripple here"
    ),
    **{(_DI + sfx, obs, m): _DI_OFFSET for sfx in ("", DEAD_TIME_SUFFIX) for obs in _LPF_SOIFO for m in _METRICS_DC},
    **{
        (_DI + sfx, "second-order SOIFO", "flux_offset"): (
            "the second-order SOIFO rejects dc (eq 36): what is left is the rotor's own response to the torque "
            "ripple of the dc current (0.0017 Wb; 0.0007 with the dead time); the paper's 0.005 Wb, 1.4 % of "
            "ψf, is read off its trace"
        )
        for sfx in ("", DEAD_TIME_SUFFIX)
    },
}
