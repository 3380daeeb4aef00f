"""One home per paper constant (jaxobs/papers.py): the copies that cannot import it agree with it,
and no module types a paper's number again."""

import ast
import json
import math
import tomllib
from pathlib import Path

import pytest

from jaxobs import drive as D
from jaxobs import linear, papers

ROOT = Path(__file__).parents[1]
PRESETS = ROOT / "tuning" / "presets"

# Preset gains whose initial value is meant to be the paper's (the closed form the job reports beside the
# tuned gains), with the decimals the TOML writes (None: exact).  TOML cannot import papers.py.
_PLL_KP, _PLL_KI = (float(g) for g in linear.pll_gains(2 * math.pi * papers.LESO_PLL_HZ))
PRESET_VALUES = [
    ("sogi_fll", "lam", papers.SOGI_FLL_LAM, None),
    ("wpf", "k1", papers.WPF_K1, 4),
    ("wpf", "k2", papers.WPF_K2, 4),
    ("wpf", "lam", papers.WPF_LAM, None),
    ("wif_robust", "k1", papers.WIF_K1, None),
    ("wif_robust", "k2", papers.WIF_K2, None),
    ("wif_robust", "lam", papers.WIF_LAM, None),
    ("soifo", "k", papers.SOIFO_K, None),
    ("soifo", "lam", papers.SOIFO_K**2 / 4, 3),  # 000's k with the damping rule lam = k²/4
    ("sosoifo", "K1", papers.SECOND_ORDER_SOIFO_K1, None),
    ("sosoifo", "K2", papers.SECOND_ORDER_SOIFO_K2, None),
    ("recording_sosoifo", "K1", papers.SECOND_ORDER_SOIFO_K1, None),
    ("recording_sosoifo", "K2", papers.SECOND_ORDER_SOIFO_K2, None),
    ("recording_wif", "k1", papers.WIF_K1, None),
    ("recording_wif", "k2", papers.WIF_K2, None),
    ("recording_wif", "lam", papers.WIF_LAM, None),
    ("sosoifo", "lam", papers.SECOND_ORDER_SOIFO_K1**3 / (2 * papers.SECOND_ORDER_SOIFO_K2), 2),  # lam = K1³/(2K2)
    ("soifo_noise", "k", papers.SOIFO_K, None),
    ("soifo_noise", "lam", papers.SOIFO_K**2 / 4, 3),
    ("gileso", "omega0", papers.LESO_OMEGA0, 1),
    ("gileso", "omega_c", papers.GILESO_OMEGA_C, 5),
    ("gileso", "kp_pll", _PLL_KP, 1),
    ("gileso", "ki_pll", _PLL_KI, 1),
    ("cleso", "omega0", papers.LESO_OMEGA0, 1),
    ("faleso", "k1", papers.FALESO_K1, 4),
    ("faleso", "k2", papers.FALESO_K2, 3),
    ("faleso", "kp_pll", _PLL_KP, 1),  # the ASSUMED PLL, ω_b = 2π·LESO_PLL_HZ
    ("faleso", "ki_pll", _PLL_KI, 1),
]


@pytest.mark.parametrize("preset, gain, value, decimals", PRESET_VALUES, ids=[f"{p}.{g}" for p, g, *_ in PRESET_VALUES])
def test_preset_initial_gains_are_the_papers(preset, gain, value, decimals):
    job = tomllib.loads((PRESETS / f"{preset}.toml").read_text())
    init = job["gains"][gain]["init"]
    assert init == (value if decimals is None else round(value, decimals)), (preset, gain, init, value)


def test_every_preset_gain_is_checked():
    """Every preset gain starts at the paper's value: a new preset (or gain) is added to the table above."""
    checked = {(p, g) for p, g, _, _ in PRESET_VALUES}
    for path in sorted(PRESETS.glob("*.toml")):
        for gain in tomllib.loads(path.read_text()).get("gains", {}):
            assert (path.stem, gain) in checked, f"{path.name}: gains.{gain} is not checked against jaxobs.papers"


@pytest.mark.parametrize(
    "preset, table", [(D.spmsm_paper000, papers.SPMSM_000), (D.ipmsm_paper002, papers.IPMSM_002)], ids=["000", "002"]
)
def test_machine_presets_are_the_papers_tables(preset, table):
    """jaxobs.drive's machine presets hold the tables of jaxobs.papers (000 Table II; 002's ASSUMED machine): the
    motor alone with inertia="motor", and by default the shipped drive file's machine, the same but for the
    bench's ASSUMED inertia (papers.BENCH_J_000, BENCH_J_002) -- one machine per paper, the one the CLI runs."""
    par = preset(inertia="motor")
    for field, value in table.items():
        assert float(getattr(par, field)) == value, field
    bench = preset()
    name, bench_j = ("spmsm000", papers.BENCH_J_000) if table is papers.SPMSM_000 else ("ipmsm002", papers.BENCH_J_002)
    assert bench is D.bench_machine(name) and float(bench.J) == bench_j
    for field, value in table.items():
        assert float(getattr(bench, field)) == (bench_j if field == "J" else value), field
    assert float(preset(J=1.0).J) == 1.0
    with pytest.raises(ValueError, match="inertia must be 'bench' or 'motor'"):
        preset(inertia="load")
    with pytest.raises(ValueError, match="give the inertia once"):
        preset(inertia="motor", J=1.0)


# Numbers that identify a paper constant (their value is unlikely to mean anything else), and the
# multiples of π that 002 Table II writes.  Found as numeric literals in jaxobs/ or tuning/ outside
# papers.py, they are a second home.
_FROM_001 = {1.815, 0.752, 11559.0, 12337.0, 23948.0, 18.8}  # Table I; ωc = 2π·18.8
_FROM_000 = {1.414, 1.56, 3.11, 6.22, 3.78e-4, 0.018}  # k, K1, K2 (and 2·K2); Table II's J; t_s
_ASSUMED_002 = {0.0675, 0.0879}  # the 5th and 7th BEMF harmonics
PAPER_LITERALS = _FROM_001 | _FROM_000 | _ASSUMED_002
PAPER_PI_MULTIPLES = {500, 10}  # ω0 = 500π, k1 = 10π

# Second homes in files other engineers own, to be removed when their changes land (the test then
# fails until the entry is deleted).  Keep this list short.
PENDING: set = set()
# Where a paper's number is typed on purpose: {file: (values, why)}.  Keep it short.
_TABLE_I = {1.815, 0.752, 11559, 12337.0, 18.8}
ALLOWED: dict = {
    "tests/test_papers.py": (PAPER_LITERALS, "this guard's own list of the papers' numbers"),
    "tests/test_cli.py": (_TABLE_I, "oracle: the printed closed form against 001 Table I; a job file's text"),
    "tests/test_tuning.py": (_TABLE_I | {"1+√2"}, "oracle: the closed form, its crossover and b against 001"),
    "tests/test_tuning_results.py": (_TABLE_I | {"1+√2"}, "oracle: as test_tuning.py, its tests split off"),
    "tests/test_export.py": (_TABLE_I, "a result.json's text, as a tuning run writes it"),
    "tests/test_fuzz.py": (_TABLE_I, "a job file's text, as a user writes it"),
    # the closed forms checked against Table I as printed: an oracle independent of jaxobs.papers, so a wrong
    # constant there cannot pass through both sides
    "tests/test_closed_forms.py": (_TABLE_I | {1.414, 23948.0}, "oracle: 001 Table I as printed, against the rules"),
    "tests/test_registry.py": (_TABLE_I, "oracle: 001 Table I's WIF as printed, against the classmethod"),
    # the traction IPMSM's stator resistance, 18 mΩ (docs/examples/traction_ipmsm.toml), equals 000's settling time
    # 0.018 s by chance: a machine's value, not the paper's
    "tests/test_drive_capability.py": ({0.018}, "the traction IPMSM's Rs = 18 mΩ, not 000's 0.018 s"),
}


def _is_pi(node, aliases) -> bool:
    """``math.pi`` / ``np.pi`` / ``jnp.pi``, or a name bound to one of them."""
    return (isinstance(node, ast.Attribute) and node.attr == "pi") or (
        isinstance(node, ast.Name) and node.id in aliases
    )


def _is_sqrt2(node) -> bool:
    """``math.sqrt(2)`` (``np.sqrt``, ``jnp.sqrt``, ``sqrt``)."""
    return (
        isinstance(node, ast.Call)
        and getattr(node.func, "attr", getattr(node.func, "id", None)) == "sqrt"
        and len(node.args) == 1
        and isinstance(node.args[0], ast.Constant)
        and node.args[0].value == 2
    )


def _pi_aliases(tree) -> set:
    """Names a module binds to π: ``pi = math.pi`` (``np.pi``, ``jnp.pi``, or an alias of them), and
    ``from math import pi [as x]`` (numpy, jax.numpy, cmath too): ``500 * pi`` is 500π all the same."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module in ("math", "cmath", "numpy", "jax.numpy"):
            names |= {a.asname or a.name for a in node.names if a.name == "pi"}
    for _ in range(3):  # an alias of an alias
        for node in ast.walk(tree):
            if isinstance(node, (ast.Assign, ast.AnnAssign)) and node.value is not None and _is_pi(node.value, names):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                names |= {t.id for t in targets if isinstance(t, ast.Name)}
    return names


def _paper_literals(source: str):
    tree = ast.parse(source)
    aliases = _pi_aliases(tree)
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and type(node.value) in (int, float) and node.value in PAPER_LITERALS:
            yield node.lineno, node.value
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):  # 001's b = 1 + √2 (papers.WIF_B)
            for one, root in ((node.left, node.right), (node.right, node.left)):
                if isinstance(one, ast.Constant) and one.value == 1 and _is_sqrt2(root):
                    yield node.lineno, "1+√2"
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Mult):
            for k, x in ((node.left, node.right), (node.right, node.left)):
                if isinstance(k, ast.Constant) and k.value in PAPER_PI_MULTIPLES and _is_pi(x, aliases):
                    yield node.lineno, f"{k.value}π"


def _notebook_code(path: Path) -> str:
    """A notebook's code cells as one module (IPython's ``%`` and ``!`` lines left out)."""
    cells = json.loads(path.read_text())["cells"]
    code = ["".join(c["source"]) for c in cells if c["cell_type"] == "code"]
    return "\n".join(ln for ln in "\n".join(code).splitlines() if not ln.lstrip().startswith(("%", "!")))


def _scanned():
    """(path relative to the root, source) of every file the guard reads: the library, tuning (the command
    line included), the tests and the notebooks' code cells."""
    for folder in ("jaxobs", "tuning", "tests"):
        for path in sorted(ROOT.joinpath(folder).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel != "jaxobs/papers.py":
                yield rel, path.read_text()
    for path in sorted(ROOT.joinpath("notebooks").glob("*.ipynb")):
        yield path.relative_to(ROOT).as_posix(), _notebook_code(path)


def test_no_paper_constant_is_typed_outside_papers_py():
    found = set()
    problems = []
    for rel, source in _scanned():
        for line, value in _paper_literals(source):
            if rel in ALLOWED and value in ALLOWED[rel][0]:
                continue
            if (rel, value) in PENDING:
                found.add((rel, value))
            else:
                problems.append(f"{rel}:{line}: {value} (import it from jaxobs.papers)")
    problems += [f"PENDING entry {entry} no longer occurs: remove it" for entry in sorted(PENDING - found, key=str)]
    assert not problems, "\n".join(problems)


def test_the_constants_guard_sees_aliases_of_pi():
    """The guard is not fooled by π under another name (the command line had ``pi = math.pi`` and 500 * pi)."""
    for src in (
        "import math\npi = math.pi\nw = 500 * pi\n",
        "from math import pi as PI\nw = PI * 500\n",
        "import numpy as np\np = np.pi\nq = p\nk = 10 * q\n",
        "import jax.numpy as jnp\nw = 500 * jnp.pi\n",
    ):
        assert [v for _, v in _paper_literals(src)] in (["500π"], ["10π"]), src
    assert not list(_paper_literals("import math\nw = 2 * math.pi * 50\n"))
    assert [v for _, v in _paper_literals("import math\nb = 1 + math.sqrt(2)\n")] == ["1+√2"]


def test_tables_are_read_only():
    with pytest.raises(TypeError):
        papers.SPMSM_000["Rs"] = 1.0  # type: ignore[index]
    with pytest.raises(TypeError):
        papers.TESTS_001["A"]["freq_step"] = 3.0  # type: ignore[index]
