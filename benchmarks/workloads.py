"""The benchmark workloads as jaxobs runs them: every call into the jaxobs API is in this module.

Workloads (each scenario differs: a frequency step, phase jump and sag per scenario):

- ``sogi-fll``, ``sogi-fll-wpf``, ``sogi-fll-wif``: the FLL family of paper 001
  with its AB3 integrator and closed-form gains, 1 s at 10 kHz, running cost
  ∫(ω̂ − ω)² (nothing else kept).  ``inputs="loop"`` computes the grid voltage
  (two cosines) inside the loop; ``"precomputed"`` samples the voltage and the
  true ω once, outside the timed call, and every implementation reads the same
  arrays (jaxobs through a :class:`jaxobs.SampledSignal`).
- ``drive-sosoifo``: the closed-loop sensorless PMSM drive of paper 000
  (plant by RK4 in two substeps, inverter with dead time, current and speed
  PI, second-order SOIFO + FLL by RK4), 0.2 s at 10 kHz, running cost
  ∫(θ̂ − θ)²; the speed reference differs per scenario.

Besides the jitted batch functions (:func:`jax_fll`, :func:`jax_drive`: ``jit``
of :func:`jaxobs.map_batch` over ``simulate``, the batch sharded over every
host device, 512 scenarios per tile) this module reads off the same jaxobs
objects the parameters and inputs the baselines take (:func:`fll_baseline_params`,
:func:`fll_samples`, :func:`drive_baseline_params`), and builds the gradient
workload (:func:`fll_loss_fn`, :func:`grad_temp_mb`).  The simulation API is
used nowhere else in ``benchmarks/``.
"""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import jaxobs
from jaxobs import drive as D
from jaxobs.linear import second_order_soifo_lambda, sogi_fll_closed_form, wif_closed_form, wpf_closed_form
from jaxobs.metrics import wrap
from jaxobs.papers import SECOND_ORDER_SOIFO_K1 as K1
from jaxobs.papers import SECOND_ORDER_SOIFO_K2 as K2

FLL_KINDS = ("sogi-fll", "sogi-fll-wpf", "sogi-fll-wif")
# the gains a tuning job tunes (omega_n, the nominal frequency, is a design input)
GAINS = {"sogi-fll": ("k", "lam"), "sogi-fll-wpf": ("k1", "k2", "lam"), "sogi-fll-wif": ("k1", "k2", "lam")}
TS = 1e-4
FLL_T1 = 1.0
DRIVE_T1 = 0.2


# ---------------------------------------------------------------------------
# FLL family
# ---------------------------------------------------------------------------


def fll_scenarios(batch: int) -> dict:
    """Per-scenario grid-signal parameters (NumPy, float64), by jaxobs.GridSignal field name."""
    s = np.linspace(0.0, 1.0, batch) if batch > 1 else np.zeros(1)
    return {
        "amplitude": np.ones(batch),
        "freq": np.full(batch, 50.0),
        "phase": np.zeros(batch),
        "t_event": np.full(batch, 0.2),
        "freq_step": -2.0 + 4.0 * s,
        "phase_jump": np.radians(40.0) * s,
        "sag": 0.5 * s,
        "dc": np.zeros(batch),
        "sub_amplitude": np.zeros(batch),
        "sub_freq": np.ones(batch),
    }


def grid_signal_batch(cols: dict, dtype):
    """A batched :class:`jaxobs.GridSignal` (leading scenario axis) with the columns of :func:`fll_scenarios`."""
    base = jaxobs.GridSignal()
    b = len(cols["freq"])
    sig = jax.tree.map(lambda x: jnp.broadcast_to(jnp.asarray(x, dtype), (b,) + jnp.shape(x)), base)
    for name, col in cols.items():
        sig = eqx.tree_at(lambda s, name=name: getattr(s, name), sig, jnp.asarray(col, dtype))
    return sig


def fll_observer(kind: str):
    """The FLL of a workload with its closed-form gains."""
    if kind == "sogi-fll":
        return sogi_fll_closed_form(k=math.sqrt(2))
    if kind == "sogi-fll-wpf":
        return wpf_closed_form()
    if kind == "sogi-fll-wif":
        return wif_closed_form()
    raise ValueError(f"FLL workload must be one of {FLL_KINDS}, got {kind!r}")


def fll_cost(o):
    """Running cost (ω̂ − ω)² of one step's :class:`jaxobs.SignalOutput`."""
    d = o.obs.omega - o.truth.omega
    return d * d


def _batched(one, shard: bool, batch=None, tile=None):
    """The jitted batch function: sharded over every device and tiled (``map_batch``, its ``tile``), or plain
    ``vmap`` (along each node's scenario axis: :func:`jaxobs.batch_axes`)."""
    if shard:
        return jax.jit(lambda b: jaxobs.map_batch(one, b, tile=tile))
    axes = 0 if batch is None else jaxobs.batch_axes(batch)
    return jax.jit(jax.vmap(one, in_axes=(axes,)))


def jax_fll(
    kind: str, batch: int, inputs: str, t1: float = FLL_T1, shard: bool = True, layout: str = "time", tile=None
):
    """(jitted function, its batch argument): per-scenario running costs of the FLL workload.

    ``inputs="loop"``: the grid signal is generated inside the loop.
    ``inputs="precomputed"``: the waveform and its true frequency are sampled
    once, before the timed function (as the baselines get them: the same
    arrays), and the loop reads them back from a :class:`jaxobs.SampledSignal`:
    with ``layout="time"`` (the default, the layout the baselines read) a time-major batch
    (``batch_inner=True``, leaves (n, B)) whose rows the loop takes one per step; with
    ``layout="scenario"`` a batch of scenario-major recordings (leaves (B, n)), read a block of steps
    at a time.
    """
    obs = fll_observer(kind)
    dtype = jnp.result_type(float)
    if layout not in ("time", "scenario"):
        raise ValueError(f"layout must be 'time' or 'scenario', got {layout!r}")
    if inputs == "loop":
        sig = grid_signal_batch(fll_scenarios(batch), dtype)
    elif inputs == "precomputed":
        u, truth = _fll_samples(fll_scenarios(batch), round(t1 / TS), dtype)
        if layout == "time":
            sig = jaxobs.SampledSignal(u.T, TS, truth=tuple(a.T for a in truth), batch_inner=True)
        else:
            sig = jax.vmap(lambda u, th, om, a: jaxobs.SampledSignal(u, TS, truth=(th, om, a)))(u, *truth)
    else:
        raise ValueError(f"inputs must be 'loop' or 'precomputed', got {inputs!r}")

    def one(s):
        return jaxobs.simulate(jaxobs.OnSignal(obs, s), t1, save=jaxobs.SaveFinal(cost=fll_cost)).cost

    return _batched(one, shard, sig, tile), (jaxobs.shard_batch(sig) if shard else sig)


@functools.partial(jax.jit, static_argnums=(1, 2))
def _fll_samples_jit(sig, n, dtype):
    t = jnp.asarray(0.0, dtype) + jnp.asarray(TS, dtype) * jnp.arange(n, dtype=dtype)
    u = jax.vmap(lambda s: s(t))(sig)
    G = jaxobs.GridSignal
    truth = tuple(jax.vmap(lambda s, f=f: f(s, t))(sig) for f in (G.theta, G.omega, G.fundamental_amplitude))
    return u, truth


def _fll_samples(cols, n, dtype):
    """The FLL workload's waveform and truth (θ, ω, V), sampled (B, n) by jaxobs's own signal in the working dtype."""
    return _fll_samples_jit(grid_signal_batch(cols, dtype), n, jnp.dtype(dtype))


def fll_samples(batch: int, n: int, dtype) -> tuple[np.ndarray, np.ndarray]:
    """The baselines' precomputed inputs (B, n): the waveform and true ω that jaxobs's precomputed rows read."""
    u, (_, om, _) = _fll_samples(fll_scenarios(batch), n, dtype)
    return np.asarray(u), np.asarray(om)


def fll_baseline_params(kind: str) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(gains P, initial state x0) of the workload's FLL as benchmarks.kernels takes them (float64).

    P = (k, lam, v_floor², 0, 0) for the SOGI-FLL, (k1, k2, lam, v_floor², 0) for the WPF and WIF;
    x0 = zeros with ω = omega_n last (3 states for the SOGI-FLL, 5 for the others).
    """
    obs = fll_observer(kind)
    vf2 = float(obs.v_floor * obs.v_floor)
    if kind == "sogi-fll":
        p, S = (float(obs.k), float(obs.lam), vf2, 0.0, 0.0), 3
    else:
        p, S = (float(obs.k1), float(obs.k2), float(obs.lam), vf2, 0.0), 5
    return p, (0.0,) * (S - 1) + (float(obs.omega_n),)


# ---------------------------------------------------------------------------
# drive
# ---------------------------------------------------------------------------


def drive_setup(batch: int):
    """(drive, observer, batched scenarios, per-scenario speed refs in rad/s) of the drive workload."""
    par = D.bench_machine("spmsm000")
    drive = D.bench_drive(par, handover=0.05)
    obs = jaxobs.SecondOrderSOIFO(
        par.Rs, par.Ld, K1, K2, second_order_soifo_lambda(K1, K2), omega_init=par.p * 1000 * D.RPM
    )
    rpm = np.linspace(500.0, 2000.0, batch) if batch > 1 else np.array([1000.0])
    base = D.Scenario(par, load=D.Profile([0.0, 0.1], [0.0, 5.0], kind="step"), omega_m0=1000 * D.RPM, dead_time=2e-6)
    sc = jax.tree.map(lambda x: jnp.broadcast_to(x, (batch,) + jnp.shape(x)), base)
    w = jnp.asarray(rpm * D.RPM, jnp.result_type(float))
    sc = eqx.tree_at(lambda s: s.speed_ref.values, sc, w[:, None])
    sc = eqx.tree_at(lambda s: s.omega_m0, sc, w)
    return drive, obs, sc, rpm * D.RPM


def drive_cost(s):
    """Running cost wrap(θ̂ − θ)² of one step's :class:`jaxobs.drive.DriveOutput`."""
    d = wrap(s.obs.theta - s.theta_e)
    return d * d


def jax_drive(batch: int, t1: float = DRIVE_T1, shard: bool = True, tile=None):
    """(jitted function, its batch argument): per-scenario running costs of the drive workload.

    The closed loop evaluates its speed and load profiles inside its step (jaxobs.drive.loop), so the
    drive has one input mode ("loop").
    """
    drive, obs, sc, _ = drive_setup(batch)

    def one(s):
        return jaxobs.simulate(D.ClosedLoop(drive, obs, s), t1, save=jaxobs.SaveFinal(cost=drive_cost)).cost

    return _batched(one, shard, tile=tile), (jaxobs.shard_batch(sc) if shard else sc)


def drive_initial(batch: int):
    """The drive workload's initial states as the baselines take them: plant (batch, 4), observer (batch, 9) and
    (batch, 11) = (u_α, u_β, int_d, int_q, int_w, i_q held, i_prev α, β, u_prev α, β, started), from jaxobs's
    steady start (``ClosedLoop.init``: the operating point and the observer's settling phase)."""
    drive, obs, sc, _ = drive_setup(batch)
    st = jax.jit(jax.vmap(lambda s: D.ClosedLoop(drive, obs, s).init()))(sc)
    o, c = st.obs, st.ctrl
    rest = jnp.stack(
        [
            st.u_a,
            st.u_b,
            c.int_d,
            c.int_q,
            c.int_w,
            c.iq_ref,
            o.i_prev[:, 0],
            o.i_prev[:, 1],
            o.u_prev[:, 0],
            o.u_prev[:, 1],
            o.started.astype(st.u_a.dtype),
        ],
        axis=1,
    )
    return np.asarray(st.plant.x), np.asarray(o.x), np.asarray(rest)


def drive_baseline_params():
    """(M, OB, C, P, speed_every) of the drive workload as benchmarks.kernels.drive_run takes them (floats)."""
    drive, obs, _, _ = drive_setup(1)
    par = D.bench_machine("spmsm000")
    foc, inv = drive.foc, drive.inverter
    du = float(inv.udc) * 2e-6 * float(inv.f_pwm)
    M = (par.Rs, par.Ld, par.Lq, par.psi_f, par.J, par.B, par.p, par.a5, par.a7, du)
    OB = (obs.Rs, obs.L, obs.K1, obs.K2, obs.lam, obs.v_floor**2, obs.omega_min)
    C = (
        foc.kp_d,
        foc.ki_d,
        foc.kp_q,
        foc.ki_q,
        foc.kp_w,
        foc.ki_w,
        foc.i_max,
        par.Ld,
        par.Lq,
        par.psi_f,
        foc.setpoint_weight,
    )
    P = (inv.u_max, drive.handover, TS * foc.speed_every, 0.1, 5.0)
    M, OB, C, P = (tuple(float(v) for v in t) for t in (M, OB, C, P))
    return M, OB, C, P, int(foc.speed_every)


# ---------------------------------------------------------------------------
# gradients
# ---------------------------------------------------------------------------


CHECKPOINTS = {
    "auto": jaxobs.AutoCheckpoint(),
    "none": jaxobs.NoCheckpoint(),
    "step": jaxobs.StepCheckpoint(),
    "chunk": jaxobs.ChunkCheckpoint(),
    "forward": jaxobs.ForwardSensitivity(),
}


def fll_loss_fn(kind: str, t1: float, checkpoint: str, names: tuple[str, ...] | None = None):
    """(loss(gains, signals) → mean running cost over the batch, the observer's tuned gains) for the FLL workload.

    ``names``: the gains differentiated (default the tuned ones, :data:`GAINS`); ``omega_n`` also sets the
    initial state."""
    obs = fll_observer(kind)
    names = GAINS[kind] if names is None else tuple(names)
    params = {n: getattr(obs, n) for n in names}

    def loss(params, sig):
        o = eqx.tree_at(lambda m: tuple(getattr(m, n) for n in names), obs, tuple(params[n] for n in names))

        def one(s):
            save = jaxobs.SaveFinal(cost=fll_cost)
            return jaxobs.simulate(jaxobs.OnSignal(o, s), t1, save=save, checkpoint=CHECKPOINTS[checkpoint]).cost

        return jnp.mean(jax.vmap(one)(sig))

    return loss, params


def fll_signal_batch(batch: int, shard: bool = True):
    """The FLL workload's signals (batched GridSignal) in the working dtype, sharded over the devices."""
    sig = grid_signal_batch(fll_scenarios(batch), jnp.result_type(float))
    return jaxobs.shard_batch(sig) if shard else sig


def grad_temp_mb(kind: str = "sogi-fll", batch: int = 1024, t1: float = 10.0, checkpoint="auto") -> float:
    """XLA's temporary-buffer size (MB) of value_and_grad over ``t1`` seconds at ``batch`` (compiled, not run)."""
    loss, params = fll_loss_fn(kind, t1, checkpoint)
    sig = fll_signal_batch(batch, shard=False)
    compiled = jax.jit(jax.value_and_grad(loss)).lower(params, sig).compile()
    return compiled.memory_analysis().temp_size_in_bytes / 1e6


# ---------------------------------------------------------------------------
# the same step hand-written in JAX: what XLA's CPU backend makes of the minimal program
# ---------------------------------------------------------------------------


def _fll_field(kind: str, obs):
    """The FLL's vector field on state rows (the last one ω̂) — the formulas of jaxobs's ``f`` and of
    benchmarks.kernels.fll (f_sogifll, f_wpf, f_wif with fll_error="input")."""
    vf2 = obs.v_floor * obs.v_floor
    if kind == "sogi-fll":
        k, lam = obs.k, obs.lam

        def f(y, q, w, u):
            e = u - y
            return w * (k * e - q), w * y, -lam * e * q / jnp.maximum(y * y + q * q, vf2)

    elif kind == "sogi-fll-wpf":
        k1, k2, lam = obs.k1, obs.k2, obs.lam

        def f(p, qp, y, q, w, u):
            return (
                w * (k1 * (u - p) - qp),
                w * p,
                w * (k2 * (p - y) - q),
                w * y,
                -lam * (p - y) * q / jnp.maximum(y * y + q * q, vf2),
            )

    elif kind == "sogi-fll-wif":
        k1, k2, lam = obs.k1, obs.k2, obs.lam

        def f(za, zb, y, q, w, u):
            return (
                w * (k1 * (k2 * (u - y) - za) - zb),
                w * za,
                w * (za - q),
                w * y,
                -(lam / k2) * za * q / jnp.maximum(y * y + q * q, vf2),
            )

    else:
        raise ValueError(f"FLL workload must be one of {FLL_KINDS}, got {kind!r}")
    return f


def fll_tuple_step(kind: str, obs, h):
    """jax-hand's steady AB3 step on state rows: ``step((x, f1, f2, acc), (u, ω)) -> (carry, None)`` with x, f1,
    f2 tuples of the state's rows (ω̂ last) and acc the running sum of (ω̂ − ω)² (the output at t_k is the state
    before the update, as in jaxobs.AbstractObserver.step)."""
    f = _fll_field(kind, obs)

    def step(c, row):
        x, f1, f2, acc = c
        uu, ww = row
        d = x[-1] - ww
        f0 = f(*x, uu)
        x = tuple(xi + (h / 12) * (23 * a - 16 * b + 5 * cc) for xi, a, b, cc in zip(x, f0, f1, f2))
        return (x, f0, f1, acc + d * d), None

    return step


def jax_hand_fll(batch: int, t1: float = FLL_T1, kind: str = "sogi-fll"):
    """(jitted function, its arguments): the precomputed FLL workload hand-written in JAX as a performance
    engineer would write it for XLA — the inputs time-major (n, B), every state component and AB3 history entry
    its own (B,) row, one plain ``lax.scan`` over time with the batch the inner dimension, the batch split over
    the host devices with ``shard_map`` along it, each device running its whole share.

    It computes the workload's costs exactly (tests/test_perf.py: equal to jaxobs to 1e-10 in float64):
    the two RK4 start-up steps of jaxobs's AB3 are taken by jaxobs itself, before the timed call (they are 2 of
    10 000 steps), and the kernel runs the remaining steady AB3 steps from that state.  Its row tells how much of
    the distance to the numba kernels is jaxobs's generic loop and how much is XLA's CPU code generation.
    """
    from jax.sharding import NamedSharding
    from jax.sharding import PartitionSpec as P

    dtype = jnp.result_type(float)
    obs = fll_observer(kind)
    n = round(t1 / TS)
    u, truth = _fll_samples(fll_scenarios(batch), n, dtype)
    sig = jax.vmap(lambda u, th, om, a: jaxobs.SampledSignal(u, TS, truth=(th, om, a)))(u, *truth)

    @jax.jit
    def start(sig):
        def one(s):
            sol = jaxobs.simulate(jaxobs.OnSignal(obs, s), 2 * TS, save=jaxobs.SaveFinal(cost=fll_cost))
            return sol.final_state.x, sol.final_state.rule.f1, sol.final_state.rule.f2, sol.cost / TS

        return jax.vmap(one)(sig)

    x, f1, f2, acc = start(sig)
    S = x.shape[1]  # state components: 3 for the SOGI-FLL, 5 for the WPF and the WIF
    h = jnp.asarray(TS, dtype)
    step = fll_tuple_step(kind, obs, h)

    def kernel(x, f1, f2, acc, U, OM):
        (_, _, _, acc), _ = jax.lax.scan(step, (x, f1, f2, acc), (U, OM))
        return h * acc

    rows = lambda a: tuple(a.T)  # noqa: E731  (B, S) -> S (B,) rows
    devs = jax.devices()
    mesh = jaxobs.batch_mesh(devs if batch % len(devs) == 0 else devs[:1])  # as shard_batch: uneven runs whole
    spec_b, spec_tb = P("batch"), P(None, "batch")
    fn = jax.jit(
        jax.shard_map(
            kernel,
            mesh=mesh,
            in_specs=((spec_b,) * S, (spec_b,) * S, (spec_b,) * S, spec_b, spec_tb, spec_tb),
            out_specs=spec_b,
            check_vma=False,
        )
    )
    put = lambda a, spec: jax.device_put(a, NamedSharding(mesh, spec))  # noqa: E731
    args = (
        tuple(put(a, spec_b) for a in rows(x)),
        tuple(put(a, spec_b) for a in rows(f1)),
        tuple(put(a, spec_b) for a in rows(f2)),
        put(acc, spec_b),
        put(jnp.asarray(u.T[2:]), spec_tb),
        put(jnp.asarray(truth[1].T[2:]), spec_tb),
    )
    return fn, args
