"""The golden vectors: the test records an export is checked on (:func:`fll_test_signal`, a drive
observer's :func:`drive_recording` in a sensored FOC drive or the synthesized :func:`drive_test_signal`)
and the float32 JAX step's outputs on them (:func:`golden_outputs`)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxobs import DriveInput
from jaxobs.observers import (
    SOGIFLL,
    SOGIFLLWIF,
    SOGIFLLWPF,
    SOIFO,
    AbstractDriveObserver,
    AbstractFluxObserver,
    AbstractLESO,
    AbstractObserver,
    AbstractVectorFieldObserver,
    LPFFlux,
    PureIntegratorFlux,
    ReducedOrderFluxObserver,
    SecondOrderSOIFO,
)

from .codegen import CStep

# a drive record's first-period shapes (drive_test_signal) and what each adds to the record's description
_STARTS = {"": "", "flux": ", first period carries psi(0)/ts", "alpha": ", first period on alpha only",
           "aligned": ", rotor at theta = 0 where the observer's angle starts"}  # fmt: skip

if TYPE_CHECKING:
    from jaxobs.core.discretize import AbstractRule
    from jaxobs.drive import Drive, PMSMParams

_O = TypeVar("_O", bound=AbstractObserver)  # an observer, returned as the same class

MIN_STEPS = 10_000  # the golden record is at least this long
MAX_STEPS = 2_000_000  # and at most this long (golden.csv about 100 MB)


def fll_test_signal(ts: float, n_steps: int, f0: float = 50.0, amplitude: float = 1.0) -> tuple[np.ndarray, str]:
    """Unit sine at ``f0`` with a +2 Hz step at n/3 and a +40° phase jump at 2n/3 (GridSignal's settle-then-disturb).

    Args:
        ts: The sample time, s.
        n_steps: The samples.
        f0: The frequency, Hz.
        amplitude: The amplitude.

    Returns:
        ``(samples as float32, shape (n_steps, 1), a one-line description)``.
    """
    t = np.arange(n_steps) * ts
    t1, t2 = (n_steps // 3) * ts, (2 * n_steps // 3) * ts
    theta = 2 * np.pi * f0 * t + np.where(t >= t1, 2 * np.pi * 2.0 * (t - t1), 0.0)
    theta = theta + np.where(t >= t2, np.radians(40.0), 0.0)
    v = (amplitude * np.cos(theta)).astype(np.float32)
    doc = f"{amplitude:g} cos at {f0:g} Hz, +2 Hz step at {t1:g} s, +40 deg phase jump at {t2:g} s, ts = {ts:g} s"
    return v[:, None], doc


def drive_test_signal(
    ts: float,
    n_steps: int,
    *,
    omega: float,
    Rs: float,
    L: float,
    psi: float = 0.1,
    current: float | None = None,
    start: str = "",
) -> tuple[np.ndarray, str]:
    """Sampled (u_α, u_β, i_α, i_β) of a surface PMSM turning at electrical speed ``omega``, with a +10 % speed
    step at n/3 and a +30° angle jump at 2n/3.

    θ(0) = π/2 (0 with ``start="aligned"``); i = I (−sin θ, cos θ) (q-axis current, I = min(5 A, ψ/(2L)) unless given),
    e = ω ψ (−sin θ, cos θ) (002 eq 5), u = R i + L di/dt + e.  ``u`` at sample k is the voltage applied
    over [t_k, t_k+1] (its period average: R i + e averaged over 8 midpoints, L Δi/ts exactly), as a drive
    observer expects; ``i`` is sampled at t_k.

    ``start`` shapes the first period so that the outputs are well conditioned from the first step
    (otherwise a float32 implementation other than XLA's own, bit for bit, cannot be held to 1e-4 there):

    - ``"flux"``: the first voltage sample also carries ψ(0)/ts, the flux the integrators cannot know
      (000's initial-value problem).  A pure integrator started at 0 estimates ψ(t) − ψ(0), which passes
      through 0 once per turn, where atan2 turns rounding into any angle;
    - ``"alpha"``: the first voltage and the first two current samples have no β component, so the first
      back EMF is on α only.  After a single back-EMF sample the two SOGIs of a SOIFO hold proportional
      states, the cross product whose sign gives the direction of rotation is 0 but for rounding, and
      the signed ω̂ is ±|ω̂| by chance; with a β-free first sample that product is exactly 0;
    - ``"aligned"``: the rotor starts at θ = 0, where an observer whose angle is its own state starts it
      (the reduced-order flux observer: θ̂ = 0).  From θ = π/2 its first 0.1 s are a large-signal search
      for the angle (ω̂ swinging through ±120 rad/s and through 0 several times, the flux estimate up to 3 ×
      ψf), a trajectory whose float32 rounding grows with every turn: on the 5.6-kW PM-SyRM's flux map
      (``docs/examples/pmsyrm_5p6kw_sat.toml``) the float32 JAX step itself ended 5.9e-4 from its float64 run
      where ω̂ crossed 0 (step 577), the C 4.9e-4 from the float32 golden, both against a 1e-4 tolerance that
      is absolute there; aligned, it tracks from the first sample.

    Args:
        ts: The sample time, s.
        n_steps: The samples.
        omega: The electrical speed, rad/s.
        Rs: The stator resistance, Ω.
        L: The inductance, H.
        psi: The rotor flux ψ, Wb.
        current: The q-axis current I, A (default min(5 A, ψ/(2L))).
        start: ``""``, ``"flux"``, ``"alpha"`` or ``"aligned"``, as above.

    Returns:
        ``(float32 array (n_steps, 4), a one-line description)``.
    """
    if start not in _STARTS:
        raise ValueError(f"drive_test_signal: start must be '', 'flux', 'alpha' or 'aligned', got {start!r}")
    th_start = 0.0 if start == "aligned" else np.pi / 2
    current = min(5.0, 0.5 * psi / L) if current is None else current
    t1, t2 = (n_steps // 3) * ts, (2 * n_steps // 3) * ts

    def theta(t):
        return (
            th_start
            + omega * t
            + np.where(t >= t1, 0.1 * omega * (t - t1), 0.0)
            + np.where(t >= t2, np.radians(30.0), 0.0)
        )

    def cur(t):
        th = theta(t)
        return current * np.stack([-np.sin(th), np.cos(th)], axis=-1)

    def emf(t):
        th = theta(t)
        w = omega * np.where(t >= t1, 1.1, 1.0)
        return (w * psi)[..., None] * np.stack([-np.sin(th), np.cos(th)], axis=-1)

    t = np.arange(n_steps + 1) * ts
    mid = t[:-1, None] + (np.arange(8) + 0.5) / 8 * ts
    u = np.mean(Rs * cur(mid) + emf(mid), axis=1) + L * (cur(t[1:]) - cur(t[:-1])) / ts
    i = cur(t[:-1])
    if start == "flux":
        th0 = theta(np.asarray(0.0))
        u[0] += psi * np.array([np.cos(th0), np.sin(th0)]) / ts
    elif start == "alpha":
        u[0, 1] = i[0, 1] = i[1, 1] = 0.0
    data = np.concatenate([u, i], axis=1).astype(np.float32)
    first = _STARTS[start]
    doc = (
        f"PMSM u/i at {omega / (2 * np.pi):g} Hz electrical (psi = {psi:g} Wb, I = {current:.3g} A, "
        f"Rs = {Rs:g} ohm, L = {L:g} H){first}, +10 % speed step at {t1:g} s, +30 deg angle jump at {t2:g} s, "
        f"ts = {ts:g} s"
    )
    return data, doc


# the bench (jaxobs.drive.bench_machine) a drive observer's recording runs on, its speed (r/min) and its name in
# the record's description, by family (the observer's abstract base)
_RECORDING_BENCH = {
    AbstractFluxObserver: ("spmsm000", 1000.0, "000 SPMSM"),  # 000's SPMSM, p = 3: 50 Hz
    AbstractLESO: ("ipmsm002", 300.0, "002 IPMSM"),  # 002's (assumed) IPMSM, p = 5: 25 Hz (see drive_recording)
    ReducedOrderFluxObserver: ("ipmsm002", 300.0, "002 IPMSM"),  # salient: it runs on the IPMSM (Ld and Lq)
}


def _bench_of(observer) -> tuple:
    for family, bench in _RECORDING_BENCH.items():
        if isinstance(observer, family):
            return bench
    raise ValueError(f"export: {type(observer).__name__} is not a drive observer (flux observer or LESO)")


def recording_bench(observer: AbstractDriveObserver) -> tuple[PMSMParams, float]:
    """The machine and the speed a drive observer's recording runs at.

    Args:
        observer: The drive observer.

    Returns:
        ``(machine, rpm)``: :func:`jaxobs.drive.bench_machine` (000's SPMSM for the flux observers, 002's IPMSM
        for the LESOs, on the drive jobs' bench inertia) and the speed, r/min.
    """
    from jaxobs.drive import bench_machine

    name, rpm, _ = _bench_of(observer)
    return bench_machine(name), rpm


class _Tap(AbstractObserver):
    """An "observer" that returns what it is fed: the measurements a ClosedLoop gives its observer.

    Attributes:
        ts: Sample time, s (the drive's).
    """

    ts: float = eqx.field(static=True)

    def init(self, u0=None):
        return None

    def step(self, state, u):
        return state, u


def drive_recording(
    observer: AbstractDriveObserver,
    n_steps: int = 12_000,
    *,
    machine: PMSMParams | None = None,
    rpm: float | None = None,
    load: tuple = (0.3, 0.8),
    speed_step: float = 0.1,
    start: str = "",
    encoder: bool = False,
    drive: Drive | None = None,
    label: str | None = None,
) -> tuple[np.ndarray, str]:
    """The (u_α, u_β, i_α, i_β) a drive observer is fed in a sensored FOC drive, ``n_steps`` samples at its ts.

    ``jaxobs.simulate(ClosedLoop(Drive(FOC.imc(machine, 2π·300, 2π·5)), _Tap(), scenario), t1)``: the
    encoder closes the loop, the sensors are ideal (no offsets, gain errors or noise, no dead time), and
    the drive starts in the steady state of ``rpm`` (default 1000 r/min on 000's SPMSM, 600 r/min on
    002's IPMSM: 50 Hz electrical) with ``load[0]``·T_rated.  The speed reference steps by
    ``speed_step`` (+10 %) at n/3, the load to ``load[1]``·T_rated at 2n/3.  The rows are the
    measurements the loop hands its observer at each sample (a tap observer returns them), so the
    voltage in row k is the one applied over [t_k, t_k+1] (the FOC computed it at t_k−1) and the
    current is sampled at t_k: the drive observers' contract.  With ideal sensors they equal the
    outputs' u_a, u_b, i_a, i_b.

    Export the observer bound to the same machine and speed (``observer.bind(machine, ω_e)``).

    The rotor starts at θe = π/2 (0 with ``start="aligned"``), where the q-axis current and the back EMF lie on
    −α, so the β components of the first samples are small.  ``start`` shapes the first period as
    :func:`drive_test_signal` does (the reasons are there): ``"flux"`` adds the rotor flux at t = 0,
    ψf (cos θe0, sin θe0), divided by ts to the first voltage (the pure integrator's initial value);
    ``"alpha"`` zeroes the β components of the first voltage and the first two currents (a few
    per cent of their amplitude at θe0 = π/2: 5 % of the voltage, the ω_e L i_q drop; 3 % of the current);
    ``"aligned"`` starts the rotor at θe0 = 0, where the reduced-order flux observer starts its own angle.

    Args:
        observer: The drive observer.
        n_steps: The samples, at the observer's ts.
        machine: A :class:`jaxobs.drive.PMSMParams` (default: the bench of the observer's family,
            :func:`jaxobs.drive.bench_machine`).
        rpm: The speed, r/min (default the bench's).
        load: The load before and after the step, × T_rated.
        speed_step: The speed reference's relative step.
        start: ``""``, ``"flux"``, ``"alpha"`` or ``"aligned"``, as above.
        encoder: Whether to append two columns, the true electrical angle θe (rad, wrapped) and speed ωe
            (rad/s) at t_k: what an encoder would record beside u and i (the shipped example recording,
            ``tuning/presets/recordings/``, is made this way).
        drive: The sensored :class:`jaxobs.drive.Drive` to record (a drive file's,
            :meth:`jaxobs.drive.DriveFile.drive_for`; its ts must be the observer's), default the benches'
            FOC on ``machine``.
        label: The drive's name in the description (default the bench's).

    Returns:
        ``(float32 array (n_steps, 4 or 6), a one-line description)``.
    """
    if start not in _STARTS:
        raise ValueError(f"drive_recording: start must be '', 'flux', 'alpha' or 'aligned', got {start!r}")
    import jaxobs
    from jaxobs import drive as D

    bench, bench_rpm = recording_bench(observer)
    machine = bench if machine is None else machine
    rpm = bench_rpm if rpm is None else float(rpm)
    if not (isinstance(n_steps, int) and n_steps >= 2):
        raise ValueError(f"drive_recording: n_steps must be an integer >= 2, got {n_steps!r}")
    ts = float(observer.ts)
    t1, t2 = (n_steps // 3) * ts, (2 * n_steps // 3) * ts
    t_rated = float(machine.T_rated)
    scenario = D.Scenario(
        machine,
        speed_ref=D.Scenario.speed_rpm([0.0, t1], [rpm, (1 + speed_step) * rpm]),
        load=D.Scenario.load_steps([0.0, t2], [load[0] * t_rated, load[1] * t_rated]),
        omega_m0=rpm * D.RPM,
        theta_e0=0.0 if start == "aligned" else math.pi / 2,
    )
    if drive is None:
        drive = D.bench_drive(machine, sensorless=False, settle=0.0, ts=ts)  # the encoder closes the loop
    elif drive.sensorless or abs(float(drive.ts) - ts) > 1e-12 * ts:
        raise ValueError(
            f"drive_recording: the drive must be sensored and run at the observer's ts = {ts:g} s, got "
            f"{'sensorless' if drive.sensorless else 'sensored'} at {float(drive.ts):g} s"
        )
    sol = jaxobs.simulate(D.ClosedLoop(drive, _Tap(ts), scenario), n_steps * ts)
    m = sol.outputs.obs
    data = np.stack([np.asarray(m.u_a), np.asarray(m.u_b), np.asarray(m.i_a), np.asarray(m.i_b)], axis=1)
    data = data[:n_steps].astype(np.float64)
    if start == "flux":
        th0 = float(np.asarray(sol.outputs.theta_e)[0])
        data[0, :2] += float(machine.psi_f) * np.array([math.cos(th0), math.sin(th0)]) / ts
    elif start == "alpha":
        data[0, 1] = data[0, 3] = data[1, 3] = 0.0
    if encoder:
        th = np.asarray(sol.outputs.theta_e, dtype=np.float64)[:n_steps]
        we_true = np.asarray(sol.outputs.omega_m, dtype=np.float64)[:n_steps] * int(machine.p)
        data = np.concatenate([data, th[:, None], we_true[:, None]], axis=1)
    if data.shape[0] != n_steps or not np.all(np.isfinite(data)):
        raise ValueError(f"drive_recording: the drive gave {data.shape[0]} finite rows of {n_steps}")
    we = rpm * math.pi / 30 * int(machine.p)
    doc = (
        f"sensored FOC drive ({_bench_of(observer)[2] if label is None else label}: Rs = {float(machine.Rs):g} ohm, "
        f"Ld = {float(machine.Ld):g} H, Lq = {float(machine.Lq):g} H, psi = {float(machine.psi_f):g} Wb, "
        f"p = {int(machine.p)}), steady start at {rpm:g} r/min ({we / (2 * math.pi):g} Hz electrical) and "
        f"{load[0]:g} T_rated, speed reference {speed_step:+.0%} at {t1:g} s, load to {load[1]:g} T_rated at "
        f"{t2:g} s, ideal sensors, ts = {ts:g} s"
    )
    doc += _STARTS[start]
    return data.astype(np.float32), doc


def float32_observer(observer: _O) -> _O:
    """``observer`` with its floating-point array leaves (its gains) rounded to float32, as the C holds them.

    Args:
        observer: Any observer.

    Returns:
        The float32 observer.
    """
    return jax.tree.map(lambda a: a.astype(jnp.float32) if eqx.is_inexact_array(a) else a, observer)


def is_drive(observer: AbstractObserver) -> bool:
    """Whether ``observer`` is a drive observer: one that reads (u_a, u_b, i_a, i_b) each step; any other
    observer reads one sample v.

    Args:
        observer: Any observer.

    Returns:
        Whether it is an :class:`~jaxobs.observers.AbstractDriveObserver`.
    """
    return isinstance(observer, AbstractDriveObserver)


def zero_input(observer: AbstractObserver) -> DriveInput | jax.Array:
    """A zero input of ``observer``'s step in float32: four zero measurements for a drive observer, else one
    zero sample.

    Args:
        observer: Any observer.

    Returns:
        The input.
    """
    z = jnp.zeros((), jnp.float32)
    return DriveInput(z, z, z, z) if is_drive(observer) else z


@eqx.filter_jit
def _scan_outputs(observer, state0, u):
    # one compile per observer class and rule: the gains are traced leaves
    _, out = jax.lax.scan(lambda s, x: observer.step(s, x), state0, u)
    return out


def golden_outputs(obs32: AbstractObserver, state0: Any, step: CStep, u: np.ndarray) -> np.ndarray:
    """The float32 JAX step's outputs over the inputs ``u``: golden.csv's outputs, one row per step.

    Args:
        obs32: The float32 observer (:func:`float32_observer`).
        state0: Its initial state.
        step: Its generated step (the outputs' names and count).
        u: The inputs, shape (n, JX_NU).

    Returns:
        The outputs, shape (n, JX_NY), float32.

    Raises:
        ValueError: An output that is not float32.
    """
    # 64-bit types off: every number in the step is float32, as on the target (some rules, e.g.
    # diffrax's Euler, would otherwise promote a float32 state with a float64 step size)
    with jax.enable_x64(False):
        uj = jnp.asarray(u, jnp.float32)
        inputs = DriveInput(*(uj[:, k] for k in range(4))) if is_drive(obs32) else uj[:, 0]
        out = _scan_outputs(obs32, state0, inputs)
    cols = []
    for leaf in jax.tree.leaves(out):
        c = np.asarray(leaf)
        if c.dtype != np.float32:
            raise ValueError(f"export: the float32 JAX step returned an output as {c.dtype}")
        cols.append(c.reshape(c.shape[0], -1))
    y = np.concatenate(cols, axis=1)
    if y.shape[1] != len(step.output_names):
        raise AssertionError(f"export: {y.shape[1]} golden outputs for {len(step.output_names)} in the C")
    return y


# How a drive recording's first period is shaped (drive_test_signal explains why): the flux the
# integrators cannot know for a pure integrator or an LPF, a beta-free first back EMF for the SOIFOs,
# whose signed speed is otherwise the sign of a rounding error, the rotor where the reduced-order flux
# observer starts its own angle.  Any other observer: unshaped.
_RECORD_START = {PureIntegratorFlux: "flux", LPFFlux: "flux", SOIFO: "alpha", SecondOrderSOIFO: "alpha",
                 ReducedOrderFluxObserver: "aligned"}  # fmt: skip


def record_start(observer: AbstractObserver) -> str:
    """How the first period of a drive recording is shaped for ``observer`` (:func:`drive_test_signal`'s
    ``start``).

    Args:
        observer: Any observer.

    Returns:
        ``"flux"`` (a pure integrator or LPF), ``"alpha"`` (the SOIFOs), ``"aligned"`` (the reduced-order flux
        observer) or ``""``.
    """
    return _RECORD_START.get(type(observer), "")


def signal_frequency_hz(observer: AbstractObserver) -> float:
    """The frequency (Hz) of a signal observer's test record: an FLL's nominal frequency (001: the grid's,
    ``omega_n``), else 50 Hz (a SOGI has no nominal frequency of its own).

    Args:
        observer: A signal observer.

    Returns:
        The frequency, Hz.
    """
    if isinstance(observer, (SOGIFLL, SOGIFLLWPF, SOGIFLLWIF)):
        return float(observer.omega_n) / (2 * math.pi)
    return 50.0


def observer_rule(observer: AbstractObserver) -> AbstractRule | None:
    """The observer's discretization rule, or None for an observer that integrates in its own step (a bank, a
    user's drive observer): every vector-field observer, flux observer and LESO declares one.

    Args:
        observer: Any observer.

    Returns:
        Its rule, or None.
    """
    if isinstance(observer, (AbstractVectorFieldObserver, AbstractFluxObserver, AbstractLESO)):
        return observer.rule
    return None


def signal_speed(observer: AbstractDriveObserver) -> float:
    """The electrical speed (rad/s) of a drive observer's synthetic record: its initial speed (the last of its
    bound fields), else 50 Hz.

    Args:
        observer: The drive observer.

    Returns:
        The electrical speed, rad/s.

    Raises:
        ValueError: An observer without an initial speed field (a bank).
    """
    speed = type(observer).bound_fields.speed
    if speed is None:
        raise ValueError(f"export: {type(observer).__name__} has no initial speed field: give the test signal")
    w = float(getattr(observer, speed))
    return w if w > 0 else 2 * math.pi * 50.0


def assumed_machine(obs: AbstractDriveObserver) -> tuple[float, float]:
    """(R̂s, L̂) the drive observer assumes: the golden signal's machine.

    Args:
        obs: The drive observer.

    Returns:
        ``(R̂s, L̂)``.

    Raises:
        ValueError: An observer that assumes no machine (a bank).
    """
    bound = type(obs).bound_fields
    if bound.resistance is None or bound.inductance is None:
        raise ValueError(f"export: {type(obs).__name__} assumes no machine (R̂s, L̂): give the test signal")
    return float(getattr(obs, bound.resistance)), float(getattr(obs, bound.inductance))
