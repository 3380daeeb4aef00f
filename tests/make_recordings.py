"""The example recordings of tuning/presets/recordings/, made reproducibly: ``python tests/make_recordings.py``.

- ``grid_50_51hz.csv``: a single-phase grid voltage (1 p.u., 50 Hz) recorded at 12.8 kHz (256 samples a
  cycle, a common DSP rate; an observer at 10 kHz reads it resampled) for 0.4 s: at 0.1 s the frequency
  steps to 51 Hz, the phase jumps +20° and 4 % 5th and 3 % 7th harmonics appear (jaxobs.GridSignal),
  plus white measurement noise of 0.005 p.u. (seeded).  Columns: t (s), v (p.u.), and the truth the
  FLL metrics compare against: theta (rad, wrapped), omega (rad/s), amplitude (p.u.).
- ``drive_spmsm_1000rpm.csv``: u/i of paper 000's SPMSM in a sensored FOC drive
  (jaxobs_tuning.export.drive_recording, ideal sensors) at 10 kHz for 0.3 s, 1000 r/min and 0.3 T_rated, +10 %
  speed reference at 0.1 s, load to 0.8 T_rated at 0.2 s.  Columns: t (s), u_a, u_b (V, applied over
  the period from t), i_a, i_b (A, sampled at t), theta_e (encoder, electrical rad, wrapped), omega_e
  (electrical rad/s).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "tuning" / "presets" / "recordings"
GRID_RATE = 12_800.0
GRID_SECONDS = 0.4


def grid_table() -> tuple[str, np.ndarray]:
    import jaxobs

    sig = jaxobs.GridSignal(
        1.0, 50.0, t_event=0.1, freq_step=1.0, phase_jump=math.radians(20.0), harmonics={5: 0.04, 7: 0.03}
    )
    t = np.arange(round(GRID_SECONDS * GRID_RATE)) / GRID_RATE
    v = np.asarray(sig(t)) + 0.005 * np.random.default_rng(20).standard_normal(t.size)
    th = np.angle(np.exp(1j * np.asarray(sig.theta(t))))
    cols = np.stack([t, v, th, np.asarray(sig.omega(t)), np.asarray(sig.fundamental_amplitude(t))], axis=1)
    return "t,v,theta,omega,amplitude", cols


def drive_table() -> tuple[str, np.ndarray]:
    import jaxobs
    from jaxobs import papers
    from jaxobs_tuning.export import drive_recording

    obs = jaxobs.SOIFO(Rs=0.0, L=1.0, k=papers.SOIFO_K, lam=0.5, omega_init=1.0)  # only its family and ts matter here
    data, _ = drive_recording(obs, 3000, encoder=True)
    t = np.arange(data.shape[0]) * float(obs.ts)
    return "t,u_a,u_b,i_a,i_b,theta_e,omega_e", np.concatenate([t[:, None], data.astype(np.float64)], axis=1)


def write(name: str, header: str, cols: np.ndarray, note: str) -> Path:
    path = OUT / name
    np.savetxt(path, cols, delimiter=",", header=f"{note}\n{header}", comments="", fmt="%.7g")
    # the first header line is a comment
    text = path.read_text().splitlines()
    path.write_text("\n".join([f"# {text[0]}", *text[1:]]) + "\n")
    return path


def main() -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    OUT.mkdir(parents=True, exist_ok=True)
    h, c = grid_table()
    print(write("grid_50_51hz.csv", h, c, "jaxobs example: 50 Hz grid, +1 Hz, +20 deg, 5th/7th at 0.1 s; 12.8 kHz"))
    if "--grid-only" not in sys.argv:
        h, c = drive_table()
        print(write("drive_spmsm_1000rpm.csv", h, c, "jaxobs example: 000 SPMSM sensored FOC, 1000 r/min; 10 kHz"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
