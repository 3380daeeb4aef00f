"""Fuzzing what a run reads besides its job file: result.json files fed to `study` and
`export` (jaxobs_tuning.results.load_result, then tuned_component as a study builds it) and CSV recordings
(jaxobs.signals.read_recording).  Every input ends accepted or refused with a one-line ValueError raised by one
of jaxobs's checks (the command line shows it as bad input, not as an internal error): never
another exception (a traceback), never a hang, and never an input known to be invalid accepted
("accepted-invalid": a gain that is not a finite JSON number, an unknown gain or component, a CSV field
that is not a strict number).  The counts are printed (`pytest -s`).  The study-file fuzz is in
tests/test_fuzz.py.  Seeded: reproducible."""

from __future__ import annotations

import copy
import json
import math
import random
import time
from pathlib import Path

import pytest

from jaxobs import papers
from jaxobs.signals import read_recording
from jaxobs_tuning.cli_run import _raised_by_a_check
from jaxobs_tuning.results import load_result, tuned_component

HANG_S = 10.0  # CPU seconds of this process (time.process_time): other processes' load does not stretch them
PRESETS = Path(__file__).parents[1] / "tuning" / "presets"

RESULT = {
    "status": "converged",
    "job": {
        "job": {"name": "t", "component": "SOGIFLLWIF"},
        "component": {"k1": 1.7},
        "gains": {"lam": {"init": 11000.0, "lower": 1000.0, "upper": 1e5}},
        "scenarios": {"signal": "grid", "grid": {"dc": [0.0]}},
        "objective": {"terms": [{"metric": "itae_freq"}]},
    },
    "component": "SOGIFLLWIF",
    "ts": 1e-4,
    "omega_n": 314.159,
    "gains": {"initial": {"lam": 11000.0}, "tuned": {"lam": 9000.0}, "closed_form": {"lam": 11000.3}},
    "scores": {"tuned": {"objective": 0.1, "diverged": 0}},
}

# (value, is it a finite JSON number?)
BAD_VALUES = [
    ("12337", False),
    (True, False),
    (None, False),
    ([], False),
    ({}, False),
    ([1.0], False),
    ("x" * 10_000, False),
    (-1, True),
    (0, True),
    (1e308, True),
    (10**30, True),
]
_TOKENS = ["NaN", "Infinity", "-Infinity", "1e999", "[" * 100 + "]" * 100, "{" * 70 + "}" * 70]


def _paths(obj, prefix=()):
    """Every (path, leaf) of a JSON value."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, (*prefix, k))
    else:
        yield prefix, obj


def _set(obj, path, value):
    for k in path[:-1]:
        obj = obj[k]
    obj[path[-1]] = value


def _strict(path) -> bool:
    """A leaf the schema (or the job parser a study runs) must refuse any non-number at."""
    return path[:1] == ("gains",) or path[:2] == ("job", "component") or path in (("ts",), ("omega_n",))


def result_mutations(seed=0, n=400):
    """(label, bytes, invalid): ``invalid`` True where the result must be refused."""
    rng = random.Random(seed)
    leaves = list(_paths(RESULT))
    for j in range(n):
        res = copy.deepcopy(RESULT)
        kind = rng.choice(["value", "value", "token", "drop", "gain", "component", "truncate"])
        path, _ = rng.choice(leaves)
        invalid = False
        if kind == "value":
            v, number = rng.choice(BAD_VALUES)
            _set(res, path, v)
            invalid = _strict(path) and (not number or (path == ("ts",) and v <= 0))
            invalid = invalid and not (path == ("omega_n",) and v is None)  # null: a component without one
            data = json.dumps(res).encode()
        elif kind == "token":
            _set(res, path, "@@")
            tok = rng.choice(_TOKENS)
            data = json.dumps(res).replace('"@@"', tok).encode()
            invalid = _strict(path) or tok.startswith(("[", "{"))  # deeper than 64, or not a JSON number
            invalid = invalid or tok in ("NaN", "Infinity", "-Infinity")
        elif kind == "drop":
            del_path = path[:-1] if len(path) > 1 and rng.random() < 0.3 else path
            parent = res
            for k in del_path[:-1]:
                parent = parent[k]
            del parent[del_path[-1]]
            invalid = del_path in (("gains",), ("component",), ("job",), ("gains", "tuned"), ("gains", "tuned", "lam"))
            data = json.dumps(res).encode()
        elif kind == "gain":
            res["gains"]["tuned"][rng.choice(["k", "gamma", "Rs", "", "lam "])] = 1.0
            invalid, data = True, json.dumps(res).encode()
        elif kind == "component":
            res["component"] = rng.choice(["SOGIFLL", "CLESO", "X", "sogifllwif", ""])
            invalid, data = True, json.dumps(res).encode()
        else:
            full = json.dumps(res).encode()
            data = full[: rng.randrange(len(full))]
            invalid = True
        yield f"result:{kind}:{'.'.join(map(str, path))}:{j}", data, invalid
    yield "result:bad-utf8", json.dumps(RESULT).encode().replace(b'"t"', b'"\xff"'), True
    yield "result:deep-100000", b"[" * 100_000 + b"]" * 100_000, True
    yield "result:empty", b"", True


def csv_mutations(seed=0, n=400):
    rng = random.Random(seed)
    rows = [[f"{k * 1e-4:.4f}", f"{math.sin(k * 0.0314):.6f}", f"{math.cos(k * 0.0314):.6f}"] for k in range(200)]
    bad_fields = ["1_0", "0x10", "", "1,5", '"1', "nan", "inf", "1e999", "1" * 2000, "١", " 1 2", "--1", "1e", "e5"]
    for j in range(n):
        new = [list(r) for r in rows]
        kind = rng.choice(["field", "field", "field", "extra", "drop", "truncate", "header"])
        i, c = rng.randrange(1, len(new)), rng.randrange(1, 3)
        invalid = True
        if kind == "field":
            new[i][c] = rng.choice(bad_fields)
        elif kind == "extra":
            new[i].append("1.0")
        elif kind == "drop":
            del new[i][c]
        elif kind == "header":
            invalid = False
        text = "t,x,y\n" + "\n".join(",".join(r) for r in new) + "\n"
        if kind == "header":
            text = "t,x,x\n" + text.split("\n", 1)[1]
            invalid = True
        data = text.encode()
        if kind == "truncate":
            data = data[: rng.randrange(8, len(data))]
            invalid = False  # a row cut inside a number is still a number, or a short row (refused)
        yield f"csv:{kind}:{i}.{c}:{j}", data, invalid
    yield "csv:field-140000", ("t,x\n0," + "1" * 140_000 + "\n").encode(), True
    yield "csv:unterminated", b't,x\n0,"1\n1,2\n', True
    yield "csv:bad-utf8", b"t,x\n0,1\xff\n", True
    yield "csv:empty", b"", True


def _fuzz(cases, path, read, what):
    counts = dict(tried=0, accepted=0, refused=0, tracebacks=0, hangs=0, accepted_invalid=0)
    bad = []
    for label, data, invalid in cases:
        path.write_bytes(data)
        t0 = time.process_time()
        try:
            read(path)
            counts["accepted"] += 1
            if invalid:
                counts["accepted_invalid"] += 1
                bad.append(f"{label}: accepted")
        except ValueError as e:
            counts["refused"] += 1
            if "\n" in str(e) or len(str(e)) > 400:
                counts["tracebacks"] += 1
                bad.append(f"{label}: not one line: {str(e)[:200]!r}")
            elif not _raised_by_a_check(e):  # the command line would show it as an internal error, with a log
                counts["tracebacks"] += 1
                bad.append(f"{label}: a ValueError no check raised: {str(e)[:200]!r}")
        except Exception as e:  # noqa: BLE001 - counted: a traceback in the command line
            counts["tracebacks"] += 1
            bad.append(f"{label}: {type(e).__name__}: {str(e)[:200]}")
        counts["tried"] += 1
        if time.process_time() - t0 > HANG_S:
            counts["hangs"] += 1
            bad.append(f"{label}: {time.process_time() - t0:.1f} s")
    print(f"{what}: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    assert not bad, bad[:10]
    return counts


def _result_as_a_study_reads_it(path):
    tuned_component(load_result(path))


def _csv(path):
    read_recording(path, ["x", "y"], time_column="t", ts=1e-4)


def test_fuzzed_result_json_never_traceback_hang_or_accept_invalid(tmp_path):
    counts = _fuzz(list(result_mutations()), tmp_path / "result.json", _result_as_a_study_reads_it, "result.json")
    assert counts["tried"] >= 400 and counts["accepted"] > 0


def test_fuzzed_csv_recordings_never_traceback_hang_or_accept_invalid(tmp_path):
    counts = _fuzz(list(csv_mutations()), tmp_path / "rec.csv", _csv, "CSV recordings")
    assert counts["tried"] >= 400 and counts["accepted"] > 0


@pytest.mark.slow
def test_fuzzed_inputs_more_seeds(tmp_path):
    for seed in range(1, 6):
        _fuzz(list(result_mutations(seed)), tmp_path / "r.json", _result_as_a_study_reads_it, f"result.json {seed}")
        _fuzz(list(csv_mutations(seed)), tmp_path / "r.csv", _csv, f"CSV {seed}")


# --------------------------------------------------------------------------
# checkpoints: every forged or damaged one refused (all of these are invalid)
# --------------------------------------------------------------------------


def checkpoint_mutations(good: bytes, seed=0, n=200):
    """(label, bytes) of checkpoints no run writes: a meta field or an array forged (with the digest
    recomputed, or the old one kept), an entry dropped, the file truncated."""
    import io

    import numpy as np

    from jaxobs_tuning.checkpoint import DIGEST, content_digest

    with np.load(io.BytesIO(good), allow_pickle=False) as d:
        base = {k: d[k] for k in d.files}
    meta0 = json.loads(str(base["meta"]))
    it = meta0["iteration"]
    forged_meta = {
        "iteration": [-1, "3", 1.5, None, it + 5, it - 1],
        "since_best": [-1, it + 1, "0", None, 0.5],
        "best_value": ["x", True, -5.0, [1.0]],
        "history": [{}, [], meta0["history"][:-1], None, [None] * it],
        "format": ["jaxobs-checkpoint-1", None],
        "n_leaves": [-1, 10**6, "2"],
    }
    forged_arrays = {
        "theta": [np.asarray([np.nan, 0.0]), np.asarray([np.inf, 0.0]), np.zeros(3), np.zeros(2, dtype=np.int64)],
        "best_theta": [np.asarray([0.0, np.nan]), np.zeros((2, 2))],
        "arr_1": [np.full_like(base["arr_1"], np.nan)],
    }
    rng = random.Random(seed)
    for j in range(n):
        e = dict(base)
        kind = rng.choice(["meta", "meta", "array", "drop", "truncate", "stale digest"])
        if kind == "truncate":
            yield f"ckpt:truncate:{j}", good[: rng.randrange(len(good))]
            continue
        if kind == "drop":
            e.pop(rng.choice([k for k in e if k != DIGEST]))
        elif kind == "array":
            k = rng.choice(list(forged_arrays))
            e[k] = rng.choice(forged_arrays[k])
        else:
            k = rng.choice(list(forged_meta))
            meta = dict(meta0, **{k: rng.choice(forged_meta[k])})
            e["meta"] = np.asarray(json.dumps(meta))
        if kind != "stale digest":
            e[DIGEST] = np.asarray(content_digest(e))
        else:  # a hand edit of the history that keeps the old digest
            meta = dict(meta0, history=[dict(h, value=h["value"] - 1.0) for h in meta0["history"]])
            e["meta"] = np.asarray(json.dumps(meta))
        buf = io.BytesIO()
        np.savez(buf, **e)
        yield f"ckpt:{kind}:{j}", buf.getvalue()


def test_fuzzed_checkpoints_are_all_refused(tmp_path):
    from jaxobs_tuning.solvers import CheckpointError
    from tests.test_outputs import _run

    good = tmp_path / "good.npz"
    _run(good)
    cases = [(label, data, True) for label, data in checkpoint_mutations(good.read_bytes())]
    ckpt = tmp_path / "c.npz"

    def resume(path):
        _run(path, resume=True)  # refused: a CheckpointError, a ValueError

    assert issubclass(CheckpointError, ValueError)
    counts = _fuzz(cases, ckpt, resume, "checkpoints")
    assert counts["tried"] >= 200 and counts["accepted"] == 0


# --------------------------------------------------------------------------
# result files through the command line: envelope, export and study share one reader
# --------------------------------------------------------------------------

COMMANDS = ("envelope", "export", "study")
ALL = frozenset(COMMANDS)
CLESO_CF = papers.LESO_OMEGA0  # the C-LESO job's closed form (002 Table II), inside its bounds [200, 10000]


def _drive_result() -> dict:
    """A result.json of the C-LESO preset job as run_job writes it (the fields any command reads back)."""
    from jaxobs_tuning.job import load_job

    job = load_job(PRESETS / "cleso.toml")
    fixed = {k: float(v) for k, v in job.values.items()}
    gains = {"initial": {"omega0": job.gains[0].init}, "closed_form": {"omega0": CLESO_CF}, "tuned": {"omega0": 2000.0}}
    return {
        "status": "converged",
        "job": job.raw,
        "component": "CLESO",
        "loop": "sensorless",
        "machine": "ipmsm002",
        "ts": float(fixed.pop("ts", 1e-4)),
        "omega_n": None,
        "gains": gains,
        "values": {k: {**fixed, **g} for k, g in gains.items()},
        "scores": {"tuned": {"objective": 0.1, "diverged": 0}},
    }


def _number_ok(path, v) -> bool:
    """Whether a number ``v`` at leaf ``path`` is valid for every command (False: refused by all)."""
    if path[-1] == "omega0" and path[0] in ("gains", "values"):
        if path[1] == "closed_form" and math.isclose(v, CLESO_CF, rel_tol=1e-6):
            return True
        return 200.0 <= v <= 10000.0
    return True


def cli_result_mutations(seed=0, n=120):
    """(label, bytes, refused_by): the commands that must refuse the file (empty: any outcome but a traceback;
    a valid file is accepted by all three)."""
    rng = random.Random(seed)
    base = _drive_result()
    strict = [("gains", g, "omega0") for g in ("initial", "closed_form", "tuned")]
    strict += [("values", g, k) for g in ("initial", "closed_form", "tuned") for k in base["values"]["tuned"]]
    strict += [("ts",), ("omega_n",)]
    for j in range(n):
        res = copy.deepcopy(base)
        kind = rng.choice(["value", "value", "value", "number", "drop", "gain", "bounds", "component", "token",
                           "truncate", "valid"])  # fmt: skip
        path = rng.choice(strict)
        refused = ALL
        if kind == "value":
            v, number = rng.choice(BAD_VALUES)
            _set(res, path, v)
            if number:
                refused = ALL if not _number_ok(path, v) else frozenset()
                refused = refused if path != ("ts",) or v > 0 else ALL
            elif path == ("omega_n",) and v is None:
                refused = frozenset()
        elif kind == "number":  # a finite number: inside or outside the bounds
            v = rng.choice([150.0, 199.9, 200.0, 5000.0, 10000.0, 10001.0, 1e308, -3.0, 1e-9])
            path = rng.choice(strict[:3] + [p for p in strict if p[-1] == "omega0"])
            _set(res, path, v)
            refused = frozenset() if _number_ok(path, v) else ALL
        elif kind == "drop":
            path = rng.choice([("gains",), ("values",), ("job",), ("component",), ("gains", "tuned"),
                               ("values", "tuned"), ("values", "initial"), ("scores",), ("status",)])  # fmt: skip
            parent = res
            for k in path[:-1]:
                parent = parent[k]
            del parent[path[-1]]
            refused = {
                ("values",): frozenset({"envelope"}),
                ("values", "tuned"): frozenset(),
                ("values", "initial"): frozenset(),
                ("scores",): frozenset(),
                ("status",): frozenset(),
            }.get(path, ALL)
        elif kind == "gain":
            table = res[rng.choice(["gains", "values"])][rng.choice(["initial", "closed_form", "tuned"])]
            table[rng.choice(["K1", "gamma", "", "omega0 ", "k1"])] = 1.0
        elif kind == "bounds":  # the job's bounds moved off the stored gains (or made unparseable)
            g = res["job"]["gains"]["omega0"]
            g.update(rng.choice([{"upper": 1800.0}, {"lower": 1600.0, "init": 1700.0}, {"lower": "200"}]))
        elif kind == "component":
            res["component"] = rng.choice(["FALESO", "SOGIFLL", "X", "cleso", ""])
        elif kind == "token":
            _set(res, path, "@@")
            tok = rng.choice(_TOKENS)
            data = json.dumps(res).replace('"@@"', tok).encode()
            yield f"cli:{kind}:{'.'.join(path)}:{j}", data, ALL
            continue
        elif kind == "truncate":
            full = json.dumps(res).encode()
            yield f"cli:{kind}:{j}", full[: rng.randrange(len(full))], ALL
            continue
        else:  # valid: another design inside the bounds, a report key, the keys reordered
            res["values"]["tuned"]["omega0"] = res["gains"]["tuned"]["omega0"] = rng.uniform(200.0, 10000.0)
            res["notes"] = {"anything": [1, "two", None]}
            res = dict(reversed(list(res.items())))
            refused = frozenset()
        yield f"cli:{kind}:{'.'.join(path)}:{j}", json.dumps(res).encode(), refused
    yield "cli:values-list", json.dumps({**base, "values": [1.0]}).encode(), frozenset({"envelope"})
    yield "cli:values-empty", json.dumps({**base, "values": {}}).encode(), frozenset({"envelope"})
    yield "cli:deep-200000", b"[" * 200_000 + b"]" * 200_000, ALL
    yield "cli:bad-utf8", json.dumps(base).encode().replace(b"cleso", b"cl\xffso", 1), ALL
    yield "cli:empty", b"", ALL


class _Accepted(BaseException):
    """Raised once `jaxobs export` has read its result: the export itself is not what is fuzzed."""


def _fuzz_cli(cases, tmp_path, capsys, monkeypatch, what):
    """Each file through envelope --check, export (stopped once read) and study --check, in process."""
    from jaxobs_tuning.cli import main
    from jaxobs_tuning.export import command

    real = command.observer_from_result

    def read_then_stop(*a, **k):
        real(*a, **k)
        raise _Accepted

    monkeypatch.setattr(command, "observer_from_result", read_then_stop)
    res = tmp_path / "result.json"
    study = tmp_path / "study.toml"
    study.write_text(
        '[study]\nkind = "drive"\nname = "f"\nmachine = "ipmsm002"\nhorizon = 0.2\n'
        '[designs.T]\nresult = "result.json"\n[axes]\nspeed_rpm = [300.0]\nload_nm = [0.0]\n'
    )
    argv = {
        "envelope": ["envelope", str(res), "--check", "--no-cache"],
        "export": ["export", str(res), "--out", str(tmp_path / "x"), "--force", "--quiet", "--no-cache"],
        "study": ["study", str(study), "--check", "--out", str(tmp_path / "s"), "--no-cache"],
    }
    counts = dict(files=0, runs=0, accepted=0, refused=0, tracebacks=0, hangs=0, accepted_invalid=0)
    bad = []
    for label, data, refused_by in cases:
        res.write_bytes(data)
        counts["files"] += 1
        for cmd in COMMANDS:
            t0 = time.perf_counter()
            try:
                rc = main(argv[cmd])
            except _Accepted:
                rc = 0
            except BaseException as e:  # noqa: BLE001 - counted: a traceback
                rc = f"{type(e).__name__}: {str(e)[:160]}"
            err = capsys.readouterr().err.strip()
            counts["runs"] += 1
            if rc == 0:
                counts["accepted"] += 1
                if cmd in refused_by:
                    counts["accepted_invalid"] += 1
                    bad.append(f"{cmd} {label}: accepted")
            elif rc == 2 and len(err.splitlines()) == 1 and err.startswith("jaxobs: error: ") and len(err) < 400:
                counts["refused"] += 1
            else:
                counts["tracebacks"] += 1
                bad.append(f"{cmd} {label}: exit {rc}: {err[:200]!r}")
            if time.perf_counter() - t0 > HANG_S:
                counts["hangs"] += 1
                bad.append(f"{cmd} {label}: {time.perf_counter() - t0:.1f} s")
    print(f"{what}: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    assert not bad, bad[:10]
    return counts


def test_fuzzed_result_files_through_envelope_export_and_study(tmp_path, capsys, monkeypatch):
    """At least 300 mutated result files, each read by the three commands: 0 tracebacks, 0 accepted invalid."""
    cases = list(cli_result_mutations())
    counts = _fuzz_cli(cases, tmp_path, capsys, monkeypatch, "result files x (envelope, export, study)")
    with capsys.disabled():
        print(f"\nresult files x (envelope, export, study): {counts}")
    assert counts["files"] >= 100 and counts["runs"] >= 300
    assert counts["accepted"] >= 3 * sum(1 for _, _, r in cases if not r) // 2  # the valid ones run


@pytest.mark.parametrize(
    "label, edit, field",
    [
        ("values as a list", lambda r: r.update(values=[1.0]), "values must be a table"),
        ("values.initial as a list", lambda r: r["values"].update(initial=[1.0]), "values.initial must be a table"),
        ("a gain as a table", lambda r: r["values"]["tuned"].update(omega0={"v": 1.0}), "values.tuned.omega0"),
        ("an unknown gain", lambda r: r["values"]["tuned"].update(K1=1.0), "values.tuned.K1 is not a value"),
        ("a gain as a string", lambda r: r["values"]["tuned"].update(omega0="1.56"), "values.tuned.omega0"),
        ("a gain as a bool", lambda r: r["values"]["tuned"].update(omega0=True), "values.tuned.omega0"),
        ("no design", lambda r: r.update(values={}), "values holds no design"),
        ("off its bounds", lambda r: r["values"]["tuned"].update(omega0=1e308), "[200, 10000]"),
        ("the gains off their bounds", lambda r: r["gains"]["tuned"].update(omega0=1e308), "gains.tuned.omega0"),
    ],
    ids=lambda v: v if isinstance(v, str) and " " in v else "",
)
def test_malformed_results_are_one_line_exit_2_from_envelope(tmp_path, capsys, label, edit, field):
    from jaxobs_tuning.cli import main

    res = _drive_result()
    edit(res)
    (tmp_path / "result.json").write_text(json.dumps(res))
    assert main(["envelope", str(tmp_path / "result.json"), "--check", "--no-cache"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and field in err[0], err


def test_deep_result_is_one_line_exit_2_from_envelope(tmp_path, capsys):
    from jaxobs_tuning.cli import main

    (tmp_path / "result.json").write_bytes(b"[" * 200_000 + b"]" * 200_000)
    assert main(["envelope", str(tmp_path / "result.json"), "--check", "--no-cache"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nested deeper than 64" in err[0]
