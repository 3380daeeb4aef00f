"""MkDocs hook: the TOML reference (docs page ``toml-reference.md``), generated from the job and study schema.

The schema is the validator itself (``jaxobs_tuning.parse_job``, ``jaxobs_tuning.study_file.parse_study``), so the
reference is
built from it at every docs build and cannot drift:

- the keys of each table are what the validator allows: a probe key is put into the table of a valid job or study
  file and the validator's one-line refusal lists the allowed keys;
- each key's type, default and constraints are read from the validator's source (the ``_get(table, key, field,
  kind, default)`` call that reads it, and the ``JobError(field, message)`` calls that refuse a value), by parsing
  every module of ``tuning/`` (wherever a refactor moves the code);
- the scenario axes (unit, range), components (gains, constructor defaults), metrics and machines are the public
  tables the validator checks against.

Run as a script, it prints the page (``python docs/hooks/toml_reference.py``).
"""

from __future__ import annotations

import ast
import copy
import importlib
import re
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PROBE = "zz_probe"
KINDS = {
    "float": "number",
    "int": "integer",
    "str": "string",
    "bool": "boolean",
    "list": "list of numbers",
    "dict": "table",
}


# --------------------------------------------------------------------------------------------------
# the validator's source: type, default and constraints of each field
# --------------------------------------------------------------------------------------------------


def _module_constants(modname: str) -> dict:
    try:
        mod = importlib.import_module(modname)
    except Exception:  # a module that cannot be imported alone: its names stay as written
        return {}
    return {k: v for k, v in vars(mod).items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


def _render(node, consts: dict) -> str:
    """An f-string or constant as text; a ``{value}`` becomes its module constant's value, else its name."""
    if isinstance(node, ast.Constant):
        return str(node.value)
    if isinstance(node, ast.JoinedStr):
        out = []
        for v in node.values:
            if isinstance(v, ast.Constant):
                out.append(str(v.value))
            else:
                expr = v.value
                if isinstance(expr, ast.Name) and expr.id in consts:
                    out.append(f"{consts[expr.id]:g}")
                elif isinstance(expr, (ast.Name, ast.Attribute)):  # a value the message fills in: its name
                    out.append("{" + ast.unparse(expr).rsplit(".", 1)[-1] + "}")
                else:
                    out.append("…")
        return "".join(out)
    return "…"  # a message computed elsewhere (another error's text)


def _pattern(field: str) -> re.Pattern | None:
    """A field as written in the source (``{where}.t_event``) as a regex over TOML paths; None when its last
    segment is not literal (it would match every key)."""
    last = field.rsplit(".", 1)[-1]
    if "{" in last or not last:
        return None
    parts = re.split(r"\{[^}]*\}", field)
    return re.compile("^" + ".+".join(re.escape(p) for p in parts) + "$")


class SourceIndex:
    """Every ``get_field(...)`` (or ``..._get(...)``) and ``JobError(...)`` call of ``tuning/``, by field pattern."""

    def __init__(self, package: Path):
        self.gets = []  # (pattern, exact, function, kind, default, required)
        self.errors = []  # (pattern, exact, function, message)
        for path in sorted(package.rglob("*.py")):
            modname = ".".join(path.relative_to(package.parent).with_suffix("").parts)
            consts = _module_constants(modname)
            tree = ast.parse(path.read_text())
            for fn in ast.walk(tree):
                if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    continue
                for node in ast.walk(fn):
                    if not isinstance(node, ast.Call):
                        continue
                    name = getattr(node.func, "id", getattr(node.func, "attr", ""))
                    if (name.endswith("_get") or name == "get_field") and len(node.args) >= 4:
                        field = _render(node.args[2], consts)
                        pat = _pattern(field)
                        if pat is None:
                            continue
                        kw = {k.arg: k.value for k in node.keywords}
                        default = node.args[4] if len(node.args) > 4 else kw.get("default")
                        required = isinstance(kw.get("required"), ast.Constant) and kw["required"].value is True
                        kind = ast.unparse(node.args[3])
                        self.gets.append(
                            (
                                modname,
                                pat,
                                "{" not in field,
                                fn.name,
                                KINDS.get(kind, kind),
                                None if default is None else ast.unparse(default),
                                required,
                            )
                        )
                    elif name.endswith("JobError") and len(node.args) >= 2:
                        field = _render(node.args[0], consts)
                        pat = _pattern(field)
                        if pat is None:
                            continue
                        msg = _render(node.args[1], consts)
                        msg = re.split(r",? got [{…]", msg)[0].strip().rstrip(",;:")
                        if len(msg.strip("…{}, ")) < 3:
                            continue  # a message that only forwards another error's text
                        self.errors.append((modname, pat, "{" not in field, fn.name, msg))

    @staticmethod
    def _best(rows, path: str, tag: str | None, study: bool):
        # job and study files share table names ([drive]): a study field is read in a study module
        hits = [r[1:] for r in rows if r[1].match(path) and ("study" in r[0]) == study]
        if not hits:  # a part both files share (a study's recordings are read by the job's parser)
            hits = [r[1:] for r in rows if r[1].match(path)]
        exact = [r for r in hits if r[1]]
        hits = exact or hits
        if tag:
            tagged = [r for r in hits if tag in r[2]]
            hits = tagged or hits
        return hits

    def field(self, path: str, tag: str | None = None, study: bool = False) -> dict:
        gets = self._best(self.gets, path, tag, study)
        errs = self._best(self.errors, path, tag, study)
        info = {"type": "", "default": "", "required": False, "checks": []}
        if gets:
            _, _, _, kind, default, required = gets[0]
            info.update(type=kind, required=required)
            if required:
                info["default"] = "required"
            elif default is None:
                info["default"] = "none (optional)"
            else:
                info["default"] = _default_text(default)
        seen = []
        for e in errs:
            if e[3] not in seen and not e[3].startswith("missing"):
                seen.append(e[3])
        info["checks"] = seen
        return info


# defaults that the validator computes, in words (an expression not listed here is shown as written)
DEFAULT_WORDS = {
    "signals[0]": "the component's (FLLs: grid; flux observers: emf; LESOs: drive)",
    "values[gname]": "the component's value (`[component]` or its default)",
    "info.machines[0]": "the component's (LESOs: ipmsm002; flux observers: spmsm000)",
    "seed": "from `job.seed`",
    "default": "see the text",
    "{}": "empty",
}


def _default_text(expr: str) -> str:
    if expr in DEFAULT_WORDS:
        return DEFAULT_WORDS[expr]
    try:
        v = ast.literal_eval(expr)
    except (ValueError, SyntaxError):
        return f"`{expr}`"
    if isinstance(v, bool):
        return f"`{str(v).lower()}`"
    if isinstance(v, str):
        return f'`"{v}"`'
    return f"`{v!r}`"


# --------------------------------------------------------------------------------------------------
# the validator's key lists: probe each table of a valid file
# --------------------------------------------------------------------------------------------------


def _dig(raw: dict, where: tuple):
    """The table at ``where``; an optional table the file leaves out is created empty."""
    node = raw
    for k in where:
        node = node.setdefault(k, {}) if isinstance(k, str) else node[k]
    return node


def allowed_keys(parse, raw: dict, where: tuple, base: Path) -> list[str]:
    """The keys the validator allows in table ``where`` of the valid file ``raw``: its refusal of a probe key."""
    bad = copy.deepcopy(raw)
    _dig(bad, where)[PROBE] = 1
    try:
        parse(bad, base=base)
    except ValueError as e:
        m = re.search(r"allowed: (.*)$", str(e))
        if m and PROBE in str(e):
            keys = [k.strip() for k in m.group(1).split(",")]
            if keys and keys[-1].endswith(("…", "...")):
                return None  # the one-line message was cut: the caller reads the keys another way
            return keys
        raise RuntimeError(f"probing {'.'.join(map(str, where)) or 'the top level'}: {e}") from None
    raise RuntimeError(f"the validator accepted an unknown key in {where}")


def _load(path: Path) -> dict:
    return tomllib.loads(path.read_text())


# Keys that the validator reads without a typed ``_get`` (lists of strings, lists of tables): what it takes,
# in words.  A key missing here still appears in the reference (the validator lists it), with its checks.
NOTES = {
    "objective.terms": ("list of tables", "required", "each `{ metric = ..., weight = ... }`: see below"),
    "recording.file": ("string or list of strings", "required", "CSV files, relative to the job or study file"),
    "recording.time_column": ("string or integer", "", "a column of seconds (name or 0-based index)"),
    "recording.columns": ("list of strings or integers", "see below", "the signal's columns (names or indices)"),
    "recording.truth": ("list of strings or integers", "see below", "the reference columns (names or indices)"),
    "envelope.speed_rpm": (
        "[lo, hi] numbers",
        "the tuning grid's span",
        "r/min, 1 <= lo <= hi <= the machine's drive speed limit (2835 on spmsm000, 1323 on ipmsm002)",
    ),
    "envelope.load_nm": ("[lo, hi] numbers", "the tuning grid's span", "N·m, 0 <= lo <= hi <= 3 × rated torque"),
}


def _note(path: str):
    for k, v in NOTES.items():
        if path.endswith(k) or path.replace("[0]", "") == k:
            return v
    return None


def _table(
    title: str,
    keys: list[str],
    prefix: str,
    index: SourceIndex,
    tag: str | None,
    intro: str = "",
    study: bool = False,
    inherit: dict | None = None,
) -> str:
    lines = [f"### `{title}`", ""]
    if intro:
        lines += [intro, ""]
    lines += ["| key | type | default | checks |", "|---|---|---|---|"]
    for key in keys:
        path = f"{prefix}.{key}" if prefix else key
        info = index.field(path, tag, study)
        note = _note(path)
        typ, default = info["type"], (inherit or {}).get(key, info["default"])
        checks = list(info["checks"])
        if note:
            typ = typ or note[0]
            default = default or note[1]
            checks.insert(0, note[2])
        cell = "; ".join(c.replace("|", "\\|") for c in checks) or ""
        lines.append(f"| `{key}` | {typ or 'table'} | {default or '—'} | {cell} |")
    return "\n".join(lines) + "\n"


def _axes_table(title: str, ranges: dict, intro: str) -> str:
    lines = [f"### `{title}`", "", intro, "", "| axis | unit | range |", "|---|---|---|"]
    from jaxobs.core.quantities import text_unit

    for name, axis in ranges.items():  # jaxobs.core.quantities.Axis records
        lo, hi = axis.range
        lines.append(f"| `{name}` | {text_unit(axis.units)} | [{lo:g}, {hi:g}] |")
    return "\n".join(lines) + "\n"


class _Names:
    """The given public names of the ``tuning`` package, each from whichever of its modules defines it."""

    def __init__(self, *names: str):
        import pkgutil

        import jaxobs_tuning

        pkgs = pkgutil.walk_packages(jaxobs_tuning.__path__, "jaxobs_tuning.")
        mods = [jaxobs_tuning] + [importlib.import_module(m.name) for m in pkgs]
        for name in names:
            found = [vars(m)[name] for m in mods if name in vars(m)]
            if not found:
                raise RuntimeError(f"the TOML reference needs tuning's {name}, which no module of tuning defines")
            setattr(self, name, found[0])


def reference_markdown() -> str:
    sys.path.insert(0, str(ROOT))
    import jaxobs_tuning
    from jaxobs.drive import SHIPPED_DRIVES  # the drive jobs' and studies' shipped drive files
    from jaxobs.metrics import ALIASES  # the old metric names a job may still give

    # the schema's public tables wherever a refactor puts them (tuning's modules are being split): each name is
    # looked up in tuning's submodules, the first that defines it wins
    job_mod = _Names("AXIS_RANGES", "RECORDING_COLUMNS")
    study_file = _Names("parse_study", "FLL_CLOSED_FORMS", "DRIVE_OBSERVERS", "FLL_COMPONENTS")

    index = SourceIndex(ROOT / "tuning")
    presets = ROOT / "tuning" / "presets"
    grid_job, drive_job, rec_job = presets / "wif_robust.toml", presets / "faleso.toml", presets / "recording_wif.toml"
    parse = jaxobs_tuning.parse_job
    g, d, r = _load(grid_job), _load(drive_job), _load(rec_job)
    gain = next(iter(g["gains"]))
    out = [
        "# TOML reference",
        "",
        "Generated from the schema when this site is built (`docs/hooks/toml_reference.py`): the keys of each",
        "table are the ones the validator allows, and each key's type, default and checks are read from the",
        "validator's source, so this page cannot drift from `jaxobs tune --check` and `jaxobs study --check`.",
        "A default written as an expression (`t_event + 0.75 * (horizon - t_event)`) is computed from the other",
        "keys; `none (optional)` means the key may be left out. Every error names the field, in one line.",
        "",
        "## Job files (`jaxobs tune JOB.toml`)",
        "",
        "Examples: `tuning/presets/*.toml` (and `jaxobs tune` with no file runs `wif_robust.toml`).",
        "",
    ]
    top = allowed_keys(parse, g, (), grid_job.parent)
    out.append(_table("top level", top, "", index, None, "The tables of a job file."))
    out.append(_table("[job]", allowed_keys(parse, g, ("job",), grid_job.parent), "job", index, None))
    comps = ", ".join(f"`{c}`" for c in jaxobs_tuning.COMPONENTS)
    comp_lines = ["| component | tunable gains | other constructor values (defaults) |", "|---|---|---|"]
    for name, info in jaxobs_tuning.COMPONENTS.items():
        gains = ", ".join(f"`{k}`" for k in info.gains)
        vals = ", ".join(f"`{k}` = {v:g}" for k, v in info.defaults.items() if isinstance(v, (int, float)))
        comp_lines.append(f"| `{name}` | {gains} | {vals} |")
    out.append(
        "### `[component]`\n\nThe constructor values of `job.component` (one of "
        + comps
        + "), numbers: any key of the component's defaults below (the gains' closed-form values included).\n\n"
        + "\n".join(comp_lines)
        + "\n"
    )
    out.append(
        _table(
            "[gains.<name>]",
            allowed_keys(parse, g, ("gains", gain), grid_job.parent),
            f"gains.{gain}",
            index,
            None,
            "One table per free gain (a tunable gain of the component).",
        )
    )
    scen_keys = allowed_keys(parse, g, ("scenarios",), grid_job.parent)
    out.append(_table("[scenarios]", scen_keys, "scenarios", index, None))
    out.append(
        _table(
            "[holdout]",
            scen_keys,
            "holdout",
            index,
            None,
            "Optional: a held-out set scored (not tuned on), with the keys of `[scenarios]`.",
            inherit={k: "`[scenarios]`' value" for k in ("signal", "t_event", "horizon", "steady_from")},
        )
    )
    for sig, intro in (
        ("grid", 'Axes of `[scenarios.grid]` for `signal = "grid"` (the FLL family): each a list of values.'),
        ("emf", 'Axes for `signal = "emf"` (flux observers on a synthetic back EMF).'),
        ("drive", 'Axes for `signal = "drive"` (an observer in the closed-loop drive).'),
    ):
        out.append(_axes_table(f"[scenarios.grid] ({sig})", job_mod.AXIS_RANGES[sig], intro))
    rec_keys = allowed_keys(parse, r, ("scenarios", "recording"), rec_job.parent)
    cols = "; ".join(
        f"`{s}`: columns {', '.join(c)}, truth {', '.join(t)}" for s, (c, t, _) in job_mod.RECORDING_COLUMNS.items()
    )
    out.append(
        _table(
            "[scenarios.recording]",
            rec_keys,
            "scenarios.recording",
            index,
            None,
            "Instead of `[scenarios.grid]`: one scenario per recorded file. Default columns by signal: " + cols + ".",
        )
    )
    out.append(
        _table(
            "[drive]",
            allowed_keys(parse, d, ("drive",), drive_job.parent),
            "drive",
            index,
            None,
            'Drive jobs only (`scenarios.signal = "drive"`). Shipped machines: '
            + ", ".join(f"`{m}`" for m in SHIPPED_DRIVES)
            + '; or a drive file (`file = "my_drive.toml"`, or its tables inline: see `jaxobs drive check`).',
        )
    )
    out.append(
        _table(
            "[envelope]",
            allowed_keys(parse, d, ("envelope",), drive_job.parent),
            "envelope",
            index,
            None,
            "Sensorless drive jobs, optional: the envelope the design claims. After tuning, initial, closed form "
            "and tuned run at 3 speeds × 2 loads of it over `horizon` s, pulsed up and down, through the drive "
            "file's `[sensors]` (`ideal_sensors = true`: ideal sensors), with the stability verdict at the same "
            "points (`verification` in result.json); a tuned design failing where the closed form holds is "
            'status `"unsafe"`, exit 4.',
        )
    )
    out.append(_table("[objective]", allowed_keys(parse, g, ("objective",), grid_job.parent), "objective", index, None))
    terms = allowed_keys(parse, g, ("objective", "terms", 0), grid_job.parent)
    out.append(
        _table(
            "[[objective.terms]]",
            terms,
            "objective.terms[0]",
            index,
            None,
            "Metrics (SI units; the table `jaxobs.metrics.METRICS`): "
            + ", ".join(f"`{m}` ({jaxobs_tuning.TERM_METRICS[m].units})" for m in jaxobs_tuning.TERM_METRICS)
            + ". Old names (`"
            + "`, `".join(ALIASES)
            + "`) are read with a warning, their weights converted.",
        )
    )
    out.append(_table("[solver]", allowed_keys(parse, g, ("solver",), grid_job.parent), "solver", index, None))

    # study files
    def study_table(*a, **k):
        return _table(*a, **k, study=True)

    sparse = study_file.parse_study
    fll_study = ROOT / "jaxobs" / "data" / "default_study.toml"
    drive_study = presets / "study_leso_drive.toml"
    rec_study = presets / "study_recording_fll.toml"
    fs, ds, rs = _load(fll_study), _load(drive_study), _load(rec_study)
    out += [
        "## Study files (`jaxobs study STUDY.toml`)",
        "",
        "Examples: `jaxobs/data/default_study.toml` (the default), `tuning/presets/study_*.toml`.",
        "",
    ]
    out.append(study_table("top level", allowed_keys(sparse, fs, (), fll_study.parent), "", index, None))
    out.append(
        study_table(
            '[study] (kind = "fll")',
            allowed_keys(sparse, fs, ("study",), fll_study.parent),
            "study",
            index,
            "fll",
            "An FLL study (the default kind).",
        )
    )
    out.append(
        study_table(
            '[study] (kind = "drive")',
            allowed_keys(sparse, ds, ("study",), drive_study.parent),
            "study",
            index,
            "drive",
            "A sensorless-drive study. Machines: " + ", ".join(f"`{m}`" for m in SHIPPED_DRIVES) + ".",
        )
    )
    out.append(
        study_table(
            "[study.recording]",
            allowed_keys(sparse, rs, ("study", "recording"), rec_study.parent),
            "study.recording",
            index,
            None,
            "FLL studies on recordings instead of `[axes]`: the keys of a job's `[scenarios.recording]`.",
        )
    )
    out.append(
        study_table(
            "[drive] (study)",
            allowed_keys(sparse, ds, ("drive",), drive_study.parent),
            "drive",
            index,
            "drive",
            "Drive studies only.",
        )
    )
    out.append(
        "### `[designs.<name>]`\n\nOne table per design, with exactly one of `closed_form` (FLL studies: "
        + ", ".join(f"`{k}`" for k in study_file.FLL_CLOSED_FORMS)
        + "; drive studies: "
        + ", ".join(f"`{k}`" for k in study_file.DRIVE_OBSERVERS)
        + "), `result` (a tuning run's `result.json`, relative to the study file) or `component` (FLL studies: "
        + ", ".join(f"`{k}`" for k in study_file.FLL_COMPONENTS)
        + "; drive studies: the drive observers) with that constructor's values as keys.\n"
    )
    import inspect

    import jaxobs

    rows = ["| kind | component | keys (defaults) |", "|---|---|---|"]
    for kind, comps, raw, base in (
        ("fll", study_file.FLL_COMPONENTS, fs, fll_study.parent),
        ("drive", study_file.DRIVE_OBSERVERS, ds, drive_study.parent),
    ):
        for comp in comps:
            params = inspect.signature(getattr(jaxobs, comp)).parameters
            probe = copy.deepcopy(raw)
            probe["designs"] = {"d": {"component": comp}}
            keys = allowed_keys(sparse, probe, ("designs", "d"), base) or ["component", *params]
            cells = []
            for k in keys:
                if k in ("component", "rule"):
                    continue
                d = params[k].default if k in params else inspect.Parameter.empty
                if d is inspect.Parameter.empty:
                    cells.append(f"`{k}`")
                else:
                    cells.append(f"`{k}` ({d:g})" if isinstance(d, float) else f"`{k}` ({d})")
            rows.append(f"| {kind} | `{comp}` | {', '.join(cells)} |")
    out.append(
        "Keys of a `component` design, besides `component` (numbers unless the default says otherwise):\n\n"
        + "\n".join(rows)
        + "\n"
    )
    from jaxobs.scenarios.families import DriveScenarios, GridSignals

    out.append(_axes_table('[axes] (kind = "fll")', GridSignals.axes, "Each a list of values."))
    out.append(_axes_table('[axes] (kind = "drive")', DriveScenarios.axes, "Each a list of values."))
    return "\n".join(out)


def on_files(files, config):
    """Add the generated page (mkdocs ≥ 1.6: ``File.generated``)."""
    from mkdocs.structure.files import File

    files.append(File.generated(config, "toml-reference.md", content=reference_markdown()))
    return files


if __name__ == "__main__":
    print(reference_markdown())
