"""`robot-calib compensate`: nominal joint commands, or targets, -> the commands that
make the calibrated robot go where the nominal model would (msgs_doc/compensate.md;
robot_calib/compensation/); a robot program -> the compensated program and its
per-target table (`--program`, msgs_doc/programs.md)."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robot_calib.cli.common import calibration_of, plausible_or_forced, robot_files
from robot_calib.cli.options import CALIBRATION_ROBOT, add_force, add_output
from robot_calib.errors import InputError, RobotCalibError

if TYPE_CHECKING:
    from robot_calib.compensation.program import ProgramCompensation
    from robot_calib.identify.calibration import Calibration
    from robot_calib.programs.language import Language
    from robot_calib.programs.source import Frame, Program

NAME = "compensate"
HELP = (
    "nominal joint commands (JOINTS.csv), targets (TARGETS.csv) or a robot program (KRL, "
    "RAPID, FANUC TP, URScript) -> compensated commands or program"
)
ROBOT = CALIBRATION_ROBOT  # --robot's default, in words


def add_arguments(comp: argparse.ArgumentParser) -> None:
    comp.add_argument(
        "params", metavar="PARAMS.json", help="the calibration (calibrate's or diagnose's)"
    )
    given = comp.add_mutually_exclusive_group(required=True)
    given.add_argument(
        "--joints",
        help="JOINTS.csv of the nominal program, header q1..qJ [rad] (optional t [s], "
        "dir1..dirJ approach directions, temp_c): where the nominal model puts the tool is "
        "where the compensated commands make the calibrated robot go (this, --targets or "
        "--program is required)",
    )
    given.add_argument(
        "--targets",
        help="TARGETS.csv: header x,y,z (the tool point, --unit), optional qx,qy,qz,qw (the "
        "tool frame's orientation; without: positions only), optional q1..qJ [rad] seeds, t "
        "[s], dir1..dirJ, temp_c (msgs_doc/compensate.md; this, --joints or --program is "
        "required)",
    )
    given.add_argument(
        "--program",
        metavar="PROGRAM",
        help="a robot program: KUKA .src (with its .dat), ABB .mod, FANUC .ls or URScript "
        ".script; every motion target replaced by the one the nominal controller must be "
        "given, every other byte kept (msgs_doc/programs.md; this, --joints or --targets is "
        "required)",
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
        "target; over the program's own; repeatable (default: the program's own tools)",
    )
    comp.add_argument(
        "--base",
        action="append",
        metavar="[KEY=]VALUES",
        help="with --program: a base (user) frame in the robot base frame, as --tool (KRL "
        "BASE_DATA number, RAPID wobjdata name, FANUC UF number; default: the program's "
        "own bases)",
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
        "the file to write: with --joints or --targets a JOINTS.csv (q1..qJ [rad] "
        "compensated, dir1..dirJ the approach directions assumed, error_mm and error_urad "
        "the calibrated model's remaining error, iterations, status); with --program the "
        "compensated program in its language's suffix (a KRL .dat is written beside its "
        ".src) and a per-target table NAME.targets.csv beside it",
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


SHOWN = 8  # targets named per warning at most


class NotCompensated(RobotCalibError):
    """A program some of whose targets could not be compensated: exit 3, the outputs
    written for inspection (those targets left as they were and marked in the table)."""

    exit_status = 3
    kind = "not compensated"


def frame_options(
    values: list[str] | None, language: Language, kind: int, option: str
) -> dict[str, Frame]:
    """--tool / --base ([KEY=]VALUES, the language's pose notation) -> frames by the key
    the program uses (`Language.frame_keys`; '*' without KEY); InputError for a value that
    is not the language's pose, an empty KEY, or one KEY given twice."""
    from robot_calib.programs.source import EVERY

    out: dict[str, Frame] = {}
    for text in values or []:
        key, equals, numbers = text.rpartition("=")
        try:
            pose = np.array([float(v) for v in numbers.split(",")])
        except ValueError:
            pose = np.zeros(0)
        if equals and not key.strip():
            raise InputError(f"--{option} {text}: KEY= without a KEY (or give no '=')")
        frame = language.frame(kind, key.strip() or EVERY, pose, f"--{option} {text}")
        reach = float(np.abs(pose[:3]).max())
        metres = language.joint_unit == 1.0  # URScript: poses in m, axes in rad
        if (metres and reach > 5.0) or (not metres and 0.0 < reach < 2.0):
            unit, other = ("m", "mm") if metres else ("mm", "m")
            print(
                f"warning: --{option} {text}: its position is in {unit} in {language.title}; "
                f"{reach:g} looks like {other}",
                file=sys.stderr,
            )
        if frame.key in out:
            what = key.strip() or "the frame of every target"
            raise InputError(f"--{option} {text}: {what} given twice")
        out[frame.key] = frame
    return out


def compensate_program_file(args: argparse.Namespace, cal: Calibration) -> int:
    """The --program mode of `compensate` (msgs_doc/programs.md)."""
    from robot_calib.atomic import refuse_input, staged_outputs
    from robot_calib.cli.common import robot_files
    from robot_calib.compensation.program import compensate_program
    from robot_calib.compensation.program_table import write_program_table
    from robot_calib.programs.registry import check_robot, language_for

    for option in ("seed_joints", "frame", "unit"):
        if getattr(args, option) is not None:
            raise InputError(f"--{option.replace('_', '-')} goes with --targets, not --program")
    source = Path(args.program)
    if not source.is_file():
        raise InputError(f"{source}: no such program file")
    language = language_for(source, args.language)
    check_robot(language, cal.model.robot.name, args.params)
    output = Path(args.output)
    if output.suffix.lower() not in language.suffixes:
        raise InputError(
            f"-o {output}: a {language.title} program is written as {language.suffixes[0]}"
        )
    program = language.read(source)
    if not any(t.used for t in program.targets):
        raise InputError(
            f"{source}: no motion to a target of the program read as {language.title}"
        )
    language.check_output(program, output)
    paths = language.outputs(program, output)
    table = output.with_name(output.stem + ".targets.csv")
    inputs = [args.params, *(source.with_name(n) for n in program.texts), *robot_files(args)]
    if not output.parent.is_dir():
        raise InputError(f"{output.parent}: no such folder for the compensated program")
    for path in (*paths.values(), table):
        refuse_input(path, inputs)
    tools = frame_options(args.tool, language, 0, "tool")
    bases = frame_options(args.base, language, 1, "base")
    result = compensate_program(cal, program, language, tools, bases)
    with staged_outputs(output.parent, args.force) as stage:
        for name, path in paths.items():
            encoding = program.encoding(name)
            with open(stage / path.name, "w", encoding=encoding, newline="") as stream:
                stream.write(result.texts[name])
        write_program_table(stage / table.name, result.rows, tools, bases)
    _report(args, cal, language, program, result, paths, table, {**tools, **bases})
    return 0


#: statuses of targets the program moves to but that were left as they were: the
#: compensation failed there, or the target cannot be compensated as it stands
FAILED = ("configuration", "not_reached", "beyond_limits", "large_change", "left")


def _report(
    args: argparse.Namespace,
    cal: Calibration,
    language: Language,
    program: Program,
    result: ProgramCompensation,
    paths: dict[str, Path],
    table: Path,
    given: dict[str, Frame],
) -> None:
    """The summary on stdout (files, robot, counts, the largest changes and their targets,
    the frames each side used); warnings naming the targets left as they were; exit 3
    (written for inspection) when the compensation failed at a target."""
    from robot_calib.compensation.program import WRITTEN
    from robot_calib.ik import first_tool2flange

    rows = [r for r in result.rows if r.status != "unused"]
    written = [r for r in rows if r.status in WRITTEN]
    files = ", ".join(str(p) for p in paths.values())
    print(
        f"{files}: {len(written)}/{len(rows)} targets of {args.program} ({language.title}) "
        f"compensated for robot {cal.model.robot.name} ({args.params}); per-target table "
        f"{table}"
    )
    if written:
        moved = max(written, key=lambda r: r.moved_mm)
        turned = max(written, key=lambda r: r.turned_deg)
        print(
            f"largest change: {moved.moved_mm:.4f} mm ({moved.target.name}), "
            f"{turned.turned_deg:.5f} deg ({turned.target.name}; of the orientation, or of "
            "an axis for an axis target)"
        )
    smr = np.round(first_tool2flange(cal.model, cal.parameters)[:3, 3] * 1e3, 1) + 0.0
    print(
        "frames: "
        + "; ".join(
            f"{what} {_frame_source(key, program, given, default)}"
            for what, keys, default in (
                ("tool", {r.target.tool for r in rows}, "the flange"),
                ("base", {r.target.base for r in rows}, "the robot base"),
            )
            for key in sorted(keys, key=str)
        )
        + f"; the calibration measured its target (SMR) at ({smr[0]:.1f}, {smr[1]:.1f}, "
        f"{smr[2]:.1f}) mm in the flange"
        + ("; the learned correction applied" if cal.correction is not None else "")
    )
    for status in (*FAILED, "position_only", "near_singular"):
        hit = [r for r in rows if r.status == status]
        if hit:
            names = ", ".join(f"{r.target.name} ({r.target.where})" for r in hit[:SHOWN])
            more = f" and {len(hit) - SHOWN} more" if len(hit) > SHOWN else ""
            done = "written" if status in WRITTEN else "left as they were"
            print(
                f"warning: {args.program}: {len(hit)} target(s) {done}, {status}: "
                f"{names}{more}: {hit[0].reason}",
                file=sys.stderr,
            )
    for remark in program.remarks:
        print(f"warning: {remark}", file=sys.stderr)
    unused = [r for r in result.rows if r.status == "unused"]
    if unused:
        print(
            f"note: {len(unused)} target(s) no motion goes to, left as they were "
            f"(first {unused[0].target.name}, {unused[0].target.where})",
            file=sys.stderr,
        )
    failed = [r for r in rows if r.status in FAILED]
    if failed:
        raise NotCompensated(
            f"{args.program}: {len(failed)} of its {len(rows)} targets could not be "
            f"compensated and were left as they were ({table} says why for each; the program "
            "was written for inspection: do not run it as compensated)"
        )


def _frame_source(key: str | None, program: Program, given: dict[str, Frame], default: str) -> str:
    """'TOOL_DATA[1] (pick_place.src:13)', 'UT 1 (--tool 1=...)', or the default."""
    from robot_calib.programs.source import EVERY

    if EVERY in given and key is not None:
        return f"{key} as {given[EVERY].where}"
    if key is None:
        return f"{default} ({given[EVERY].where})" if EVERY in given else default
    frame = given.get(key) or program.tools.get(key) or program.bases.get(key)
    return f"{key} ({frame.where})" if frame is not None else key
