"""`robot-calib` command line: parse, call the core, print, map errors to exit codes.

Every bad input ends in one line on stderr naming the file/value and exit status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from robot_calib.errors import RobotCalibError
from robot_calib.kinematics.description import RobotDescription, load_robot
from robot_calib.model import KinematicModel, geometric_parameters
from robot_calib.poses import Poses

DEFAULT_ROBOT = "kr5_sixx_r650"


def _robot_table(robot: RobotDescription) -> str:
    """The nominal DH/Hayati table in mm and deg (human units, labelled)."""
    lines = [
        f"{robot.name}: nominal DH/Hayati table ({robot.source})",
        "joint  theta[deg]    d[mm]    a[mm]  alpha[deg]  beta[deg]  limits[deg]",
    ]
    for j in range(robot.n_joints):
        beta = f"{np.degrees(robot.beta[j]):9.3f}" if robot.hayati[j] else "        -"
        lo, hi = np.degrees(robot.limits[j])
        lines.append(
            f"{robot.joint_names[j]:>8} {np.degrees(robot.theta[j]):8.3f} "
            f"{robot.d[j] * 1e3:8.2f} {robot.a[j] * 1e3:8.2f} {np.degrees(robot.alpha[j]):10.3f}"
            f"  {beta}  [{lo:.0f}, {hi:.0f}]"
        )
    return "\n".join(lines)


def cmd_run(args: argparse.Namespace) -> int:
    """The main job on built-in defaults (grows into simulate -> ... -> report)."""
    robot = load_robot(args.robot)
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    model = KinematicModel(robot)
    params = geometric_parameters(robot)
    print(_robot_table(robot))
    q = np.array([np.zeros(robot.n_joints), robot.limits.mean(axis=1)])
    flange = model.flange2base(params, Poses.from_readings(q))
    for name, qq, f in zip(("zero reading", "mid-range"), q, flange):
        print(
            f"flange at {name} q={np.degrees(qq).round(1).tolist()} deg: "
            f"{(f[:3, 3] * 1e3).round(3).tolist()} mm in base"
        )
    summary = {
        "robot": robot.name,
        "parameters": params.to_dict(),
        "free_parameters": list(params.free_names),
    }
    path = out / "nominal_model.json"
    path.write_text(json.dumps(summary, indent=1))
    print(f"{len(params)} parameters ({len(params.free_names)} free) written to {path}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="robot-calib", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    def add(
        name: str, func: Callable[[argparse.Namespace], int], help_: str
    ) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help_, description=help_)
        p.add_argument(
            "--robot",
            default=DEFAULT_ROBOT,
            help=f"built-in robot name or robot YAML file (default {DEFAULT_ROBOT})",
        )
        p.set_defaults(func=func)
        return p

    run = add("run", cmd_run, "the main job on built-in defaults")
    run.add_argument("-o", "--output", default="out", help="output folder (default out/)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except RobotCalibError as exc:
        print(f"robot-calib {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_status
    except KeyboardInterrupt:
        print(f"robot-calib {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
