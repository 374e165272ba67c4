"""The one interface of a robot-program language (msgs_doc/programs.md): how its programs
are read, how its poses and axis values are written, which configuration its targets
carry, and which files a compensated program is written to.

Each language is one module (`krl`, `rapid`, `fanuc_tp`, `urscript`) holding one
`Language`; `registry` finds them by name or by a file's suffix.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.programs.source import Program


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

    def places(self, kind: str, count: int) -> tuple[int, ...]:
        """The fewest decimals of each of a target's `count` numbers."""
        return self.pose_places[:count] if kind == "pose" else (self.joint_places,) * count


def single_output(program: Program, output: Path) -> dict[str, Path]:
    """A one-file program goes to the output path as given."""
    (name,) = program.texts
    return {name: output}
