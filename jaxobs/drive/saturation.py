"""Magnetic saturation with cross-saturation: an algebraic current map i(ψ) and what follows from it.

:class:`AlgebraicSaturation` is the saturation model motulator 0.18's ``SaturationModelSyRM`` and
``SaturationModelPMSyRM`` implement (``motulator/drive/utils/_sm_flux_maps.py``), written here from the
published equations:

- Hinkkanen, Pescetto, Mölsä, Saarakkala, Pellegrino, Bojoi, "Sensorless self-commissioning of synchronous
  reluctance motors at standstill without rotor locking," IEEE Trans. Ind. Appl. 53(3), 2017,
  doi:10.1109/TIA.2016.2644624 (the self- and cross-saturation current map, derived from a magnetic energy so
  that the incremental inductance matrix is symmetric):

      i_d = [a_d0 + a_dd |ψd|^S + a_dq/(V+2) |ψd|^U |ψq|^(V+2)] ψd
      i_q = [a_q0 + a_qq |ψq|^T + a_dq/(U+2) |ψd|^(U+2) |ψq|^V] ψq

- Lelli, Hinkkanen, Giulii Capponi, "A saturation model based on a simplified equivalent magnetic circuit for
  permanent magnet machines," Proc. ICEM 2024, doi:10.1109/ICEM60801.2024.10700403 (the PM as a Norton
  equivalent with a saturating rib/bridge reluctance in parallel), added to the above:

      ψb = ψd − ψn,   ψb,sat² = ψb² + k_q ψq²,   G_b = a_b ψb,sat^W / (1 + a_bp ψb,sat^W)
      i_d += G_b ψb,   i_q += k_q G_b ψq

  With a_b = 0 (the default) the machine is the synchronous reluctance machine of the first model.

Why a current map, and the plant's state.  The model gives the current as an explicit function of the flux
linkage.  A plant with such a machine is therefore integrated in the flux linkages, x = [ψd, ψq, ωm, θe]
(motulator's choice too, ``SynchronousMachine``): dψ/dt = u − Rs i(ψ) − jωe ψ, with no inversion and no matrix
solve inside the vector field; the currents are an algebraic output.  The inverse, the flux map ψ(i), is
needed only where a current is given (the plant's initial state, a drive check's inductances at an operating
point) and is found by Newton's method (:meth:`AlgebraicSaturation.flux`).

Smoothness.  |x|^e x is C¹ for e ≥ 0 and the bridge term is written in ψb,sat² (no square root at the
bridge's zero), so the vector field is continuously differentiable for every exponent ≥ 1 allowed here
(exponent 0 is the constant 1, handled statically: JAX's derivative of |x|^0 at 0 is NaN).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..core.validate import check_nonnegative, check_positive, check_real

__all__ = [
    "AlgebraicSaturation",
    "SAT_KEYS",
    "map_mtpa",
    "map_summary",
    "map_torque",
    "saturation_from_table",
    "check_inverse",
    "NOMINAL_RULES",
]

# the flux-map inversion's fixed Newton count: from the bounded start below, 40 steps reach the double-precision
# root on the 5.6-kW PM-SyRM from −3 to +3 times its rated current (tests/test_fluxmap.py checks it)
NEWTON_ITERS = 40


def _pow_abs(x, e: float):
    """|x|^e with e a static float; exactly 1 for e = 0 (no 0^0 and no NaN derivative)."""
    if e == 0.0:
        return jnp.ones_like(x)
    if float(e).is_integer() and e <= 8:
        ax = jnp.abs(x)
        out = ax
        for _ in range(int(e) - 1):
            out = out * ax
        return out
    return jnp.abs(x) ** e


class AlgebraicSaturation(eqx.Module):
    """The algebraic saturation model of Hinkkanen et al. 2017 with Lelli et al. 2024's PM bridge (module doc).

    Coefficients are leaves (differentiable); exponents are static (they pick the code, e.g. exponent 0).

    Args:
        a_d0: d-axis unsaturated inverse inductance, A/Vs (> 0).
        a_dd: d-axis self-saturation coefficient, A/Vs^(S+1) (≥ 0).
        S: d-axis self-saturation exponent, in [0, 12].
        a_q0: q-axis unsaturated inverse inductance, A/Vs (> 0).
        a_qq: q-axis self-saturation coefficient, A/Vs^(T+1) (≥ 0).
        T: q-axis self-saturation exponent, in [0, 12].
        a_dq: cross-saturation coefficient, A/Vs^(U+V+3) (≥ 0).
        U: cross-saturation exponent of ψd, in [0, 12].
        V: cross-saturation exponent of ψq, in [0, 12].
        psi_n: the PM's Norton flux, Vs (≥ 0).
        a_b: the bridge's inverse inductance coefficient, A/Vs^(W+1) (≥ 0; 0: no PM, a SyRM).
        a_bp: the bridge's saturation coefficient, 1/Vs^W (≥ 0).
        W: the bridge's exponent, in [2, 12] (≥ 2: smooth at the bridge's zero flux).
        k_q: the bridge flux's q-axis coupling, in [0, 1].

    Raises:
        ValueError: A value out of its range, naming the field.
    """

    a_d0: jax.Array
    a_dd: jax.Array
    a_q0: jax.Array
    a_qq: jax.Array
    a_dq: jax.Array
    psi_n: jax.Array
    a_b: jax.Array
    a_bp: jax.Array
    k_q: jax.Array
    state_is_flux = True  # the plant integrates the flux linkages with this map (module doc)
    S: float = eqx.field(static=True)
    T: float = eqx.field(static=True)
    U: float = eqx.field(static=True)
    V: float = eqx.field(static=True)
    W: float = eqx.field(static=True)

    def __init__(self, a_d0, a_dd, S, a_q0, a_qq, T, a_dq=0.0, U=1.0, V=0.0, *, psi_n=0.0, a_b=0.0, a_bp=0.0,
                 W=2.0, k_q=0.0):  # fmt: skip
        own = "AlgebraicSaturation"
        self.a_d0 = check_positive("a_d0", a_d0, own)
        self.a_dd = check_nonnegative("a_dd", a_dd, own)
        self.a_q0 = check_positive("a_q0", a_q0, own)
        self.a_qq = check_nonnegative("a_qq", a_qq, own)
        self.a_dq = check_nonnegative("a_dq", a_dq, own)
        self.psi_n = check_nonnegative("psi_n", psi_n, own)
        self.a_b = check_nonnegative("a_b", a_b, own)
        self.a_bp = check_nonnegative("a_bp", a_bp, own)
        self.k_q = check_real("k_q", k_q, lower=0.0, lower_open=False, upper=1.0, owner=own)
        for name, e, lo in (("S", S, 0.0), ("T", T, 0.0), ("U", U, 0.0), ("V", V, 0.0), ("W", W, 2.0)):
            e = float(check_real(name, e, lower=lo, lower_open=False, upper=12.0, owner=own))
            setattr(self, name, e)

    def current(self, psi_d: jax.Array | float, psi_q: jax.Array | float) -> tuple[jax.Array, jax.Array]:
        """The current map i(ψ) (module doc).

        Args:
            psi_d: The d-axis flux linkage, Vs.
            psi_q: The q-axis flux linkage, Vs.

        Returns:
            ``(i_d, i_q)``, A.
        """
        S, T, U, V = self.S, self.T, self.U, self.V
        ad, aq = _pow_abs(psi_d, 1.0), _pow_abs(psi_q, 1.0)
        g_d = self.a_d0 + self.a_dd * _pow_abs(psi_d, S) + self.a_dq / (V + 2) * _pow_abs(ad, U) * _pow_abs(aq, V + 2)
        g_q = self.a_q0 + self.a_qq * _pow_abs(psi_q, T) + self.a_dq / (U + 2) * _pow_abs(ad, U + 2) * _pow_abs(aq, V)
        i_d, i_q = g_d * psi_d, g_q * psi_q
        psi_b = psi_d - self.psi_n
        sat2 = psi_b * psi_b + self.k_q * psi_q * psi_q
        sw = sat2 if self.W == 2.0 else sat2 ** (0.5 * self.W)
        g_b = self.a_b * sw / (1.0 + self.a_bp * sw)
        return i_d + g_b * psi_b, i_q + self.k_q * g_b * psi_q

    def inverse_inductance(self, psi_d: jax.Array | float, psi_q: jax.Array | float) -> jax.Array:
        """The incremental inverse inductance matrix ∂i/∂ψ at ψ.

        Args:
            psi_d: The d-axis flux linkage, Vs.
            psi_q: The q-axis flux linkage, Vs.

        Returns:
            A (..., 2, 2) array [[∂i_d/∂ψd, ∂i_d/∂ψq], [∂i_q/∂ψd, ∂i_q/∂ψq]], 1/H.
        """

        def f(v):
            return jnp.stack(self.current(v[0], v[1]))

        jac = jnp.vectorize(jax.jacfwd(f), signature="(2)->(2,2)")
        return jac(jnp.stack(jnp.broadcast_arrays(psi_d, psi_q), axis=-1))

    def flux(self, i_d: jax.Array | float, i_q: jax.Array | float) -> tuple[jax.Array, jax.Array]:
        """The flux map ψ(i): the current map inverted by Newton's method.

        The start is the unsaturated guess (ψf + i_d/a_d0, i_q/a_q0) clipped to ±2 Vs, then :data:`NEWTON_ITERS`
        steps (the map is the gradient of a convex magnetic energy, so the root is unique; convergence is not
        proven for every coefficient set: a drive file's map is refused where the residual up to 3 times the
        rated current is not at rounding level, :func:`check_inverse`).  Gradients: the steps run on values only
        and one last Newton step carries the derivative, which at the converged root is the implicit function's,
        dψ = (∂i/∂ψ)⁻¹ (di − ∂i/∂θ dθ) (the standard way to differentiate a fixed point; no derivative is dropped).

        Args:
            i_d: The d-axis current, A.
            i_q: The q-axis current, A.

        Returns:
            ``(ψd, ψq)``, Vs.
        """
        i_d, i_q = jnp.broadcast_arrays(jnp.asarray(i_d, float), jnp.asarray(i_q, float))
        par = jax.lax.stop_gradient(self)
        psi_0 = par.no_load_flux()

        def step(m, pd, pq, t_d=i_d, t_q=i_q):
            fd, fq = m.current(pd, pq)
            g = m.inverse_inductance(pd, pq)
            rd, rq = fd - t_d, fq - t_q
            det = g[..., 0, 0] * g[..., 1, 1] - g[..., 0, 1] * g[..., 1, 0]
            dd = (g[..., 1, 1] * rd - g[..., 0, 1] * rq) / det
            dq = (-g[..., 1, 0] * rd + g[..., 0, 0] * rq) / det
            return pd - dd, pq - dq

        id_s, iq_s = jax.lax.stop_gradient(i_d), jax.lax.stop_gradient(i_q)
        pd = psi_0 + jnp.clip(id_s / par.a_d0, -2.0, 2.0)
        pq = jnp.clip(iq_s / par.a_q0, -2.0, 2.0)

        def body(_, c):
            c_d, c_q = c
            return step(par, c_d, c_q, id_s, iq_s)

        pd, pq = jax.lax.fori_loop(0, NEWTON_ITERS, body, (pd, pq))
        pd, pq = jax.lax.stop_gradient(pd), jax.lax.stop_gradient(pq)
        return step(self, pd, pq)  # the derivative-carrying step (docstring)

    def no_load_flux(self) -> jax.Array:
        """ψd at zero current: the root of i_d(ψd, 0) = 0 (bisection over [0, ψn]; 0 for a SyRM).

        With a_b > 0, i_d(ψd, 0) is monotonic in ψd, negative at 0 (the bridge's current −G_b ψn) and ≥ 0
        at ψn, so the root lies in [0, ψn].

        Returns:
            ψf, Vs (the PM flux the plant sees at no load).
        """
        lo, hi = jnp.zeros_like(self.psi_n), self.psi_n

        def body(_, c):
            lo_, hi_ = c
            mid = 0.5 * (lo_ + hi_)
            neg = self.current(mid, jnp.zeros_like(mid))[0] < 0.0
            return jnp.where(neg, mid, lo_), jnp.where(neg, hi_, mid)

        lo, hi = jax.lax.fori_loop(0, 80, body, (lo, hi))
        return 0.5 * (lo + hi)

    def inductance(self, i_d: jax.Array | float, i_q: jax.Array | float) -> jax.Array:
        """The incremental inductance matrix ∂ψ/∂i at the current i (the inverse of :meth:`inverse_inductance`).

        Args:
            i_d: The d-axis current, A.
            i_q: The q-axis current, A.

        Returns:
            A (..., 2, 2) array [[L_dd, L_dq], [L_qd, L_qq]], H.
        """
        pd, pq = self.flux(i_d, i_q)
        return jnp.linalg.inv(self.inverse_inductance(pd, pq))


# a drive file's [machine.saturation] keys (model = "algebraic"): name -> (lower, upper, lower open, unit)
SAT_KEYS = {
    "a_d0": (0.0, 1e6, True, "A/Vs"),
    "a_dd": (0.0, 1e9, False, "A/Vs^(S+1)"),
    "S": (0.0, 12.0, False, "1"),
    "a_q0": (0.0, 1e6, True, "A/Vs"),
    "a_qq": (0.0, 1e9, False, "A/Vs^(T+1)"),
    "T": (0.0, 12.0, False, "1"),
    "a_dq": (0.0, 1e9, False, "A/Vs^(U+V+3)"),
    "U": (0.0, 12.0, False, "1"),
    "V": (0.0, 12.0, False, "1"),
    "psi_n": (0.0, 100.0, False, "Vs"),
    "a_b": (0.0, 1e9, False, "A/Vs^(W+1)"),
    "a_bp": (0.0, 1e9, False, "1/Vs^W"),
    "W": (2.0, 12.0, False, "1"),
    "k_q": (0.0, 1.0, False, "1"),
}
_REQUIRED = ("a_d0", "a_dd", "S", "a_q0", "a_qq", "T")


_CURRENT_UNITS = {"A": 1.0, "kA": 1e3}
_FLUX_UNITS = {"Vs": 1.0, "Wb": 1.0, "mVs": 1e-3, "mWb": 1e-3}
_TABLE_KEYS = ("model", "nominal", "current_unit", "flux_unit", "csv", "i_d", "i_q", "psi_d", "psi_q")


def _table_map(tbl, base) -> FluxTable:
    """``model = "table"``: ψd, ψq over an (i_d, i_q) grid, inline or from a CSV file, in declared units."""
    own = "machine.saturation"
    for k in tbl:
        if k not in _TABLE_KEYS:
            raise ValueError(f'{own}.{k}: unknown key with model = "table"; allowed: {", ".join(_TABLE_KEYS)}')
    for k, units in (("current_unit", _CURRENT_UNITS), ("flux_unit", _FLUX_UNITS)):
        if k not in tbl:
            raise ValueError(f"{own}.{k}: missing (a table declares its units: one of {', '.join(units)})")
        if tbl[k] not in units:
            raise ValueError(f"{own}.{k} must be one of {', '.join(map(repr, units))}, got {tbl[k]!r}")
    ki, kf = _CURRENT_UNITS[tbl["current_unit"]], _FLUX_UNITS[tbl["flux_unit"]]
    inline = [k for k in ("i_d", "i_q", "psi_d", "psi_q") if k in tbl]
    if "csv" in tbl:
        if inline:
            raise ValueError(f"{own}.csv: give either csv or the inline tables ({', '.join(inline)}), not both")
        x, y, fd, fq = _read_csv(tbl["csv"], base)
    else:
        for k in ("i_d", "i_q", "psi_d", "psi_q"):
            if k not in tbl:
                raise ValueError(f'{own}.{k}: missing (model = "table" needs i_d, i_q, psi_d, psi_q, or csv)')
        try:
            x, y = np.asarray(tbl["i_d"], float), np.asarray(tbl["i_q"], float)
            fd, fq = np.asarray(tbl["psi_d"], float), np.asarray(tbl["psi_q"], float)
        except (TypeError, ValueError):
            raise ValueError(f"{own}: i_d, i_q must be lists of numbers and psi_d, psi_q lists of rows of numbers (one "
                             "row per i_d)") from None  # fmt: skip
    return FluxTable(x * ki, y * ki, fd * kf, fq * kf, owner=own)


def _read_csv(name, base):
    """A CSV flux map: a header with the columns i_d, i_q, psi_d, psi_q (any order), one row per grid node."""
    from pathlib import Path

    own = "machine.saturation.csv"
    if not isinstance(name, str):
        raise ValueError(f"{own} must be a file name (a string), got {type(name).__name__}")
    path = Path(name) if base is None or Path(name).is_absolute() else Path(base) / name
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise ValueError(f"{own}: cannot read {path} ({e.strerror})") from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    head = [h.strip() for h in lines[0].split(",")] if lines else []
    cols = ("i_d", "i_q", "psi_d", "psi_q")
    if sorted(head) != sorted(cols):
        raise ValueError(f"{own}: the header must name the columns i_d, i_q, psi_d, psi_q, got {', '.join(head)}")
    try:
        rows = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]], dtype=float)
    except ValueError:
        raise ValueError(f"{own}: every row must be {len(head)} numbers") from None
    if rows.ndim != 2 or rows.shape[1] != 4:
        raise ValueError(f"{own}: every row must be 4 numbers")
    c = {h: rows[:, j] for j, h in enumerate(head)}
    x, y = np.unique(c["i_d"]), np.unique(c["i_q"])
    if len(rows) != len(x) * len(y):
        raise ValueError(f"{own}: {len(rows)} rows for a {len(x)} × {len(y)} grid: every (i_d, i_q) node once")
    fd, fq = np.full((len(x), len(y)), np.nan), np.full((len(x), len(y)), np.nan)
    ix, iy = np.searchsorted(x, c["i_d"]), np.searchsorted(y, c["i_q"])
    fd[ix, iy], fq[ix, iy] = c["psi_d"], c["psi_q"]
    if np.isnan(fd).any():
        raise ValueError(f"{own}: the rows do not cover the grid: every (i_d, i_q) node once")
    return x, y, fd, fq


def _short(v) -> str:
    r = repr(v)
    return r if len(r) <= 60 else r[:57] + "..."


def saturation_from_table(tbl: dict[str, Any], base: str | Path | None = None) -> AlgebraicSaturation | FluxTable:
    """A drive file's ``[machine.saturation]`` table as the saturation model.

    ``model = "algebraic"`` (default): :data:`SAT_KEYS` (SI: the coefficients in A and Vs; ``a_d0``, ``a_dd``,
    ``S``, ``a_q0``, ``a_qq``, ``T`` required, the cross-saturation and the PM bridge optional: a_dq = 0, U = 1,
    V = 0, ψn = 0, a_b = 0, a_bp = 0, W = 2, k_q = 0).  ``model = "table"``: ``current_unit`` ("A", "kA") and
    ``flux_unit`` ("Vs", "Wb", "mVs", "mWb") required, then either the inline ``i_d``, ``i_q`` (lists) and
    ``psi_d``, ``psi_q`` (one row per i_d, one column per i_q) or ``csv`` (a file, relative to ``base``, with
    the columns i_d, i_q, psi_d, psi_q, one row per grid node).  ``nominal`` is read by the drive file (how
    ``[machine]``'s missing Ld, Lq, psi_f follow from the map).

    Args:
        tbl: The table (a dict).
        base: The folder a ``csv`` name is relative to (the drive file's), or None (the working folder).

    Returns:
        The :class:`AlgebraicSaturation` or :class:`FluxTable`.

    Raises:
        ValueError: One line naming the key ``machine.saturation.KEY`` and its allowed range.
    """
    own = "machine.saturation"
    if not isinstance(tbl, dict):
        raise ValueError(f"{own} must be a table ([machine.saturation]), got {type(tbl).__name__}")
    model = tbl.get("model", "algebraic")
    if model == "table":
        return _table_map(tbl, base)
    tbl = {k: v for k, v in tbl.items() if k != "nominal"}  # read by the drive file (jaxobs.drive.drivefile)
    if model != "algebraic":
        raise ValueError(f'{own}.model must be "algebraic" or "table", got {_short(model)}')
    vals = {}
    for k, v in tbl.items():
        if k == "model":
            continue
        if k not in SAT_KEYS:
            raise ValueError(f"{own}.{k}: unknown key; allowed: model, {', '.join(SAT_KEYS)}")
        lo, hi, lo_open, unit = SAT_KEYS[k]
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and v == v and abs(v) != float("inf")
        if not ok or (v <= lo if lo_open else v < lo) or v > hi:
            rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}] {unit}"
            raise ValueError(f"{own}.{k}: must be a number in {rng}, got {v!r}")
        vals[k] = float(v)
    for k in _REQUIRED:
        if k not in vals:
            raise ValueError(f'{own}.{k}: missing (required with model = "algebraic")')
    if vals.get("a_b", 0.0) > 0.0 and vals.get("psi_n", 0.0) <= 0.0:
        raise ValueError(f"{own}.psi_n: must be > 0 Vs where a_b > 0 (the PM's Norton flux), got 0")
    return AlgebraicSaturation(
        vals["a_d0"], vals["a_dd"], vals["S"], vals["a_q0"], vals["a_qq"], vals["T"],
        vals.get("a_dq", 0.0), vals.get("U", 1.0), vals.get("V", 0.0), psi_n=vals.get("psi_n", 0.0),
        a_b=vals.get("a_b", 0.0), a_bp=vals.get("a_bp", 0.0), W=vals.get("W", 2.0), k_q=vals.get("k_q", 0.0),
    )  # fmt: skip


@eqx.filter_jit
def _torque_jit(sat, p, i_d, i_q):
    psi_d, psi_q = sat.flux(i_d, i_q)
    return 1.5 * p * (psi_d * i_q - psi_q * i_d)


def map_torque(
    sat: AlgebraicSaturation | FluxTable, p: int, i_d: jax.Array | float, i_q: jax.Array | float
) -> jax.Array:
    """The torque of the map at the current i: (3/2) p (ψd i_q − ψq i_d), N·m (compiled once per shape).

    Args:
        sat: The map.
        p: Pole pairs.
        i_d: The d-axis current, A.
        i_q: The q-axis current, A.

    Returns:
        The torque, N·m.
    """
    i_d, i_q = jnp.broadcast_arrays(jnp.asarray(i_d, float), jnp.asarray(i_q, float))
    return _torque_jit(sat, float(p), i_d, i_q)


def map_mtpa(sat: AlgebraicSaturation | FluxTable, p: int, i_abs: float) -> tuple[float, float, float]:
    """Maximum torque per ampere on the map: the current angle that maximizes the torque at |i| = ``i_abs``.

    721 angles over [90°, 180°] (motoring, i_d ≤ 0), then 721 over the best two cells, then the vertex of the
    parabola through the best three (the torque is smooth in the angle: the vertex is exact to the cube of the
    0.0003° spacing).

    Args:
        sat: The map.
        p: Pole pairs.
        i_abs: The current's magnitude, A (peak, > 0).

    Returns:
        ``(i_d, i_q, torque)`` (A, A, N·m) as floats.
    """

    def best(beta):
        te = np.asarray(map_torque(sat, p, i_abs * np.cos(beta), i_abs * np.sin(beta)))
        return int(np.argmax(te)), te

    beta = np.linspace(0.5 * np.pi, np.pi, 721)
    k, _ = best(beta)
    beta = np.linspace(beta[max(k - 1, 0)], beta[min(k + 1, len(beta) - 1)], 721)
    k, te = best(beta)
    b = beta[k]
    if 0 < k < len(beta) - 1:
        h = beta[1] - beta[0]
        den = te[k - 1] - 2 * te[k] + te[k + 1]
        if den < 0:
            b = beta[k] + 0.5 * h * (te[k - 1] - te[k + 1]) / den
    i_d, i_q = i_abs * math.cos(b), i_abs * math.sin(b)
    return i_d, i_q, float(map_torque(sat, p, i_d, i_q))


@eqx.filter_jit
def _summary_jit(sat, i_d, i_q):
    psi_d, psi_q = sat.flux(i_d, i_q)
    return sat.no_load_flux(), sat.inductance(0.0, 0.0), sat.inductance(i_d, i_q), psi_d, psi_q


def map_summary(sat: AlgebraicSaturation | FluxTable, p: int, i_rated: float) -> dict[str, float]:
    """What a drive check prints of a map: no-load flux, the inductances at no load and at the rated current's
    MTPA point, and that point.

    Args:
        sat: The map.
        p: Pole pairs.
        i_rated: The rated current, A peak.

    Returns:
        name -> float: ``psi_f`` (Vs), ``Ld0``, ``Lq0`` (incremental at i = 0, H), ``mtpa_id``, ``mtpa_iq`` (A),
        ``mtpa_torque`` (N·m), ``Ld_inc``, ``Lq_inc``, ``Ldq_inc`` (incremental at that point, H), ``Ld_sec``
        ((ψd − ψf)/i_d), ``Lq_sec`` (ψq/i_q, H).
    """
    i_d, i_q, te = map_mtpa(sat, p, i_rated)
    psi_f, l0, lr, psi_d, psi_q = (np.asarray(v) for v in _summary_jit(sat, i_d, i_q))
    psi_f, psi_d, psi_q = float(psi_f), float(psi_d), float(psi_q)
    return {
        "psi_f": psi_f,
        "Ld0": float(l0[0, 0]),
        "Lq0": float(l0[1, 1]),
        "mtpa_id": i_d,
        "mtpa_iq": i_q,
        "mtpa_torque": te,
        "Ld_inc": float(lr[0, 0]),
        "Lq_inc": float(lr[1, 1]),
        "Ldq_inc": float(lr[0, 1]),
        "Ld_sec": (psi_d - psi_f) / i_d if i_d != 0.0 else float(lr[0, 0]),
        "Lq_sec": psi_q / i_q,
    }


NOMINAL_RULES = ("rated_secant", "rated_incremental", "no_load")


@eqx.filter_jit
def _roundtrip_jit(sat, i_d, i_q):
    return sat.current(*sat.flux(i_d, i_q))


def check_inverse(sat: AlgebraicSaturation, i_max: float) -> float:
    """The largest relative residual |i(ψ(i)) − i| / i_max of the flux map over a polar grid of currents up to
    ``i_max`` (the drive file refuses a map whose inversion does not converge there).

    Args:
        sat: The map.
        i_max: The current limit, A peak.

    Returns:
        The residual, relative to i_max.
    """
    r, b = np.meshgrid(np.linspace(0.0, i_max, 9), np.linspace(-np.pi, np.pi, 25))
    i_d, i_q = r * np.cos(b), r * np.sin(b)
    j_d, j_q = _roundtrip_jit(sat, jnp.asarray(i_d, float), jnp.asarray(i_q, float))
    res = np.hypot(np.asarray(j_d) - i_d, np.asarray(j_q) - i_q)
    return float(np.nanmax(np.where(np.isfinite(res), res, np.inf))) / i_max


def _slopes(f, x, axis):
    """∂f/∂x along ``axis`` at the nodes: central differences inside, one-sided at the ends (non-uniform grids)."""
    f = np.moveaxis(f, axis, 0)
    d = np.empty_like(f)
    h = np.diff(x)
    d[0] = (f[1] - f[0]) / h[0]
    d[-1] = (f[-1] - f[-2]) / h[-1]
    if len(x) > 2:
        d[1:-1] = (f[2:] - f[:-2]) / (x[2:] - x[:-2]).reshape((-1,) + (1,) * (f.ndim - 1))
    return np.moveaxis(d, 0, axis)


class FluxTable(eqx.Module):
    """A flux map given as tables: ψd and ψq over a rectilinear (i_d, i_q) grid, interpolated bicubically.

    The interpolant is cubic Hermite in each axis, with the nodes' slopes and cross slopes from finite differences
    (central inside, one-sided at the edges): continuous with continuous first derivatives, so the incremental
    inductances are continuous and the plant's vector field is differentiable.  Outside the grid it continues
    linearly from the edge with the edge's gradient (C¹ across the edge).  The plant integrates the currents
    with it (:func:`jaxobs.drive.machine.plant_vf`): the map gives ψ(i) and its Jacobian explicitly.

    Args:
        i_d: The d-axis grid, A (strictly increasing, ≥ 4 points).
        i_q: The q-axis grid, A (strictly increasing, ≥ 4 points).
        psi_d: ψd at the grid's nodes, Vs, shape (len(i_d), len(i_q)); strictly increasing in i_d.
        psi_q: ψq at the nodes, Vs, same shape; strictly increasing in i_q.

    Raises:
        ValueError: A wrong shape, a non-finite value, an axis not increasing or a flux not monotonic.
    """

    i_d: jax.Array
    i_q: jax.Array
    coef_d: jax.Array  # (4, nd, nq): value, ∂/∂i_d, ∂/∂i_q, ∂²/∂i_d∂i_q at the nodes
    coef_q: jax.Array
    state_is_flux = False  # the plant integrates the currents with a table (class doc)

    def __init__(self, i_d, i_q, psi_d, psi_q, owner="FluxTable"):
        x, y = np.asarray(i_d, float), np.asarray(i_q, float)
        fd, fq = np.asarray(psi_d, float), np.asarray(psi_q, float)
        for name, a in (("i_d", x), ("i_q", y)):
            if a.ndim != 1 or len(a) < 4:
                raise ValueError(f"{owner}.{name} must be a list of at least 4 currents, got shape {a.shape}")
            if not np.all(np.isfinite(a)) or not np.all(np.diff(a) > 0):
                raise ValueError(f"{owner}.{name} must be finite and strictly increasing")
        for name, f in (("psi_d", fd), ("psi_q", fq)):
            if f.shape != (len(x), len(y)):
                raise ValueError(f"{owner}.{name} must have shape (len(i_d), len(i_q)) = ({len(x)}, {len(y)}), "
                                 f"got {f.shape}")  # fmt: skip
            if not np.all(np.isfinite(f)):
                raise ValueError(
                    f"{owner}.{name} must be finite (a NaN or inf at node {np.argwhere(~np.isfinite(f))[0]})"
                )
        if not np.all(np.diff(fd, axis=0) > 0):
            k = np.argwhere(np.diff(fd, axis=0) <= 0)[0]
            raise ValueError(f"{owner}.psi_d must increase strictly with i_d (not at i_d = {x[k[0]]:g} .. "
                             f"{x[k[0] + 1]:g} A, i_q = {y[k[1]]:g} A): a flux map is monotonic")  # fmt: skip
        if not np.all(np.diff(fq, axis=1) > 0):
            k = np.argwhere(np.diff(fq, axis=1) <= 0)[0]
            raise ValueError(f"{owner}.psi_q must increase strictly with i_q (not at i_q = {y[k[1]]:g} .. "
                             f"{y[k[1] + 1]:g} A, i_d = {x[k[0]]:g} A): a flux map is monotonic")  # fmt: skip

        def coef(f):
            fx, fy = _slopes(f, x, 0), _slopes(f, y, 1)
            return np.stack([f, fx, fy, _slopes(fx, y, 1)])

        self.i_d, self.i_q = jnp.asarray(x), jnp.asarray(y)
        self.coef_d, self.coef_q = jnp.asarray(coef(fd)), jnp.asarray(coef(fq))

    def _eval(self, c, i_d, i_q):
        x, y = self.i_d, self.i_q
        xc, yc = jnp.clip(i_d, x[0], x[-1]), jnp.clip(i_q, y[0], y[-1])
        k = jnp.clip(jnp.searchsorted(x, xc, side="right") - 1, 0, len(x) - 2)
        m = jnp.clip(jnp.searchsorted(y, yc, side="right") - 1, 0, len(y) - 2)
        hx, hy = x[k + 1] - x[k], y[m + 1] - y[m]
        t, u = (xc - x[k]) / hx, (yc - y[m]) / hy

        def basis(s, h):  # values and slopes (per unit current) of the Hermite basis at s, and their derivatives
            h0, h1 = 2 * s**3 - 3 * s**2 + 1, -2 * s**3 + 3 * s**2
            g0, g1 = (s**3 - 2 * s**2 + s) * h, (s**3 - s**2) * h
            dh0, dh1 = (6 * s**2 - 6 * s) / h, (-6 * s**2 + 6 * s) / h
            dg0, dg1 = 3 * s**2 - 4 * s + 1, 3 * s**2 - 2 * s
            return (h0, h1, g0, g1), (dh0, dh1, dg0, dg1)

        (bx, dbx), (by, dby) = basis(t, hx), basis(u, hy)

        def comb(bx, by):
            out = 0.0
            for ia, ha, ga in ((k, bx[0], bx[2]), (k + 1, bx[1], bx[3])):
                for jb, hb, gb in ((m, by[0], by[2]), (m + 1, by[1], by[3])):
                    out = out + (c[0, ia, jb] * ha * hb + c[1, ia, jb] * ga * hb + c[2, ia, jb] * ha * gb
                                 + c[3, ia, jb] * ga * gb)  # fmt: skip
            return out

        val = comb(bx, by)
        # outside the grid: on linearly with the edge's gradient (C¹ across the edge)
        return val + comb(dbx, by) * (i_d - xc) + comb(bx, dby) * (i_q - yc)

    def flux(self, i_d: jax.Array | float, i_q: jax.Array | float) -> tuple[jax.Array, jax.Array]:
        """The flux map ψ(i), interpolated.

        Args:
            i_d: The d-axis current, A.
            i_q: The q-axis current, A.

        Returns:
            ``(ψd, ψq)``, Vs.
        """
        i_d, i_q = jnp.broadcast_arrays(jnp.asarray(i_d, float), jnp.asarray(i_q, float))
        return self._eval(self.coef_d, i_d, i_q), self._eval(self.coef_q, i_d, i_q)

    def inductance(self, i_d: jax.Array | float, i_q: jax.Array | float) -> jax.Array:
        """The incremental inductance matrix ∂ψ/∂i of the interpolant.

        Args:
            i_d: The d-axis current, A.
            i_q: The q-axis current, A.

        Returns:
            A (..., 2, 2) array, H.
        """

        def f(v):
            return jnp.stack(self.flux(v[0], v[1]))

        jac = jnp.vectorize(jax.jacfwd(f), signature="(2)->(2,2)")
        return jac(jnp.stack(jnp.broadcast_arrays(jnp.asarray(i_d, float), jnp.asarray(i_q, float)), axis=-1))

    def no_load_flux(self) -> jax.Array:
        """ψd at zero current, Vs."""
        return self.flux(0.0, 0.0)[0]
