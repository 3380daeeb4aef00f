"""Data flows one way (docs/architecture.md): signals and plant produce measurements → observers estimate →
metrics score → tuning changes gains → the command line runs it all.

The import statements of every module in jaxobs/ and tuning/ are parsed (nothing is imported) and
checked against LAYERS, the declared order of the modules, lowest first:

- jaxobs never imports tuning;
- every import of a project module goes strictly down: to a module in a lower layer, never beside
  or above (importing ``a.b.c`` also runs the package ``a.b``: that package must be lower too);
- no import of a project module inside a function, where it would hide a cycle: none in jaxobs/, and
  none of a tuning module in tuning/ (tuning may defer a jaxobs import: jaxobs never imports tuning,
  so that cannot close a cycle).  The command line, which nothing imports, may defer its own;
- every module has its place in LAYERS, so a new module is placed on purpose.
"""

import ast
from pathlib import Path

ROOT = Path(__file__).parents[1]
PACKAGES = ("jaxobs", "jaxobs_tuning")
FOLDER = {"jaxobs": "jaxobs", "jaxobs_tuning": "tuning"}  # the folder tuning/ is installed as jaxobs_tuning

# Lowest first.  A module may import only modules of lower layers.  The order is docs/architecture.md's.
LAYERS = [
    # packages whose __init__ imports nothing: the foundations, files in and out, the studies
    ("jaxobs.core", "jaxobs.io", "jaxobs.studies"),
    ("jaxobs.io.files",),  # the one file writer (no project imports)
    # traced programs kept across processes (jaxobs.runtime.cache sets their folder), written by jaxobs.io.files
    ("jaxobs.runtime.programs",),
    # foundations: no project imports
    (
        "jaxobs.core.numerics",
        "jaxobs.core.trig",
        "jaxobs.core.validate",
        "jaxobs.papers",
        "jaxobs.core.measurements",
        "jaxobs.core.system",
        "jaxobs.core.sampletime",
        "jaxobs.runtime.progress",
        "jaxobs.io.provenance",
        "jaxobs.runtime.cache",
        "jaxobs.drive.component",
        "jaxobs.runtime.chunkstore",
        "jaxobs.core.quantities",
    ),
    # integration rules (and check_rule)
    ("jaxobs.core.discretize", "jaxobs.io.safetoml", "jaxobs.signals._base", "jaxobs.drive.saturation"),
    # a recording's declared layout, and the one reader of delimited text (recordings and drive logs alike)
    ("jaxobs.signals._layout",),
    ("jaxobs.signals._logfile",),  # delimited text streamed into disk-backed columns, or read whole
    # signals and plant: they produce the measurements
    (
        "jaxobs.signals._waveforms",
        "jaxobs.signals._recordings",
        "jaxobs.signals._logchecks",
        "jaxobs.drive.machine",
        "jaxobs.drive.hardware",
        "jaxobs.drive.latency",
    ),
    # drive logs: a declared layout read into DriveRecordings; carrier-comparison PWM (the inverter's transforms);
    # field weakening (on the machine's parameters)
    ("jaxobs.signals._logs", "jaxobs.drive.pwm", "jaxobs.drive.weakening"),
    ("jaxobs.signals._read",),  # the recordings reader: one file as a family's scenarios
    ("jaxobs.signals",),
    # the FOC's parts: the I-f start-up, the i_d policy's maps, its interface types, the current limit at every
    # sample; the steady operating point
    ("jaxobs.drive.startup", "jaxobs.drive._policy", "jaxobs.drive._foctypes", "jaxobs.drive._reflimit"),
    ("jaxobs.drive._operating",),
    ("jaxobs.scenarios", "jaxobs.drive.plant", "jaxobs.drive.dual", "jaxobs.drive.control", "jaxobs.drive.scenario"),
    ("jaxobs.drive._zerospeed",),  # scenarios through and at zero speed, made from a base Scenario
    # observers: they estimate
    ("jaxobs.observers._cores", "jaxobs.observers._gains", "jaxobs.observers._rules"),
    ("jaxobs.observers.speed",),
    ("jaxobs.observers.base",),  # its one bound check is _gains'; a drive observer holds a speed estimator
    (
        "jaxobs.observers.sogi",
        "jaxobs.observers.fll",
        "jaxobs.observers.flux",
        "jaxobs.observers.leso",
        "jaxobs.observers.rofo",
    ),
    ("jaxobs.observers.soifo", "jaxobs.observers.faleso"),  # on flux's and leso's contracts
    ("jaxobs.observers",),
    # the closed loop composes the drive's parts with a drive observer (its contract, observers.base)
    ("jaxobs.drive.loop",),
    # the dual loop shares the loop's base, AbstractDriveLoop; a drive file builds a machine and a Drive
    ("jaxobs.drive.dual_loop",),
    ("jaxobs.drive._dualfile",),  # a drive file's [dual]: the dual machine and drive on one set's derivation
    ("jaxobs.drive._filekeys", "jaxobs.drive._steady"),  # a drive file's keys and its steady-state rules
    ("jaxobs.drive._filemap", "jaxobs.drive._filebuild"),  # its saturation map; its derivation, table by table
    ("jaxobs.drive.drivefile",),
    ("jaxobs.drive.bench",),
    ("jaxobs.drive",),
    # the one loop over a system, and sharding a batch over devices
    ("jaxobs.runtime._steps", "jaxobs.runtime._sensitivity"),
    ("jaxobs.runtime._loop", "jaxobs.runtime.onsignal"),  # the loop; an observer on a signal as a system
    ("jaxobs.runtime.simulation", "jaxobs.runtime.sharding"),
    ("jaxobs.runtime",),  # the loop's public names (simulate, the savers, the checkpoints)
    # metrics: the functions that score a run, the one metric table (its entries' forms use them), the package
    ("jaxobs.metrics._core",),
    ("jaxobs.metrics._lock",),  # lost lock, lost speed and the position error of a run
    ("jaxobs.metrics._table",),
    ("jaxobs.metrics",),
    # linear analysis: the observers' models, closed forms that return observers, settling times (metrics)
    ("jaxobs.linear._tf",),
    ("jaxobs.linear._margins", "jaxobs.linear._discrete"),  # frequency responses and margins; H(z) and Tustin
    ("jaxobs.linear._models", "jaxobs.linear._fll"),
    ("jaxobs.linear",),
    ("jaxobs",),
    # the one study runner (samplers in jaxobs.scenarios), the scenario families (their axes, batches, systems)
    # and the registry of observer classes
    ("jaxobs.runtime.runner", "jaxobs.scenarios.families._base", "jaxobs.studies.registry"),
    ("jaxobs.scenarios.families.signals",),  # grid signals and back EMFs
    ("jaxobs.scenarios.families.drive",),  # the drive (its recordings are the back EMFs')
    ("jaxobs.scenarios.families",),
    # the figures' helpers and the Bode figures (jaxobs.plot re-exports them)
    ("jaxobs.plot._figure", "jaxobs.reproduce.compare", "jaxobs.reproduce._run"),
    ("jaxobs.plot._bode", "jaxobs.plot._paper", "jaxobs.plot._envelope"),
    # the library's own applications: studies, the demo, the papers' reproductions, figures, benchmarks
    (
        "jaxobs.studies.study",
        "jaxobs.studies.demo",
        "jaxobs.reproduce.flux",
        "jaxobs.reproduce.leso",
        "jaxobs.plot",
    ),
    # the drive study: a preset of jaxobs.studies.study.study
    ("jaxobs.studies.drive",),
    # analyses above the studies they run: the package (no imports), the closed loop's stability verdict, then
    # the envelope map (the stability verdict and the long runs of a drive study, over the speed x load plane)
    ("jaxobs.analysis",),
    # the loop's linearization along its orbit (the tangent blocks, the window's multipliers, whole or matrix-free)
    ("jaxobs.analysis.monodromy",),
    (
        "jaxobs.analysis.stability",
        "jaxobs.analysis.verdict",
        "jaxobs.analysis.envelope_layout",
        "jaxobs.analysis.drive_points",
    ),
    ("jaxobs.analysis.envelope_runs",),
    ("jaxobs.analysis.worst",),
    ("jaxobs.analysis.envelope",),
    ("jaxobs.reproduce.leso_dual", "jaxobs.reproduce.figures"),
    ("jaxobs.reproduce",),
    # tuning: it changes gains (and exports the tuned observer)
    # the results folder, checkpoints, and what a solver minimises (the objective's protocol)
    ("jaxobs_tuning.outdir", "jaxobs_tuning.checkpoint", "jaxobs_tuning.base", "jaxobs_tuning.minimisers"),
    # the C export's code generator (jaxpr -> C) is beside the rest: it knows no observer
    ("jaxobs_tuning.export.ir", "jaxobs_tuning.export.c99"),
    ("jaxobs_tuning.export.lower",),
    ("jaxobs_tuning.export.codegen", "jaxobs_tuning.params", "jaxobs_tuning.solvers", "jaxobs_tuning.aggregations"),
    ("jaxobs_tuning.strategies",),
    ("jaxobs_tuning.objective", "jaxobs_tuning.report", "jaxobs_tuning.targets"),
    ("jaxobs_tuning.structure",),
    ("jaxobs_tuning.job.fields",),
    ("jaxobs_tuning.job.toml", "jaxobs_tuning.job.components", "jaxobs_tuning.job.spec"),
    ("jaxobs_tuning.job.recordings", "jaxobs_tuning.job.drive"),
    ("jaxobs_tuning.job.verify", "jaxobs_tuning.job.output"),
    ("jaxobs_tuning.job.schema", "jaxobs_tuning.job.scenarios"),
    ("jaxobs_tuning.job.run",),
    ("jaxobs_tuning.job",),
    ("jaxobs_tuning.results",),
    ("jaxobs_tuning.study_file",),
    # the export: where the observer comes from, its test records, the harness; the export; its command
    ("jaxobs_tuning.export.sources", "jaxobs_tuning.export.golden", "jaxobs_tuning.export.harness"),
    ("jaxobs_tuning.export.files",),
    ("jaxobs_tuning.export.command",),
    ("jaxobs_tuning.export", "jaxobs_tuning.envelope"),
    ("jaxobs_tuning",),
    # the command line: the top layer (`jaxobs ...` and `python -m jaxobs`)
    ("jaxobs_tuning.cli_common", "jaxobs_tuning.summary", "jaxobs_tuning.distributed"),
    ("jaxobs_tuning.cli_run",),  # the runner of every command: one-line errors, the compile cache, --quiet's log
    ("jaxobs_tuning.cli_papers", "jaxobs_tuning.cli_drive", "jaxobs_tuning.cli_log"),
    ("jaxobs_tuning.cli",),
    # the console script: help and version at once, `drive` by its own parser, the other commands by cli
    ("jaxobs_tuning.cli_entry",),
    ("jaxobs.__main__",),
]
# Imported by nothing outside it, so it may defer imports for start-up time.  jaxobs/__main__.py is an
# entry point that `import jaxobs` never runs: the one place under jaxobs/ that imports tuning.
COMMAND_LINE = {"jaxobs_tuning.cli", "jaxobs_tuning.cli_entry", "jaxobs.__main__"}

# Violations that other engineers' changes remove; the lead empties this list after merging them.
# An entry that no longer occurs fails the test: delete it.  Keep this list short.
PENDING: set = set()

RANK = {m: i for i, layer in enumerate(LAYERS) for m in layer}


def _modules():
    """{dotted name: path} for every module of the project's packages."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / FOLDER[pkg]).rglob("*.py")):
            parts = (pkg, *path.relative_to(ROOT / FOLDER[pkg]).with_suffix("").parts)
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


MODULES = _modules()


def _package_of(name):
    return name if MODULES[name].name == "__init__.py" else name.rpartition(".")[0]


def _imports(name):
    """(target module, line, lazy) for every import of a project module in module ``name``."""
    tree = ast.parse(MODULES[name].read_text())
    lazy_nodes = set()
    for fn in ast.walk(tree):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            lazy_nodes.update(id(n) for n in ast.walk(fn) if n is not fn)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = _package_of(name).split(".")
                base = base[: len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module
            # `from pkg import sub` imports the module pkg.sub; `from mod import name` imports mod
            targets = [f"{module}.{a.name}" if f"{module}.{a.name}" in MODULES else module for a in node.names]
        else:
            continue
        for target in dict.fromkeys(targets):
            if target.split(".")[0] in PACKAGES:
                yield target, node.lineno, id(node) in lazy_nodes


def _ancestors(name):
    parts = name.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def test_every_module_has_a_layer():
    unplaced = sorted(set(MODULES) - set(RANK))
    stale = sorted(set(RANK) - set(MODULES))
    assert not unplaced, f"place these modules in LAYERS: {unplaced}"
    assert not stale, f"LAYERS names modules that do not exist (remove them): {stale}"
    assert len(RANK) == sum(len(layer) for layer in LAYERS), "a module appears in two layers"


def test_jaxobs_never_imports_tuning():
    bad = [
        f"{name}:{line} imports {target}"
        for name in MODULES
        if name.split(".")[0] == "jaxobs" and name not in COMMAND_LINE
        for target, line, _ in _imports(name)
        if target.split(".")[0] == "jaxobs_tuning"
    ]
    assert not bad, "\n".join(bad)


def test_nothing_imports_the_folder_name_tuning():
    """The folder tuning/ is installed as jaxobs_tuning: an ``import jaxobs_tuning`` would work from the repository root
    only, and beside ``jaxobs_tuning`` it would load every module twice (two classes, two registries)."""
    roots = [ROOT / "jaxobs", ROOT / "tuning", ROOT / "tests", ROOT / "benchmarks", ROOT / "docs"]
    bad = []
    for path in sorted(p for r in roots for p in r.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom) and not node.level:
                names = [node.module or ""]
            bad += [f"{path.relative_to(ROOT)}:{node.lineno} imports {n}" for n in names if n.split(".")[0] == "tuning"]
    assert not bad, "\n".join(bad)


def test_nothing_imports_the_command_line():
    bad = [
        f"{name}:{line} imports {target}"
        for name in MODULES
        if name not in COMMAND_LINE
        for target, line, _ in _imports(name)
        if target in COMMAND_LINE
    ]
    assert not bad, bad


def _violations():
    """{(importer, imported): [messages]} for every import that breaks a rule."""
    found = {}
    for name in MODULES:
        own = {*_ancestors(name), name}
        for target, line, lazy in _imports(name):
            if target not in RANK:
                continue  # an unknown module fails test_every_module_has_a_layer
            # the module and the packages that importing it runs (the importer's own packages run anyway)
            for t in [target, *(a for a in _ancestors(target) if a not in own)]:
                if RANK[t] >= RANK[name]:
                    where = "beside" if RANK[t] == RANK[name] else "above"
                    found.setdefault((name, target), []).append(f"{name}:{line} imports {t}, a layer {where} it")
            inside_jaxobs = name.split(".")[0] == target.split(".")[0] == "jaxobs"
            inside_tuning = name.split(".")[0] == target.split(".")[0] == "jaxobs_tuning" and name not in COMMAND_LINE
            if lazy and (inside_jaxobs or inside_tuning):
                found.setdefault((name, target), []).append(f"{name}:{line} imports {target} inside a function")
    return found


def test_imports_go_down_the_layers_and_none_is_deferred():
    found = _violations()
    pending_used = set()
    problems = []
    for (name, target), messages in sorted(found.items()):
        if (name, target) in PENDING:
            pending_used.add((name, target))
        else:
            problems += messages
    problems += [f"PENDING entry {entry} no longer occurs: remove it" for entry in sorted(PENDING - pending_used)]
    assert not problems, "\n".join(problems)


def test_the_checks_see_a_violation(tmp_path, monkeypatch):
    """The parser resolves relative and package imports, and flags upward and deferred ones."""
    targets = {(t, lazy) for t, _, lazy in _imports("jaxobs.signals._waveforms")}
    assert ("jaxobs.papers", False) in targets  # `from .. import papers`
    assert ("jaxobs.core.measurements", False) in targets  # `from .._measurements import DriveInput`
    assert {t for t, _, _ in _imports("jaxobs.reproduce.leso")} >= {"jaxobs.drive", "jaxobs.linear", "jaxobs.papers"}
    probe = tmp_path / "_probe.py"  # a module beside signals that imports upward, once at the top, once deferred
    probe.write_text("from .studies import study\n\n\ndef f():\n    from . import metrics\n")
    monkeypatch.setitem(MODULES, "jaxobs._probe", probe)
    monkeypatch.setitem(RANK, "jaxobs._probe", RANK["jaxobs.signals"])
    assert {(t, lazy) for t, _, lazy in _imports("jaxobs._probe")} == {
        ("jaxobs.studies.study", False),
        ("jaxobs.metrics", True),
    }
    found = _violations()
    assert "a layer above it" in " ".join(found[("jaxobs._probe", "jaxobs.studies.study")])
    assert "inside a function" in " ".join(found[("jaxobs._probe", "jaxobs.metrics")])


def _private_imports(name):
    """(line, what) for every import in module ``name`` of a private module or name that belongs to another
    package: ``from x._y import ...`` / ``import x._y`` where ``x`` is not the importer's package or one
    enclosing it, and ``from pkg.mod import _name`` where ``pkg`` is not.  A package's private parts are its
    own and its subpackages'."""
    own = _package_of(name)

    def inside(pkg):  # pkg is the importer's package or encloses it
        return own == pkg or own.startswith(pkg + ".")

    tree = ast.parse(MODULES[name].read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            pairs = [(a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = own.split(".")
                module = ".".join(base[: len(base) - (node.level - 1)] + ([node.module] if node.module else []))
            else:
                module = node.module
            pairs = [(module, a.name) for a in node.names]
        else:
            continue
        for module, imported in pairs:
            if module.split(".")[0] not in PACKAGES:
                continue
            parts = module.split(".")
            for i, part in enumerate(parts):
                if part.startswith("_") and not part.startswith("__") and not inside(".".join(parts[:i])):
                    yield node.lineno, f"the private module {module}"
                    break
            else:
                if imported and imported.startswith("_") and not imported.startswith("__"):
                    target = f"{module}.{imported}"
                    pkg = target if target in MODULES and MODULES[target].name == "__init__.py" else module
                    pkg = pkg if pkg in MODULES and MODULES[pkg].name == "__init__.py" else pkg.rpartition(".")[0]
                    if not inside(pkg):
                        yield node.lineno, f"the private name {imported} of {module}"


def test_no_private_name_crosses_a_package():
    """A module imports another package's public names only (its own package's, and enclosing packages',
    private modules and names are its own): a private name is free to change without a caller elsewhere."""
    bad = [f"{name}:{line} imports {what}" for name in MODULES for line, what in _private_imports(name)]
    assert not bad, "\n".join(bad)


def test_the_private_import_check_sees_one(tmp_path, monkeypatch):
    probe = tmp_path / "_probe.py"
    probe.write_text(
        "from jaxobs.observers._cores import x\nfrom .job.fields import _cap\nfrom jaxobs.runtime._loop import y\n"
        "import jaxobs.runtime._steps\nfrom .targets import _z\n"
    )
    monkeypatch.setitem(MODULES, "jaxobs_tuning._probe", probe)
    found = [what for _, what in _private_imports("jaxobs_tuning._probe")]
    assert found == [
        "the private module jaxobs.observers._cores",
        "the private name _cap of jaxobs_tuning.job.fields",
        "the private module jaxobs.runtime._loop",
        "the private module jaxobs.runtime._steps",
    ], found


def test_the_drive_imports_nothing_above_it():
    """``jaxobs/drive/`` holds the drive only: its modules import the drive's parts and what lies below the
    package ``jaxobs.drive`` (signals, observers, the rules), never a study, the loop runner or an analysis."""
    top = RANK["jaxobs.drive"]
    bad = [
        f"{name}:{line} imports {target}"
        for name in MODULES
        if name == "jaxobs.drive" or name.startswith("jaxobs.drive.")
        for target, line, _ in _imports(name)
        if target in RANK and RANK[target] > top
    ]
    assert not bad, "\n".join(bad)


def test_the_architecture_page_draws_these_layers():
    """docs/architecture.md's layer block is LAYERS: the same modules, in the same order, grouped into the same
    numbered layers (a number starts a layer; a line without one is beside the line above)."""
    import re

    doc = (ROOT / "docs" / "architecture.md").read_text()
    start = doc.index("```\n #  module")
    block = doc[start + 4 : doc.index("```", start + 3)].splitlines()[1:]
    drawn = []
    for line in block:
        m = re.match(r"^( ?\d+[a-z]?  |    )((?:jaxobs_tuning|jaxobs)(?:\.\w+)*)(\s|$)", line)
        if not m:
            continue
        if m.group(1).strip():
            drawn.append([])
        drawn[-1].append(m.group(2))
    assert drawn == [list(layer) for layer in LAYERS]
