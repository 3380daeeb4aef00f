"""The torque–speed capability of a drive file (jaxobs.drive.weakening.capability_curve, DriveFile.capability) and
``jaxobs drive check``'s table and figure of it."""

import math
from pathlib import Path

import numpy as np
import pytest

import jaxobs.drive as D
from jaxobs.drive.saturation import map_mtpa
from jaxobs.drive.weakening import _map_flux, capability_curve, capability_torque
from jaxobs_tuning.cli import main

ROOT = Path(__file__).parents[1]
EXAMPLES = ROOT / "docs" / "examples"


def _volt(m, w, i_d, i_q, pd=None, pq=None):
    pd = float(m.psi_f) + float(m.Ld) * i_d if pd is None else pd
    pq = float(m.Lq) * i_q if pq is None else pq
    return np.hypot(float(m.Rs) * i_d - w * pq, float(m.Rs) * i_q + w * pd)


@pytest.mark.parametrize(("Ld", "Lq"), [(0.00037, 0.0012), (0.0008, 0.0008), (0.0012, 0.0007)])
def test_the_curve_is_the_brute_force_maximum_at_every_speed_at_once(Ld, Lq):
    """Constant inductances with field weakening: the vectorised curve equals capability_torque speed by speed,
    each point is feasible, and no current of a dense (i_d, i_q) grid over the reference's reach (i_d in
    [max(−i_max, −ψf/Ld), 0], the circle, MTPV on the inverse-salient machine) fits the voltage with more torque."""
    m = D.PMSMParams(0.018, Ld, Lq, 0.066, 0.39, 3)
    u_max, i_max, margin = 173.2, 240.0, 0.95
    w = np.linspace(0.0, 3.0 * 12000 * D.RPM, 13)
    c = capability_curve(m, w, u_max, i_max, margin)
    for k in range(len(w)):
        assert c["torque"][k] == pytest.approx(capability_torque(m, float(w[k]), u_max, i_max, margin)[0], rel=1e-12)
    ok = np.isfinite(c["torque"])
    assert ok[:3].all()
    assert np.all(np.hypot(c["i_d"], c["i_q"])[ok] <= i_max * (1 + 1e-12))
    assert np.all(c["u"][ok] <= margin * u_max * (1 + 1e-9))
    lo = max(-i_max, -0.066 / Ld)
    gd, gq = np.meshgrid(np.linspace(lo, 0.0, 601), np.linspace(0.0, i_max, 601))
    inside = gd**2 + gq**2 <= i_max**2
    if Ld > Lq:
        inside &= gq <= np.asarray(D.weakening.mtpv_iq(m, gd))
    te = 1.5 * 3 * (0.066 + (Ld - Lq) * gd) * gq
    for k in range(len(w)):
        fit = inside & (_volt(m, w[k], gd, gq) <= margin * u_max)
        best = te[fit].max() if fit.any() else math.nan
        if math.isnan(best):
            assert not ok[k]
        else:  # the grid is a lower bound; the curve's closed-form i_q is exact on its own d grid
            assert c["torque"][k] >= best * (1 - 1e-9), (k, c["torque"][k], best)
            assert c["torque"][k] <= best * 1.01 + 1e-9


def test_without_field_weakening_the_curve_keeps_the_policys_i_d():
    """The zero policy without field weakening: i_d = 0 throughout; above the speed where i_max meets the voltage,
    i_q is the root of |u| = m u_max at i_d = 0; at the no-load speed m u_max/ψf nothing fits."""
    m = D.PMSMParams(0.5, 0.002, 0.002, 0.05, 1e-4, 4)
    u_max, i_max, margin = 13.86, 10.0, 0.95
    w_emf = margin * u_max / 0.05
    c = capability_curve(m, np.array([0.0, 0.6 * w_emf, 1.001 * w_emf]), u_max, i_max, margin, weakening=False)
    assert np.all(c["i_d"][:2] == 0.0)
    assert c["i_q"][0] == pytest.approx(i_max)
    assert _volt(m, 0.6 * w_emf, 0.0, c["i_q"][1]) == pytest.approx(margin * u_max, rel=1e-3)
    assert np.isnan(c["torque"][2])


def test_the_map_curve_is_feasible_on_the_map_and_starts_at_its_mtpa():
    """The saturated PM-SyRM (its map's flux): every point lies within the circle and meets the voltage on the
    map; at standstill the torque is the map's MTPA torque on the references' circle i_ref_max (within the grid's
    0.5 %)."""
    f = D.read_drive(EXAMPLES / "pmsyrm_5p6kw_sat.toml")
    m = f.machine
    n = np.array([0.0, 1800.0, 4000.0, 9000.0])
    c = f.capability(n)
    i_max = float(f.derived["i_ref_max"].value)
    u_lim = float(f.derived["fw_margin"].value) * float(f.derived["u_max"].value)
    assert m.sat is not None
    assert np.all(np.isfinite(c["torque"]))
    pd, pq = (np.asarray(v) for v in _map_flux(m.sat, c["i_d"], c["i_q"]))
    assert np.all(np.hypot(c["i_d"], c["i_q"]) <= i_max * (1 + 1e-12))
    assert np.all(_volt(m, n * m.p * D.RPM, c["i_d"], c["i_q"], pd, pq) <= u_lim * (1 + 1e-9))
    assert np.allclose(c["torque"], 1.5 * m.p * (pd * c["i_q"] - pq * c["i_d"]), rtol=1e-9)
    te_mtpa = map_mtpa(m.sat, m.p, i_max)[2]
    assert te_mtpa * 0.995 <= c["torque"][0] <= te_mtpa * (1 + 1e-9)
    assert np.all(np.diff(c["torque"]) < 0)


def test_drive_check_prints_the_capability_and_draws_it(tmp_path, capsys):
    """The check's table: standstill to the speed limit, the limit that binds; the figure is written; the last line
    says the points are not simulated and how to."""
    fig = tmp_path / "cap.png"
    rc = main(["drive", "check", "--no-cache", str(EXAMPLES / "traction_ipmsm.toml"), "--figure", str(fig)])
    out = capsys.readouterr().out
    assert rc == 0
    # the references' circle, 0.71 % below the 240 A limit (jaxobs.drive._reflimit)
    assert "capability (steady maximum torque; |i| <= i_ref_max = 238.3 A, |u| <= fw_margin × u_dc/√3 = 164.54 V" in out
    rows = {ln.split()[0]: ln.split() for ln in out.splitlines() if ln.startswith("  ") and ln.split()[0][0].isdigit()}
    assert rows["0"][1:2] == ["158.7"] and rows["0"][-1] == "current"
    assert rows["3996.6"][1] == "103.1" and rows["3996.6"][-1] == "voltage+i_d_stop"  # at −ψf/Ld, under u
    assert rows["12000"][1] == "34.35"
    assert fig.stat().st_size > 10_000 and fig.read_bytes()[:4] == b"\x89PNG"
    assert out.rstrip().splitlines()[-1].startswith("operating points not simulated: --simulate runs")


def test_a_claimed_rating_the_curve_cannot_carry_is_a_warning(tmp_path, capsys):
    """Teknic's servo without field weakening: its rated point needs 97 % of u_dc/√3, so at the 95 % margin the
    curve gives less than the rated torque at the rated speed: a warning naming the key."""
    rc = main(["drive", "check", "--no-cache", str(EXAMPLES / "teknic_m2310p.toml")])
    out = capsys.readouterr().out
    assert rc == 0
    assert "warning: machine.rated_torque_nm: the capability at the rated speed is 0.2425 N·m" in out
    assert "control.field_weakening = true" in out


def test_a_foc_built_from_concrete_values_has_the_jax_operations_bits():
    """FOC.imc on concrete values computes its gains in NumPy (no XLA kernel compiled: a drive check runs nothing);
    they are bit for bit what the same operations give one by one on JAX arrays (how it computed them before), the
    default i_max too; and as_float places a Python number with JAX's own rounding."""
    import jax

    from jaxobs.core.validate import as_float

    m = D.PMSMParams(0.018, 0.00037, 0.0012, 0.066, 0.3883, 3, T_rated=135.0)
    a_c, a_s = as_float(3490.7), as_float(31.4159)
    foc = D.FOC.imc(m, a_c, a_s)
    by_jax = {
        "kp_d": a_c * m.Ld,
        "ki_d": a_c * m.Rs,
        "kp_q": a_c * m.Lq,
        "ki_q": a_c * m.Rs,
        "kp_w": 2 * a_s * m.J / m.kt,
        "ki_w": a_s**2 * m.J / m.kt,
        "i_max": 1.5 * m.i_rated,
    }
    for k, v in by_jax.items():
        assert np.asarray(getattr(foc, k)).tobytes() == np.asarray(v).tobytes(), k
    placed = jax.numpy.asarray(0.1, dtype=as_float(0.0).dtype)
    assert np.asarray(as_float(0.1)).tobytes() == np.asarray(placed).tobytes()


@pytest.mark.parametrize(("Ld", "Lq"), [(0.0012, 0.0007), (0.00037, 0.0012)])
def test_the_numpy_mtpv_bound_is_the_references(Ld, Lq):
    """mtpv_iq_np (the check's, no kernel compiled) is the reference's mtpv_iq, inf on a salient machine."""
    from jaxobs.drive.weakening import mtpv_iq, mtpv_iq_np

    m = D.PMSMParams(0.018, Ld, Lq, 0.066, 0.39, 3)
    i_d = np.linspace(-200.0, 0.0, 41)
    assert np.allclose(mtpv_iq_np(m, i_d), np.asarray(mtpv_iq(m, i_d)), rtol=1e-12, atol=0.0)
