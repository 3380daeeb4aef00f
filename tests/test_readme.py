"""Every python block of the README runs as written, in order, in one fresh process (what a new user does)."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_readme_python_blocks_run_in_order(tmp_path):
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S)
    assert len(blocks) >= 3
    script = tmp_path / "readme.py"
    script.write_text("\n".join(blocks))
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=tmp_path, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    # the first block prints the SOGI-FLL-WIF's frequency estimate after Test A's 50 → 52 Hz step
    assert abs(float(r.stdout.split()[0]) - 52.0) < 1e-3, r.stdout
