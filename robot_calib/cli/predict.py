"""`robot-calib predict`: target positions (tracker frame, m) of a calibration for the
joint angles of JOINTS.csv (robot_calib/csv_tables.py)."""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from robot_calib.cli.common import calibration_of, plausible_or_forced, robot_files
from robot_calib.cli.options import CALIBRATION_ROBOT, add_force, add_output
from robot_calib.errors import InputError

NAME = "predict"
HELP = "target positions for joint angles (JOINTS.csv)"
ROBOT = CALIBRATION_ROBOT  # --robot's default, in words


def add_arguments(pred: argparse.ArgumentParser) -> None:
    pred.add_argument("params", metavar="PARAMS.json")
    pred.add_argument(
        "--joints",
        required=True,
        help="JOINTS.csv, header q1..qJ [rad]: the readings of the robot's J joints, in rad "
        "(optional columns t [s] and dir1..dirJ: approach directions +1/-1); a reading beyond "
        "any reading of its joint in rad (degrees?) is refused",
    )
    add_output(pred, "POINTS.csv to write (x,y,z m)")
    pred.add_argument(
        "--target",
        metavar="NAME",
        help="which target of a several-target calibration (msgs_doc/targets.md; default: "
        "the first, /laser_tracker/point)",
    )
    add_force(pred, implausible=True)


def main(args: argparse.Namespace) -> int:
    """Target positions (tracker frame, m) for the joint angles of JOINTS.csv."""
    from robot_calib.atomic import output_path
    from robot_calib.csv_tables import read_joints_csv, write_points_csv
    from robot_calib.messages import target_topic

    cal = calibration_of(args)
    plausible_or_forced(cal.implausible, args)
    model, params, correction = cal.model, cal.parameters, cal.correction
    args.target = model.targets[0] if args.target is None else args.target
    if args.target not in model.targets:
        known = ", ".join(target_topic(t) for t in model.targets)
        raise InputError(f"{args.params}: no target {args.target!r} (its targets: {known})")
    poses = read_joints_csv(args.joints, model.robot.n_joints, model.robot.limits)
    index = np.full(len(poses), model.targets.index(args.target))
    poses = dataclasses.replace(poses, target=index)
    output = output_path(
        args.output, "POINTS.csv", [args.params, args.joints, *robot_files(args)], args.force
    )
    quaternions = None
    if args.target in model.oriented:  # a 6-DoF probe: its frame too (msgs_doc/six_dof.md)
        from scipy.spatial.transform import Rotation

        frames = model.probe_orientations(params, poses)
        quaternions = Rotation.from_matrix(frames).as_quat()
    points = cal.predict(poses)  # hybrid: less the learned correction's residual
    write_points_csv(points, output, quaternions)
    which = "" if len(model.targets) == 1 else f", target {target_topic(args.target)}"
    frames_too = "" if quaternions is None else " with the probe frame as qx,qy,qz,qw"
    learned = "" if correction is None else "; the learned correction applied"
    print(f"{output}: {len(poses)} points (m, laser_tracker frame{which}){frames_too}{learned}")
    return 0
