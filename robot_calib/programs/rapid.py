"""ABB RAPID: a `.mod` module (msgs_doc/programs.md#abb-rapid).

Targets: robtarget `[[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],[eax_a..eax_f]]` (mm; a unit
quaternion with q1 = w; configuration) and jointtarget `[[j1..j6],[eax_a..eax_f]]` (deg),
declared (`CONST robtarget p10 := [...];`, also PERS and VAR, LOCAL or TASK) or written
inline in a motion; motions MoveJ, MoveL, MoveC (two targets), MoveAbsJ and their
...DO/...Sync/...AO forms. Frames: a motion's tool (its last positional argument) and
`\\WObj:=` work object; tooldata `[robhold,[[x,y,z],[q1..q4]],load]` and wobjdata
`[robhold,ufprog,ufmec,[[uframe]],[[oframe]]]` declared in the module (the target is in
the object frame: base <- uframe <- oframe). tool0 and wobj0 are the flange and the base.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from robot_calib.errors import InputError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.programs.configuration import posture
from robot_calib.programs.language import Language, single_output
from robot_calib.programs.source import (
    Frame,
    Program,
    Target,
    TargetBook,
    blank_comments,
    line_of,
    numbers_in,
    read_text,
)

ZERO_DEG = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # ABB's calibration position: cfx 0

_DECL = re.compile(
    r"\b(?:(?:LOCAL|TASK)\s+)?(CONST|PERS|VAR)\s+(robtarget|jointtarget|tooldata|wobjdata)"
    r"\s+(\w+)\s*:=\s*",
    re.IGNORECASE,
)
_MOTION = re.compile(r"\b(MoveJ|MoveL|MoveC|MoveAbsJ)(DO|AO|GO|Sync)?\s+", re.IGNORECASE)
_EXPRESSION = re.compile(r"\b(Offs|RelTool|CRobT|CJointT|CalcRobT|CalcJointT)\s*\(", re.I)


def _bracket_end(code: str, start: int, where: str) -> int:
    """The index after the `]` closing the `[` at `start`."""
    depth = 0
    for k in range(start, len(code)):
        if code[k] == "[":
            depth += 1
        elif code[k] == "]":
            depth -= 1
            if depth == 0:
                return k + 1
    raise InputError(f"{where}: '[' without its closing ']'")


def _split_arguments(code: str, start: int, end: int) -> list[tuple[int, int]]:
    """Top-level comma-separated pieces of code[start:end] as (start, end) spans."""
    pieces, depth, at = [], 0, start
    for k in range(start, end):
        if code[k] in "[(":
            depth += 1
        elif code[k] in "])":
            depth -= 1
        elif code[k] == "," and depth == 0:
            pieces.append((at, k))
            at = k + 1
    pieces.append((at, end))
    return pieces


def _target(name: str, kind: str, code: str, start: int, end: int, file: str) -> Target:
    """A robtarget / jointtarget from its aggregate code[start:end]."""
    line = line_of(code, start)
    found = numbers_in(code, start, end, file)
    count = 11 if kind == "pose" else 6
    if len(found) < count:
        raise InputError(
            f"{file}:{line}: {name}: {'robtarget' if kind == 'pose' else 'jointtarget'} with "
            f"{len(found)} numbers, expected at least {count}"
        )
    values = tuple(v for v, _ in found[: 7 if kind == "pose" else 6])
    spans = tuple(s for _, s in found[: 7 if kind == "pose" else 6])
    config = tuple(int(v) for v, _ in found[7:11]) if kind == "pose" else None
    return Target(name, file, line, kind, values, spans, configuration=config)


def _frame(kind: str, name: str, code: str, start: int, end: int, file: str) -> Frame:
    """A tooldata (tool in the flange) or wobjdata (uframe x oframe in the base)."""
    where = f"{file}:{line_of(code, start)}"
    head = code[start:end].lstrip("[ \t\r\n").upper()
    numbers = [v for v, _ in numbers_in(code, start, end, file)]
    if kind == "tooldata":
        if head.startswith("FALSE"):
            raise InputError(f"{where}: tooldata {name}: a stationary tool (robhold FALSE)")
        return Frame(name, pose_to_base(np.array([numbers[:7]]))[0], where)
    if head.startswith("TRUE"):
        raise InputError(f"{where}: wobjdata {name}: a work object held by the robot")
    if head.split(",")[1].strip() == "FALSE":
        raise InputError(f"{where}: wobjdata {name}: moved by a mechanical unit (ufmec)")
    uframe, oframe = pose_to_base(np.array([numbers[:7], numbers[7:14]]))
    return Frame(name, uframe @ oframe, where)


def read(path: Path) -> Program:
    """The module `path`."""
    name = Path(path).name
    text = read_text(path)
    code = blank_comments(text, "!")
    book = TargetBook()
    tools: dict[str, Frame] = {}
    bases: dict[str, Frame] = {}
    remarks: list[str] = []
    for m in _DECL.finditer(code):
        kind, declared = m.group(2).lower(), m.group(3)
        if code[m.end() : m.end() + 1] != "[":
            continue  # := another name or a function: not a literal
        end = _bracket_end(code, m.end(), f"{name}:{line_of(code, m.start())}")
        if kind in ("robtarget", "jointtarget"):
            form = "pose" if kind == "robtarget" else "joints"
            book.declare(_target(declared, form, code, m.end(), end, name))
        else:
            (tools if kind == "tooldata" else bases)[declared] = _frame(
                kind, declared, code, m.end(), end, name
            )
    for m in _MOTION.finditer(code):
        end = code.find(";", m.end())
        line = line_of(code, m.start())
        if end < 0:
            raise InputError(f"{name}:{line}: {m.group(1)} without its closing ';'")
        arguments = _split_arguments(code, m.end(), end)
        positional = [(a, b) for a, b in arguments if not code[a:b].strip().startswith("\\")]
        wobj = re.search(r"\\WObj\s*:=\s*(\w+)", code[m.end() : end], re.IGNORECASE)
        tool = code[slice(*positional[-1])].split("\\")[0].strip() if positional else "tool0"
        tool_key = None if tool.lower() == "tool0" else tool
        base_key = None if wobj is None or wobj.group(1).lower() == "wobj0" else wobj.group(1)
        count = 2 if m.group(1).lower() == "movec" else 1
        for a, b in positional[:count]:
            argument = code[a:b].split("\\")[0].strip()  # without \ID:= and the like
            if argument.startswith("["):
                start = code.index("[", a)
                kind = "joints" if m.group(1).lower() == "moveabsj" else "pose"
                target = book.inline_name(line_of(code, start))
                close = _bracket_end(code, start, name)
                book.declare(_target(target, kind, code, start, close, name))
                book.use(target, line, tool_key, base_key)
            elif re.fullmatch(r"\w+", argument):
                if not book.known(argument):
                    raise InputError(
                        f"{name}:{line}: {m.group(1)} to {argument}: no robtarget or jointtarget "
                        f"of that name declared in {name}"
                    )
                book.use(argument, line, tool_key, base_key)
            elif _EXPRESSION.match(argument):
                used = re.search(r"\(\s*(\w+)", argument)
                if used and book.known(used.group(1)):
                    book.use(used.group(1), line, tool_key, base_key)
                    remarks.append(
                        f"{name}:{line}: {argument[:40]} moves relative to {used.group(1)}: it "
                        f"gets {used.group(1)}'s correction"
                    )
                else:
                    remarks.append(f"{name}:{line}: {argument[:40]}: not compensated")
            else:
                remarks.append(f"{name}:{line}: {m.group(1)} to {argument[:40]}: not compensated")
    return Program("rapid", {name: text}, book.targets(), tools, bases, tuple(remarks))


def pose_to_base(values: Array) -> Array:
    """[x, y, z, q1, q2, q3, q4] (n, 7) [mm; q1 = w] -> (n, 4, 4) [m]."""
    values = np.atleast_2d(np.asarray(values, dtype=float))
    out = np.tile(np.eye(4), (len(values), 1, 1))
    out[:, :3, :3] = Rotation.from_quat(values[:, [4, 5, 6, 3]]).as_matrix()
    out[:, :3, 3] = values[:, :3] * 1e-3
    return out


def base_to_pose(poses: Array, old: Array) -> Array:
    """(n, 4, 4) [m] -> [x, y, z, q1..q4] (n, 7), each quaternion of the old one's sign."""
    xyzw = Rotation.from_matrix(poses[:, :3, :3]).as_quat()
    wxyz = xyzw[:, [3, 0, 1, 2]]
    flip = np.einsum("ni,ni->n", wxyz, np.asarray(old)[:, 3:7]) < 0.0
    wxyz[flip] *= -1.0
    return np.hstack([poses[:, :3, 3] * 1e3, wxyz])


def configuration(robot: RobotDescription, q: Array) -> list[tuple[int, ...]]:
    """ABB's confdata [cf1, cf4, cf6, cfx] of readings q (n, J) [rad]: the quadrants
    floor(angle / 90 deg) of axes 1, 4 and 6, and cfx = 4 x (wrist centre behind axis 1)
    + 2 x (behind the lower arm: the elbow not as at the calibration position) + (axis 5
    negative)."""
    pose = posture(robot, q, ZERO_DEG)
    quadrant = np.floor(pose.degrees[:, [0, 3, 5]] / 90.0).astype(int)
    cfx = (~pose.front) * 4 + (~pose.elbow) * 2 + (pose.degrees[:, 4] < 0.0)
    return [(*map(int, quad), int(x)) for quad, x in zip(quadrant, cfx)]


LANGUAGE = Language(
    name="rapid",
    title="ABB RAPID",
    suffixes=(".mod", ".modx"),
    read=read,
    pose_to_base=pose_to_base,
    base_to_pose=base_to_pose,
    joint_unit=np.pi / 180.0,
    pose_places=(4, 4, 4, 8, 8, 8, 8),
    joint_places=5,
    configuration=configuration,
    outputs=single_output,
)
