"""Ctrl-C on `jaxobs tune` says how to continue, and rerunning over the checkpoint names --resume first
(issue 29).  A real SIGINT to a real process, not a raised KeyboardInterrupt."""

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


def _run(args, **kw):
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "JAXOBS_HOST_DEVICES": "1"}
    return subprocess.Popen(
        [sys.executable, "-m", "jaxobs", *args], cwd=ROOT, env=env, stderr=subprocess.PIPE, text=True, **kw
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
        p.kill()
        raise AssertionError(f"still running 120 s after SIGINT; stderr:\n{p.communicate()[1][-3000:]}") from None
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


def test_a_ctrl_c_swallowed_by_a_finalizer_is_raised_again(monkeypatch):
    """A KeyboardInterrupt raised inside a finalizer is printed and dropped by Python; under the command line's
    handler (jaxobs_tuning.interrupt) the next check() raises it again, and outside it nothing is recorded."""
    from jaxobs_tuning import interrupt

    class Finalized:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGINT)  # the handler runs here, inside the finalizer
            time.sleep(0.01)

    dropped = []  # what Python reports as "Exception ignored in ..."
    monkeypatch.setattr(sys, "unraisablehook", lambda u: dropped.append(u.exc_type))
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with interrupt.installed():
            Finalized()  # collected at once: its KeyboardInterrupt is dropped
            assert dropped == [KeyboardInterrupt]
            try:
                interrupt.check()
            except KeyboardInterrupt:
                pass
            else:
                raise AssertionError("the swallowed Ctrl-C was not raised again")
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back
        interrupt.check()  # cleared on leaving
    finally:
        signal.signal(signal.SIGINT, previous)
