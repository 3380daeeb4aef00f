"""Scenario families own what a study needs: each built by its own class, recordings read by the recordings
reader, the presets' one way of taking samplers, and no fork on a family's name anywhere a family is used."""

import ast
from pathlib import Path

import equinox as eqx
import numpy as np
import pytest

import jaxobs
from jaxobs import drive as D
from jaxobs.scenarios import LHS, Given, Grid, Random, Recordings, Sobol, sampler_of
from jaxobs.scenarios.families import (
    FAMILIES,
    AbstractFamily,
    DriveScenarios,
    DriveSetting,
    EMFSignals,
    GridSignals,
    RecordedSignals,
)
from jaxobs.signals import SampledSignal, read_recorded

ROOT = Path(__file__).parents[1]


def test_each_family_is_built_by_its_own_from_toml():
    """Each family reads its own keys of a TOML table (the others are its reader's) and what the run gives it."""
    assert not hasattr(AbstractFamily, "of")  # no shared constructor taking every family's options
    table = {"t_event": 0.2, "seed": 7, "horizon": 1.0, "grid": {}}  # horizon, grid: the job reader's keys
    assert GridSignals.from_toml(table, freq_n=60.0) == GridSignals(0.2, 60.0, 7)
    assert GridSignals.from_toml({}, freq_n=50.0) == GridSignals(0.1, 50.0, 0)  # the jobs' defaults
    assert EMFSignals.from_toml(table) == EMFSignals()
    par = D.ipmsm_paper002()
    drive = D.Drive(D.FOC.imc(par, 2000.0, 100.0), sensorless=True)
    fam = DriveScenarios.from_toml(table, drive=DriveSetting(par, drive))
    assert (fam.t_event, fam.seed, fam.sensors) == (0.2, 7, None) and fam.machine is par and fam.drive is drive
    assert DriveScenarios.from_toml({}, drive=DriveSetting(par, drive)).t_event == 0.0  # no event by default
    for v in (-0.1, float("nan"), "0.1", True):
        with pytest.raises(ValueError, match=r"^scenarios.t_event: must be a finite number of seconds >= 0"):
            GridSignals.from_toml({"t_event": v})
    for v in (-1, 2**32, 1.5, False):
        with pytest.raises(ValueError, match=r"^study.seed: must be an integer in \[0, 2\^32\)"):
            DriveScenarios.from_toml({"seed": v}, "study", drive=DriveSetting(par, drive))
    with pytest.raises(ValueError, match="^study: drive scenarios need the drive they close"):
        DriveScenarios.from_toml({}, "study")
    with pytest.raises(ValueError, match="no drive applies"):
        GridSignals.from_toml({}, drive=DriveSetting(par, drive))
    with pytest.raises(ValueError, match="nominal frequency must be > 0 Hz"):
        GridSignals.from_toml({}, freq_n=0.0)
    with pytest.raises(ValueError, match=r"recordings stand for a family's signals"):
        RecordedSignals.from_toml({})
    assert set(FAMILIES) == {"grid", "emf", "drive"}


def test_recordings_are_made_by_the_family_they_stand_for_and_hold_no_class():
    """RecordedSignals holds what the recordings are (plain data), not the family's class; reading is the
    recordings reader's (jaxobs.signals.read_recorded)."""
    grid, emf, drive = (f.recorded() for f in (GridSignals, EMFSignals, DriveScenarios))
    assert (grid.columns, grid.truth, grid.truth_counts, grid.binds) == (
        ("v",),
        ("theta", "omega", "amplitude"),
        (3,),
        False,
    )
    assert emf.columns == drive.columns == ("u_a", "u_b", "i_a", "i_b") and emf.binds and drive.binds
    assert (grid.source, emf.source, drive.source) == ("grid", "emf", "drive")
    with pytest.raises(ValueError, match="RecordedSignals: no recording stands for its signals"):
        RecordedSignals.recorded()
    for rec in (grid, emf, drive):
        assert not any(isinstance(getattr(rec, f), type) for f in rec.__dataclass_fields__)
        assert not hasattr(rec, "read") and not hasattr(rec, "kind")


def test_the_recordings_reader_reads_a_grid_voltage_as_from_csv(tmp_path):
    t = np.arange(200) / 10_000.0
    theta = 2 * np.pi * 50.0 * t
    rows = "\n".join(f"{a:.9g},{np.cos(b):.9g},{b:.9g},{2 * np.pi * 50:.9g},1" for a, b in zip(t, theta))
    path = tmp_path / "g.csv"
    path.write_text("t,v,theta,omega,amplitude\n" + rows + "\n")
    got = read_recorded(str(path), ("v",), ("theta", "omega", "amplitude"), drive=False, time_column="t")
    want = SampledSignal.from_csv(str(path), columns="v", truth=("theta", "omega", "amplitude"), time_column="t")
    assert got.n == want.n == 200 and bool(eqx.tree_equal(got, want))


def test_both_presets_take_samplers_one_way():
    axes = {"dc": [0.0, 0.1], "sag": [0.2, 0.5]}
    assert isinstance(sampler_of(axes), Grid)
    assert isinstance(sampler_of(axes, sample=3, seed=2), Random) and sampler_of(axes, sample=3, seed=2).seed == 2
    assert isinstance(sampler_of(axes, sampling="sobol", sample=4), Sobol)
    assert isinstance(sampler_of(axes, sampling="lhs", sample=4), LHS)
    given = Given({"a": np.zeros(3)})
    assert sampler_of(given) is given
    with pytest.raises(ValueError, match="sampling must be 'grid', 'random', 'sobol' or 'lhs', got 'halton'"):
        sampler_of(axes, sampling="halton", sample=4)
    with pytest.raises(ValueError, match="sample applies to sampling 'random', 'sobol' or 'lhs'"):
        sampler_of(axes, sampling="grid", sample=4)
    with pytest.raises(ValueError, match="sample must be an integer >= 1 with sampling='sobol'"):
        sampler_of(axes, sampling="sobol")
    with pytest.raises(ValueError, match="a sampler is taken as it is"):
        sampler_of(given, sample=2)
    with pytest.raises(ValueError, match="axes must be a dict of axis values or a sampler"):
        sampler_of([1, 2])
    # a dim of a sampler's own (a recording's) has its attributes from the sampler, not from a family's axis
    assert Recordings({"a": np.zeros(2)}, ["x.csv", "y.csv"]).dim_attrs["long_name"].startswith("recording file")


def test_one_preset_the_family_declares_the_study():
    """run_study is the one preset: its defaults are the family's (horizon, chunk), the family's study_plan says
    what is scored, and a family without a study is refused in one line naming it."""
    import inspect

    from jaxobs.scenarios import Grid
    from jaxobs.studies.study import run_study

    params = inspect.signature(run_study).parameters
    assert params["mesh"].default is None and params["sampling"].default is None and params["sample"].default == 0
    assert params["family"].default is None and params["horizon"].default is None
    assert (GridSignals.study_horizon, GridSignals.study_chunk) == (0.4, 2048)
    assert (DriveScenarios.study_horizon, DriveScenarios.study_chunk) == (0.3, 256)
    fll = jaxobs.SOGIFLL(k=0.3, lam=500.0)
    plan = GridSignals(0.1, 50.0).study_plan({"a": fll}, Grid({"dc": [0.0]}), horizon=0.4)
    assert plan.metrics == GridSignals.metrics and plan.mask == "diverged" and plan.quantiles == ()
    assert [f.name for f in plan.flags] == list(GridSignals.flags) and plan.ctx.steady_from == pytest.approx(0.325)
    with pytest.raises(ValueError, match="EMFSignals: no study runs on this family"):
        run_study({"a": fll}, {"speed_hz": [50.0]}, family=EMFSignals())


# the modules that take a family: none forks on a family's (or a study kind's) name
USERS = (
    "jaxobs/scenarios/families/_base.py",
    "jaxobs/scenarios/families/signals.py",
    "jaxobs/scenarios/families/drive.py",
    "jaxobs/studies/study.py",
    "jaxobs/studies/drive.py",
    "jaxobs/analysis/envelope.py",
    "tuning/objective.py",
    "tuning/cli.py",
    "tuning/study_file.py",
    "tuning/job/schema.py",
    "tuning/job/scenarios.py",
    "tuning/job/recordings.py",
)
KIND_NAMES = {"fll", "drive", "grid", "emf", "recording"}


def _kind_comparisons(tree) -> list[int]:
    """Lines comparing a value with a family's name: ``x == "drive"``, ``x is not "fll"``, ``x in ("fll", ...)``
    (a key looked up in a table, ``"drive" in raw``, is no comparison of a kind)."""
    lines = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Compare):
            continue
        sides = [node.left, *node.comparators]
        for op, right in zip(node.ops, node.comparators):
            if isinstance(op, (ast.Eq, ast.NotEq, ast.Is, ast.IsNot)):
                if any(isinstance(s, ast.Constant) and s.value in KIND_NAMES for s in sides):
                    lines.append(node.lineno)
            elif isinstance(op, (ast.In, ast.NotIn)) and isinstance(right, (ast.Tuple, ast.List, ast.Set)):
                if any(isinstance(e, ast.Constant) and e.value in KIND_NAMES for e in right.elts):
                    lines.append(node.lineno)
    return lines


@pytest.mark.parametrize("path", USERS)
def test_no_module_that_takes_a_family_forks_on_its_name(path):
    src = (ROOT / path).read_text()
    assert _kind_comparisons(ast.parse(src)) == [], f"{path}: a comparison with a family's name"


def test_the_kind_check_sees_a_fork():
    forks = 'if kind == "drive": pass\nif s in ("fll", "x"): pass\nif "drive" in raw: pass\n'
    assert _kind_comparisons(ast.parse(forks)) == [1, 2]
