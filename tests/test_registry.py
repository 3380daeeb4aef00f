"""The observers own their design data: gains with metadata, closed forms as classmethods, one registry.

- every registered class declares every gain a job may tune with its units, role, bounds and symbol, and every
  array field of it is a gain, a bound field or a named parameter;
- a study's designs of one family give each gain name one unit (and mixing 001's WIF k1 with 002's FA-LESO k1
  is refused, since they are different gains);
- each class's ``closed_form`` gives the numbers of the papers' rules, evaluated here as the rules' formulas;
- the shared second-order SOGI core takes its gains by role, and the WIF passes 001's k1 as the damping gain;
- ``omega0``, the flux observers' initial speed in job and result files, is read as ``omega_init``;
- ``jaxobs closed-form`` prints the numbers it printed from its own tables, now every design's own rows;
- one check enforces every gain's declared bounds, and 002 eq (16) is written once.
"""

import dataclasses
import inspect
import json
import math
import re
import tomllib
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxobs
from jaxobs import linear, papers
from jaxobs.observers import AbstractDriveObserver, ClosedForm, gain_fields, gain_table
from jaxobs.studies import registry as registry_module
from jaxobs.studies.registry import REGISTRY, closed_form_gains, registered
from jaxobs_tuning import cli_papers
from jaxobs_tuning.cli import main
from jaxobs_tuning.cli_papers import CF_DESIGNS, CF_OPTIONS
from jaxobs_tuning.job import COMPONENTS, parse_job

# what is not a gain: the machine and start speed bind() sets, the FLLs' nominal frequency, and the speed
# estimator a LESO or a PLL-type flux observer holds (a module whose gains are its own: tests/test_zero_speed.py);
# the reduced-order flux observer's flux_map: the assumed machine's current map, which bind() sets too
NOT_GAINS = {"Rs", "L", "Ld", "Lq", "psi_f", "omega_init", "omega0_pll", "omega_n", "speed", "flux_map"}
UNITS = {"1", "s-1", "s-2", "rad s-1", "rad2 s-2"}


@pytest.mark.parametrize("name", list(REGISTRY))
def test_every_array_field_is_a_gain_with_metadata_or_named(name):
    cls = REGISTRY[name].cls
    gains = gain_fields(cls)
    arrays = {f.name for f in dataclasses.fields(cls) if not f.metadata.get("static", False)}
    assert gains and set(gains) <= arrays, name
    assert arrays - set(gains) <= NOT_GAINS, (name, arrays - set(gains))
    bound = cls.bound_fields.names if issubclass(cls, AbstractDriveObserver) else ()  # FLLs bind nothing
    assert set(bound) & set(gains) == set(), name
    for g, info in gains.items():
        assert info.name == g and info.units in UNITS, (name, g, info.units)
        assert info.role in ("sogi", "prefilter", "fll", "pll", "leso", "filter", "flux"), (name, g)
        assert info.long_name and info.symbol and info.bounds[0] < info.bounds[1], (name, g)


def test_the_jobs_tunable_gains_are_the_fields_gains():
    want = {
        "SOGIFLL": {"k", "lam"},
        "SOGIFLLWPF": {"k1", "k2", "lam"},
        "SOGIFLLWIF": {"k1", "k2", "lam"},
        "SOIFO": {"k", "lam"},
        "SecondOrderSOIFO": {"K1", "K2", "lam"},
        "LPFFlux": {"omega_c", "kp_pll", "ki_pll"},
        "CLESO": {"omega0", "kp_pll", "ki_pll"},
        "GILESO": {"omega0", "K_r", "omega_c", "kp_pll", "ki_pll"},
        "FALESO": {"k1", "k2", "kp_pll", "ki_pll"},
        "ReducedOrderFluxObserver": {"c_sigma", "zeta_inf", "k_theta", "k_omega"},
    }
    assert {n: set(c.gains) for n, c in COMPONENTS.items()} == want
    assert "PureIntegratorFlux" in REGISTRY and not REGISTRY["PureIntegratorFlux"].tunable


def test_one_unit_per_gain_name_within_a_studys_family_and_per_class_gain_across():
    fll = {n: e.cls.closed_form() for n, e in REGISTRY.items() if e.signal == "grid"}
    drive = {n: e.cls.closed_form() for n, e in REGISTRY.items() if "drive" in e.signals and e.tunable}
    assert gain_table(fll)["lam"].units == "rad2 s-2"  # 001's λ
    t = gain_table(drive)
    assert t["lam"].units == "1" and t["omega0"].units == "rad s-1" and t["k1"].units == "s-2"
    # across the registry a name may mean two gains (the papers' names); its class says which
    units = {(n, g): i.units for n, e in REGISTRY.items() for g, i in gain_fields(e.cls).items()}
    assert units[("SOGIFLLWIF", "k1")] == "1" and units[("FALESO", "k1")] == "s-2"
    with pytest.raises(ValueError, match="gain k1 is in '1' in design 'wif' and in 's-2' in 'fa'"):
        gain_table({"wif": fll["SOGIFLLWIF"], "fa": drive["FALESO"]})


def _old_closed_forms(omega_n):
    """The closed forms as the rules' formulas give them (001 eqs 22, 29, 34; 000; 002 Table II)."""
    pll_leso = dict(zip(("kp_pll", "ki_pll"), (float(g) for g in linear.pll_gains(2 * math.pi * papers.LESO_PLL_HZ))))
    pll_flux = dict(zip(("kp_pll", "ki_pll"), (float(g) for g in linear.pll_gains(2 * math.pi * papers.FLUX_PLL_HZ))))
    k1, k2, lam = linear.wif_symmetric_optimum(papers.WIF_B, papers.WIF_OMEGA_C, omega_n)
    K1, K2 = papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2
    a_o = -math.expm1(-2 * math.pi * 50.0 * 1e-4) / 1e-4  # the matched pole of α_o = 2π·50 at ts = 1e-4 s
    return {
        "SOGIFLL": {"k": papers.SOGI_FLL_K, "lam": float(linear.sogi_fll_lambda(papers.SOGI_FLL_K, omega_n))},
        "SOGIFLLWPF": {"k1": papers.WPF_K1, "k2": papers.WPF_K2, "lam": float(linear.wpf_lambda(omega_n))},
        "SOGIFLLWIF": {"k1": float(k1), "k2": float(k2), "lam": float(lam)},
        "SOIFO": {"k": papers.SOIFO_K, "lam": linear.soifo_lambda(papers.SOIFO_K)},
        "SecondOrderSOIFO": {"K1": K1, "K2": K2, "lam": linear.second_order_soifo_lambda(K1, K2)},
        "LPFFlux": {"omega_c": papers.LPF_OMEGA_C, **pll_flux},
        "CLESO": {"omega0": papers.LESO_OMEGA0, **pll_leso},
        "GILESO": {
            "omega0": papers.LESO_OMEGA0,
            "K_r": papers.GILESO_K_R,
            "omega_c": papers.GILESO_OMEGA_C,
            **pll_leso,
        },
        "FALESO": {"k1": papers.FALESO_K1, "k2": papers.FALESO_K2, **pll_leso},
        # Hinkkanen et al. 2018's observer (jaxobs.observers.rofo): motulator's defaults, kθ = 2α', kω = α'²
        "ReducedOrderFluxObserver": {"c_sigma": 0.5, "zeta_inf": 0.2, "k_theta": 2 * a_o, "k_omega": a_o * a_o},
    }


@pytest.mark.parametrize("omega_n", [papers.FLL_OMEGA_N, 2 * math.pi * 60.0])
def test_closed_forms_are_the_rules_numbers_exactly(omega_n):
    old = _old_closed_forms(omega_n)
    for name, info in COMPONENTS.items():
        comp = info.ctor(**{**info.defaults, **({"omega_n": omega_n} if "omega_n" in info.defaults else {})})
        assert info.closed_form(comp) == old[name], name
    # Table I of 001 (the WIF's printed k1, k2, λ to their printed digits)
    wif = registered("wif").cls.closed_form()
    assert (round(float(wif.k1), 3), round(float(wif.k2), 3), round(float(wif.lam))) == (1.815, 0.752, 11559)
    if omega_n == papers.FLL_OMEGA_N:  # without a component: the paper's nominal frequency
        assert closed_form_gains("sogi-fll") == old["SOGIFLL"]


def test_linear_closed_forms_are_the_classmethods():
    for fn, cls in ((linear.sogi_fll_closed_form, jaxobs.SOGIFLL), (linear.wpf_closed_form, jaxobs.SOGIFLLWPF)):
        assert bool(
            jax.tree.all(jax.tree.map(lambda a, b: jnp.all(a == b), fn(omega_n=300.0), cls.closed_form(omega_n=300.0)))
        )
    a, b = linear.wif_closed_form(b=3.0), jaxobs.SOGIFLLWIF.closed_form(b=3.0)
    assert float(a.lam) == float(b.lam) and float(a.k1) == float(b.k1)
    doc = jaxobs.SOGIFLLWIF.closed_form_design.__doc__
    assert "001 eq (34)" in doc and "002 Table II" in jaxobs.CLESO.closed_form_design.__doc__


def test_the_wif_passes_001s_k1_as_the_damping_gain():
    """001 eq (30): the WIF's envelope damping term carries k1, so its filter is 000's second-order SOGI with
    K1 = k2, K2 = k1.  The WIF's first four state rates equal SOGI2's at the WIF's frequency estimate."""
    wif = jaxobs.SOGIFLLWIF(k1=1.8, k2=0.75, lam=1e4)
    sogi2 = jaxobs.SOGI2(K1=0.75, K2=1.8, omega=float(wif.omega_n))
    x = jnp.asarray([0.3, -0.2, 0.5, 0.1, float(wif.omega_n)])
    np.testing.assert_array_equal(np.asarray(wif.f(x, 0.7)[:4]), np.asarray(sogi2.f(x[:4], 0.7)))
    swapped = jaxobs.SOGI2(K1=1.8, K2=0.75, omega=float(wif.omega_n))
    assert not np.allclose(np.asarray(wif.f(x, 0.7)[:4]), np.asarray(swapped.f(x[:4], 0.7)))


def test_omega0_is_read_as_a_flux_observers_omega_init():
    a = jaxobs.SOIFO(0.0, 1.0, 1.4, 0.5, omega0=200.0)
    assert float(a.omega_init) == 200.0 and not hasattr(a, "omega0")
    with pytest.raises(ValueError, match="give the initial speed once"):
        jaxobs.SecondOrderSOIFO(0.0, 1.0, 1.5, 3.0, 0.5, 100.0, omega0=200.0)
    raw = tomllib.loads((Path(__file__).parents[1] / "tuning" / "presets" / "soifo.toml").read_text())
    raw["component"] = {"omega0": 300.0}
    job = parse_job(raw)
    assert job.values["omega_init"] == 300.0 and "omega0" not in job.values


# the numbers printed before the designs printed their own rows (same values, now with units and every row)
CLOSED_FORM_TEXT = {
    ("wif",): (
        "wif (001 eq (34), Table I): omega_c = 118.124, b = 2.41421, omega_n = 314.159\n"
        "  k1                       1.81549 1         k1 = 2bωc/ωn                                        001 eq (34)\n"
        "  k2                         0.752 1         k2 = 2ωc/ωn                                         001 eq (34)\n"
        "  lam                      11559.3 rad2 s-2  λ = 2ωc²/b                                          001 eq (34)\n"
        "  phase_margin_deg              45 degree    PM = atan((b²−1)/(2b))                              001 eq (39)\n"
    ),
    ("cleso", "--rs", "0.5", "--lq", "0.012"): (
        "cleso (002 Table II (ω0 = 500π), PLL pole placement ω_b = 2π·15): omega0 = 1570.8, pll_hz = 15, "
        "Rs = 0.5, Lq = 0.012, omega0_pll = 0\n"
        "  omega0                    1570.8 rad s-1   chosen: ω0 = 500π                                   "
        "002 Table II\n"
        "  l1                       3099.93 s-1       l1 = 2ω0 − μ, μ = Rs/Lq                             002 eq (16)\n"
        "  l2                    2.4674e+06 s-2       l2 = ω0²                                            002 eq (16)\n"
        "  kp_pll                   133.286 s-1       k_p = 2ζω_b, ω_b = 2π·pll_hz, ζ = 1/√2              "
        "ours (module doc: 002's ramp pins 15 Hz)\n"
        "  ki_pll                   8882.64 s-2       k_i = ω_b²                                          "
        "ours (module doc: 002's ramp pins 15 Hz)\n"
    ),
}


@pytest.mark.parametrize("args", list(CLOSED_FORM_TEXT))
def test_closed_form_command_prints_the_same_table(args, capsys):
    assert main(["closed-form", *args]) == 0
    assert capsys.readouterr().out == CLOSED_FORM_TEXT[args]


def test_closed_form_command_json_values(capsys):
    assert main(["closed-form", "sogi-fll", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["inputs"] == {"k": papers.SOGI_FLL_K, "omega_n": papers.FLL_OMEGA_N, "zeta": papers.FLL_ZETA}
    assert [g["value"] for g in res["gains"]] == [
        papers.SOGI_FLL_K,
        float(linear.sogi_fll_lambda(papers.SOGI_FLL_K, papers.FLL_OMEGA_N)),
    ]
    assert main(["closed-form", "wpf", "--zeta", "-1"]) == 2
    assert "--zeta must be finite and > 0" in capsys.readouterr().err


def _tree_equal(a, b) -> bool:
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    return len(la) == len(lb) and all(bool(jnp.all(x == y)) for x, y in zip(la, lb))


@pytest.mark.parametrize("name", list(REGISTRY))
def test_every_registered_class_has_a_closed_form_design_with_a_row_per_gain(name):
    """closed_form_design is the one rule: closed_form is its observer, every gain has a row in the gain's
    declared units with the observer's value, and the record's inputs are the method's arguments."""
    cls = REGISTRY[name].cls
    d = cls.closed_form_design()
    assert isinstance(d, ClosedForm) and type(d.observer) is cls and _tree_equal(d.observer, cls.closed_form())
    rows = {r.name: r for r in d.rows}
    assert len(rows) == len(d.rows) and d.source and d.rule.startswith(d.source)
    for g, info in gain_fields(cls).items():
        assert rows[g].units == info.units and float(rows[g].value) == float(getattr(d.observer, g)), (name, g)
    for r in d.rows:
        assert r.formula and r.source and r.units, (name, r)
    assert tuple(d.inputs) == CF_OPTIONS[REGISTRY[name].aliases[0]], name


def test_closed_form_offers_every_registered_design_and_keeps_no_formulas():
    assert set(CF_DESIGNS.values()) == {e.cls for e in REGISTRY.values()}
    flux = {jaxobs.PureIntegratorFlux, jaxobs.LPFFlux, jaxobs.SOIFO, jaxobs.SecondOrderSOIFO}
    assert flux <= set(CF_DESIGNS.values())
    # the command prints the designs' rows as they are: no formula of its own (no paper symbol in its source)
    src = inspect.getsource(cli_papers)
    assert not any(sym in src for sym in ("λ", "ω", "μ", "²", "eq (")), [s for s in ("λ", "ω", "μ", "²") if s in src]


@pytest.mark.parametrize("alias", ["soifo", "second-order-soifo", "lpf", "integrator", "gileso", "faleso", "rofo"])
def test_closed_form_command_prints_the_flux_observers_and_lesos(alias, capsys):
    assert main(["closed-form", alias, "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    cls = CF_DESIGNS[alias]
    got = {g["name"]: g["value"] for g in res["gains"]}
    assert {g: got[g] for g in gain_fields(cls)} == closed_form_gains(alias)
    assert res["source"] == cls.closed_form_design().source


def test_closed_form_command_sets_a_flux_observers_input(capsys):
    assert main(["closed-form", "soifo", "--k", "2.0", "--json"]) == 0
    got = {g["name"]: g["value"] for g in json.loads(capsys.readouterr().out)["gains"]}
    assert got == {"k": 2.0, "lam": 1.0}  # lam = k²/4
    assert main(["closed-form", "second-order-soifo", "--k1", "2.0", "--k2", "4.0", "--json"]) == 0
    got = {g["name"]: g["value"] for g in json.loads(capsys.readouterr().out)["gains"]}
    assert got == {"K1": 2.0, "K2": 4.0, "lam": 1.0}  # lam = K1³/(2K2)


@pytest.mark.parametrize("name", list(REGISTRY))
def test_one_check_enforces_every_gains_declared_bounds(name):
    """AbstractObserver.__check_init__ (check_gains) refuses each gain at its declared bound, naming the class,
    the gain and the range; no constructor checks a gain by hand any more."""
    entry = REGISTRY[name]
    cls = entry.cls
    kwargs = {**entry.defaults, **closed_form_gains(name)}
    cls(**kwargs)
    for g, info in gain_fields(cls).items():
        lo, _ = info.bounds
        with pytest.raises(ValueError, match=rf"^{name}\.{g} must be finite and > {lo:g}, got"):
            cls(**{**kwargs, g: lo})
        assert f'"{g}"' not in inspect.getsource(cls.__init__), (name, g)


def test_002_eq_16_is_written_once():
    """l1 = 2ω0 − μ, l2 = ω0² (002 eq 16): the C-LESO runs it, the GI-LESO's L1 is it, linear and the rows
    report it, all from jaxobs.observers.cleso_gains."""
    w0, rs, lq = 900.0, 0.7, 0.011
    l1, l2 = (float(x) for x in jaxobs.observers.cleso_gains(w0, rs / lq))
    g = linear.cleso_closed_form(w0, rs, lq)
    rows = {r.name: float(r.value) for r in jaxobs.CLESO.closed_form_design(omega0=w0, Rs=rs, Lq=lq).rows}
    assert (float(g.l1), float(g.l2)) == (l1, l2) == (rows["l1"], rows["l2"]) == (2 * w0 - rs / lq, w0**2)
    # the observer runs it: with ε = x̂1 − i and x̂2 = 0 the C-LESO's x̂1 rate is b0 u − μ x̂1 − l1 ε
    obs = jaxobs.CLESO(rs, lq, w0)
    xl = jnp.asarray([1.0, 0.0, 0.0, 0.0])
    dxl, _ = obs.leso(xl, jnp.zeros(2), jnp.zeros(2), 0.0)
    assert float(dxl[0]) == pytest.approx(-rs / lq - l1, rel=1e-12) and float(dxl[2]) == pytest.approx(-l2, rel=1e-12)
    src = "".join(p.read_text() for p in (Path(jaxobs.__file__).parent).rglob("*.py"))
    assert src.count("2 * omega0 - mu") == 1 and "2 * self.omega0 - mu" not in src


def test_registry_holds_no_formulas_or_models():
    """The registry keeps application facts; the classes declare their closed form, small-signal model and
    whether a job may tune them."""
    fields = {f.name for f in dataclasses.fields(REGISTRY["SOGIFLL"])}
    assert not fields & {"closed_form_source", "closed_form_rule", "model", "tunable"}
    src = inspect.getsource(registry_module)
    assert not re.search(r"\blambda\b", src) and "eq (" not in src
    assert REGISTRY["SOIFO"].model is not None and REGISTRY["CLESO"].model is None
    for e in REGISTRY.values():
        if e.cls.small_signal_model is not None:
            fn, args = e.cls.small_signal_model
            assert callable(getattr(linear, fn)) and set(args) <= {f.name for f in dataclasses.fields(e.cls)}
    assert REGISTRY["PureIntegratorFlux"].tunable is False and "integration constant" in (
        jaxobs.PureIntegratorFlux.why_not_tunable
    )
