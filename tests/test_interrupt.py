"""Ctrl-C on `jaxobs tune` says how to continue, rerunning over the checkpoint names --resume first, and a run
stopped at any iteration and resumed writes the same files, byte for byte, as one run uninterrupted.

The stops are injected at chosen iterations (the solver's testing hook ``jaxobs_tuning.solvers._at_iteration``),
not timed against a running process: in this process a KeyboardInterrupt (what Python's SIGINT handler raises),
and once in a child process a real SIGINT that the process sends itself at its iteration 3."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

import jaxobs_tuning.solvers as solvers
from jaxobs_tuning.cli import main

ROOT = Path(__file__).parents[1]

# 6 iterations, a checkpoint every 2: the stops below land before the first checkpoint, on one, and between two
JOB = """
[job]
name = "interrupt-me"
component = "SOGIFLL"
[gains.lam]
init = 12337.0
lower = 1000.0
upper = 200000.0
[scenarios]
t_event = 0.05
horizon = 0.1
[scenarios.grid]
freq_step = [-2.0, 2.0]
[objective]
terms = [{ metric = "itae_freq", weight = 1.0 }]
[solver]
kind = "adam"
learning_rate = 0.05
steps = 6
patience = 100
checkpoint_every = 2
"""

VARYING = {"timing.json"}  # wall-clock seconds; every other file of the results folder is compared byte for byte


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The job file and the results folder of one uninterrupted run."""
    d = tmp_path_factory.mktemp("interrupt")
    job = d / "job.toml"
    job.write_text(JOB)
    assert main(["tune", str(job), "--out", str(d / "ref"), "--quiet"]) == 0
    return job, d / "ref"


def _stop_at(i: int):
    def hook(it):
        if it == i:
            raise KeyboardInterrupt

    return hook


def _assert_same_results(out: Path, ref: Path):
    names = sorted(p.name for p in ref.iterdir())
    assert sorted(p.name for p in out.iterdir()) == names
    assert {"result.json", "history.json", "scores.nc", "checkpoint.npz"} <= set(names)
    for name in set(names) - VARYING:
        assert (out / name).read_bytes() == (ref / name).read_bytes(), name


@pytest.mark.parametrize("i", [0, 3, 4])
def test_tune_stopped_at_an_iteration_then_resumed_is_byte_identical(reference, tmp_path, monkeypatch, capsys, i):
    """Stopped before iteration 0 (no checkpoint yet), 3 (one iteration past the checkpoint of iteration 2: it
    is computed again) or 4 (just after a checkpoint), then ``--resume``: the same results as one run."""
    job, ref = reference
    out = tmp_path / "o"
    monkeypatch.setattr(solvers, "_at_iteration", _stop_at(i))
    assert main(["tune", str(job), "--out", str(out), "--quiet"]) == 130
    monkeypatch.setattr(solvers, "_at_iteration", None)
    assert not (out / "result.json").exists()
    assert (out / "checkpoint.npz").exists() == (i >= 2)
    if i >= 2:
        last = capsys.readouterr().err.strip().splitlines()[-1]
        assert last == f"jaxobs: interrupted; continue with: jaxobs tune {job} --out {out} --resume", last
    assert main(["tune", str(job), "--out", str(out), "--quiet", "--resume"]) == 0
    _assert_same_results(out, ref)


def test_rerun_over_a_checkpoint_names_resume_first(reference, tmp_path, monkeypatch, capsys):
    job, _ = reference
    out = tmp_path / "o"
    monkeypatch.setattr(solvers, "_at_iteration", _stop_at(3))
    assert main(["tune", str(job), "--out", str(out), "--quiet"]) == 130
    monkeypatch.setattr(solvers, "_at_iteration", None)
    capsys.readouterr()
    # the same command again, without --resume: refused, naming --resume before --force
    assert main(["tune", str(job), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "continue it with `jaxobs tune" in err[0] and err[0].index("--resume") < err[0].index("--force"), err
    assert not (out / "result.json").exists()


# the command line with the solver's hook set to send this process a real SIGINT at its iteration 3.  SIGINT
# handled by Python and not blocked first, as in a shell's foreground job: a child inherits both from pytest, and a
# suite started in the background (``make test &`` in a script, ``nohup``) has SIGINT ignored, which Python keeps
_SIGINT_AT_3 = """
import os, signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)
signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
import jaxobs_tuning.solvers as solvers
from jaxobs_tuning.cli import main

def hook(it):
    if it == 3:
        os.kill(os.getpid(), signal.SIGINT)

solvers._at_iteration = hook
sys.exit(main(sys.argv[1:]))
"""


def test_a_real_sigint_at_iteration_3_exits_130_naming_resume(reference, tmp_path):
    """The signal itself, in a process of its own: Python's handler turns it into the KeyboardInterrupt the
    command line reports (exit 130, one line naming --resume); the resumed run equals the uninterrupted one."""
    job, ref = reference
    out = tmp_path / "o"
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    p = subprocess.run(
        [sys.executable, "-c", _SIGINT_AT_3, "tune", str(job), "--out", str(out), "--quiet"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert p.returncode == 130, p.stderr[-3000:]
    last = p.stderr.strip().splitlines()[-1]
    assert last == f"jaxobs: interrupted; continue with: jaxobs tune {job} --out {out} --resume", p.stderr[-3000:]
    assert main(["tune", str(job), "--out", str(out), "--quiet", "--resume"]) == 0
    _assert_same_results(out, ref)


def test_no_command_lists_the_commands(capsys):
    assert main([]) == 2
    err = capsys.readouterr().err
    for cmd in ("tune", "study", "export", "closed-form", "reproduce"):
        assert f"    {cmd}" in err, err


def test_closed_form_error_names_the_flag(capsys):
    assert main(["closed-form", "wif", "--b", "-1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "jaxobs: error: --b must be finite and > 1, got -1", err
