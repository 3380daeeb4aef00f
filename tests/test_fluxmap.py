"""Saturation with cross-saturation (jaxobs.drive.saturation): the algebraic current map of Hinkkanen et al. 2017
with Lelli et al. 2024's PM bridge, its inverse, the plant integrated in the flux linkages, gradients against
finite differences, the drive file's [machine.saturation] and its one-line refusals."""

from pathlib import Path
from types import SimpleNamespace

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxobs import drive as D
from jaxobs.drive.drivefile import drive_from_table
from jaxobs.drive.plant import PlantInput
from jaxobs.drive.saturation import AlgebraicSaturation, check_inverse, map_mtpa, map_summary
from jaxobs.io.safetoml import read_toml

EXAMPLE = Path(__file__).resolve().parent.parent / "docs" / "examples" / "pmsyrm_5p6kw_sat.toml"
# motulator's 5.6-kW PM-SyRM example map (docs/examples/pmsyrm_5p6kw_sat.toml)
SAT = AlgebraicSaturation(3.96, 28.5, 4, 5.89, 2.67, 6, 41.5, 1, 1, psi_n=0.804, a_b=81.75, a_bp=1, W=2, k_q=0.1)
I_RATED = 8.8 * np.sqrt(2)


def _run(par, op, u, n, ts=1e-4, n_sub=4):
    """The plant of ``par`` from ``op`` under the held input ``u`` for ``n`` periods (one compiled scan): its
    outputs (i_d, i_q, ω_m, θ_e, torque) per period."""
    plant = D.PMSM(par, ts=ts, n_sub=n_sub)

    @jax.jit
    def go(s):
        def body(s, _):
            s, o = plant.step(s, u)
            return s, jnp.stack([o.i_d, o.i_q, o.omega_m, o.theta_e, o.torque])

        return jax.lax.scan(body, s, None, length=n)[1]

    return np.asarray(go(plant.init(op)))


def _machine(sat=SAT, **kw):
    return D.PMSMParams(0.63, 0.0214, 0.102, 0.4767, 0.05, 2, T_rated=29.7, n_rated=1800.0, sat=sat, **kw)


def test_current_map_is_the_published_one_written_out():
    """The map at one flux, against Hinkkanen et al. 2017's and Lelli et al. 2024's equations written here by hand."""
    pd, pq = 0.6, -0.7
    g_d = 3.96 + 28.5 * pd**4 + 41.5 / 3 * abs(pd) * abs(pq) ** 3
    g_q = 5.89 + 2.67 * pq**6 + 41.5 / 3 * abs(pd) ** 3 * abs(pq)
    pb = pd - 0.804
    s2 = pb * pb + 0.1 * pq * pq
    g_b = 81.75 * s2 / (1 + s2)
    i_d, i_q = SAT.current(pd, pq)
    np.testing.assert_allclose([i_d, i_q], [g_d * pd + g_b * pb, g_q * pq + 0.1 * g_b * pq], rtol=1e-13)


def test_flux_map_inverts_the_current_map_and_its_inductances_are_symmetric():
    """ψ(i) within rounding of the root up to 3 × the rated current; ∂ψ/∂i symmetric (a magnetic energy), Lq falls
    with i_q (saturation) and the no-load flux is the root of i_d(ψd, 0)."""
    assert check_inverse(SAT, 3 * I_RATED) < 1e-12
    psi_f = float(SAT.no_load_flux())
    assert abs(float(SAT.current(psi_f, 0.0)[0])) < 1e-12
    lr = np.asarray(SAT.inductance(-8.7, 8.9))
    assert lr[0, 1] == pytest.approx(lr[1, 0], rel=1e-10) and abs(lr[0, 1]) > 1e-4  # cross-saturation present
    l0 = np.asarray(SAT.inductance(0.0, 0.0))
    assert lr[1, 1] < 0.5 * l0[1, 1]  # q saturates: down more than half at the rated current


def test_flux_map_gradient_matches_finite_differences():
    """d ψ(i)/d(i, a_q0): the last-Newton-step derivative is the implicit function's."""

    def f(v):
        sat = eqx.tree_at(lambda s: s.a_q0, SAT, v[2])
        pd, pq = sat.flux(v[0], v[1])
        return pd + 2.0 * pq

    v = jnp.array([-5.0, 11.0, 5.89])
    g = np.asarray(jax.grad(f)(v))
    h = 1e-6
    fd = [(f(v.at[k].add(h)) - f(v.at[k].add(-h))) / (2 * h) for k in range(3)]
    np.testing.assert_allclose(g, fd, rtol=1e-6)


def test_plant_field_gradient_matches_finite_differences():
    """The mapped plant's vector field is differentiable in its state and in the map's coefficients."""
    par = _machine()
    u = (120.0, -80.0)

    def f(v):
        p2 = eqx.tree_at(lambda m: (m.sat.a_dd, m.sat.a_dq), par, (v[4], v[5]))
        return jnp.sum(D.plant_vf(p2, v[:4], u, 3.0) * jnp.array([1.0, 0.7, 0.01, 0.0]))

    v = jnp.array([0.55, 0.6, 100.0, 0.4, 28.5, 41.5])
    g = np.asarray(jax.grad(f)(v))
    h = 1e-6
    fd = np.array([(f(v.at[k].add(h)) - f(v.at[k].add(-h))) / (2 * h) for k in range(6)])
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-9)


def test_linear_map_gives_the_constant_inductance_plant():
    """A map with only a_d0 = 1/Ld, a_q0 = 1/Lq (a linear SyRM) integrated in its fluxes follows the current-state
    plant of the same Ld, Lq with a vanishing ψf: the state conversions, outputs and initial state are wired right."""
    ld, lq = 0.02, 0.05
    lin = AlgebraicSaturation(1 / ld, 0.0, 0, 1 / lq, 0.0, 0)
    kw = dict(T_rated=10.0, n_rated=1500.0)
    mapped = D.PMSMParams(0.5, ld, lq, 1e-30, 0.01, 2, sat=lin, **kw)
    plain = D.PMSMParams(0.5, ld, lq, 1e-30, 0.01, 2, **kw)
    op = SimpleNamespace(i_d=-2.0, i_q=4.0, omega_m=50.0, theta_e=0.3)  # what PMSM.init reads of an OperatingPoint
    u = PlantInput(jnp.asarray(60.0), jnp.asarray(-40.0), jnp.asarray(0.5))
    outs = [_run(par, op, u, 50) for par in (mapped, plain)]
    np.testing.assert_allclose(outs[0], outs[1], rtol=1e-9, atol=1e-11)
    assert float(outs[0][0, 0]) == pytest.approx(-2.0, rel=1e-12)


def test_no_map_keeps_the_pytree():
    """A machine without a map has no extra leaf (the constant-inductance plant's pytree, so its numbers)."""
    par = D.PMSMParams(0.5, 0.02, 0.05, 0.1, 0.01, 2)
    assert par.sat is None and len(jax.tree_util.tree_leaves(par)) == 10


def test_map_mtpa_is_the_torque_peak():
    """The map's MTPA current angle gives more torque than its neighbours at the same |i|."""
    i_d, i_q, te = map_mtpa(SAT, 2, I_RATED)
    assert np.hypot(i_d, i_q) == pytest.approx(I_RATED, rel=1e-12)
    b = np.arctan2(i_q, i_d)
    for db in (-0.02, 0.02):
        other = float(D.saturation.map_torque(SAT, 2, I_RATED * np.cos(b + db), I_RATED * np.sin(b + db)))
        assert other < te
    s = map_summary(SAT, 2, I_RATED)
    assert s["Ld_sec"] * i_d + s["psi_f"] == pytest.approx(float(SAT.flux(i_d, i_q)[0]), rel=1e-12)


def _raw():
    raw, _ = read_toml(EXAMPLE, "drive file")
    return raw


def test_example_drive_file_fills_the_nominal_constants_from_the_map():
    f = drive_from_table(_raw(), "x")
    s = map_summary(f.machine.sat, 2, I_RATED)
    assert float(f.machine.Ld) == pytest.approx(s["Ld_sec"], rel=1e-12)
    assert float(f.machine.Lq) == pytest.approx(s["Lq_sec"], rel=1e-12)
    assert float(f.machine.psi_f) == pytest.approx(s["psi_f"], rel=1e-12)
    assert "sat_Lq_rated" in f.derived and f.derived["sat_Lq_rated"].value < f.derived["sat_Lq0"].value
    assert f.table["machine"]["saturation"]["a_d0"] == 3.96  # the table a job keeps holds the map


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (lambda s: s.update(a_d0=-1.0), "machine.saturation.a_d0"),
        (lambda s: s.update(a_qq=float("nan")), "machine.saturation.a_qq"),
        (lambda s: s.update(S="4"), "machine.saturation.S"),
        (lambda s: s.update(W=1.0), "machine.saturation.W"),
        (lambda s: s.update(psi_d_table=[1.0]), "machine.saturation.psi_d_table"),
        (lambda s: s.update(model="fem"), "machine.saturation.model"),
        (lambda s: s.update(nominal="rated"), "machine.saturation.nominal"),
        (lambda s: s.update(psi_n=0.0), "machine.saturation.psi_n"),
        (lambda s: s.pop("a_q0"), "machine.saturation.a_q0"),
    ],
)
def test_bad_maps_are_one_line_errors_naming_the_key(edit, key):
    raw = _raw()
    edit(raw["machine"]["saturation"])
    with pytest.raises(ValueError, match=key.replace(".", r"\.")) as e:
        drive_from_table(raw, "x")
    assert "\n" not in str(e.value)


def test_saturation_and_q_saturation_are_exclusive_and_nominal_needs_a_missing_constant():
    raw = _raw()
    raw["machine"]["q_sat_current_a"] = 20.0
    with pytest.raises(ValueError, match=r"machine\.q_sat_current_a"):
        drive_from_table(raw, "x")
    raw = _raw()
    raw["machine"].update(Ld=0.02, Lq=0.1, psi_f=0.48)
    with pytest.raises(ValueError, match=r"machine\.saturation\.nominal"):
        drive_from_table(raw, "x")
    with pytest.raises(ValueError, match="sat"):
        _machine(q_sat=D.QSaturation(20.0))


def test_dsat_axis_scales_the_true_machines_saturation_only():
    """The saturation-mismatch axis: the true map's a_dd, a_qq, a_dq times (1 + v); what is assumed stays."""
    f = drive_from_table(_raw(), "x")
    sc = D.Scenario(f.machine)
    b = D.scenario_batch(sc, ("dsat",), [(-1.0,), (0.5,)])
    np.testing.assert_allclose(b.par.sat.a_qq, [0.0, 1.5 * 2.67], rtol=1e-12)
    np.testing.assert_allclose(b.par.sat.a_dq, [0.0, 1.5 * 41.5], rtol=1e-12)
    np.testing.assert_allclose(b.par.sat.a_d0, [3.96, 3.96], rtol=0)
    np.testing.assert_allclose(b.est_par.Lq, [float(f.machine.Lq)] * 2, rtol=0)
    np.testing.assert_allclose(b.est_par.sat.a_qq, [2.67, 2.67], rtol=0)
    with pytest.raises(ValueError, match="dsat"):
        D.scenario_batch(D.Scenario(_machine(sat=None)), ("dsat",), [(0.1,)])


def test_sensored_drive_on_the_mapped_machine_carries_the_load():
    """The example's derived FOC (nominal constants from the map) on the mapped plant: a 25 N·m load step at
    900 r/min is carried (the map's torque equals the load in steady state) with |i| within i_max."""
    import jaxobs

    f = drive_from_table(_raw(), "x")
    sc = D.Scenario(
        f.machine,
        speed_ref=D.Scenario.speed_rpm([0.0], [900.0]),
        load=D.Scenario.load_steps([0.0, 0.05], [0.0, 25.0]),
        omega_m0=900 * D.RPM,
    )
    o = jaxobs.simulate(D.ClosedLoop(f.drive_for(sensorless=False), None, sc), 0.35).outputs
    assert float(o.torque[-1]) == pytest.approx(25.0, abs=0.05)
    assert float(o.speed_rpm[-1]) == pytest.approx(900.0, abs=2.0)
    assert float(np.hypot(o.i_d, o.i_q).max()) <= float(f.derived["i_max"].value)


# --- flux maps as tables


def _table_raw(n=25, edit=None):
    """The example drive file with its map sampled on an n × n grid over ±24 A, as an inline table (mWb)."""
    raw = _raw()
    x = np.linspace(-24.0, 24.0, n)
    pd, pq = SAT.flux(*np.meshgrid(x, x, indexing="ij"))
    tbl = dict(model="table", current_unit="A", flux_unit="mWb", i_d=x.tolist(), i_q=x.tolist(),
               psi_d=(1e3 * np.asarray(pd)).tolist(), psi_q=(1e3 * np.asarray(pq)).tolist())  # fmt: skip
    if edit is not None:
        edit(tbl)
    raw["machine"]["saturation"] = tbl
    return raw


def test_table_interpolant_is_smooth_and_matches_the_sampled_map():
    """A table sampled from the algebraic map: exact at the nodes, close between them, a continuous incremental
    inductance across a cell edge (C¹), monotonic flux, and the drive file reads it in its declared units."""
    f = drive_from_table(_table_raw(), "x")
    t = f.machine.sat
    assert isinstance(t, D.saturation.FluxTable)
    np.testing.assert_allclose(t.flux(-8.0, 10.0), SAT.flux(-8.0, 10.0), rtol=0, atol=2e-3)
    edge = float(t.i_d[12])  # a node: the cells on either side meet here
    left, right = np.asarray(t.inductance(edge - 1e-9, 5.3)), np.asarray(t.inductance(edge + 1e-9, 5.3))
    np.testing.assert_allclose(left, right, rtol=1e-6)
    assert f.derived["sat_Lq_rated"].value == pytest.approx(float(SAT.inductance(-8.74, 8.86)[1, 1]), rel=0.03)


def test_table_plant_gradient_matches_finite_differences_and_follows_the_algebraic_plant():
    """The table's plant (state in currents) is differentiable in its state; over 20 ms from standstill under a
    small held voltage (the currents stay within the table) it follows the algebraic map's plant (state in
    fluxes) to the interpolation error."""
    f = drive_from_table(_table_raw(), "x")
    par = f.machine
    u = (120.0, -80.0)

    def fv(v):
        return jnp.sum(D.plant_vf(par, v, u, 3.0) * jnp.array([1.0, 0.7, 0.01, 0.0]))

    v = jnp.array([-5.3, 7.1, 100.0, 0.4])
    g = np.asarray(jax.grad(fv)(v))
    h = 1e-6
    fd = np.array([(fv(v.at[k].add(h)) - fv(v.at[k].add(-h))) / (2 * h) for k in range(4)])
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-9)
    op = SimpleNamespace(i_d=-3.0, i_q=6.0, omega_m=0.0, theta_e=0.2)  # currents within the table's ±24 A
    uin = PlantInput(jnp.asarray(3.0), jnp.asarray(4.0), jnp.asarray(0.0))
    rows = [_run(p2, op, uin, 160, ts=1.25e-4)[:, :2] for p2 in (par, _machine())]
    assert np.abs(rows[0] - rows[1]).max() < 0.05 * np.abs(rows[1]).max()


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (lambda t: t.pop("flux_unit"), "machine.saturation.flux_unit"),
        (lambda t: t.update(current_unit="mA"), "machine.saturation.current_unit"),
        (lambda t: t.update(psi_d=t["psi_d"][:-1]), "machine.saturation.psi_d"),
        (lambda t: t["psi_q"][3].__setitem__(4, float("nan")), "machine.saturation.psi_q"),
        (lambda t: t["psi_d"].reverse(), "machine.saturation.psi_d"),
        (lambda t: t.update(i_q=t["i_q"][::-1]), "machine.saturation.i_q"),
        (lambda t: t.update(csv="x.csv"), "machine.saturation.csv"),
        (lambda t: t.update(a_d0=1.0), "machine.saturation.a_d0"),
    ],
)
def test_bad_tables_are_one_line_errors_naming_the_key(edit, key):
    with pytest.raises(ValueError, match=key.replace(".", r"\.")) as e:
        drive_from_table(_table_raw(edit=edit), "x")
    assert "\n" not in str(e.value)


def test_table_from_csv_is_the_inline_table(tmp_path):
    raw = _table_raw(n=9)
    t = raw["machine"]["saturation"]
    lines = ["psi_q,i_d,i_q,psi_d"]
    for a, x in enumerate(t["i_d"]):
        for b, y in enumerate(t["i_q"]):
            lines.append(f"{t['psi_q'][a][b]!r},{x!r},{y!r},{t['psi_d'][a][b]!r}")
    (tmp_path / "map.csv").write_text("\n".join(lines[:1] + lines[1:][::-1]) + "\n")
    inline = drive_from_table(raw, "x").machine.sat
    raw["machine"]["saturation"] = dict(model="table", current_unit="A", flux_unit="mWb", csv="map.csv")
    from_csv = drive_from_table(raw, "x", tmp_path).machine.sat
    np.testing.assert_array_equal(from_csv.coef_d, inline.coef_d)
    np.testing.assert_array_equal(from_csv.coef_q, inline.coef_q)


def test_a_run_on_a_map_traces_few_flux_solves(monkeypatch):
    """The steady start on a saturation map iterates in loops, each body traced once: tracing one sensorless run on
    the 5.6-kW PM-SyRM traces the map's flux (a Newton solve of its own) 54 times.  With its Newton iterations as
    Python loops it traced 456 (42 s of tracing, a compile past 10 GiB): counted, not timed, so a slower machine
    cannot fail it."""

    from jaxobs import simulate
    from jaxobs.drive import read_drive
    from jaxobs.observers import ReducedOrderFluxObserver
    from jaxobs.scenarios.families.drive import DriveScenarios

    f = read_drive(Path(__file__).parents[1] / "docs" / "examples" / "pmsyrm_5p6kw_sat.toml")
    drive = f.drive_for(sensorless=True)
    family = DriveScenarios(f.machine, drive)  # type: ignore[arg-type]  # a single machine's drive
    sc = family.build(["speed_rpm", "load_nm"], [(900.0, 29.7)])
    sc = jax.tree.map(lambda x: x[0], sc)
    design = ReducedOrderFluxObserver.closed_form(ts=drive.ts)
    calls = []
    flux = AlgebraicSaturation.flux
    monkeypatch.setattr(AlgebraicSaturation, "flux", lambda self, *a, **k: calls.append(1) or flux(self, *a, **k))
    jax.make_jaxpr(lambda s: simulate(family.system(design, s), 0.01))(sc)
    assert 0 < len(calls) <= 80, len(calls)
