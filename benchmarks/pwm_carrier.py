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
   vmapped, averaged vs carrier (the drive's n_sub = 2 RK4 steps per sub-interval, and 1) in the same run:
   scenario-steps per second (the best of three after compiling); and the plant alone under a rotating command.

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


def cost(batch):
    """Scenario-steps per second of the file's sensored loop, averaged vs carrier (the best of three)."""
    import equinox as eqx
    import jax
    import numpy as np

    import jaxobs
    from jaxobs import drive as D
    from jaxobs.drive import read_drive

    d = read_drive(FILE)
    avg = d.drive_for(sensorless=False)
    inv = avg.inverter
    car = eqx.tree_at(lambda x: x.inverter, avg, D.Inverter(inv.udc, inv.f_pwm, pwm="carrier"))
    car1 = D.Drive(avg.foc, car.inverter, n_sub=1, rule=avg.rule, latency=avg.latency)  # one RK4 per sub-interval
    side = max(int(round(math.sqrt(batch))), 1)
    sc = D.grid(D.Scenario(d.machine), speed_rpm=list(np.linspace(300, 1500, side)),
                load_nm=list(np.linspace(0, 14, max(batch // side, 1)))).scenarios  # fmt: skip
    n = int(round(0.1 / d.ts))
    out = {}
    for name, drv in (("averaged", avg), ("carrier", car), ("carrier_1", car1)):
        run = jax.jit(jax.vmap(lambda s, drv=drv: jaxobs.simulate(D.ClosedLoop(drv, None, s), 0.1).outputs.omega_m))
        jax.block_until_ready(run(sc))
        best = math.inf
        for _ in range(3):
            t0 = time.perf_counter()
            jax.block_until_ready(run(sc))
            best = min(best, time.perf_counter() - t0)
        out[name] = sc.omega_m0.shape[0] * n / best
    return out, sc.omega_m0.shape[0], n


def plant_cost(batch):
    """Scenario-steps per second of the plant alone (the lab machine under a rotating command, 1 µs dead time)."""
    import jax
    import jax.numpy as jnp

    from jaxobs import drive as D
    from jaxobs.drive import read_drive
    from jaxobs.drive.plant import PlantState

    d = read_drive(FILE)
    inv, n = d.drive.inverter, int(round(0.1 / d.ts))
    x0 = jnp.asarray([0.0, 1.0, 100.0, 0.0]) + jnp.linspace(0.0, 1.0, batch)[:, None]
    out = {}
    for name, pwm, n_sub in (("averaged", "averaged", 2), ("carrier", "carrier", 2), ("carrier_1", "carrier", 1)):
        plant = D.PMSM(d.machine, D.Inverter(inv.udc, inv.f_pwm, pwm=pwm), 1e-6, ts=d.ts, n_sub=n_sub)

        def run(x, plant=plant):
            def step(s, k):
                th = 0.04 * k
                s, o = plant.step(s, D.PlantInput(150 * jnp.cos(th), 150 * jnp.sin(th), 0.0))
                return s, o.i_a

            return jax.lax.scan(step, PlantState(x, None), jnp.arange(n))[1]

        f = jax.jit(jax.vmap(run))
        jax.block_until_ready(f(x0))
        best = math.inf
        for _ in range(3):
            t0 = time.perf_counter()
            jax.block_until_ready(f(x0))
            best = min(best, time.perf_counter() - t0)
        out[name] = batch * n / best
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--motulator-python", default=os.environ.get("MOTULATOR_PYTHON"))
    ap.add_argument("--batch", type=int, default=16)
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
    rates, b, n = cost(a.batch)
    r_a, r_c, r_1 = rates["averaged"], rates["carrier"], rates["carrier_1"]
    print(f"cost: sensored closed loop, batch {b}, {n} steps, jit+vmap, scenario-steps/s: averaged (n_sub 2) "
          f"{r_a:.3g}; carrier, n_sub 2 per sub-interval {r_c:.3g} ({r_c / r_a:.3f} of averaged), n_sub 1 "
          f"{r_1:.3g} ({r_1 / r_a:.3f})")  # fmt: skip
    p = plant_cost(b)
    p_a, p_c, p_1 = p["averaged"], p["carrier"], p["carrier_1"]
    print(f"cost: the plant alone, batch {b}, {n} steps: averaged (n_sub 2) {p_a:.3g}; carrier, n_sub 2 {p_c:.3g} "
          f"({p_c / p_a:.3f}), n_sub 1 {p_1:.3g} ({p_1 / p_a:.3f})")  # fmt: skip
    print(subprocess.run(["uptime"], capture_output=True, text=True).stdout.rstrip())
    return 0


if __name__ == "__main__":
    sys.exit(main())
