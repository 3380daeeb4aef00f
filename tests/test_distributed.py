"""A study split over processes (jax.distributed, CPU collectives) equals the same study in one process.

Two local processes, one CPU device each, join a run on a free localhost port; each runs the
``jaxobs study`` command line (process 0 writes the results, process 1 only computes) and then
``run_study`` itself, and saves the Dataset it returned.  Both Datasets and process 0's study.nc must
equal the study run here, in one process, to float64 rounding.
"""

import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import jaxobs
from jaxobs import linear
from jaxobs.io.provenance import by_label
from jaxobs.studies.study import run_study
from jaxobs_tuning.cli import main

ROOT = Path(__file__).resolve().parents[1]
# the processes import this checkout, and what this process was given before it (a worktree's own tuning/)
PYTHONPATH = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
AXES = {"freq_step": [-2.0, 1.0], "dc": [0.0, 0.05, 0.1]}
# 6 scenarios in chunks of 4 over 2 devices: two chunks, the last padded (2 scenarios of 4 are copies)
OPTS = {"t_event": 0.1, "horizon": 0.2, "chunk_size": 4}
STUDY_TOML = """\
[study]
name = "two-processes"
t_event = 0.1
horizon = 0.2
chunk_size = 4
[designs.SOGI-FLL]
closed_form = "sogi-fll"
[axes]
freq_step = [-2.0, 1.0]
dc = [0.0, 0.05, 0.1]
"""

_WORKER = (
    textwrap.dedent(
        """
    import sys
    import jax
    from jaxobs_tuning.cli import main

    import jaxobs.runtime.sharding as S

    # the split itself: every chunk's results reach gather_batch spread over both processes, this process
    # holding 2 rows of each chunk of 4 (without the split, both would compute everything, and agree too)
    seen, gather = [], S.gather_batch
    def spy(tree):
        seen.extend((x.is_fully_addressable, [s.data.shape[0] for s in x.addressable_shards])
                    for x in jax.tree.leaves(tree))
        return gather(tree)
    S.gather_batch = spy

    pid, addr, toml, out = int(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4]
    rc = main(["study", toml, "--out", out, "--quiet", "--coordinator", addr, "--num-processes", "2",
               "--process-id", str(pid)])
    assert rc == 0, rc
    # the command line joined the run: two processes, one device each, the mesh over both
    assert (jax.process_count(), len(jax.devices()), len(jax.local_devices())) == (2, 2, 1), jax.devices()
    from jaxobs import linear
    from jaxobs.studies.study import run_study

    ds = run_study({"SOGI-FLL": linear.sogi_fll_closed_form()}, __AXES__, **__OPTS__)
    ds.to_netcdf(f"{out}/process{pid}.nc", engine="h5netcdf")
    # 2 runs x 2 chunks x 8 leaves (7 metrics and flags, ok)
    assert len(seen) == 32 and all(s == (False, [2]) for s in seen), seen
    print("WORKER-DONE", pid)
    """
    )
    .replace("__AXES__", repr(AXES))
    .replace("__OPTS__", repr(OPTS))
)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _process_env() -> dict:
    """The environment of a study process: one CPU device, this checkout first on the path."""
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAX_NUM_CPU_DEVICES")}
    env.update(JAX_PLATFORMS="cpu", JAXOBS_HOST_DEVICES="1", PYTHONPATH=PYTHONPATH)
    return env


def _communicate(procs, timeout: float) -> list[tuple[str, str]]:
    """Each process's (stdout, stderr); a process still running after (one left waiting for its peer in a
    collective) is killed."""
    try:
        return [p.communicate(timeout=timeout) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()


def _gloo_available() -> bool:
    try:
        from jax._src.lib import _jax
    except ImportError:  # cannot tell in this jaxlib: run, and let the processes say
        return True
    return hasattr(_jax, "make_gloo_tcp_collectives")


def _assert_same_study(got: xr.Dataset, want: xr.Dataset, what: str):
    assert set(got.data_vars) == set(want.data_vars), what
    for k in want.data_vars:
        a, b = got[k].values, want[k].values
        assert a.shape == b.shape and a.dtype == b.dtype, (what, k)
        if a.dtype.kind == "f":
            # a device's share is a smaller vmap, which XLA may vectorize differently: last-bit differences
            # (the same ones as chunk_size=2 in one process gives)
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=0, equal_nan=True, err_msg=f"{what}: {k}")
        else:
            np.testing.assert_array_equal(a, b, err_msg=f"{what}: {k}")
    for c in want.coords:
        np.testing.assert_array_equal(got[c].values, want[c].values, err_msg=f"{what}: coordinate {c}")
    for key, v in want.attrs.items():
        assert got.attrs[key] == v, (what, key)


@pytest.mark.skipif(not _gloo_available(), reason="this jaxlib has no gloo CPU collectives")
def test_study_over_two_processes_equals_one_process(tmp_path):
    toml = tmp_path / "study.toml"
    toml.write_text(STUDY_TOML)
    out = tmp_path / "out"
    env = _process_env()
    cache = os.environ.get("JAXOBS_TEST_CACHE", str(Path.home() / ".cache" / "jaxobs" / "jax-tests"))
    if cache:  # the test suite's persistent compilation cache (tests/conftest.py): it changes no number
        env.update(JAX_COMPILATION_CACHE_DIR=cache, JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="1.0")
    addr = f"127.0.0.1:{_free_port()}"
    args = [str(toml), str(out)]
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", _WORKER, str(pid), addr, *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
            cwd=ROOT,
        )
        for pid in (0, 1)
    ]
    outs = _communicate(procs, timeout=300)
    for pid, (p, (so, se)) in enumerate(zip(procs, outs)):
        assert p.returncode == 0 and f"WORKER-DONE {pid}" in so, f"process {pid}:\n{so[-2000:]}\n{se[-3000:]}"
    # the command line: process 0 wrote the results and printed the table, process 1 one line
    assert "study two-processes: 1 designs x 6 scenarios" in outs[0][0]
    assert "process 1 of 2 computed its share; process 0 writes the results" in outs[1][0]
    assert "[Gloo]" not in outs[0][0] + outs[1][0]  # gloo's connection line goes to stderr, stdout is results
    assert sorted(f.name for f in out.glob("*.nc")) == ["process0.nc", "process1.nc", "study.nc"]

    want = run_study({"SOGI-FLL": linear.sogi_fll_closed_form()}, AXES, **OPTS)
    want.to_netcdf(tmp_path / "one_process.nc", engine="h5netcdf")  # through the same writer (NetCDF4)
    want = by_label(xr.load_dataset(tmp_path / "one_process.nc", engine="h5netcdf"))
    assert want.sizes["freq_step"] * want.sizes["dc"] == 6 and float(want["ripple_freq"].max()) > 0
    for name in ("process0.nc", "process1.nc"):
        _assert_same_study(by_label(xr.load_dataset(out / name, engine="h5netcdf")), want, name)
    cli = by_label(xr.load_dataset(out / "study.nc", engine="h5netcdf"))
    assert cli.attrs["source"] == "jaxobs.studies.study.run_study" and "study_sha256" in cli.attrs
    _assert_same_study(cli, want, "study.nc (jaxobs study, process 0)")


def test_init_distributed_rejects_bad_arguments_before_touching_jax():
    for kw, field in (
        ({"coordinator": "localhost"}, "coordinator"),
        ({"coordinator": "localhost:0"}, "coordinator"),
        ({"coordinator": ":1234"}, "coordinator"),
        ({"coordinator": 1234}, "coordinator"),
        ({"num_processes": 0}, "num_processes"),
        ({"num_processes": True}, "num_processes"),
        ({"process_id": -1}, "process_id"),
        ({"process_id": 1.0}, "process_id"),
        ({"num_processes": 2, "process_id": 2}, r"process_id must be in 0\.\.1"),
    ):
        with pytest.raises(ValueError, match=field):
            jaxobs.init_distributed(**kw)


def test_global_batch_and_gather_batch_in_one_process():
    import jax

    x = {"a": np.arange(6.0), "b": np.arange(12.0).reshape(6, 2)}
    mesh = jaxobs.batch_mesh(jax.devices()[:1])
    g = jaxobs.runtime.sharding.global_batch(x, mesh)
    assert g["a"].sharding.spec == jax.sharding.PartitionSpec("batch")
    back = jaxobs.runtime.sharding.gather_batch(g)
    np.testing.assert_array_equal(back["b"], x["b"])
    assert isinstance(back["a"], np.ndarray)
    with pytest.raises(ValueError, match="divide"):
        jaxobs.runtime.sharding.global_batch({"a": np.arange(5.0)}, jaxobs.batch_mesh([jax.devices()[0]] * 2))
    with pytest.raises(ValueError, match="scalar"):
        jaxobs.runtime.sharding.global_batch({"a": np.arange(6.0), "s": np.float64(1.0)}, mesh)
    with pytest.raises(ValueError, match="mesh"):
        run_study({"a": linear.sogi_fll_closed_form()}, {"dc": [0.0]}, mesh="cpu")


def test_study_cli_rejects_bad_distributed_options(capsys):
    for argv, msg in (
        (["--num-processes", "0"], "--num-processes: must be an integer >= 1"),
        (["--process-id", "x"], "--process-id: must be an integer >= 0"),
        (["--coordinator", "host"], "--coordinator: must be HOST:PORT"),
        (["--coordinator", "h:1", "--num-processes", "2", "--process-id", "2"], "--process-id must be in 0..1"),
        (["--timeout", "0"], "--timeout: must be an integer >= 1"),
        # without --distributed all three are needed, named as the command line names them
        (["--num-processes", "2", "--process-id", "0"], "needs --coordinator, --num-processes and --process-id"),
        (["--coordinator", "h:1", "--process-id", "0"], "(missing: --num-processes)"),
        (["--timeout", "5"], "--timeout applies to a distributed run"),
    ):
        try:
            rc = main(["study", "--out", "unused", *argv])
        except SystemExit as e:  # argparse's error (jaxobs_tuning.cli._Parser): one line, then exit 2
            rc = e.code
        assert rc == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and msg in err[0], (argv, err)


def test_study_cli_refuses_what_cannot_be_split_before_joining(tmp_path, capsys):
    # a drive or recording study is refused from the file before the process joins (a refusal after
    # joining would leave the other processes waiting); --timeout 1 bounds the test if it did join
    dist = ["--coordinator", f"127.0.0.1:{_free_port()}", "--num-processes", "2", "--process-id", "1"]
    for body, kind in (('[study]\nkind = "drive"\n', "drive"), ('[study.recording]\nfiles = ["a.csv"]\n', "recording")):
        f = tmp_path / f"{kind}.toml"
        f.write_text(body)
        for check in ([], ["--check"]):  # --check refuses it too: what passes --check, the run accepts
            assert main(["study", str(f), "--out", str(tmp_path / "o"), "--timeout", "1", *check, *dist]) == 2
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and f"run this {kind} study without --coordinator" in err[0], err
    assert not (tmp_path / "o").exists()


def test_process_0_that_cannot_join_gets_one_line(tmp_path, capsys, monkeypatch):
    """Process 0 given --coordinator localhost:1 --resume (no --check) from main() after a JAX computation
    ended in an internal error, exit 1 (JAX's RuntimeError: it must be joined before JAX starts); a port this
    user may not serve (port 1 but as root) made JAX fail to start its service, an internal error too."""
    import errno

    import jax

    jax.numpy.zeros(1).block_until_ready()  # JAX started: main() below cannot join (and so never waits)
    study = tmp_path / "s.toml"
    study.write_text('[designs.a]\nclosed_form = "sogi-fll"\n[axes]\ndc = [0.0]\n')
    dist = ["--coordinator", "localhost:1", "--num-processes", "2", "--process-id", "0", "--timeout", "1"]
    argv = ["study", str(study), "--out", str(tmp_path / "o"), "--resume", "--quiet", *dist]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "this process cannot join the distributed run" in err[0], err
    assert "--coordinator/--num-processes/--process-id" in err[0] and "fresh `jaxobs study`" in err[0]

    def refused(self, addr):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(socket.socket, "bind", refused)  # what a user without root gets for port 1
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--coordinator localhost:1: port 1 is privileged here" in err[0], err
    assert "pick a free port in " in err[0] and "..65535" in err[0]
    assert not (tmp_path / "o").exists()


def test_a_process_whose_coordinator_never_comes_gets_one_line(tmp_path, capsys):
    # process 1 checks that process 0 listens before JAX's runtime would abort it: exit 2, one line
    dist = ["--coordinator", f"127.0.0.1:{_free_port()}", "--num-processes", "2", "--process-id", "1"]
    t0 = time.monotonic()
    assert main(["study", "--out", str(tmp_path / "o"), "--timeout", "1", "--quiet", *dist]) == 2
    # the 1 s of --timeout, not the 300 s default: a wait, which the machine's load does not stretch, and a
    # few connection attempts (what the 29 s of margin are for)
    assert time.monotonic() - t0 < 30
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no coordinator (process 0) listening at 127.0.0.1:" in err[0], err
    with pytest.raises(ValueError, match="timeout must be an integer >= 1"):
        jaxobs.init_distributed(timeout=0)


def test_distributed_without_an_environment_names_what_to_set(tmp_path):
    # a subprocess: jax.distributed.initialize changes process-wide JAX state even when it refuses
    env = {k: v for k, v in os.environ.items() if not k.startswith(("JAX_COORDINATOR", "SLURM_", "OMPI_", "PMI"))}
    env.update(
        JAX_PLATFORMS="cpu",
        JAXOBS_HOST_DEVICES="1",
        PYTHONPATH=PYTHONPATH,
    )
    cmd = [sys.executable, "-m", "jaxobs_tuning.cli", "study", "--distributed", "--quiet", "--out", str(tmp_path / "o")]
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT, timeout=120, check=False)
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1, r.stderr
    assert "--distributed: the environment does not give the run" in err[0] and "JAX_COORDINATOR_ADDRESS" in err[0]
    assert not (tmp_path / "o").exists()


@pytest.mark.slow  # two more processes (3 s quiet, more under load): the default suite is at its time budget
@pytest.mark.skipif(not _gloo_available(), reason="this jaxlib has no gloo CPU collectives")
def test_processes_given_different_study_files_stop_before_computing(tmp_path):
    # different files would give different chunk shapes, on which gloo aborts both processes (a C++ dump);
    # the command line compares the files' sha256 right after joining and ends each process in one line
    env = _process_env()
    addr = f"127.0.0.1:{_free_port()}"
    procs = []
    for pid in (0, 1):
        f = tmp_path / f"study{pid}.toml"
        f.write_text(STUDY_TOML if pid == 0 else STUDY_TOML.replace("dc = [0.0, 0.05, 0.1]", "dc = [0.0, 0.1]"))
        cmd = [sys.executable, "-m", "jaxobs_tuning.cli", "study", str(f), "--out", str(tmp_path / "out"), "--quiet"]
        cmd += ["--coordinator", addr, "--num-processes", "2", "--process-id", str(pid), "--timeout", "60"]
        procs.append(subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env))
    outs = _communicate(procs, timeout=120)
    for pid, (p, (so, se)) in enumerate(zip(procs, outs)):
        err = [line for line in se.strip().splitlines() if not line.startswith("[Gloo]")]
        assert p.returncode == 2 and len(err) == 1, f"process {pid}: rc {p.returncode}\n{so}\n{se[-3000:]}"
        assert "given different study files" in err[0] and "process(es) 1 differ" in err[0], err
    assert not (tmp_path / "out" / "study.nc").exists()


def test_a_coordinator_port_in_use_gets_one_line(tmp_path, capsys):
    # process 0 with its port taken: one line, not JAX's "Failed to start RPC server" and a traceback
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("", 0))
        s.listen()
        port = s.getsockname()[1]
        dist = ["--coordinator", f"127.0.0.1:{port}", "--num-processes", "2", "--process-id", "0"]
        assert main(["study", "--out", str(tmp_path / "o"), "--timeout", "1", "--quiet", *dist]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"port {port} is in use" in err[0], err


def test_a_non_jax_listener_on_the_coordinator_port_gets_one_line(tmp_path, capsys):
    # a process that finds something listening and joins would have JAX's runtime abort it after its timeout
    # with a C++ stack dump.  A plain listener that says nothing, and one that answers HTTP/1, each end it in one
    # line naming the port, exit 2, before JAX is touched
    import threading

    for answer in (None, b"HTTP/1.1 400 Bad Request\r\n\r\n"):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind(("127.0.0.1", 0))
            s.listen()
            port = s.getsockname()[1]
            if answer is not None:

                def serve(s=s, answer=answer):
                    conn, _ = s.accept()
                    with conn:
                        conn.sendall(answer)

                threading.Thread(target=serve, daemon=True).start()
            dist = ["--coordinator", f"127.0.0.1:{port}", "--num-processes", "2", "--process-id", "1"]
            t0 = time.monotonic()
            assert main(["study", "--out", str(tmp_path / "o"), "--timeout", "3", "--quiet", *dist]) == 2
            assert time.monotonic() - t0 < 30  # --timeout's 3 s, not the default 300 s (a wait, as above)
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "is not a JAX coordinator" in err[0] and f"port {port}" in err[0], err
        assert ("answered b'HTTP/1.1" in err[0]) == (answer is not None), err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow  # two more processes, as the test above
@pytest.mark.skipif(not _gloo_available(), reason="this jaxlib has no gloo CPU collectives")
def test_a_process_given_another_process_count_stops_before_computing(tmp_path):
    # a process given --num-processes 3 must not join a 2-process run (and report "1 of 2", exit 0)
    env = _process_env()
    addr = f"127.0.0.1:{_free_port()}"
    f = tmp_path / "study.toml"
    f.write_text(STUDY_TOML)
    procs = []
    for pid, n in ((0, 2), (1, 3)):
        cmd = [sys.executable, "-m", "jaxobs_tuning.cli", "study", str(f), "--out", str(tmp_path / "out"), "--quiet"]
        cmd += ["--coordinator", addr, "--num-processes", str(n), "--process-id", str(pid), "--timeout", "60"]
        procs.append(subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env))
    outs = _communicate(procs, timeout=120)
    for pid, (p, (so, se)) in enumerate(zip(procs, outs)):
        err = [line for line in se.strip().splitlines() if not line.startswith("[Gloo]")]
        assert p.returncode == 2 and len(err) == 1, f"process {pid}: rc {p.returncode}\n{so}\n{se[-3000:]}"
        assert "--num-processes: process(es) 1 were given 3, the run has 2 processes" in err[0], err
    assert not (tmp_path / "out" / "study.nc").exists()


# 2 designs x 16 scenarios in chunks of 2 (one scenario a process): 16 chunks, so that a kill lands mid-run
RESUME_TOML = (
    STUDY_TOML.replace("chunk_size = 4", "chunk_size = 2")
    .replace("[axes]", '[designs.WIF]\nclosed_form = "wif"\n[axes]')
    .replace("dc = [0.0, 0.05, 0.1]", "dc = [0.0, 0.02, 0.04, 0.06, 0.08, 0.1, 0.12, 0.14]")
)


# process 0 of a run whose store kills this process (SIGKILL, no cleanup) once its 5th chunk is on disk
_KILLED_AFTER_5 = """
import os, signal, sys
from jaxobs.runtime.chunkstore import ChunkStore
from jaxobs_tuning.cli import main

real, count = ChunkStore.put, [0]

def put(self, design, i, values):
    real(self, design, i, values)
    count[0] += 1
    if count[0] == 5:
        os.kill(os.getpid(), signal.SIGKILL)

ChunkStore.put = put
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.slow  # three runs of two processes
@pytest.mark.skipif(not _gloo_available(), reason="this jaxlib has no gloo CPU collectives")
def test_a_study_over_two_processes_killed_then_resumed_is_byte_identical(tmp_path):
    # process 0 writes each chunk; on --resume it tells the other which chunks are on disk, and both skip them.
    # The kill is injected: process 0 kills itself once its 5th chunk is written, then the test kills process 1
    # (left waiting for its peer), as a lost node would leave the run
    from jaxobs_tuning.cli import STUDY_CHUNKS

    env = _process_env()
    f = tmp_path / "study.toml"
    f.write_text(RESUME_TOML)

    def launch(out, *extra, first=()):
        addr = f"127.0.0.1:{_free_port()}"
        args = ["study", str(f), "--out", str(out), "--quiet", *extra]
        args += ["--coordinator", addr, "--num-processes", "2", "--timeout", "60"]
        return [
            subprocess.Popen(
                [*(first if pid == 0 and first else [sys.executable, "-m", "jaxobs_tuning.cli"]), *args]
                + ["--process-id", str(pid)],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                env=env,
                cwd=ROOT,
            )
            for pid in (0, 1)
        ]

    def finish(procs):
        outs = _communicate(procs, timeout=180)
        for pid, (p, (so, se)) in enumerate(zip(procs, outs)):
            assert p.returncode == 0, f"process {pid}: rc {p.returncode}\n{so}\n{se[-3000:]}"
        return outs

    finish(launch(tmp_path / "ref"))
    out = tmp_path / "out"
    procs = launch(out, first=[sys.executable, "-c", _KILLED_AFTER_5])
    procs[0].communicate(timeout=180)
    assert procs[0].returncode == -signal.SIGKILL, procs[0].returncode
    procs[1].kill()
    procs[1].communicate()
    assert not (out / "study.nc").exists() and len(list((out / STUDY_CHUNKS).glob("*.h5"))) == 5
    outs = finish(launch(out, "--resume"))
    assert "resumed: 5 chunks of 16" in outs[0][0], outs[0]
    assert "process 1 of 2 computed its share" in outs[1][0]
    assert (out / "study.nc").read_bytes() == (tmp_path / "ref" / "study.nc").read_bytes()
    assert not (out / STUDY_CHUNKS).exists()
