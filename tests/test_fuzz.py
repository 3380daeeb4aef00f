"""Fuzzing `jaxobs tune --check` with mutated preset jobs, and `jaxobs study --check` with mutated study files:
every file ends in exit 0 (valid) or exit 2 with one short line on stderr, never a traceback or a hang; and
lists of files that must fail are rejected, each naming its field.

The mutations (seeded, so the run is reproducible): a key dropped or duplicated, a value replaced by a wrong
type, a huge / negative / NaN / inf number, an integer of 400 digits, a long string or list, deep nesting of
arrays, inline tables and dotted keys, unknown sections, bad UTF-8, truncation.
"""

import json
import random
import time
from pathlib import Path

import pytest

from jaxobs_tuning.cli import main
from jaxobs_tuning.job.fields import MAX_ERROR

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


class _Named:
    def __init__(self, name: str, text: str):
        self.name, self.text = name, text


# A hang is unbounded work; a --check takes 0.01-1.4 s on the quiet 2-core machine (the largest file, 200 000
# values, is the slowest).  Measured in this process's CPU seconds (time.process_time), which other processes'
# load does not stretch: 10 s catches a parse gone quadratic (a blocking read never returns at all).
HANG_S = 10.0


def _lines_with_values(text: str) -> list[int]:
    return [i for i, ln in enumerate(text.splitlines()) if "=" in ln and not ln.lstrip().startswith("#")]


def mutations(seed: int = 0, per_preset: int = 50, files=None):
    """(label, bytes) for ``per_preset`` random mutations of each preset job (or of ``files``: (name, text)),
    plus structural ones."""
    rng = random.Random(seed)
    for preset in files if files is not None else [_Named(p.name, p.read_text()) for p in JOBS]:
        text = preset.text
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
        "freq_step 600 Hz",
        W.replace("freq_step = [-2.0, -1.0,", "freq_step = [600.0, -1.0,"),
        "scenarios.grid.freq_step[0]",
    ),
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
    t0 = time.process_time()
    rc = main(["tune", str(path), "--check"])
    dt = time.process_time() - t0
    return rc, capsys.readouterr().err, dt


def _one_line(err: str):
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxobs: error: "), err[:500]
    # MAX_ERROR bounds the message; 30 more for the "jaxobs: error: " prefix
    assert len(lines[0]) <= MAX_ERROR + 30 and "Traceback" not in err, lines[0][:500]


def test_a_long_job_error_keeps_its_remedy():
    """A message of several hundred characters is printed whole: the remedy at its end is never cut away."""
    from jaxobs_tuning.job.fields import JobError

    msg = "x " * 200 + "(declare delimiter = ';')"
    assert str(JobError("scenarios.recording", msg)).endswith("(declare delimiter = ';')")


def _run_fuzz(cases, path, check, capsys, what):
    """Every mutated file through ``check`` (--check): exit 0 or 2, a one-line error, no hang."""
    stats = {0: 0, 2: 0}
    slowest = (0.0, "")
    for label, data in cases:
        path.write_bytes(data)
        rc, err, dt = check(path, capsys)
        assert rc in (0, 2), f"{label}: exit {rc}: {err[:500]}"
        if rc == 2:
            _one_line(err)
        stats[rc] += 1
        slowest = max(slowest, (dt, label))
        assert dt < HANG_S, f"{label}: --check took {dt:.2f} s"
    print(
        f"{what}: {len(cases)} files, {stats[2]} rejected, {stats[0]} accepted, 0 tracebacks, "
        f"slowest {slowest[0]:.2f} s ({slowest[1]})"
    )


def test_fuzzed_job_files_never_traceback_or_hang(tmp_path, capsys):
    cases = list(mutations())
    assert len(cases) >= 300
    _run_fuzz(cases, tmp_path / "job.toml", _check, capsys, "fuzz")


@pytest.mark.parametrize("label, text, field", MUST_FAIL, ids=[m[0] for m in MUST_FAIL])
def test_must_fail_job_files_are_rejected_by_check(tmp_path, capsys, label, text, field):
    path = tmp_path / "job.toml"
    path.write_text(text)
    rc, err, dt = _check(path, capsys)
    assert rc == 2, f"{label}: accepted"
    _one_line(err)
    assert field in err, err
    assert dt < HANG_S


# --------------------------------------------------------------------------
# study files
# --------------------------------------------------------------------------

DEFAULT_STUDY = Path(__file__).parents[1] / "jaxobs" / "data" / "default_study.toml"
S = DEFAULT_STUDY.read_text()
DRIVE_STUDY = (PRESETS / "study_leso_drive.toml").read_text()
# a study with every kind of design: a closed form, a tuning result (beside the study file), explicit gains
MIXED = """[study]
name = "mixed"
t_event = 0.05
horizon = 0.2
steady_from = 0.15
band_hz = 0.1
sample = 16
seed = 3
chunk_size = 8
[designs.cf]
closed_form = "wpf"
[designs.tuned]
result = "result.json"
[designs.mine]
component = "SOGIFLLWIF"
k1 = 1.8
k2 = 0.75
lam = 11559.0
[axes]
freq_step = [-2.0, 2.0]
sag = [0.0, 0.5]
noise = [0.0, 0.01]
"""
STUDIES = [
    _Named("default_study.toml", S),
    _Named("study_leso_drive.toml", DRIVE_STUDY),
    _Named("study_flux_drive.toml", (PRESETS / "study_flux_drive.toml").read_text()),
    _Named("mixed.toml", MIXED),
]
RESULT = {
    "job": {
        "job": {"name": "t", "component": "SOGIFLLWIF"},
        "gains": {"lam": {"init": 11559.0, "lower": 1000.0, "upper": 1e5}},
        "scenarios": {"grid": {"dc": [0.0]}},
        "objective": {"terms": [{"metric": "itae_freq"}]},
    },
    "component": "SOGIFLLWIF",
    "gains": {"tuned": {"lam": 9000.0}},
}

# (label, study text, a field the one-line error must name)
STUDY_MUST_FAIL = [
    ("unknown table", S + "\n[studyy]\na = 1\n", "study file.studyy"),
    ("unknown study key", S.replace("horizon = 0.4", "horizn = 0.4"), "study.horizn"),
    ("unknown design key", MIXED.replace("k2 = 0.75", "k2 = 0.75\nlamm = 3.0"), "designs.mine.lamm"),
    ("gain typo", MIXED.replace("k1 = 1.8", "kl = 1.8"), "designs.mine.kl"),
    ("missing gain", MIXED.replace("k1 = 1.8\n", ""), "designs.mine.k1"),
    ("gain a string", MIXED.replace("lam = 11559.0", 'lam = "big"'), "designs.mine.lam"),
    ("negative gain", MIXED.replace("lam = 11559.0", "lam = -1.0"), "designs.mine"),
    ("missing result", MIXED.replace('"result.json"', '"nope/result.json"'), "designs.tuned.result"),
    ("result not JSON", MIXED.replace('"result.json"', '"mixed.toml"'), "designs.tuned.result"),
    ("result a folder", MIXED.replace('"result.json"', '"."'), "designs.tuned.result"),
    ("two kinds", MIXED.replace('closed_form = "wpf"', 'closed_form = "wpf"\ncomponent = "SOGIFLL"'), "designs.cf"),
    ("no kind", MIXED.replace('closed_form = "wpf"', "x = 1"), "designs.cf"),
    ("closed form unknown", S.replace('"wif"', '"nope"'), "designs.SOGI-FLL-WIF.closed_form"),
    ("component unknown", MIXED.replace('"SOGIFLLWIF"', '"CLESO"'), "designs.mine.component"),
    ("design not a table", S + "\n[designs]\nx = 1\n", "designs.x"),
    ("no designs", "[axes]\ndc = [0.0]\n", "designs"),
    ("no axes", '[designs.a]\nclosed_form = "wif"\n', "axes"),
    ("unknown axis", S.replace("dc = [", "dcc = ["), "axes.dcc"),
    ("sag 2.0", S.replace("dc = [0.0, 0.025, 0.05, 0.075, 0.1]", "sag = [2.0]"), "axes.sag[0]"),
    ("freq_step -60 Hz", S.replace("freq_step = [-3.0,", "freq_step = [-60.0,"), "axes.freq_step[0]"),
    ("freq_step past ts", S.replace("freq_step = [-3.0,", "freq_step = [3000.0,"), "axes.freq_step[0]"),
    # tied to the nominal frequency: a 600 Hz step on a 50 Hz grid is under the sampling limit
    ("freq_step 600 Hz", S.replace("freq_step = [-3.0,", "freq_step = [600.0,"), "axes.freq_step[0]"),
    ("negative noise", MIXED.replace("noise = [0.0, 0.01]", "noise = [-0.1]"), "axes.noise[0]"),
    ("nan in an axis", S.replace("dc = [0.0,", "dc = [nan,"), "axes.dc[0]"),
    ("bool in an axis", S.replace("dc = [0.0,", "dc = [true,"), "axes.dc[0]"),
    ("empty axis", S.replace("dc = [0.0, 0.025, 0.05, 0.075, 0.1]", "dc = []"), "axes.dc"),
    ("horizon 1e300", S.replace("horizon = 0.4", "horizon = 1e300"), "study.horizon"),
    ("horizon 1e9", S.replace("horizon = 0.4", "horizon = 1e9"), "study.horizon"),
    ("horizon before the event", S.replace("horizon = 0.4", "horizon = 0.05"), "study.horizon"),
    ("horizon 10^400", S.replace("horizon = 0.4", "horizon = " + "9" * 400), "study.horizon"),
    ("negative t_event", S.replace("t_event = 0.1", "t_event = -0.1"), "study.t_event"),
    ("steady_from at the end", MIXED.replace("steady_from = 0.15", "steady_from = 0.2"), "study.steady_from"),
    ("empty steady window", MIXED.replace("steady_from = 0.15", "steady_from = 0.1995"), "study.steady_from"),
    ("band 0", MIXED.replace("band_hz = 0.1", "band_hz = 0.0"), "study.band_hz"),
    ("sample 10^12", MIXED.replace("sample = 16", "sample = 1000000000000"), "study.sample"),
    ("sample float", MIXED.replace("sample = 16", "sample = 1.5"), "study.sample"),
    ("chunk 0", S.replace("chunk_size = 1024", "chunk_size = 0"), "study.chunk_size"),
    ("negative seed", MIXED.replace("seed = 3", "seed = -1"), "study.seed"),
    ("name not a string", S.replace('name = "fll-family-closed-forms"', "name = 3"), "study.name"),
    ("kind unknown", S.replace("[study]", '[study]\nkind = "pll"'), "study.kind"),
    (
        "too many scenarios",
        S.replace("harmonics_scale = [", "phase_deg = [" + ", ".join(["1.0"] * 6000) + "]\nharmonics_scale = ["),
        "axes",
    ),
    (
        "memory",
        MIXED.replace("horizon = 0.2", "horizon = 900.0")
        .replace("steady_from = 0.15", "steady_from = 899.0")
        .replace("sample = 16", "sample = 100000")
        .replace("chunk_size = 8", "chunk_size = 100000"),
        "study.chunk_size",
    ),
    ("deep nesting", S + "\nx = " + "[" * 5000 + "]" * 5000 + "\n", "study file"),
    ("file > 1 MB", S + "#" * 1_100_000 + "\n", "study file"),
    ("drive: speed 0", DRIVE_STUDY.replace("speed_rpm = [", "speed_rpm = [0.0, "), "axes.speed_rpm[0]"),
    ("drive: unknown axis", DRIVE_STUDY.replace("[axes]", "[axes]\nspin = [1.0]"), "axes.spin"),
    ("drive: unknown key", DRIVE_STUDY.replace("[axes]", "[drive]\nalpha = 1.0\n[axes]"), "drive.alpha"),
    # the FOC is the drive jobs' (jaxobs_tuning.job.job_drive): a study cannot choose another
    ("drive: bandwidth", DRIVE_STUDY.replace("[axes]", "[drive]\nalpha_c_hz = 300.0\n[axes]"), "drive.alpha_c_hz"),
    ("drive: settle", DRIVE_STUDY.replace("[axes]", "[drive]\nsettle = 100.0\n[axes]"), "drive.settle"),
    ("drive: machine", DRIVE_STUDY.replace('"ipmsm002"', '"mine"'), "study.machine"),
    ("drive: machine's old name", DRIVE_STUDY.replace('"ipmsm002"', '"ipmsm_paper002"'), "study.machine"),
    (
        "drive: t_event at the horizon",
        DRIVE_STUDY.replace("horizon = 0.2", "horizon = 0.2\nt_event = 0.2"),
        "study.t_event",
    ),
    ("drive: t_event < 0", DRIVE_STUDY.replace("horizon = 0.2", "horizon = 0.2\nt_event = -0.1"), "study.t_event"),
    ("drive: unknown table", DRIVE_STUDY + "\n[studyy]\na = 1\n", "allowed: study, designs, axes, drive"),
    ("fll: a [drive] table", S + "\n[drive]\nsettle = 0.1\n", "drive"),
    ("drive: sampling", DRIVE_STUDY.replace('kind = "drive"', 'kind = "drive"\nsampling = "halton"'), "study.sampling"),
    ("drive: gain typo", DRIVE_STUDY.replace('component = "FALESO"', 'component = "FALESO"\nk3 = 1.0'), "k3"),
    ("drive: closed_form", DRIVE_STUDY + '\n[designs.cf]\nclosed_form = "wif"\n', "designs.cf.closed_form"),
    ("drive: an FLL", DRIVE_STUDY + '\n[designs.f]\ncomponent = "SOGIFLL"\n', "designs.f.component"),
]


def _study_check(path: Path, capsys) -> tuple[int, str, float]:
    t0 = time.process_time()
    rc = main(["study", str(path), "--check"])
    dt = time.process_time() - t0
    return rc, capsys.readouterr().err, dt


def test_the_base_study_files_pass_check(tmp_path, capsys):
    """The shipped studies, and one with every kind of design (a result read beside the study file)."""
    (tmp_path / "result.json").write_text(json.dumps(RESULT))
    for st in STUDIES:
        (tmp_path / st.name).write_text(st.text)
        rc, err, _ = _study_check(tmp_path / st.name, capsys)
        assert rc == 0, (st.name, err)
    assert 'component = "FALESO"' in DRIVE_STUDY  # STUDY_MUST_FAIL edits it


def test_fuzzed_study_files_never_traceback_or_hang(tmp_path, capsys):
    cases = list(mutations(seed=1, per_preset=30, files=STUDIES))
    assert len(cases) >= 100
    (tmp_path / "result.json").write_text(json.dumps(RESULT))
    _run_fuzz(cases, tmp_path / "study.toml", _study_check, capsys, "study fuzz")


@pytest.mark.parametrize("label, text, field", STUDY_MUST_FAIL, ids=[m[0] for m in STUDY_MUST_FAIL])
def test_must_fail_study_files_are_rejected_by_check(tmp_path, capsys, label, text, field):
    (tmp_path / "result.json").write_text(json.dumps(RESULT))
    path = tmp_path / "mixed.toml"
    path.write_text(text)
    rc, err, dt = _study_check(path, capsys)
    assert rc == 2, f"{label}: accepted"
    _one_line(err)
    assert field in err, err
    assert dt < HANG_S
