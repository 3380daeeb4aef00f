"""The command line: the main job's demo and its error handling."""

import json
import math
import subprocess
import sys

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
