"""The verbs of `robot-calib`, in the order `robot-calib --help` lists them, and the parser
built from them. A verb is one module of this package (ros2cli's verb extensions): NAME,
HELP (one line, in the verb list and as its description), ROBOT (what --robot defaults to,
in words; None: the default robot), `add_arguments(parser)` and `main(args) -> int`.
Adding a verb is one new module and one line in VERBS."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from types import ModuleType

from robot_calib.cli import (
    calibrate,
    compensate,
    diagnose,
    export,
    import_csv,
    plan,
    predict,
    repair,
    run,
    score,
    simulate,
    split,
)
from robot_calib.cli.options import (
    OVERWRITE_POLICY,
    OneLineParser,
    RequiredHelpFormatter,
    add_robot,
)

VERBS: tuple[ModuleType, ...] = (
    simulate,
    plan,
    calibrate,
    diagnose,
    import_csv,
    predict,
    compensate,
    split,
    score,
    export,
    repair,
    run,
)

VERB_NAMES = frozenset(module.NAME for module in VERBS)


def build_parser(verb: str | None = None) -> argparse.ArgumentParser:
    """`robot-calib`'s parser: --version and one sub-parser per verb of VERBS, each with the
    robot options, its own arguments and `func`, the verb's `main`. With `verb` (a NAME of
    VERBS) only that verb gets its options and arguments, the others their name and help:
    a command line of that verb parses the same, and the other verbs' `add_arguments`
    (their imports: 0.04 s of every run) are not paid."""
    parser = OneLineParser(
        prog="robot-calib",
        description="Calibrate 6-axis robots from laser-tracker measurements and diagnose "
        "why the real robot still differs from the model. Start with `robot-calib run`; "
        "units on disk are SI (m, rad), reports add mm/deg. Bad input: one line, exit 2.",
        epilog=OVERWRITE_POLICY,
    )
    from robot_calib import __version__

    parser.add_argument("--version", action="version", version=f"robot-calib {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for module in VERBS:
        p = sub.add_parser(
            module.NAME,
            help=module.HELP,
            description=module.HELP,
            epilog=getattr(module, "FILES", OVERWRITE_POLICY),  # a verb's own policy
            formatter_class=RequiredHelpFormatter,
        )
        if verb in (None, module.NAME):
            add_robot(p, module.ROBOT)
            module.add_arguments(p)
        main: Callable[[argparse.Namespace], int] = module.main
        p.set_defaults(func=main)
    return parser
