"""FANUC TP: an ASCII `.ls` program (msgs_doc/programs.md#fanuc-tp).

Targets: the /POS section's `P[n]` (or `P[n:"comment"]`) group 1 data: `UF : u, UT : t,
CONFIG : 'F|N U|D T|B, t1, t4, t6', X, Y, Z [mm], W, P, R [deg]` (the orientation
Rz(R) Ry(P) Rx(W), fixed axes) or `J1= .. J6=` [deg]; other groups (extended axes) are
left as they are. Motions in /MN: `J`, `L`, `C` (two positions, the second on the
continuation line) and `A` to `P[n]`; motions to position registers `PR[n]` hold no
target in the program and are named as not compensated. Frames: UF n and UT n (0: the
world frame, the robot base, and the faceplate); their values are the controller's
system variables, not in the .ls: give them as options.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from robot_calib.errors import InputError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.programs.configuration import posture
from robot_calib.programs.language import Language, single_output
from robot_calib.programs.source import (
    Program,
    Span,
    Target,
    TargetBook,
    base_to_euler,
    blank_comments,
    euler_to_base,
    line_of,
    number,
    read_text,
)

ZERO_DEG = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # FANUC's zero position: 'U' and 'T'

_POSITION = re.compile(r'^\s*P\[(\d+)(?::"[^"]*")?\]\s*\{', re.MULTILINE)
_GROUP = re.compile(r"\bGP(\d+)\s*:")
_CONFIG = re.compile(r"CONFIG\s*:\s*'([^']*)'")
#: a motion instruction's position: 'N:J P[n] ...' or the continuation line ':  P[n]' of a
#: circular motion (an assignment 'PR[2]=P[1]' is no motion)
_MOTION = re.compile(
    r"^\s*(?:\d+\s*:\s*([JLCA])\s+|:\s*)(P|PR)\[(\d+|\w+\[\d+\])(?::[^\]]*)?\]", re.MULTILINE
)
POSE_KEYS = ("X", "Y", "Z", "W", "P", "R")
AXIS_KEYS = ("J1", "J2", "J3", "J4", "J5", "J6")


def _section(text: str, name: str) -> tuple[int, int]:
    """The [start, end) of section /NAME (up to the next /SECTION line or the end)."""
    found = re.search(rf"^/{name}\b[^\n]*\n", text, re.MULTILINE)
    if found is None:
        return len(text), len(text)
    after = re.search(r"^/[A-Z]+\b", text[found.end() :], re.MULTILINE)
    return found.end(), found.end() + (after.start() if after else len(text) - found.end())


def _config(text: str, where: str) -> tuple[int, ...]:
    """'N U T, 0, 0, 0' -> (flip, up, front, t1, t4, t6) with F, U, T as 1."""
    parts = [p.strip() for p in text.replace(",", " ").split()]
    letters = [p for p in parts if p.isalpha()]
    turns = [int(p) for p in parts if re.fullmatch(r"[-+]?\d+", p)]
    if len(letters) != 3 or any(len(p) != 1 for p in letters) or len(turns) != 3:
        raise InputError(f"{where}: CONFIG '{text}': expected 'N|F U|D T|B, t1, t4, t6'")
    flip, up, front = (p.upper() for p in letters)
    if flip not in "NF" or up not in "UD" or front not in "TB":
        raise InputError(f"{where}: CONFIG '{text}': expected 'N|F U|D T|B, t1, t4, t6'")
    return (int(flip == "F"), int(up == "U"), int(front == "T"), *(turns + [0, 0, 0])[:3])


def _body(text: str, start: int, end: int, file: str, where: str) -> dict[str, tuple[float, Span]]:
    """The components of a position's group 1, text[start:end]: 'UF : u', 'UT : t',
    'CONFIG : ...', 'X = v mm' (X, Y, Z), 'W = v deg' (W, P, R), 'Jn = v deg' or 'En = v
    mm|deg', separated by commas; InputError naming `where` for anything else, a component
    given twice or a number that is none."""
    code = _CONFIG.sub(lambda c: " " * len(c.group()), text[start:end])  # its commas
    out: dict[str, tuple[float, Span]] = {}
    at = start
    for piece in code.split(","):
        part = re.fullmatch(r"\s*(UF|UT)\s*:\s*(\S+)\s*|\s*(\w+)\s*=\s*(\S+)\s*(\w+)\s*", piece)
        if piece.strip() and part is None:
            raise InputError(f"{where}: {piece.strip()[:30]!r}: expected NAME = value unit")
        if part is not None:
            key = part.group(1) or part.group(3)
            value_group = 2 if part.group(1) else 4
            unit = part.group(5)
            expected = _UNITS.get(key[0] if key[0] in "JE" else key)
            if expected is None or (unit is not None and unit not in expected):
                raise InputError(
                    f"{where}: {piece.strip()[:30]!r}: expected "
                    + (f"{key} in {' or '.join(expected)}" if expected else "a known component")
                )
            if key in out:
                raise InputError(f"{where}: {key} given twice")
            at_value = at + part.start(value_group)
            value = number(part.group(value_group), f"{file}:{line_of(text, at_value)}")
            span = Span(file, at + part.start(value_group), at + part.end(value_group))
            out[key] = (value, span)
        at += len(piece) + 1
    return out


#: each component's unit(s): positions in mm, angles in deg; axes in deg (E: mm or deg)
_UNITS = {
    "UF": ("",),
    "UT": ("",),
    "X": ("mm",),
    "Y": ("mm",),
    "Z": ("mm",),
    "W": ("deg",),
    "P": ("deg",),
    "R": ("deg",),
    "J": ("deg",),
    "E": ("mm", "deg"),
}


def read(path: Path) -> Program:
    """The program `path` (.ls)."""
    name = Path(path).name
    text, encoding = read_text(path)
    book = TargetBook()
    start, end = _section(text, "POS")
    for m in _POSITION.finditer(text, start, end):
        close = text.find("};", m.end(), end)
        line = line_of(text, m.start())
        label = f"P[{m.group(1)}]"
        where = f"{name}:{line}"
        if close < 0:
            raise InputError(f"{where}: {label} without its closing '}};'")
        groups = list(_GROUP.finditer(text, m.end(), close))
        if not groups or groups[0].group(1) != "1":
            raise InputError(f"{where}: {label} has no group 1 (GP1:)")
        body_end = groups[1].start() if len(groups) > 1 else close
        parts = _body(text, groups[0].end(), body_end, name, where)
        if "UF" not in parts or "UT" not in parts:
            raise InputError(f"{where}: {label} has no 'UF : u, UT : t'")
        keys = POSE_KEYS if "X" in parts else AXIS_KEYS
        missing = [k for k in keys if k not in parts]
        if missing:
            raise InputError(f"{where}: {label} lacks {', '.join(missing)}")
        config = _CONFIG.search(text, groups[0].end(), body_end)
        uf, ut = int(parts["UF"][0]), int(parts["UT"][0])
        if book.known(label):
            raise InputError(f"{where}: {label} declared twice")
        book.declare(
            Target(
                label,
                name,
                line,
                "pose" if keys == POSE_KEYS else "joints",
                tuple(parts[k][0] for k in keys),
                tuple(parts[k][1] for k in keys),
                configuration=_config(config.group(1), where) if config else None,
                tool=f"UT {ut}" if ut else None,
                base=f"UF {uf}" if uf else None,
            )
        )
    remarks = []
    start, end = _section(text, "MN")
    for m in _MOTION.finditer(text, start, end):
        line = line_of(text, m.start())
        index = m.group(3)
        if m.group(2) == "PR" or not index.isdigit():
            what = (
                "a position register (not in the program)"
                if m.group(2) == "PR"
                else ("an indirect position")
            )
            remarks.append(
                f"{name}:{line}: a motion to {m.group(2)}[{index}], {what}: not compensated"
            )
            continue
        label = f"P[{index}]"
        if not book.known(label):
            raise InputError(f"{name}:{line}: a motion to {label}: not in the /POS section")
        target = book.get(label)
        book.use(label, line, target.tool, target.base)
        rest = text[m.end() : text.find("\n", m.end())]
        if re.search(r"\bINC\b", rest):
            book.noted(label, f"an incremental motion (INC) on line {line}")
        elif re.search(r"\b(Offset|Tool_Offset|VOFFSET)\b", rest, re.IGNORECASE):
            remarks.append(
                f"{name}:{line}: a motion to {label} with an offset: it gets {label}'s correction"
            )
    pos_start, _ = _section(text, "POS")  # the /MN and what precedes it
    book.referenced(blank_comments(text[:pos_start], "!"), name, set())  # PR[2]=P[1] and alike
    return Program(
        "fanuc_tp",
        {name: text},
        book.targets(),
        remarks=tuple(remarks),
        encodings={name: encoding},
    )


def pose_to_base(values: Array) -> Array:
    """X, Y, Z, W, P, R (n, 6) [mm, deg] -> (n, 4, 4) [m]: Rz(R) Ry(P) Rx(W)."""
    return euler_to_base(values, "xyz", 1e-3)


def base_to_pose(poses: Array, old: Array) -> Array:
    """(n, 4, 4) [m] -> X, Y, Z, W, P, R (n, 6), angles within 180 deg of the old ones."""
    return base_to_euler(poses, old, "xyz", 1e-3)


def configuration(robot: RobotDescription, q: Array) -> list[tuple[int, ...]]:
    """FANUC's CONFIG of readings q (n, J) [rad] as (flip, up, front, t1, t4, t6): F where
    J5 > 0, U with the elbow as at the zero position, T with the wrist centre in front of
    J1; the turn numbers of J1, J4, J6 (0 for (-180, 180] deg, 1 for (180, 540], ...)."""
    pose = posture(robot, q, ZERO_DEG)
    turns = np.ceil((pose.degrees[:, [0, 3, 5]] - 180.0) / 360.0).astype(int)
    flip = pose.degrees[:, 4] > 0.0
    return [
        (int(f), int(u), int(t), *map(int, turn))
        for f, u, t, turn in zip(flip, pose.elbow, pose.front, turns)
    ]


LANGUAGE = Language(
    vendor="FANUC",
    name="fanuc_tp",
    title="FANUC TP",
    suffixes=(".ls",),
    read=read,
    pose_to_base=pose_to_base,
    base_to_pose=base_to_pose,
    joint_unit=np.pi / 180.0,
    pose_places=(3, 3, 3, 4, 4, 4),
    joint_places=4,
    configuration=configuration,
    frame_keys=("UT {}", "UF {}"),
    outputs=single_output,
)
