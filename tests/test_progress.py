"""Progress: silent library by default, tqdm bars on stderr when asked (compilation announced), --quiet
on every command, stdout untouched."""

import sys

import jax.numpy as jnp
import pytest

import jaxobs
from jaxobs.runtime.progress import Progress
from jaxobs.studies.study import run_study
from jaxobs_tuning import AbstractObjective, strategies
from jaxobs_tuning.cli import build_parser
from jaxobs_tuning.solvers import tune


def test_progress_is_silent_by_default_a_bar_on_stderr_or_a_callback(capsys, monkeypatch):
    calls = []
    with Progress(lambda d, t: calls.append((d, t)), 3, "x") as p:
        p.stage("compiling")
        p.update()
        p.update(2)
    assert calls == [(1, 3), (3, 3)]
    with Progress(None, 3, "x") as p:
        p.stage("compiling")
        p.update(3)
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""
    with Progress(True, 2, "demo") as p:
        p.stage("compiling SOGIFLL")
        p.update(2, objective="1.5")
    out = capsys.readouterr()
    assert out.out == "" and "demo: compiling SOGIFLL" in out.err and "2/2" in out.err and "objective=1.5" in out.err
    _terminal(monkeypatch, False)
    with Progress("auto", 1, "x") as p:  # "auto": a bar only on a terminal
        p.update()
    assert capsys.readouterr().err == ""
    _terminal(monkeypatch)
    with Progress("auto", 1, "x") as p:
        p.update()
    assert "1/1" in capsys.readouterr().err
    with pytest.raises(ValueError, match="progress must be True, False, None, 'auto' or a callable"):
        Progress("yes", 1, "x")


class _Quadratic(AbstractObjective):
    """A stand-in objective with no compilation: (θ − 1)², never diverged."""

    class param:
        @staticmethod
        def values(theta):
            return {"g": float(theta[0])}

        @staticmethod
        def to_theta(values):
            return jnp.asarray([values["g"]])

    def value_grad_diverged_overflowed(self, theta, scenarios):
        return jnp.sum((theta - 1.0) ** 2), 2 * (theta - 1.0), 0, 0

    def value(self, theta, scenarios):
        return jnp.sum((theta - 1.0) ** 2)


def _terminal(monkeypatch, yes=True):
    """stderr (pytest's capture) taken for a terminal: the command line's bars are on ("auto")."""
    monkeypatch.setattr(sys.stderr, "isatty", lambda: yes, raising=False)


@pytest.mark.parametrize("kind", ["adam", "bfgs"])
def test_every_solver_shows_progress_on_stderr_unless_quiet(capsys, monkeypatch, kind):
    cfg = strategies.solver(kind, learning_rate=0.1, steps=5, patience=100)
    _terminal(monkeypatch, False)  # a pipe or a log: no bar (an error stays one line)
    tune(_Quadratic(), cfg, jnp.zeros(1), quiet=False)
    assert capsys.readouterr().err == ""
    _terminal(monkeypatch)
    tune(_Quadratic(), cfg, jnp.zeros(1), quiet=False)
    out = capsys.readouterr()
    assert out.out == ""
    assert f"tune ({kind})" in out.err and "compiling the objective" in out.err and "/5" in out.err, out.err
    assert "objective=" in out.err and "best=" in out.err
    tune(_Quadratic(), cfg, jnp.zeros(1), quiet=True)
    assert capsys.readouterr().err == ""


def test_study_announces_each_compilation_and_counts_scenarios(capsys):
    calls = []
    designs = {"sogi": jaxobs.linear.sogi_fll_closed_form()}
    run_study(designs, {"freq_step": [1.0, 2.0]}, horizon=0.15, progress=lambda d, t: calls.append((d, t)))
    assert calls == [(2, 2)]
    assert capsys.readouterr().err == ""  # a callback, no bar
    run_study(designs, {"freq_step": [1.0, 2.0]}, horizon=0.15, progress=True)
    err = capsys.readouterr().err
    assert "study: sogi (compiling" in err and "2/2" in err


@pytest.mark.parametrize(
    "argv",
    [
        ["tune", "--quiet"],
        ["demo", "--quiet"],
        ["closed-form", "wif", "--quiet"],
        ["bode", "--quiet"],
        ["reproduce", "flux", "--quiet"],
        ["reproduce", "leso", "--quiet"],
        ["study", "--quiet"],
        ["export", "--design", "wif", "--quiet"],
    ],
)
def test_every_command_takes_quiet(argv):
    args = build_parser().parse_args(argv)
    assert args.quiet is True
    assert build_parser().parse_args([a for a in argv if a != "--quiet"]).quiet is False


def test_export_reports_its_three_stages(tmp_path):
    from jaxobs_tuning.export import export_observer, observer_from_design

    calls = []
    export_observer(observer_from_design("wif"), tmp_path, n_steps=10_000, progress=lambda d, t: calls.append((d, t)))
    assert calls == [(1, 3), (2, 3), (3, 3)]
    assert (tmp_path / "golden.csv").exists()


def test_reproduce_leso_progress_has_a_total(monkeypatch):
    """`reproduce leso`'s bar counts its experiments out of a total.  No simulation:
    the first run is stopped at once, after the bar was made; each run() is one step of N_EXPERIMENTS."""
    from jaxobs.reproduce import leso

    made = []

    class Recorder(leso.Progress):
        def __init__(self, progress, total, desc, unit="it"):
            made.append(total)
            super().__init__(progress, total, desc, unit)

    class Stop(Exception):
        pass

    def stop(*_a, **_k):
        raise Stop

    monkeypatch.setattr(leso, "Progress", Recorder)
    monkeypatch.setattr(leso, "run_kept", stop)
    with pytest.raises(Stop):
        leso.run_leso_experiments(progress=False)
    assert made == [leso.N_EXPERIMENTS] and leso.N_EXPERIMENTS == 19


def test_warnings_and_log_records_during_a_bar_get_lines_of_their_own(capsys):
    """A warning or a log record printed while a bar is drawn does not go into the bar's line: through
    tqdm.write it gets a line of its own and the bar is redrawn after it; warnings.showwarning and logging.lastResort
    are restored once it closes."""
    import logging
    import re
    import warnings

    shown, last = warnings.showwarning, logging.lastResort
    log = logging.getLogger("jaxobs.tests.progress")  # a logger with no handler: logging's last resort, as JAX's
    log.propagate = False
    try:
        with Progress(True, 2, "bar") as p:
            p.update()
            with warnings.catch_warnings():
                warnings.simplefilter("always")
                warnings.warn("careful", UserWarning, stacklevel=1)
            log.warning("from a logger")
            p.update()
        assert warnings.showwarning is shown and logging.lastResort is last
    finally:
        log.propagate = True
    err = capsys.readouterr().err
    lines = re.split(r"[\r\n]", err)
    for what in ("from a logger", "UserWarning: careful"):
        line = next(x for x in lines if what in x)
        assert "1/2" not in line and "bar" not in line.replace("test_progress", ""), err
    assert "2/2" in err[err.index("from a logger") :]  # the bar goes on below the messages
