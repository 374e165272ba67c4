"""`robot-calib export`: a calibration (PARAMS.json) in a format robots and their software
read: URDF (bare, or into your own URDF), DH table, UR calibration YAML, flat JSON
(robot_calib/export/)."""

from __future__ import annotations

import argparse

from robot_calib.cli.common import log, plausible_or_forced, robot_files
from robot_calib.cli.options import CALIBRATION_ROBOT, add_force, add_output
from robot_calib.errors import InputError
from robot_calib.kinematics.loader import load_robot

NAME = "export"
HELP = "a calibration as a URDF, DH table, UR calibration or JSON"
ROBOT = CALIBRATION_ROBOT  # --robot's default, in words


def add_arguments(exp: argparse.ArgumentParser) -> None:
    from robot_calib.export import FORMATS

    exp.add_argument("params", metavar="PARAMS.json")
    exp.add_argument(
        "--format",
        required=True,
        choices=sorted(FORMATS),
        help="; ".join(f"{k}: {v.description}" for k, v in sorted(FORMATS.items()))
        + " (msgs_doc/export.md; no default)",
    )
    add_output(exp, "file to write (e.g. robot.urdf)")
    exp.add_argument(
        "--nominal-urdf",
        metavar="NOMINAL.urdf",
        help="--format urdf: write the calibrated joint origins into this nominal URDF of the "
        "robot, keeping its link names, limits, meshes and other tags (default: a bare chain)",
    )
    add_force(exp, implausible=True)


def main(args: argparse.Namespace) -> int:
    """A calibration (PARAMS.json) in a format robots and their software read."""
    from robot_calib.atomic import output_path, write_text_atomic
    from robot_calib.export import FORMATS
    from robot_calib.export.base import correction_lines
    from robot_calib.identify.calibration import load_calibration

    cal = load_calibration(args.params)
    plausible_or_forced(cal.implausible, args)
    robot = cal.model.robot
    if args.robot is not None and load_robot(args.robot).name != robot.name:
        raise InputError(
            f"{args.params}: identified for robot {robot.name}, not --robot {args.robot}"
        )
    exporter = FORMATS[args.format]
    inputs = [args.params, *robot_files(args)] + ([args.nominal_urdf] if args.nominal_urdf else [])
    output = output_path(args.output, f"the {args.format} export", inputs, args.force)
    if args.nominal_urdf is not None:
        from robot_calib.export.urdf_nominal import render_on_nominal

        if args.format != "urdf":
            raise InputError(f"--nominal-urdf is for --format urdf, not {args.format}")
        text = render_on_nominal(cal, str(args.params), args.nominal_urdf)
    else:
        text = exporter.render(cal, str(args.params))
    write_text_atomic(output, text)
    effects = len(cal.model.effects) if args.format in ("urdf", "ur") else 0
    left = f"; {effects} effect(s) it cannot hold, listed in its header" if effects else ""
    print(f"{output}: {exporter.description}, robot {robot.name}, model {cal.name}{left}")
    for line in correction_lines(cal):  # also in the file's header where it has one
        log(f"warning: {output}: {line}")
    return 0
