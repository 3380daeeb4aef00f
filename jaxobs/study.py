"""Batch robustness studies: designs × a named grid of scenarios → an xarray Dataset.

    ds = run_study({"closed form": fll_a, "tuned": fll_b}, axes={"freq_step": [...], "dc": [...]})
    ds["settling_freq"].sel(design="tuned").max()
    ds.to_netcdf("study.nc", engine="scipy")

Every design is simulated on every scenario of the Cartesian grid (or on
``sample`` random points drawn from the axes' ranges) in one ``jit(vmap)``
call per chunk of ``chunk_size`` scenarios (the last chunk is padded, so one
compilation serves all), with a progress bar over chunks.  The result has one
variable per metric, dims ``("design", *axes)`` (or ``("design", "sample")``
with the axes as coordinates along ``sample``), and a ``diverged`` flag: a
diverging scenario is reported, never fatal.

Scenarios are single-phase grid signals (the FLL family) built by
:func:`jaxobs.scenarios.grid_signals`: axes are ``freq_step`` (Hz),
``phase_jump_deg``, ``sag``, ``dc``, ``harmonics_scale`` (× Test C's spectrum),
``sub_amplitude`` (1 Hz), ``phase_deg`` (initial phase) and ``noise`` (white noise
standard deviation, p.u., with a per-scenario seed).
Metrics (exact versions): ``settling_freq`` (s after the event for the
one-period average of f̂ to stay within ``band_hz`` of the final frequency), ``ripple_freq`` (steady p-p, Hz),
``rms_phase`` (steady rms phase error, rad), ``itae_freq`` and ``iae_phase``.
"""

from __future__ import annotations

import itertools
import math
import sys
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import metrics as M
from .scenarios import GRID_SIGNAL_AXES, grid_signals
from .simulate import OnSignal, simulate

__all__ = ["STUDY_AXES", "STUDY_METRICS", "run_study", "worst_cases"]

STUDY_AXES = GRID_SIGNAL_AXES  # the scenarios a study runs: jaxobs.scenarios.grid_signals
STUDY_METRICS = ("settling_freq", "ripple_freq", "rms_phase", "itae_freq", "iae_phase")


def _metrics(sol, t_event: float, steady_from: float, band_hz: float, n_period: int):
    t = sol.t
    out = sol.outputs
    f_hat = out.obs.omega / (2 * math.pi)
    f_true = out.truth.omega / (2 * math.pi)
    ferr = f_hat - f_true
    perr = M.wrap(out.obs.theta - out.truth.theta)
    steady = t >= steady_from
    # settle on the one-period average of f̂: harmonics and dc leave a ripple that is not a transient
    f_avg = M.moving_average(f_hat, n_period)
    return {
        "settling_freq": M.settling_time(t, f_avg, f_true[-1], band_hz, t_event),
        "ripple_freq": M.peak_to_peak(ferr, steady),
        "rms_phase": M.rms(perr, steady),
        "itae_freq": M.itae(t, ferr, t_event),
        "iae_phase": M.iae(t, perr, t_event),
    }


def _progress(done, total, t0, stream=sys.stderr):
    width = 24
    k = int(width * done / max(total, 1))
    stream.write(f"study [{'#' * k}{'.' * (width - k)}] {done}/{total} scenarios, {time.time() - t0:.1f} s\n")
    stream.flush()


def run_study(
    designs: dict,
    axes: dict,
    *,
    t_event=0.1,
    horizon=0.4,
    steady_from=None,
    band_hz=0.05,
    sample=0,
    seed=0,
    chunk_size=2048,
    progress=True,
):
    """Simulate every design on every scenario; returns an ``xarray.Dataset`` (see module doc)."""
    import xarray as xr

    if not designs:
        raise ValueError("run_study needs at least one design")
    for name in axes:  # names and values are checked by grid_signals
        if len(axes[name]) < 1:
            raise ValueError(f"study axis {name!r} needs at least one value")
    if not horizon > t_event >= 0:
        raise ValueError(f"horizon must exceed t_event >= 0, got t_event={t_event}, horizon={horizon}")
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    steady_from = t_event + 0.75 * (horizon - t_event) if steady_from is None else steady_from
    names = list(axes)
    if sample:
        rng = np.random.default_rng(seed)
        combos = [tuple(rng.uniform(min(axes[n]), max(axes[n])) for n in names) for _ in range(sample)]
    else:
        combos = list(itertools.product(*(list(map(float, axes[n])) for n in names)))
    n = len(combos)
    freq = float(next(iter(designs.values())).omega_n) / (2 * math.pi)
    sigs = grid_signals(names, combos, t_event, freq)
    chunk = min(chunk_size, n)
    pad = (-n) % chunk
    if pad:
        sigs = jax.tree.map(lambda x: jnp.concatenate([x, jnp.repeat(x[-1:], pad, axis=0)]), sigs)

    results = {}
    t0 = time.time()
    total = n * len(designs)
    done = 0
    for dname, obs in designs.items():

        @eqx.filter_jit
        def run_chunk(obs, batch):
            def one(sig):
                sol = simulate(OnSignal(obs, sig), horizon)
                m = _metrics(sol, t_event, steady_from, band_hz, max(1, int(round(1.0 / (freq * obs.ts)))))
                ok = sol.ok & jnp.all(jnp.stack([jnp.isfinite(v) for v in m.values()]))
                return m, ok

            return jax.vmap(one)(batch)

        parts_m, parts_ok = [], []
        for start in range(0, n + pad, chunk):
            batch = jax.tree.map(lambda x: x[start : start + chunk], sigs)
            m, ok = run_chunk(obs, batch)
            parts_m.append(jax.tree.map(np.asarray, m))
            parts_ok.append(np.asarray(ok))
            done += min(chunk, n - start)
            if progress:
                _progress(done, total, t0)
        results[dname] = (
            {k: np.concatenate([p[k] for p in parts_m])[:n] for k in STUDY_METRICS},
            np.concatenate(parts_ok)[:n],
        )

    dnames = list(designs)
    if sample:
        dims = ("design", "sample")
        shape = (n,)
        coords = {"design": dnames, "sample": np.arange(n)}
        for i, name in enumerate(names):
            coords[name] = ("sample", np.asarray([c[i] for c in combos]))
    else:
        dims = ("design", *names)
        shape = tuple(len(axes[nm]) for nm in names)
        coords = {"design": dnames, **{nm: np.asarray(axes[nm], dtype=float) for nm in names}}
    data = {}
    for k in STUDY_METRICS:
        arr = np.stack([np.where(results[d][1], results[d][0][k], np.nan).reshape(shape) for d in dnames])
        data[k] = (dims, arr)
    data["diverged"] = (dims, np.stack([(~results[d][1]).astype(np.int8).reshape(shape) for d in dnames]))
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update(
        t_event=t_event,
        horizon=horizon,
        steady_from=steady_from,
        band_hz=band_hz,
        scenarios=n,
        seconds=time.time() - t0,
    )
    for dname, obs in designs.items():
        gains = {f: float(getattr(obs, f)) for f in ("k", "k1", "k2", "lam") if hasattr(obs, f)}
        ds.attrs[f"gains {dname}"] = ", ".join(f"{k}={v:.6g}" for k, v in gains.items())
    return ds


def worst_cases(ds, metric: str, k: int = 5):
    """The ``k`` worst scenarios per design for ``metric``: dicts with the design, the value and the coordinates."""
    out = []
    for d in ds["design"].values:
        df = ds[metric].sel(design=d).to_dataframe(name="value").reset_index()
        df = df.dropna(subset=["value"]).sort_values("value", ascending=False).head(k)
        for rec in df.to_dict("records"):
            rec = {
                key: (float(v) if isinstance(v, (int, float, np.floating, np.integer)) else str(v))
                for key, v in rec.items()
            }
            rec.update(design=str(d), metric=metric)
            out.append(rec)
    return out
