"""Paper 002's experiments (Sec. V) on the simulated IPMSM drive: ``jaxobs reproduce leso``.

Set-up and assumptions (our copy of 002 lacks the machine table and the PLL section):

- Machine: the ASSUMED IPMSM preset (:func:`jaxobs.drive.ipmsm_paper002`), p = 5, so
  300/600/840 r/min are 25/50/70 Hz as in 002, on a bench whose total inertia we
  ASSUME to be 10× the motor's (0.05 kg·m²: a load machine is coupled; with the
  motor alone an 80 % load step stalls the drive before any speed loop reacts).  i_d* = 0, plus
  voltage-feedback field weakening in the speed ramp (002 engages field weakening, its ref. [32];
  :mod:`jaxobs.drive.weakening`).  With the assumed machine and the 540 V dc link, 840 r/min (198 V of
  back EMF against u_max = 312 V) is below base speed, so the field weakening is engaged but idle (the
  rows ``max_u`` and ``min_id`` show it); 002 gives no dc-link voltage.  On a 330 V link it acts
  (tests/test_weakening.py, encoder-driven); sensorless on the FA-LESO there the ramp holds with the speed
  loop at 2.5 Hz (SENSORLESS_FW_SPEED_HZ; docs/papers.md), drawn in the paper's layout with its i_d
  (jaxobs.reproduce.figures.LESO_FIGURES).
- Observers with 002 Table II's gains: C-LESO ω0 = 500π; GI-LESO ω0 = 500π,
  K_r = 2ω0², ωc = π; FA-LESO k1 = 10π, k2 = 100π; each with our PLL
  (ω_b = 2π·15 rad/s, ζ = 1/√2, pole placement).
- The drive runs sensorless on the FA-LESO (after an encoder hand-over); the
  C- and GI-LESO estimate from the same measurements (an ObserverBank).  The speed ramp and the
  load step are run three times, each LESO in turn closing the loop (002 Figs 16-17 (a)-(c)); the
  FA-LESO's runs keep the plain experiment names, the others carry ", C-LESO closing the loop" etc.
- 002 Sec. V-B: the C-LESO "cannot complete" half load at 600 r/min (hence Fig. 14's 40 %).  We
  run that test with the C-LESO closing the loop ("half load 600 r/min, C-LESO closing the loop"):
  on our drive it holds (rows ``holds``, ``max_abs``, ``speed_dev``); docs/papers.md says why.
- BEMF harmonics (Sec. V-B): 002 does not give the machine's harmonic content;
  we set a5 = 6.75 % and a7 = 8.79 % so that the C-LESO's *transfer function*
  at 300 r/min predicts the C-LESO percentages 002 measured (5.4 % and 5.9 %).
  Everything else in that experiment is then a prediction.
- Position error = θ̂e (PLL) − θe, wrapped, in degrees.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

import numpy as np

from .. import drive as D
from .. import linear, papers
from ..metrics import harmonic_amplitude, wrap
from ..observers import CLESO, FALESO, GILESO, ObserverBank
from ..runtime.progress import Progress, ProgressArg
from ._run import Run, run_kept
from .compare import annotate

__all__ = [
    "EXPLANATIONS",
    "FIG18_NAMES",
    "LESO_EXPERIMENTS",
    "LESO_NAMES",
    "LesoExperiment",
    "leso_bank",
    "run_leso_experiment",
    "run_leso_experiments",
]

LESO_NAMES = ("C-LESO", "GI-LESO", "FA-LESO")
# 002 Table II's gains and our ASSUMED harmonic content, under short names; jaxobs.papers is their home.
A5, A7 = papers.IPMSM_002_A5, papers.IPMSM_002_A7
W0, K_R, WC_GI = papers.LESO_OMEGA0, papers.GILESO_K_R, papers.GILESO_OMEGA_C
K1_FA, K2_FA = papers.FALESO_K1, papers.FALESO_K2


def leso_bank(
    est: D.PMSMParams, omega_e: float, pll: tuple[float, float] | None = None, primary: int = 2
) -> ObserverBank:
    """C-, GI- and FA-LESO with 002 Table II's gains, bound by their one binding (``ObserverBank.bind``).

    Args:
        est: the machine they assume (its Rs, Lq).
        omega_e: their PLLs' start, rad/s.
        pll: the PLLs' (kp, ki) (None: :func:`jaxobs.linear.pll_gains` at papers.LESO_PLL_HZ).
        primary: the one that closes the loop, an index into LESO_NAMES (default the FA-LESO).

    Returns:
        The bound :class:`~jaxobs.ObserverBank`.
    """
    kp, ki = linear.pll_gains(2 * math.pi * papers.LESO_PLL_HZ) if pll is None else pll
    # Rs = 0, Lq = 1 are placeholders: bind() sets the assumed machine and the PLLs' start speed
    # eqx.AbstractVar ts (a property here) reads as a field to pyright's dataclass transform
    bank = ObserverBank(  # pyright: ignore[reportCallIssue]
        (
            CLESO(0.0, 1.0, W0, kp, ki),
            GILESO(0.0, 1.0, W0, K_R, WC_GI, kp, ki),
            FALESO(0.0, 1.0, K1_FA, K2_FA, kp, ki),
        ),
        primary=primary,
    )
    return bank.bind(est, omega_e)


def _tfs(we):
    """The three LESOs' ê/e at ω̂e = ``we`` (002 Table II's gains), in LESO_NAMES' order."""
    return linear.cleso_tf(W0), linear.gileso_tf(W0, K_R, WC_GI, we), linear.faleso_tf(K1_FA, K2_FA, we)


def _err_deg(sol, i):
    return np.degrees(np.asarray(wrap(sol.outputs.obs.each[i].theta - sol.outputs.theta_e)))


def _speed_err_rpm(sol, i, par, m):
    """max |ω̂m − ωm| (r/min) of observer ``i`` over the mask ``m``."""
    o = sol.outputs
    return float(np.max(np.abs(np.asarray(o.obs.each[i].omega) / par.p - np.asarray(o.omega_m))[m]) * 30 / math.pi)


def _closing_rows(name, sol, i, par, m, paper_deg, paper_rpm):
    """The peak position error (deg) and speed-estimate error (r/min) of observer ``i`` where ``m``."""
    return [
        dict(
            experiment=name,
            observer=LESO_NAMES[i],
            metric="max_abs",
            unit="deg",
            paper=paper_deg,
            ours=float(np.abs(_err_deg(sol, i)[m]).max()),
        ),
        dict(
            experiment=name,
            observer=LESO_NAMES[i],
            metric="max_speed_err",
            unit="r/min",
            paper=paper_rpm,
            ours=_speed_err_rpm(sol, i, par, m),
        ),
    ]


def _ramp_rows(name, sol, t, par, inv, i=2):
    """The speed ramp's rows: observer ``i``'s peak error and speed error after 0.6 s (002 Fig. 16: 4.5° is the
    FA-LESO's, 13 r/min all three's), and the field weakening's work: the peak voltage |u|/u_max and the most
    negative i_d."""
    m = t >= 0.6
    o = sol.outputs
    u_pu = np.hypot(np.asarray(o.u_a), np.asarray(o.u_b)) / float(inv.u_max)
    return [
        *_closing_rows(name, sol, i, par, m, 4.5 if i == 2 else None, 13.0),
        dict(experiment=name, observer="drive", metric="max_u", unit="u_max", paper=None, ours=float(u_pu.max())),
        dict(experiment=name, observer="drive", metric="min_id", unit="A", paper=None, ours=float(np.min(o.i_d))),
        dict(
            experiment=name,
            observer="drive",
            metric="max_speed",
            unit="r/min",
            paper=840.0,
            ours=float(np.max(np.asarray(o.speed_rpm))),
        ),
    ]


def _speed_mode_rows(name, par, rpm, i_d, speed_hz=papers.BENCH_SPEED_HZ):
    """The least damped pole of the bench's speed loop (I-P at 2π·``speed_hz`` rad/s) closed through the
    FA-LESO's PLL at ``rpm`` and i_d (A) (:func:`jaxobs.linear.faleso_speed_loop_poles`): its damping ratio
    and frequency (Hz)."""
    kp, ki = linear.pll_gains(2 * math.pi * papers.LESO_PLL_HZ)
    a = 2 * math.pi * speed_hz
    kp_w, ki_w = 2 * a * float(par.J) / float(par.kt), a * a * float(par.J) / float(par.kt)
    we = par.p * rpm * D.RPM
    r = np.asarray(
        linear.faleso_speed_loop_poles(
            K1_FA, K2_FA, we, kp, ki, kp_w, ki_w,
            p=par.p, psi_f=float(par.psi_f), Ld=float(par.Ld), Lq=float(par.Lq), J=float(par.J), i_d=i_d,
        )
    )  # fmt: skip
    r = r[np.abs(r.imag) < we / 2]  # without the FA-LESO's slow mode at ±jωe
    m = r[np.argmax(np.real(r))]  # in r's precision (np.real, np.imag: the stubs type no .real of it)
    return [
        dict(
            experiment=name,
            observer="drive",
            metric="speed_mode_zeta",
            unit="1",
            paper=None,
            ours=float(-np.real(m) / abs(m)),
        ),
        dict(
            experiment=name,
            observer="drive",
            metric="speed_mode_hz",
            unit="Hz",
            paper=None,
            ours=float(abs(np.imag(m)) / (2 * math.pi)),
        ),
    ]


# The speed loop (Hz) of the sensorless ramp on a 330 V link: half the bench's, so that the speed loop closed
# through the 15 Hz PLL stays damped with the field weakening's i_d (jaxobs.linear.faleso_speed_loop_poles).
SENSORLESS_FW_SPEED_HZ = 2.5

# 002 Fig. 18: the observer's R̂s, then L̂q, ramped 1 → 1.5 → 0.5 → 1 p.u. during one run at rated load,
# 300 r/min (jaxobs.drive.ParameterDrift; the FOC keeps the nominal machine).  Times (s) and factors (p.u.);
# the plateaus [0.85, 1.0) s at 1.5 and [1.95, 2.1) s at 0.5 p.u. are scored after 0.15 s of settling.
FIG18_TIMES = (0.0, 0.3, 0.7, 1.0, 1.8, 2.1, 2.5)
FIG18_FACTORS = (1.0, 1.0, 1.5, 1.5, 0.5, 0.5, 1.0)
FIG18_PLATEAUS = ((1.5, 0.85, 1.0), (0.5, 1.95, 2.1))
FIG18_T1 = 2.6
FIG18_NAMES = {
    "Rs": "Fig. 18 (a): R̂s ramped 1-1.5-0.5-1 p.u., rated load, 300 r/min",
    "Lq": "Fig. 18 (b): L̂q ramped 1-1.5-0.5-1 p.u., rated load, 300 r/min",
}


Rows = list[dict[str, Any]]
# (experiment, run, t, true machine, drive options) -> its rows
Measure = Callable[["LesoExperiment", Run, np.ndarray, D.PMSMParams, Mapping[str, Any]], Rows]


def _fig18_measure(exp: LesoExperiment, sol: Run, t: np.ndarray, par: D.PMSMParams, kw: Mapping[str, Any]) -> Rows:
    """002 Fig. 18 closing the loop on the FA-LESO: its mean error on each plateau of the ramped R̂s or L̂q,
    beside eqs (42)-(43) at the currents measured there (Δ = true − assumed), and the FA-LESO's |êα| on the
    plateaus relative to the nominal one (002: "hardly changes")."""
    rows = []
    which, name = exp.drift, exp.name
    assert which is not None
    we = par.p * 300 * D.RPM
    e_ex = we * float(par.psi_f)  # E_ex at i_d = 0 (eqs 42-43)
    o = sol.outputs
    err = _err_deg(sol, 2)
    e_a = np.asarray(o.obs.each[2].e_a)
    nominal = (t >= 0.15) & (t < 0.3)
    amp0 = np.ptp(e_a[nominal]) / 2
    for factor, a, b in FIG18_PLATEAUS:
        m = (t >= a) & (t < b)
        delta = (1.0 - factor) * float(getattr(par, which))
        i_d, i_q = float(np.mean(np.asarray(o.i_d)[m])), float(np.mean(np.asarray(o.i_q)[m]))
        if which == "Rs":
            pred = math.degrees(float(linear.position_error_rs(delta, i_d, i_q, e_ex)))
        else:
            pred = math.degrees(float(linear.position_error_lq(delta, i_d, i_q, e_ex, we)))
        tag = f"{factor:g}pu"
        rows += [
            dict(
                experiment=name,
                observer="FA-LESO",
                metric=f"mean_error_{tag}",
                unit="deg",
                paper=0.0 if which == "Rs" else None,
                ours=float(np.mean(err[m])),
            ),
            dict(experiment=name, observer="FA-LESO", metric=f"eq42_43_{tag}", unit="deg", paper=None, ours=pred),
            dict(
                experiment=name,
                observer="FA-LESO",
                metric=f"e_amp_{tag}",
                unit="1",
                paper=None,
                ours=float(np.ptp(e_a[m]) / 2 / amp0),
            ),
        ]
    return rows


def _steady_measure(exp: LesoExperiment, sol: Run, t: np.ndarray, par: D.PMSMParams, kw: Mapping[str, Any]) -> Rows:
    """Steady state, no load (Figs. 10-12): each LESO's mean lag and ripple after 0.6 s, and its transfer
    function's lag (``exp.paper``: the paper's mean lags, in :data:`LESO_NAMES`' order)."""
    rows = []
    name, rpm = exp.name, exp.rpm0
    m = t >= 0.6
    for i, obs in enumerate(LESO_NAMES):
        err = _err_deg(sol, i)[m]
        # 002 reports the lag as a positive error; ours is θ̂ − θ (negative for a lag)
        rows.append(
            dict(
                experiment=name,
                observer=obs,
                metric="mean_lag",
                unit="deg",
                paper=exp.paper[i],
                ours=float(-err.mean()),
            )
        )
        rows.append(
            dict(
                experiment=name,
                observer=obs,
                metric="ripple",
                unit="deg",
                paper=2.3 if obs == "FA-LESO" else None,
                ours=float(np.ptp(err)),
                bound="upper",  # 002: "the fluctuation of the errors are within 2.3 deg"
            )
        )
    we = par.p * rpm * D.RPM
    for obs, tf in zip(LESO_NAMES, _tfs(we)):
        lag = -math.degrees(float(np.angle(complex(tf.freqresp(we)))))
        rows.append(dict(experiment=name, observer=obs, metric="tf_lag", unit="deg", paper=None, ours=lag))
    return rows


def _harmonics_measure(exp: LesoExperiment, sol: Run, t: np.ndarray, par: D.PMSMParams, kw: Mapping[str, Any]) -> Rows:
    """BEMF harmonics (Figs. 13-14): each LESO's 5th and 7th in ê over ten electrical periods, and its transfer
    function's prediction (``exp.paper``: the paper's (h5, h7) %, per LESO)."""
    rows = []
    name, rpm = exp.name, exp.rpm0
    we = par.p * rpm * D.RPM
    n_per = int(round(2 * math.pi / we / 1e-4))
    m = np.zeros_like(t, dtype=bool)
    m[-10 * n_per :] = True  # ten whole electrical periods
    for i, obs in enumerate(LESO_NAMES):
        ea = np.asarray(sol.outputs.obs.each[i].e_a)
        fund = float(harmonic_amplitude(t, ea, we, m))
        for h, paper in zip((5, 7), exp.paper[i]):
            pct = 100 * float(harmonic_amplitude(t, ea, h * we, m)) / fund
            rows.append(dict(experiment=name, observer=obs, metric=f"h{h}", unit="%", paper=paper, ours=pct))
    for obs, tf in zip(LESO_NAMES, _tfs(we)):
        for h, a, sgn in ((5, A5, -1), (7, A7, +1)):
            pred = 100 * a * abs(complex(tf.freqresp(sgn * h * we))) / abs(complex(tf.freqresp(we)))
            rows.append(dict(experiment=name, observer=obs, metric=f"h{h}_tf", unit="%", paper=None, ours=pred))
    return rows


def _half_load_measure(exp: LesoExperiment, sol: Run, t: np.ndarray, par: D.PMSMParams, kw: Mapping[str, Any]) -> Rows:
    """The C-LESO closing the loop at half load, 600 r/min: whether it holds, its speed deviation and error."""
    name = exp.name
    m = t >= 0.6
    dev = float(np.max(np.abs(np.asarray(sol.outputs.speed_rpm)[m] - 600.0)))
    return [
        # "holds": finite, and the true speed within 5 % of 600 r/min after 0.6 s; 002: it does not
        dict(
            experiment=name, observer="C-LESO", metric="holds", unit="bool", paper=False, ours=bool(sol.ok) and dev < 30
        ),
        dict(experiment=name, observer="C-LESO", metric="speed_dev", unit="r/min", paper=None, ours=dev),
        dict(
            experiment=name,
            observer="C-LESO",
            metric="max_abs",
            unit="deg",
            paper=None,
            ours=float(np.abs(_err_deg(sol, 0)[m]).max()),
        ),
    ]


def _ramp_measure(exp: LesoExperiment, sol: Run, t: np.ndarray, par: D.PMSMParams, kw: Mapping[str, Any]) -> Rows:
    """The speed ramp's rows (:func:`_ramp_rows`) for the closing LESO."""
    return _ramp_rows(exp.name, sol, t, par, kw["inverter"], exp.primary)


def _ramp_330_measure(exp: LesoExperiment, sol: Run, t: np.ndarray, par: D.PMSMParams, kw: Mapping[str, Any]) -> Rows:
    """The ramp on 330 V: the ramp's rows and the speed loop's least damped mode at 840 r/min, i_d = −6.4 A, at
    :data:`SENSORLESS_FW_SPEED_HZ` and at the bench's 5 Hz."""
    name = exp.name
    rows = _ramp_rows(name, sol, t, par, kw["inverter"], 2)
    rows += _speed_mode_rows(name, par, 840, -6.4, SENSORLESS_FW_SPEED_HZ)
    rows += _speed_mode_rows(name + " (at the bench's 5 Hz)", par, 840, -6.4)
    return rows


def _load_step_measure(exp: LesoExperiment, sol: Run, t: np.ndarray, par: D.PMSMParams, kw: Mapping[str, Any]) -> Rows:
    """The load step (Fig. 17): the closing LESO's peak errors after 0.55 s (3.2° is the FA-LESO's, 5 r/min all
    three's); for the FA-LESO also its BEMF angle's error and the speed loop's least damped mode."""
    name, i = exp.name, exp.primary
    m = t >= 0.55
    rows: Rows = _closing_rows(name, sol, i, par, m, 3.2 if i == 2 else None, 5.0)
    if i == 2:
        # the FA-LESO's own part: the error of its BEMF's angle, before the PLL (docs/papers.md)
        o = sol.outputs
        emf = np.degrees(np.asarray(wrap(o.obs.each[2].theta_emf - o.theta_e)))
        rows.append(
            dict(
                experiment=name,
                observer="FA-LESO",
                metric="max_abs_emf",
                unit="deg",
                paper=None,
                ours=float(np.abs(emf[m]).max()),
            )
        )
        rows += _speed_mode_rows(name, par, 600, 0.0)
    return rows


def _mismatch_measure(exp: LesoExperiment, sol: Run, t: np.ndarray, par: D.PMSMParams, kw: Mapping[str, Any]) -> Rows:
    """Rs or Lq mismatch at 300 r/min, rated load (Fig. 18): the FA-LESO's mean error after 1 s beside eqs
    (42)-(43) (``exp.est``: the parameter, its assumed factor and Δ = true − nominal as a share of it)."""
    name = exp.name
    assert exp.est is not None
    which, _, share = exp.est
    delta = share * float(getattr(par, which))
    we = par.p * 300 * D.RPM
    m = t >= 1.0
    err = float(np.mean(_err_deg(sol, 2)[m]))
    # eqs (42)-(43): Δ = true − nominal; E_ex at i_d = 0 is ωe ψf (+ (Ld − Lq) i_d = 0)
    e_ex = we * float(par.psi_f)
    id_hat = float(np.mean(np.asarray(sol.outputs.i_d)[m]))
    iq_hat = float(np.mean(np.asarray(sol.outputs.i_q)[m]))
    if which == "Rs":
        pred = math.degrees(float(linear.position_error_rs(delta, id_hat, iq_hat, e_ex)))
    else:
        pred = math.degrees(float(linear.position_error_lq(delta, id_hat, iq_hat, e_ex, we)))
    return [
        dict(experiment=name, observer="FA-LESO", metric="mean_error", unit="deg", paper=None, ours=err),
        dict(experiment=name, observer="FA-LESO", metric="eq42_43", unit="deg", paper=None, ours=pred),
    ]


class LesoExperiment(NamedTuple):
    """One of 002's experiments: its scenario on the bench, what is measured and the paper's values.

    :func:`run_leso_experiment` runs any one; :data:`LESO_EXPERIMENTS` is the table of them.
    """

    name: str  # the rows' experiment
    figure: str  # where 002 shows it
    rpm0: int  # r/min, the start
    t1: float  # s, the horizon
    speed_ref: Callable[[], D.Profile]  # the speed reference, rad/s
    measure: Measure  # (experiment, run, t, true machine, drive options) -> its rows
    paper: Any = None  # the paper's values, as ``measure`` reads them
    harmonics: bool = False  # the true machine carries the ASSUMED 5th and 7th (A5, A7)
    est: tuple[str, float, float] | None = None  # (parameter, assumed factor, (true − assumed)/true); None: exact
    load: Callable[[D.PMSMParams], D.Profile] | None = None  # N·m, of the true machine (None: no load)
    primary: int = 2  # the LESO closing the loop (an index into LESO_NAMES)
    drift: str | None = None  # the assumed parameter Fig. 18 ramps (FIG18_TIMES, FIG18_FACTORS)
    drive: Callable[[], dict[str, Any]] = dict  # the bench drive's options (inverter, field weakening, α_s)


def _constant(rpm: int) -> Callable[[], D.Profile]:
    return lambda: D.Profile.constant(rpm * D.RPM)


def _rated(frac: float | None = None) -> Callable[[D.PMSMParams], D.Profile]:
    """A constant load: the rated torque, or ``frac`` of it."""
    if frac is None:
        return lambda par: D.Profile.constant(float(par.T_rated))
    return lambda par: D.Profile.constant(float(par.T_rated) * frac)


def _closing(name: str, i: int) -> str:
    """Each LESO in turn closes the loop in the ramp and the load step (002 Figs 16-17 (a)-(c))."""
    return name if i == 2 else f"{name}, {LESO_NAMES[i]} closing the loop"


def _ramp() -> D.Profile:
    return D.Scenario.speed_rpm([0.0, 0.6, 1.4, 2.2, 3.0], [300, 600, 840, 600, 300], ramp=0.4)


_RAMP_NAME, _STEP_NAME = "speed ramp 300-600-840-600-300 r/min", "load step 0-80 % at 600 r/min"
_HALF_LOAD = "half load 600 r/min, C-LESO closing the loop"
_PAPER_MEAN = {300: (14.0, 7.0, 0.0), 600: (23.0, 10.0, 0.0), 840: (34.0, 12.0, 0.0)}
_PAPER_H = {300: ((5.4, 5.9), (3.6, 4.0), (0.8, 0.7)), 600: ((4.1, 4.5), (2.7, 2.9), (0.6, 0.7))}

LESO_EXPERIMENTS: tuple[LesoExperiment, ...] = (
    # --- steady state, no load (Figs. 10-12)
    *(
        LesoExperiment(f"steady {rpm} r/min no load", "Figs. 10-12", rpm, 0.8, _constant(rpm), _steady_measure,
                       _PAPER_MEAN[rpm])
        for rpm in (300, 600, 840)
    ),
    # --- BEMF harmonics (Figs. 13-14)
    *(
        LesoExperiment(f"harmonics {rpm} r/min {int(frac * 100)} % load", "Figs. 13-14", rpm, 1.0, _constant(rpm),
                       _harmonics_measure, _PAPER_H[rpm], harmonics=True, load=_rated(frac))
        for rpm, frac in ((300, 0.5), (600, 0.4))
    ),
    # --- the C-LESO closing the loop at half load, 600 r/min: 002 says it cannot complete this test (Sec. V-B)
    LesoExperiment(_HALF_LOAD, "Sec. V-B", 600, 1.0, _constant(600), _half_load_measure, harmonics=True,
                   load=lambda par: D.Profile.constant(0.5 * float(par.T_rated)), primary=0),
    # --- speed ramp 300-600-840-600-300 r/min, no load (Fig. 16), field weakening on (module doc)
    *(
        LesoExperiment(_closing(_RAMP_NAME, i), "Fig. 16", 300, 3.6, _ramp, _ramp_measure, primary=i,
                       drive=lambda: dict(inverter=D.Inverter(), field_weakening=D.VoltageFeedbackFW()))
        for i in (2, 0, 1)
    ),
    # --- the same ramp on a 330 V link, where the field weakening acts at 840 r/min (i_d ≈ −6.4 A), the
    # FA-LESO closing the loop.  With the bench's 5 Hz speed loop the drive leaves 840 r/min (a lagging
    # estimate turns the negative i_d into accelerating torque: the speed loop's 9.4 Hz pair has Re s > 0,
    # rows speed_mode_*); the speed loop at 2.5 Hz (SENSORLESS_FW_SPEED_HZ) is damped there and holds.
    LesoExperiment(
        f"{_RAMP_NAME}, 330 V dc link, speed loop 2.5 Hz", "Fig. 16 (docs/papers.md)", 300, 3.6, _ramp,
        _ramp_330_measure,
        drive=lambda: dict(inverter=D.Inverter(udc=330.0), field_weakening=D.VoltageFeedbackFW(),
                           alpha_s=2 * math.pi * SENSORLESS_FW_SPEED_HZ),
    ),
    # --- load step 0 -> 80 % -> 0 at 600 r/min (Fig. 17)
    *(
        LesoExperiment(
            _closing(_STEP_NAME, i), "Fig. 17", 600, 1.2, _constant(600), _load_step_measure, primary=i,
            load=lambda par: D.Scenario.load_steps([0.0, 0.6, 0.9], [0.0, 0.8 * float(par.T_rated), 0.0]),
        )
        for i in (2, 0, 1)
    ),
    # --- Rs and Lq mismatch at 300 r/min, rated load (Fig. 18), against eqs (42)-(43)
    *(
        LesoExperiment(f"{label}, rated load, 300 r/min", "Fig. 18", 300, 1.2, _constant(300), _mismatch_measure,
                       est=est, load=_rated())
        for label, est in (
            ("Rs_est = 1.5 Rs", ("Rs", 1.5, -0.5)),
            ("Rs_est = 0.5 Rs", ("Rs", 0.5, 0.5)),
            ("Lq_est = 1.5 Lq", ("Lq", 1.5, -0.5)),
            ("Lq_est = 0.5 Lq", ("Lq", 0.5, 0.5)),
        )
    ),
    # --- Fig. 18's ramps of R̂s and L̂q during one run
    *(
        LesoExperiment(name, "Fig. 18", 300, FIG18_T1, _constant(300), _fig18_measure, load=_rated(), drift=which)
        for which, name in FIG18_NAMES.items()
    ),
)  # fmt: skip
# the progress bar's total (tests/test_progress.py checks a run makes exactly these many steps)
N_EXPERIMENTS = len(LESO_EXPERIMENTS)


def run_leso_experiment(exp: LesoExperiment) -> tuple[Rows, Run]:
    """Run one of 002's experiments and measure it.

    Args:
        exp: the experiment (a record of :data:`LESO_EXPERIMENTS`).

    Returns:
        (rows, run): its rows {experiment, observer, metric, unit, paper, ours}, not yet annotated, and its run.
    """
    par = D.bench_machine("ipmsm002", a5=A5, a7=A7) if exp.harmonics else D.bench_machine("ipmsm002")
    est = par
    if exp.est is not None:
        which, factor, _ = exp.est
        est = D.bench_machine("ipmsm002", **{which: factor * float(getattr(par, which))})
    drift = None if exp.drift is None else D.ParameterDrift.ramps(exp.drift, FIG18_TIMES, FIG18_FACTORS)
    we = par.p * exp.rpm0 * D.RPM
    sc = D.Scenario(
        par,
        est_par=est,
        speed_ref=exp.speed_ref(),
        load=None if exp.load is None else exp.load(par),
        omega_m0=exp.rpm0 * D.RPM,
        est_drift=drift,
    )
    kw = exp.drive()
    drive = D.bench_drive(par, handover=0.3, **kw)
    sol = run_kept(D.ClosedLoop(drive, leso_bank(est, we, primary=exp.primary), sc), exp.t1)
    return exp.measure(exp, sol, np.asarray(sol.t), par, kw), sol


def run_leso_experiments(
    progress: ProgressArg = None,
) -> tuple[Rows, dict[str, Run]]:
    """Run 002's experiments (:data:`LESO_EXPERIMENTS`, in order).

    Args:
        progress: one step per experiment, each named as it compiles and runs (:mod:`jaxobs.runtime.progress`).

    Returns:
        (rows, traces): rows {experiment, observer, metric, unit, paper, ours, tolerance, within, explanation}
        (:mod:`jaxobs.reproduce.compare`, :data:`EXPLANATIONS`), and each experiment's run by name.
    """
    rows, traces = [], {}
    bar = Progress(progress, N_EXPERIMENTS, "reproduce leso", unit="experiment")
    for exp in LESO_EXPERIMENTS:
        bar.stage(f"{exp.name} ({exp.t1:g} s)")
        exp_rows, traces[exp.name] = run_leso_experiment(exp)
        bar.update()
        rows += exp_rows
    for name, sol in traces.items():
        rows.append(
            dict(experiment=name, observer="drive", metric="finite", unit="bool", paper=None, ours=bool(sol.ok))
        )
    bar.close()
    return annotate(rows, EXPLANATIONS), traces


# Why our number differs from 002's, for the rows outside their tolerance (jaxobs.reproduce.compare): the measured
# cause and where the measurement is (docs/papers.md, "Paper 002"), and what is left unexplained.
_LOAD_STEP = "load step 0-80 % at 600 r/min"
GI_HARMONICS = (
    "the GI-LESO's resonant term acts within ωc = π of ω̂e only, so at −5ω̂e and +7ω̂e it passes what the "
    "C-LESO does (rows 'h5_tf', 'h7_tf': linear.gileso_tf, which the simulation follows within 6 %); 002's GI/C "
    "ratio (0.67) needs other gains than Table II prints (a lower ω0): unexplained which 002 ran"
)
FA_HARMONICS = (
    "Table II's k2 = 100π passes 32 % of a −5ω̂e component (rows 'h5_tf', 'h7_tf': linear.faleso_tf, which the "
    "simulation follows within 6 %); 002's FA/C ratio (0.12-0.15) needs k2 ≈ 25-35π: unexplained why 002's "
    "observer attenuates more than its printed gains do"
)
LOAD_STEP = (
    "the PLL's acceleration error under the assumed mechanical step (24 N·m at once on 0.05 kg·m²), rung by the "
    "speed loop's 10 Hz pair through the 15 Hz PLL (ζ 0.067); measured (docs/papers.md, 'Load step'): the "
    "FA-LESO's own BEMF angle errs 5.9°, 6x J gives 3.8° / 13 r/min, a 0.3 s load ramp 1.8° / 5.9 r/min. "
    "Unexplained: 002's 1.6 r/min per degree (5 / 3.2), half what every variant of ours gives (3.3-3.4) and "
    "002's own ramp (2.9)"
)
LOAD_STEP_OTHERS = (
    "the closing LESO's steady lag at 600 r/min (C-LESO 22.6°, GI-LESO 7.7°) carries the same PLL acceleration "
    "error and 10 Hz speed-loop ringing as the FA-LESO's step (its row); unexplained, as there, how 002's drive "
    "keeps the speed-estimate error at 5 r/min"
)
EXPLANATIONS = {
    ("steady 300 r/min no load", "GI-LESO", "mean_lag"): (
        "our GI-LESO's lag is its transfer function's phase at ω̂e with Table II's gains (row 'tf_lag', 3.83°: "
        "ωc = π keeps the GI's peak finite, so eq (37)'s |G| ≈ 1 does not hold); 002's C- and GI-LESO lags sit "
        "1-3° above their transfer functions, this one 3.2°: what adds it on 002's drive is not measured here"
    ),
    **{
        (f"harmonics {r} r/min {f} % load", "GI-LESO", h): GI_HARMONICS
        for r, f in ((300, 50), (600, 40))
        for h in ("h5", "h7")
    },
    **{
        (f"harmonics {r} r/min {f} % load", "FA-LESO", h): FA_HARMONICS
        for r, f in ((300, 50), (600, 40))
        for h in ("h5", "h7")
    },
    ("half load 600 r/min, C-LESO closing the loop", "C-LESO", "holds"): (
        "002's C-LESO cannot complete half load at 600 r/min; ours holds within 0.36 r/min.  Measured, neither "
        "q-axis saturation (20-40 % at rated current) nor the dual machine's individual sets make it fail, and a "
        "faster speed loop fails worst at no load (tests/test_leso_speed_loop.py): 002's cause is unexplained"
    ),
    (_LOAD_STEP, "FA-LESO", "max_abs"): LOAD_STEP,
    (_LOAD_STEP, "FA-LESO", "max_speed_err"): LOAD_STEP,
    (f"{_LOAD_STEP}, C-LESO closing the loop", "C-LESO", "max_speed_err"): LOAD_STEP_OTHERS,
    (f"{_LOAD_STEP}, GI-LESO closing the loop", "GI-LESO", "max_speed_err"): LOAD_STEP_OTHERS,
}
