"""The command line's registry (one module per verb): every verb module of
`robot_calib.cli` is registered once, in the order `robot-calib --help` lists the verbs,
and has the verb interface (NAME, HELP, ROBOT, add_arguments, main)."""

from __future__ import annotations

import argparse
import pkgutil

import robot_calib.cli
from robot_calib.cli.registry import VERBS, build_parser

NOT_VERBS = {"registry", "options", "common", "flags"}  # the package's own helpers


def test_every_verb_module_is_registered_once_in_help_order() -> None:
    modules = {m.name for m in pkgutil.iter_modules(robot_calib.cli.__path__)} - NOT_VERBS
    assert sorted(v.__name__.rpartition(".")[2] for v in VERBS) == sorted(modules)
    parser = build_parser()
    verbs = parser._subparsers._group_actions[0].choices  # noqa: SLF001 - argparse internals
    assert list(verbs) == [v.NAME for v in VERBS]
    assert len(set(verbs)) == len(VERBS) == 12


def test_each_verb_has_the_interface_and_runs_its_own_main() -> None:
    parser = build_parser()
    verbs = parser._subparsers._group_actions[0].choices  # noqa: SLF001 - argparse internals
    for verb in VERBS:
        assert isinstance(verb.HELP, str) and verb.HELP, verb.NAME
        assert verb.ROBOT is None or isinstance(verb.ROBOT, str), verb.NAME
        assert callable(verb.add_arguments) and callable(verb.main), verb.NAME
        sub: argparse.ArgumentParser = verbs[verb.NAME]
        assert sub.get_default("func") is verb.main
        assert sub.description == verb.HELP
        # every verb has the robot options, first
        assert [a.dest for a in sub._actions[1:4]] == ["robot", "base_link", "tip_link"]  # noqa: SLF001


def test_a_parser_built_for_one_verb_gives_that_verb_the_same_options() -> None:
    """`main` builds only the named verb's options (the others' imports are not paid): that
    verb's sub-parser is the full parser's, the others carry their name and help only."""
    full = build_parser()._subparsers._group_actions[0].choices  # noqa: SLF001
    for verb in VERBS:
        alone = build_parser(verb.NAME)._subparsers._group_actions[0].choices  # noqa: SLF001
        assert list(alone) == list(full)
        for name, sub in alone.items():
            actions = [(a.dest, tuple(a.option_strings), a.default, a.nargs) for a in sub._actions]  # noqa: SLF001
            if name == verb.NAME:
                assert actions == [
                    (a.dest, tuple(a.option_strings), a.default, a.nargs)
                    for a in full[name]._actions
                ]  # noqa: SLF001
                assert len(actions) > 4
            else:
                assert [dest for dest, *_ in actions] == ["help"]
                assert sub.get_default("func") is full[name].get_default("func")
