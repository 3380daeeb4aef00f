"""Carrier PWM against the averaged inverter, and against motulator 0.18's carrier comparison: cost and ripple.

``python -m benchmarks.pwm_carrier [--motulator-python PY] [--batch N]`` prints:

1. **Ripple, open loop** on the 2.2-kW lab IPMSM (docs/examples/ipmsm_2p2kw_lab.toml: 540 V, 8 kHz, carrier at
   8 kHz, single update), 1000 r/min imposed (the inertia set to 1e6 kg·m², so the speed stays), rated load
   (14 N·m at the MTPA currents), the steady rotor-frame voltage rotated to the middle of each period, dead time 0
   and 2 µs.  The ripple is the stator current less its fundamental (both tools' currents at their switching
   instants, linear between them: the rms of |i_αβ − i_1| over three electrical periods, 40–100 ms), with phase a's
   peak to peak and the rms at the sample instants (the carrier's peak, where the ripple crosses its mean).
   motulator runs the same case (:mod:`benchmarks.peer_motulator_pwm`) where ``$MOTULATOR_PYTHON`` is given.
2. **Cost**: the file's sensored closed loop (encoder), a batch of scenarios (speed × load) over 0.1 s, jitted and
   vmapped, averaged vs carrier (the drive's n_sub = 2 RK4 steps per sub-interval, and 1), and the carrier plant
   as it was before 2026-12-03 (``jaxobs.drive.pwm._switched``, no division by one) in the same run: scenario-steps
   per second, wall and CPU, the medians of ``--rounds`` rounds that call each variant in turn, and each compiled
   program's count of ``minimum`` ops (constant in n_sub when the period's edges are computed once); then the
   plant alone under a rotating command, each scenario its own.  ``--cost-only`` prints only these.

``--figure PNG`` only draws phase a's current of the open-loop case (2 µs dead time) under carrier PWM, at every
switching instant, beside the averaged inverter's samples (docs/img/pwm_current_lab.png).

The output is meant for benchmarks/results/ with the date and ``uptime`` (the machine's load moves the cost).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).parents[1]
FILE = ROOT / "docs" / "examples" / "ipmsm_2p2kw_lab.toml"
RPM, TORQUE = 1000.0, 14.0
T_END, T_FROM = 0.1, 0.04  # s: the run and the window scored (three electrical periods at 50 Hz)


def ripple(t, i_a, i_b, w_e, t_samples=None):
    """The current's ripple about its fundamental (piecewise linear between the points).

    Args:
        t: The times, s (sorted, spanning whole electrical periods).
        i_a: i_α at those times, A.
        i_b: i_β, A.
        w_e: The electrical frequency, rad/s.
        t_samples: The sample instants (a subset of ``t``) for the rms at them, or None.

    Returns:
        ``(rms, p2p_a, rms_at_samples)``, A.
    """
    import numpy as np

    t, i = np.asarray(t), np.asarray(i_a) + 1j * np.asarray(i_b)
    span = t[-1] - t[0]
    h = np.diff(t)
    z = i * np.exp(-1j * w_e * t)
    i1 = np.sum(0.5 * h * (z[1:] + z[:-1])) / span
    r = i - i1 * np.exp(1j * w_e * t)
    a, b = r[:-1], r[1:]
    rms = math.sqrt(np.sum(h / 3 * (abs(a) ** 2 + (a * b.conj()).real + abs(b) ** 2)) / span)
    p2p = float(np.ptp(r.real))
    at = None
    if t_samples is not None:
        k = np.searchsorted(t, t_samples)
        at = float(np.sqrt(np.mean(abs(r[k]) ** 2)))
    return rms, p2p, at


def _case():
    from jaxobs.drive import read_drive

    d = read_drive(FILE)
    m, f_s = d.machine, 1.0 / d.ts
    p, Rs, Ld, Lq, psi_f = int(m.p), float(m.Rs), float(m.Ld), float(m.Lq), float(m.psi_f)
    dl, a = Lq - Ld, psi_f / (2 * (Lq - Ld))

    def torque(iq):
        i_d = a - math.sqrt(a * a + iq * iq)  # MTPA
        return 1.5 * p * (psi_f - dl * i_d) * iq, i_d

    lo, hi = 0.0, 100.0
    for _ in range(200):  # bisection for the MTPA i_q that gives the rated torque
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if torque(mid)[0] < TORQUE else (lo, mid)
    i_q = 0.5 * (lo + hi)
    i_d = torque(i_q)[1]
    w_m = RPM * 2 * math.pi / 60
    w_e = p * w_m
    u_d, u_q = Rs * i_d - w_e * Lq * i_q, Rs * i_q + w_e * (Ld * i_d + psi_f)
    return dict(n_p=p, R_s=Rs, L_d=Ld, L_q=Lq, psi_f=psi_f, u_dc=float(d.drive.inverter.udc), T_s=1.0 / f_s,
                i_dq=[i_d, i_q], u_dq=[u_d, u_q], w_M=w_m, theta0=0.0, t_end=T_END, t_from=T_FROM)  # fmt: skip


def jaxobs_waveform(case, t_d, pwm="carrier"):
    """The open-loop case on jaxobs's plant: the stator current at each switching instant (carrier) or at each
    sample (averaged) from ``t_from`` on, and the sample instants.

    Returns:
        ``(t, i, t_samples)``: times, s; the complex α-β current, A; the sample instants, s.
    """
    import jax
    import jax.numpy as jnp
    import numpy as np

    from jaxobs import drive as D
    from jaxobs.drive.plant import PlantState

    c = case
    par = D.PMSMParams(c["R_s"], c["L_d"], c["L_q"], c["psi_f"], 1e6, c["n_p"])
    ts = c["T_s"]
    plant = D.PMSM(par, D.Inverter(c["u_dc"], 1.0 / ts, pwm=pwm), t_d, ts=ts, n_sub=1)
    n = int(round(c["t_end"] / ts))
    w_e = c["n_p"] * c["w_M"]
    th = c["theta0"] + w_e * ts * (np.arange(n) + 0.5)
    u = (c["u_dq"][0] + 1j * c["u_dq"][1]) * np.exp(1j * th)
    x0 = jnp.asarray([c["i_dq"][0], c["i_dq"][1], c["w_M"], c["theta0"]])
    t_samples = ts * np.arange(int(math.ceil(c["t_from"] / ts - 1e-9)), n)
    inp = D.PlantInput(jnp.asarray(u.real), jnp.asarray(u.imag), jnp.zeros(n))
    if pwm != "carrier":
        xs = np.asarray(jax.jit(lambda s, i: jax.lax.scan(lambda a, b: (plant.step(a, b)[0], a.x), s, i)[1])(
            PlantState(x0, None), inp))  # fmt: skip
        t = ts * np.arange(n)
        keep = t >= c["t_from"] - 1e-12
        x = xs[keep]
        return t[keep], (x[:, 0] + 1j * x[:, 1]) * np.exp(1j * x[:, 3]), t_samples

    def step(state, inp):
        tt, xs, rs = plant.carrier_substeps(state, inp)
        x = xs[-1]
        return PlantState(x.at[3].set(jnp.arctan2(jnp.sin(x[3]), jnp.cos(x[3]))), rs), (tt, xs)

    _, (tt, xs) = jax.jit(lambda s, i: jax.lax.scan(step, s, i))(PlantState(x0, None), inp)
    tt, xs = np.asarray(tt), np.asarray(xs)
    t = (np.arange(n)[:, None] * ts + tt[:, :-1]).ravel()  # each period's 7 starts (its end is the next start)
    x = xs[:, :-1].reshape(-1, 4)
    keep = t >= c["t_from"] - 1e-12
    t, x = t[keep], x[keep]
    t, first = np.unique(np.round(t, 15), return_index=True)  # zero-length sub-intervals repeat an instant
    x = x[first]
    return t, (x[:, 0] + 1j * x[:, 1]) * np.exp(1j * x[:, 3]), t_samples


def jaxobs_ripple(case, t_d):
    """The open-loop case on jaxobs's carrier plant: the ripple (:func:`ripple`)."""
    import numpy as np

    t, i, t_samples = jaxobs_waveform(case, t_d)
    w_e = case["n_p"] * case["w_M"]
    return ripple(t, i.real, i.imag, w_e, t[np.isin(t, np.round(t_samples, 15))])


def figure(case, path, t_d=2e-6):
    """Phase a's current under carrier PWM (at every switching instant, so its ripple shows) beside the averaged
    inverter's samples: one electrical period, and four PWM periods of it enlarged; written to ``path``."""
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tc, ic, _ = jaxobs_waveform(case, t_d)
    ta, ia, _ = jaxobs_waveform(case, t_d, pwm="averaged")
    period = 2 * math.pi / (case["n_p"] * case["w_M"])
    t0 = case["t_from"]
    fig, (ax, az) = plt.subplots(1, 2, figsize=(10, 3.4), dpi=110, gridspec_kw={"width_ratios": [2, 1]})
    k = ta <= t0 + period
    t_peak = ta[k][np.argmax(ia[k].real)]  # phase a's positive peak
    for a in (ax, az):
        lo, hi = (t0, t0 + period) if a is ax else (t_peak - 2 * case["T_s"], t_peak + 2 * case["T_s"])
        kc, ka = (tc >= lo) & (tc <= hi), (ta >= lo) & (ta <= hi)
        a.plot((tc[kc] - t0) * 1e3, ic[kc].real, lw=0.8, label=f"carrier PWM, {t_d * 1e6:g} µs dead time")
        a.plot((ta[ka] - t0) * 1e3, ia[ka].real, "o", ms=2.5 if a is ax else 5, label="averaged inverter (samples)")
        a.set_xlabel("t (ms)")
        a.grid(alpha=0.3)
    ax.set_ylabel("phase a current (A)")
    ax.set_title(f"{FILE.name}: {RPM:g} r/min, {TORQUE:g} N·m, open loop", fontsize=9)
    az.set_title("four PWM periods at its positive peak", fontsize=9)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def motulator_ripple(case, t_d, python):
    import numpy as np

    arg = json.dumps({**case, "t_d": t_d})
    run = subprocess.run(
        [python, str(ROOT / "benchmarks" / "peer_motulator_pwm.py"), arg], capture_output=True, text=True
    )
    if run.returncode != 0:
        raise RuntimeError(f"motulator failed: {run.stderr.strip().splitlines()[-1:]}")
    out = json.loads(run.stdout)
    t = np.asarray(out["t"])
    w_e = case["n_p"] * case["w_M"]
    t_samples = case["T_s"] * np.arange(int(math.ceil(case["t_from"] / case["T_s"] - 1e-9)), 10**7)
    t_samples = t_samples[t_samples <= t[-1]]
    k = np.searchsorted(t, t_samples - 1e-12)
    near = np.abs(t[np.minimum(k, len(t) - 1)] - t_samples) < 1e-9
    return ripple(t, out["i_a"], out["i_b"], w_e, t[k[near]]), out.get("version", "?")


def _compiled(fn, args, undivided):
    """``fn`` jitted and compiled ahead of time for ``args``; with ``undivided``, the carrier plant's intervals as
    before 2026-12-03 (``jaxobs.drive.pwm._switched``: without the division by one that stops XLA's fusion copying
    them into every RK4 stage).  The tracing caches are cleared around it, so that no variant reuses another's
    trace; the compiled program keeps its own.  Returns the compiled function and its count of ``minimum`` ops (the
    sorting network's and the clips': a count that grows with n_sub is the copying)."""
    import jax

    from jaxobs.drive import plant as plant_module
    from jaxobs.drive import pwm

    jax.clear_caches()
    saved = plant_module.carrier_intervals
    if undivided:
        plant_module.carrier_intervals = pwm._switched
    try:
        compiled = jax.jit(fn).lower(*args).compile()
    finally:
        plant_module.carrier_intervals = saved
        jax.clear_caches()
    return compiled, (compiled.as_text() or "").count(" minimum(")


def _rates(variants, rounds):
    """Scenario-steps per second of each variant (name -> (compiled, args, scenario-steps)): after one warm-up
    call each, ``rounds`` rounds that call every variant once in turn (so the machine's load falls on all
    alike); the median of each one's wall times, and of its process CPU times."""
    import statistics

    import jax

    for f, args, _ in variants.values():
        jax.block_until_ready(f(*args))
    wall = {k: [] for k in variants}
    cpu = {k: [] for k in variants}
    for _ in range(rounds):
        for k, (f, args, _) in variants.items():
            c0, t0 = time.process_time(), time.perf_counter()
            jax.block_until_ready(f(*args))
            wall[k].append(time.perf_counter() - t0)
            cpu[k].append(time.process_time() - c0)
    return {k: (n / statistics.median(wall[k]), n / statistics.median(cpu[k])) for k, (_, _, n) in variants.items()}


LABELS = {  # (name, pwm, n_sub, undivided): the variants each cost row times
    "averaged": ("averaged", 2, False),
    "carrier": ("carrier", 2, False),
    "carrier_1": ("carrier", 1, False),
    "carrier_before": ("carrier", 2, True),
    "carrier_1_before": ("carrier", 1, True),
}


def cost(batch, rounds=5):
    """The file's sensored loop, averaged vs carrier (n_sub 2 and 1, each also as before 2026-12-03): per
    variant ``(wall rate, CPU rate, minimum ops)``, rates in scenario-steps per second (:func:`_rates`)."""
    import equinox as eqx
    import jax
    import numpy as np

    import jaxobs
    from jaxobs import drive as D
    from jaxobs.drive import read_drive

    d = read_drive(FILE)
    avg = d.drive_for(sensorless=False)
    inv = avg.inverter
    side = max(int(round(math.sqrt(batch))), 1)
    sc = D.grid(D.Scenario(d.machine), speed_rpm=list(np.linspace(300, 1500, side)),
                load_nm=list(np.linspace(0, 14, max(batch // side, 1)))).scenarios  # fmt: skip
    n = int(round(0.1 / d.ts))
    variants, mins = {}, {}
    for name, (pwm, n_sub, undivided) in LABELS.items():
        drv = avg  # the file's drive (n_sub 2)
        if pwm == "carrier":
            drv = eqx.tree_at(lambda x: x.inverter, avg, D.Inverter(inv.udc, inv.f_pwm, pwm="carrier"))
        if n_sub != drv.n_sub:  # one RK4 step per sub-interval
            drv = D.Drive(drv.foc, drv.inverter, n_sub=n_sub, rule=drv.rule, latency=drv.latency)
        fn = jax.vmap(lambda s, drv=drv: jaxobs.simulate(D.ClosedLoop(drv, None, s), 0.1).outputs.omega_m)
        f, mins[name] = _compiled(fn, (sc,), undivided)
        variants[name] = (f, (sc,), sc.omega_m0.shape[0] * n)
    rates = _rates(variants, rounds)
    return {k: (*rates[k], mins[k]) for k in variants}, sc.omega_m0.shape[0], n


def plant_cost(batch, rounds=5):
    """The plant alone (the lab machine, 1 µs dead time) under a rotating command, each scenario its own (its
    phase and amplitude), as in a closed loop: the variants of :func:`cost`.  (A command shared by the batch, as
    this benchmark had before 2026-12-03, left the copied modulation unbatched and cheap: the plant alone then
    looked 2-3 times cheaper than in the loop.)"""
    import jax
    import jax.numpy as jnp

    from jaxobs import drive as D
    from jaxobs.drive import read_drive
    from jaxobs.drive.plant import PlantState

    d = read_drive(FILE)
    inv, n = d.drive.inverter, int(round(0.1 / d.ts))
    lane = jnp.linspace(0.0, 1.0, batch)
    x0 = jnp.asarray([0.0, 1.0, 100.0, 0.0]) + lane[:, None]
    variants, mins = {}, {}
    for name, (pwm, n_sub, undivided) in LABELS.items():
        plant = D.PMSM(d.machine, D.Inverter(inv.udc, inv.f_pwm, pwm=pwm), 1e-6, ts=d.ts, n_sub=n_sub)

        def run(x, c, plant=plant):
            def step(s, k):
                th = 0.04 * k + c
                s, o = plant.step(s, D.PlantInput((150 + 20 * c) * jnp.cos(th), (150 + 20 * c) * jnp.sin(th), 0.0))
                return s, o.i_a

            return jax.lax.scan(step, PlantState(x, None), jnp.arange(n))[1]

        f, mins[name] = _compiled(jax.vmap(run), (x0, lane), undivided)
        variants[name] = (f, (x0, lane), batch * n)
    rates = _rates(variants, rounds)
    return {k: (*rates[k], mins[k]) for k in variants}


def _cost_lines(title, res):
    """The cost table's lines: each variant's rates (wall and CPU) and its ratio to the averaged one's."""
    a_wall, a_cpu, _ = res["averaged"]
    lines = [
        f"{title}",
        f"{'variant':>18} | {'wall steps/s':>12} {'ratio':>6} | {'CPU steps/s':>11} {'ratio':>6} | min ops",
    ]
    for k, (w, c, m) in res.items():
        lines.append(f"{k:>18} | {w:12.3g} {w / a_wall:6.3f} | {c:11.3g} {c / a_cpu:6.3f} | {m:7d}")
    return lines


def _print_costs(a) -> int:
    res, b, n = cost(a.batch, a.rounds)
    title = f"cost: sensored closed loop, batch {b}, {n} steps, jit+vmap, medians of {a.rounds} interleaved rounds"
    print("\n".join(_cost_lines(title, res)))
    print(subprocess.run(["uptime"], capture_output=True, text=True).stdout.rstrip())
    title = f"cost: the plant alone, a command per scenario, batch {b}, {n} steps"
    print("\n".join(_cost_lines(title, plant_cost(b, a.rounds))))
    print(subprocess.run(["uptime"], capture_output=True, text=True).stdout.rstrip())
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--motulator-python", default=os.environ.get("MOTULATOR_PYTHON"))
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--rounds", type=int, default=5, help="interleaved timing rounds (the medians are printed)")
    ap.add_argument("--cost-only", action="store_true", help="only the cost tables (no ripple, no motulator)")
    ap.add_argument("--figure", metavar="PNG", help="only draw phase a's current, carrier beside averaged, to PNG")
    a = ap.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)  # before any array: the machine's values in float64
    print(time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()))
    print(subprocess.run(["uptime"], capture_output=True, text=True).stdout.rstrip())
    case = _case()
    if a.figure:
        figure(case, a.figure)
        print(f"figure: {a.figure}")
        return 0
    i_d, i_q = case["i_dq"]
    if a.cost_only:
        return _print_costs(a)
    print(f"case: {FILE.name}, {RPM:g} r/min, {TORQUE:g} N·m (MTPA i_d {i_d:.4f} A, i_q {i_q:.4f} A), "
          f"u_dc {case['u_dc']:g} V, carrier {1 / case['T_s']:g} Hz single update")  # fmt: skip
    print(f"{'dead time':>10} | {'jaxobs rms':>10} {'p-p a':>7} {'at samples':>10} | "
          f"{'motulator rms':>13} {'p-p a':>7} {'at samples':>10} | rms ratio")  # fmt: skip
    version = None
    for t_d in (0.0, 2e-6):
        j = jaxobs_ripple(case, t_d)
        line = f"{t_d * 1e6:8.1f}µs | {j[0]:10.4f} {j[1]:7.4f} {j[2]:10.4f} |"
        if a.motulator_python:
            m, version = motulator_ripple(case, t_d, a.motulator_python)
            line += f" {m[0]:13.4f} {m[1]:7.4f} {m[2]:10.4f} | {j[0] / m[0]:.4f}"
        else:
            line += " motulator skipped (no --motulator-python or $MOTULATOR_PYTHON)"
        print(line)
    if version:
        print(f"motulator {version}")
    return _print_costs(a)


if __name__ == "__main__":
    sys.exit(main())
