"""`robot-calib compensate`: nominal joint commands, or targets, -> the commands that
make the calibrated robot go where the nominal model would (msgs_doc/compensate.md;
robot_calib/compensation/)."""

from __future__ import annotations

import argparse
import dataclasses
import sys

import numpy as np

from robot_calib.cli.common import calibration_of, plausible_or_forced, robot_files
from robot_calib.cli.options import CALIBRATION_ROBOT, add_force, add_output
from robot_calib.errors import InputError, RobotCalibError

NAME = "compensate"
HELP = (
    "nominal joint commands (JOINTS.csv), targets (TARGETS.csv) or a robot program (KRL, "
    "RAPID, FANUC TP, URScript) -> compensated commands or program"
)
ROBOT = CALIBRATION_ROBOT  # --robot's default, in words


def add_arguments(comp: argparse.ArgumentParser) -> None:
    comp.add_argument("params", metavar="PARAMS.json")
    given = comp.add_mutually_exclusive_group(required=True)
    given.add_argument(
        "--joints",
        help="JOINTS.csv of the nominal program, header q1..qJ [rad] (optional t [s], "
        "dir1..dirJ approach directions, temp_c): where the nominal model puts the tool is "
        "where the compensated commands make the calibrated robot go (this or --targets is "
        "required)",
    )
    given.add_argument(
        "--targets",
        help="TARGETS.csv: header x,y,z (the tool point, --unit), optional qx,qy,qz,qw (the "
        "tool frame's orientation; without: positions only), optional q1..qJ [rad] seeds, t "
        "[s], dir1..dirJ, temp_c (msgs_doc/compensate.md; this or --joints is required)",
    )
    given.add_argument(
        "--program",
        metavar="PROGRAM",
        help="a robot program: KUKA .src (with its .dat), ABB .mod, FANUC .ls or URScript "
        ".script; every motion target replaced by the one the nominal controller must be "
        "given, every other byte kept (msgs_doc/programs.md)",
    )
    comp.add_argument(
        "--language",
        choices=("krl", "rapid", "fanuc_tp", "urscript"),
        help="with --program: its language (default: from the file's suffix)",
    )
    comp.add_argument(
        "--tool",
        action="append",
        metavar="[KEY=]VALUES",
        help="with --program: a tool frame in the program's own pose notation (KRL X,Y,Z,A,B,C; "
        "RAPID x,y,z,q1,q2,q3,q4; FANUC X,Y,Z,W,P,R; URScript x,y,z,rx,ry,rz), for tool KEY "
        "(KRL/FANUC: its number; RAPID: its tooldata name) or, without KEY=, for every "
        "target; over the program's own; repeatable",
    )
    comp.add_argument(
        "--base",
        action="append",
        metavar="[KEY=]VALUES",
        help="with --program: a base (user) frame in the robot base frame, as --tool (KRL "
        "BASE_DATA number, RAPID wobjdata name, FANUC UF number)",
    )
    comp.add_argument(
        "--frame",
        choices=("base", "tracker"),
        help="with --targets: the frame of the targets, the robot base or the laser tracker "
        "(through the calibration's base2tracker) (default base)",
    )
    comp.add_argument(
        "--unit",
        choices=("m", "mm"),
        help="with --targets: unit of x,y,z (default m)",
    )
    comp.add_argument(
        "--seed-joints",
        metavar="JOINTS.csv",
        help="with --targets: readings q1..qJ [rad], one row per target, where the nominal "
        "inverse kinematics starts (default: seed columns of TARGETS.csv, else the home pose)",
    )
    add_output(
        comp,
        "JOINTS.csv to write: q1..qJ [rad] compensated, dir1..dirJ (the approach "
        "directions assumed), error_mm and error_urad (the calibrated model's remaining "
        "error), iterations; with --program: the compensated program (a KRL .dat is "
        "written beside its .src), and a per-target table NAME.targets.csv beside it",
    )
    add_force(comp, implausible=True)


def main(args: argparse.Namespace) -> int:
    """Nominal joint commands, or targets, -> compensated commands (msgs_doc/compensate.md)."""
    from robot_calib.atomic import output_path
    from robot_calib.compensation import compensate_commands, compensate_targets
    from robot_calib.compensation.solve import within_limits
    from robot_calib.compensation.targets import check_reach, goals_in_base, read_targets_csv
    from robot_calib.compensation.write import LARGE_CHANGE_DEG, row_status, write_compensated_csv
    from robot_calib.csv_tables import read_joints_csv

    cal = calibration_of(args)
    plausible_or_forced(cal.implausible, args)
    if args.program:
        from robot_calib.cli.compensate_program import compensate_program_file

        return compensate_program_file(args, cal)
    for option in ("language", "tool", "base"):
        if getattr(args, option) is not None:
            raise InputError(f"--{option} goes with --program")
    model, params, correction = cal.model, cal.parameters, cal.correction
    n_joints, limits = model.robot.n_joints, model.robot.limits
    source = args.joints or args.targets
    inputs = [args.params, source, *robot_files(args)] + (
        [args.seed_joints] if args.seed_joints else []
    )
    if args.joints:
        for option in ("seed_joints", "frame", "unit"):
            if getattr(args, option) is not None:
                raise InputError(f"--{option.replace('_', '-')} goes with --targets, not --joints")
        poses = read_joints_csv(args.joints, n_joints, limits)
        output = output_path(args.output, "JOINTS.csv", inputs, args.force)
        result = compensate_commands(cal, poses)
        # a command or its correction beyond the limits: `beyond_limits` (the one check)
        inside = within_limits(model.robot, result.q) & within_limits(model.robot, poses.q)
        status = row_status(result, poses.q, inside)
        write_compensated_csv(output, result, poses.direction, status)
        change = np.degrees(np.abs(result.q - poses.q)).max()
        what = f"compensated commands (rad); largest change {change:.4f} deg"
    else:
        targets = read_targets_csv(args.targets, n_joints, limits, args.unit or "m")
        if args.seed_joints:
            if targets.seed is not None:
                raise InputError(
                    f"{args.targets}: has seed columns q1..q{n_joints}; give "
                    "them or --seed-joints, not both"
                )
            seeds = read_joints_csv(args.seed_joints, n_joints, limits).q
            if len(seeds) != len(targets):
                raise InputError(
                    f"{args.seed_joints}: {len(seeds)} seed rows for "
                    f"{len(targets)} targets in {args.targets}"
                )
            targets = dataclasses.replace(targets, seed=seeds)
        goals = goals_in_base(targets, args.frame or "base", model, params)
        check_reach(goals, model, args.targets, args.unit or "m", args.frame or "base")
        output = output_path(args.output, "JOINTS.csv", inputs, args.force)
        found = compensate_targets(cal, targets, goals)
        result = found.compensated
        status = row_status(result, found.nominal.q, found.within_limits)
        write_compensated_csv(output, result, found.direction, status)
        kind = "poses" if targets.rotation is not None else "positions"
        seeded = "seed readings" if targets.seed is not None else "the home pose"
        frame = args.frame or "base"
        what = f"commands (rad) for target {kind} ({frame} frame; nominal IK from {seeded})"
    flags = np.array(status)
    n, reached = len(result.q), int(np.isin(flags, ("ok", "large_change", "position_only")).sum())
    print(
        f"{output}: {n} {what}; model error max {result.error_m.max() * 1e3:.6f} mm / "
        f"{result.error_rad.max() * 1e6:.3f} urad, {int(result.iterations.max())} iterations "
        f"at most; {reached}/{n} reached"
        + ("; the learned correction applied" if correction is not None else "")
    )
    for flag, text in (
        (
            "not_reached",
            "not reached by the calibrated model (near a singularity or out of "
            "reach; their q are nan)",
        ),
        ("beyond_limits", "reached only beyond the joint limits"),
        (
            "large_change",
            f"moved by more than {LARGE_CHANGE_DEG:g} deg (near a singularity?): "
            "check them before sending",
        ),
        (
            "position_only",
            f"near a singularity (the exact pose would swing a joint by more "
            f"than {LARGE_CHANGE_DEG:g} deg): solved for the tool position alone, "
            "orientation off by their error_urad",
        ),
    ):
        if (flags == flag).any():
            print(
                f"warning: {source}: {int((flags == flag).sum())} row(s) {text}: "
                f"{_data_rows(flags == flag)[0]} (column status)",
                file=sys.stderr,
            )
    if n and not reached:  # written for inspection, but no exit 0 when nothing is usable
        raise NothingReached(
            f"{source}: none of its {n} rows reached by the calibration "
            f"{args.params} ({output} written, every row flagged in column "
            "status): a calibration far from the robot, or targets out of "
            "its reach?"
        )
    return 0


class NothingReached(RobotCalibError):
    """`compensate` ran to its end but reached no row (msgs_doc/compensate.md): exit 3, the
    output written for inspection."""

    exit_status = 3
    kind = "nothing reached"


def _data_rows(*masks: np.ndarray) -> list[str]:
    """'rows 1, 5, ...' (data rows, 1 = the first after the header) of each boolean mask,
    at most 10 named."""
    out = []
    for mask in masks:
        rows = [str(k + 1) for k in np.flatnonzero(mask)]
        more = f" and {len(rows) - 10} more" if len(rows) > 10 else ""
        out.append(f"data rows {', '.join(rows[:10])}{more}")
    return out
