"""The code's surface, as a reader meets it (docs/architecture.md, "The layers").

- no module of jaxobs/ or tuning/ over 700 lines, and no function over 100 lines of code (its docstring is
  documentation, not counted), but the hot loops named in LONG with their reason;
- every public function (no leading underscore, in any module: a private module's public names are its package's
  surface, re-exported or used across it) annotated in full, every parameter and its return;
- every public function with parameters has a Google-style docstring (an ``Args:`` section), every public class
  a docstring.

Nothing is imported: the files are parsed.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
FILES = sorted(p for d in ("jaxobs", "tuning") for p in (ROOT / d).rglob("*.py"))
MAX_FILE_LINES = 700
MAX_FUNCTION_LINES = 100
# function (path:qualified name) -> why it may be longer
LONG: dict[str, str] = {}


def _functions(tree, prefix="", public=True):
    """(qualified name, node, public) for every function, methods and nested functions included."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            pub = public and not node.name.startswith("_")
            yield prefix + node.name, node, pub
            yield from _functions(node, f"{prefix}{node.name}.", False)
        elif isinstance(node, ast.ClassDef):
            yield from _functions(node, f"{prefix}{node.name}.", public and not node.name.startswith("_"))


def _code_lines(fn) -> int:
    n = fn.end_lineno - fn.lineno + 1
    first = fn.body[0]
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
        n -= first.end_lineno - first.lineno + 1
    return n


PARSED = {path: ast.parse(path.read_text()) for path in FILES}


def _class_index() -> dict[str, tuple[list[str], dict[str, bool]]]:
    """Every project class by name: its bases' names and, per method, whether it has a docstring."""
    out: dict[str, tuple[list[str], dict[str, bool]]] = {}
    for tree in PARSED.values():
        for c in ast.walk(tree):
            if isinstance(c, ast.ClassDef):
                bases = [
                    b.id if isinstance(b, ast.Name) else b.attr if isinstance(b, ast.Attribute) else "" for b in c.bases
                ]
                methods = {m.name: bool(ast.get_docstring(m)) for m in c.body if isinstance(m, ast.FunctionDef)}
                out.setdefault(c.name, (bases, methods))
    return out


CLASSES = _class_index()


def _inherits_doc(cls: str, method: str, seen: frozenset = frozenset()) -> bool:
    """Whether a base of ``cls`` (a project class, at any depth) documents ``method``: an override then inherits its
    docstring (``inspect.getdoc`` and the API pages follow the MRO), so it need not repeat it."""
    for base in CLASSES.get(cls, ([], {}))[0]:
        if base in CLASSES and base not in seen:
            if CLASSES[base][1].get(method) or _inherits_doc(base, method, seen | {base}):
                return True
    return False


def test_no_module_over_700_lines():
    big = [f"{p.relative_to(ROOT)}: {p.read_text().count(chr(10))}" for p in FILES]
    big = [b for b in big if int(b.rsplit(": ", 1)[1]) > MAX_FILE_LINES]
    assert not big, "\n".join(big)


def test_no_function_over_100_lines():
    long = {}
    for path, tree in PARSED.items():
        for name, fn, _ in _functions(tree):
            key = f"{path.relative_to(ROOT)}:{name}"
            if _code_lines(fn) > MAX_FUNCTION_LINES:
                long[key] = _code_lines(fn)
    unexplained = {k: n for k, n in long.items() if k not in LONG}
    stale = sorted(set(LONG) - set(long))
    assert not unexplained, "\n".join(f"{k}: {n} lines" for k, n in unexplained.items())
    assert not stale, f"LONG names functions no longer over {MAX_FUNCTION_LINES} lines: {stale}"


def _args(fn):
    a = fn.args
    out = [x for x in a.posonlyargs + a.args + a.kwonlyargs if x.arg not in ("self", "cls")]
    return out + [x for x in (a.vararg, a.kwarg) if x is not None]


@pytest.mark.parametrize("check", ["typed", "documented"])
def test_public_functions_are_typed_and_documented(check):
    bad = []
    for path, tree in PARSED.items():
        for name, fn, public in _functions(tree):
            overload = any(
                (isinstance(d, ast.Name) and d.id == "overload")
                or (isinstance(d, ast.Attribute) and d.attr == "overload")
                for d in fn.decorator_list
            )
            if not public or overload:  # an @overload stub: the implementation below it carries the docstring
                continue
            where = f"{path.relative_to(ROOT)}:{fn.lineno} {name}"
            if check == "typed":
                if any(x.annotation is None for x in _args(fn)) or (fn.returns is None and fn.name != "__init__"):
                    bad.append(where)
            else:
                doc = ast.get_docstring(fn) or ""
                owner = name.rsplit(".", 2)[-2] if "." in name else ""
                if not doc and owner and _inherits_doc(owner, fn.name):
                    continue
                decorated = any(
                    (isinstance(d, ast.Name) and d.id in ("property", "cached_property"))
                    or (isinstance(d, ast.Attribute) and d.attr in ("setter", "cached_property"))
                    for d in fn.decorator_list
                )
                if not doc or (_args(fn) and not decorated and "Args:" not in doc):
                    bad.append(where)
        if check == "documented":
            for node in ast.walk(tree):
                if isinstance(node, ast.ClassDef) and not node.name.startswith("_") and not ast.get_docstring(node):
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno} class {node.name}")
    assert not bad, f"{len(bad)} public functions not {check}:\n" + "\n".join(bad)
