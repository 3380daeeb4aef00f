"""docs/img/fluxmap_pmsyrm_5p6kw.png: the saturation map of docs/examples/pmsyrm_5p6kw_sat.toml.

``python -m benchmarks.fluxmap_figure``.  Left: ψd(i_d) at several i_q (the PM bridge's knee near i_d = 0 and the
cross-saturation: ψd falls as |i_q| grows); right: ψq(i_q) at several i_d (q-axis self-saturation; cross-saturation
again).  The dots are the rated current's MTPA point on the map (:func:`jaxobs.drive.saturation.map_mtpa`).
"""

from __future__ import annotations

import math
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main():
    import jax

    jax.config.update("jax_enable_x64", True)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from jaxobs.drive import read_drive
    from jaxobs.drive.saturation import map_mtpa

    f = read_drive(ROOT / "docs" / "examples" / "pmsyrm_5p6kw_sat.toml")
    sat, p = f.machine.sat, f.machine.p
    i_r = math.sqrt(2) * f.table["machine"]["rated_current_a"]
    i_max = float(f.derived["i_max"].value)
    i_d0, i_q0, te = map_mtpa(sat, p, i_r)
    psi_d0, psi_q0 = (float(v) for v in sat.flux(i_d0, i_q0))
    i = np.linspace(-i_max, i_max, 241)
    fig, ax = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for frac in (0.0, 0.5, 1.0):
        psi_d, _ = sat.flux(i, frac * i_max * np.ones_like(i))
        ax[0].plot(i, psi_d, label=f"i_q = {frac * i_max:.3g} A")
        _, psi_q = sat.flux(-frac * i_max * np.ones_like(i), i)
        ax[1].plot(i, psi_q, label=f"i_d = {-frac * i_max + 0.0:.3g} A")
    ax[0].plot([i_d0], [psi_d0], "ko", label=f"rated MTPA ({i_d0:.3g}, {i_q0:.3g}) A, {te:.3g} N·m")
    ax[1].plot([i_q0], [psi_q0], "ko", label="rated MTPA")
    ax[0].set(xlabel="i_d (A)", ylabel="ψd (Vs)", title="d-axis flux ψd(i_d, i_q)")
    ax[1].set(xlabel="i_q (A)", ylabel="ψq (Vs)", title="q-axis flux ψq(i_d, i_q)")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(f"5.6-kW PM-SyRM (motulator's example): algebraic saturation map, ±i_max = ±{i_max:.3g} A")
    out = ROOT / "docs" / "img" / "fluxmap_pmsyrm_5p6kw.png"
    fig.savefig(out, dpi=110)
    print(out)


if __name__ == "__main__":
    main()
