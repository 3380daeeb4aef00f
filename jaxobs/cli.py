"""The ``jaxobs`` command line.

    jaxobs demo [--out DIR] [--json]     the FLL family on paper 001 Tests A–E

Errors in the arguments end the program with one line on stderr and exit
status 2; nothing prints a traceback for bad input.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _enable_x64():
    import jax

    jax.config.update("jax_enable_x64", True)


def _cmd_demo(args) -> int:
    _enable_x64()
    from .demo import DEMO_TESTS, fll_demo, format_table
    from .plot import fll_demo_figure

    if args.t_event <= 0:
        raise ValueError(f"--t-event must be > 0 s, got {args.t_event}")
    rows, traces = fll_demo(t_event=args.t_event)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fig_path = out / "fll_tests_A_E.png"
    fll_demo_figure(traces, DEMO_TESTS, args.t_event, fig_path)
    if args.json:
        print(json.dumps(rows, indent=1))
    else:
        print("Paper 001 FLLs with Table I gains on Tests A–E (float64, AB3 at 10 kHz)")
        print(format_table(rows))
        print(f"figure: {fig_path}")
    return 0 if all(r["ok"] for r in rows) else 1


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2, no usage dump
        self.exit(2, f"jaxobs: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="jaxobs", description="Differentiable simulation and tuning of motor-drive observers and FLLs.")
    sub = p.add_subparsers(dest="cmd", required=True, parser_class=_Parser)
    d = sub.add_parser("demo", help="FLL family (SOGI-FLL, -WPF, -WIF) on paper 001 Tests A-E")
    d.add_argument("--out", default="out", help="folder for the figure (default: out)")
    d.add_argument("--json", action="store_true", help="print the table as JSON rows")
    d.add_argument("--t-event", type=float, default=0.2, help="time of the test event, s (default 0.2)")
    d.set_defaults(func=_cmd_demo)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ValueError as e:
        print(f"jaxobs: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
