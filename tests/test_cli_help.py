"""Every option of every command has help text that states its default (issue #16)."""

from __future__ import annotations

import argparse

import pytest

from fault_tolerance.cli import build_parser
from fault_tolerance.resolution.mda import MDA_GAIN


def options(parser, path=()):
    """(command path, action) of every option, sub-commands included."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from options(sub, (*path, name))
        elif action.option_strings and not isinstance(
            action, (argparse._HelpAction, argparse._VersionAction)
        ):
            yield " ".join(path), action


def test_every_option_has_help_stating_its_default():
    """Walking the parser tree: no option without help, none whose help omits its default (a
    required option says it is required instead)."""
    found = list(options(build_parser()))
    assert len(found) > 50
    missing = [(cmd, a.option_strings[-1]) for cmd, a in found if not a.help]
    silent = [
        (cmd, a.option_strings[-1])
        for cmd, a in found
        if "default" not in a.help.lower() and not (a.required and "(required)" in a.help)
    ]
    assert missing == [] and silent == [], (missing, silent)


@pytest.mark.parametrize(
    ("command", "option", "number"),
    [
        ("simulate", "--gain", f"{MDA_GAIN:g}"),
        ("lock", "--gain", f"{MDA_GAIN:g}"),
        ("simulate", "--feedback", "0 for simulate"),
        ("lock", "--feedback", "10 for lock"),
        ("simulate", "--dt", "0.001"),
        ("lock", "--tau", "0.05"),
        ("lock", "--at", "default: max"),
        ("lock", "--algorithm", "default: lnva"),
    ],
)
def test_the_issue_options_state_their_default_value(command, option, number):
    """--gain, --feedback, --dt, --tau, --at and --algorithm give the default's value."""
    helps = {(c, a.option_strings[-1]): a.help for c, a in options(build_parser())}
    assert number in helps[(command, option)], helps[(command, option)]
