"""Permanent-magnet synchronous machine: parameters and the plant vector field (the papers' machines are the
shipped drive files', :func:`jaxobs.drive.spmsm_paper000` and :func:`jaxobs.drive.ipmsm_paper002`).

Frames and scaling (motulator's conventions): space vectors are complex,
x_ab = x_α + j x_β (stationary) and x_dq = x_ab e^{−jθe} (rotor), amplitude
invariant (peak phase quantities), so power is P = (3/2) Re(u i*) and torque
Te = (3/2) p Im(ψ* i) style expressions carry the 3/2.  Angles are electrical
(θe = p θm); ``omega_m`` is the mechanical speed in rad/s.

Plant, integrated in the rotor frame (the currents are smooth there):

    Ld di_d/dt = u_d − Rs i_d + ωe Lq i_q − e_d
    Lq di_q/dt = u_q − Rs i_q − ωe Ld i_d − e_q
    J dωm/dt   = Te − TL − B ωm,       dθe/dt = p ωm

with the PM back EMF, fundamental plus a negative-sequence 5th and a
positive-sequence 7th harmonic in the stationary frame (relative amplitudes
a5, a7 of the fundamental EMF):

    e_ab = j ωe ψf (e^{jθe} + a5 e^{−j5θe} + a7 e^{j7θe})
    e_dq = j ωe ψf (1 + a5 e^{−j6θe} + a7 e^{j6θe})

(002 eq 5 is the fundamental: e_ab = ωe ψf [−sin θe, cos θe]).  Torque from the
power balance, Te·ωm = (3/2) Re(e_dq i_dq*) + reluctance term:

    Te = (3/2) p [ψf Re(j(1 + a5 e^{−j6θe} + a7 e^{j6θe}) i_dq*) + (Ld − Lq) i_d i_q].

Optional q-axis saturation (``PMSMParams(q_sat=QSaturation(i_sat, n))``, off by default; no
cross-saturation): the q flux ψq = Lq(i_q) i_q with the apparent inductance

    Lq(i_q) = Lq / (1 + (|i_q|/i_sat)^n)^(1/n)

so ψq rises monotonically and levels off at Lq·i_sat.  The q equation then carries the incremental
inductance dψq/di_q = Lq / (1 + (|i_q|/i_sat)^n)^(1 + 1/n) (always > 0, so the plant stays well posed at any
current), the d equation's ωe ψq and the torque's reluctance term the apparent one; with ψq a function of
i_q alone the co-energy torque is (3/2) p (ψd i_q − ψq i_d), the formula above with Lq(i_q).  ``Lq`` stays the
unsaturated (small-current) value, the one an observer or FOC tuned on nameplate data assumes.

Saturation with cross-saturation (``PMSMParams(sat=AlgebraicSaturation(...))``, :mod:`jaxobs.drive.saturation`,
off by default): the machine's currents are the map i(ψ) of its flux linkages, and the plant's state is then
x = [ψd, ψq, ωm, θe] (:func:`plant_vf`), integrated as

    dψ_dq/dt = u_dq − Rs i(ψ) − jωe ψ − e_h,    e_h = jωe ψf (a5 e^{−j6θe} + a7 e^{j6θe})

(the PM's fundamental flux is inside the map's ψd; the harmonics, if declared, add their EMF), with the
co-energy torque Te = (3/2) p [Im(ψ* i) + ψf Re(j (h − 1) i*)].  ``Ld``, ``Lq`` and ``psi_f`` stay the nominal
constants a controller or observer assumes; the plant uses the map alone.  ``q_sat`` and ``sat`` are exclusive.
A map given as tables (``sat=FluxTable(...)``: ψ(i) interpolated bicubically) keeps the state in currents,
di/dt = L(i)⁻¹ (u − Rs i − jωe ψ(i) − e_h) with L = ∂ψ/∂i the interpolant's incremental inductance matrix: the
table gives ψ and L explicitly, so either way the vector field needs no inversion.
"""

from __future__ import annotations

import math
import numbers

import equinox as eqx
import jax
import jax.numpy as jnp

from ..core.trig import sincos
from ..core.validate import check_nonnegative, check_positive, check_real
from .saturation import AlgebraicSaturation, FluxTable

__all__ = [
    "PMSMParams",
    "QSaturation",
    "psi_f_from_ke",
    "psi_f_from_kt",
    "lq_apparent",
    "lq_incremental",
    "plant_vf",
    "torque",
    "bemf_dq",
    "bemf_ab",
    "state_currents",
    "mapped_torque",
]


class QSaturation(eqx.Module):
    """q-axis saturation Lq(i_q) = Lq / (1 + (|i_q|/i_sat)^n)^(1/n) (module doc).

    Both arguments are leaves: differentiable.  E.g. ``QSaturation.at(0.8, i_rated)``: Lq down 20 % at the
    rated current.

    Args:
        i_sat: The current at which the apparent Lq has fallen to 2^(−1/n) of its small-current value
            (A, peak, > 0).
        n: The knee's sharpness, in [1, 16].

    Raises:
        ValueError: A value out of its range.
    """

    i_sat: jax.Array  # A (> 0)
    n: jax.Array  # 1 (>= 1)

    def __init__(self, i_sat, n=2.0):
        own = "QSaturation"
        self.i_sat = check_positive("i_sat", i_sat, own)
        self.n = check_real("n", n, lower=1.0, lower_open=False, upper=16.0, owner=own)

    @classmethod
    def at(cls, ratio: float, i_q: float, n: float = 2.0) -> QSaturation:
        """The saturation whose apparent Lq is ``ratio`` of the small-current one at ``i_q``.

        Args:
            ratio: The apparent Lq at ``i_q`` over the small-current one, in (0, 1).
            i_q: The current, A (peak).
            n: The knee's sharpness, in [1, 16].

        Returns:
            The :class:`QSaturation`.
        """
        ratio, i_q, n = float(ratio), float(i_q), float(n)
        if not 0.0 < ratio < 1.0:
            raise ValueError(f"QSaturation.at: ratio must be in (0, 1), got {ratio}")
        if not i_q > 0.0:
            raise ValueError(f"QSaturation.at: i_q must be > 0 A, got {i_q}")
        return cls(i_q / (ratio**-n - 1.0) ** (1.0 / n), n)

    def factor(self, i_q: jax.Array | float) -> jax.Array:
        """The saturation's factor.

        Args:
            i_q: The q-axis current, A.

        Returns:
            (1 + (|i_q|/i_sat)^n) as an array (1 at i_q = 0).
        """
        return 1.0 + (jnp.abs(i_q) / self.i_sat) ** self.n


def lq_apparent(par: PMSMParams, i_q: jax.Array | float) -> jax.Array:
    """The apparent q-axis inductance ψq / i_q.

    Args:
        par: The machine.
        i_q: The q-axis current, A.

    Returns:
        ψq / i_q, H: ``par.Lq`` without saturation (exactly, not a limit), else Lq / factor^(1/n).
    """
    if par.q_sat is None:
        return par.Lq
    return par.Lq * par.q_sat.factor(i_q) ** (-1.0 / par.q_sat.n)


def lq_incremental(par: PMSMParams, i_q: jax.Array | float) -> jax.Array:
    """The incremental q-axis inductance dψq / di_q.

    Args:
        par: The machine.
        i_q: The q-axis current, A.

    Returns:
        dψq / di_q, H: ``par.Lq`` without saturation, else Lq / factor^(1 + 1/n).
    """
    if par.q_sat is None:
        return par.Lq
    return par.Lq * par.q_sat.factor(i_q) ** (-1.0 - 1.0 / par.q_sat.n)


class PMSMParams(eqx.Module):
    """Machine parameters (SI).  ``p`` is static: it is a structural integer, not a gain.

    Args:
        Rs: Stator resistance, Ω (≥ 0).
        Ld: d-axis inductance, H (> 0).
        Lq: q-axis inductance, H (> 0).
        psi_f: PM flux linkage (peak, amplitude invariant), Wb (> 0).
        J: Inertia, kg·m² (> 0).
        p: Pole pairs (a positive integer; static).
        B: Viscous friction, N·m·s/rad (≥ 0).
        a5: 5th-harmonic BEMF amplitude / fundamental (negative sequence), in [0, 1].
        a7: 7th-harmonic BEMF amplitude / fundamental (positive sequence), in [0, 1].
        T_rated: Rated torque, N·m (> 0).
        n_rated: Rated speed, r/min (> 0).
        q_sat: The q-axis saturation (:class:`QSaturation`), or ``None`` (linear, Lq constant; a None field
            adds no leaf, so a machine without it is the same pytree, and computes the same numbers, as one
            built without this field).
        sat: The saturation map with cross-saturation (:class:`~jaxobs.drive.saturation.AlgebraicSaturation`),
            or ``None`` (the default: no extra leaf, the plant's state in currents).  With it the plant's state
            is in flux linkages (module doc).

    Raises:
        ValueError: A value out of its range, naming the field.
    """

    Rs: jax.Array  # stator resistance, Ω (>= 0)
    Ld: jax.Array  # d-axis inductance, H (> 0)
    Lq: jax.Array  # q-axis inductance, H (> 0)
    psi_f: jax.Array  # PM flux linkage (peak, amplitude invariant), Wb (> 0)
    J: jax.Array  # inertia, kg·m² (> 0)
    B: jax.Array  # viscous friction, N·m·s/rad (>= 0)
    a5: jax.Array  # 5th-harmonic BEMF amplitude / fundamental (negative sequence)
    a7: jax.Array  # 7th-harmonic BEMF amplitude / fundamental (positive sequence)
    T_rated: jax.Array  # rated torque, N·m (> 0)
    n_rated: jax.Array  # rated speed, r/min (> 0)
    p: int = eqx.field(static=True)  # pole pairs
    # q-axis saturation of the machine (None: linear, Lq constant; a None field adds no leaf, so a machine
    # without it is the same pytree, and computes the same numbers, as one built without this field)
    q_sat: QSaturation | None = None
    # saturation map with cross-saturation (None: none, no leaf; else the plant's state is in flux linkages)
    sat: AlgebraicSaturation | FluxTable | None = None

    def __init__(self, Rs, Ld, Lq, psi_f, J, p, *, B=0.0, a5=0.0, a7=0.0, T_rated=1.0, n_rated=1000.0, q_sat=None,
                 sat=None):  # fmt: skip
        own = "PMSMParams"
        if q_sat is not None and not isinstance(q_sat, QSaturation):
            raise ValueError(f"{own}.q_sat must be a QSaturation or None, got {type(q_sat).__name__}")
        if sat is not None and not isinstance(sat, (AlgebraicSaturation, FluxTable)):
            raise ValueError(f"{own}.sat must be an AlgebraicSaturation, a FluxTable or None, got {type(sat).__name__}")
        if sat is not None and q_sat is not None:
            raise ValueError(f"{own}.sat: give either q_sat (q-axis only) or sat (the map), not both")
        self.q_sat = q_sat
        self.sat = sat
        self.Rs = check_nonnegative("Rs", Rs, own)
        self.Ld = check_positive("Ld", Ld, own)
        self.Lq = check_positive("Lq", Lq, own)
        self.psi_f = check_positive("psi_f", psi_f, own)
        self.J = check_positive("J", J, own)
        self.B = check_nonnegative("B", B, own)
        self.a5 = check_real("a5", a5, lower=0.0, lower_open=False, upper=1.0, owner=own)
        self.a7 = check_real("a7", a7, lower=0.0, lower_open=False, upper=1.0, owner=own)
        self.T_rated = check_positive("T_rated", T_rated, own)
        self.n_rated = check_positive("n_rated", n_rated, own)
        integral = isinstance(p, numbers.Integral) and not isinstance(p, bool)
        if not integral and isinstance(p, float) and math.isfinite(p) and p.is_integer():
            integral = True
        if not integral or int(p) < 1:
            raise ValueError(f"{own}.p (pole pairs) must be a positive integer, got {p!r}")
        self.p = int(p)

    @property
    def kt(self) -> jax.Array:
        """Torque constant at i_d = 0, N·m/A (peak current): (3/2) p ψf."""
        return 1.5 * self.p * self.psi_f

    @property
    def i_rated(self) -> jax.Array:
        """q-axis current for rated torque at i_d = 0, A (peak)."""
        return self.T_rated / self.kt

    def with_mismatch(
        self, dRs: jax.Array | float = 0.0, dL: jax.Array | float = 0.0, dpsi: jax.Array | float = 0.0
    ) -> PMSMParams:
        """A copy with relative errors — what an estimate assumes.

        Args:
            dRs: Relative error of Rs: Rs(1 + dRs).
            dL: Relative error of Ld and Lq: Ld, Lq (1 + dL).
            dpsi: Relative error of ψf: ψf (1 + dpsi).

        Returns:
            The :class:`PMSMParams` with the errors.
        """
        return eqx.tree_at(
            lambda m: (m.Rs, m.Ld, m.Lq, m.psi_f),
            self,
            (self.Rs * (1 + dRs), self.Ld * (1 + dL), self.Lq * (1 + dL), self.psi_f * (1 + dpsi)),
        )


def psi_f_from_ke(ke_v_per_krpm: float, p: int, *, line_peak: bool = False) -> tuple[float, str]:
    """ψf (Wb, peak phase flux, amplitude-invariant) from a datasheet's back-EMF constant.

    A datasheet gives Ke as the line-to-line voltage per 1000 r/min, rms (the usual) or peak.  The phase
    voltage's peak is ωe ψf with ωe = p · 2π · 1000/60 rad/s at 1000 r/min, and a line-to-line voltage is √3
    times the phase voltage, so ψf = Ke √2/√3 / ωe (rms) or Ke/√3 / ωe (peak).

    Args:
        ke_v_per_krpm: Ke, V per 1000 r/min, line to line (> 0).
        p: The pole pairs.
        line_peak: Ke is the line-to-line peak voltage (default: rms).

    Returns:
        ``(ψf, the rule as one line)``.

    Raises:
        ValueError: Ke or p out of range.
    """
    ke, p = float(ke_v_per_krpm), int(p)
    if not (math.isfinite(ke) and ke > 0.0) or p < 1:
        raise ValueError(f"psi_f_from_ke: Ke must be > 0 V/krpm and p >= 1, got {ke_v_per_krpm!r}, {p!r}")
    w_e = p * 2.0 * math.pi * 1000.0 / 60.0
    if line_peak:
        return ke / math.sqrt(3.0) / w_e, "Ke (V/krpm, line-to-line peak) / √3 / (p 2π 1000/60)"
    return ke * math.sqrt(2.0 / 3.0) / w_e, "Ke (V/krpm, line-to-line rms) × √2/√3 / (p 2π 1000/60)"


def psi_f_from_kt(kt_nm_per_a_rms: float, p: int) -> tuple[float, str]:
    """ψf (Wb, peak, amplitude-invariant) from a datasheet's torque constant Kt in N·m per A rms (phase).

    The magnet torque is T = 1.5 p ψf i_peak = 1.5 √2 p ψf I_rms, so ψf = Kt / (1.5 √2 p).  (A surface
    machine's Kt; on an IPMSM the datasheet's Kt may include reluctance torque at rated current, which this
    reading attributes to the magnet.)

    Args:
        kt_nm_per_a_rms: Kt, N·m/A rms (> 0).
        p: The pole pairs.

    Returns:
        ``(ψf, the rule as one line)``.

    Raises:
        ValueError: Kt or p out of range.
    """
    kt, p = float(kt_nm_per_a_rms), int(p)
    if not (math.isfinite(kt) and kt > 0.0) or p < 1:
        raise ValueError(f"psi_f_from_kt: Kt must be > 0 N·m/A and p >= 1, got {kt_nm_per_a_rms!r}, {p!r}")
    return kt / (1.5 * math.sqrt(2.0) * p), "Kt (N·m/A rms) / (1.5 √2 p)"


def _harmonic_factor(par: PMSMParams, sc):
    """1 + a5 e^{−j6θ} + a7 e^{j6θ} as (re, im), from ``sc`` = (sin θ, cos θ).

    e^{j6θ} = (e^{jθ})⁶ by two squarings and a product (e^{j2θ}, e^{j3θ}, e^{j6θ}): no second sine and
    cosine per angle.  Inside the plant's vector field XLA evaluates this once per state component it
    stacks, in scalar code (jaxobs.core.trig), where a polynomial sine costs several times these six products."""
    s, c = sc
    c2, s2 = c * c - s * s, 2.0 * s * c
    c3, s3 = c2 * c - s2 * s, s2 * c + c2 * s
    c6, s6 = c3 * c3 - s3 * s3, 2.0 * s3 * c3
    re = 1.0 + (par.a5 + par.a7) * c6
    im = (par.a7 - par.a5) * s6
    return re, im


def _bemf_dq(par: PMSMParams, omega_e, h):
    """e_dq = j ωe ψf h for the harmonic factor h = (re, im) of :func:`_harmonic_factor`."""
    re, im = h
    k = omega_e * par.psi_f
    return -k * im, k * re


def _torque(par: PMSMParams, i_d, i_q, h):
    """Torque (N·m) for the harmonic factor h = (re, im) of :func:`_harmonic_factor`."""
    re, im = h
    # Re(j h i*) with h = re + j im, i = i_d + j i_q:  j h = −im + j re;
    # Re((−im + j re)(i_d − j i_q)) = −im i_d + re i_q
    pm = par.psi_f * (re * i_q - im * i_d)
    return 1.5 * par.p * (pm + (par.Ld - lq_apparent(par, i_q)) * i_d * i_q)


def bemf_dq(par: PMSMParams, omega_e: jax.Array | float, theta_e: jax.Array | float) -> tuple[jax.Array, jax.Array]:
    """The back EMF in the rotor frame, e_dq = j ωe ψf (1 + a5 e^{−j6θ} + a7 e^{j6θ}).

    Args:
        par: The machine.
        omega_e: The electrical speed ωe, rad/s.
        theta_e: The electrical angle θe, rad.

    Returns:
        ``(e_d, e_q)``, V.
    """
    return _bemf_dq(par, omega_e, _harmonic_factor(par, sincos(theta_e)))


def bemf_ab(par: PMSMParams, omega_e: jax.Array | float, theta_e: jax.Array | float) -> tuple[jax.Array, jax.Array]:
    """The back EMF in the stationary frame, e_ab = e_dq e^{jθe}.

    Args:
        par: The machine.
        omega_e: The electrical speed ωe, rad/s.
        theta_e: The electrical angle θe, rad.

    Returns:
        ``(e_α, e_β)``, V.
    """
    ed, eq = bemf_dq(par, omega_e, theta_e)
    return dq_to_ab(ed, eq, theta_e)


def _torque_mapped(par: PMSMParams, psi_d, psi_q, i_d, i_q, h):
    """Torque (N·m) of a mapped machine: (3/2) p [ψd i_q − ψq i_d + ψf Re(j (h − 1) i*)] (module doc)."""
    re, im = h
    harm = par.psi_f * ((re - 1.0) * i_q - im * i_d)
    return 1.5 * par.p * (psi_d * i_q - psi_q * i_d + harm)


def state_currents(par: PMSMParams, x: jax.Array) -> tuple[jax.Array, jax.Array]:
    """The currents of a plant state (:func:`plant_vf`'s x).

    Args:
        par: The machine.
        x: The state: [i_d, i_q, ...], or [ψd, ψq, ...] where the machine has a map (``par.sat``).

    Returns:
        ``(i_d, i_q)``, A.
    """
    sat = par.sat
    if isinstance(sat, AlgebraicSaturation) and sat.state_is_flux:
        return sat.current(x[0], x[1])
    return x[0], x[1]


def mapped_torque(par: PMSMParams, x: jax.Array) -> jax.Array:
    """The torque of a mapped machine's plant state x = [ψd, ψq, ωm, θe].

    Args:
        par: The machine (``par.sat`` set).
        x: The state.

    Returns:
        The torque, N·m.
    """
    h = _harmonic_factor(par, sincos(x[3]))
    sat = par.sat
    if isinstance(sat, AlgebraicSaturation) and sat.state_is_flux:  # the state is the flux linkage
        i_d, i_q = sat.current(x[0], x[1])
        return _torque_mapped(par, x[0], x[1], i_d, i_q, h)
    assert sat is not None  # a mapped machine; a table: the state is the current
    return _torque_mapped(par, *sat.flux(x[0], x[1]), x[0], x[1], h)


def torque(par: PMSMParams, i_d: jax.Array | float, i_q: jax.Array | float, theta_e: jax.Array | float) -> jax.Array:
    """Electromagnetic torque (see module doc).

    Args:
        par: The machine.
        i_d: The d-axis current, A.
        i_q: The q-axis current, A.
        theta_e: The electrical angle θe, rad (the BEMF harmonics' torque ripple).

    Returns:
        The torque, N·m.
    """
    return _torque(par, i_d, i_q, _harmonic_factor(par, sincos(theta_e)))


def plant_vf(
    par: PMSMParams,
    x: jax.Array,
    u_ab: tuple[jax.Array, jax.Array],
    t_load: jax.Array | float,
    sc: tuple[jax.Array, jax.Array] | None = None,
) -> jax.Array:
    """The machine's vector field.

    Args:
        par: The machine.
        x: The state [i_d, i_q, ωm, θe]; [ψd, ψq, ωm, θe] where the machine has a map (``par.sat``).
        u_ab: The stationary-frame voltage ``(u_α, u_β)``, V.
        t_load: The load torque, N·m.
        sc: ``(sin θe, cos θe)`` when the caller has them already (:func:`jaxobs.drive.plant.plant_field`),
            else computed here.

    Returns:
        dx/dt.
    """
    w_m, th = x[2], x[3]
    w_e = par.p * w_m
    s, c = sincos(th) if sc is None else sc
    u_d, u_q = rotate(u_ab[0], u_ab[1], -s, c)
    h = _harmonic_factor(par, (s, c))  # one for both the BEMF and the torque
    if par.sat is not None and not par.sat.state_is_flux:  # a table ψ(i): the state is the current (module doc)
        i_d, i_q = x[0], x[1]
        psi_d, psi_q = par.sat.flux(i_d, i_q)
        ell = par.sat.inductance(i_d, i_q)
        re, im = h
        k = w_e * par.psi_f
        v_d = u_d - par.Rs * i_d + w_e * psi_q + k * im
        v_q = u_q - par.Rs * i_q - w_e * psi_d - k * (re - 1.0)
        det = ell[0, 0] * ell[1, 1] - ell[0, 1] * ell[1, 0]
        di_d = (ell[1, 1] * v_d - ell[0, 1] * v_q) / det
        di_q = (-ell[1, 0] * v_d + ell[0, 0] * v_q) / det
        te = _torque_mapped(par, psi_d, psi_q, i_d, i_q, h)
        dw = (te - t_load - par.B * w_m) / par.J
        return jnp.stack([di_d, di_q, dw, w_e])
    if isinstance(par.sat, AlgebraicSaturation):  # the state is the flux linkage (module doc)
        psi_d, psi_q = x[0], x[1]
        i_d, i_q = par.sat.current(psi_d, psi_q)
        re, im = h
        k = w_e * par.psi_f  # the harmonics' EMF, e_h = j ωe ψf (h − 1)
        dpsi_d = u_d - par.Rs * i_d + w_e * psi_q + k * im
        dpsi_q = u_q - par.Rs * i_q - w_e * psi_d - k * (re - 1.0)
        te = _torque_mapped(par, psi_d, psi_q, i_d, i_q, h)
        dw = (te - t_load - par.B * w_m) / par.J
        return jnp.stack([dpsi_d, dpsi_q, dw, w_e])
    i_d, i_q = x[0], x[1]
    e_d, e_q = _bemf_dq(par, w_e, h)
    di_d = (u_d - par.Rs * i_d + w_e * lq_apparent(par, i_q) * i_q - e_d) / par.Ld
    di_q = (u_q - par.Rs * i_q - w_e * par.Ld * i_d - e_q) / lq_incremental(par, i_q)
    te = _torque(par, i_d, i_q, h)
    dw = (te - t_load - par.B * w_m) / par.J
    return jnp.stack([di_d, di_q, dw, w_e])


def rotate(x: jax.Array | float, y: jax.Array | float, s: jax.Array, c: jax.Array) -> tuple[jax.Array, jax.Array]:
    """A vector rotated by the angle whose sine and cosine are given.

    Args:
        x: The first component.
        y: The second component.
        s: The angle's sine.
        c: The angle's cosine.

    Returns:
        (c x − s y, s x + c y).
    """
    return c * x - s * y, s * x + c * y


def dq_to_ab(d: jax.Array | float, q: jax.Array | float, theta: jax.Array | float) -> tuple[jax.Array, jax.Array]:
    """Inverse Park: the (α, β) of a rotor-frame (d, q).

    Args:
        d: The d component.
        q: The q component.
        theta: The electrical angle, rad.

    Returns:
        ``(α, β)``.
    """
    s, c = sincos(theta)
    return rotate(d, q, s, c)


def ab_to_dq(a: jax.Array | float, b: jax.Array | float, theta: jax.Array | float) -> tuple[jax.Array, jax.Array]:
    """Park: the (d, q) of a stationary (α, β).

    Args:
        a: The α component.
        b: The β component.
        theta: The electrical angle of the frame, rad.

    Returns:
        ``(d, q)``.
    """
    s, c = sincos(theta)
    return rotate(a, b, -s, c)


RPM = 2 * math.pi / 60.0  # r/min → rad/s
