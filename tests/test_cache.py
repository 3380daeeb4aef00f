"""The persistent compilation cache (jaxobs.use_compile_cache, the command line's default)."""

import os
import subprocess
import sys
from pathlib import Path

import jax
import pytest

import jaxobs
from jaxobs.runtime.cache import CACHE_ENV

ROOT = Path(__file__).parents[1]


@pytest.fixture
def restore_cache_config():
    before = (jax.config.jax_compilation_cache_dir, jax.config.jax_persistent_cache_min_compile_time_secs)
    yield
    jax.config.update("jax_compilation_cache_dir", before[0])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", before[1])


def test_cache_folder_order(tmp_path, monkeypatch, restore_cache_config):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "env"))
    assert jaxobs.use_compile_cache() == tmp_path / "env"  # the environment variable
    assert jax.config.jax_compilation_cache_dir == str(tmp_path / "env")
    assert (tmp_path / "env").is_dir()
    assert jaxobs.use_compile_cache(tmp_path / "arg", min_compile_s=2.0) == tmp_path / "arg"  # the argument wins
    assert jax.config.jax_persistent_cache_min_compile_time_secs == 2.0
    for off in ("off", "0", ""):
        monkeypatch.setenv(CACHE_ENV, off)
        assert jaxobs.use_compile_cache() is None
    assert jax.config.jax_compilation_cache_dir == str(tmp_path / "arg")  # "off" changed nothing
    monkeypatch.delenv(CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert jaxobs.use_compile_cache() == tmp_path / "xdg" / "jaxobs" / "jax"


def test_cache_bad_input(tmp_path, restore_cache_config):
    with pytest.raises(ValueError, match="min_compile_s must be a number >= 0"):
        jaxobs.use_compile_cache(tmp_path, min_compile_s=-1)
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="JAXOBS_CACHE_DIR: cannot create"):
        jaxobs.use_compile_cache(tmp_path / "file" / "sub")


_PROBE = """
import sys
from jaxobs_tuning import cli, cli_run
real = cli_run.use_compile_cache
cli_run.use_compile_cache = lambda: print("CACHE", real())
sys.exit(cli.main(sys.argv[1:]))
"""


@pytest.mark.parametrize("extra, expect", [([], "set"), (["--no-cache"], None)])
def test_cli_uses_cache_unless_told(tmp_path, extra, expect):
    env = {**os.environ, CACHE_ENV: str(tmp_path / "c"), "JAX_PLATFORMS": "cpu"}
    r = subprocess.run(
        [sys.executable, "-c", _PROBE, "closed-form", "sogi-fll", *extra],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    lines = [x for x in r.stdout.splitlines() if x.startswith("CACHE")]
    assert lines == ([] if expect is None else [f"CACHE {tmp_path / 'c'}"])
    assert "sogi" in r.stdout.lower()  # the command itself ran
