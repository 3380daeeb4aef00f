"""float32 vs float64: the main metrics and gradients of a SOGI-FLL-WIF run at 2, 20 and 100 s horizons.

    python -m benchmarks.precision              # the table (README, "float32 vs float64"); a few minutes on 2 cores
    python -m benchmarks.precision --horizons 2 20

Each precision runs in its own process (``jax_enable_x64`` is set once, before the first
computation).  Two scenarios, the WIF with its paper gains: "distorted" is one of the default job's
(presets/wif_robust.toml), 50 Hz with Test C's harmonics and a 0.05 p.u. dc offset, and at
t_e = H − 0.5 s a +2 Hz step with a +40° phase jump; "clean" is the same step and jump on a pure
sinusoid, where the float64 steady errors are nearly zero and float32 shows its own floor.

The run is split in two: up to H − 0.6 s with
``SaveFinal`` (no trajectory), then the last 0.6 s saved, from the first part's final state
(``OnSignal(..., t0=H − 0.6)``), so a 100 s horizon holds 6000 samples, not a million.

Metrics (``jaxobs.metrics``) on the saved window:

- settling time of f̂ into ±0.1 Hz of 52 Hz after t_e (exact ``settling_time``);
- steady ripple: peak-to-peak of the frequency error over the last 0.2 s;
- rms phase error wrap(θ̂ − θ) over the last 0.2 s;
- ITAE of the frequency error (Hz) after t_e;
- the gradient with respect to k1, k2, λ of the default job's per-scenario cost
  (its terms, ``itae_freq`` + 0.01·``ripple_freq``, with t_event = t_e and the steady window
  the last 0.2 s), through both parts of the run.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys

WINDOW = 0.6  # saved window at the end of the horizon, s
EVENT_BEFORE_END = 0.5  # t_e = H − 0.5 s
STEADY = 0.2  # steady window: the last 0.2 s
SCENARIOS = ("distorted", "clean")
BAND_HZ = 0.1  # 5 % of the 2 Hz step (the steady ripple is ±0.055 Hz)


def _worker(horizons, x64: bool) -> dict:
    import jax

    jax.config.update("jax_enable_x64", x64)
    import warnings

    import jax.numpy as jnp

    import jaxobs
    from jaxobs import metrics as M
    from jaxobs import papers

    warnings.simplefilter("ignore")
    out = {}
    for scen, H in [(s, H) for s in SCENARIOS for H in horizons]:
        te = H - EVENT_BEFORE_END
        distorted = scen == "distorted"
        harm = {h: 1.0 * m for h, m in papers.TEST_C_HARMONICS.items()} if distorted else None
        sig = jaxobs.GridSignal(
            freq=50.0,
            t_event=te,
            freq_step=2.0,
            phase_jump=math.radians(40.0),
            dc=0.05 if distorted else 0.0,
            harmonics=harm,
        )
        obs0 = jaxobs.SOGIFLLWIF(papers.WIF_K1, papers.WIF_K2, papers.WIF_LAM)
        t_w = H - WINDOW

        def run(gains, sig=sig, obs0=obs0, t_w=t_w, H=H):
            k1, k2, lam = gains
            obs = eqx_set(obs0, k1, k2, lam)
            pre = jaxobs.simulate(jaxobs.OnSignal(obs, sig), t_w, save=jaxobs.SaveFinal())
            return jaxobs.simulate(jaxobs.OnSignal(obs, sig, t0=t_w), H, state0=pre.final_state)

        def cost(gains, te=te, H=H):
            sol = run(gains)
            f_err = (sol.outputs.obs.omega - sol.outputs.truth.omega) / (2 * math.pi)
            steady = sol.t >= H - STEADY
            return M.itae(sol.t, f_err, te) + 0.01 * M.smooth_peak_to_peak(f_err, steady, 1e-3)

        g0 = jnp.asarray([papers.WIF_K1, papers.WIF_K2, papers.WIF_LAM])
        sol = jax.jit(run)(g0)
        t = sol.t
        f_hat = sol.outputs.obs.omega / (2 * math.pi)
        f_err = (sol.outputs.obs.omega - sol.outputs.truth.omega) / (2 * math.pi)
        steady = t >= H - STEADY
        perr = M.wrap(sol.outputs.obs.theta - sol.outputs.truth.theta)
        grad = jax.jit(jax.grad(cost))(g0)
        out[f"{scen} {H:g}"] = {
            "settling time (s)": float(M.settling_time(t, f_hat, 52.0, BAND_HZ, te)),
            "steady ripple (Hz p-p)": float(M.peak_to_peak(f_err, steady)),
            "rms phase error (rad)": float(M.rms(perr, steady)),
            "ITAE freq (Hz·s²)": float(M.itae(t, f_err, te)),
            "∂cost/∂k1": float(grad[0]),
            "∂cost/∂k2": float(grad[1]),
            "∂cost/∂λ": float(grad[2]),
        }
    return out


def eqx_set(obs, k1, k2, lam):
    import equinox as eqx

    return eqx.tree_at(lambda o: (o.k1, o.k2, o.lam), obs, (k1, k2, lam))


def table(horizons) -> str:
    res = {}
    for name in ("f64", "f32"):
        args = [sys.executable, "-m", "benchmarks.precision", "--worker", name, "--horizons", *map(str, horizons)]
        res[name] = json.loads(subprocess.run(args, check=True, capture_output=True, text=True).stdout)
    keys = list(next(iter(res["f64"].values())))
    lines = [
        "| scenario | metric | H (s) | float64 | float32 | float32/float64 − 1 |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for scen in SCENARIOS:
        for k in keys:
            for H in horizons:
                a, b = res["f64"][f"{scen} {H:g}"][k], res["f32"][f"{scen} {H:g}"][k]
                rel = f"{b / a - 1:+.1%}" if a != 0 else "—"
                lines.append(f"| {scen} | {k} | {H:g} | {a:.4g} | {b:.4g} | {rel} |")
    return "\n".join(lines)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--horizons", type=float, nargs="+", default=[2.0, 20.0, 100.0])
    p.add_argument("--worker", choices=("f32", "f64"), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        print(json.dumps(_worker(a.horizons, a.worker == "f64")))
    else:
        print(table(a.horizons))


if __name__ == "__main__":
    main()
