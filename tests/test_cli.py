"""The command line: the main job's demo and its error handling."""

import json
import math
import subprocess
import sys

import pytest

from jaxobs.cli import main


def test_demo_json_rows_and_figure(tmp_path, capsys):
    rc = main(["demo", "--out", str(tmp_path), "--json"])
    assert rc == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["test"] for r in rows} == {"A", "B", "C", "D", "E"}
    assert {r["fll"] for r in rows} == {"SOGI-FLL", "SOGI-FLL-WPF", "SOGI-FLL-WIF"}
    a = [r for r in rows if r["test"] == "A"]
    assert all(math.isfinite(r["settle_cycles"]) for r in a)
    assert (tmp_path / "fll_tests_A_E.png").stat().st_size > 10_000


def test_bad_arguments_exit_with_one_line():
    for argv in (["demo", "--t-event", "-1"], ["nonsense"], ["demo", "--t-event", "abc"]):
        p = subprocess.run([sys.executable, "-m", "jaxobs.cli", *argv], capture_output=True, text=True)
        assert p.returncode == 2, (argv, p.stderr)
        lines = p.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("jaxobs: error:"), p.stderr
        assert "Traceback" not in p.stderr


def test_closed_form_json_reports_formula_and_source(capsys):
    assert main(["closed-form", "wif", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    gains = {g["name"]: g for g in res["gains"]}
    assert round(gains["k1"]["value"], 3) == 1.815 and round(gains["k2"]["value"], 3) == 0.752
    assert round(gains["lam"]["value"]) == 11559
    assert gains["lam"]["source"] == "001 eq (34)" and "2ωc²/b" in gains["lam"]["formula"]
    assert main(["closed-form", "cleso", "--rs", "0.5", "--lq", "0.012", "--omega0", "1000"]) == 0
    out = capsys.readouterr().out
    assert "l2" in out and "1e+06" in out


def test_closed_form_bad_options_exit_2(capsys):
    assert main(["closed-form", "wif", "--k", "2"]) == 2
    assert "--k does not apply to wif" in capsys.readouterr().err
    assert main(["closed-form", "cleso"]) == 2
    assert "--rs" in capsys.readouterr().err
    assert main(["closed-form", "sogi-fll", "--zeta", "-1"]) == 2
    assert "zeta" in capsys.readouterr().err


def test_bode_figures(tmp_path):
    assert main(["bode", "--out", str(tmp_path)]) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["bode_fll_open_loop_001_fig14.png", "bode_flux_observers_000_fig5.png", "bode_lesos_002_fig4.png"]


@pytest.mark.slow
def test_reproduce_flux_quick_json(tmp_path, capsys):
    """The paper-000 reproduction runs end to end (about a minute) and prints comparable rows."""
    assert main(["reproduce", "flux", "--quick", "--json", "--out", str(tmp_path)]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {"experiment", "observer", "metric", "unit", "paper", "ours"} <= set(rows[0])
    by = {(r["experiment"], r["observer"], r["metric"]): r for r in rows}
    lpf = by[("du_alpha = 5 V at 1000 r/min", "LPF", "flux_offset")]
    assert lpf["paper"] == 0.05 and lpf["ours"] == pytest.approx(0.05, rel=0.02)
    assert by[("speed 400-2000-400 r/min", "second-order SOIFO", "max_abs")]["ours"] < 0.2
    assert len(list(tmp_path.glob("*.png"))) == 5
