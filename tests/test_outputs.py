"""Outputs that stay in place: sanitised names, no symlinks followed, a lock per --out, no silent overwrite;
atomic, fingerprinted checkpoints that resume bit-identically after a kill at any point."""

import contextlib
import errno
import fcntl
import json
import multiprocessing
import os
import socket
import time

import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr

from jaxobs.io.provenance import by_label
from jaxobs_tuning import AbstractObjective, solvers, strategies
from jaxobs_tuning.cli import main
from jaxobs_tuning.outdir import LOCK, OutDir, OutError, atomic_path, atomic_write_bytes, safe_name
from jaxobs_tuning.params import GainSpec, Parametrization
from jaxobs_tuning.solvers import CheckpointError, tune
from jaxobs_tuning.summary import print_summary

# --------------------------------------------------------------------------
# containment
# --------------------------------------------------------------------------


def test_names_are_sanitised():
    assert safe_name("../../etc") == "_.._etc"
    assert safe_name("/abs/path") == "_abs_path"
    assert safe_name("..") == "job" and safe_name("") == "job" and safe_name("...", "study") == "study"
    assert safe_name("wif-robust_1.2") == "wif-robust_1.2"


@contextlib.contextmanager
def held_lock(out, pid):
    """``out``'s lock held as another process would hold it (an open file description of its own, flock'ed),
    naming ``pid``."""
    fd = os.open(out / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        os.write(fd, f"{pid} {socket.gethostname()}\n".encode())
        yield
    finally:
        (out / LOCK).unlink(missing_ok=True)
        os.close(fd)


def test_symlinks_locks_and_existing_results(tmp_path):
    target = tmp_path / "elsewhere"
    target.mkdir()
    (tmp_path / "link").symlink_to(target)
    with pytest.raises(OutError, match="symlink"):
        OutDir(tmp_path / "link", ["result.json"]).__enter__()
    out = tmp_path / "o"
    out.mkdir()
    (out / "result.json").symlink_to(target / "x.json")
    with pytest.raises(OutError, match="symlink"):
        OutDir(out, ["result.json"], force=True).__enter__()
    (out / "result.json").unlink()
    (out / "result.json").write_text("{}")
    with pytest.raises(OutError, match="--force"):
        OutDir(out, ["result.json"]).__enter__()
    assert not (out / LOCK).exists()  # released on refusal
    with OutDir(out, ["result.json"], force=True):
        assert (out / LOCK).exists()
        with pytest.raises(OutError, match="in use by process"):  # a second writer on the same folder
            OutDir(out, [], force=True).__enter__()
    assert not (out / LOCK).exists()
    (out / LOCK).write_text(f"999999999 {socket.gethostname()}\n")  # left by a killed run: nobody holds it
    with OutDir(out, [], force=True):  # locked again: the lock now names this process
        assert (out / LOCK).read_text().split() == [str(os.getpid()), socket.gethostname()]
    assert not (out / LOCK).exists()
    (out / LOCK).write_text("")  # a 0-byte lock (a full disk, once): lockable, not "remove it by hand"
    with OutDir(out, [], force=True):
        assert (out / LOCK).read_text().split() == [str(os.getpid()), socket.gethostname()]
    assert not (out / LOCK).exists()
    (tmp_path / "file").write_text("")
    with pytest.raises(OutError, match="not a folder"):
        OutDir(tmp_path / "file").__enter__()


GOOD = """
[job]
name = "../../escape"
component = "SOGIFLL"
[gains.lam]
init = 12337.0
lower = 1000.0
upper = 100000.0
[scenarios]
t_event = 0.02
horizon = 0.06
[scenarios.grid]
freq_step = [1.0]
[objective]
terms = [{ metric = "itae_freq", weight = 1.0 }]
[solver]
steps = 1
checkpoint_every = 1
"""


def test_cli_refuses_a_locked_or_used_out_with_one_line(tmp_path, capsys, monkeypatch):
    path = tmp_path / "job.toml"
    path.write_text(GOOD)
    out = tmp_path / "o"
    out.mkdir()
    with held_lock(out, 1):  # another process holds it
        assert main(["tune", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "in use" in err[0]
    (out / "result.json").write_text("{}")
    assert main(["tune", str(path), "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    # the name cannot escape: the default folder is ./out/<sanitised name>
    monkeypatch.chdir(tmp_path)
    old_umask = os.umask(0o027)  # not the usual 022: a mode that neither 0600 nor a hard-coded 0644 matches
    try:
        assert main(["tune", str(path), "--quiet"]) == 0
        with open(tmp_path / "plain", "w") as f:
            f.write("")
    finally:
        os.umask(old_umask)
    assert (tmp_path / "out" / "_.._escape" / "result.json").exists()
    # every output (the atomically written JSON files included) gets the mode a plain open() gives, 0640 here
    plain = (tmp_path / "plain").stat().st_mode & 0o777
    modes = {p.name: oct(p.stat().st_mode & 0o777) for p in (tmp_path / "out" / "_.._escape").iterdir()}
    assert {"result.json", "history.json", "timing.json", "responses.png"} <= set(modes)
    assert set(modes.values()) == {oct(plain)} == {"0o640"}, modes
    # lost lock, per design and per scenario: the closed form and the tuned design hold it
    res = json.loads((tmp_path / "out" / "_.._escape" / "result.json").read_text())
    assert [res["scores"][d]["lost_lock"] for d in ("initial", "closed_form", "tuned")] == [0, 0, 0]
    assert res["lost_lock_tuned_only"] == {"tuning": 0}
    scores = by_label(xr.load_dataset(tmp_path / "out" / "_.._escape" / "scores.nc", engine="h5netcdf"))
    assert scores["lost_lock"].dtype == np.int8 and scores["lost_lock"].dims == scores["total"].dims
    assert int(scores["lost_lock"].sum()) == 0
    # a tuned design that loses lock where the closed form holds it is a warning
    capsys.readouterr()
    print_summary(dict(res, lost_lock_tuned_only={"tuning": 2}), tmp_path)
    warn = [ln for ln in capsys.readouterr().err.splitlines() if "lost lock" in ln]
    assert len(warn) == 1 and "2 tuning scenarios where the closed form holds it" in warn[0]
    assert not (tmp_path.parent / "escape").exists()
    capsys.readouterr()
    # --resume on another job's checkpoint: one line, exit 2
    other = tmp_path / "other.toml"
    other.write_text(GOOD.replace("init = 12337.0", "init = 12000.0"))
    assert main(["tune", str(other), "--out", str(tmp_path / "out" / "_.._escape"), "--resume", "--force"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "another job" in err[0]


def test_internal_error_is_one_line_with_a_log(tmp_path, capsys, monkeypatch):
    path = tmp_path / "job.toml"
    path.write_text(GOOD)

    def boom(*a, **k):
        raise RuntimeError("boom")

    monkeypatch.setattr("jaxobs_tuning.cli.run_job", boom)
    assert main(["tune", str(path), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "error.log" in err[0]
    assert "RuntimeError: boom" in (tmp_path / "o" / "error.log").read_text()
    assert not (tmp_path / "o" / LOCK).exists()


def test_a_value_error_of_ours_is_an_internal_error_and_a_check_is_bad_input(tmp_path, capsys, monkeypatch):
    """Both are ValueError: one raised by an operation (math.log(-1), as a gain one ulp outside its bound once
    did) is a fault with its traceback in a log, exit 1; one raised by a check is the user's, one line, exit 2."""
    import math

    path = tmp_path / "job.toml"
    path.write_text(GOOD)

    def domain(*a, **k):
        return math.log(-1.0)

    monkeypatch.setattr("jaxobs_tuning.cli.run_job", domain)
    assert main(["tune", str(path), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "internal error (ValueError): math domain error" in err[0] and "error.log" in err[0]
    assert "math.log(-1.0)" in (tmp_path / "o" / "error.log").read_text()
    # a check's verdict, raised by jaxobs: one line, exit 2, no log
    monkeypatch.undo()
    bad = tmp_path / "bad.toml"
    bad.write_text(GOOD.replace("init = 12337.0", "init = -1.0"))
    assert main(["tune", str(bad), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("jaxobs: error: ") and "traceback" not in err[0]


# --------------------------------------------------------------------------
# checkpoints: kill at every point, resume bit-identically
# --------------------------------------------------------------------------


class _Quadratic(AbstractObjective):
    """A cheap stand-in objective with the interface the solvers use."""

    param: Parametrization
    n: int

    def __init__(self, n_gains=2):
        specs = [GainSpec("a", 2.0, 0.1, 50.0), GainSpec("b", 1.0, 0.01, 10.0, log=False)]
        self.param = Parametrization(specs[:n_gains])
        self.n = n_gains

    def value_grad_diverged_overflowed(self, theta, scenarios):
        target, w = jnp.asarray([0.3, -0.7])[: self.n], jnp.asarray([1.0, 3.0])[: self.n]
        v = jnp.sum((theta - target) ** 2 * w) + 0.1 * jnp.sum(jnp.sin(3 * theta))
        g = 2 * (theta - target) * w + 0.3 * jnp.cos(3 * theta)
        return v, g, 0, 0

    def value(self, theta, scenarios):
        return self.value_grad_diverged_overflowed(theta, scenarios)[0]


CFG = strategies.solver("adam", learning_rate=0.1, steps=24, patience=100, checkpoint_every=2, progress_every=1)


class Killed(BaseException):
    pass


def _run(ckpt, resume=False, fp="job-a", n_gains=2):
    obj = _Quadratic(n_gains)
    res = tune(obj, CFG, obj.param.theta0(), checkpoint=ckpt, resume=resume, quiet=True, fingerprint=fp)
    return json.dumps(
        dict(theta=np.asarray(res.theta).tolist(), h=res.history, s=res.status, r=res.reason, b=res.best_iteration)
    ).encode()


@pytest.mark.parametrize("where", ["before_rename", "after_rename"])
@pytest.mark.parametrize("k", [1, 2, 3, 5, 8, 11])
def test_kill_at_any_checkpoint_and_resume_is_bit_identical(tmp_path, monkeypatch, where, k):
    """12 kill points: at the k-th checkpoint, with its temp file written but not yet renamed (a kill
    mid-checkpoint), or just after the rename; the resumed run equals an uninterrupted one byte for byte."""
    ref = _run(tmp_path / "ref.npz")
    ckpt = tmp_path / "c.npz"
    calls = {"n": 0}
    real = os.replace

    def replace(src, dst):
        calls["n"] += 1
        if calls["n"] == k and where == "before_rename":
            raise Killed
        real(src, dst)
        if calls["n"] == k and where == "after_rename":
            raise Killed

    monkeypatch.setattr(solvers, "_replace", replace)
    with pytest.raises(Killed):
        _run(ckpt)
    monkeypatch.setattr(solvers, "_replace", real)
    assert not [p for p in tmp_path.iterdir() if ".tmp" in p.name]  # no temp file left behind
    assert ckpt.exists() == (k > 1 or where == "after_rename")
    assert _run(ckpt, resume=True) == ref


def test_resume_refuses_foreign_and_corrupt_checkpoints(tmp_path, capsys):
    ckpt = tmp_path / "c.npz"
    ref = _run(ckpt)
    with pytest.raises(CheckpointError, match="another job"):
        _run(ckpt, resume=True, fp="job-b")
    ckpt.write_bytes(ckpt.read_bytes()[:100])
    with pytest.raises(CheckpointError, match="corrupt") as e:
        _run(ckpt, resume=True)
    assert "\n" not in str(e.value)
    ckpt.unlink()
    assert _run(ckpt, resume=True) == ref  # nothing to resume: one line, a fresh start
    assert "no checkpoint" in capsys.readouterr().err


@pytest.mark.parametrize("n_saved, n_resumed", [(1, 2), (2, 1), (2, 2)])
def test_a_foreign_checkpoint_belongs_to_another_job_whatever_its_gain_count(tmp_path, n_saved, n_resumed):
    """The fingerprint is checked before the arrays: another job's checkpoint with another number of gains
    (other array shapes) is "another job", not "corrupt"; a same-fingerprint checkpoint whose shapes differ
    (a hand-edited job hash) is still reported as corrupt."""
    ckpt = tmp_path / "c.npz"
    _run(ckpt, fp="job-a", n_gains=n_saved)
    with pytest.raises(CheckpointError, match="belongs to another job") as e:
        _run(ckpt, resume=True, fp="job-b", n_gains=n_resumed)
    assert "corrupt" not in str(e.value) and "\n" not in str(e.value)
    if n_saved != n_resumed:
        with pytest.raises(CheckpointError, match="corrupt or unreadable.*shapes differ"):
            _run(ckpt, resume=True, fp="job-a", n_gains=n_resumed)


@pytest.mark.parametrize(
    "argv, product",
    [
        (["demo"], "fll_tests_A_E.png"),
        (["bode"], "bode_lesos_002_fig4.png"),
        (["reproduce", "flux", "--quick"], "flux_circles_400rpm.png"),
        (["reproduce", "leso"], "leso_speed_ramp.png"),
        (["export", "--design", "wif"], "observer.c"),
    ],
    ids=lambda v: " ".join(v) if isinstance(v, list) else v,
)
def test_every_writing_command_takes_the_lock_and_keeps_results(tmp_path, capsys, argv, product):
    """demo, bode, reproduce and export, as tune and study: a second process on the same --out refuses in one
    line; a result already there is kept without --force; a symlinked --out or result is refused — each
    before any work (these runs would take seconds to minutes: they return at once, writing nothing)."""
    out = tmp_path / "o"
    out.mkdir()

    def refused(args, what):
        assert main([*argv, *args]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("jaxobs: error: ") and what in err[0], err

    with held_lock(out, 1):  # another process holds it
        refused(["--out", str(out)], "in use by process 1")
        refused(["--out", str(out), "--force"], "in use by process 1")
    (out / product).write_text("mine")
    refused(["--out", str(out)], "use --force")
    assert (out / product).read_text() == "mine" and not (out / LOCK).exists()
    (out / product).unlink()
    (out / product).symlink_to(tmp_path / "elsewhere")
    refused(["--out", str(out), "--force"], "symlink")
    (tmp_path / "link").symlink_to(out)
    refused(["--out", str(tmp_path / "link")], "symlink")
    assert sorted(p.name for p in out.iterdir()) == [product] and not (tmp_path / "elsewhere").exists()


# --------------------------------------------------------------------------
# the lock under concurrent starters; temp files nobody can redirect


def _starter(out, log, barrier):
    """One starter: wait for the others, try the lock, and if it is ours log the interval we held it."""
    barrier.wait()
    try:
        with OutDir(out, [], force=True):
            fd = os.open(log, os.O_WRONLY | os.O_APPEND)
            os.write(fd, f"in {os.getpid()}\n".encode())
            time.sleep(0.002)
            os.write(fd, f"out {os.getpid()}\n".encode())
            os.close(fd)
    except OutError:
        pass  # refused: another starter holds the lock (what the log checks)
    os._exit(0)


# 100 trials in the slow suite: ~35 s on a loaded 2-core machine, mostly forking a
# process that has JAX loaded; 10 in the fast suite
@pytest.mark.parametrize("trials", [10, pytest.param(100, marks=pytest.mark.slow)])
def test_six_concurrent_starters_never_hold_the_lock_together(tmp_path, trials):
    """6 processes start on one folder at once, ``trials`` times, half of the trials over a lock file left by a dead
    process: the log of who held the lock never shows two holders at once, and every trial has a holder.
    (The former read-pid/unlink/re-create takeover gave two holders in 11 of 100 trials.)"""
    ctx = multiprocessing.get_context("fork")  # cheap starters: no interpreter start-up, no JAX import
    out, log = tmp_path / "o", tmp_path / "log"
    out.mkdir()
    for trial in range(trials):
        log.write_text("")
        if trial % 2:
            (out / LOCK).write_text(f"999999999 {socket.gethostname()}\n")  # left behind by a kill
        barrier = ctx.Barrier(6)
        procs = [ctx.Process(target=_starter, args=(out, log, barrier)) for _ in range(6)]
        for p in procs:
            p.start()
        for p in procs:
            p.join(30)
            assert p.exitcode == 0
        events = log.read_text().split("\n")[:-1]
        assert events, f"trial {trial}: nobody got the lock"
        holders = 0
        for e in events:
            holders += 1 if e.startswith("in ") else -1
            assert holders in (0, 1), f"trial {trial}: two holders at once: {events}"
        assert not (out / LOCK).exists()


def test_a_lock_that_cannot_be_written_leaves_no_file(tmp_path, monkeypatch):
    out = tmp_path / "o"
    out.mkdir()

    def full(fd, data, offset):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "pwrite", full)
    with pytest.raises(OutError, match=r"cannot write the lock .*\.jaxobs\.lock.*No space left on device"):
        OutDir(out, []).__enter__()
    assert list(out.iterdir()) == []


def test_temp_files_cannot_be_redirected(tmp_path):
    """Symlinks pre-created at every name the former temp files used (``.<stem>.<pid>.tmp<suffix>``, for
    the pids around ours) point outside; writing through atomic_path and atomic_write_bytes changes nothing
    there, leaves regular files at the results' paths and no temp file behind."""
    out, outside = tmp_path / "o", tmp_path / "outside"
    out.mkdir()
    outside.mkdir()
    names = ("scores.nc", "convergence.png", "responses.png", "study.nc", "checkpoint.npz")
    for name in names:
        stem, suffix = name.rsplit(".", 1)
        for pid in range(os.getpid() - 50, os.getpid() + 50):
            for tmp in (f".{stem}.{pid}.tmp.{suffix}", f".{stem}.{pid}.tmp{('.' + suffix)}"):
                (out / tmp).unlink(missing_ok=True)
                (out / tmp).symlink_to(outside / f"{tmp}-target")
    for name in names[:-1]:
        with atomic_path(out / name) as tmp:
            tmp.write_bytes(b"result")
    atomic_write_bytes(out / "checkpoint.npz", b"ckpt")
    assert list(outside.iterdir()) == []
    for name in names:
        assert (out / name).is_file() and not (out / name).is_symlink()
    assert all(p.is_symlink() for p in out.iterdir() if p.name.startswith("."))  # only the planted links
    with pytest.raises(RuntimeError):  # a failed write leaves nothing either
        with atomic_path(out / "failed.png") as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError
    assert not (out / "failed.png").exists()
    assert all(p.is_symlink() for p in out.iterdir() if p.name.startswith("."))


# --------------------------------------------------------------------------
# a killed run's litter; Ctrl-C's last line
# --------------------------------------------------------------------------


@pytest.mark.parametrize("force", [False, True], ids=["resumed", "forced"])
def test_temp_litter_of_a_killed_run_is_removed_by_the_next_run(tmp_path, force):
    """The temp entries a kill leaves (a writer's folder ``.scores.nc.<8>.tmp``, a file ``.result.json.<12 hex>.tmp``,
    a link planted at such a name) go when the next run locks the folder, resumed or forced; other files stay,
    and nothing a link points to is touched."""
    out, outside = tmp_path / "o", tmp_path / "outside.txt"
    out.mkdir()
    outside.write_text("keep")
    (out / ".scores.nc.ab_cd123.tmp").mkdir()
    (out / ".scores.nc.ab_cd123.tmp" / "scores.nc").write_bytes(b"half")
    (out / ".result.json.0123456789ab.tmp").write_bytes(b"half")
    (out / ".history.json.fedcba987654.tmp").symlink_to(outside)
    (out / "checkpoint.npz").write_bytes(b"ckpt")
    (out / "notes.tmp").write_text("mine")
    (out / ".notes").write_text("mine")
    with OutDir(out, ["result.json"], force=force):
        assert sorted(p.name for p in out.iterdir()) == [".jaxobs.lock", ".notes", "checkpoint.npz", "notes.tmp"]
    assert outside.read_text() == "keep"


def test_a_hard_link_at_the_lock_is_not_written_through(tmp_path):
    out, outside = tmp_path / "o", tmp_path / "outside.txt"
    out.mkdir()
    outside.write_text("keep")
    os.link(outside, out / LOCK)
    with OutDir(out, []):
        assert (out / LOCK).stat().st_nlink == 1 and not os.path.samefile(out / LOCK, outside)
    assert outside.read_text() == "keep" and outside.stat().st_nlink == 1


def _interrupted(saves: bool):
    """run_job stand-in: a progress bar left open (as a call cut short by Ctrl-C leaves it), a checkpoint
    written first or not, then Ctrl-C."""
    from jaxobs.runtime.progress import Progress

    def run_job(job, out, resume=False, quiet=False):
        if saves:
            (out / "checkpoint.npz").write_bytes(b"ckpt")
        bar = Progress(True, 10, "tune")  # referenced by this frame, which the traceback keeps alive
        bar.update(3)
        raise KeyboardInterrupt

    return run_job


@pytest.mark.parametrize("saves", [False, True], ids=["no checkpoint", "checkpoint"])
def test_ctrl_c_names_resume_only_with_a_checkpoint_and_draws_nothing_after(tmp_path, capsys, monkeypatch, saves):
    import gc

    path = tmp_path / "job.toml"
    path.write_text(GOOD)
    monkeypatch.setattr("jaxobs_tuning.cli.run_job", _interrupted(saves))
    assert main(["tune", str(path), "--out", str(tmp_path / "o")]) == 130
    err = capsys.readouterr().err
    assert err.endswith("\n") and err.splitlines()[-1].startswith("jaxobs: interrupted"), err
    assert ("continue with: jaxobs tune" in err.splitlines()[-1]) == saves
    assert err.count("--resume") == int(saves)
    gc.collect()
    assert capsys.readouterr().err == ""  # the bar was closed before the line: nothing drawn after it


def test_a_study_store_has_chunks_to_resume_only_once_one_is_written(tmp_path):
    from jaxobs.runtime.chunkstore import ChunkStore

    s = ChunkStore(tmp_path / "c", "f" * 64)
    assert not s.has_chunks()
    s.start(n=4, chunk=2, devices=1, designs=["a"])
    assert not s.has_chunks()  # meta.json alone: nothing to continue from
    s.put("a", 0, {"x": np.arange(2)})
    assert s.has_chunks()
    s.retire()
    assert s.has_chunks()  # moved aside before study.nc's rename: a --resume puts it back
    s.remove()
    assert not s.has_chunks()
