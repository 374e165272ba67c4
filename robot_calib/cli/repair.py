"""`robot-calib repair`: every complete message of a crashed (or intact) recording copied
into a new, indexed bag (robot_calib/bag/repair.py)."""

from __future__ import annotations

import argparse
from pathlib import Path

from robot_calib.cli.options import add_force, add_output

NAME = "repair"
HELP = "recover the messages of a crashed recording -> a new bag"
ROBOT = None  # --robot's default: DEFAULT_ROBOT


def add_arguments(rep: argparse.ArgumentParser) -> None:
    rep.add_argument("bag", metavar="BAG", help="bag whose writer was killed (.mcap)")
    add_output(rep, "new bag to write (FIXED.mcap)")
    add_force(rep)


def main(args: argparse.Namespace) -> int:
    """Copy every complete message of a crashed (or intact) bag into a new, indexed bag."""
    from robot_calib.bag.repair import repair_bag

    print(repair_bag(Path(args.bag), Path(args.output), args.force).summary())
    return 0
