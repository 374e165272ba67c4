"""`robot-calib score`: a calibration scored on bags it was not fitted on (absolute and
seed criterion; robot_calib/identify/score.py)."""

from __future__ import annotations

import argparse
import sys

from robot_calib.cli.common import calibration_of, log
from robot_calib.cli.options import (
    CALIBRATION_ROBOT,
    add_force,
    add_joint_names,
    add_pair_tolerance,
)
from robot_calib.kinematics.description import with_joint_names

NAME = "score"
HELP = "score a calibration on bags it was not fitted on"
ROBOT = CALIBRATION_ROBOT  # --robot's default, in words


def add_arguments(sco: argparse.ArgumentParser) -> None:
    sco.add_argument("params", metavar="PARAMS.json")
    sco.add_argument("bags", nargs="+", metavar="BAG", help="bag(s) to score on (.mcap)")
    sco.add_argument(
        "--points-csv", help="also write a per-point table (CSV, m; default: not written)"
    )
    add_joint_names(sco)
    add_pair_tolerance(sco)
    add_force(sco)


def main(args: argparse.Namespace) -> int:
    """A calibration scored on bags it was not fitted on (absolute and seed criterion)."""
    from robot_calib.atomic import output_path
    from robot_calib.flows.bags import read_bags
    from robot_calib.identify.score import write_points_table

    cal = calibration_of(args)
    if cal.implausible:  # scored all the same: that is inspecting it
        log(
            f"warning: {args.params}: fitted, implausible ({'; '.join(cal.implausible)}); "
            "scored to inspect it"
        )
    robot = cal.model.robot
    if args.joint_names is not None:
        robot = with_joint_names(robot, args.joint_names)
    table = None
    if args.points_csv:
        table = output_path(
            args.points_csv, "the per-point table", [args.params, *args.bags], args.force
        )
    recording = read_bags(args.bags, robot, args.pair_tolerance, log)
    correction = cal.correction
    result = cal.score(recording)
    terminal = sys.stdout.isatty() and sys.stderr.isatty()  # both on one screen: once
    for warning in [] if terminal else result.warnings:  # also in stdout and the table
        log(warning)
    for line in result.lines(", ".join(args.bags)):
        print(line)
    if correction is not None:
        print(f"the learned correction applied ({correction.line()})")
    if table is not None:
        write_points_table(result, recording, table)
        print(f"{table}: {len(recording)} points (bag, index, x/y/z, dx/dy/dz, error in m)")
    return 0
