"""matplotlib figures (imported lazily: the library itself never needs a display)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from . import linear, metrics, papers


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _finish(fig, path, dpi=110):
    """Lay out, save to ``path`` (if given) and close; the figure is returned for notebooks."""
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=dpi)
        _plt().close(fig)
    return fig


def fll_demo_figure(traces, tests, t_event, path=None):
    """Frequency estimate and phase error of each FLL for each test (rows = tests)."""
    plt = _plt()
    fig, axes = plt.subplots(len(tests), 2, figsize=(11, 2.2 * len(tests)), sharex=False, squeeze=False)
    for name, sol in traces.items():
        t = np.asarray(sol.t[0])
        f_hat = np.asarray(sol.outputs.obs.omega) / (2 * math.pi)
        err = np.degrees(np.asarray(metrics.wrap(sol.outputs.obs.theta - sol.outputs.truth.theta)))
        for i, test in enumerate(tests):
            span = 0.3 if test in ("A", "B") else 1.2
            m = (t >= t_event - 0.05) & (t <= t_event + span)
            axes[i, 0].plot(1e3 * (t[m] - t_event), f_hat[i][m], lw=1, label=name)
            axes[i, 1].plot(1e3 * (t[m] - t_event), err[i][m], lw=1, label=name)
    for i, test in enumerate(tests):
        axes[i, 0].set_ylabel(f"Test {test}\nf̂ (Hz)")
        axes[i, 1].set_ylabel("θ̂ − θ (deg)")
        for ax in axes[i]:
            ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time after event (ms)")
    axes[-1, 1].set_xlabel("time after event (ms)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Paper 001 Tests A–E, Table I gains (simulated, 10 kHz, AB3)")
    return _finish(fig, path)


def bode_figure(tfs: dict, omega, title: str, path=None, hz: bool = True, mark=None):
    """Bode magnitude (dB) and phase (deg) of several transfer functions on one grid.

    Complex-coefficient filters are plotted over negative and positive frequency
    when ``omega`` contains both signs (their response is not conjugate-symmetric).
    """
    plt = _plt()
    omega = np.asarray(omega)
    x = omega / (2 * math.pi) if hz else omega
    fig, (ax_m, ax_p) = plt.subplots(2, 1, figsize=(7.5, 6), sharex=True)
    for name, tf in tfs.items():
        mag, ph = linear.bode(tf, omega)
        ax_m.plot(x, np.asarray(mag), lw=1.3, label=name)
        ax_p.plot(x, np.asarray(ph), lw=1.3, label=name)
    if np.all(omega > 0):
        ax_m.set_xscale("log")
    if mark is not None:
        for ax in (ax_m, ax_p):
            ax.axvline(mark / (2 * math.pi) if hz else mark, color="k", lw=0.6, ls=":")
    ax_m.set_ylabel("magnitude (dB)")
    ax_p.set_ylabel("phase (deg)")
    ax_p.set_xlabel("frequency (Hz)" if hz else "ω (rad/s)")
    for ax in (ax_m, ax_p):
        ax.grid(True, which="both", alpha=0.3)
    ax_m.legend(fontsize=8)
    ax_m.set_title(title)
    return _finish(fig, path)


def paper_bode_figures(out_dir):
    """The three Bode figures of the papers: 000 Fig. 5, 002 Fig. 4, 001 Fig. 14. Returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    # 000 Fig. 5: ω' = 100π, ωc = 100, k = 1.414, K1 = 1.56, K2 = 3.11
    w1 = papers.FLUX_FIG5_OMEGA
    k, K1, K2 = papers.SOIFO_K, papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2
    flux = {
        "pure integrator": linear.integrator_flux_tf(),
        f"LPF (ωc = {papers.LPF_OMEGA_C:g})": linear.lpf_flux_tf(papers.LPF_OMEGA_C),
        f"SOIFO (k = {k:g})": linear.soifo_tf(k, w1),
        f"second-order SOIFO (K1 = {K1:g}, K2 = {K2:g})": linear.sosoifo_tf(K1, K2, w1),
    }
    p = out / "bode_flux_observers_000_fig5.png"
    bode_figure(flux, np.logspace(0, 5, 2000), "Paper 000 Fig. 5: flux observers ψ̂/e", p, mark=w1)
    paths.append(p)
    # 002 Fig. 4 / Table II (two-sided, the FA-LESO is complex)
    we = papers.LESO_TABLE_II_OMEGA_E
    leso = {
        "C-LESO (ω0 = 500π)": linear.cleso_tf(papers.LESO_OMEGA0),
        "GI-LESO (Kr = 2ω0², ωc = π)": linear.gileso_tf(
            papers.LESO_OMEGA0, papers.GILESO_K_R, papers.GILESO_OMEGA_C, we
        ),
        "FA-LESO (k1 = 10π, k2 = 100π)": linear.faleso_tf(papers.FALESO_K1, papers.FALESO_K2, we),
    }
    wpos = np.logspace(0, 4.5, 1200)
    omega = np.concatenate([-wpos[::-1], wpos])
    p = out / "bode_lesos_002_fig4.png"
    fig = bode_figure(leso, omega, "Paper 002 Fig. 4: LESOs ê/e at ω̂e = 100π (two-sided)", None, mark=we)
    for ax in fig.axes:
        ax.set_xscale("symlog", linthresh=10)
    _finish(fig, p)
    paths.append(p)
    # 001 Fig. 14: open loops θ̂/(θ − θ̂), Table I gains
    s, wp, wi = linear.sogi_fll_closed_form(), linear.wpf_closed_form(), linear.wif_closed_form()
    fll = {
        "SOGI-FLL": linear.sogi_fll_model(s.k, s.lam, s.omega_n).open_loop,
        "SOGI-FLL-WPF": linear.wpf_model(wp.k1, wp.k2, wp.lam, wp.omega_n).open_loop,
        "SOGI-FLL-WIF": linear.wif_model(wi.k1, wi.k2, wi.lam, wi.omega_n).open_loop,
    }
    p = out / "bode_fll_open_loop_001_fig14.png"
    bode_figure(
        fll, np.logspace(0, 4, 1500), "Paper 001 Fig. 14: FLL open loops, Table I gains", p, mark=papers.WIF_OMEGA_C
    )
    paths.append(p)
    return paths


def flux_circles_figure(sol, names, title, path=None, last: float = 0.1):
    """Estimated rotor-flux circles (ψ̂β vs ψ̂α) of each observer over the last ``last`` seconds."""
    plt = _plt()
    t = np.asarray(sol.t)
    m = t >= t[-1] - last
    fig, axes = plt.subplots(1, len(names), figsize=(3.2 * len(names), 3.4), squeeze=False)
    for ax, name, o in zip(axes[0], names, sol.outputs.obs.each):
        pa, pb = np.asarray(o.psi_a)[m], np.asarray(o.psi_b)[m]
        ax.plot(pa, pb, lw=0.8)
        ax.set_aspect("equal", adjustable="datalim")
        ax.axhline(0, color="k", lw=0.4)
        ax.axvline(0, color="k", lw=0.4)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("ψ̂α (Wb)")
        ax.grid(True, alpha=0.3)
    axes[0, 0].set_ylabel("ψ̂β (Wb)")
    fig.suptitle(title, fontsize=10)
    return _finish(fig, path)


def position_error_figure(sol, names, title, path=None, t_from: float = 0.0):
    """Wrapped position error θ̂e − θe of each observer, with the speed on a second axis."""
    plt = _plt()
    t = np.asarray(sol.t)
    m = t >= t_from
    fig, (ax_s, ax_e) = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    ax_s.plot(t[m], np.asarray(sol.outputs.speed_rpm)[m], label="speed", lw=1)
    ax_s.plot(t[m], np.asarray(sol.outputs.omega_m_ref)[m] * 30 / math.pi, "k--", lw=0.8, label="reference")
    ax_s.set_ylabel("speed (r/min)")
    ax_s.legend(fontsize=8)
    for name, o in zip(names, sol.outputs.obs.each):
        err = np.asarray(metrics.wrap(o.theta - sol.outputs.theta_e))[m]
        ax_e.plot(t[m], err, lw=0.8, label=name)
    ax_e.set_ylim(-1.7, 1.7)
    ax_e.set_ylabel("θ̂e − θe (rad)")
    ax_e.set_xlabel("time (s)")
    ax_e.legend(fontsize=8, ncol=4)
    for ax in (ax_s, ax_e):
        ax.grid(True, alpha=0.3)
    fig.suptitle(title, fontsize=10)
    return _finish(fig, path)


def study_figures(ds, out_dir):
    """Heat-maps (mean over the other axes, first two axes) and distributions per metric; returns the paths."""
    plt = _plt()
    out = Path(out_dir)
    paths = []
    axes = [d for d in ds.dims if d != "design"]
    for metric in ("settling_freq", "ripple_freq", "rms_phase"):
        da = ds[metric]
        if len(axes) >= 2 and "sample" not in axes:
            a0, a1 = axes[0], axes[1]
            red = da.mean(dim=[d for d in axes if d not in (a0, a1)]) if len(axes) > 2 else da
            designs = list(ds["design"].values)
            fig, axs = plt.subplots(1, len(designs), figsize=(4 * len(designs), 3.4), squeeze=False)
            for ax, d in zip(axs[0], designs):
                arr = np.asarray(red.sel(design=d).transpose(a1, a0))
                im = ax.imshow(arr, origin="lower", aspect="auto", extent=None)
                ax.set_xticks(range(len(ds[a0])), [f"{v:g}" for v in ds[a0].values], fontsize=7)
                ax.set_yticks(range(len(ds[a1])), [f"{v:g}" for v in ds[a1].values], fontsize=7)
                ax.set_xlabel(a0)
                ax.set_ylabel(a1)
                ax.set_title(str(d), fontsize=9)
                fig.colorbar(im, ax=ax)
            fig.suptitle(f"{metric} (mean over the other axes)", fontsize=10)
            p = out / f"heatmap_{metric}.png"
            _finish(fig, p, dpi=100)
            paths.append(p)
        fig, ax = plt.subplots(figsize=(6, 3.4))
        for d in ds["design"].values:
            vals = np.asarray(da.sel(design=d)).ravel()
            vals = vals[np.isfinite(vals)]
            ax.hist(vals, bins=30, alpha=0.5, label=str(d))
        ax.set_xlabel(metric)
        ax.set_ylabel("scenarios")
        ax.legend(fontsize=8)
        p = out / f"distribution_{metric}.png"
        _finish(fig, p, dpi=100)
        paths.append(p)
    return paths


def drive_study_figure(ds, path):
    """Empirical CDFs of every drive-study metric over the scenarios, all designs on one axis per metric
    (one scale per metric across designs, units on the axes), lost-sync counts in the legend."""
    plt = _plt()
    metrics = [v[: -len("_q")] for v in ds.data_vars if v.endswith("_q")]  # the metrics with quantiles
    fig, axs = plt.subplots(1, len(metrics), figsize=(4.2 * len(metrics), 3.6), squeeze=False)
    for ax, m in zip(axs[0], metrics):
        unit, long_name = ds[m].attrs["units"], ds[m].attrs["long_name"]
        for d in ds["design"].values:
            v = np.sort(np.asarray(ds[m].sel(design=d)).ravel())
            v = v[np.isfinite(v)]
            lost = int(ds["lost_sync_count"].sel(design=d))
            if v.size:
                ax.step(v, np.arange(1, v.size + 1) / v.size, where="post", label=f"{d} (lost sync: {lost})")
        ax.set_xlabel(f"{m} ({unit})")
        ax.set_ylabel("fraction of scenarios")
        ax.set_title(long_name, fontsize=8)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"drive study: {int(ds.attrs['scenarios'])} scenarios per design", fontsize=10)
    return _finish(fig, path, dpi=100)
