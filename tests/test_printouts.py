"""What a user reads: each subcommand's ``--help`` says what it does, and printed margins are numbers."""

import argparse
import re

import jax.numpy as jnp


def _subparsers(parser: argparse.ArgumentParser, prefix: str = "jaxobs"):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield f"{prefix} {name}", sub
                yield from _subparsers(sub, f"{prefix} {name}")


def test_every_subcommand_help_opens_with_a_description():
    from jaxobs_tuning.cli import build_parser

    subs = list(_subparsers(build_parser()))
    assert len(subs) >= 10  # tune, demo, closed-form, bode, reproduce, study, export, envelope, drive, drive check
    for name, sub in subs:
        assert sub.description, f"{name} --help has no description"
        text = sub.format_help()
        assert sub.description.split()[0] in text, name


def test_margins_print_as_numbers():
    from jaxobs import linear

    m = linear.margins(linear.TransferFunction(jnp.array([10.0]), jnp.array([1.0, 2.0, 1.0, 0.0])))
    for text in (str(m), repr(m)):
        assert not re.search(r"f(32|64)\[", text), text
        assert re.fullmatch(
            r"Margins\(gain_margin=[-\d.e+]+, phase_margin=[-\d.e+]+ deg, omega_gc=[\d.e+]+ rad/s, "
            r"omega_pc=[\d.e+]+ rad/s\)",
            text,
        ), text
    assert f"gain_margin={float(m.gain_margin):.6g}," in str(m)
