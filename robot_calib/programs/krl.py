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

from robot_calib.errors import InputError, param
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.programs.configuration import posture
from robot_calib.programs.language import Language
from robot_calib.programs.source import (
    OUTSIDE,
    Frame,
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
_MOTION = re.compile(r"\b(S?PTP|S?LIN|S?CIRC)(_REL)?\b[ \t]*([^\r\n]*)", re.IGNORECASE)
_ARGUMENT = re.compile(r"\s*(\{[^}\n]*\}?|\$?\w+(?:\s*\[[^\]]*\])?)(\s*:)?")
#: $TOOL / $BASE set to a frame: TOOL_DATA[n], BASE_DATA[n], $NULLFRAME, STOOL2(FPn),
#: SBASE(FPn.BASE_NO); anything else is refused (a frame the reader cannot resolve)
_ASSIGN = re.compile(r"\$(TOOL|BASE)\s*=\s*([^,\r\n;]*)", re.IGNORECASE)
_FRAME_VALUE = re.compile(
    r"(?:(TOOL_DATA|BASE_DATA)\s*\[\s*(\d+)\s*\]|(\$NULLFRAME)"
    r"|(?:STOOL2|SBASE)\s*\(\s*(\w+)(?:\.\w+)?\s*\))\s*$",
    re.IGNORECASE,
)
#: an assignment in the .src to a declared position or one of its components
_CHANGED = re.compile(r"^[ \t]*(\w+)(?:\.\w+)?[ \t]*=(?!=)", re.MULTILINE)
_BAS_OTHER = re.compile(r"\bBAS\s*\(\s*#(?:TOOL|BASE)\s*,\s*(?!\d+\s*\))[^)]*\)", re.I)
_SETTINGS = re.compile(
    r"\bBAS\s*\(\s*#(TOOL|BASE)\s*,\s*(\d+)\s*\)|\bFDAT_ACT\s*=\s*(\w+)", re.IGNORECASE
)


def _number(token: str, where: str) -> float:
    """A KRL number: decimal, or a 'B0101' / 'H1F' literal (S and T are written so)."""
    literal = re.fullmatch(r"'([BH])([0-9A-F]+)'", token.strip(), re.IGNORECASE)
    if literal:
        base = 2 if literal.group(1).upper() == "B" else 16
        try:
            return float(int(literal.group(2), base))
        except ValueError:
            raise InputError(f"{where}: {token.strip()} is not a binary or hex number") from None
    return number(token, where)


def _components(text: str, start: int, file: str) -> tuple[dict[str, tuple[float, Span]], int]:
    """The components of the aggregate whose `{` ends at `start`: name -> (value, span),
    and the index of its `}`; InputError naming the line for a component that is not
    `NAME number`, twice given, or an aggregate not closed on its line."""
    where = f"{file}:{line_of(text, start)}"
    end, newline = text.find("}", start), text.find("\n", start)
    if end < 0 or 0 <= newline < end:
        raise InputError(f"{where}: aggregate without its closing '}}' on its line")
    out: dict[str, tuple[float, Span]] = {}
    at = start
    for piece in text[start:end].split(","):
        part = re.fullmatch(r"\s*(\w+)(\[\])?\s+(\S+)\s*", piece)
        if piece.strip() and part is None:
            if re.fullmatch(r"\s*\w+\[\]\s*\"[^\"]*\"\s*", piece):  # POINT2[] " "
                at += len(piece) + 1
                continue
            raise InputError(f"{where}: {piece.strip()[:30]!r}: expected NAME value")
        if part is not None:
            name = part.group(1).upper()
            if name in out:
                raise InputError(f"{where}: component {name} given twice")
            if part.group(2) is None:
                value = _number(part.group(3), where)
                out[name] = (value, Span(file, at + part.start(3), at + part.end(3)))
        at += len(piece) + 1
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
    missing = [k for k in POSE_KEYS if k not in parts]
    if missing:  # KRL keeps the old value of a component left out: unknown here
        raise InputError(f"{where}: {key} without {', '.join(missing)}")
    values = np.array([[parts[k][0] for k in POSE_KEYS]])
    return Frame(key, pose_to_base(values)[0], where)


class _Frames:
    """The tool and base in force while the .src is read in program order."""

    def __init__(self, fdat: dict[str, tuple[int, int, str]], src: str, code: str) -> None:
        self.fdat, self.src, self.code = fdat, src, code
        self.tool: str | None = None
        self.base: str | None = None
        self.external = ""

    def key(self, kind: str, number: int) -> str | None:
        return f"{kind.upper()}_DATA[{number}]" if number else None

    def from_fdat(self, name: str, line: int) -> tuple[str | None, str | None]:
        """The tool and base of FDAT `name`; one declared elsewhere ($config.dat's FHOME)
        gives keys no frame has: a target moved to with them is refused by name."""
        if name.upper() not in self.fdat:
            self.external = ""
            return f"of FDAT {name} ({OUTSIDE})", f"of FDAT {name} ({OUTSIDE})"
        tool_no, base_no, frame = self.fdat[name.upper()]
        self.external = "" if frame == "BASE" else f"IPO_FRAME #{frame} (a fixed tool)"
        return self.key("TOOL", tool_no), self.key("BASE", base_no)

    def value(self, which: str, text: str, line: int) -> str | None:
        """The key of `$TOOL = text` / `$BASE = text`; InputError when unresolvable."""
        found = _FRAME_VALUE.match(text.strip())
        if found is None:
            raise InputError(
                f"{self.src}:{line}: ${which.upper()} = {text.strip()[:40]}: a frame this "
                "reader cannot resolve (TOOL_DATA[n], BASE_DATA[n], STOOL2(FPn) or "
                "SBASE(FPn.BASE_NO) only)"
            )
        if found.group(3):
            return None
        if found.group(4):
            tool, base = self.from_fdat(found.group(4), line)
            return tool if which.upper() == "TOOL" else base
        if found.group(1).upper()[:4] != which.upper():
            raise InputError(f"{self.src}:{line}: ${which.upper()} = {found.group(1).upper()}")
        return self.key(which, int(found.group(2)))

    def assign(self, which: str, text: str, line: int) -> None:
        if which.upper() == "TOOL":
            self.tool = self.value(which, text, line)
        else:
            self.base = self.value(which, text, line)


def read(path: Path) -> Program:
    """The program `path` (a .src) and its .dat (same name beside it, if any)."""
    path = Path(path)
    if path.suffix.lower() == ".dat":
        raise InputError(f"{path}: give the program's .src (its .dat is read beside it)")
    texts, encodings = {}, {}
    texts[path.name], encodings[path.name] = read_text(path)
    for suffix in (".dat", ".DAT", ".Dat"):
        dat = path.with_suffix(suffix)
        if dat.exists():
            texts[dat.name], encodings[dat.name] = read_text(dat)
            break
    book = TargetBook()
    tools: dict[str, Frame] = {}
    bases: dict[str, Frame] = {}
    fdat: dict[str, tuple[int, int, str]] = {}
    codes = {name: blank_comments(text, ";") for name, text in texts.items()}
    for name in sorted(codes, key=lambda n: not n.lower().endswith(".dat")):  # .dat first
        code = codes[name]
        for m in _DECL.finditer(code):
            kind = "pose" if m.group(1).upper() in POSE_TYPES else "joints"
            parts, _ = _components(code, m.end(), name)
            target = _target(m.group(2), kind, parts, name, line_of(code, m.start()))
            if book.known(target.name):
                raise InputError(f"{target.where}: {target.name} declared twice")
            book.declare(target)
        for m in _DATA.finditer(code):
            key = f"{m.group(1).upper()}[{m.group(2)}]"
            where = f"{name}:{line_of(code, m.start())}"
            parts, _ = _components(code, m.end(), name)
            frames_of = tools if key.startswith("TOOL") else bases
            if key in frames_of:  # which value serves which motion: not followed here
                raise InputError(f"{where}: {key} given a value twice in the program")
            frames_of[key] = _frame_of(parts, key, where)
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
    frames = _Frames(fdat, src, code)
    remarks = []
    events = sorted(
        [(m.start(), "assign", m) for m in _ASSIGN.finditer(code)]
        + [(m.start(), "set", m) for m in _SETTINGS.finditer(code)]
        + [(m.start(), "move", m) for m in _MOTION.finditer(code)],
        key=lambda e: e[0],
    )
    in_with: set[int] = set()  # assignments of a motion's WITH clause: that motion only
    for start, kind, m in events:
        line = line_of(code, start)
        if kind == "assign":
            if start not in in_with:
                frames.assign(m.group(1), m.group(2), line)
            continue
        if kind == "set":
            if m.group(1):  # BAS(#TOOL, n) / BAS(#BASE, n)
                frames.assign(m.group(1), f"{m.group(1).upper()}_DATA[{m.group(2)}]", line)
            else:
                frames.tool, frames.base = frames.from_fdat(m.group(3), line)
            continue
        motion, relative, rest = m.group(1).upper(), bool(m.group(2)), m.group(3)
        tool, base = frames.tool, frames.base
        clause = re.search(r"\bWITH\b(.*)", rest, re.IGNORECASE)
        if clause:  # a spline motion's own frames
            offset = m.start(3) + clause.start(1)
            for a in _ASSIGN.finditer(code, offset, m.end(3)):
                in_with.add(a.start())
                value = frames.value(a.group(1), a.group(2), line)
                tool, base = (value, base) if a.group(1).upper() == "TOOL" else (tool, value)
        at = m.start(3)
        for _ in range(2 if motion.endswith("CIRC") else 1):
            argument = _ARGUMENT.match(code, at)
            if argument is None or not argument.group(1):
                break
            arg = argument.group(1)
            if arg.startswith("{"):
                parts, _ = _components(code, argument.start(1) + 1, src)
                target_kind = "joints" if any(k in parts for k in AXIS_KEYS) else "pose"
                name = book.inline_name(line)
                book.declare(_target(name, target_kind, parts, src, line))
            elif "[" in arg:
                remarks.append(
                    f"{src}:{line}: {motion} {arg}, an element of an array: not compensated"
                )
                break
            elif not book.known(arg):
                if arg.startswith("$") or arg.upper() in ("HOME", "XHOME"):
                    remarks.append(
                        f"{src}:{line}: {motion} {arg}, the controller's own position (not "
                        "in the program): not compensated"
                    )
                    break
                hint = "" if len(texts) > 1 else f" (no {path.with_suffix('.dat').name} beside it)"
                raise InputError(
                    f"{src}:{line}: {motion} to {arg}: no such position declared in "
                    f"{' or '.join(texts)}{hint}"
                )
            else:
                name = arg
            book.use(name, line, tool, base)
            if relative:
                book.noted(name, f"{motion}_REL: a relative motion")
            elif argument.group(2):
                book.noted(name, f"moved to through the geometric operator ':' on line {line}")
                break  # its operand is no target of this motion
            elif frames.external:
                book.noted(name, frames.external)
            comma = code.find(",", argument.end(1), m.end(3))
            if comma < 0:
                break
            at = comma + 1
    for m in _CHANGED.finditer(code):  # a target changed while the program runs
        if book.known(m.group(1)):
            book.noted(m.group(1), f"changed at run time on line {line_of(code, m.start())}")
    for m in _BAS_OTHER.finditer(code):
        raise InputError(
            f"{src}:{line_of(code, m.start())}: {m.group().strip()}: a frame this reader cannot "
            "resolve (BAS(#TOOL, n) with a number only)"
        )
    declared_at = {m.start(2) for m in _DECL.finditer(code)}
    book.referenced(code, src, declared_at)  # SPL of a spline block, and the like
    return Program("krl", texts, book.targets(), tools, bases, tuple(remarks), encodings)


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


def check_output(program: Program, output: Path) -> None:
    """InputError when the output's name is not the module's: the controller loads a
    .src/.dat pair only under the name after DEF and DEFDAT."""
    src = next(iter(program.texts))
    found = re.search(r"^\s*(?:GLOBAL\s+)?DEF\s+(\w+)\s*\(", program.texts[src], re.I | re.M)
    if found and found.group(1).lower() != output.stem.lower():
        raise InputError(
            f"{param('output', str(output))}: the module is {found.group(1)} (DEF "
            f"{found.group(1)}() in {src}); "
            f"the controller loads it only as {found.group(1)}.src: write it to "
            f"{output.with_name(found.group(1) + output.suffix)} (another folder)"
        )


def outputs(program: Program, output: Path) -> dict[str, Path]:
    """The .src to the output path, its .dat beside it with the same name."""
    out = {}
    for name in program.texts:
        suffix = Path(name).suffix
        out[name] = output if suffix.lower() == ".src" else output.with_suffix(suffix)
    return out


LANGUAGE = Language(
    vendor="KUKA",
    check_output=check_output,
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
