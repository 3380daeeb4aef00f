"""``jaxobs bench``: scenario-steps per second of jaxobs beside NumPy and numba, in one process and run.

Workloads (each scenario differs: a frequency step, phase jump and sag per scenario):

- ``sogi-fll``, ``sogi-fll-wpf``, ``sogi-fll-wif``: the FLL family of paper 001
  with its AB3 integrator and closed-form gains, 1 s at 10 kHz, running cost
  ∫(ω̂ − ω)² (nothing else kept).  ``inputs="loop"`` computes the grid voltage
  (two cosines) inside the loop; ``"precomputed"`` samples the voltage and the
  true ω once, outside the timed call, and every implementation reads the same
  arrays (jaxobs through a :class:`~jaxobs.signals.SampledSignal`).
- ``drive-sosoifo``: the closed-loop sensorless PMSM drive of paper 000
  (plant by RK4 in two substeps, inverter with dead time, current and speed
  PI, second-order SOIFO + FLL by RK4), 0.2 s at 10 kHz, running cost
  ∫(θ̂ − θ)²; the speed reference differs per scenario.

Implementations: ``jaxobs`` (``jit`` of :func:`jaxobs.map_batch` over
``simulate``: the batch sharded over every host device, 512 scenarios per tile), ``numba`` (``njit`` loop over the batch, serial and
``parallel=True``), ``numpy`` (Python loop over time, vectorized over the
batch).  The baselines are :mod:`jaxobs.bench.kernels`, checked equal to jaxobs
in tests/test_bench.py.  numba is optional (``pip install jaxobs[bench]``).

Besides throughput: compile time of a new observer shape, the
``value_and_grad``/forward time ratio (checkpointed per step), and XLA's
temporary-buffer size of a 10 s (100k-step) gradient at batch 1024 with and
without checkpointing.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import drive as D
from ..linear import sogi_fll_closed_form, wif_closed_form, wpf_closed_form
from ..metrics import wrap
from ..observers import SecondOrderSOIFO
from ..sharding import map_batch, shard_batch
from ..signals import GridSignal, SampledSignal
from ..simulate import simulate
from . import kernels

__all__ = ["FLL_KINDS", "run_bench", "fll_scenarios", "fll_observer", "drive_setup", "Row"]

FLL_KINDS = ("sogi-fll", "sogi-fll-wpf", "sogi-fll-wif")
TS = 1e-4
FLL_T1 = 1.0
DRIVE_T1 = 0.2
DTYPES = {"f32": np.float32, "f64": np.float64}


@dataclasses.dataclass
class Row:
    workload: str
    impl: str  # jaxobs | numba-parallel | numba-serial | numpy
    dtype: str
    batch: int
    inputs: str  # loop | precomputed
    steps_per_s: float
    ratio_vs_numba_parallel: float | None = None


# ---------------------------------------------------------------------------
# workloads
# ---------------------------------------------------------------------------


def fll_scenarios(batch: int):
    """Per-scenario signal parameters (NumPy, float64): (amp, f0, ph, te, fstep, pj, sag, dc, suba, subf)."""
    s = np.linspace(0.0, 1.0, batch) if batch > 1 else np.zeros(1)
    cols = dict(
        amplitude=np.ones(batch),
        freq=np.full(batch, 50.0),
        phase=np.zeros(batch),
        t_event=np.full(batch, 0.2),
        freq_step=-2.0 + 4.0 * s,
        phase_jump=np.radians(40.0) * s,
        sag=0.5 * s,
        dc=np.zeros(batch),
        sub_amplitude=np.zeros(batch),
        sub_freq=np.ones(batch),
    )
    return cols


def _grid_signal_batch(cols, dtype):
    base = GridSignal()
    b = len(cols["freq"])
    sig = jax.tree.map(lambda x: jnp.broadcast_to(jnp.asarray(x, dtype), (b,) + jnp.shape(x)), base)
    for name, col in cols.items():
        sig = eqx.tree_at(lambda s, name=name: getattr(s, name), sig, jnp.asarray(col, dtype))
    return sig


def fll_observer(kind: str):
    if kind == "sogi-fll":
        return sogi_fll_closed_form(k=math.sqrt(2))
    if kind == "sogi-fll-wpf":
        return wpf_closed_form()
    if kind == "sogi-fll-wif":
        return wif_closed_form()
    raise ValueError(f"FLL workload must be one of {FLL_KINDS}, got {kind!r}")


def _fll_cost(out, truth):
    d = out.omega - truth.omega
    return d * d


def _batched(one, shard: bool):
    """The jitted batch function: sharded over every device and tiled (``map_batch``), or plain ``vmap``."""
    if shard:
        return jax.jit(lambda b: map_batch(one, b))
    return jax.jit(jax.vmap(one))


def jax_fll(kind: str, batch: int, inputs: str, t1: float = FLL_T1, shard: bool = True):
    """(jitted function, sharded argument): per-scenario running costs of the FLL workload.

    ``inputs="loop"``: the grid signal is generated inside the loop.
    ``inputs="precomputed"``: the waveform and its true frequency are sampled
    once, before the timed function (as the baselines get them: the same
    arrays), and the loop reads them back from a
    :class:`~jaxobs.signals.SampledSignal`, a block of steps at a time.
    """
    obs = fll_observer(kind)
    dtype = jnp.result_type(float)
    if inputs == "loop":
        sig = _grid_signal_batch(fll_scenarios(batch), dtype)
    elif inputs == "precomputed":
        n = int(round(t1 / TS))
        u, truth = _fll_samples(fll_scenarios(batch), n, dtype)
        sig = jax.vmap(lambda u, th, om, a: SampledSignal(u, TS, truth=(th, om, a)))(u, *truth)
    else:
        raise ValueError(f"inputs must be 'loop' or 'precomputed', got {inputs!r}")

    one = lambda s: simulate(obs, s, t1, inputs="loop", save="final", cost=_fll_cost).cost  # noqa: E731
    return _batched(one, shard), (shard_batch(sig) if shard else sig)


def _fll_params(kind, dtype):
    obs = fll_observer(kind)
    vf2 = obs.v_floor * obs.v_floor
    if kind == "sogi-fll":
        p, fname, S = (float(obs.k), float(obs.lam), vf2, 0.0, 0.0), "f_sogifll", 3
    else:
        p, fname, S = (float(obs.k1), float(obs.k2), float(obs.lam), vf2, 0.0), ("f_wpf" if kind == "sogi-fll-wpf" else "f_wif"), 5
    x0 = np.zeros(S)
    x0[-1] = float(obs.omega_n)
    return np.asarray(p, dtype), fname, S, x0.astype(dtype)


@functools.partial(jax.jit, static_argnums=(1, 2))
def _fll_samples_jit(sig, n, dtype):
    t = jnp.asarray(0.0, dtype) + jnp.asarray(TS, dtype) * jnp.arange(n, dtype=dtype)
    u = jax.vmap(lambda s: s(t))(sig)
    truth = tuple(jax.vmap(lambda s, f=f: f(s, t))(sig) for f in (GridSignal.theta, GridSignal.omega, GridSignal.fundamental_amplitude))
    return u, truth


def _fll_samples(cols, n, dtype):
    """The FLL workload's waveform and truth (θ, ω, V), sampled (B, n) by jaxobs's own signal in the working dtype."""
    return _fll_samples_jit(_grid_signal_batch(cols, dtype), n, jnp.dtype(dtype))


def _fll_inputs(cols, n, dtype):
    """Precomputed inputs (B, n) for the baselines: the same samples jaxobs's precomputed rows read."""
    u, (_, om, _) = _fll_samples(cols, n, dtype)
    return np.asarray(u), np.asarray(om)


_NUMBA_CACHE: dict = {}


def numba_fll(kind: str, dtype, parallel: bool, inputs: str):
    """A compiled numba batch runner ``run(batch, n) -> costs`` (cached per configuration)."""
    import numba

    key = ("fll", kind, dtype, parallel, inputs)
    if key not in _NUMBA_CACHE:
        ns = kernels.numba_namespace(dtype, TS)
        p, fname, S, x0 = _fll_params(kind, dtype)
        f = ns[fname]
        ab3, ab3_pre = ns["ab3_run"], ns["ab3_run_pre"]
        h = dtype(TS)

        @numba.njit(parallel=parallel)
        def run_loop_(SP, n):
            B = SP.shape[0]
            out = np.empty(B, SP.dtype)
            for b in numba.prange(B):
                x = x0.copy()
                k1, k2, k3, k4, xt, f1, f2 = (np.zeros(S, SP.dtype), np.zeros(S, SP.dtype), np.zeros(S, SP.dtype), np.zeros(S, SP.dtype),
                                              np.zeros(S, SP.dtype), np.zeros(S, SP.dtype), np.zeros(S, SP.dtype))
                P = (p[0], p[1], p[2], p[3], p[4])
                sp = (SP[b, 0], SP[b, 1], SP[b, 2], SP[b, 3], SP[b, 4], SP[b, 5], SP[b, 6], SP[b, 7], SP[b, 8], SP[b, 9])
                out[b] = ab3(f, S, x, P, sp, n, h, k1, k2, k3, k4, xt, f1, f2)
            return out

        @numba.njit(parallel=parallel)
        def run_pre_(U, OM, n):
            B = U.shape[0]
            out = np.empty(B, U.dtype)
            for b in numba.prange(B):
                x = x0.copy()
                k1, k2, k3, k4, xt, f1, f2 = (np.zeros(S, U.dtype), np.zeros(S, U.dtype), np.zeros(S, U.dtype), np.zeros(S, U.dtype),
                                              np.zeros(S, U.dtype), np.zeros(S, U.dtype), np.zeros(S, U.dtype))
                P = (p[0], p[1], p[2], p[3], p[4])
                out[b] = ab3_pre(f, S, x, P, U[b], OM[b], n, h, k1, k2, k3, k4, xt, f1, f2)
            return out

        _NUMBA_CACHE[key] = run_loop_ if inputs == "loop" else run_pre_
    return _NUMBA_CACHE[key]


def fll_baseline_args(kind, batch, dtype, inputs, n):
    cols = fll_scenarios(batch)
    if inputs == "loop":
        SP = np.stack([cols[k] for k in ("amplitude", "freq", "phase", "t_event", "freq_step", "phase_jump", "sag", "dc", "sub_amplitude", "sub_freq")], axis=1)
        return (np.ascontiguousarray(SP.astype(dtype)), n)
    u, om = _fll_inputs(cols, n, dtype)
    return (u, om, n)


def numpy_fll(kind: str, batch: int, dtype, n: int):
    """The FLL workload by NumPy: a Python loop over time, each step vectorized over the batch."""
    ns = kernels.numpy_namespace(dtype, TS)
    p, fname, S, x0 = _fll_params(kind, dtype)
    cols = fll_scenarios(batch)
    sp = tuple(np.asarray(cols[k], dtype) for k in ("amplitude", "freq", "phase", "t_event", "freq_step", "phase_jump", "sag", "dc", "sub_amplitude", "sub_freq"))
    x = np.repeat(x0[:, None], batch, axis=1)
    bufs = [np.zeros((S, batch), dtype) for _ in range(7)]
    return ns["ab3_run"](ns[fname], S, x, tuple(p), sp, n, dtype(TS), *bufs)


# --- drive ------------------------------------------------------------------


def drive_setup(batch: int):
    """(drive, observer, batched scenarios, per-scenario speed refs in rad/s) of the drive workload."""
    from ..reproduce.flux import K1, K2, bench_machine, flux_drive

    par = bench_machine()
    drive = flux_drive(par, handover=0.05)
    obs = SecondOrderSOIFO(par.Rs, par.Ld, K1, K2, K1**3 / (2 * K2), omega0=par.p * 1000 * D.RPM)
    rpm = np.linspace(500.0, 2000.0, batch) if batch > 1 else np.array([1000.0])
    base = D.Scenario(par, load=D.Profile([0.0, 0.1], [0.0, 5.0], kind="step"), omega_m0=1000 * D.RPM, dead_time=2e-6)
    sc = jax.tree.map(lambda x: jnp.broadcast_to(x, (batch,) + jnp.shape(x)), base)
    w = jnp.asarray(rpm * D.RPM, jnp.result_type(float))
    sc = eqx.tree_at(lambda s: s.speed_ref.values, sc, w[:, None])
    sc = eqx.tree_at(lambda s: s.omega_m0, sc, w)
    return drive, obs, sc, rpm * D.RPM


def _drive_cost(s):
    d = wrap(s.obs.theta - s.theta_e)
    return d * d


def jax_drive(batch: int, inputs: str = "loop", t1: float = DRIVE_T1, shard: bool = True):
    drive, obs, sc, _ = drive_setup(batch)

    one = lambda s: D.simulate_drive(drive, s, t1, obs, save="final", cost=_drive_cost, inputs=inputs).cost  # noqa: E731
    return _batched(one, shard), (shard_batch(sc) if shard else sc)


def _drive_params(dtype):
    drive, obs, _, _ = drive_setup(1)
    from ..reproduce.flux import bench_machine

    par = bench_machine()
    foc, inv = drive.foc, drive.inverter
    du = float(inv.udc) * 2e-6 * float(inv.f_pwm)
    M = (par.Rs, par.Ld, par.Lq, par.psi_f, par.J, par.B, par.p, par.a5, par.a7, du)
    O = (obs.Rs, obs.L, obs.K1, obs.K2, obs.lam, obs.v_floor**2, obs.omega_min)
    C = (foc.kp_d, foc.ki_d, foc.kp_q, foc.ki_q, foc.kp_w, foc.ki_w, foc.i_max, par.Ld, par.Lq, par.psi_f, foc.setpoint_weight)
    P = (float(inv.u_max), drive.handover, TS * foc.speed_every, 0.1, 5.0)
    cast = lambda t: np.asarray([float(v) for v in t], dtype)  # noqa: E731
    return cast(M), cast(O), cast(C), cast(P), float(obs.omega0), foc.speed_every


def numba_drive(dtype, parallel: bool):
    import numba

    key = ("drive", dtype, parallel)
    if key not in _NUMBA_CACHE:
        M, O, C, P, omega0, every = _drive_params(dtype)
        ns = kernels.numba_namespace(dtype, TS / 2, ts=TS, speed_every=every)
        drive_run = ns["drive_run"]
        ts = dtype(TS)
        w0 = dtype(omega0)
        zero = dtype(0.0)

        @numba.njit(parallel=parallel)
        def run(W, n):
            B = W.shape[0]
            out = np.empty(B, W.dtype)
            for b in numba.prange(B):
                x = np.zeros(4, W.dtype)
                x[2] = W[b]
                o = np.zeros(9, W.dtype)
                o[8] = w0
                k1, k2, k3, k4, xt = np.zeros(4, W.dtype), np.zeros(4, W.dtype), np.zeros(4, W.dtype), np.zeros(4, W.dtype), np.zeros(4, W.dtype)
                ok1, ok2, ok3, ok4, ot = np.zeros(9, W.dtype), np.zeros(9, W.dtype), np.zeros(9, W.dtype), np.zeros(9, W.dtype), np.zeros(9, W.dtype)
                Mt = (M[0], M[1], M[2], M[3], M[4], M[5], M[6], M[7], M[8], M[9])
                Ot = (O[0], O[1], O[2], O[3], O[4], O[5], O[6])
                Ct = (C[0], C[1], C[2], C[3], C[4], C[5], C[6], C[7], C[8], C[9], C[10])
                Pt = (P[0], P[1], P[2], P[3], P[4])
                prof = (W[b], zero, zero, zero, zero)
                out[b] = drive_run(x, o, Pt, Mt, Ot, Ct, prof, n, ts, k1, k2, k3, k4, xt, ok1, ok2, ok3, ok4, ot)
            return out

        _NUMBA_CACHE[key] = run
    return _NUMBA_CACHE[key]


def numpy_drive(batch: int, dtype, n: int):
    M, O, C, P, omega0, every = _drive_params(dtype)
    ns = kernels.numpy_namespace(dtype, TS / 2, ts=TS, speed_every=every)
    w = np.asarray(drive_setup(batch)[3], dtype)
    x = np.zeros((4, batch), dtype)
    x[2] = w
    o = np.zeros((9, batch), dtype)
    o[8] = omega0
    b4 = [np.zeros((4, batch), dtype) for _ in range(5)]
    b9 = [np.zeros((9, batch), dtype) for _ in range(5)]
    z = np.zeros(batch, dtype)
    return ns["drive_run"](x, o, tuple(P), tuple(M), tuple(O), tuple(C), (w, z, z, z, z), n, dtype(TS), *b4, *b9)


# ---------------------------------------------------------------------------
# timing
# ---------------------------------------------------------------------------


def _best_time(fn: Callable, repeats: int, min_time: float = 0.0) -> float:
    best = math.inf
    spent = 0.0
    i = 0
    while i < repeats or spent < min_time:
        t0 = time.perf_counter()
        out = fn()
        jax.block_until_ready(out)
        dt = time.perf_counter() - t0
        best, spent, i = min(best, dt), spent + dt, i + 1
        if i >= 20:
            break
    return best


def _set_dtype(dt: str):
    jax.config.update("jax_enable_x64", dt == "f64")


def _numba_available() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def run_bench(quick: bool = False, log: Callable[[str], None] = print) -> dict:
    """Run every benchmark; returns ``{"rows": [...], "grad_over_forward": ..., ...}``."""
    batches = (1, 1024) if quick else (1, 64, 1024, 8192)
    fll_t1, drive_t1 = (0.1, 0.05) if quick else (FLL_T1, DRIVE_T1)
    kinds = ("sogi-fll",) if quick else FLL_KINDS
    repeats = 2 if quick else 3
    have_numba = _numba_available()
    rows: list[Row] = []
    extra: dict = {"devices": [str(d) for d in jax.devices()], "numba": have_numba, "quick": quick}
    if not have_numba:
        log("numba is not installed (pip install 'jaxobs[bench]'): numba rows and ratios are left out")

    def add(row):
        rows.append(row)
        log(f"  {row.workload:14s} {row.impl:15s} {row.dtype} {row.inputs:11s} batch {row.batch:5d}: {row.steps_per_s / 1e6:9.2f} M steps/s")

    for dt in ("f32", "f64"):
        _set_dtype(dt)
        dtype = DTYPES[dt]
        for kind in kinds:
            n = int(round(fll_t1 / TS))
            for batch in batches:
                for inputs in ("loop", "precomputed"):
                    fn, args = jax_fll(kind, batch, inputs, fll_t1)
                    jax.block_until_ready(fn(args))
                    t = _best_time(lambda: fn(args), repeats)
                    add(Row(kind, "jaxobs", dt, batch, inputs, batch * n / t))
                    if have_numba:
                        for par in (True, False):
                            if not par and batch > 1024:
                                continue  # serial numba at 8192 adds minutes and no information
                            run = numba_fll(kind, dtype, par, inputs)
                            bargs = fll_baseline_args(kind, batch, dtype, inputs, n)
                            run(*fll_baseline_args(kind, 2, dtype, inputs, 3))  # compile
                            t = _best_time(lambda: run(*bargs), repeats)
                            add(Row(kind, "numba-parallel" if par else "numba-serial", dt, batch, inputs, batch * n / t))
                if batch in (1024,):
                    n_np = min(n, 1000)
                    t = _best_time(lambda: numpy_fll(kind, batch, dtype, n_np), 1)
                    add(Row(kind, "numpy", dt, batch, "loop", batch * n_np / t))
        # drive
        n = int(round(drive_t1 / TS))
        for batch in batches:
            fn, args = jax_drive(batch, "loop", drive_t1)
            jax.block_until_ready(fn(args))
            t = _best_time(lambda: fn(args), repeats)
            add(Row("drive-sosoifo", "jaxobs", dt, batch, "loop", batch * n / t))
            if have_numba:
                for par in (True, False):
                    if not par and batch > 1024:
                        continue
                    run = numba_drive(dtype, par)
                    run(np.ones(2, dtype), 3)
                    w = np.asarray(drive_setup(batch)[3], dtype)
                    t = _best_time(lambda: run(w, n), repeats)
                    add(Row("drive-sosoifo", "numba-parallel" if par else "numba-serial", dt, batch, "loop", batch * n / t))
            if batch == 1024:
                n_np = min(n, 200)
                t = _best_time(lambda: numpy_drive(batch, dtype, n_np), 1)
                add(Row("drive-sosoifo", "numpy", dt, batch, "loop", batch * n_np / t))

    # ratios against numba-parallel of the same workload, dtype, batch and inputs
    ref = {(r.workload, r.dtype, r.batch, r.inputs): r.steps_per_s for r in rows if r.impl == "numba-parallel"}
    for r in rows:
        key = (r.workload, r.dtype, r.batch, r.inputs)
        if key in ref:
            r.ratio_vs_numba_parallel = r.steps_per_s / ref[key]

    _set_dtype("f64")
    extra.update(gradient_benchmarks(quick, log))
    extra.update(compile_benchmarks(log))
    return {"rows": [dataclasses.asdict(r) for r in rows], **extra}


# ---------------------------------------------------------------------------
# gradients, memory, compile time
# ---------------------------------------------------------------------------


# the gains a tuning job tunes (omega_n, the nominal frequency, is a design input)
GAINS = {"sogi-fll": ("k", "lam"), "sogi-fll-wpf": ("k1", "k2", "lam"), "sogi-fll-wif": ("k1", "k2", "lam")}


def _fll_loss_fn(kind, t1, checkpoint, inputs="loop"):
    """(gains → mean running cost over the batch) for the FLL workload, and its tuned gains."""
    obs = fll_observer(kind)
    names = GAINS[kind]
    params = {n: getattr(obs, n) for n in names}

    def loss(params, sig):
        o = eqx.tree_at(lambda m: tuple(getattr(m, n) for n in names), obs, tuple(params[n] for n in names))
        costs = jax.vmap(lambda s: simulate(o, s, t1, inputs=inputs, save="final", cost=_fll_cost, checkpoint=checkpoint).cost)(sig)
        return jnp.mean(costs)

    return loss, params


def grad_temp_mb(kind: str = "sogi-fll", batch: int = 1024, t1: float = 10.0, checkpoint: str = "auto") -> float:
    """XLA's temporary-buffer size (MB) of value_and_grad over ``t1`` seconds at ``batch`` (compiled, not run)."""
    loss, params = _fll_loss_fn(kind, t1, checkpoint)
    sig = _grid_signal_batch(fll_scenarios(batch), jnp.result_type(float))
    compiled = jax.jit(jax.value_and_grad(loss)).lower(params, sig).compile()
    return compiled.memory_analysis().temp_size_in_bytes / 1e6


def gradient_benchmarks(quick: bool, log) -> dict:
    """value_and_grad vs forward time (batch 1024, 1 s, float64) and 10 s gradient memory."""
    kind, batch = "sogi-fll", 1024
    t1 = 0.2 if quick else FLL_T1
    sig = shard_batch(_grid_signal_batch(fll_scenarios(batch), jnp.result_type(float)))
    out = {"grad_over_forward": {}, "grad_temp_mb_10s": {}, "grad_10s_s": None}
    loss, params = _fll_loss_fn(kind, t1, "auto")
    fwd = jax.jit(loss)
    jax.block_until_ready(fwd(params, sig))
    for ck in ("auto", "none", "step", "chunk"):
        loss_c, _ = _fll_loss_fn(kind, t1, ck)
        vg = jax.jit(jax.value_and_grad(loss_c))
        jax.block_until_ready(vg(params, sig))
        # interleaved, best of each: a ratio of two timings taken side by side
        t_f, t_g = math.inf, math.inf
        for _ in range(3):
            t_f = min(t_f, _best_time(lambda: fwd(params, sig), 1))
            t_g = min(t_g, _best_time(lambda: vg(params, sig), 1))
        out["grad_over_forward"][ck] = t_g / t_f
        log(f"  value_and_grad / forward ({kind} gains {GAINS[kind]}, batch {batch}, {t1:g} s, f64, checkpoint={ck}): {t_g / t_f:.2f}")
    for ck in ("auto", "none", "step", "chunk"):
        mb = grad_temp_mb(kind, batch, 10.0, ck)
        out["grad_temp_mb_10s"][ck] = mb
        log(f"  10 s gradient temporaries ({kind}, batch {batch}, f64, checkpoint={ck}): {mb:,.1f} MB")
    if not quick:
        loss10, _ = _fll_loss_fn(kind, 10.0, "auto")
        vg10 = jax.jit(jax.value_and_grad(loss10))
        t0 = time.perf_counter()
        val, g = jax.block_until_ready(vg10(params, sig))
        out["grad_10s_s"] = time.perf_counter() - t0
        out["grad_10s_finite"] = bool(np.isfinite(float(val)) and all(np.all(np.isfinite(x)) for x in jax.tree.leaves(g)))
        log(f"  10 s gradient at batch {batch} (compile + run, checkpoint=auto): {out['grad_10s_s']:.1f} s")
    return out


def compile_benchmarks(log) -> dict:
    """Seconds to trace and compile a new observer / scenario shape (batch 1024, 1 s)."""
    res = {}
    for name, build in (
        ("sogi-fll-wif", lambda: jax_fll("sogi-fll-wif", 1024, "loop", 1.0)),
        ("drive-sosoifo", lambda: jax_drive(1024, "loop", DRIVE_T1)),
    ):
        fn, args = build()
        t0 = time.perf_counter()
        fn.lower(args).compile()
        res[name] = time.perf_counter() - t0
        log(f"  compile {name} (batch 1024): {res[name]:.2f} s")
    return {"compile_s": res}


def table(res: dict) -> str:
    """The results as a text table: throughput rows, then the gradient, memory and compile figures."""
    lines = [f"{'workload':14s} {'impl':15s} {'dtype':5s} {'inputs':11s} {'batch':>6s} {'M steps/s':>10s} {'vs numba-par':>12s}"]
    for r in res["rows"]:
        ratio = "" if r["ratio_vs_numba_parallel"] is None else f"{r['ratio_vs_numba_parallel']:.2f}"
        lines.append(f"{r['workload']:14s} {r['impl']:15s} {r['dtype']:5s} {r['inputs']:11s} {r['batch']:6d} {r['steps_per_s'] / 1e6:10.2f} {ratio:>12s}")
    g = res["grad_over_forward"]
    lines.append("value_and_grad / forward: " + ", ".join(f"{k} {v:.2f}" for k, v in g.items()))
    lines.append("10 s gradient temporaries, MB: " + ", ".join(f"{k} {v:,.1f}" for k, v in res["grad_temp_mb_10s"].items()))
    lines.append("compile, s: " + ", ".join(f"{k} {v:.2f}" for k, v in res["compile_s"].items()))
    lines.append(f"devices: {len(res['devices'])} ({', '.join(res['devices'])})")
    return "\n".join(lines)
