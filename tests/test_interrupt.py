"""Ctrl-C on `jaxobs tune` says how to continue, and rerunning over the checkpoint names --resume first.
A real SIGINT to a real process, not a raised KeyboardInterrupt."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).parents[1]

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
[solver]                # runs until interrupted: no stopping rule can end it between its first checkpoint
kind = "adam"           # and the SIGINT (under load the test's SIGINT came after adam had stopped on its
learning_rate = 0.01    # own patience, and the process exited 0)
steps = 100000
patience = 100000
tol = 0.0
"""


def _as_from_a_terminal():
    """In the child before exec: SIGINT handled by default and not blocked, as a shell's foreground job has it.
    A child inherits both from pytest, and a suite started in the background (``make test &`` in a script,
    ``nohup``) has SIGINT ignored: Python then leaves it ignored, and the tune process outlived its SIGINT
    by 120 s (seen in three background runs of the suite; reproduced by running this test with SIGINT
    ignored, and gone with this reset)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _signals(pid) -> str:
    """The SigBlk / SigIgn / SigCgt masks of a process (Linux), for a failure's message."""
    try:
        lines = Path(f"/proc/{pid}/status").read_text().splitlines()
    except OSError:
        return "?"
    return " ".join(line.replace("\t", "") for line in lines if line.startswith(("SigBlk", "SigIgn", "SigCgt")))


def _run(args, **kw):
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "JAXOBS_HOST_DEVICES": "1"}
    return subprocess.Popen(
        [sys.executable, "-m", "jaxobs", *args],
        cwd=ROOT,
        env=env,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_as_from_a_terminal,
        **kw,
    )


def test_ctrl_c_names_resume_and_rerun_names_resume_first(tmp_path):
    job, out = tmp_path / "job.toml", tmp_path / "out"
    job.write_text(JOB)
    p = _run(["tune", str(job), "--out", str(out)], stdout=subprocess.DEVNULL)
    deadline = time.monotonic() + 240
    while not (out / "checkpoint.npz").exists():  # the solver is iterating: its first checkpoint is written
        assert p.poll() is None, p.stderr.read()
        assert time.monotonic() < deadline, "no checkpoint within 240 s"
        time.sleep(0.2)
    p.send_signal(signal.SIGINT)
    try:
        err = p.communicate(timeout=120)[1]
    except subprocess.TimeoutExpired:  # what it was doing, for the failure's message
        child, parent = _signals(p.pid), _signals(os.getpid())
        p.kill()
        raise AssertionError(
            f"still running 120 s after SIGINT (its signals: {child}; this worker's: {parent}); "
            f"stderr:\n{p.communicate()[1][-3000:]}"
        ) from None
    assert p.returncode == 130, err
    last = err.strip().splitlines()[-1]
    assert last == f"jaxobs: interrupted; continue with: jaxobs tune {job} --out {out} --resume", err
    # the same command again, without --resume: refused, naming --resume before --force
    q = _run(["tune", str(job), "--out", str(out)], stdout=subprocess.DEVNULL)
    err = q.communicate(timeout=120)[1].strip().splitlines()
    assert q.returncode == 2 and len(err) == 1, err
    assert "continue it with `jaxobs tune" in err[0] and err[0].index("--resume") < err[0].index("--force"), err


def test_no_command_lists_the_commands(capsys):
    from jaxobs_tuning.cli import main

    assert main([]) == 2
    err = capsys.readouterr().err
    for cmd in ("tune", "study", "export", "closed-form", "reproduce"):
        assert f"    {cmd}" in err, err


def test_closed_form_error_names_the_flag(capsys):
    from jaxobs_tuning.cli import main

    assert main(["closed-form", "wif", "--b", "-1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "jaxobs: error: --b must be finite and > 1, got -1", err
