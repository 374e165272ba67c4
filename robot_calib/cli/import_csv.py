"""`robot-calib import`: measurement CSV(s) -> a bag of the contract (rows in visiting
order, bad rows reported by line; robot_calib/bag/csv_import.py, csv_format.py, write.py)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

import numpy as np

from robot_calib.cli.common import log, robot_files, robot_of
from robot_calib.cli.options import add_force, add_joint_names, add_output, separator
from robot_calib.errors import InputError
from robot_calib.flows import DEFAULT_ROBOT

if TYPE_CHECKING:
    from robot_calib.bag.csv_format import OrientationColumns, SigmaColumns
    from robot_calib.kinematics.frames import Array

NAME = "import"
HELP = "measurement CSV(s) -> a bag of the contract"
ROBOT = f"{DEFAULT_ROBOT}; with --preset, the preset's robot"  # --robot's default, in words


def add_arguments(imp: argparse.ArgumentParser) -> None:
    imp.add_argument("csv", nargs="+", metavar="CSV", help="CSV file(s), rows in visiting order")
    imp.add_argument(
        "--preset",
        help="a known export format: ur5_jacobi2025 (its columns, units and robot; options "
        "given override them) (default: none; then --joints and --point)",
    )
    imp.add_argument(
        "--joints",
        help="joint columns, names or 0-based indices: q1,q2,... (default: the preset's)",
    )
    imp.add_argument("--point", help="measured point columns x,y,z (default: the preset's)")
    imp.add_argument(
        "--dif",
        help="difference columns dx,dy,dz: point = point + sign * dif (default: none, or the "
        "preset's)",
    )
    imp.add_argument(
        "--dif-sign",
        type=float,
        choices=(-1.0, 1.0),
        help="sign of --dif (+1/-1) (default +1; ur5_jacobi2025: -1)",
    )
    imp.add_argument("--time", help="time column [s] (default: none; poses 1 s apart)")
    imp.add_argument(
        "--target",
        action="append",
        metavar="NAME:X,Y,Z",
        help="a further target (SMR) measured at each pose: its name and x,y,z columns, onto "
        "/laser_tracker/NAME/point (repeat per target; an empty cell: not measured there) "
        "(default: none)",
    )
    imp.add_argument(
        "--reference",
        action="append",
        metavar="NAME:X,Y,Z",
        help="a reference reflector fixed off the robot (on its base, the floor) read with "
        "each pose: its name and x,y,z columns (repeat per reflector, 3 or more give the "
        "tracker's rotation too), written to /laser_tracker/reference/NAME/point; the "
        "tracker's drift they show is removed from every point by the readers and their "
        "scatter about it reported (default: none)",
    )
    imp.add_argument(
        "--temperature",
        help="a temperature column [deg C]: written to /temperature (sensor_msgs/Temperature) "
        "(default: none)",
    )
    imp.add_argument(
        "--orientation",
        action="append",
        metavar="[NAME:]QX,QY,QZ,QW",
        help="a 6-DoF probe's orientation as unit quaternion columns in x, y, z, w order, onto "
        "/laser_tracker/(NAME/)pose; without NAME the first target, else the --target NAME "
        "(repeat per target; empty cells: orientation not measured at that pose) (default: none)",
    )
    imp.add_argument(
        "--orientation-rpy",
        action="append",
        metavar="[NAME:]R,P,Y",
        help="as --orientation, as roll, pitch, yaw columns: R = Rz(yaw) Ry(pitch) Rx(roll), "
        "in --orientation-unit (default: none)",
    )
    imp.add_argument(
        "--orientation-unit",
        choices=("deg", "rad"),
        help="unit of --orientation-rpy columns (default: --angle-unit)",
    )
    imp.add_argument(
        "--sigma",
        action="append",
        metavar="[NAME:]SP[,SR]",
        help="the tracker's stated standard deviations: position column (per coordinate, "
        "--sigma-unit) and optionally orientation column (per axis, --sigma-angle-unit) of "
        "the first target, or of target NAME (repeat per target; an empty cell: not stated) "
        "(default: none)",
    )
    imp.add_argument(
        "--sigma-unit",
        choices=("mm", "m", "um"),
        help="unit of the position standard deviations (default: --length-unit)",
    )
    imp.add_argument(
        "--sigma-angle-unit",
        choices=("deg", "rad", "mdeg", "urad"),
        help="unit of the orientation standard deviations (default: --orientation-unit, "
        "else --angle-unit)",
    )
    imp.add_argument(
        "--sep",
        type=separator,
        help="field separator, one character; tab: a tab (default ',')",
    )
    imp.add_argument(
        "--decimal-comma",
        action="store_true",
        help="numbers written 1,5 (default: off, numbers written 1.5)",
    )
    imp.add_argument(
        "--angle-unit",
        choices=("deg", "rad"),
        help="joint angle unit (default rad; ur5_jacobi2025: deg)",
    )
    imp.add_argument(
        "--length-unit",
        choices=("mm", "m"),
        help="unit of the point, --dif and --target columns (default m; ur5_jacobi2025: mm)",
    )
    imp.add_argument(
        "--no-header",
        action="store_true",
        help="the CSV has no header row (default: the first row is the header)",
    )
    add_joint_names(imp, "JointState names to write for joints 1..J")
    add_output(imp, "bag to write (BAG.mcap)")
    add_force(imp)


def main(args: argparse.Namespace) -> int:
    """Measurement CSV(s) -> a contract bag (rows in order, bad rows reported by line)."""
    from robot_calib.atomic import output_path
    from robot_calib.bag.csv_format import PRESETS, CsvFormat, target_label, with_overrides
    from robot_calib.bag.csv_import import (
        check_no_copies,
        counted,
        joined_times,
        read_measurement_csv,
    )
    from robot_calib.bag.write import write_measurement_bag

    preset = PRESETS.get(args.preset or "")
    robot_name = args.robot  # else the preset's robot, else the default robot
    if robot_name is None:
        robot_name = preset.robot if preset is not None and preset.robot else DEFAULT_ROBOT
    robot = robot_of(args, robot_name)
    output = output_path(args.output, "the bag", [*args.csv, *robot_files(args)], args.force)
    if args.preset:
        if args.preset not in PRESETS:
            raise InputError(f"--preset {args.preset}: known presets: {', '.join(PRESETS)}")
        fmt = PRESETS[args.preset]
    else:
        if not args.joints or not args.point:
            raise InputError("give --preset, or --joints and --point (column names or indices)")
        fmt = CsvFormat(joints=tuple(args.joints.split(",")), point=tuple(args.point.split(",")))
    references = _target_columns(args.reference or [], "--reference")
    clash = {n for n, _ in references} & {n for n, _ in _target_columns(args.target or [])}
    if clash:
        raise InputError(f"--reference {sorted(clash)[0]}: also given as a --target")
    split = lambda text: None if text is None else tuple(text.split(","))  # noqa: E731
    fmt = with_overrides(
        fmt,
        joints=split(args.joints),
        point=split(args.point),
        dif=split(args.dif),
        dif_sign=args.dif_sign,
        time=args.time,
        temperature=args.temperature,
        separator=args.sep,
        decimal_comma=True if args.decimal_comma else None,
        angle_unit=args.angle_unit,
        length_unit=args.length_unit,
        header=False if args.no_header else None,
        targets=(_target_columns(args.target or []) + references) or None,
        references=tuple(name for name, _ in references) or None,
        orientations=_orientation_columns(args.orientation, args.orientation_rpy),
        sigmas=_sigma_columns(args.sigma),
        orientation_unit=args.orientation_unit,
        sigma_unit=args.sigma_unit,
        sigma_angle_unit=args.sigma_angle_unit,
    )
    rpy = any(o.kind == "rpy" for o in fmt.orientations)
    for unit, needs, what in (
        (fmt.sigma_unit, fmt.sigmas, "--sigma-unit goes with --sigma"),
        (fmt.sigma_angle_unit, fmt.sigmas, "--sigma-angle-unit goes with --sigma"),
        (fmt.orientation_unit, rpy, "--orientation-unit goes with --orientation-rpy"),
    ):
        if unit is not None and not needs:  # a unit of no column: ignored without a word
            raise InputError(f"{what} (the columns it is the unit of)")
    reference_names = {name for name, _ in references}
    sides: list[SigmaColumns | OrientationColumns] = [*fmt.sigmas, *fmt.orientations]
    for side in sides:
        if side.target in reference_names:
            raise InputError(
                f"{side.option}: {side.target} is a --reference, not a target: "
                "a reflector off the robot has no stated accuracy or orientation "
                "here"
            )
    if len(fmt.point) != 3 or (fmt.dif is not None and len(fmt.dif) != 3):
        raise InputError("--point and --dif take three columns: x,y,z")
    if len(fmt.joints) != robot.n_joints:  # before any file is read or counted
        raise InputError(
            f"--joints {','.join(fmt.joints)}: {len(fmt.joints)} columns for robot "
            f"{robot.name} with {robot.n_joints} joints"
        )
    tables = []
    check_no_copies(args.csv, [])  # a CSV given twice, before any is read
    for csv_path in args.csv:
        table = read_measurement_csv(csv_path, fmt, robot.limits)
        for warning in table.warnings:
            log(warning)
        for line, why in table.bad_rows:
            log(f"warning: {csv_path}:{line}: {why}: row skipped")
        print(
            f"{csv_path}: {counted(len(table.q), 'row')} imported, "
            f"{counted(len(table.bad_rows), 'bad row')} skipped"
        )
        for name, (rotation, sigma) in table.six_dof.items():
            oriented = int(np.isfinite(rotation).all(axis=(1, 2)).sum())
            stated = int(np.isfinite(sigma).any(axis=1).sum())
            parts = ([f"{oriented} orientations"] if oriented else []) + (
                [f"{stated} rows with stated standard deviations"] if stated else []
            )
            if parts:
                print(f"  {target_label(name)}: {', '.join(parts)}")
        tables.append(table)
    note = check_no_copies(args.csv, tables)
    if note:
        print(note)
    q = np.concatenate([t.q for t in tables])
    points = np.concatenate([t.points for t in tables])
    times = joined_times([t.time for t in tables])  # absolute Unix times kept as they are
    temperature = None
    if all(t.temperature is not None for t in tables):
        temperature = np.concatenate([t.temperature for t in tables if t.temperature is not None])
    extra = {
        name: np.concatenate([t.extra_points[name] for t in tables]) for name, _ in fmt.targets
    }
    reference_reads = _reference_reads(args.csv, references, times, extra) if references else None
    for name, xyz in extra.items():
        if not np.isfinite(xyz).all(axis=1).any():
            log(
                f"warning: {', '.join(args.csv)}: target {name} has no measured point: no "
                "topic written for it"
            )
    six_dof = {
        name: (
            np.concatenate([t.six_dof[name][0] for t in tables]),
            np.concatenate([t.six_dof[name][1] for t in tables]),
        )
        for name in tables[0].six_dof
    }
    for o in fmt.orientations:
        if not np.isfinite(six_dof[o.target][0]).any():
            log(
                f"warning: {', '.join(args.csv)}: {o.option}: every cell is empty: "
                f"{target_label(o.target)} has no orientation"
            )
    counts = write_measurement_bag(
        output,
        q,
        points,
        robot.joint_names,
        times,
        args.force,
        temperature=temperature,
        extra_points=extra,
        six_dof=six_dof,
        references=reference_reads,
    )
    print(
        f"{output}: {', '.join(f'{k}={v}' for k, v in counts.items())} messages "
        f"({robot.name}, {fmt.angle_unit}/{fmt.length_unit} -> rad/m)"
    )
    return 0


def _reference_reads(
    csvs: list[str],
    references: tuple[tuple[str, tuple[str, str, str]], ...],
    times: Array | None,
    extra: dict[str, Array],
) -> dict[str, Array]:
    """The reference reflectors' reads {NAME: (n, 3) [m]} taken out of the further targets
    `extra`, written as read (the readers remove the drift they show from every point,
    msgs_doc/references.md); the drift and the references' scatter printed now, an
    InputError when they are read too seldom for a drift, a warning when they scatter
    beyond any tracker (the readers then remove nothing either)."""
    from robot_calib.measurements.references import NoDrift, TooFewReads, estimate_drift

    names = [name for name, _ in references]
    time_s = np.arange(len(next(iter(extra.values()))), dtype=float) if times is None else times
    reads = {name: extra.pop(name) for name in names}
    try:
        drift = estimate_drift(
            names, np.asarray(time_s, dtype=float), np.stack(list(reads.values()))
        )
    except TooFewReads as exc:
        raise InputError(f"{', '.join(csvs)}: --reference: {exc}") from None
    except NoDrift as exc:
        log(f"warning: {', '.join(csvs)}: --reference: {exc}")
        return reads
    print(drift.line())
    return reads


def _target_columns(
    specs: list[str], option: str = "--target"
) -> tuple[tuple[str, tuple[str, str, str]], ...]:
    """--target NAME:X,Y,Z (repeated; or `option`) -> ((NAME, (X, Y, Z)), ...); InputError on
    a bad one."""
    from robot_calib.poses import TARGET_NAME

    out: list[tuple[str, tuple[str, str, str]]] = []
    for spec in specs:
        name, _, columns = spec.partition(":")
        cols = tuple(columns.split(","))
        if not TARGET_NAME.fullmatch(name) or len(cols) != 3 or not all(cols):
            raise InputError(
                f"{option} {spec}: expected NAME:X,Y,Z (NAME letters, digits, underscores, "
                "starting with a letter; three columns)"
            )
        if name in (n for n, _ in out):
            raise InputError(f"{option} {spec}: {name} given twice")
        out.append((name, (cols[0], cols[1], cols[2])))
    return tuple(out)


def _named_columns(option: str, spec: str, n_columns: tuple[int, ...]) -> tuple[str, list[str]]:
    """'[NAME:]C,C,...' of `option` -> (NAME or '' for the first target, the columns);
    InputError unless the columns are non-empty and their number is one of `n_columns`."""
    name, colon, columns = spec.partition(":")
    if not colon:
        name, columns = "", spec
    cols = columns.split(",")
    if (colon and not name) or len(cols) not in n_columns or not all(cols):
        counts = " or ".join(map(str, n_columns))
        raise InputError(
            f"{option} {spec}: expected [NAME:] and {counts} columns, comma-"
            "separated (without NAME: the first target)"
        )
    return name, cols


def _orientation_columns(
    quaternions: list[str] | None, rpys: list[str] | None
) -> tuple[OrientationColumns, ...] | None:
    """--orientation [NAME:]QX,QY,QZ,QW and --orientation-rpy [NAME:]R,P,Y (each repeated)
    -> the format's orientation columns (None when neither is given)."""
    from robot_calib.bag.csv_format import OrientationColumns

    if not quaternions and not rpys:
        return None
    out = []
    for kind, option, specs, n in (
        ("quaternion", "--orientation", quaternions, 4),
        ("rpy", "--orientation-rpy", rpys, 3),
    ):
        for spec in specs or ():
            name, cols = _named_columns(option, spec, (n,))
            out.append(OrientationColumns(name, kind, tuple(cols)))
    return tuple(out)


def _sigma_columns(specs: list[str] | None) -> tuple[SigmaColumns, ...] | None:
    """--sigma [NAME:]SP[,SR] (repeated) -> the format's standard deviation columns."""
    from robot_calib.bag.csv_format import SigmaColumns

    if not specs:
        return None
    out = []
    for spec in specs:
        name, cols = _named_columns("--sigma", spec, (1, 2))
        out.append(SigmaColumns(name, cols[0], cols[1] if len(cols) == 2 else None))
    return tuple(out)
