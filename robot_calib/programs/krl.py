"""KUKA KRL: a `.src` program and the `.dat` beside it (msgs_doc/programs.md#kuka-krl).

Targets: E6POS / POS / FRAME aggregates `{X, Y, Z, A, B, C[, S, T][, E1..]}` (mm, deg; the
orientation Rz(A) Ry(B) Rx(C)) and E6AXIS / AXIS `{A1 .. A6[, E1..]}` (deg), declared in
either file (`DECL E6POS XP1={...}`) or written inline in a motion (`PTP {A1 0, ...}`);
motions PTP, LIN, CIRC and their spline forms SPTP, SLIN, SCIRC. Frames: `$TOOL =
TOOL_DATA[n]`, `$BASE = BASE_DATA[n]`, `BAS(#TOOL, n)`, `BAS(#BASE, n)` and the inline
forms' `FDAT_ACT = FPn` (a `DECL FDAT FPn={TOOL_NO n, BASE_NO m, ...}`), in program order;
TOOL_DATA[n] / BASE_DATA[n] values written in the program (they usually live in
$config.dat: give them as options then). S and T: KUKA's status and turn (`configuration`).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from robot_calib.errors import InputError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.programs.configuration import posture
from robot_calib.programs.language import Language
from robot_calib.programs.source import (
    NUMBER,
    Frame,
    Program,
    Span,
    Target,
    TargetBook,
    base_to_euler,
    blank_comments,
    euler_to_base,
    line_of,
    read_text,
)

POSE_TYPES = ("E6POS", "POS", "FRAME")
AXIS_TYPES = ("E6AXIS", "AXIS")
POSE_KEYS = ("X", "Y", "Z", "A", "B", "C")
AXIS_KEYS = ("A1", "A2", "A3", "A4", "A5", "A6")
HOME_DEG = (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)  # KUKA's home: S bit 1 set (A3 >= phi)

_DECL = re.compile(
    r"\b(?:DECL\s+)?(?:GLOBAL\s+)?(" + "|".join(POSE_TYPES + AXIS_TYPES) + r")\s+(\w+)\s*=\s*\{",
    re.IGNORECASE,
)
_DATA = re.compile(r"\b(TOOL_DATA|BASE_DATA)\s*\[\s*(\d+)\s*\]\s*=\s*\{", re.IGNORECASE)
_FDAT = re.compile(r"\bDECL\s+(?:GLOBAL\s+)?FDAT\s+(\w+)\s*=\s*\{([^}]*)\}", re.IGNORECASE)
_COMPONENT = re.compile(r"(\w+)\s+('[BH][0-9A-F]+'|" + NUMBER + ")", re.IGNORECASE)
_MOTION = re.compile(
    r"\b(S?PTP|S?LIN|S?CIRC)(_REL)?\s+(\{[^}\n]*\}?|\$?\w+)(?:\s*,\s*(\{[^}\n]*\}?|\$?\w+))?",
    re.IGNORECASE,
)
_SETTINGS = re.compile(
    r"\$(TOOL|BASE)\s*=\s*(?:(TOOL_DATA|BASE_DATA)\s*\[\s*(\d+)\s*\]|(\$NULLFRAME))"
    r"|\bBAS\s*\(\s*#(TOOL|BASE)\s*,\s*(\d+)\s*\)"
    r"|\bFDAT_ACT\s*=\s*(\w+)",
    re.IGNORECASE,
)


def _number(text: str) -> float:
    """A KRL number: decimal, or a 'B0101' / 'H1F' literal."""
    if text.startswith("'"):
        return float(int(text[2:-1], 2 if text[1] in "bB" else 16))
    return float(text)


def _components(
    text: str, start: int, file: str, where: str
) -> tuple[dict[str, tuple[float, Span]], int]:
    """The components of the aggregate whose `{` ends at `start`: name -> (value, span),
    and the index of its `}`."""
    end, newline = text.find("}", start), text.find("\n", start)
    if end < 0 or 0 <= newline < end:
        raise InputError(f"{where}: aggregate without its closing '}}' on its line")
    out = {}
    for m in _COMPONENT.finditer(text, start, end):
        out[m.group(1).upper()] = (
            _number(m.group(2)),
            Span(file, m.start(2), m.end(2)),
        )
    return out, end


def _target(
    name: str, kind: str, parts: dict[str, tuple[float, Span]], file: str, line: int
) -> Target:
    """A target from an aggregate's components; a pose without all of X..C, or axes without
    A1..A6, is kept unchanged with a note (the controller fills the rest in)."""
    keys = POSE_KEYS if kind == "pose" else AXIS_KEYS
    missing = [k for k in keys if k not in parts]
    if missing:
        return Target(name, file, line, kind, (), (), note=f"no {', '.join(missing)}: partial")
    config = None
    if kind == "pose" and ("S" in parts or "T" in parts):
        config = tuple(int(parts[k][0]) if k in parts else -1 for k in ("S", "T"))
    return Target(
        name,
        file,
        line,
        kind,
        tuple(parts[k][0] for k in keys),
        tuple(parts[k][1] for k in keys),
        configuration=config,
    )


def _frame_of(parts: dict[str, tuple[float, Span]], key: str, where: str) -> Frame:
    values = np.array([[parts.get(k, (0.0, None))[0] for k in POSE_KEYS]])
    return Frame(key, pose_to_base(values)[0], where)


def read(path: Path) -> Program:
    """The program `path` (a .src) and its .dat (same name beside it, if any)."""
    path = Path(path)
    if path.suffix.lower() == ".dat":
        raise InputError(f"{path}: give the program's .src (its .dat is read beside it)")
    texts = {path.name: read_text(path)}
    for suffix in (".dat", ".DAT", ".Dat"):
        dat = path.with_suffix(suffix)
        if dat.exists():
            texts[dat.name] = read_text(dat)
            break
    book = TargetBook()
    tools: dict[str, Frame] = {}
    bases: dict[str, Frame] = {}
    fdat: dict[str, tuple[int, int, str]] = {}
    codes = {name: blank_comments(text, ";") for name, text in texts.items()}
    for name, code in codes.items():  # declarations, .dat first
        for m in _DECL.finditer(code):
            kind = "pose" if m.group(1).upper() in POSE_TYPES else "joints"
            where = f"{name}:{line_of(code, m.start())}"
            parts, _ = _components(code, m.end(), name, where)
            book.declare(_target(m.group(2), kind, parts, name, line_of(code, m.start())))
        for m in _DATA.finditer(code):
            key = f"{m.group(1).upper()}[{m.group(2)}]"
            where = f"{name}:{line_of(code, m.start())}"
            parts, _ = _components(code, m.end(), name, where)
            (tools if key.startswith("TOOL") else bases)[key] = _frame_of(parts, key, where)
        for m in _FDAT.finditer(code):
            body = m.group(2).upper()
            tool_no = re.search(r"TOOL_NO\s+(\d+)", body)
            base_no = re.search(r"BASE_NO\s+(\d+)", body)
            ipo = re.search(r"IPO_FRAME\s+#(\w+)", body)
            fdat[m.group(1).upper()] = (
                int(tool_no.group(1)) if tool_no else 0,
                int(base_no.group(1)) if base_no else 0,
                ipo.group(1) if ipo else "BASE",
            )
    src = path.name
    code = codes[src]
    tool: str | None = None
    base: str | None = None
    external = ""
    remarks = []
    events = sorted(
        [(m.start(), "set", m) for m in _SETTINGS.finditer(code)]
        + [(m.start(), "move", m) for m in _MOTION.finditer(code)],
        key=lambda e: e[0],
    )
    for _, kind, m in events:
        line = line_of(code, m.start())
        if kind == "set":
            if m.group(1):  # $TOOL = / $BASE =
                number = 0 if m.group(4) else int(m.group(3))
                chosen = f"{m.group(1).upper()}_DATA[{number}]" if number else None
                if m.group(1).upper() == "TOOL":
                    tool = chosen
                else:
                    base = chosen
            elif m.group(5):  # BAS(#TOOL, n)
                number = int(m.group(6))
                chosen = f"{m.group(5).upper()}_DATA[{number}]" if number else None
                if m.group(5).upper() == "TOOL":
                    tool = chosen
                else:
                    base = chosen
            elif m.group(7).upper() in fdat:
                tool_number, base_number, frame = fdat[m.group(7).upper()]
                tool = f"TOOL_DATA[{tool_number}]" if tool_number else None
                base = f"BASE_DATA[{base_number}]" if base_number else None
                external = "" if frame == "BASE" else f"IPO_FRAME #{frame} (a fixed tool)"
            continue
        relative = bool(m.group(2))
        for group in (3, 4):
            arg = m.group(group)
            if arg is None:
                continue
            if arg.startswith("{"):
                parts, _ = _components(code, m.start(group) + 1, src, f"{src}:{line}")
                kind_ = "joints" if any(k in parts for k in AXIS_KEYS) else "pose"
                name = book.inline_name(line)
                book.declare(_target(name, kind_, parts, src, line))
            else:
                name = arg
                if not book.known(name):
                    if name.startswith("$") or name.upper() in ("HOME", "XHOME"):
                        remarks.append(
                            f"{src}:{line}: {m.group(1).upper()} {name}, the controller's own "
                            "position (not in the program): not compensated"
                        )
                        continue
                    raise InputError(
                        f"{src}:{line}: {m.group(1).upper()} to {name}: no such position "
                        f"declared in {' or '.join(texts)}"
                    )
            book.use(name, line, tool, base)
            if relative:
                book.noted(name, f"{m.group(1).upper()}_REL: a relative motion")
            elif external:
                book.noted(name, external)
    return Program("krl", texts, book.targets(), tools, bases, tuple(remarks))


def pose_to_base(values: Array) -> Array:
    """{X, Y, Z, A, B, C} (n, 6) [mm, deg] -> (n, 4, 4) [m]; A about z, B about the new y,
    C about the newest x (Rz(A) Ry(B) Rx(C))."""
    return euler_to_base(values, "ZYX", 1e-3)


def base_to_pose(poses: Array, old: Array) -> Array:
    """(n, 4, 4) [m] -> {X, Y, Z, A, B, C} (n, 6) [mm, deg], angles within 180 deg of
    the old ones."""
    return base_to_euler(poses, old, "ZYX", 1e-3)


def configuration(robot: RobotDescription, q: Array) -> list[tuple[int, ...]]:
    """KUKA's (S, T) of readings q (n, J) [rad]: S bit 0 set in the overhead area (the
    wrist centre behind axis 1), bit 1 set where A3 >= phi (the elbow as at the home
    pose), bit 2 set where A5 is in (-180, 0) or [180, 360); T bit j set where axis j+1 is
    below 0 deg."""
    pose = posture(robot, q, HOME_DEG)
    a5 = pose.degrees[:, 4]
    bit2 = ((a5 < 0.0) & (a5 > -180.0)) | (a5 >= 180.0)
    status = (~pose.front) * 1 + pose.elbow * 2 + bit2 * 4
    return [(int(s), int(t)) for s, t in zip(status, turn_bits(pose.degrees))]


def turn_bits(readings_deg: Array) -> Array:
    """(n,) KUKA-style turn bits: bit j set where axis j+1 is below 0 deg."""
    below = np.asarray(readings_deg) < 0.0
    return (below * (1 << np.arange(below.shape[1]))).sum(axis=1)


def outputs(program: Program, output: Path) -> dict[str, Path]:
    """The .src to the output path, its .dat beside it with the same name."""
    out = {}
    for name in program.texts:
        suffix = Path(name).suffix
        out[name] = output if suffix.lower() == ".src" else output.with_suffix(suffix)
    return out


LANGUAGE = Language(
    name="krl",
    title="KUKA KRL",
    suffixes=(".src",),
    read=read,
    pose_to_base=pose_to_base,
    base_to_pose=base_to_pose,
    joint_unit=np.pi / 180.0,
    pose_places=(4, 4, 4, 5, 5, 5),
    joint_places=5,
    configuration=configuration,
    frame_keys=("TOOL_DATA[{}]", "BASE_DATA[{}]"),
    outputs=outputs,
)
