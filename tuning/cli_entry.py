"""The ``jaxobs`` console script's entry: ``jaxobs``, ``jaxobs --help`` and ``jaxobs --version`` answered at once,
without importing JAX; ``jaxobs drive ...`` run by a parser of that command alone (:mod:`jaxobs_tuning.cli_run`:
the full parser imports every command's module, the tuning jobs' solvers among them, which a drive file's check
never uses); every other command handed to :func:`jaxobs_tuning.cli.main`.

The list of commands (:data:`COMMANDS`) is the full parser's (:func:`jaxobs_tuning.cli.build_parser`), word for
word: ``tests/test_cli.py`` compares the two help texts.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from importlib.metadata import PackageNotFoundError, version

DESCRIPTION = "Differentiable simulation and tuning of motor-drive observers and FLLs."

# command -> its line in `jaxobs --help` (each command's parser gives the same help=)
COMMANDS = {
    "tune": "gradient-based gain tuning from a TOML job (default: embedded WIF job)",
    "demo": "FLL family (SOGI-FLL, -WPF, -WIF) on paper 001 Tests A-E",
    "closed-form": "closed-form gains with formula and source equation",
    "bode": "Bode figures of the papers' flux observers, LESOs and FLL loops",
    "reproduce": "reproduce a paper's experiments on the simulated drive",
    "study": "robustness study of FLL or sensorless-drive designs over a scenario grid (xarray/NetCDF)",
    "export": "an observer as C99 float32 with golden vectors and a test harness",
    "envelope": "where a drive job's designs hold: stability and synchronism over speed x load",
    "drive": "drive files: check one and print what follows from it",
    "log": "a drive log read as declared: what was understood, and its warnings",
}


def jaxobs_version() -> str:
    """The installed jaxobs's version (as ``jaxobs.__version__`` reads it), without importing jaxobs.

    Returns:
        The version, or ``"0+unknown"`` outside an installation.
    """
    try:
        return version("jaxobs")
    except PackageNotFoundError:
        return "0+unknown"


def top_parser() -> argparse.ArgumentParser:
    """The top level of the ``jaxobs`` parser: its description, ``--version`` and the commands' one-line helps (no
    command's own options: those are :func:`jaxobs_tuning.cli.build_parser`'s).

    Returns:
        The parser.
    """
    p = argparse.ArgumentParser(prog="jaxobs", description=DESCRIPTION)
    p.add_argument("--version", action="version", version=f"jaxobs {jaxobs_version()}")
    sub = p.add_subparsers(dest="cmd", metavar="COMMAND")
    for name, text in COMMANDS.items():
        sub.add_parser(name, help=text)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line: the top level's help and version here, ``drive`` by its own parser, every other command
    by :func:`jaxobs_tuning.cli.main`.

    Args:
        argv: The arguments (default ``sys.argv[1:]``).

    Returns:
        The exit status.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if not args:  # `jaxobs` alone: the commands, on stderr, exit 2 (as the full parser does)
        top_parser().print_help(sys.stderr)
        return 2
    if args[0] in ("-h", "--help", "--version"):
        try:
            top_parser().parse_args(args[:1])
        except SystemExit as e:  # argparse's own exit after printing the help or the version
            return int(e.code or 0)
    if args[0] == "drive":  # a drive file's check: its own parser, none of the tuning commands' modules
        from .cli_drive import add_drive_parser
        from .cli_run import Parser, quiet_parent, run_parser

        p = Parser(prog="jaxobs", description=DESCRIPTION)
        sub = p.add_subparsers(dest="cmd", parser_class=Parser, metavar="COMMAND")
        add_drive_parser(sub, parents=[quiet_parent()])
        return run_parser(p, args)
    from .cli import main as run  # the commands: JAX and the library, imported only now

    return run(args)
