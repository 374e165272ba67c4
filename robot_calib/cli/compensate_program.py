"""`robot-calib compensate PARAMS.json --program PROGRAM -o OUT`: a robot program in, the
compensated program and its per-target table out (msgs_doc/programs.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from robot_calib.errors import InputError, RobotCalibError
from robot_calib.identify.calibration import Calibration
from robot_calib.programs.language import Language
from robot_calib.programs.source import Frame

SHOWN = 8  # targets named per warning at most


class NothingCompensated(RobotCalibError):
    """A program none of whose targets could be compensated: exit 3, the outputs written
    for inspection (every target left as it was and marked in the table)."""

    exit_status = 3
    kind = "nothing compensated"


def frame_options(
    values: list[str] | None, language: Language, kind: int, option: str
) -> dict[str, Frame]:
    """--tool / --base ([KEY=]VALUES, the language's pose notation) -> frames by the key
    the program uses (`Language.frame_keys`; '*' without KEY)."""
    from robot_calib.compensation.program import EVERY

    out: dict[str, Frame] = {}
    count = len(language.pose_places)
    for text in values or []:
        key, _, numbers = text.rpartition("=")
        try:
            pose = np.array([float(v) for v in numbers.split(",")])
        except ValueError:
            pose = np.zeros(0)
        if pose.size != count or not np.isfinite(pose).all():
            raise InputError(
                f"--{option} {text}: expected [KEY=]{count} numbers separated by commas "
                f"({language.title}'s pose notation)"
            )
        if language.name == "rapid" and abs(np.linalg.norm(pose[3:]) - 1.0) > 1e-3:
            raise InputError(f"--{option} {text}: the quaternion q1..q4 has not norm 1")
        name = EVERY if not key else language.frame_keys[kind].format(key.strip())
        out[name] = Frame(name, language.pose_to_base(pose[None])[0], f"--{option} {text}")
    return out


def compensate_program_file(args: argparse.Namespace, cal: Calibration) -> int:
    """The --program mode of `compensate` (msgs_doc/programs.md)."""
    from robot_calib.atomic import refuse_input, staged_outputs
    from robot_calib.cli.common import robot_files
    from robot_calib.compensation.program import compensate_program
    from robot_calib.compensation.program_table import write_program_table
    from robot_calib.programs.registry import language_for

    for option in ("seed_joints", "frame", "unit"):
        if getattr(args, option) is not None:
            raise InputError(f"--{option.replace('_', '-')} goes with --targets, not --program")
    source = Path(args.program)
    if not source.is_file():
        raise InputError(f"{source}: no such program file")
    language = language_for(source, args.language)
    try:
        program = language.read(source)
    except UnicodeDecodeError as exc:
        raise InputError(
            f"{source}: not a text program (byte {exc.start}: {exc.reason})"
        ) from None
    if not any(t.used for t in program.targets):
        raise InputError(f"{source}: no motion to a target of the program ({language.title})")
    output = Path(args.output)
    paths = language.outputs(program, output)
    table = output.with_name(output.stem + ".targets.csv")
    inputs = [args.params, *(source.with_name(n) for n in program.texts), *robot_files(args)]
    for path in (*paths.values(), table):
        if path.parent != output.parent:
            raise InputError(f"{path}: the outputs go to one folder")
        refuse_input(path, inputs)
    if not output.parent.is_dir():
        raise InputError(f"{output.parent}: no such folder for the compensated program")
    tools = frame_options(args.tool, language, 0, "tool")
    bases = frame_options(args.base, language, 1, "base")
    result = compensate_program(cal, program, language, tools, bases)
    with staged_outputs(output.parent, args.force) as stage:
        for name, path in paths.items():
            with open(stage / path.name, "w", encoding="utf-8", newline="") as stream:
                stream.write(result.texts[name])
        write_program_table(stage / table.name, result.rows)
    _report(args, cal, language, program, result, paths, table)
    return 0


def _report(
    args: argparse.Namespace,
    cal: Calibration,
    language: Language,
    program: object,
    result: object,
    paths: dict[str, Path],
    table: Path,
) -> None:
    """The summary line on stdout; warnings naming the targets left as they were."""
    from robot_calib.compensation.program import WRITTEN, ProgramCompensation
    from robot_calib.ik import first_tool2flange

    assert isinstance(result, ProgramCompensation)
    rows = [r for r in result.rows if r.status != "unused"]
    written = [r for r in rows if r.status in WRITTEN]
    moved = max((r.moved_mm for r in written), default=0.0)
    turned = max((r.turned_deg for r in written), default=0.0)
    smr = first_tool2flange(cal.model, cal.parameters)[:3, 3] * 1e3
    tools = sorted({r.target.tool or "the flange" for r in rows})
    files = ", ".join(str(p) for p in paths.values())
    print(
        f"{files}: {len(written)}/{len(rows)} targets of {args.program} compensated "
        f"({language.title}); largest change {moved:.4f} mm / {turned:.5f} deg; "
        f"per-target table {table}"
    )
    print(
        f"frames: the program's tool {', '.join(tools)}; the calibration measured its target "
        f"at ({smr[0]:.1f}, {smr[1]:.1f}, {smr[2]:.1f}) mm in the flange"
        + ("; the learned correction applied" if cal.correction is not None else "")
    )
    for status in (
        "configuration",
        "not_reached",
        "beyond_limits",
        "large_change",
        "left",
        "position_only",
        "near_singular",
    ):
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
    for remark in getattr(program, "remarks", ()):
        print(f"warning: {remark}", file=sys.stderr)
    unused = [r for r in result.rows if r.status == "unused"]
    if unused:
        print(
            f"note: {len(unused)} target(s) no motion goes to, left as they were "
            f"(first {unused[0].target.name}, {unused[0].target.where})",
            file=sys.stderr,
        )
    if rows and not written:
        raise NothingCompensated(
            f"{args.program}: none of its {len(rows)} targets compensated ({table} names "
            "why for each; the program was written unchanged)"
        )
