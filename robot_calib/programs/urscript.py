"""Universal Robots URScript: a `.script` program (msgs_doc/programs.md#universal-robots-urscript).

Targets: `movej`, `movel`, `movep` to a pose `p[x, y, z, rx, ry, rz]` (m; a rotation
vector [rad]) or to joint positions `[q1, .., q6]` (rad), and `movec(via, to, ...)`,
written in the motion or in a variable assigned before it (`name = p[...]`, also
`global`; a motion uses the variable's last assignment above it). Frames: the tool set by
`set_tcp(p[...])` above a motion; poses are in the robot's base frame. A target given by
an expression (`pose_trans(...)`, `get_inverse_kin(...)`) is left as it is and named.
URScript targets carry no configuration: the controller takes the solution nearest the
arm's pose before the motion, as `compensate` follows the program's rows.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from robot_calib.errors import InputError
from robot_calib.kinematics.frames import Array, homogeneous
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

_LITERAL = r"(p?)\[([^\[\]]*)\]"
_ASSIGN = re.compile(
    r"^[ \t]*(?:(?:global|local)[ \t]+)?(\w+)[ \t]*=[ \t]*" + _LITERAL + r"[ \t\r]*$", re.MULTILINE
)
#: a variable set to anything but a literal (a pose from pose_trans(...), a function's)
_OTHER = re.compile(
    r"^[ \t]*(?:(?:global|local)[ \t]+)?(\w+)[ \t]*=(?!=)[ \t]*(?=\S)(?!p?\[[^\[\]]*\][ \t\r]*$)",
    re.MULTILINE,
)
_ELEMENT = re.compile(r"^[ \t]*(\w+)\s*\[[^\]]*\]\s*=(?!=)", re.MULTILINE)
_MOTION = re.compile(r"\b(movej|movel|movep|movec)\s*\(")
_TCP = re.compile(r"\bset_tcp\s*\(\s*(?:p\[([^\[\]]*)\]|(\w+)\s*\))")


def _literal(name: str, pose: bool, code: str, start: int, end: int, file: str) -> Target:
    """A target from the numbers of a `p[...]` (pose) or `[...]` (joints) at [start, end)."""
    line = line_of(code, start)
    found = numbers_in(code, start, end, file)
    if len(found) != 6:
        raise InputError(
            f"{file}:{line}: {name}: {'p' if pose else ''}[...] with {len(found)} numbers, "
            "expected 6"
        )
    return Target(
        name,
        file,
        line,
        "pose" if pose else "joints",
        tuple(v for v, _ in found),
        tuple(s for _, s in found),
    )


def _call(code: str, start: int) -> str:
    """The expression starting at `start` up to its balanced end (a ',' or ')' at depth 0)."""
    depth = 0
    for k in range(start, len(code)):
        if code[k] in "([":
            depth += 1
        elif code[k] in ")]":
            if depth == 0:
                return code[start:k].strip()
            depth -= 1
        elif code[k] in ",\n" and depth == 0:
            return code[start:k].strip()
    return code[start:].strip()


def read(path: Path) -> Program:
    """The script `path`."""
    name = Path(path).name
    text, encoding = read_text(path)
    code = blank_comments(text, "#")
    book = TargetBook()
    tools: dict[str, Frame] = {}
    events = sorted(
        [(m.start(), "assign", m) for m in _ASSIGN.finditer(code)]
        + [(m.start(), "other", m) for m in _OTHER.finditer(code)]
        + [(m.start(), "element", m) for m in _ELEMENT.finditer(code)]
        + [(m.start(), "move", m) for m in _MOTION.finditer(code)]
        + [(m.start(), "tcp", m) for m in _TCP.finditer(code)],
        key=lambda e: e[0],
    )
    current: dict[str, str | None] = {}  # variable -> its last literal's target (None: other)
    remarks = []
    relative: list[tuple[int, str, str, str]] = []  # motions to pose_trans(p, ...) and alike
    tool = None
    for _, kind, m in events:
        line = line_of(code, m.start())
        if kind in ("assign", "other"):
            before = current.get(m.group(1))
            if before is not None and book.get(before).used:  # moved to, then set again
                book.noted(before, f"its variable set again on line {line} (in a loop?)")
        if kind == "assign":
            key = f"{m.group(1)} (line {line})"
            book.declare(_literal(key, bool(m.group(2)), code, m.start(3), m.end(3), name))
            current[m.group(1)] = key
        elif kind == "other":
            current[m.group(1)] = None  # set to an expression: no literal of the program
        elif kind == "element":
            known = current.get(m.group(1))
            if known is not None:
                book.noted(known, f"an element changed at run time on line {line}")
        elif kind == "tcp":
            tool = f"set_tcp (line {line})"
            if m.group(1) is not None:
                found = [v for v, _ in numbers_in(code, m.start(1), m.end(1), name)]
            else:
                variable = current.get(m.group(2))
                if variable is None or book.get(variable).kind != "pose":
                    raise InputError(
                        f"{name}:{line}: set_tcp({m.group(2)}): not a p[...] assigned above"
                    )
                found = list(book.get(variable).values)
            if len(found) != 6:
                raise InputError(f"{name}:{line}: set_tcp(p[...]) with {len(found)} numbers")
            tools[tool] = Frame(tool, pose_to_base(np.array([found]))[0], f"{name}:{line}")
        else:
            count = 2 if m.group(1) == "movec" else 1
            at = m.end()
            for _ in range(count):
                argument = re.match(r"\s*(?:" + _LITERAL + r"|(\w+)\s*(?=[,)])|)", code[at:])
                assert argument is not None  # the pattern matches the empty string
                if argument.group(2) is not None:
                    start = at + argument.start(2)
                    key = book.inline_name(line_of(code, start))
                    close, pose = at + argument.end(2), bool(argument.group(1))
                    book.declare(_literal(key, pose, code, start, close, name))
                    book.use(key, line, tool, None)
                elif argument.group(3) is not None:
                    variable = argument.group(3)
                    if variable not in current:
                        raise InputError(
                            f"{name}:{line}: {m.group(1)} to {variable}: not assigned a p[...] "
                            "or [...] above this line"
                        )
                    target = current[variable]
                    if target is None:
                        remarks.append(
                            f"{name}:{line}: {m.group(1)} to {variable}, set by an expression: "
                            "not compensated"
                        )
                    else:
                        book.use(target, line, tool, None)
                else:
                    shown = _call(code, at)[:60]
                    inner = re.match(r"\s*\w+\s*\(\s*(\w+)\s*,", shown)
                    relative.append((line, m.group(1), shown, inner.group(1) if inner else ""))
                    break
                comma = code.find(",", at + argument.end())
                at = comma + 1 if comma >= 0 else len(code)
    for line, motion, shown, base in relative:  # pose_trans(p, ...): p's correction
        target = current.get(base)
        moved = target is not None and bool(book.get(target).used) and not book.get(target).note
        remarks.append(
            f"{name}:{line}: {motion} to {shown} moves relative to {base}: it gets {base}'s "
            "correction"
            if moved
            else f"{name}:{line}: {motion} to {shown}: not compensated"
        )
    for m in re.finditer(r"\bset_tcp\s*\(", code):
        if not _TCP.match(code, m.start()):
            raise InputError(
                f"{name}:{line_of(code, m.start())}: set_tcp({_call(code, m.end())[:40]}): a "
                "TCP this reader cannot resolve (p[...] or a variable assigned one)"
            )
    declared_at = {m.start(1) for m in _ASSIGN.finditer(code)} | {
        m.start(1) for m in _OTHER.finditer(code)
    }
    declared_at |= {m.start(2) for m in _TCP.finditer(code) if m.group(2)}
    book.referenced(code, name, declared_at)
    return Program(
        "urscript", {name: text}, book.targets(), tools, {}, tuple(remarks), {name: encoding}
    )


def pose_to_base(values: Array) -> Array:
    """p[x, y, z, rx, ry, rz] (n, 6) [m, rad; a rotation vector] -> (n, 4, 4) [m]."""
    values = np.atleast_2d(np.asarray(values, dtype=float))
    return homogeneous(Rotation.from_rotvec(values[:, 3:6]).as_matrix(), values[:, :3])


def base_to_pose(poses: Array, old: Array) -> Array:
    """(n, 4, 4) [m] -> p[x, y, z, rx, ry, rz] (n, 6): of the rotation vector's two
    forms near a half turn (angle t about u, or t - 2 pi about u), the one nearer the old."""
    vector = Rotation.from_matrix(poses[:, :3, :3]).as_rotvec()
    angle = np.linalg.norm(vector, axis=1, keepdims=True)
    other = vector * (1.0 - 2.0 * np.pi / np.where(angle > 0.0, angle, 1.0))
    old = np.asarray(old)[:, 3:6]
    nearer = np.linalg.norm(other - old, axis=1) < np.linalg.norm(vector - old, axis=1)
    vector[nearer] = other[nearer]
    return np.hstack([poses[:, :3, 3], vector])


LANGUAGE = Language(
    vendor="Universal Robots",
    name="urscript",
    title="Universal Robots URScript",
    suffixes=(".script", ".urscript"),
    read=read,
    pose_to_base=pose_to_base,
    base_to_pose=base_to_pose,
    joint_unit=1.0,
    pose_places=(7, 7, 7, 7, 7, 7),
    joint_places=7,
    configuration=None,
    outputs=single_output,
)
