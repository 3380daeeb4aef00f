"""The command line: the one parser, the demo, error handling; no side effects of ``import jaxobs``."""

import json
import math
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import jaxobs
from jaxobs import papers
from jaxobs_tuning.cli import BODE_FILES, DEMO_FILES, REPRODUCE_FILES, build_parser, load_study, main
from jaxobs_tuning.cli_common import native_stderr_to_log
from jaxobs_tuning.results import load_result, tuned_component

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = ("tune", "demo", "closed-form", "bode", "reproduce", "study", "export", "envelope", "drive", "log")


def _python(code_or_args, env_drop=(), env_add=None):
    """Run a fresh interpreter (``-c code`` or ``-m ...`` args) with this checkout first on the path."""
    env = {k: v for k, v in os.environ.items() if k not in env_drop}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    env.update(env_add or {})
    args = ["-c", code_or_args] if isinstance(code_or_args, str) else list(code_or_args)
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)


def test_python_m_jaxobs_lists_every_command_and_version():
    p = _python(["-m", "jaxobs", "--help"])
    assert p.returncode == 0, p.stderr
    listed = re.findall(r"^    ([a-z][a-z-]*)\b", p.stdout, flags=re.M)  # the COMMAND list, one a line
    assert sorted(listed) == sorted(COMMANDS)
    assert "bench" not in listed  # benchmarks run with `make bench`
    p = _python(["-m", "jaxobs", "--version"])
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == f"jaxobs {jaxobs.__version__}"
    assert re.fullmatch(r"\d+\.\d+\.\d+\S*", jaxobs.__version__)


def test_console_script_is_the_one_parser():
    """pyproject's ``jaxobs`` script is ``jaxobs_tuning.cli_entry:main`` (help and version at once), which hands every
    command to ``jaxobs_tuning.cli``'s parser, the one with every command."""
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert meta["project"]["scripts"] == {"jaxobs": "jaxobs_tuning.cli_entry:main"}
    assert jaxobs.__version__ == meta["project"]["version"]
    helptext = build_parser().format_help()
    assert all(c in helptext for c in COMMANDS) and "--version" in helptext
    assert not (ROOT / "jaxobs" / "cli.py").exists()
    # every package folder is installed, tuning/ under its own name (pyproject's explicit list)
    setup = meta["tool"]["setuptools"]
    assert setup["package-dir"] == {"jaxobs": "jaxobs", "jaxobs_tuning": "tuning"}
    folders = {".".join(p.relative_to(ROOT).parent.parts) for p in (ROOT / "jaxobs").rglob("__init__.py")} | {
        ".".join(("jaxobs_tuning",) + p.relative_to(ROOT / "tuning").parent.parts)
        for p in (ROOT / "tuning").rglob("__init__.py")
    }

    # and the only other entries are data-only folders (listed so that setuptools does not warn): real folders
    # that hold package data and no Python
    def folder(name):
        top, *rest = name.split(".")
        return ROOT.joinpath({"jaxobs": "jaxobs", "jaxobs_tuning": "tuning"}[top], *rest)

    data = set(setup["packages"]) - folders
    assert all(folder(d).is_dir() and not list(folder(d).glob("*.py")) for d in data), data
    assert sorted(set(setup["packages"]) - data) == sorted(folders)
    assert len(setup["packages"]) == len(set(setup["packages"]))


def test_import_jaxobs_leaves_the_environment_alone():
    """``import jaxobs`` changes no environment variable (jax's own import sets a few, so jax comes first)."""
    code = (
        "import os, jax; before = dict(os.environ); import jaxobs, tuning; "
        "assert 'XLA_FLAGS' not in os.environ, os.environ['XLA_FLAGS']; "
        "assert dict(os.environ) == before, {k: v for k, v in os.environ.items() if before.get(k) != v}"
    )
    p = _python(code, env_drop=("XLA_FLAGS", "JAXOBS_HOST_DEVICES"))
    assert p.returncode == 0, p.stderr


def test_importing_the_command_line_starts_no_jax_backend():
    """Importing the command line (and so the library, the registry, the job and export tables) runs no JAX
    computation: the first would start JAX with its default device count before ``main`` sets it."""
    code = (
        "import jax._src.xla_bridge as xb\n"
        "def started(*a, **k):\n"
        "    raise SystemExit('a JAX computation at import')\n"
        "xb.backends = started\n"
        "import jaxobs_tuning.cli\n"
    )
    p = _python(code)
    assert p.returncode == 0, p.stderr[-2000:]


def test_library_never_imports_tuning():
    """Every module of jaxobs/ but the ``python -m jaxobs`` entry point imports without tuning/."""
    code = (
        "import importlib, pkgutil, sys, jaxobs\n"
        "for m in pkgutil.walk_packages(jaxobs.__path__, 'jaxobs.'):\n"
        "    if m.name != 'jaxobs.__main__':\n"
        "        importlib.import_module(m.name)\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('tuning', 'jaxobs_tuning')))\n"
    )
    p = _python(code)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "[]"


def test_use_host_devices_before_and_after_jax_starts():
    code = (
        "import warnings, jax, jaxobs\n"
        "assert jaxobs.use_host_devices(2) == 2\n"
        "assert len(jax.devices()) == 2, jax.devices()\n"
        "with warnings.catch_warnings(record=True) as w:\n"
        "    warnings.simplefilter('always')\n"
        "    assert jaxobs.use_host_devices(3) == 2\n"  # too late: warns, keeps 2
        "    assert jaxobs.use_host_devices(3) == 2\n"  # warns once
        "    assert jaxobs.use_host_devices() == 2\n"
        "    assert jaxobs.use_host_devices(2) == 2\n"
        "assert len(w) == 1 and 'already started' in str(w[0].message), [str(x.message) for x in w]\n"
        "print(len(jax.devices()))\n"
    )
    p = _python(code, env_drop=("XLA_FLAGS", "JAXOBS_HOST_DEVICES"))
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "2"


def test_use_host_devices_default_and_env_override():
    code = (
        "import os, jax, jaxobs; n = jaxobs.use_host_devices(); "
        "print(n, len(jax.devices()), len(os.sched_getaffinity(0)))"
    )
    p = _python(code, env_drop=("XLA_FLAGS", "JAXOBS_HOST_DEVICES"))
    assert p.returncode == 0, p.stderr
    n, devs, cores = map(int, p.stdout.split())
    assert n == devs == cores
    p = _python(code, env_drop=("XLA_FLAGS",), env_add={"JAXOBS_HOST_DEVICES": "1"})
    assert p.returncode == 0, p.stderr
    assert p.stdout.split()[:2] == ["1", "1"]
    p = _python(code, env_drop=("XLA_FLAGS",), env_add={"JAXOBS_HOST_DEVICES": "3"})
    assert p.returncode == 0, p.stderr
    assert p.stdout.split()[:2] == ["3", "3"]
    with pytest.raises(ValueError, match="n must be an integer >= 1"):
        jaxobs.use_host_devices(0)


def test_public_apis_only():
    """No private attributes of other libraries: argparse's _actions, jax._src, diffrax._..."""
    for pkg in ("jaxobs", "tuning", "benchmarks"):
        for f in (ROOT / pkg).rglob("*.py"):
            text = f.read_text()
            for private in ("_actions", "jax._src", "diffrax._"):
                assert private not in text, (f, private)
    assert not (ROOT / "jaxobs" / "bench").exists()  # benchmarks live in benchmarks/, outside the library


def test_demo_json_rows_and_figure(tmp_path, capsys):
    rc = main(["demo", "--out", str(tmp_path), "--json"])
    assert rc == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["test"] for r in rows} == {"A", "B", "C", "D", "E"}
    assert {r["fll"] for r in rows} == {"SOGI-FLL", "SOGI-FLL-WPF", "SOGI-FLL-WIF"}
    a = [r for r in rows if r["test"] == "A"]
    assert all(math.isfinite(r["settle_cycles"]) for r in a)
    assert (tmp_path / "fll_tests_A_E.png").stat().st_size > 10_000
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(DEMO_FILES)


def test_bad_arguments_exit_with_one_line(capsys):
    # in this process (main, as `python -m jaxobs` runs it: tests above): 4 fresh interpreters cost 6 s cold
    for argv in (
        ["demo", "--t-event", "-1"],
        ["nonsense"],
        ["demo", "--t-event", "abc"],
        ["export", "--design", "wif", "--out", "/dev/null/x"],  # an output folder that cannot be made
    ):
        capsys.readouterr()
        try:
            rc = main(argv)
        except SystemExit as e:  # argparse's own errors
            rc = e.code
        err = capsys.readouterr().err
        assert rc == 2, (argv, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("jaxobs: error:"), err
        assert "Traceback" not in err


def test_closed_form_json_reports_formula_and_source(capsys):
    assert main(["closed-form", "wif", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    gains = {g["name"]: g for g in res["gains"]}
    assert round(gains["k1"]["value"], 3) == 1.815 and round(gains["k2"]["value"], 3) == 0.752
    assert round(gains["lam"]["value"]) == 11559
    assert gains["lam"]["source"] == "001 eq (34)" and "2ωc²/b" in gains["lam"]["formula"]
    assert main(["closed-form", "cleso", "--rs", "0.5", "--lq", "0.012", "--omega0", "1000"]) == 0
    out = capsys.readouterr().out
    assert "l2" in out and "1e+06" in out


def test_help_and_version_answer_without_importing_jax(capsys):
    """The console script (jaxobs_tuning.cli_entry) answers `jaxobs`, `--help` and `--version` without JAX: its
    list of commands is the full parser's, word for word, and a fresh interpreter has not imported jax after it."""
    from jaxobs_tuning.cli import build_parser
    from jaxobs_tuning.cli_entry import main as entry
    from jaxobs_tuning.cli_entry import top_parser

    assert top_parser().format_help() == build_parser().format_help()
    assert entry(["--help"]) == 0 and capsys.readouterr().out == build_parser().format_help()
    assert entry([]) == 2 and capsys.readouterr().err == build_parser().format_help()
    code = (
        "import sys; from jaxobs_tuning.cli_entry import main; rc = main(['--version']); "
        "assert rc == 0 and 'jax' not in sys.modules and 'numpy' not in sys.modules, sorted(sys.modules)"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0 and run.stdout.startswith("jaxobs "), run.stderr[-2000:]


# modules a plain `jaxobs drive check` must not import: the tuning commands' jobs and solvers, the integrators'
# and optimisers' libraries, the figures, the closed-loop analyses (each costs start-up time the check never uses)
DRIVE_CHECK_UNUSED = (
    "jaxobs_tuning.cli",
    "jaxobs_tuning.job",
    "jaxobs_tuning.solvers",
    "jaxobs_tuning.distributed",
    "optax",
    "optimistix",
    "lineax",
    "diffrax",
    "matplotlib",
    "xarray",
    "jaxobs.analysis.drive_points",
    "scipy.signal",  # 1.6 s of import: a third of the check's time when the current-reference margin imported it
    "scipy.stats",
)


@pytest.mark.parametrize("name", ["traction_ipmsm.toml", "teknic_m2310p.toml"])
def test_a_plain_drive_check_compiles_nothing_and_imports_no_command_it_does_not_run(name):
    """`jaxobs drive check FILE` (no --simulate, no saturation map) answers from the file's arithmetic: JAX compiles
    no program (JAX_LOG_COMPILES logs none; each eager operation on a JAX array would compile one kernel), and the
    console script runs it by the drive command's own parser, without the modules of DRIVE_CHECK_UNUSED."""
    code = (
        "import sys; from jaxobs_tuning.cli_entry import main; "
        f"rc = main(['drive', 'check', '--no-cache', {str(ROOT / 'docs' / 'examples' / name)!r}]); "
        f"bad = [m for m in {DRIVE_CHECK_UNUSED!r} if m in sys.modules]; "
        "assert rc == 0 and not bad, bad"
    )
    env = {**os.environ, "JAX_LOG_COMPILES": "1", "JAX_PLATFORMS": "cpu"}
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "Compiling" not in run.stderr, run.stderr[-2000:]
    assert "operating points not simulated" in run.stdout


def test_the_drive_commands_own_parser_is_the_full_parsers(capsys):
    """`jaxobs drive check --help` through the console script's drive parser is the full parser's, word for word."""
    from jaxobs_tuning.cli_entry import main as entry

    with pytest.raises(SystemExit):
        build_parser().parse_args(["drive", "check", "--help"])
    full = capsys.readouterr().out
    with pytest.raises(SystemExit) as e:
        entry(["drive", "check", "--help"])
    assert e.value.code == 0 and capsys.readouterr().out == full
    assert "--simulate" in full and "--figure" in full


def test_a_design_is_named_by_its_alias_or_class_name_in_any_case(capsys):
    """`closed-form` and `export --design` read a class name (as job files and result.json name a component) or an
    alias, in any case: the same rows; an unknown name is argparse's one line naming the choices."""
    outs = []
    for name in ("soifo", "SOIFO", "SecondOrderSOIFO", "second-order-soifo", "SOGIFLL"):
        assert main(["closed-form", name, "--json"]) == 0
        outs.append(json.loads(capsys.readouterr().out))
    assert outs[0] == outs[1] and outs[2] == outs[3] and outs[0] != outs[2]
    assert outs[4]["design"] == "sogi-fll"
    with pytest.raises(SystemExit) as e:  # argparse's own error
        main(["closed-form", "SOIF"])
    assert e.value.code == 2 and "invalid choice: 'SOIF' (choose from 'sogi-fll'" in capsys.readouterr().err


def test_closed_form_bad_options_exit_2(capsys):
    assert main(["closed-form", "wif", "--k", "2"]) == 2
    assert "--k does not apply to wif" in capsys.readouterr().err
    assert main(["closed-form", "cleso", "--lq", "0"]) == 2
    assert "CLESO.Lq must be finite and > 0" in capsys.readouterr().err
    assert main(["closed-form", "faleso", "--k1", "-1"]) == 2  # a gain's declared bounds (check_gains)
    assert "FALESO.k1 must be finite and > 0" in capsys.readouterr().err
    assert main(["closed-form", "sogi-fll", "--zeta", "-1"]) == 2
    assert "zeta" in capsys.readouterr().err


def test_bode_figures(tmp_path, capsys):
    assert main(["bode", "--out", str(tmp_path)]) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["bode_fll_open_loop_001_fig14.png", "bode_flux_observers_000_fig5.png", "bode_lesos_002_fig4.png"]
    assert names == sorted(BODE_FILES)  # the files the lock protects are the files written
    # a second run keeps them without --force, and replaces them with it
    before = {p.name: p.stat().st_mtime_ns for p in tmp_path.iterdir()}
    assert main(["bode", "--out", str(tmp_path)]) == 2
    assert "--force" in capsys.readouterr().err
    assert main(["bode", "--out", str(tmp_path), "--force"]) == 0
    after = {p.name: p.stat().st_mtime_ns for p in tmp_path.iterdir()}
    assert set(after) == set(before) and all(after[n] > before[n] for n in before)


@pytest.mark.slow
def test_reproduce_flux_quick_json(tmp_path, capsys):
    """The paper-000 reproduction runs end to end (about a minute) and prints comparable rows."""
    assert main(["reproduce", "flux", "--quick", "--json", "--out", str(tmp_path)]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {"experiment", "observer", "metric", "unit", "paper", "ours"} <= set(rows[0])
    by = {(r["experiment"], r["observer"], r["metric"]): r for r in rows}
    lpf = by[("du_alpha = 5 V at 1000 r/min", "LPF", "flux_offset")]
    assert lpf["paper"] == 0.05 and lpf["ours"] == pytest.approx(0.05, rel=0.02)
    assert by[("speed 400-2000-400 r/min", "second-order SOIFO", "max_abs")]["ours"] < 0.2
    # paper vs ours: every row with a paper number within its stated tolerance or explained
    # (jaxobs.reproduce.compare); the experiments run with 000's sampling delay, the load step's SOIFOs
    # carrying its 2.5 samples (0.157 rad at 2000 r/min)
    for r in rows:
        assert "within" in r and (r["within"] is not False or r["explanation"]), r
        if r["paper"] is not None and not isinstance(r["ours"], bool):
            assert r["tolerance"] > 0 and (r["within"] or r["explanation"]), r
    assert by[("load step 10 N·m at 2000 r/min", "second-order SOIFO", "max_abs")]["within"]
    # --quick skips 20 r/min and the I-f start: their figures are not drawn
    skipped = {"fig16_17_flux_position_20rpm.png", "fig20_if_start_low_speed.png"}
    assert sorted(p.name for p in tmp_path.glob("*.png")) == sorted(set(REPRODUCE_FILES["flux"]) - skipped)


@pytest.mark.repro
def test_reproduce_leso_json_rows_are_within_or_explained(tmp_path, capsys):
    """The paper-002 reproduction, single and dual machine (tens of minutes on two cores, beyond CI's budget: `make
    test-repro`; the slow suite checks the dual runs' rows and tests/test_papers_rows.py every row as last
    measured): every row carries `within`; every row outside its tolerance names its cause
    (jaxobs.reproduce.compare)."""
    main(["reproduce", "leso", "--json", "--out", str(tmp_path)])
    rows = json.loads(capsys.readouterr().out)
    for r in rows:
        assert {"paper", "ours", "tolerance", "within", "explanation"} <= set(r), r
        assert (r["within"] is None) == (r["paper"] is None), r
        assert r["within"] is not False or r["explanation"], r


def _result_json(tmp_path, component="SOGIFLLWIF", tuned=None):
    """A tuning result as ``run_job`` writes it (the fields a study reads back)."""
    job = {
        "job": {"name": "t", "component": component},
        "component": {"k1": 1.7},
        "gains": {"lam": {"init": 11559.0, "lower": 1000.0, "upper": 1e5, "log": True}},
        "scenarios": {"signal": "grid", "grid": {"dc": [0.0]}},
        "objective": {"terms": [{"metric": "itae_freq"}]},
    }
    p = tmp_path / "result.json"
    p.write_text(json.dumps({"job": job, "component": component, "gains": {"tuned": tuned or {"lam": 9000.0}}}))
    return p


def test_study_design_from_a_tuning_result(tmp_path):
    """jaxobs_tuning.results reads result.json; the study gets the tuned component (job values + tuned gains)."""
    obs = tuned_component(load_result(_result_json(tmp_path)))
    assert isinstance(obs, jaxobs.SOGIFLLWIF)
    assert (float(obs.k1), float(obs.k2), float(obs.lam)) == (
        1.7,
        papers.WIF_K2,
        9000.0,
    )  # [component], job default, tuned
    st = tmp_path / "s.toml"
    st.write_text(f'[designs.tuned]\nresult = "{_result_json(tmp_path)}"\n[axes]\ndc = [0.0]\n')
    name, designs, axes, _ = load_study(st)
    assert float(designs["tuned"].lam) == 9000.0 and axes == {"dc": [0.0]}


def test_study_result_errors_are_one_line(tmp_path, capsys):
    st = tmp_path / "s.toml"
    for content, expect in ((None, "no such file"), ("{", "not valid JSON"), ('{"job": {}}', "no 'component'")):
        res = tmp_path / "r.json"
        if content is None:
            res.unlink(missing_ok=True)
        else:
            res.write_text(content)
        st.write_text(f'[designs.a]\nresult = "{res}"\n[axes]\ndc = [0.0]\n')
        assert main(["study", str(st)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("jaxobs: error: designs.a.result:") and expect in err[0], err
    _result_json(tmp_path, tuned={"zz": 1.0})
    st.write_text(f'[designs.a]\nresult = "{tmp_path / "result.json"}"\n[axes]\ndc = [0.0]\n')
    assert main(["study", str(st)]) == 2
    assert "gains.tuned.zz" in capsys.readouterr().err


def test_study_result_paths_are_relative_to_the_study_file(tmp_path, monkeypatch):
    """``result = "result.json"`` means the file beside the study file, whatever the working directory."""
    studies, cwd = tmp_path / "studies", tmp_path / "cwd"
    studies.mkdir()
    cwd.mkdir()
    _result_json(studies, tuned={"lam": 9000.0})
    _result_json(cwd, tuned={"lam": 5000.0})  # another result in the working directory: never read
    (studies / "s.toml").write_text('[designs.tuned]\nresult = "result.json"\n[axes]\ndc = [0.0]\n')
    monkeypatch.chdir(cwd)
    for path in (studies / "s.toml", Path("..") / "studies" / "s.toml"):
        assert float(load_study(path)[1]["tuned"].lam) == 9000.0
    (studies / "t.toml").write_text(f'[designs.tuned]\nresult = "{cwd / "result.json"}"\n[axes]\ndc = [0.0]\n')
    assert float(load_study(studies / "t.toml")[1]["tuned"].lam) == 5000.0  # an absolute path as it is


def test_check_also_checks_out(tmp_path, capsys):
    """``--check`` refuses an ``--out`` the real run would refuse: a folder with the results of
    an earlier run, a file in its place, a folder that cannot be created; a fresh folder passes, and
    ``--check`` creates nothing."""
    done = tmp_path / "done"
    done.mkdir()
    (done / "result.json").write_text("{}")
    (done / "study.nc").write_text("")
    assert main(["tune", "--check", "--out", str(done)]) == 2
    assert "result.json' exists: use --force" in capsys.readouterr().err
    assert main(["tune", "--check", "--out", str(done), "--force"]) == 0
    assert main(["study", "--check", "--out", str(done)]) == 2
    assert "study.nc' exists: use --force" in capsys.readouterr().err
    (tmp_path / "file").write_text("")
    assert main(["study", "--check", "--out", str(tmp_path / "file")]) == 2
    assert "exists and is not a folder" in capsys.readouterr().err
    assert main(["study", "--check", "--out", str(tmp_path / "file" / "sub")]) == 2
    assert "cannot be created" in capsys.readouterr().err
    (done / "study.nc").unlink()
    (done / "study.chunks").mkdir()  # an interrupted study: the run names --resume, and so does --check
    assert main(["study", "--check", "--out", str(done)]) == 2
    assert "--resume" in capsys.readouterr().err
    assert main(["study", "--check", "--out", str(done), "--resume"]) == 0
    fresh = tmp_path / "new" / "deeper"
    capsys.readouterr()
    assert main(["tune", "--check", "--out", str(fresh)]) == 0
    assert main(["study", "--check", "--out", str(fresh)]) == 0
    # the embedded job and study are named, not by the installed package's path
    tune_line, study_line = capsys.readouterr().out.splitlines()[-2:]
    assert tune_line.startswith("the default job (wif_robust.toml): OK — SOGIFLLWIF")
    assert study_line.startswith("the default study (default_study.toml): OK — GridSignals")
    assert not (tmp_path / "new").exists()  # --check writes nothing


def test_the_package_lists_every_lazy_name():
    """jaxobs_tuning's names load on first use: __all__ is the lazy table's names, and each resolves."""
    import jaxobs_tuning

    assert jaxobs_tuning.__all__ == list(jaxobs_tuning._LAZY)
    assert all(getattr(jaxobs_tuning, n) is not None for n in jaxobs_tuning.__all__)


def test_quiet_sends_native_stderr_to_the_log_and_keeps_python_lines(tmp_path):
    """Under --quiet, what native code writes to descriptor 2 (XLA's slow-compile alarms) goes to the log; Python's
    one-line messages stay on stderr, and both are restored after the block.  Without --quiet, or where sys.stderr
    was replaced (a test's capture), nothing moves."""
    code = (
        "import os, sys\n"
        "from jaxobs_tuning.cli_common import native_stderr_to_log\n"
        "with native_stderr_to_log(True) as path:\n"
        "    os.write(2, b'native alarm\\n'); print('python line', file=sys.stderr)\n"
        "os.write(2, b'native after\\n'); print(path)\n"
        "with native_stderr_to_log(False) as none:\n"
        "    os.write(2, b'not quiet\\n')\n"
        "print(none)\n"
    )
    log = tmp_path / "native.log"
    run = _python(code, env_add={"JAXOBS_NATIVE_LOG": str(log)})
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == [str(log), "None"]
    assert run.stderr.splitlines() == ["python line", "native after", "not quiet"]
    assert log.read_text() == "native alarm\n"
    with native_stderr_to_log(True) as path:  # pytest's capture replaced sys.stderr: left alone
        assert path is None
