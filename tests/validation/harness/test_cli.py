"""The validation's command line: ``harvester validate`` comes from the validation package
through the ``fpe_harvester.commands`` entry points, and ``python -m validation`` is the same."""

from __future__ import annotations

import argparse

import validation.harness.cli as vcli
from fpe_harvester.cli import COMMAND_GROUP, build_parser, command_plugins


def test_validate_is_an_entry_point_of_the_validation():
    (ep,) = [ep for ep in command_plugins() if ep.name == "validate"]
    assert ep.group == COMMAND_GROUP and ep.load() is vcli.register


def test_harvester_validate_runs_the_validation_handler():
    args = build_parser().parse_args(["validate", "--quick", "--out", "d", "--seed", "5"])
    assert args.handler is vcli.run and (args.quick, args.out, args.seed) == (True, "d", 5)


def test_both_command_lines_take_the_same_options():
    def options(p: argparse.ArgumentParser) -> set[str]:
        return {s for a in p._actions for s in a.option_strings}

    sub = build_parser()._subparsers._group_actions[0].choices["validate"]
    assert options(sub) == options(vcli.build_parser())
