"""The papers' commands: ``jaxobs demo``, ``closed-form``, ``bode`` and ``reproduce``."""

from __future__ import annotations

import argparse
import inspect
import json
import re
from pathlib import Path

from jaxobs.reproduce.figures import FLUX_FIGURES, LESO_FIGURES
from jaxobs.studies.registry import REGISTRY

from .cli_common import CommandOut, enable_x64, progress_of
from .outdir import atomic_path

# the files each command writes under --out (refused there without --force; jaxobs.plot names them)
DEMO_FILES = ("fll_tests_A_E.png",) + tuple(f"fll_test_{t}.png" for t in "ABCDE123")  # 001's layout, one a test


BODE_FILES = ("bode_flux_observers_000_fig5.png", "bode_lesos_002_fig4.png", "bode_fll_open_loop_001_fig14.png")


REPRODUCE_FILES = {
    "flux": (
        "flux_circles_du_alpha_5V.png",
        "flux_circles_400rpm.png",
        "position_error_load_step.png",
        "position_error_speed_variation.png",
        "position_error_du_alpha_5V.png",
        # 000 Figs 12-23 in the paper's layout (jaxobs.reproduce.figures; --quick skips 20 r/min and the I-f start)
        *(spec[1] for spec in FLUX_FIGURES),
    ),
    "leso": (
        "leso_position_error_600rpm.png",
        "leso_speed_ramp.png",
        "leso_load_step.png",
        # 002 Figs 16-17 (a)-(b): the C- and GI-LESO closing the loop; Sec. V-B's half-load C-LESO test
        "leso_speed_ramp_cleso_closing.png",
        "leso_speed_ramp_gileso_closing.png",
        "leso_load_step_cleso_closing.png",
        "leso_load_step_gileso_closing.png",
        "leso_half_load_600rpm_cleso_closing.png",
        # 002 Fig. 18: the observer's R̂s, then L̂q, ramped by ±0.5 p.u. at rated load
        "leso_fig18_rs_ramp.png",
        "leso_fig18_lq_ramp.png",
        # 002 Figs 16-17 in the paper's layout (jaxobs.reproduce.figures)
        *(spec[1] for spec in LESO_FIGURES),
    ),
}
# ``reproduce leso`` (``--machine dual``, its default) adds these: jaxobs.reproduce.leso_dual's DUAL_EXPERIMENTS and
# then DUAL_DYNAMICS, in their order
REPRODUCE_DUAL_FILES = (
    "leso_dual_individual_300rpm.png",
    "leso_dual_individual_600rpm.png",
    "leso_dual_vsd_600rpm.png",
    "leso_dual_speed_ramp.png",
    "leso_dual_speed_ramp_cleso_closing.png",
    "leso_dual_speed_ramp_gileso_closing.png",
    "leso_dual_load_step.png",
    "leso_dual_load_step_cleso_closing.png",
    "leso_dual_load_step_gileso_closing.png",
    "leso_dual_speed_ramp_330V.png",
)
# and the 330 V ramp in 002's Fig. 16 layout (speed, i_d under its reference, the FA-LESO's error)
REPRODUCE_DUAL_LAYOUT_FILES = ("leso_dual_fig16_speed_ramp_330V_layout.png",)


def cmd_demo(args: argparse.Namespace) -> int:
    """``jaxobs demo``: the FLL family on paper 001's Tests A-E, a table and its figure.

    Args:
        args: The parsed command line.

    Returns:
        0, or 1 when a test failed.

    Raises:
        ValueError: Bad input (one line, exit 2).
    """
    enable_x64()
    from jaxobs.plot import fll_demo_figure
    from jaxobs.reproduce.figures import fll_figure
    from jaxobs.studies.demo import DEMO_TESTS, fll_demo, format_table

    if args.t_event <= 0:
        raise ValueError(f"--t-event must be > 0 s, got {args.t_event}")
    with CommandOut(args, DEMO_FILES) as out:
        rows, traces = fll_demo(t_event=args.t_event, progress=progress_of(args))
        fig_path = out / DEMO_FILES[0]
        with atomic_path(fig_path) as tmp:
            fll_demo_figure(traces, DEMO_TESTS, args.t_event, tmp)
        # each test in paper 001's layout (Tests A-E of Sec. VI, and Sec. V's Tests 1-3 run for their figures)
        _, traces_123 = fll_demo(t_event=args.t_event, progress=progress_of(args), tests=("1", "2", "3"))
        for tests, tr in ((DEMO_TESTS, traces), (("1", "2", "3"), traces_123)):
            for i, test in enumerate(tests):
                with atomic_path(out / f"fll_test_{test}.png") as tmp:
                    fll_figure(tr, i, test, args.t_event, tmp)
    if args.json:
        print(json.dumps(rows, indent=1))
    else:
        print("Paper 001 FLLs with Table I gains on Tests A–E (float64, AB3 at 10 kHz)")
        print(format_table(rows))
        # every figure written, not only the overview: a user looks for the per-test ones too
        print(f"figures: {fig_path}, and one per test in paper 001's layout: {', '.join(DEMO_FILES[1:])}")
    return 0 if all(r["ok"] for r in rows) else 1


# The closed forms `jaxobs closed-form` offers: every registered observer, by its aliases (jaxobs.studies.registry);
# # each class's closed_form_design is its rule, its keyword arguments (less the constructor's **kw) its inputs, and its
# rows carry their own formulas and sources, printed here as they are.
CF_DESIGNS = {a: e.cls for e in REGISTRY.values() for a in e.aliases}


def _inputs(cls) -> tuple:
    """The inputs of a class's closed form: ``closed_form_design``'s named parameters (its ``ClosedForm.inputs``)."""
    params = inspect.signature(cls.closed_form_design).parameters.values()
    return tuple(p.name for p in params if p.kind is inspect.Parameter.KEYWORD_ONLY or p.default is not p.empty)


def cf_flag(name: str) -> str:
    """The command-line flag of a closed-form input: ``Rs`` -> ``--rs``, ``omega_n`` -> ``--omega-n``.

    Args:
        name: The input's name (a keyword of the class's ``closed_form_design``).

    Returns:
        The flag.
    """
    return "--" + name.lower().replace("_", "-")


# alias -> the closed form's inputs (one flag each; a flag names the same input of every design that has it)
CF_OPTIONS = {a: _inputs(cls) for a, cls in CF_DESIGNS.items()}


def cf_flags() -> dict:
    """Every closed-form input's flag, with the designs that take it: flag -> (dest, help)."""
    out: dict = {}
    for alias, names in CF_OPTIONS.items():
        for n in names:
            dest = n.lower()
            out.setdefault(cf_flag(n), [dest, []])[1].append(alias)
    return {f: (d, f"closed-form input of {', '.join(a)} (default: the paper's)") for f, (d, a) in out.items()}


def closed_form_rows(design: str, values: dict) -> dict:
    """A closed-form design's inputs and rows (name, value, units, formula, source), as the class's
    ``closed_form_design`` gives them: the defaults are the papers' (:mod:`jaxobs.papers`).

    Args:
        design: An alias of :data:`CF_DESIGNS` (``"wif"``, ``"soifo"``, ``"cleso"``, ...).
        values: Inputs by their flag's name (``rs``, ``omega_n``); each must be an input of the design.

    Returns:
        ``{"design", "source", "inputs", "gains": [{"name", "value", "units", "formula", "source"}, ...]}``.

    Raises:
        ValueError: an unknown design, an input it does not take, or a value out of its range.
    """
    if design not in CF_DESIGNS:
        raise ValueError(f"design must be one of {', '.join(CF_DESIGNS)}, got {design!r}")
    by_flag = {n.lower(): n for n in CF_OPTIONS[design]}
    for k in values:
        if k not in by_flag:
            allowed = ", ".join(cf_flag(o) for o in CF_OPTIONS[design])
            raise ValueError(f"{cf_flag(k)} does not apply to {design} (allowed: {allowed})")
    cf = CF_DESIGNS[design].closed_form_design(**{by_flag[k]: v for k, v in values.items()})
    given = {by_flag[k] for k in values}  # a gain given as an input is not the paper's choice: its formula is "given"
    return {
        "design": design,
        "source": cf.source,
        "inputs": {k: float(v) for k, v in cf.inputs.items()},
        "gains": [
            dict(
                name=r.name,
                value=float(r.value),
                units=r.units,
                formula=f"given ({cf_flag(r.name)})" if r.name in given else r.formula,
                source=r.source,
            )
            for r in cf.rows
        ],
    }


def cmd_closed_form(args: argparse.Namespace) -> int:
    """``jaxobs closed-form``: a design rule's closed-form gains with their formulas and sources.

    Args:
        args: The parsed command line.

    Returns:
        0.

    Raises:
        ValueError: Bad input (one line, exit 2).
    """
    enable_x64()
    values = {}
    for flag, (dest, _) in cf_flags().items():
        v = getattr(args, dest, None)
        if v is None:
            continue
        if dest not in {n.lower() for n in CF_OPTIONS[args.design]}:
            allowed = ", ".join(cf_flag(o) for o in CF_OPTIONS[args.design])
            raise ValueError(f"{flag} does not apply to {args.design} (allowed: {allowed})")
        values[dest] = v
    try:
        res = closed_form_rows(args.design, values)
    except ValueError as e:  # name the flag the user typed (SOGIFLLWIF.closed_form.b -> --b), not the argument
        raise ValueError(re.sub(r"\b\w+\.closed_form\.(\w+)", lambda m: cf_flag(m[1]), str(e))) from None
    if args.json:
        print(json.dumps(res, indent=1))
    else:
        ins = ", ".join(f"{k} = {v:.6g}" for k, v in res["inputs"].items())
        print(f"{args.design} ({res['source']}): {ins}")
        for g in res["gains"]:
            print(f"  {g['name']:<18}{g['value']:>14.6g} {g['units']:<10}{g['formula']:<52}{g['source']}")
    return 0


def cmd_bode(args: argparse.Namespace) -> int:
    """``jaxobs bode``: the Bode figures of the papers' observers and loops.

    Args:
        args: The parsed command line.

    Returns:
        0.
    """
    enable_x64()
    from jaxobs.plot import paper_bode_figures

    with CommandOut(args, BODE_FILES) as out:
        figs = paper_bode_figures(out, hz=not args.rad_per_s)
    for p in figs:
        print(p)
    return 0


def _emit_rows(rows, figs, as_json: bool, title: str) -> int:
    """Print paper-vs-ours rows (table or JSON); non-zero exit if any simulation diverged."""
    from jaxobs.reproduce.flux import format_rows

    if as_json:
        print(json.dumps(rows, indent=1))
    else:
        print(title)
        print(format_rows(rows))
        for p in figs:
            print(f"figure: {p}")
    return 0 if all(r["ours"] for r in rows if r["metric"] == "finite") else 1


def _error_figures(traces, names, paper: str, specs, out: Path):
    """One position-error figure per (experiment, file name, start time) in ``specs``."""
    from jaxobs.plot import position_error_figure

    paths = []
    for key, fname, t_from in specs:
        p = out / fname
        position_error_figure(traces[key], names, f"Paper {paper}: {key}", p, t_from=t_from)
        paths.append(p)
    return paths


def reproduce_files(args: argparse.Namespace) -> tuple[str, ...]:
    """The figures ``reproduce`` writes; settles ``args.machine`` (None: "dual" for leso, "single" for flux).

    Args:
        args: The parsed command line (``paper``, ``machine``).

    Returns:
        The figures' file names.

    Raises:
        ValueError: An unknown paper, or the dual machine asked of paper 000.
    """
    if args.paper not in REPRODUCE_FILES:
        raise ValueError(f"reproduce: unknown paper {args.paper!r}")
    if args.machine is None:  # 002's machine is the dual three-phase IPMSM: its rows come by default
        args.machine = "dual" if args.paper == "leso" else "single"
    if args.machine != "single" and args.paper != "leso":
        raise ValueError(f"reproduce {args.paper}: --machine must be 'single' (the dual machine is paper 002's)")
    dual = REPRODUCE_DUAL_FILES + REPRODUCE_DUAL_LAYOUT_FILES
    return REPRODUCE_FILES[args.paper] + (dual if args.machine == "dual" else ())


def cmd_reproduce(args: argparse.Namespace) -> int:
    """``jaxobs reproduce``: a paper's experiments on the simulated drive, with its figures.

    Args:
        args: The parsed command line.

    Returns:
        0, or 1 when a simulation diverged.

    Raises:
        ValueError: Bad input (one line, exit 2).
    """
    enable_x64()
    files = reproduce_files(args)
    args.out = args.out or f"out/reproduce-{args.paper}"
    with CommandOut(args, files) as out:
        return _reproduce(args, out)


def _reproduce(args, out: Path) -> int:
    if args.paper == "flux":
        from jaxobs import drive as D
        from jaxobs.plot import flux_circles_figure
        from jaxobs.reproduce.flux import OBSERVER_NAMES, run_flux_experiments

        rows, traces = run_flux_experiments(quick=args.quick, progress=progress_of(args))
        figs = []
        files = REPRODUCE_FILES["flux"]
        for key, fname in zip(("du_alpha = 5 V at 1000 r/min", "steady 400 r/min"), files[:2], strict=True):
            p = out / fname
            flux_circles_figure(traces[key], OBSERVER_NAMES, f"Paper 000: estimated flux, {key}", p)
            figs.append(p)
        figs += _error_figures(
            traces,
            OBSERVER_NAMES,
            "000",
            zip(
                ("load step 10 N·m at 2000 r/min", "speed 400-2000-400 r/min", "du_alpha = 5 V at 1000 r/min"),
                files[2:5],
                (0.3, 0.8, 0.8),
                strict=True,
            ),
            out,
        )
        from jaxobs.reproduce.figures import flux_figures

        par = D.bench_machine("spmsm000")
        figs += flux_figures(traces, OBSERVER_NAMES, par.p, float(par.psi_f), out)
        return _emit_rows(
            rows,
            figs,
            args.json,
            "Paper 000 (second-order SOIFO) experiments on the simulated SPMSM drive — paper vs ours",
        )
    if args.paper == "leso":
        from jaxobs.reproduce.leso import FIG18_NAMES, LESO_NAMES, run_leso_experiments

        rows, traces = run_leso_experiments(progress=progress_of(args))
        if args.machine == "dual":  # 002's dual three-phase machine, beside the single one
            from jaxobs.reproduce.leso_dual import run_leso_dual

            rows_dual, traces_dual = run_leso_dual(progress=progress_of(args))
            rows, traces = rows + rows_dual, {**traces, **traces_dual}
        figs = _error_figures(
            traces,
            LESO_NAMES,
            "002",
            zip(
                (
                    "steady 600 r/min no load",
                    "speed ramp 300-600-840-600-300 r/min",
                    "load step 0-80 % at 600 r/min",
                    "speed ramp 300-600-840-600-300 r/min, C-LESO closing the loop",
                    "speed ramp 300-600-840-600-300 r/min, GI-LESO closing the loop",
                    "load step 0-80 % at 600 r/min, C-LESO closing the loop",
                    "load step 0-80 % at 600 r/min, GI-LESO closing the loop",
                    "half load 600 r/min, C-LESO closing the loop",
                    *FIG18_NAMES.values(),
                ),
                REPRODUCE_FILES["leso"][: -len(LESO_FIGURES)],
                (0.4,) * 8 + (0.0,) * 2,
                strict=True,
            ),
            out,
        )
        from jaxobs import drive as D
        from jaxobs.reproduce.figures import drive_figure

        p = D.bench_machine("ipmsm002").p
        for key, fname, fig, methods, kind, window in LESO_FIGURES:
            title = f"Paper 002 {fig} (ours): {key}, the FA-LESO closing the loop"
            figs.append(out / fname)
            drive_figure(traces[key], LESO_NAMES, methods, kind, window, title, p, path=figs[-1])
        if args.machine == "dual":
            from jaxobs.reproduce.leso_dual import DUAL_DYNAMICS, DUAL_EXPERIMENTS

            keys = [e[0] for e in DUAL_EXPERIMENTS] + list(DUAL_DYNAMICS)
            specs = zip(keys, REPRODUCE_DUAL_FILES, (0.4,) * len(keys), strict=True)
            figs += _error_figures(traces, LESO_NAMES, "002, dual three-phase", specs, out)
            from jaxobs.reproduce.leso_dual import DUAL_RAMP_FW

            figs.append(out / REPRODUCE_DUAL_LAYOUT_FILES[0])
            title = f"Paper 002 Fig. 16 (ours): {DUAL_RAMP_FW}, the FA-LESO closing the loop"
            drive_figure(
                traces[DUAL_RAMP_FW], LESO_NAMES, ("FA-LESO",), "weakening", (0.4, None), title, p, path=figs[-1]
            )
        return _emit_rows(
            rows, figs, args.json, "Paper 002 (LESOs) experiments on the simulated IPMSM drive — paper vs ours"
        )
    raise ValueError(f"reproduce: unknown paper {args.paper!r}")
