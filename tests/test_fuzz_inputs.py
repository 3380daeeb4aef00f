"""Fuzzing what a run reads besides its job file: result.json files fed to `study` and
`export` (jaxobs_tuning.results.load_result, then tuned_component as a study builds it) and CSV recordings
(jaxobs.signals.read_recording).  Every input ends accepted or refused with a one-line ValueError: never
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

import pytest

from jaxobs.signals import read_recording
from jaxobs_tuning.results import load_result, tuned_component

HANG_S = 10.0  # CPU seconds of this process (time.process_time): other processes' load does not stretch them

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
        try:
            _run(path, resume=True)
        except CheckpointError as e:  # a ValueError: refused in one line
            raise ValueError(str(e)) from None

    counts = _fuzz(cases, ckpt, resume, "checkpoints")
    assert counts["tried"] >= 200 and counts["accepted"] == 0
