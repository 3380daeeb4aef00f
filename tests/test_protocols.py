"""Protocols are declared, not probed (docs/architecture.md, "Protocols").

Every module of jaxobs/ and tuning/ is parsed (nothing is imported) for the three ways code asks an object
what it is instead of relying on what its class declares: ``hasattr(x, name)``, ``getattr(x, name,
default)`` (a two-argument ``getattr`` reads a field a declared record names, e.g. a drive observer's
``bound_fields``, and is no probe) and ``import inspect``.  They are allowed only in the modules of
:data:`IO`, which meet the outside world: the operating system's optional flags, a terminal, an ``argparse``
namespace, a TOML file's keys checked against a constructor, a results folder's recordings, the program
cache's files.  A probe anywhere else fails here, naming its line.
"""

import ast
from pathlib import Path

import jax.numpy as jnp
import pytest

ROOT = Path(__file__).parents[1]

# module -> why it may probe (input and output only)
IO = {
    "jaxobs/io/files.py": "the operating system's optional open() flags (O_NOFOLLOW, O_DIRECTORY, O_BINARY, ...)",
    "jaxobs/io/provenance.py": "the operating system's optional open() flags",
    "tuning/outdir.py": "the operating system's optional open() flags",
    "jaxobs/runtime/progress.py": "whether stderr is a terminal (a stream may have no isatty)",
    "jaxobs/runtime/programs.py": "the key of a kept program: what it meets, by module, name and fields",
    "tuning/cli_run.py": "the command line's argparse namespace (a subcommand defines only its own options)",
    "tuning/envelope.py": "the command line's argparse namespace",
    "tuning/export/command.py": "the command line's argparse namespace",
    "tuning/cli_papers.py": "`jaxobs closed-form`'s options, one per parameter of a design, and its namespace",
    "tuning/study_file.py": "a study file's keys checked against a constructor's parameters; a recording's digests",
}


def _probes(path: Path) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            if node.func.id == "hasattr" or (node.func.id == "getattr" and len(node.args) == 3):
                found.append(f"{node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, ast.Import) and any(a.name.split(".")[0] == "inspect" for a in node.names):
            found.append(f"{node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "inspect":
            found.append(f"{node.lineno}: {ast.unparse(node)}")
    return found


def test_no_protocol_probes_outside_io():
    probes = {}
    for folder in ("jaxobs", "tuning"):
        for f in sorted((ROOT / folder).rglob("*.py")):
            rel = f.relative_to(ROOT).as_posix()
            if rel not in IO and (hits := _probes(f)):
                probes[rel] = hits
    assert probes == {}, f"protocol probes outside I/O (declare a method, attribute or abstract base): {probes}"


def test_the_probe_finder_finds_each_kind(tmp_path):
    """The check above can fail: each kind of probe is found, a two-argument getattr is not."""
    f = tmp_path / "m.py"
    f.write_text(
        "import inspect\nfrom inspect import signature\n"
        "a = hasattr(x, 'init')\nb = getattr(x, 'rule', None)\nc = getattr(x, name)\n"
    )
    got = _probes(f)
    assert [g.split(":")[0] for g in got] == ["1", "2", "3", "4"], got


def test_every_io_module_exists_and_still_probes():
    """The allow-list does not outlive its reason: each entry is a module that still needs it."""
    for rel in IO:
        assert (ROOT / rel).is_file(), rel
        assert _probes(ROOT / rel), f"{rel} no longer probes: remove it from IO"


def test_observer_ts_is_declared_and_required():
    """ts is an abstract variable of every observer: a field (the families) or a property (a bank); a class
    with neither cannot be built, and no field named ts is inherited from the base."""
    import dataclasses

    import jaxobs
    from jaxobs.observers import AbstractObserver, ObserverBank

    class NoTs(AbstractObserver):
        def init(self, u0=None):
            return None

        def step(self, state, u):
            return state, u

    with pytest.raises(TypeError, match="ts"):
        NoTs()
    assert "ts" not in {f.name for f in dataclasses.fields(ObserverBank)}
    bank = ObserverBank((jaxobs.SOIFO.closed_form(ts=2e-4),))
    assert bank.ts == 2e-4
    assert [f.name for f in dataclasses.fields(jaxobs.SOGIFLL)][:3] == ["ts", "rule", "k"]  # field order unchanged


def test_ab3_components_are_found_by_class():
    """The AB3 start-up (jaxobs.core.discretize.ab3_steady_from_start) finds a component's (x, rule) by its class,
    AbstractRuleCarry: a look-alike with the same attribute names is not one (the carry is peeled instead)."""
    import equinox as eqx

    from jaxobs.core.discretize import AB3, ab3_steady_from_start
    from jaxobs.observers import ObserverState

    x0 = jnp.asarray([1.0, 2.0])
    rule = AB3().init(None, x0, None)
    real = ObserverState(x=x0, rule=rule)
    got = ab3_steady_from_start(real, real, real, 1e-3)
    assert isinstance(got, ObserverState) and got.rule.n is None

    class LookAlike(eqx.Module):
        x: jnp.ndarray
        rule: object

    fake = LookAlike(x=x0, rule=rule)
    assert ab3_steady_from_start(fake, fake, fake, 1e-3) is None
