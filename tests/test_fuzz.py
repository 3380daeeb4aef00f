"""Fuzzing `jaxobs tune --check` with mutated preset jobs: every file ends in exit 0 (valid) or exit 2 with
one short line on stderr, never a traceback or a hang; and a list of files that must fail is rejected.

The mutations (seeded, so the run is reproducible): a key dropped or duplicated, a value replaced by a wrong
type, a huge / negative / NaN / inf number, an integer of 400 digits, a long string or list, deep nesting of
arrays, inline tables and dotted keys, unknown sections, bad UTF-8, truncation.
"""

import random
import time
from pathlib import Path

import pytest

from tuning.cli import main

PRESETS = Path(__file__).parents[1] / "tuning" / "presets"
JOBS = sorted(p for p in PRESETS.glob("*.toml") if not p.name.startswith("study_"))

BAD_VALUES = [
    "nan",
    "inf",
    "-inf",
    "+nan",
    "1e400",
    "-1e400",
    "9" * 400,
    "-" + "9" * 400,
    "1e300",
    "-1e300",
    "1e-300",
    "0",
    "-1",
    "-0.0",
    "1000000000000",
    "2.5",
    '"x"',
    '"' + "a" * 5000 + '"',
    "true",
    "[]",
    "{}",
    "[1.0, 2.0]",
    "[nan]",
    "[" + "9" * 400 + "]",
    "[" + ", ".join(["1.0"] * 3000) + ", true]",
    "{ a = 1 }",
    "1979-05-27T07:32:00Z",
    "[[1.0]]",
    '["a", 1]',
]


def _lines_with_values(text: str) -> list[int]:
    return [i for i, ln in enumerate(text.splitlines()) if "=" in ln and not ln.lstrip().startswith("#")]


def mutations(seed: int = 0, per_preset: int = 50):
    """(label, bytes) for ``per_preset`` random mutations of each preset job, plus structural ones."""
    rng = random.Random(seed)
    for preset in JOBS:
        text = preset.read_text()
        lines = text.splitlines()
        valued = _lines_with_values(text)
        for j in range(per_preset):
            kind = rng.choice(["value", "value", "value", "drop", "dup", "section", "header", "truncate"])
            new = list(lines)
            i = rng.choice(valued)
            if kind == "value":
                key = new[i].split("=", 1)[0]
                new[i] = f"{key}= {rng.choice(BAD_VALUES)}"
            elif kind == "drop":
                del new[i]
            elif kind == "dup":
                new.insert(i, new[i])
            elif kind == "section":
                new.append(rng.choice(["[studyy]", "[job.extra]", "[solver.x]", "[gains.nope]", '["\\u0000"]']))
                new.append("a = 1")
            elif kind == "header":
                hs = [k for k, ln in enumerate(new) if ln.startswith("[")]
                h = rng.choice(hs)
                new[h] = new[h].replace("]", "x]", 1)
            else:
                new = new[: rng.randrange(len(new))]
            yield f"{preset.name}:{kind}:{j}", ("\n".join(new) + "\n").encode()
        yield f"{preset.name}:bad-utf8", text.encode() + b"\n# \xff\xfe\n"
        yield f"{preset.name}:bad-utf8-value", text.encode().replace(b'name = "', b'name = "\xc3\x28', 1)
        yield f"{preset.name}:deep-array", text.encode() + b"\nz = " + b"[" * 5000 + b"]" * 5000 + b"\n"
        yield f"{preset.name}:deep-inline", text.encode() + b"\nz = " + b"{a = " * 3000 + b"1" + b"}" * 3000 + b"\n"
        yield f"{preset.name}:dotted", text.encode() + b"\n" + b".".join([b"a"] * 100_000) + b" = 1\n"
        yield f"{preset.name}:long-key", text.encode() + b"\n" + b"k" * 10_000 + b" = 1\n"
        yield f"{preset.name}:big", text.encode() + b"#" * 1_100_000 + b"\n"
        yield f"{preset.name}:empty", b""


def _base(name="wif_robust.toml") -> str:
    return (PRESETS / name).read_text()


W = _base()
C = _base("cleso.toml")

# (label, job text, a field the one-line error must name)
MUST_FAIL = [
    ("int 10^400 in a float", W.replace("t_event = 0.1", "t_event = " + "9" * 400), "scenarios.t_event"),
    ("horizon 1e300", W.replace("horizon = 0.4", "horizon = 1e300"), "scenarios.horizon"),
    ("horizon 1e9", W.replace("horizon = 0.4", "horizon = 1e9"), "scenarios.horizon"),
    (
        "horizon < one sample",
        W.replace("t_event = 0.1", "t_event = 0.0")
        .replace("horizon = 0.4", "horizon = 5e-5")
        .replace("steady_from = 0.3", "steady_from = 0.0"),
        "scenarios.horizon",
    ),
    ("empty steady window", W.replace("steady_from = 0.3", "steady_from = 0.3995"), "scenarios.steady_from"),
    ("sample 10^12", W.replace("steady_from = 0.3", "steady_from = 0.3\nsample = 1000000000000"), "scenarios.sample"),
    ("negative tol", W.replace("steps = 60", "steps = 60\ntol = -1.0"), "solver.tol"),
    (
        "narrow bounds",
        W.replace("lower = 500.0\nupper = 200000.0", "lower = 11558.9999999\nupper = 11559.0000001"),
        "gains.lam",
    ),
    ("sag 2.0", W.replace("dc = [0.0, 0.05, 0.1]", "sag = [2.0]"), "scenarios.grid.sag"),
    (
        "holdout freq_step -60 Hz",
        W.replace("freq_step = [-1.5, 0.5, 2.5]", "freq_step = [-60.0]"),
        "holdout.grid.freq_step",
    ),
    ("holdout sag 1.0", W.replace("dc = [0.02, 0.12]", "sag = [1.0]"), "holdout.grid.sag"),
    (
        "negative harmonics",
        W.replace("harmonics_scale = [0.0, 1.0]", "harmonics_scale = [-1.0]"),
        "scenarios.grid.harmonics_scale",
    ),
    ("drive speed 0", C.replace("speed_rpm = [300.0, 600.0, 840.0]", "speed_rpm = [0.0]"), "scenarios.grid.speed_rpm"),
    (
        "too many scenarios",
        W.replace("phase_jump_deg = [-40.0, 0.0, 40.0]", "phase_jump_deg = [" + ",".join(["1"] * 200_000) + "]"),
        "scenarios.grid",
    ),
    (
        "memory",
        W.replace("horizon = 0.4", "horizon = 900.0")
        .replace("steady_from = 0.3", "steady_from = 899.0")
        .replace("phase_jump_deg = [-40.0, 0.0, 40.0]", "phase_jump_deg = [" + ", ".join(["1.0"] * 500) + "]"),
        "scenarios.horizon",
    ),
    ("nan alpha", W.replace("alpha = 0.75", "alpha = nan"), "objective.alpha"),
    ("inf penalty", W.replace("penalty = 1000.0", "penalty = inf"), "objective.penalty"),
    ("seed 10^400", W.replace("seed = 0", "seed = " + "9" * 400), "job.seed"),
    ("steps 10^12", W.replace("steps = 60", "steps = 1000000000000"), "solver.steps"),
    ("deep nesting", W + "\nx = " + "[" * 5000 + "]" * 5000 + "\n", "job file"),
    ("dotted key", W + "\n" + ".".join(["a"] * 100_000) + " = 1\n", "job file"),
    (
        "bad element of a long axis",
        W.replace("dc = [0.0, 0.05, 0.1]", "dc = [" + "0.0, " * 100_000 + '"x"]'),
        "scenarios.grid.dc[100000]",
    ),
    ("unknown section", W + "\n[studyy]\na = 1\n", "job file.studyy"),
    ("file > 1 MB", W + "#" * 1_100_000 + "\n", "job file"),
]


def _check(path: Path, capsys) -> tuple[int, str, float]:
    t0 = time.perf_counter()
    rc = main(["tune", str(path), "--check"])
    dt = time.perf_counter() - t0
    return rc, capsys.readouterr().err, dt


def _one_line(err: str):
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxobs: error: "), err[:500]
    assert len(lines[0]) <= 230 and "Traceback" not in err, lines[0][:500]


def test_fuzzed_job_files_never_traceback_or_hang(tmp_path, capsys):
    cases = list(mutations())
    assert len(cases) >= 300
    path = tmp_path / "job.toml"
    stats = {0: 0, 2: 0}
    slowest = (0.0, "")
    for label, data in cases:
        path.write_bytes(data)
        rc, err, dt = _check(path, capsys)
        assert rc in (0, 2), f"{label}: exit {rc}: {err[:500]}"
        if rc == 2:
            _one_line(err)
        stats[rc] += 1
        slowest = max(slowest, (dt, label))
        assert dt < 2.0, f"{label}: --check took {dt:.2f} s"
    print(
        f"fuzz: {len(cases)} files, {stats[2]} rejected, {stats[0]} accepted, 0 tracebacks, "
        f"slowest {slowest[0]:.2f} s ({slowest[1]})"
    )


@pytest.mark.parametrize("label, text, field", MUST_FAIL, ids=[m[0] for m in MUST_FAIL])
def test_must_fail_job_files_are_rejected_by_check(tmp_path, capsys, label, text, field):
    path = tmp_path / "job.toml"
    path.write_text(text)
    rc, err, dt = _check(path, capsys)
    assert rc == 2, f"{label}: accepted"
    _one_line(err)
    assert field in err, err
    assert dt < 2.0
