"""Nothing trusted that should not be: what a run reads is verified and bounded.

Each test here is an input that a run must refuse in one line, or bound: a checkpoint resumed with NaN in θ, a
forged history, a FIFO at the checkpoint's path, a CSV field over the csv module's limit, ..."""

from __future__ import annotations

import io
import json
import os
import threading

import numpy as np
import pytest

from jaxobs.io.provenance import read_file
from jaxobs_tuning import AbstractObjective
from jaxobs_tuning.checkpoint import DIGEST, content_digest
from jaxobs_tuning.params import GainSpec, Parametrization
from jaxobs_tuning.solvers import CheckpointError
from tests.test_outputs import _run

# --------------------------------------------------------------------------
# the one reader: regular files only, bounded
# --------------------------------------------------------------------------


def _in_thread(fn, timeout=20):
    """fn() in a thread: (finished, its exception or None); a FIFO read that blocks never finishes."""
    box = {}

    def go():
        try:
            fn()
        except BaseException as e:  # noqa: BLE001 - reported to the test
            box["e"] = e

    t = threading.Thread(target=go, daemon=True)
    t.start()
    t.join(timeout)
    return not t.is_alive(), box.get("e")


def test_read_file_refuses_fifos_devices_folders_and_big_files(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    done, e = _in_thread(lambda: read_file(fifo, 100))
    assert done and isinstance(e, ValueError) and "not a file" in str(e)
    for p in ("/dev/zero", tmp_path):
        with pytest.raises(ValueError, match="not a file"):
            read_file(p, 100)
    (tmp_path / "big").write_bytes(b"x" * 101)
    with pytest.raises(ValueError, match="more than the limit of 100 bytes"):
        read_file(tmp_path / "big", 100)
    with pytest.raises(ValueError, match="cannot read"):
        read_file(tmp_path / "none", 100)
    assert read_file(tmp_path / "big", 101) == b"x" * 101


# --------------------------------------------------------------------------
# checkpoints: a content digest, and a state a run could have written
# --------------------------------------------------------------------------


def _entries(path):
    with np.load(path, allow_pickle=False) as d:
        return {k: d[k] for k in d.files}


def _write(path, entries, redigest=True):
    entries = {k: v for k, v in entries.items() if k != DIGEST}
    digest = {DIGEST: np.asarray(content_digest(entries))} if redigest else {}
    buf = io.BytesIO()
    np.savez(buf, **entries, **digest)
    path.write_bytes(buf.getvalue())


def _forge(path, redigest=True, theta=None, best_theta=None, **meta_changes):
    e = _entries(path)
    meta = json.loads(str(e["meta"]))
    meta.update(meta_changes)
    e["meta"] = np.asarray(json.dumps(meta))
    if theta is not None:
        e["theta"] = theta
    if best_theta is not None:
        e["best_theta"] = best_theta
    if not redigest:  # keep the old digest: what a hand edit leaves
        old = e.pop(DIGEST)
        e[DIGEST] = old
        buf = io.BytesIO()
        np.savez(buf, **e)
        path.write_bytes(buf.getvalue())
        return
    _write(path, e)


def test_checkpoint_content_digest_refuses_an_edited_history(tmp_path):
    """A forged history that changes the status to no_improvement: the digest refuses it."""
    ckpt = tmp_path / "c.npz"
    _run(ckpt)
    meta = json.loads(str(_entries(ckpt)["meta"]))
    hist = meta["history"]
    hist[0]["value"] = -1e9
    _forge(ckpt, redigest=False, history=hist)
    with pytest.raises(CheckpointError, match="content digest does not match") as e:
        _run(ckpt, resume=True)
    assert "\n" not in str(e.value)
    e = _entries(ckpt)  # a checkpoint without a digest (the old format) is refused too
    e.pop(DIGEST)
    buf = io.BytesIO()
    np.savez(buf, **e)
    ckpt.write_bytes(buf.getvalue())
    with pytest.raises(CheckpointError, match="content digest"):
        _run(ckpt, resume=True)


def _bad_states(meta):
    """(name, forged fields) of states no run writes, each consistent with its own digest."""
    it = meta["iteration"]
    nan2 = np.asarray([np.nan, 0.0])
    short = meta["history"][:-1]
    renumbered = [dict(h, iteration=h["iteration"] + 1) for h in meta["history"]]
    return [
        ("theta NaN", dict(theta=nan2), "theta is not finite"),
        ("best theta NaN", dict(best_theta=nan2), "best_theta is not finite"),
        ("theta shape", dict(theta=np.zeros(3)), "shape"),
        ("best NaN", dict(best_value=float("nan")), "NaN is not JSON"),
        ("best inf", dict(best_value=1e400), "Infinity is not JSON"),
        ("best string", dict(best_value="1.0"), "best_value must be a finite number"),
        ("best not in history", dict(best_value=-123.0), "not the value of a stable design"),
        ("since_best > iteration", dict(since_best=it + 1), "since_best"),
        ("since_best negative", dict(since_best=-1), "since_best"),
        ("iteration float", dict(iteration=float(it)), "iteration must be an integer"),
        ("history short", dict(history=short), f"holds {it - 1} entries"),
        ("history renumbered", dict(history=renumbered), "history entry 0"),
        ("history not a list", dict(history={}), "history holds dict"),
    ]


@pytest.mark.parametrize("case", range(13))
def test_checkpoint_state_is_validated_on_load(tmp_path, case):
    """A NaN θ would resume to exit 0 with a tuned design that diverges everywhere; a NaN best value would
    change the tuned gain.  Each forged state, though its digest matches, is refused in one line."""
    ckpt = tmp_path / "c.npz"
    _run(ckpt)
    meta = json.loads(str(_entries(ckpt)["meta"]))
    name, change, match = _bad_states(meta)[case]
    arrays = {k: change.pop(k) for k in ("theta", "best_theta") if k in change}
    _forge(ckpt, **arrays, **change)
    with pytest.raises(CheckpointError, match=match) as e:
        _run(ckpt, resume=True)
    assert "\n" not in str(e.value), name


def test_checkpoint_fifo_does_not_block_resume(tmp_path):
    """`mkfifo OUT/checkpoint.npz; jaxobs tune --resume` is refused in one line, not blocked on forever."""
    ckpt = tmp_path / "c.npz"
    os.mkfifo(ckpt)
    done, e = _in_thread(lambda: _run(ckpt, resume=True))
    assert done and isinstance(e, CheckpointError) and "not a file" in str(e)


# --------------------------------------------------------------------------
# result.json read back by `study` and `export`: one schema, bounded before parsing
# --------------------------------------------------------------------------


def _result(**changes):
    """A minimal SOGIFLLWIF result (the fields study and export read), with ``changes`` applied."""
    res = {
        "job": {
            "job": {"name": "t", "component": "SOGIFLLWIF"},
            "component": {"k1": 1.7},
            "gains": {"lam": {"init": 11000.0, "lower": 1000.0, "upper": 1e5}},
            "scenarios": {"signal": "grid", "grid": {"dc": [0.0]}},
            "objective": {"terms": [{"metric": "itae_freq"}]},
        },
        "component": "SOGIFLLWIF",
        "gains": {"tuned": {"lam": 9000.0}},
    }
    res.update(changes)
    return res


# (name, result.json text, expected message): each refused in one line, not accepted, coerced or a traceback
BAD_RESULTS = [
    ("nested 100000", "[" * 100_000 + "]" * 100_000, "nested deeper than 64"),
    ("nested in an object", '{"job": ' + "[" * 70 + "]" * 70 + "}", "nested deeper than 64"),
    ("lam a string", json.dumps(_result(gains={"tuned": {"lam": "12337"}})), "gains.tuned.lam must be a finite number"),
    ("lam a bool", json.dumps(_result(gains={"tuned": {"lam": True}})), "gains.tuned.lam must be a finite number"),
    ("lam NaN", json.dumps(_result(gains={"tuned": {"lam": float("nan")}})), "NaN is not a JSON number"),
    ("lam 1e999", json.dumps(_result()).replace("9000.0", "1e999"), "gains.tuned.lam must be a finite number"),
    ("tuned empty", json.dumps(_result(gains={"tuned": {}})), "gains.tuned is empty"),
    ("tuned missing", json.dumps(_result(gains={"initial": {"lam": 1e4}})), "gains.tuned must be a table"),
    ("tuned null, tuned", json.dumps(_result(gains={"tuned": None}, status="converged")), "gains.tuned must be"),
    ("unknown gain", json.dumps(_result(gains={"tuned": {"gamma": 1.0}})), "gains.tuned.gamma is not a value"),
    ("unknown gain set", json.dumps(_result(gains={"tuned": {"lam": 1.0}, "best": {}})), "gains.best is not one"),
    ("SOGI-FLL relabelled", json.dumps(_result(gains={"tuned": {"k": 1.0, "lam": 9e3}})), "gains.tuned.k is not"),
    (
        "component differs from the job's",
        json.dumps(_result(job={"job": {"component": "SOGIFLL"}})),
        "differs from the job's job.component",
    ),
    ("component CLESO", json.dumps(_result(component="CLESO")), "differs from the job's"),
    ("component unknown", json.dumps(_result(component="X")), "component 'X' is not a jaxobs component"),
    ("component a list", json.dumps(_result(component=[1])), "is not a jaxobs component"),
    ("job a string", json.dumps(_result(job="SOGIFLLWIF")), "job must be a table, got str"),
    ("job.component a list", json.dumps(_result(job={"component": [1]})), "job.component must be a table"),
    ("job value a string", json.dumps(_result(job={"component": {"k1": "1.7"}})), "job.component.k1 must be"),
    ("ts a string", json.dumps(_result(ts="1e-4")), "ts must be a sample time"),
    ("ts negative", json.dumps(_result(ts=-1e-4)), "ts must be a sample time"),
    ("omega_n a string", json.dumps(_result(omega_n="314")), "omega_n must be a finite number"),
    ("scores a list", json.dumps(_result(scores=[])), "scores must be a table"),
    ("lam off its bounds", json.dumps(_result(gains={"tuned": {"lam": 1e6}})), r"1e\+06 is outside .*1000, 100000"),
    ("no design", json.dumps(_result(gains={"tuned": None, "initial": None}, status="diverged")), "holds no design"),
    ("values a list", json.dumps(_result(values=[])), "values must be a table"),
    ("values a string gain", json.dumps(_result(values={"tuned": {"lam": "9e3"}})), "values.tuned.lam must be"),
    ("job unparseable", json.dumps(_result(job={"job": {"component": "SOGIFLLWIF"}})), r"missing \(required\)"),
    ("a list", "[]", "not a tuning result"),
    ("no gains", json.dumps({"job": {}, "component": "SOGIFLLWIF"}), "no 'gains'"),
    ("not JSON", "{", "not valid JSON"),
    ("not UTF-8", b"\xff\xfe{}", "not UTF-8"),
]


@pytest.mark.parametrize("name, text, match", BAD_RESULTS, ids=[b[0] for b in BAD_RESULTS])
def test_result_json_schema(tmp_path, name, text, match):
    from jaxobs_tuning.results import load_result

    p = tmp_path / "result.json"
    (p.write_bytes if isinstance(text, bytes) else p.write_text)(text)
    with pytest.raises(ValueError, match=match) as e:
        load_result(p)
    assert "\n" not in str(e.value) and len(str(e.value)) < 400


def test_result_json_special_and_large_files(tmp_path):
    from jaxobs_tuning.results import MAX_RESULT_BYTES, load_result

    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    done, e = _in_thread(lambda: load_result(fifo))
    assert done and isinstance(e, ValueError) and "not a file" in str(e)
    big = tmp_path / "big.json"
    with open(big, "wb") as f:
        f.truncate(MAX_RESULT_BYTES + 1)
    with pytest.raises(ValueError, match="more than the limit"):
        load_result(big)
    ok = tmp_path / "ok.json"
    ok.write_text(json.dumps(_result()))
    assert load_result(ok)["gains"]["tuned"] == {"lam": 9000.0}


@pytest.mark.parametrize("cmd", ["export", "study"])
@pytest.mark.parametrize("case", ["nested 100000", "lam a string", "tuned empty", "job a string", "component CLESO"])
def test_result_json_errors_are_one_line_exit_2_in_export_and_study(tmp_path, capsys, cmd, case):
    """`export` and `study` read a result through the one schema: one line, exit 2 (a RecursionError,
    TypeError or AttributeError before, or a string accepted as a gain)."""
    from jaxobs_tuning.cli import main

    text = dict((b[0], b[1]) for b in BAD_RESULTS)[case]
    (tmp_path / "result.json").write_text(text)
    if cmd == "export":
        argv = ["export", str(tmp_path / "result.json"), "--out", str(tmp_path / "x"), "--quiet", "--no-cache"]
    else:
        (tmp_path / "s.toml").write_text('[designs.t]\nresult = "result.json"\n[axes]\ndc = [0.0]\n')
        argv = ["study", str(tmp_path / "s.toml"), "--check", "--no-cache"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("jaxobs: error:"), err


# --------------------------------------------------------------------------
# CSV recordings: csv errors in one line, strict numbers
# --------------------------------------------------------------------------

BAD_CSV = [
    # one reader for recordings and drive logs (jaxobs.signals._logfile): no field-length limit of its own (the file's
    # size is capped); a numeral past float64's range is read as inf and refused by the finiteness check
    ("a numeral of 140000 digits", "t,x\n0," + "1" * 140_000 + "\n1,2\n", "column 'x' is not finite at data row 1"),
    ("unterminated quote", 't,x\n0,"1\n1,2\n', "line 2 holds a field that is not a number$"),
    ("1_0", "t,x\n0,1_0\n1,2\n", "line 2 holds a field that is not a number"),
    ("0x10", "t,x\n0,0x10\n1,2\n", "not a number"),
    ("an Arabic-Indic digit", "t,x\n0,\u0661\n1,2\n", "line 2 holds a field that is not a number"),
    ("a long number", "t,x\n0," + "1" * 2000 + "\n1,2\n", "column 'x' is not finite at data row 1"),
    ("extra fields", "t,x\n0,1\n1,2,3\n", "line 3 has 3 fields, the file 2"),
    ("a field missing", "t,x\n0,1\n1\n2,3\n", "line 3 has 1 fields, the file 2"),
]


@pytest.mark.parametrize("name, text, match", BAD_CSV, ids=[b[0] for b in BAD_CSV])
def test_csv_errors_are_one_line(tmp_path, name, text, match):
    import jaxobs

    p = tmp_path / "r.csv"
    p.write_text(text)
    with pytest.raises(ValueError, match=match) as e:
        jaxobs.SampledSignal.from_csv(p, time_column="t")
    assert "\n" not in str(e.value) and str(p) in str(e.value)


def test_csv_fifo_is_refused(tmp_path):
    import jaxobs

    p = tmp_path / "r.csv"
    os.mkfifo(p)
    done, e = _in_thread(lambda: jaxobs.SampledSignal.from_csv(p, time_column="t"))
    assert done and isinstance(e, ValueError) and "not a file" in str(e)


# --------------------------------------------------------------------------
# bounded: every size a flag or a number in a file can set ends in one line naming it, exit 2
# --------------------------------------------------------------------------


def _one_line_exit_2(capsys, argv, match):
    """``jaxobs ARGV`` exits 2 (returned, or argparse's SystemExit) with ``match`` on stderr's last line, and
    nothing but argparse's usage before it."""
    from jaxobs_tuning.cli import main

    try:
        rc = main(argv)
    except SystemExit as e:  # argparse: usage, then one error line
        rc = e.code
    assert rc == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert match in lines[-1] and all(ln.startswith(("usage:", " ")) for ln in lines[:-1]), lines


@pytest.mark.parametrize(
    "argv, match",
    [
        (["export", "--design", "wif", "--steps", "100000000"], "--steps must be in 10000..2000000"),
        (["export", "--design", "wif", "--ts", "1e-300"], "--ts must be a sample time in [1e-09, 1] s"),
        (["export", "--design", "wif", "--ts", "10"], "--ts must be a sample time"),
        (["study", "s.toml", "--coordinator", "localhost:1", "--num-processes", "2", "--process-id", "1",
          "--timeout", "2147483648"], "--timeout: must be an integer >= 1 and <= 86400"),
        (["study", "s.toml", "--num-processes", "9" * 5000], "--num-processes: must be an integer >= 1"),
    ],
)  # fmt: skip
def test_flag_sizes_are_bounded(tmp_path, capsys, argv, match):
    """Unbounded, `export --steps 100000000` writes 6.3 GB, `--ts 1e-300` underflows to 0 in float32 (and
    --check says OK) and `--timeout 2147483648` is a TypeError: each is refused in one line naming the flag."""
    if argv[0] == "export":
        argv = [*argv, "--out", str(tmp_path / "x"), "--no-cache"]
    _one_line_exit_2(capsys, argv, match)


def test_a_5000_digit_integer_in_a_job_names_its_field(tmp_path, capsys):
    """A 5000-digit integer is refused naming its field, not with Python's "Exceeds the limit (4300 digits)"."""
    from importlib import resources

    text = (resources.files("jaxobs_tuning") / "presets" / "wif_robust.toml").read_text()
    assert "seed = 0" in text
    job = tmp_path / "job.toml"
    job.write_text(text.replace("seed = 0", "seed = " + "9" * 5000))
    _one_line_exit_2(capsys, ["tune", str(job), "--check", "--no-cache"], "job.seed: a number of 5000 digits")


# --------------------------------------------------------------------------
# studies apply the jobs' physical ranges (one validator: jaxobs_tuning.job.check_speed_axes)
# --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "machine, axes, field",
    [
        ("ipmsm002", "speed_rpm = [600.0, 5000.0]", "axes.speed_rpm[1]"),
        ("spmsm000", "speed_rpm = [600.0, 3000.0]", "axes.speed_rpm[1]"),
        ("ipmsm002", "speed_rpm = [600.0]\nspeed_step_rpm = [1000.0]", "axes.speed_step_rpm[0]"),
    ],
)
def test_drive_study_speeds_within_the_inverter_limit(tmp_path, capsys, machine, axes, field):
    """A drive study's speeds are held to the inverter's limit at --check, as a job's are (ipmsm002: nothing
    above 1323 r/min)."""
    comp = "CLESO" if machine == "ipmsm002" else "SOIFO"
    study = tmp_path / "s.toml"
    study.write_text(
        f'[study]\nkind = "drive"\nmachine = "{machine}"\nhorizon = 0.2\n'
        f'[designs.a]\nclosed_form = "{comp}"\n[axes]\n{axes}\n'
    )
    _one_line_exit_2(capsys, ["study", str(study), "--check", "--no-cache"], f"{field}: ")


# --------------------------------------------------------------------------
# honest outcomes: an objective that overflows is not a system that diverged
# --------------------------------------------------------------------------


GOOD_TERMS = 'terms = [{ metric = "itae_freq", weight = 1.0 }]'


def test_objective_overflow_is_its_own_outcome(tmp_path, capsys, monkeypatch):
    """weight = 1e308 is status "overflow", a reason naming the weights, exit 3 (nothing tuned): not "every design
    tried (5) diverged in >= 54 scenarios" while the scores show 0 diverged.

    The gradient of this objective is finite (about 1e306) and forward mode, the objective's default for a
    few gains, computes it: the job is scored (1.3e307) and its figures drawn (the convergence plot's log
    axis once overflowed there).  Reverse mode overflows inside its cotangents, which carry the weight
    back through every step: that run reaches the overflow outcome."""
    import jaxobs_tuning.objective as O
    from jaxobs_tuning.cli import main
    from tests.test_outputs import GOOD

    job = tmp_path / "job.toml"
    assert GOOD_TERMS in GOOD
    terms = 'terms = [{ metric = "itae_freq", weight = 1e308 }, { metric = "ripple_freq", weight = 1e308 }]'
    job.write_text(GOOD.replace('name = "../../escape"', 'name = "o"').replace(GOOD_TERMS, terms))
    assert main(["tune", str(job), "--out", str(tmp_path / "f"), "--quiet"]) == 0
    res = json.loads((tmp_path / "f" / "result.json").read_text())
    assert res["status"] != "overflow" and 1e306 < res["scores"]["initial"]["objective"] < 1.8e308
    assert (tmp_path / "f" / "convergence.png").stat().st_size > 0
    capsys.readouterr()
    monkeypatch.setattr(O, "FORWARD_MAX", 0)  # reverse mode
    # another job file (its digest keys the kept traced programs, jaxobs.kept_jit: not the forward-mode ones)
    job.write_text(job.read_text().replace('name = "o"', 'name = "o-reverse"'))
    assert main(["tune", str(job), "--out", str(tmp_path / "o"), "--quiet"]) == 3
    res = json.loads((tmp_path / "o" / "result.json").read_text())
    assert res["status"] == "overflow" and "terms[1].weight = 1e+308" in res["reason"], res["reason"]
    assert "diverged" not in res["reason"] and res["scores"]["initial"]["diverged"] == 0
    assert "OVERFLOW" in capsys.readouterr().out


class _OverflowsAt(AbstractObjective):
    """A stand-in objective whose gradient overflows from iteration ``at`` on (a finite value, a finite run)."""

    param: Parametrization
    at: int
    calls: list  # [evaluations so far] (a module is frozen: the count lives in a list)

    def __init__(self, at: int):
        self.param = Parametrization([GainSpec("a", 2.0, 0.1, 50.0)])
        self.at, self.calls = at, [0]

    def value_grad_diverged_overflowed(self, theta, scenarios):
        import jax.numpy as jnp

        n = self.calls[0]
        self.calls[0] += 1
        return jnp.sum(theta**2), 2 * theta, int(n >= self.at), int(n >= self.at)

    def value(self, theta, scenarios):
        return self.value_grad_diverged_overflowed(theta, scenarios)[0]


@pytest.mark.parametrize("at", [0, 3, 6])
def test_overflow_is_checked_at_every_iteration_and_stays_the_outcome(at):
    """An objective that overflows at a later iterate (or the last, scored after the loop) ends the run there
    with status "overflow" and nothing tuned, not "converged" on the designs before it."""
    from jaxobs_tuning import solvers, strategies

    cfg = strategies.solver("adam", learning_rate=0.1, steps=6, patience=100, progress_every=1)
    obj = _OverflowsAt(at)
    res = solvers.tune(obj, cfg, obj.param.theta0(), quiet=True)
    assert res.status == "overflow" and res.theta is None and res.best_iteration is None
    assert res.iterations == at and len(res.history) == at + 1
    assert f"overflows at iteration {at}" in res.reason
    never = solvers.tune(_OverflowsAt(99), cfg, obj.param.theta0(), quiet=True)
    assert never.status != "overflow" and never.theta is not None
