"""The same saturated machine in motulator 0.18 and jaxobs under the same open-loop voltages: the currents agree
to 1e-6 relative.

``python -m benchmarks.peer_fluxmap --motulator-python PY [--out FILE]`` (or ``$MOTULATOR_PYTHON``).  The machine is
docs/examples/pmsyrm_5p6kw_sat.toml's: the 5.6-kW PM-SyRM of motulator's examples with its algebraic saturation map
(Hinkkanen et al. 2017 with Lelli et al. 2024's PM bridge; :mod:`jaxobs.drive.saturation`).  motulator's side
(:mod:`benchmarks.peer_fluxmap_motulator`) integrates its own ``SynchronousMachine`` with that map
(``SaturationModelPMSyRM``) by DOP853 at rtol = atol = 1e-12; jaxobs's side is the drive's plant
(:class:`jaxobs.drive.PMSM`, RK4, float64) with n_sub = 32 substeps per 125 µs period.  Both at a fixed speed of
1200 r/min (jaxobs: J = 1e9 kg·m², so the speed moves by less than 1e-12 relative), both from the no-load flux,
under the same held stationary-frame voltage per period: 0.15 s of the steady voltage of the rated current's MTPA
point on the map (ψ = ψ(i), u = Rs i + jωe ψ), then 0.1 s of 1.3 times it (deeper saturation).  The figure of
merit: max_k |i_jaxobs(t_k) − i_motulator(t_k)| / max_k |i_motulator(t_k)| over the 2000 samples.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DRIVE = ROOT / "docs" / "examples" / "pmsyrm_5p6kw_sat.toml"
RPM_RUN = 1200.0
N_SUB = 32
TOL = 1e-6


def _case():
    import jax

    jax.config.update("jax_enable_x64", True)
    from jaxobs.drive import read_drive
    from jaxobs.drive.saturation import map_mtpa

    f = read_drive(DRIVE)
    par = f.machine
    sat = par.sat
    ts = f.ts
    i_d, i_q, _ = map_mtpa(sat, par.p, math.sqrt(2) * float(f.table["machine"]["rated_current_a"]))
    psi_d, psi_q = (float(v) for v in sat.flux(i_d, i_q))
    w_e = par.p * RPM_RUN * 2 * math.pi / 60
    u_dq = float(par.Rs) * complex(i_d, i_q) + 1j * w_e * complex(psi_d, psi_q)
    n1, n2 = round(0.15 / ts), round(0.1 / ts)
    theta0 = 0.0
    t = np.arange(n1 + n2) * ts
    # the voltage held over period k: the steady voltage at the period's centre angle (an open-loop V/f drive)
    amp = np.where(np.arange(n1 + n2) < n1, 1.0, 1.3)
    u_ab = amp * u_dq * np.exp(1j * (theta0 + w_e * (t + 0.5 * ts)))
    c = {k: float(getattr(sat, k)) for k in ("a_d0", "a_dd", "a_q0", "a_qq", "a_dq", "psi_n", "a_b", "a_bp", "k_q")}
    c.update({k: getattr(sat, k) for k in ("S", "T", "U", "V", "W")})
    psi0 = (float(sat.no_load_flux()), 0.0)
    case = dict(coef=c, p=par.p, Rs=float(par.Rs), omega_m=RPM_RUN * 2 * math.pi / 60, ts=ts, u_a=u_ab.real.tolist(),
                u_b=u_ab.imag.tolist(), psi0=psi0, theta0=theta0)  # fmt: skip
    return f, case


def run_jaxobs(f, case):
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from jaxobs.drive import PMSM
    from jaxobs.drive.plant import PlantInput, PlantState

    par = eqx.tree_at(lambda m: m.J, f.machine, jnp.asarray(1e9))
    plant = PMSM(par, ts=case["ts"], n_sub=N_SUB)
    x0 = jnp.array([case["psi0"][0], case["psi0"][1], case["omega_m"], case["theta0"]])
    s0 = PlantState(x=x0, rule=plant.rule.init(plant.field, x0, None))
    u = (jnp.asarray(case["u_a"]), jnp.asarray(case["u_b"]), jnp.zeros(len(case["u_a"])))

    @jax.jit
    def sim(s0, u):
        def body(s, uk):
            return plant.step(s, PlantInput(*uk))

        return jax.lax.scan(body, s0, u)[1]

    out = sim(s0, u)
    return np.asarray(out.i_d), np.asarray(out.i_q)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--motulator-python", default=os.environ.get("MOTULATOR_PYTHON"))
    ap.add_argument("--out", default=None, help="write the report here too")
    a = ap.parse_args(argv)
    if not a.motulator_python:
        print("motulator: skipped (no --motulator-python or $MOTULATOR_PYTHON)")
        return 0
    f, case = _case()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "case.json"
        path.write_text(json.dumps(case))
        done = subprocess.run([a.motulator_python, str(ROOT / "benchmarks" / "peer_fluxmap_motulator.py"), str(path)],
                              capture_output=True, text=True)  # fmt: skip
    if done.returncode != 0:
        print(done.stderr[-2000:], file=sys.stderr)
        return 1
    mot = json.loads(done.stdout)
    i_m = np.asarray(mot["i_d"]) + 1j * np.asarray(mot["i_q"])
    jd, jq = run_jaxobs(f, case)
    i_j = jd + 1j * jq
    err = np.abs(i_j - i_m)
    rel = float(err.max() / np.abs(i_m).max())
    k = int(err.argmax())
    lines = [
        "peer_fluxmap: motulator 0.18 vs jaxobs, the saturated 5.6-kW PM-SyRM (docs/examples/pmsyrm_5p6kw_sat.toml)",
        f"open-loop held voltages at {RPM_RUN:g} r/min, {len(i_m)} samples of {case['ts'] * 1e6:g} µs; "
        f"jaxobs RK4 n_sub = {N_SUB}, motulator DOP853 rtol = atol = 1e-12",
        f"psi_f: motulator {mot['psi_f']:.12g} Vs, jaxobs {case['psi0'][0]:.12g} Vs",
        f"|i| range: {np.abs(i_m).min():.4g} .. {np.abs(i_m).max():.4g} A; final i_dq motulator "
        f"({i_m[-1].real:.9g}, {i_m[-1].imag:.9g}) A, jaxobs ({i_j[-1].real:.9g}, {i_j[-1].imag:.9g}) A",
        f"max |Δi| = {err.max():.3e} A at sample {k}; relative to max |i|: {rel:.3e} (must be <= {TOL:g}): "
        + ("PASS" if rel <= TOL else "FAIL"),
    ]
    text = "\n".join(lines)
    print(text)
    if a.out:
        Path(a.out).write_text(text + "\n")
    return 0 if rel <= TOL else 1


if __name__ == "__main__":
    sys.exit(main())
