"""Drive files (jaxobs.drive.drivefile) and `jaxobs drive check`: the issue's exact keys, broken files (one line
naming the key), the shipped benches equal to bench_machine / bench_drive leaf by leaf, a machine from public
data.  No simulation: every test here is cheap."""

from __future__ import annotations

import math
from pathlib import Path

import jax
import numpy as np
import pytest

import jaxobs
from jaxobs import papers
from jaxobs.drive import Inverter, bench_drive, bench_machine, ipmsm_paper002, load_drive, read_drive, spmsm_paper000
from jaxobs_tuning.cli import main

ROOT = Path(__file__).parents[1]
DATA = Path(jaxobs.__file__).parent / "data"
TEKNIC = ROOT / "docs" / "examples" / "teknic_m2310p.toml"

# the issue's file, exactly its keys
ISSUE = """\
[machine]
p = 4                      # pole pairs
Rs = 0.45                  # Ω
Ld = 0.0028                # H
Lq = 0.0041                # H
psi_f = 0.11               # Wb, peak (amplitude-invariant)
J = 0.0012                 # kg·m²
rated_speed_rpm = 3000
rated_torque_nm = 3.2
rated_current_a = 4.0      # rms phase current
[inverter]
u_dc = 320.0               # V
f_sample_hz = 16000.0      # control and PWM period = 1/f_sample_hz
"""


def _check(tmp_path, text, capsys):
    path = tmp_path / "drive.toml"
    path.write_text(text)
    rc = main(["drive", "check", "--no-cache", str(path)])
    out, err = capsys.readouterr()
    return rc, out, err


def test_the_issue_file_passes_and_prints_the_derived_values(tmp_path, capsys):
    rc, out, err = _check(tmp_path, ISSUE, capsys)
    assert rc == 0, err
    keys = "base_speed_rpm emf_speed_rpm max_speed_fw_rpm i_char tau_d tau_q alpha_c alpha_s kp_d ki_q kp_w ki_w"
    for key in (*keys.split(), "i_max", "id_policy", "field_weakening", "if_current"):
        assert f" {key} " in out, key
    assert "lowest speed at which each observer family closes the speed loop" in out
    f = read_drive(tmp_path / "drive.toml")
    d = {k: v.value for k, v in f.derived.items()}
    # the rules, recomputed: IMC at a 60° phase margin with 1.5 periods of delay at 16 kHz
    assert d["alpha_c"] == pytest.approx((math.pi / 6) / (1.5 / 16000.0), rel=1e-12)
    assert d["current_phase_margin"] == pytest.approx(60.0, rel=1e-12)
    # a decade below the current loop, or a third of the 15 Hz PLL: the PLL binds
    assert d["alpha_s"] == pytest.approx(min(d["alpha_c"] / 10, 2 * math.pi * 15 / 3), rel=1e-12)
    assert d["i_max"] == pytest.approx(1.5 * math.sqrt(2) * 4.0, rel=1e-12)
    assert d["id_policy"] == "mtpa" and f.drive.foc.id_mode == "mtpa"  # Lq > Ld
    assert d["field_weakening"] is False and f.drive.foc.field_weakening is None
    assert d["speed_every"] == 16 and f.drive.ts == 1 / 16000.0
    assert d["i_char"] == pytest.approx(0.11 / 0.0028, rel=1e-12)
    # without field weakening the highest speed to ask for is where the back EMF alone reaches u_dc/√3
    assert (
        d["speed_limit_rpm"] == d["emf_speed_rpm"] == pytest.approx(320 / math.sqrt(3) / 0.11 / 4 * 60 / (2 * math.pi))
    )
    # the FLL flux observers close the loop from ωe = 4.3 α_s (docs/stability.md)
    fll = f.lowest_speeds["FLL flux observers (SOIFO, SecondOrderSOIFO)"][0]
    assert fll == pytest.approx(4.3 * d["alpha_s"] / 4 * 60 / (2 * math.pi), rel=1e-12)
    # the base speed is where the rated point's |u| reaches u_dc/√3, at MTPA's currents: the least |i| of
    # rated torque, found here by brute force over i_d
    i_d = np.linspace(-3.0, 0.0, 300_001)
    i_q = 3.2 / (1.5 * 4 * (0.11 + (0.0028 - 0.0041) * i_d))
    k = np.argmin(np.hypot(i_d, i_q))
    assert d["i_rated_point"] == pytest.approx(np.hypot(i_d[k], i_q[k]), rel=1e-9)
    w = d["base_speed_rpm"] * 4 * 2 * math.pi / 60
    u = math.hypot(0.45 * i_d[k] - w * 0.0041 * i_q[k], 0.45 * i_q[k] + w * (0.0028 * i_d[k] + 0.11))
    assert u == pytest.approx(320 / math.sqrt(3), rel=1e-5)  # the grid's i_d step, 1e-5 A


BROKEN = {
    "negative inductance": ("Ld = 0.0028", "Ld = -0.0028", "machine.Ld"),
    "zero inductance": ("Lq = 0.0041", "Lq = 0.0", "machine.Lq"),
    "fractional p": ("p = 4 ", "p = 4.5 ", "machine.p"),
    "p zero": ("p = 4 ", "p = 0 ", "machine.p"),
    "u_dc too low": ("u_dc = 320.0", "u_dc = 150.0", "inverter.u_dc"),
    "unknown key": ("J = 0.0012", "J = 0.0012\nJm = 1.0", "machine.Jm"),
    "unknown table": ("[inverter]", "[motor]\nx = 1\n[inverter]", "motor"),
    "missing required": ("psi_f = 0.11", "", "machine.psi_f"),
    "bandwidth too high": (
        "f_sample_hz = 16000.0",
        "f_sample_hz = 16000.0\n[control]\ncurrent_bandwidth_hz = 2500.0",
        "control.current_bandwidth_hz",
    ),  # fmt: skip
    "speed loop above the current loop": (
        "f_sample_hz = 16000.0",
        "f_sample_hz = 16000.0\n[control]\ncurrent_bandwidth_hz = 300.0\nspeed_bandwidth_hz = 100.0",
        "control.speed_bandwidth_hz",
    ),
    "sampling too slow": ("f_sample_hz = 16000.0", "f_sample_hz = 50.0", "inverter.f_sample_hz"),
    "rated torque beyond the current limit": (
        "rated_torque_nm = 3.2",
        "rated_torque_nm = 9.0",
        "machine.rated_torque_nm",
    ),
    "string for a number": ("Rs = 0.45", 'Rs = "0.45"', "machine.Rs"),
    "ADC range below the limit": (
        "f_sample_hz = 16000.0",
        "f_sample_hz = 16000.0\n[sensors]\nadc_bits = 12\nadc_range_a = 2.0",
        "sensors.adc_range_a",
    ),  # fmt: skip
    "id policy": ("f_sample_hz = 16000.0", 'f_sample_hz = 16000.0\n[control]\nid_policy = "max"', "control.id_policy"),
    "startup above rated speed": (
        "f_sample_hz = 16000.0",
        "f_sample_hz = 16000.0\n[startup]\nswitch_rpm = 4000.0",
        "startup.switch_rpm",
    ),  # fmt: skip
    "dual without its xy inductance": (
        "f_sample_hz = 16000.0",
        'f_sample_hz = 16000.0\n[dual]\nmode = "vsd"',
        "dual.Lls",
    ),  # fmt: skip
    "dual mode": ("f_sample_hz = 16000.0", 'f_sample_hz = 16000.0\n[dual]\nLls = 0.001\nmode = "both"', "dual.mode"),
    "dual with another DSP timing": (
        "f_sample_hz = 16000.0",
        "f_sample_hz = 16000.0\ncompute_delay = 0\n[dual]\nLls = 0.001",
        "inverter.compute_delay",
    ),  # fmt: skip
    "tiny rated torque": ("rated_torque_nm = 3.2", "rated_torque_nm = 1e-300", "machine.rated_torque_nm"),
    "zero rated current": ("rated_current_a = 4.0", "rated_current_a = 0", "machine.rated_current_a"),
    "tiny I-f current": (
        "f_sample_hz = 16000.0",
        "f_sample_hz = 16000.0\n[startup]\ncurrent_a = 1e-300",
        "startup.current_a",
    ),  # fmt: skip
    "I-f current of no torque": (
        "f_sample_hz = 16000.0",
        "f_sample_hz = 16000.0\n[startup]\ncurrent_a = 0.001",
        "startup.current_a",
    ),  # fmt: skip
    "two magnet fluxes": ("psi_f = 0.11", "psi_f = 0.11\nkt_nm_per_a_rms = 0.9", "machine.psi_f"),
    "no magnet flux": ("psi_f = 0.11", "", "machine.psi_f"),
    "zero max speed": ("rated_current_a = 4.0", "rated_current_a = 4.0\nmax_speed_rpm = 0.0", "machine.max_speed_rpm"),
    "tiny inductance": ("Ld = 0.0028", "Ld = 5e-324", "machine.Ld"),
    "dual with q saturation": (
        "rated_current_a = 4.0",
        "rated_current_a = 4.0\nq_sat_current_a = 20.0",
        "machine.q_sat_current_a",
    ),  # fmt: skip (a dual file below: ISSUE_DUAL)
}
# the issue's file as a dual three-phase machine (two sets of the same phases on one shaft, twice the torque)
ISSUE_DUAL = (
    ISSUE.replace("rated_torque_nm = 3.2", "rated_torque_nm = 6.4").replace("J = 0.0012", "J = 0.0024")
    + "[dual]\nLls = 0.0009\n"
)


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_a_broken_file_gives_one_line_naming_the_key(case, tmp_path, capsys):
    old, new, key = BROKEN[case]
    base = ISSUE_DUAL if case == "dual with q saturation" else ISSUE
    assert old in base
    rc, out, err = _check(tmp_path, base.replace(old, new, 1), capsys)
    assert rc == 2, out
    assert err.count("\n") == 1 and err.startswith("jaxobs: error: "), err
    assert key in err, err


def test_a_file_over_1_mb_is_refused_before_it_is_parsed(tmp_path, capsys):
    rc, _, err = _check(tmp_path, ISSUE + "#" * 1_000_001 + "\n", capsys)
    assert rc == 2 and err.count("\n") == 1 and "drive file" in err and "1000000 bytes" in err, err


def test_u_dc_with_field_weakening_is_checked_within_the_current_circle(tmp_path):
    # 160 V: the rated point needs more than u_dc/√3 (so field weakening goes on), and within the current limit a
    # negative i_d reaches it; 100 V: no i_d within the circle does (one line naming u_dc and the least voltage)
    path = tmp_path / "d.toml"
    path.write_text(ISSUE.replace("u_dc = 320.0", "u_dc = 220.0"))
    f = read_drive(path)
    assert f.derived["field_weakening"].value is True and f.drive.foc.field_weakening is not None
    assert f.derived["u_rated_point_fw"].value <= 220 / math.sqrt(3)
    assert f.derived["speed_limit_rpm"].value == f.derived["max_speed_fw_rpm"].value
    path.write_text(ISSUE.replace("u_dc = 320.0", "u_dc = 100.0"))
    with pytest.raises(ValueError, match=r"^inverter\.u_dc: must be >= .* with field weakening"):
        read_drive(path)


def _leaves_equal(a, b):
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    assert ta == tb  # the same structure and the same static fields (ts, speed_every, id_mode, latency, ...)
    for x, y in zip(la, lb, strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-12, atol=0)


@pytest.mark.parametrize("name", ["spmsm000", "ipmsm002"])
def test_the_shipped_bench_files_build_the_benches(name):
    machine, drive = load_drive(DATA / f"{name}.toml")
    # the papers' values on the benches' inertia (bench_machine reads the same shipped file)
    ref = {"spmsm000": spmsm_paper000(J=papers.BENCH_J_000), "ipmsm002": ipmsm_paper002(J=papers.BENCH_J_002)}[name]
    _leaves_equal(machine, ref)
    _leaves_equal(bench_machine(name), ref)
    _leaves_equal(drive, bench_drive(ref))
    f = read_drive(DATA / f"{name}.toml")
    assert f.name == name and f.warnings == ()
    text = (DATA / f"{name}.toml").read_text()
    assert "ASSUMED" in text  # the values the papers leave open are marked


def test_a_shipped_drive_takes_the_precision_in_force_when_it_is_asked_for():
    # the files are read once per precision: parameters read under float32 must not reach a float64 drive (the
    # loop's carry would change dtype in its first step, as a benchmark timing float32 then float64 found)
    with jax.enable_x64(False):
        assert bench_machine("spmsm000").Rs.dtype == np.float32
    assert bench_machine("spmsm000").Rs.dtype == np.float64


def test_a_machine_from_public_data_differs_from_both_benches_and_loads():
    f = read_drive(TEKNIC)
    m, ts, udc = f.machine, f.drive.ts, float(f.drive.inverter.udc)
    for name in ("spmsm000", "ipmsm002"):
        b = bench_machine(name)
        bd = bench_drive(b)
        assert m.p != b.p and ts != bd.ts and udc != float(bd.inverter.udc)
        for leaf in ("Rs", "Ld", "Lq", "psi_f", "J"):
            assert float(getattr(m, leaf)) != float(getattr(b, leaf)), leaf
    # its 24 V link leaves the rated point little headroom: the check says so
    assert any(w.startswith("inverter.u_dc") for w in f.warnings)
    # quantization adds σ = LSB/√12 of a 12-bit ADC over ±16.5 A
    assert float(f.sensors.i_noise) == pytest.approx(2 * 16.5 / 4096 / math.sqrt(12), rel=1e-12)
    assert f.derived["encoder_angle_step"].value == pytest.approx(360 * 4 / 4000, rel=1e-12)


DUAL_330V = ROOT / "docs" / "examples" / "ipmsm002_dual_330v.toml"


def test_a_dual_drive_file_builds_002s_dual_bench_on_330_v():
    """002's dual machine declared by a file ([dual]): the whole machine is jaxobs.drive.dual_ipmsm_paper002's,
    the file's machine one set carrying half the rotor, and the drive the dual bench's on its 330 V link with field
    weakening and the 2.5 Hz speed loop, leaf for leaf (the same derivation as the single benches' files)."""
    from jaxobs.drive import DualDrive, VoltageFeedbackFW, dual_ipmsm_paper002
    from jaxobs.drive.dual_loop import dual_bench_drive

    f = read_drive(DUAL_330V)
    ref = dual_ipmsm_paper002()
    _leaves_equal(f.dual, ref)
    _leaves_equal(f.machine, ref.per_set())
    assert isinstance(f.drive, DualDrive) and f.drive.mode == "vsd" and f.drive.ctrl.fw_voltage == "ab"
    bench = dual_bench_drive(ref, sensorless=True, handover=0.0, inverter=Inverter(udc=330.0),
                             alpha_s=2 * math.pi * 2.5, field_weakening=VoltageFeedbackFW(),
                             speed_every=10, advance=1.5, i_max=float(f.drive.ctrl.foc.i_max))  # fmt: skip
    _leaves_equal(f.drive, bench)
    assert f.derived["kp_xy"].value == pytest.approx(2 * math.pi * 300 * 0.0045, rel=1e-12)
    # a run's drive: the same controller, the run's settle and hand-over
    d = f.drive_for(settle=0.5, handover=0.1)
    assert isinstance(d, DualDrive) and d.settle == 0.5 and d.handover == 0.1
    _leaves_equal(d.ctrl, f.drive.ctrl)


def test_the_dual_check_derives_on_one_set(tmp_path, capsys):
    """``jaxobs drive check`` on a dual file says its values are one set's: the issue's machine twice on one shaft
    (twice its J and rated torque) derives the single file's values, the xy loop's gains besides."""
    rc, out, err = _check(tmp_path, ISSUE_DUAL, capsys)
    assert rc == 0, err
    assert "dual three-phase machine ([dual])" in out and " kp_xy " in out
    (tmp_path / "single.toml").write_text(ISSUE)
    single = read_drive(tmp_path / "single.toml")
    dual = read_drive(tmp_path / "drive.toml")
    for k in ("base_speed_rpm", "alpha_c", "alpha_s", "kp_w", "i_max", "i_rated_point"):
        assert dual.derived[k].value == pytest.approx(single.derived[k].value, rel=1e-12), k
    assert float(dual.dual.m.T_rated) == pytest.approx(6.4) and float(dual.machine.T_rated) == pytest.approx(3.2)


def test_a_dual_drive_file_is_refused_by_tune_in_one_line(tmp_path, capsys):
    """A job on a dual drive file: ``jaxobs tune --check`` exits 2 with one line naming [drive] (only the
    envelope and the check run a dual drive)."""
    job = ROOT / "docs" / "examples" / "ipmsm002_dual_faleso.toml"
    rc = main(["tune", "--check", "--no-cache", str(job)])
    out, err = capsys.readouterr()
    assert rc == 2 and err.count("\n") == 1 and err.startswith("jaxobs: error: drive: "), err
    assert "jaxobs envelope" in err


def test_individual_control_keeps_its_differential_current_loop_stable(tmp_path):
    """Under mode = "individual" the differential (xy) current loop runs r = (L̂ + L̂ls)/(2 L̂ls) times faster than
    α_c (jaxobs.drive._dualfile).  Left to the derivation, α_c is lowered by r so that it keeps the single rule's
    60°; a given bandwidth leaving it under 30° is refused naming dual.mode, under 45° warned; Lls not below Ld and
    fw_voltage under "individual" are warned."""
    ind = ISSUE_DUAL + 'mode = "individual"\n'
    r = (0.0041 + 0.0009) / (2 * 0.0009)
    (tmp_path / "ind.toml").write_text(ind)
    f = read_drive(tmp_path / "ind.toml")
    (tmp_path / "single.toml").write_text(ISSUE)
    single = read_drive(tmp_path / "single.toml")
    assert f.derived["alpha_c"].value == pytest.approx(single.derived["alpha_c"].value / r, rel=1e-12)
    assert f.derived["xy_phase_margin"].value == pytest.approx(60.0, rel=1e-9) and not f.derived["alpha_c"].given
    assert f.drive.mode == "individual" and f.warnings == ()
    given = ind.replace("f_sample_hz = 16000.0", "f_sample_hz = 16000.0\n[control]\ncurrent_bandwidth_hz = 500.0")
    (tmp_path / "warn.toml").write_text(given)
    w = read_drive(tmp_path / "warn.toml")
    assert any(x.startswith("dual.mode:") for x in w.warnings), w.warnings
    assert 40.0 < w.derived["xy_phase_margin"].value < 45.0
    (tmp_path / "bad.toml").write_text(given.replace("500.0", "700.0"))
    with pytest.raises(ValueError, match=r"^dual\.mode: 'individual' runs the differential current loop"):
        read_drive(tmp_path / "bad.toml")
    (tmp_path / "odd.toml").write_text(ind.replace("Lls = 0.0009", "Lls = 0.003") + 'fw_voltage = "set"\n')
    odd = read_drive(tmp_path / "odd.toml")
    assert {x.split(":")[0] for x in odd.warnings} == {"dual.Lls", "dual.fw_voltage"}, odd.warnings


TRACTION = ROOT / "docs" / "examples" / "traction_ipmsm.toml"
LAB = ROOT / "docs" / "examples" / "ipmsm_2p2kw_lab.toml"


@pytest.mark.parametrize(
    "key, value, psi_f",
    [
        # ψf = Ke √2/√3 / (p 2π 1000/60): 0.11 Wb at p = 4 is 37.63 V/krpm line-to-line rms
        ("ke_v_per_krpm_ll_rms", 0.11 * 4 * 2 * math.pi * 1000 / 60 * math.sqrt(1.5), 0.11),
        ("ke_v_per_krpm_ll_peak", 0.11 * 4 * 2 * math.pi * 1000 / 60 * math.sqrt(3.0), 0.11),
        ("kt_nm_per_a_rms", 1.5 * math.sqrt(2.0) * 4 * 0.11, 0.11),  # T = 1.5 √2 p ψf I_rms
    ],
)
def test_datasheet_constants_give_psi_f_with_the_rule_printed(key, value, psi_f, tmp_path, capsys):
    f_ref = jaxobs.drive.drive_from_table(__import__("tomllib").loads(ISSUE))
    text = ISSUE.replace("psi_f = 0.11               # Wb, peak (amplitude-invariant)", f"{key} = {value!r}")
    path = tmp_path / "drive.toml"
    path.write_text(text)
    f = read_drive(path)
    assert float(f.machine.psi_f) == pytest.approx(psi_f, rel=1e-12)
    assert f.derived["psi_f"].given and key in f.derived["psi_f"].rule
    assert f.derived["speed_limit_rpm"].value == pytest.approx(f_ref.derived["speed_limit_rpm"].value, rel=1e-12)


def test_one_speed_limit_for_check_tune_and_envelope():
    """The traction IPMSM's voltage never bounds its speed with field weakening (ψf/Ld = 178 A < 240 A): its
    [machine] max_speed_rpm is the limit (before: inf in drive check, anything in tune, 3 × rated in envelope);
    without it the stated rule, 3 × rated.  The envelope's limit is the file's, from the same function."""
    from jaxobs.analysis.envelope import speed_limit_rpm
    from jaxobs.drive.drivefile import MECH_SPEED_PU

    f = read_drive(TRACTION)
    d = f.derived
    assert d["field_weakening"].value and math.isinf(d["max_speed_fw_rpm"].value)
    assert f.speed_limit_rpm == 12000.0 and "max_speed_rpm" in d["speed_limit_rpm"].rule and d["speed_limit_rpm"].given
    assert speed_limit_rpm(f.machine, f.drive, 12000.0) == f.speed_limit_rpm
    raw = __import__("tomllib").loads(TRACTION.read_text())
    del raw["machine"]["max_speed_rpm"]
    g = jaxobs.drive.drive_from_table(raw)
    assert g.speed_limit_rpm == MECH_SPEED_PU * 3000.0 == speed_limit_rpm(g.machine, g.drive)
    assert "3 × rated_speed_rpm" in g.derived["speed_limit_rpm"].rule
    # a finite voltage bound: the file, the envelope and the bench's function agree to the bit
    for path in (LAB, DATA / "ipmsm002.toml"):
        h = read_drive(path)
        assert speed_limit_rpm(h.machine, h.drive) == h.speed_limit_rpm
    b = read_drive(DATA / "spmsm000.toml")
    assert jaxobs.drive.drive_speed_limit_rpm(b.machine) == b.speed_limit_rpm


def test_if_current_respects_the_rated_current_and_fw_turns_on_at_its_margin():
    """The traction IPMSM's I-f current is half its 240 A rated peak (T_rated/K_t would give 227 A before
    the rated current's check, 270 A at 160.6 N·m); the lab IPMSM's rated point needs 95.05 % of u_dc/√3, above
    the 0.95 margin, so field weakening is on by default; the benches keep theirs (off, and T_rated/K_t)."""
    f = read_drive(TRACTION)
    assert f.derived["if_current"].value == pytest.approx(0.5 * 240.0, rel=1e-12)
    raw = __import__("tomllib").loads(LAB.read_text())
    del raw["control"]["field_weakening"]
    g = jaxobs.drive.drive_from_table(raw)
    assert g.derived["field_weakening"].value and not g.derived["field_weakening"].given
    assert g.derived["u_rated_point"].value > 0.95 * g.derived["u_max"].value
    for name in ("spmsm000", "ipmsm002"):
        b = read_drive(DATA / f"{name}.toml")
        assert not b.derived["field_weakening"].value
        assert b.derived["if_current"].value == float(papers.IF_CURRENT_PU * b.machine.i_rated)


def test_tune_and_study_refuse_a_speed_above_the_files_limit():
    """tune and study check their speed axes against the file's one limit: 50 000 r/min on the traction IPMSM
    (accepted before, when its limit was inf) is refused in one line naming the field and the rule."""
    from jaxobs_tuning.job import JobError, check_speed_axes

    f = read_drive(TRACTION)
    with pytest.raises(
        JobError, match=r"speed_rpm\[0\]: must be in \[1, 12000\] r/min on traction_ipmsm \(speed_limit_rpm"
    ):
        check_speed_axes({"speed_rpm": [50000.0]}, "scenarios.grid", "traction_ipmsm", f)
    check_speed_axes({"speed_rpm": [11000.0]}, "scenarios.grid", "traction_ipmsm", f)


def test_a_saturation_map_sets_the_speed_limit_and_the_base_speed():
    """The saturated PM-SyRM: its speed limit is the map's no-load bound at the FOC's stop i_d = −i_max (|ψ| =
    0.100 Vs: 14869 r/min; the constants' ψf − Ld i_max = 0.078 Vs claimed 19131), the same in drive check and
    the envelope; its base speed is where the map's flux at the rated torque's currents reaches u_max (1472 r/min;
    the constants gave 1424)."""
    from jaxobs.analysis.envelope import speed_limit_rpm
    from jaxobs.drive._steady import policy_currents
    from jaxobs.drive.weakening import map_flux_at, map_speed_flux

    f = read_drive(ROOT / "docs" / "examples" / "pmsyrm_5p6kw_sat.toml")
    m, d = f.machine, f.derived
    i_max, u_max = float(d["i_max"].value), float(d["u_max"].value)
    flux, at_stop = map_speed_flux(m, i_max, True), map_flux_at(m, -i_max, 0.0)
    assert flux is not None and at_stop is not None
    pd, pq = at_stop
    assert flux == pytest.approx(math.hypot(pd, pq), rel=1e-6) and 0.09 < flux < 0.11
    n_lim = u_max / flux / m.p * 60 / (2 * math.pi)
    assert f.speed_limit_rpm == pytest.approx(n_lim, rel=1e-12) == d["max_speed_fw_rpm"].value
    assert 14800 < f.speed_limit_rpm < 14900 and "map" in d["speed_limit_rpm"].rule
    assert speed_limit_rpm(m, f.drive) == f.speed_limit_rpm  # one rule: the envelope's is the file's
    assert float(f.capability([0.9 * f.speed_limit_rpm])["torque"][0]) > 0  # within fw_margin of it: torque left
    # the base speed: the steady |u| at the rated torque's currents on the map reaches u_max there
    i_d, i_q = policy_currents({"p": m.p, "Ld": float(m.Ld), "Lq": float(m.Lq), "psi_f": float(m.psi_f)}, "mtpa",
                               float(m.T_rated))  # fmt: skip
    at_rated = map_flux_at(m, i_d, i_q)
    assert at_rated is not None
    pd, pq = at_rated
    w = float(d["base_speed_rpm"].value) * m.p * jaxobs.drive.RPM
    u = math.hypot(float(m.Rs) * i_d - w * pq, float(m.Rs) * i_q + w * pd)
    assert u == pytest.approx(u_max, rel=1e-9)
    assert 1460 < float(d["base_speed_rpm"].value) < 1480 and "map" in d["base_speed_rpm"].rule
