"""`robot-calib score`: a calibration scored on bags it was not fitted on (absolute and
seed criterion; robot_calib/score.py)."""

from __future__ import annotations

import argparse
import sys

from robot_calib.cli.common import calibration_of, correction_of, log
from robot_calib.cli.options import (
    CALIBRATION_ROBOT,
    add_force,
    add_joint_names,
    add_pair_tolerance,
)
from robot_calib.errors import InputError
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
    from robot_calib.identify.params_file import implausible_of, in_sample_accuracy
    from robot_calib.score import score, write_points_table

    model, params, doc = calibration_of(args)
    reasons = implausible_of(doc, args.params, model, params)
    if reasons:  # scored all the same: that is inspecting it
        log(f"warning: {args.params}: fitted, implausible ({'; '.join(reasons)}); scored to "
            "inspect it")  # fmt: skip
    in_sample = in_sample_accuracy(doc, args.params)
    fitted = doc.get("recordings", [])
    if not isinstance(fitted, list) or not all(isinstance(f, str) for f in fitted):
        raise InputError(f"{args.params}: 'recordings' must be a list of bag paths")
    robot = model.robot
    if args.joint_names is not None:
        robot = with_joint_names(robot, args.joint_names)
    table = None
    if args.points_csv:
        table = output_path(args.points_csv, "the per-point table",
                            [args.params, *args.bags], args.force)  # fmt: skip
    recording = read_bags(args.bags, robot, args.pair_tolerance, log)
    correction = correction_of(doc, model, params, args)
    judged_by = "the calibration's in-sample rms"
    if correction is not None:  # the model applied: physical + learned correction
        hybrid = in_sample_accuracy(doc, args.params, "hybrid_residuals")
        if hybrid is not None:
            in_sample, judged_by = hybrid, "the hybrid model's in-sample rms"
        else:
            judged_by = ("the physical model's in-sample rms (the file has no "
                         "hybrid_residuals: written before them)")  # fmt: skip
    result = score(model, params, recording, in_sample, fitted, correction, judged_by)
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
