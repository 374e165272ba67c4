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
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from robot_calib.errors import InputError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array, homogeneous
from robot_calib.messages import QUATERNION_TOLERANCE
from robot_calib.programs.configuration import posture
from robot_calib.programs.language import Language, single_output
from robot_calib.programs.source import (
    LARGEST,
    Frame,
    Program,
    Span,
    Target,
    TargetBook,
    blank_comments,
    line_of,
    number,
    read_text,
)

ZERO_DEG = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # ABB's calibration position: cfx 0
NOT_USED = 9.1e9  # an external axis that is not used is written 9E9: allowed there

_DECL = re.compile(
    r"\b(?:(?:LOCAL|TASK)\s+)?(CONST|PERS|VAR)\s+(robtarget|jointtarget|tooldata|wobjdata)"
    r"\s+(\w+)\s*:=\s*",
    re.IGNORECASE,
)
_MOTION = re.compile(r"\b(MoveJ|MoveL|MoveC|MoveAbsJ)(DO|AO|GO|Sync)?(?=[\s\\,])", re.IGNORECASE)
#: an assignment to a declared target (or a part of it) in the program: it changes at
#: run time, its declared value is not what the robot goes to
_CHANGED = re.compile(r"\b(\w+)(?:\.\w+)*\s*:=", re.IGNORECASE)
_EXPRESSION = re.compile(r"\b(Offs|RelTool|CRobT|CJointT|CalcRobT|CalcJointT)\s*\(", re.I)


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


@dataclass(frozen=True)
class _Leaf:
    """A token of an aggregate and where it is written."""

    text: str
    start: int
    end: int
    line: int  # where it is written (an aggregate may span lines)


_Node = list["_Node | _Leaf"]


def _tree(code: str, start: int, where: str) -> tuple[_Node, int]:
    """The aggregate whose `[` is at `start` as nested lists of tokens, and the index after
    its `]`; InputError naming `where` for an empty token (',,') or a bracket not closed."""
    node: _Node = []
    k = start + 1
    token_start = k
    while k < len(code):
        char = code[k]
        if char == "[":
            child, k = _tree(code, k, where)
            node.append(child)
            token_start = k
            continue
        if char in ",]":
            token = code[token_start:k]
            if token.strip():
                lead = len(token) - len(token.lstrip())
                first = token_start + lead
                stripped = token.strip()
                node.append(_Leaf(stripped, first, first + len(stripped), line_of(code, first)))
            elif char == "," and (not node or code[token_start - 1] == ","):
                raise InputError(f"{where}: an empty value (',,')")
            if char == "]":
                return node, k + 1
            token_start = k + 1
        k += 1
    raise InputError(f"{where}: '[' without its closing ']'")


def _numbers(
    node: object, count: int, what: str, file: str, where: str, largest: float = LARGEST
) -> list[tuple[float, Span]]:
    """The `count` numbers of a list of numbers `node`; InputError naming `what` else."""
    if (
        not isinstance(node, list)
        or len(node) != count
        or not all(isinstance(n, _Leaf) for n in node)
    ):
        raise InputError(f"{where}: {what}: expected [{count} numbers]")
    return [
        (number(n.text, f"{file}:{n.line}", largest), Span(file, n.start, n.end))
        for n in node
        if isinstance(n, _Leaf)
    ]


def _pose(node: object, what: str, file: str, where: str) -> list[tuple[float, Span]]:
    """[[x, y, z], [q1, q2, q3, q4]]: 7 numbers, the quaternion of norm 1."""
    if not isinstance(node, list) or len(node) != 2:
        raise InputError(f"{where}: {what}: expected [[x,y,z],[q1,q2,q3,q4]]")
    out = _numbers(node[0], 3, f"{what} position", file, where)
    out += _numbers(node[1], 4, f"{what} orientation", file, where)
    norm = float(np.linalg.norm([v for v, _ in out[3:]]))
    if abs(norm - 1.0) > QUATERNION_TOLERANCE:
        raise InputError(f"{where}: {what}: quaternion of norm {norm:.6g}, not 1")
    return out


def _target(name: str, kind: str, code: str, start: int, file: str) -> Target:
    """A robtarget [[x,y,z],[q1..q4],[cf1,cf4,cf6,cfx],[eax_a..eax_f]] or jointtarget
    [[j1..j6],[eax_a..eax_f]] from its aggregate at `start`."""
    line = line_of(code, start)
    where = f"{file}:{line}"
    tree, _ = _tree(code, start, where)
    what = f"{name}: {'robtarget' if kind == 'pose' else 'jointtarget'}"
    if kind == "pose":
        if len(tree) != 4:
            raise InputError(
                f"{where}: {what}: expected [[x,y,z],[q1..q4],[cf1,cf4,cf6,cfx],[eax]]"
            )
        found = _pose(tree[:2], what, file, where)
        config = _numbers(tree[2], 4, f"{what} robconf", file, where)
        _numbers(tree[3], 6, f"{what} extax", file, where, NOT_USED)
        configuration: tuple[int, ...] | None = tuple(int(v) for v, _ in config)
    else:
        if len(tree) != 2:
            raise InputError(f"{where}: {what}: expected [[j1..j6],[eax_a..eax_f]]")
        found = _numbers(tree[0], 6, what, file, where)
        _numbers(tree[1], 6, f"{what} extax", file, where, NOT_USED)
        configuration = None
    return Target(
        name,
        file,
        line,
        kind,
        tuple(v for v, _ in found),
        tuple(s for _, s in found),
        configuration=configuration,
    )


def _flag(node: object, what: str, where: str) -> bool:
    if not isinstance(node, _Leaf) or node.text.upper() not in ("TRUE", "FALSE"):
        raise InputError(f"{where}: {what}: expected TRUE or FALSE")
    return node.text.upper() == "TRUE"


def _frame(kind: str, name: str, code: str, start: int, file: str) -> Frame:
    """A tooldata [robhold, [[x,y,z],[q]], load] (the tool in the flange) or wobjdata
    [robhold, ufprog, ufmec, [[uframe]], [[oframe]]] (uframe x oframe in the base)."""
    where = f"{file}:{line_of(code, start)}"
    tree, _ = _tree(code, start, where)
    what = f"{kind} {name}"
    if kind == "tooldata":
        if len(tree) != 3:
            raise InputError(f"{where}: {what}: expected [robhold,[[x,y,z],[q1..q4]],load]")
        if not _flag(tree[0], what, where):
            raise InputError(f"{where}: {what}: a stationary tool (robhold FALSE)")
        values = [v for v, _ in _pose(tree[1], what, file, where)]
        return Frame(name, pose_to_base(np.array([values]))[0], where)
    if len(tree) != 5:
        raise InputError(f"{where}: {what}: expected [robhold,ufprog,ufmec,[uframe],[oframe]]")
    if _flag(tree[0], what, where):
        raise InputError(f"{where}: {what}: a work object held by the robot (robhold TRUE)")
    if not _flag(tree[1], what, where):
        raise InputError(f"{where}: {what}: moved by a mechanical unit (ufprog FALSE)")
    uframe = [v for v, _ in _pose(tree[3], f"{what} uframe", file, where)]
    oframe = [v for v, _ in _pose(tree[4], f"{what} oframe", file, where)]
    both = pose_to_base(np.array([uframe, oframe]))
    return Frame(name, both[0] @ both[1], where)


def read(path: Path) -> Program:
    """The module `path`."""
    name = Path(path).name
    text, encoding = read_text(path)
    code = blank_comments(text, "!")
    book = TargetBook()
    tools: dict[str, Frame] = {}
    bases: dict[str, Frame] = {}
    remarks: list[str] = []
    relative: list[tuple[int, str, str]] = []  # motions through Offs(p, ...) and the like
    for m in _DECL.finditer(code):
        kind, declared = m.group(2).lower(), m.group(3)
        if code[m.end() : m.end() + 1] != "[":
            continue  # := another name or a function: not a literal
        if kind in ("robtarget", "jointtarget"):
            form = "pose" if kind == "robtarget" else "joints"
            if book.known(declared):
                raise InputError(f"{name}:{line_of(code, m.start())}: {declared} declared twice")
            book.declare(_target(declared, form, code, m.end(), name))
        else:
            (tools if kind == "tooldata" else bases)[declared.lower()] = _frame(
                kind, declared, code, m.end(), name
            )
    for m in _MOTION.finditer(code):
        end = code.find(";", m.end())
        line = line_of(code, m.start())
        instruction = m.group(1) + (m.group(2) or "")
        if end < 0:
            raise InputError(f"{name}:{line}: {instruction} without its closing ';'")
        arguments = _split_arguments(code, m.end(), end)
        positional = [(a, b) for a, b in arguments if not code[a:b].strip().startswith("\\")]
        circular = m.group(1).lower() == "movec"
        at_tool = 4 if circular else 3  # ToPoint (CirPoint), Speed, Zone, Tool
        if len(positional) <= at_tool:
            raise InputError(
                f"{name}:{line}: {instruction} with {len(positional)} arguments: no tool "
                f"(argument {at_tool + 1})"
            )
        tool = code[slice(*positional[at_tool])].split("\\")[0].strip()
        if not re.fullmatch(r"\w+", tool):
            raise InputError(
                f"{name}:{line}: {instruction}: tool {tool[:30]!r} is no tooldata name"
            )
        wobj = re.search(r"\\WObj\s*:=\s*(\w+)", code[m.end() : end], re.IGNORECASE)
        tool_key = None if tool.lower() == "tool0" else tool.lower()
        base_key = (
            None if wobj is None or wobj.group(1).lower() == "wobj0" else wobj.group(1).lower()
        )
        for a, b in positional[: 2 if circular else 1]:
            argument = code[a:b].split("\\")[0].strip()  # without \ID:= and the like
            if argument.startswith("["):
                start = code.index("[", a)
                kind = "joints" if m.group(1).lower() == "moveabsj" else "pose"
                target = book.inline_name(line_of(code, start))
                book.declare(_target(target, kind, code, start, name))
                book.use(target, line, tool_key, base_key)
            elif re.fullmatch(r"\w+", argument):
                if not book.known(argument):
                    raise InputError(
                        f"{name}:{line}: {instruction} to {argument}: no robtarget or "
                        f"jointtarget of that name declared in {name}"
                    )
                book.use(argument, line, tool_key, base_key)
            elif _EXPRESSION.match(argument):
                used = re.search(r"\(\s*(\w+)", argument)
                relative.append((line, argument[:40], used.group(1) if used else ""))
            else:
                remarks.append(f"{name}:{line}: {instruction} to {argument[:40]}: not compensated")
    declared_at = {m.start(3) for m in _DECL.finditer(code)}
    for m in _CHANGED.finditer(code):  # a target changed while the program runs
        if m.start(1) in declared_at:
            continue
        where = f"{name}:{line_of(code, m.start())}"
        if m.group(1).lower() in tools or m.group(1).lower() in bases:
            raise InputError(
                f"{where}: {m.group(1)} changed at run time: the frame a motion uses is not "
                "known here"
            )
        if book.known(m.group(1)):
            book.noted(m.group(1), f"changed at run time on line {line_of(code, m.start())}")
    for line, argument, inner in relative:  # Offs(p, ...): p's correction if p is compensated
        moved = book.known(inner) and bool(book.get(inner).used) and not book.get(inner).note
        remarks.append(
            f"{name}:{line}: {argument} moves relative to {inner}: it gets {inner}'s correction"
            if moved
            else f"{name}:{line}: {argument}: not compensated"
        )
    book.referenced(code, name, declared_at)
    return Program(
        "rapid", {name: text}, book.targets(), tools, bases, tuple(remarks), {name: encoding}
    )


def pose_to_base(values: Array) -> Array:
    """[x, y, z, q1, q2, q3, q4] (n, 7) [mm; q1 = w] -> (n, 4, 4) [m]."""
    values = np.atleast_2d(np.asarray(values, dtype=float))
    return homogeneous(
        Rotation.from_quat(values[:, [4, 5, 6, 3]]).as_matrix(), values[:, :3] * 1e-3
    )


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
    vendor="ABB",
    fold_keys=True,
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
