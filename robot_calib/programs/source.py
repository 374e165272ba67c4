"""A robot program as read: its files' exact text, the motion targets in it (with the span
of every number a compensation may rewrite), and the tool and base frames it declares.

Nothing but those spans is ever rewritten: `rewrite` splices new numbers into the original
text, so comments, declarations, line endings (CRLF included) and every other byte stay as
they were. A parse followed by `rewrite` with no change gives the files back byte for byte.
"""

from __future__ import annotations

import bisect
import functools
import re
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from robot_calib.errors import InputError
from robot_calib.kinematics.frames import Array, homogeneous

#: a number as the vendors write it: sign, digits, optional decimals and exponent
NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
NUMBER_RE = re.compile(NUMBER)
EVERY = "*"  # the key of a frame given for every target
#: in the key of a frame a program names but declares elsewhere (a KUKA FDAT of
#: $config.dat): no option can give it
OUTSIDE = "declared outside the program"


@dataclass(frozen=True)
class Span:
    """Where a number is written: `file` (a key of `Program.texts`), characters
    [start, end) of that file's text."""

    file: str
    start: int
    end: int


@dataclass(frozen=True)
class Frame:
    """A tool or base frame as a program (or an option) declares it.

    key : the name the program's targets refer to it by (`TOOL_DATA[1]`, `tool1`, `UT 2`)
    pose : shape (4, 4), the frame [m]: a tool in the flange frame, a base in the robot
        base frame
    where : 'file:line' of its declaration, or the option that gave it
    """

    key: str
    pose: Array
    where: str


@dataclass(frozen=True)
class Target:
    """One motion target of a program.

    name : as the program names it (`XP1`, `p10`, `P[3]`), or `line N` for an inline one
    file, line : where its values are written (1-based line)
    kind : 'pose' (a Cartesian target: position and orientation of the tool in its base
        frame) or 'joints' (axis values)
    values : the numbers in the language's units and order (pose: the language's position
        and orientation numbers; joints: one per axis)
    spans : where each of `values` is written (same order)
    configuration : the configuration the program gives (the language's own tuple, e.g.
        KUKA (S, T)), or None where it gives none
    tool, base : keys of the frames in `Program.tools` / `Program.bases` the target is
        used with (None: the flange / the robot base)
    used : lines of the motions that go to it, in program order (empty: never moved to)
    note : why the target cannot be compensated as it stands ('' when it can): a target
        used with two tools, inside an expression, by a relative motion
    """

    name: str
    file: str
    line: int
    kind: str
    values: tuple[float, ...]
    spans: tuple[Span, ...]
    configuration: tuple[int, ...] | None = None
    tool: str | None = None
    base: str | None = None
    used: tuple[int, ...] = ()
    note: str = ""

    @property
    def where(self) -> str:
        return f"{self.file}:{self.line}"


@dataclass(frozen=True)
class Program:
    """A program's files (name -> exact text, in the order read), its targets in the order
    the program first moves to them (never-moved-to targets last), its frames, and
    remarks: motions that hold no target of the program ('file:line: ...'), left as
    they are."""

    language: str
    texts: dict[str, str]
    targets: tuple[Target, ...]
    tools: dict[str, Frame] = field(default_factory=dict)
    bases: dict[str, Frame] = field(default_factory=dict)
    remarks: tuple[str, ...] = ()
    encodings: dict[str, str] = field(default_factory=dict)  # file -> its encoding

    def encoding(self, file: str) -> str:
        """The encoding `file` was read in (and is written back in)."""
        return self.encodings.get(file, "utf-8")


#: the encodings a program file is read in, in this order: UTF-8 (ASCII included), then
#: Windows-1252 (KUKA and ABB controllers save comments with umlauts so), then Latin-1
#: (every byte a character: a file read so is written back byte for byte)
ENCODINGS = ("utf-8", "cp1252", "latin-1")


def read_text(path: str | Path) -> tuple[str, str]:
    """A program file's exact text and its encoding (the first of ENCODINGS that decodes
    it), newlines untranslated (CRLF kept); InputError for a file with NUL bytes (not a
    program) or one that cannot be read."""
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from None
    nul = data.find(b"\x00")
    if nul >= 0:
        raise InputError(f"{path}: not a text program (a NUL byte at offset {nul})")
    for encoding in ENCODINGS:
        try:
            return data.decode(encoding), encoding
        except UnicodeDecodeError:
            continue
    raise AssertionError("latin-1 decodes every byte")


def line_of(text: str, index: int) -> int:
    """The 1-based line of character `index` in `text` (the newlines' offsets are found
    once per text: a reader asks for thousands of lines)."""
    return bisect.bisect_left(_newlines(text), index) + 1


@functools.lru_cache(maxsize=8)
def _newlines(text: str) -> list[int]:
    return [m.start() for m in re.finditer("\n", text)]


#: the largest magnitude a number of a program may have: 1e6 (a kilometre in mm, a
#: million degrees); beyond it, a corrupt value
LARGEST = 1e6


def number(token: str, where: str, largest: float = LARGEST) -> float:
    """A number written as `token` (the whole token: '463.1.63' is none); InputError
    naming `where` otherwise, or when it is not finite or beyond `largest`."""
    if not NUMBER_RE.fullmatch(token):
        raise InputError(f"{where}: {token.strip()[:30]!r} is not a number")
    value = float(token)
    if not abs(value) <= largest:
        raise InputError(f"{where}: {token.strip()[:30]} is beyond +-{LARGEST:g} (corrupt?)")
    return value


def numbers_in(text: str, start: int, end: int, file: str) -> list[tuple[float, Span]]:
    """Every number of a bracketed list text[start:end] (tokens between brackets and
    commas) with its span in the file; InputError naming the line for a token that is not
    a whole number."""
    out = []
    for m in re.finditer(r"[^\[\],\s]+", text[start:end]):
        at = start + m.start()
        value = number(m.group(), f"{file}:{line_of(text, at)}")
        out.append((value, Span(file, at, at + len(m.group()))))
    return out


def decimals(text: str) -> int:
    """Decimals written in a number's text ('1.250' -> 3, '7' -> 0, '1e-3' -> 0)."""
    mantissa = re.split("[eE]", text)[0]
    return len(mantissa.split(".")[1]) if "." in mantissa else 0


def formatted(value: float, old: str, at_least: int) -> str:
    """`value` written with the decimals of the number it replaces (`old`), at least
    `at_least` of them ('-0.000' as '0.000'); `old` itself where it reads as `value`."""
    if float(old) == value:
        return old
    places = max(decimals(old), at_least)
    out = f"{value:.{places}f}"
    if float(out) == 0.0:
        out = out.lstrip("-")
    return out


def rewrite(
    program: Program, values: dict[int, tuple[float, ...]], places: dict[int, tuple[int, ...]]
) -> dict[str, str]:
    """The program's files with target k's numbers replaced by values[k] (same length and
    order as `Target.values`), number i written with at least places[k][i] decimals;
    targets not in `values` unchanged."""
    edits: dict[str, list[tuple[int, int, str]]] = {name: [] for name in program.texts}
    for k, new in values.items():
        target = program.targets[k]
        for i, (value, span) in enumerate(zip(new, target.spans)):
            text = program.texts[span.file]
            old = text[span.start : span.end]
            edits[span.file].append((span.start, span.end, formatted(value, old, places[k][i])))
    out = {}
    for name, text in program.texts.items():
        pieces, at = [], 0
        for start, end, new_text in sorted(edits[name]):  # every other byte as it was
            pieces += [text[at:start], new_text]
            at = end
        out[name] = "".join(pieces) + text[at:]
    return out


def blank_comments(text: str, marker: str, quote: str = '"') -> str:
    """The code of `text`: every comment (from `marker` outside a `quote`d string to the end
    of its line) and the inside of every string replaced by spaces (a motion written in a
    message is no motion): the same length, so offsets in it are offsets in `text`."""
    out = list(text)
    inside = False
    k = 0
    while k < len(text):
        char = text[k]
        if char == "\n":
            inside = False
        elif char == quote:
            inside = not inside
        elif inside and char != "\r":
            out[k] = " "
        elif char == marker and not inside:
            end = text.find("\n", k)
            end = len(text) if end < 0 else end
            if end > k and text[end - 1] == "\r":
                end -= 1
            out[k:end] = " " * (end - k)
            k = end
            continue
        k += 1
    return "".join(out)


class TargetBook:
    """Targets as a reader meets them: declared (by name) and used by motions in program
    order. A target used with two different tool or base frames gets a note (one value
    cannot serve both)."""

    def __init__(self) -> None:
        self._declared: dict[str, Target] = {}  # in the order declared
        self._used: list[str] = []  # in the order first moved to

    def declare(self, target: Target) -> None:
        key = target.name.upper()
        if key not in self._declared:
            self._declared[key] = target

    def inline_name(self, line: int) -> str:
        """A name for a target written inside the motion on `line`: 'line N', then
        'line N (2)', ... for more on that line (a circular motion's two)."""
        name, count = f"line {line}", 1
        while self.known(name):
            count += 1
            name = f"line {line} ({count})"
        return name

    def known(self, name: str) -> bool:
        return name.upper() in self._declared

    def get(self, name: str) -> Target:
        return self._declared[name.upper()]

    def use(self, name: str, line: int, tool: str | None, base: str | None) -> None:
        """A motion on `line` goes to the declared target `name` with these frames."""
        key = name.upper()
        target = self._declared[key]
        note = target.note
        # an axis target means the tool where the axes put it: its base does not matter
        same_base = target.kind == "joints" or target.base == base
        if target.used and (target.tool != tool or not same_base) and not note:
            note = (
                f"used on line {target.used[0]} with tool {target.tool or 'flange'} and base "
                f"{target.base or 'robot base'}, on line {line} with tool {tool or 'flange'} "
                f"and base {base or 'robot base'}: one value cannot serve both"
            )
        first = not target.used
        self._declared[key] = replace(
            target,
            used=(*target.used, line),
            tool=tool if first else target.tool,
            base=base if first else target.base,
            note=note,
        )
        if first:  # program order: first use
            self._used.append(key)

    def noted(self, name: str, note: str) -> None:
        """Mark the declared target `name` as not compensable (`note` says why)."""
        key = name.upper()
        if not self._declared[key].note:
            self._declared[key] = replace(self._declared[key], note=note)

    def referenced(self, code: str, file: str, declared_at: set[int]) -> None:
        """Mark `left` every target no known motion goes to that the code (comments and
        strings blanked) names elsewhere than where it is declared (`declared_at`: the
        offsets of its name in declarations): an instruction this reader does not know
        (a spline block's SPL, RAPID's TriggL, an expression) moves to it uncompensated."""
        for key, target in list(self._declared.items()):
            if target.used or target.note:
                continue
            name = target.name.split(" (line")[0]
            for m in re.finditer(rf"(?<![\w$.])({re.escape(name)})(?!\w)", code, re.IGNORECASE):
                if m.start() not in declared_at:
                    line = line_of(code, m.start())
                    self._declared[key] = replace(
                        target,
                        used=(line,),
                        note=f"named on line {line} by an instruction this reader does not "
                        "compensate through",
                    )
                    self._used.append(key)
                    break

    def targets(self) -> tuple[Target, ...]:
        """Used targets in the order first moved to, then those never moved to."""
        unused = [k for k, t in self._declared.items() if not t.used]
        return tuple(self._declared[k] for k in (*self._used, *unused))


def euler_to_base(values: Array, order: str, unit_m: float) -> Array:
    """Poses (n, 6) as a position [unit_m m] and three angles [deg] in scipy's Euler
    `order` (upper case: about the moving axes; lower case: about fixed axes) -> (n, 4, 4)
    [m]."""
    values = np.atleast_2d(np.asarray(values, dtype=float))
    rotation = Rotation.from_euler(order, values[:, 3:6], degrees=True).as_matrix()
    return homogeneous(rotation, values[:, :3] * unit_m)


def base_to_euler(poses: Array, old: Array, order: str, unit_m: float) -> Array:
    """The inverse of `euler_to_base` in the vendors' ranges: the first and third angle in
    (-180, 180], the middle one in [-90, 90] (at the gimbal lock the first angle takes the
    turn about the common axis). `old` (the numbers replaced) is not needed: one form."""
    del old
    with warnings.catch_warnings():  # the gimbal lock has a valid answer: no warning
        warnings.simplefilter("ignore", UserWarning)
        angles = Rotation.from_matrix(poses[:, :3, :3]).as_euler(order, degrees=True)
    angles = 180.0 - (180.0 - angles) % 360.0  # (-180, 180]
    return np.hstack([poses[:, :3, 3] / unit_m, angles])
