"""The one interface of a robot-program language (msgs_doc/programs.md): how its programs
are read, how its poses and axis values are written, which configuration its targets
carry, and which files a compensated program is written to.

Each language is one module (`krl`, `rapid`, `fanuc_tp`, `urscript`) holding one
`Language`; `registry` finds them by name or by a file's suffix.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robot_calib.errors import InputError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.messages import QUATERNION_TOLERANCE
from robot_calib.programs.source import EVERY, LARGEST, Frame, Program


@dataclass(frozen=True)
class Language:
    """A robot-program language.

    name : its short name (`--language`), e.g. 'krl'
    title : in words, e.g. 'KUKA KRL'
    suffixes : the program file suffixes it reads (lower case, with the dot)
    read : path -> the Program (every file it belongs with, e.g. a .src's .dat)
    pose_to_base : values (n, k) of pose targets in the language's units and order ->
        (n, 4, 4) poses [m]
    base_to_pose : (n, 4, 4) poses [m] and the values they replace (n, k) -> values
        (n, k) (the old values choose among equal forms, e.g. a quaternion's sign)
    joint_unit : axis values [language unit] x joint_unit = readings [rad]
    pose_places, joint_places : the fewest decimals each number of a pose target / an
        axis value is written with (more where the program wrote more)
    configuration : (robot, readings (n, J) [rad]) -> each row's configuration, in the
        form `Target.configuration` holds; None for a language whose targets carry none
    outputs : (program, the output path given) -> {program file: path to write}
    frame_keys : how a tool's and a base's number or name (an option's KEY) is written as
        the key the program's targets use, e.g. ('TOOL_DATA[{}]', 'BASE_DATA[{}]')
    fold_keys : frame names are not case-sensitive (RAPID): keys are kept in lower case
    vendor : who makes the controllers that run the language
    check_output : (program, output path) -> None, InputError when the controller would
        not load the program under that name (a KRL module's DEF name)
    """

    name: str
    title: str
    suffixes: tuple[str, ...]
    read: Callable[[Path], Program]
    pose_to_base: Callable[[Array], Array]
    base_to_pose: Callable[[Array, Array], Array]
    joint_unit: float
    pose_places: tuple[int, ...]
    joint_places: int
    configuration: Callable[[RobotDescription, Array], list[tuple[int, ...]]] | None
    outputs: Callable[[Program, Path], dict[str, Path]]
    frame_keys: tuple[str, str] = ("{}", "{}")
    fold_keys: bool = False
    vendor: str = ""
    check_output: Callable[[Program, Path], None] = lambda program, output: None

    def option_key(self, kind: int, key: str) -> str:
        """The KEY an option gives for the frame key `key` of `frame_keys[kind]` (0: tool,
        1: base): 'TOOL_DATA[3]' -> '3', 'UT 2' -> '2', a name as it is."""
        head, _, tail = self.frame_keys[kind].partition("{}")
        if key.startswith(head) and key.endswith(tail) and len(key) > len(head) + len(tail):
            return key[len(head) : len(key) - len(tail)]
        return key

    def frame(self, kind: int, key: str, pose: Array | Sequence[float], where: str) -> Frame:
        """A frame given for the program (kind 0: a tool, 1: a base) under `key` (a number
        or a name as the program writes it; EVERY: for every target), its pose in the
        language's notation; InputError naming `where` for a pose that is not the
        notation's count of numbers within LARGEST, or whose quaternion has not norm 1."""
        values = np.asarray(pose, dtype=float).reshape(-1)
        count = len(self.pose_places)
        if values.size != count or not np.all(np.abs(values) < LARGEST):
            raise InputError(f"{where}: {count} numbers in {self.title}'s pose notation expected")
        if count == 7 and abs(np.linalg.norm(values[3:]) - 1.0) > QUATERNION_TOLERANCE:
            raise InputError(f"{where}: the quaternion q1..q4 has not norm 1")
        name = key.lower() if self.fold_keys else key
        name = EVERY if name == EVERY else self.frame_keys[kind].format(name)
        return Frame(name, self.pose_to_base(values[None])[0], where)

    def places(self, kind: str, count: int) -> tuple[int, ...]:
        """The fewest decimals of each of a target's `count` numbers."""
        return self.pose_places[:count] if kind == "pose" else (self.joint_places,) * count


def single_output(program: Program, output: Path) -> dict[str, Path]:
    """A one-file program goes to the output path as given."""
    (name,) = program.texts
    return {name: output}
