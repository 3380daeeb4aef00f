"""A hard link and a symlink planted at every file name each writing command writes in --out (tune, study,
envelope, export, and error.log): each file is written beside its name and renamed over it (jaxobs.io.files), so
the link is replaced and nothing outside --out changes; a symlink at a result the run would overwrite is
refused before any work (jaxobs_tuning.outdir).  The runs are the cheapest of each command: a one-step tune,
a 4-scenario study, a 1-point envelope, a 10 000-step export."""

from __future__ import annotations

import os

import pytest

from jaxobs_tuning.cli import main
from jaxobs_tuning.outdir import LOCK
from tests.test_envelope import PRESET as ENVELOPE_JOB
from tests.test_outputs import GOOD

STUDY = """
[study]
name = "links"
t_event = 0.02
horizon = 0.06
[designs.W]
closed_form = "wif"
[axes]
freq_step = [-1.0, 1.0]
dc = [0.0, 0.05]
"""

TUNE_FILES = ("result.json", "checkpoint.npz", "history.json", "timing.json", "scores.nc")
TUNE_FILES += ("convergence.png", "responses.png")
METRICS = ("settling_freq", "ripple_freq", "rms_phase_steady")
STUDY_FIGURES = tuple(f"{k}_{m}.png" for k in ("heatmap", "distribution") for m in METRICS)
STUDY_FILES = ("study.nc", "worst_cases.json", *STUDY_FIGURES)
EXPORT_FILES = ("observer.h", "observer.c", "test_main.c", "golden.csv", "coefficients.json")
ENVELOPE_FILES = ("envelope.nc", "envelope.png")


def _plant(out, outside, names, symlinks=()):
    """At each name in ``out`` a hard link to a file of ``outside`` (a symlink for the names in ``symlinks``)."""
    out.mkdir(exist_ok=True)
    outside.mkdir(exist_ok=True)
    for name in names:
        target = outside / f"{out.name}-{name}"
        target.write_bytes(b"outside")
        (out / name).unlink(missing_ok=True)
        if name in symlinks:
            (out / name).symlink_to(target)
        else:
            os.link(target, out / name)


def _untouched(outside, replaced=True):
    """Nothing outside --out changed: every target as planted; ``replaced``: no name in --out links to it."""
    for p in outside.iterdir():
        assert p.read_bytes() == b"outside" and (p.stat().st_nlink == 1 or not replaced), p


def _written(out, names):
    """Each name is now a regular file of its own (the link replaced), and no temp entry is left."""
    for name in names:
        p = out / name
        assert p.is_file() and not p.is_symlink() and p.stat().st_nlink == 1 and p.read_bytes() != b"outside", p
    assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp")]


def _run(argv, capsys, code=0):
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == code, err[-2000:]
    return err


@pytest.mark.parametrize(
    "cmd, names, products",
    [
        ("tune", TUNE_FILES, ("result.json", "checkpoint.npz")),
        ("study", STUDY_FILES, ("study.nc",)),
    ],
)
def test_links_at_every_name_of_tune_and_study(tmp_path, capsys, cmd, names, products):
    src = tmp_path / f"{cmd}.toml"
    src.write_text(GOOD if cmd == "tune" else STUDY)
    out, outside = tmp_path / "o", tmp_path / "outside"
    argv = [cmd, str(src), "--out", str(out), "--force", "--quiet"]
    _plant(out, outside, names)  # hard links everywhere
    _run(argv, capsys)
    _untouched(outside)
    _written(out, names)
    assert sorted(p.name for p in out.iterdir()) == sorted(names)  # every file the command wrote had a link
    others = [n for n in names if n not in products]
    _plant(out, outside, names, symlinks=names)  # a symlink at a result: refused before any work
    assert "symlink" in _run(argv, capsys, code=2)
    _untouched(outside, replaced=False)
    _plant(out, outside, names, symlinks=others)  # symlinks at every other name: replaced
    _run(argv, capsys)
    _untouched(outside)
    _written(out, names)


def test_links_at_every_name_of_export(tmp_path, capsys):
    out, outside = tmp_path / "o", tmp_path / "outside"
    argv = ["export", "--design", "wif", "--out", str(out), "--steps", "10000", "--force", "--quiet"]
    _plant(out, outside, EXPORT_FILES)
    _run(argv, capsys)
    _untouched(outside)
    _written(out, EXPORT_FILES)
    assert sorted(p.name for p in out.iterdir()) == sorted(EXPORT_FILES)
    for name in EXPORT_FILES:  # each of them a result: a symlink there is refused
        _plant(out, outside, EXPORT_FILES, symlinks=(name,))
        assert "symlink" in _run(argv, capsys, code=2)
        _untouched(outside, replaced=False)


def test_a_symlink_at_an_envelope_file_is_refused_before_any_work(tmp_path, capsys):
    out, outside = tmp_path / "o", tmp_path / "outside"
    argv = ["envelope", str(ENVELOPE_JOB), "--out", str(out), "--force", "--quiet"]
    for name in ENVELOPE_FILES:
        _plant(out, outside, ENVELOPE_FILES, symlinks=(name,))
        assert "symlink" in _run(argv, capsys, code=2)
        _untouched(outside, replaced=False)


@pytest.mark.slow  # a one-point map still compiles the Floquet verdict and the long run: about 2 min when loaded
def test_links_at_every_name_of_envelope(tmp_path, capsys, monkeypatch):
    """The command's files from a one-point map (the envelope itself is tested in tests/test_envelope.py)."""
    import jaxobs.analysis.envelope as E

    real = E.envelope

    def one_point(designs, **kw):
        kw.update(speeds_rpm=[1000.0], loads_nm=[0.0], horizon=0.5, stability=dict(settle=0.05, window=0.15))
        return real(designs, **kw)

    monkeypatch.setattr(E, "envelope", one_point)
    out, outside = tmp_path / "o", tmp_path / "outside"
    _plant(out, outside, ENVELOPE_FILES)
    _run(["envelope", str(ENVELOPE_JOB), "--out", str(out), "--force", "--quiet"], capsys)
    _untouched(outside)
    _written(out, ENVELOPE_FILES)
    assert sorted(p.name for p in out.iterdir()) == sorted(ENVELOPE_FILES)


@pytest.mark.parametrize("kind", ["hard link", "symlink"])
def test_a_link_at_error_log_is_replaced_not_written_through(tmp_path, capsys, monkeypatch, kind):
    src = tmp_path / "job.toml"
    src.write_text(GOOD)
    out, outside = tmp_path / "o", tmp_path / "outside"
    _plant(out, outside, ["error.log"], symlinks=("error.log",) if kind == "symlink" else ())

    def boom(*a, **k):
        raise RuntimeError("boom")

    monkeypatch.setattr("jaxobs_tuning.cli.run_job", boom)
    err = _run(["tune", str(src), "--out", str(out)], capsys, code=1)
    assert "error.log" in err and str(outside) not in err
    _untouched(outside)
    assert "RuntimeError: boom" in (out / "error.log").read_text()
    assert not (out / "error.log").is_symlink() and (out / "error.log").stat().st_nlink == 1
    assert sorted(p.name for p in out.iterdir()) == ["error.log"] and not (out / LOCK).exists()
