"""Taught robot programs, simulated: a path of targets as a teach pendant would record
them on the nominal model, written in each vendor's language with a tool and a base
frame, comments, declarations and the vendor's line endings (KRL and RAPID with CRLF, as
the controllers save them). `compensate --program` is tested and benchmarked on them.

The path is a random walk of the readings (steps of up to STEP_DEG per axis) within the
limits, away from the singularities; every other target, from the second, is a
Cartesian pose (the tool's pose in the base frame, with the vendor's configuration
data), the rest axis targets (the first too: where the arm starts). `TaughtProgram`
keeps the readings each target was taught at (the nominal controller's solution) and
what each target means (the tool's pose in the robot base).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from robot_calib.kinematics.description import RobotDescription, random_readings
from robot_calib.kinematics.frames import Array, homogeneous, rpy_to_matrix
from robot_calib.programs.configuration import singular_margin
from robot_calib.programs.language import Language

STEP_DEG = 12.0  # largest step of an axis between consecutive taught targets
CLEAR_M = 0.04  # `singular_margin` at least: clear of the singularities
MARGIN = 0.1  # share of each axis range kept clear at both ends


#: the shop-floor world the programs run in: the true arm's geometry off the nominal by
#: tenths of a millimetre and milliradian (identifiable offsets and lengths [rad, m]), with
#: joint 2-3 backlash and gravity compliance under a 15 kg tool
SHOP_EFFECTS = (
    {"name": "backlash", "joints": [2, 3], "values": {"backlash2": 6e-5, "backlash3": 6e-5}},
    {"name": "compliance", "joints": [2, 3], "values": {"compliance2": 1e-6, "compliance3": 1e-6}},
)
SHOP_DEVIATIONS = {
    "a1": 8e-5,
    "a2": -6e-5,
    "alpha1": 6e-5,
    "theta2": 1e-4,
    "theta3": -8e-5,
    "d4": 6e-5,
    "theta4": 8e-5,
    "theta5": -1e-4,
    "alpha3": 4e-5,
}


def shop_world(robot: str) -> dict[str, Any]:
    """The world-file mapping of `robot` on the shop floor (SHOP_EFFECTS, SHOP_DEVIATIONS,
    a 15 kg payload 0.1 m out of the flange); `sim.world.build_world` builds it."""
    return {
        "robot": robot,
        "geometry": "nominal",
        "seed": 3,
        "payload": {"mass_kg": 15.0, "com_m": [0.0, 0.0, 0.1]},
        "effects": [dict(effect) for effect in SHOP_EFFECTS],
        "deviations": dict(SHOP_DEVIATIONS),
    }


@dataclass(frozen=True)
class TaughtProgram:
    """A simulated program.

    texts : file name -> text
    q : shape (n, J), the readings each target was taught at [rad] (program order)
    pose : shape (n,), True for Cartesian targets, False for axis targets
    meant : shape (n, 4, 4), the tool's pose in the robot base frame [m] at each target
    tool2flange, base2robot : shape (4, 4), the program's tool and base frames [m]
    """

    texts: dict[str, str]
    q: Array
    pose: Array
    meant: Array
    tool2flange: Array
    base2robot: Array


def taught_path(robot: RobotDescription, n: int, rng: np.random.Generator) -> Array:
    """(n, J) readings [rad]: a random walk inside the limits (MARGIN in from both ends),
    clear of the singularities (`singular_margin` >= CLEAR_M), steps of at most STEP_DEG."""
    limits = robot.limits
    low = limits[:, 0] + MARGIN * (limits[:, 1] - limits[:, 0])
    high = limits[:, 1] - MARGIN * (limits[:, 1] - limits[:, 0])
    out = np.zeros((n, robot.n_joints))
    starts = random_readings(robot, 200, rng, 0.3)
    q = starts[np.flatnonzero(singular_margin(robot, starts) >= CLEAR_M)[0]]
    step = np.radians(STEP_DEG)
    for k in range(n):
        trials = np.clip(q + rng.uniform(-step, step, (50, len(q))), low, high)
        clear = np.flatnonzero(singular_margin(robot, trials) >= CLEAR_M)
        q = trials[clear[0]] if clear.size else q
        out[k] = q
    return out


def frame(xyz_m: tuple[float, float, float], rpy_deg: tuple[float, float, float]) -> Array:
    """A (4, 4) frame from a position [m] and roll, pitch, yaw [deg] (Rz Ry Rx)."""
    roll, pitch, yaw = np.radians(rpy_deg)
    return homogeneous(rpy_to_matrix(roll, pitch, yaw), np.asarray(xyz_m, dtype=float))


def taught_program(
    robot: RobotDescription,
    language: Language,
    n: int,
    rng: np.random.Generator,
    tool2flange: Array | None = None,
    base2robot: Array | None = None,
    name: str = "taught",
) -> TaughtProgram:
    """A program of `n` targets taught on `robot`'s nominal model along `taught_path`,
    written in `language` (module docstring); default tool 150 mm out of the flange and
    tilted 10 deg, default base 0.4 m in front of the robot turned 30 deg."""
    tool = frame((0.02, 0.0, 0.15), (0.0, 10.0, 0.0)) if tool2flange is None else tool2flange
    base = frame((0.4, 0.1, 0.0), (0.0, 0.0, 30.0)) if base2robot is None else base2robot
    if language.name == "urscript":  # URScript poses are in the robot base frame
        base = np.eye(4)
    q = taught_path(robot, n, rng)
    pose = np.arange(n) % 2 == 1  # an axis target first: where the arm starts
    reference = _reference(language, n)
    local = np.linalg.inv(base) @ robot.nominal_frames(q)[:, -1] @ tool
    places, joint_places = _PLACES[language.name]
    scale = 10.0**places  # rounded as written
    values = np.round(language.base_to_pose(local, reference) * scale) / scale
    config = language.configuration(robot, q) if language.configuration else None
    axes = np.round(q / language.joint_unit, joint_places)
    q = np.where(pose[:, None], q, axes * language.joint_unit)
    # what each target means, from the numbers as the program holds them
    meant = robot.nominal_frames(q)[:, -1] @ tool
    meant[pose] = base @ language.pose_to_base(values[pose])
    write = _WRITERS[language.name]
    tool_values = language.base_to_pose(tool[None], reference[:1])[0]
    base_values = language.base_to_pose(base[None], reference[:1])[0]
    texts = write(_Listing(name, values, axes, pose, config, tool_values, base_values))
    return TaughtProgram(texts, q, pose, meant, tool, base)


@dataclass(frozen=True)
class _Listing:
    """What a writer puts in a program: its name; the targets' numbers in the language's
    units, pose values (n, k) and axis values (n, J); which are poses (n,); their
    configuration data (None: the language has none); the tool and base in the
    language's pose notation."""

    name: str
    values: Array
    axes: Array
    pose: Array
    config: list[tuple[int, ...]] | None
    tool: Array
    base: Array


def _reference(language: Language, n: int) -> Array:
    """Old values choosing among equal forms: angles near 0, quaternions with w >= 0."""
    width = 7 if language.name == "rapid" else 6
    out = np.zeros((n, width))
    if language.name == "rapid":
        out[:, 3] = 1.0
    return out


def _numbers(values: Array, places: int) -> list[str]:
    return [f"{v:.{places}f}" for v in values]


def _krl(p: _Listing) -> dict[str, str]:
    src = [
        "&ACCESS RVP",
        "&REL 1",
        f"DEF {p.name}( )",
        ";FOLD INI",
        "  ;FOLD BASISTECH INI",
        "    BAS (#INITMOV,0 )",
        "  ;ENDFOLD (BASISTECH INI)",
        ";ENDFOLD (INI)",
        "",
        _decl("TOOL_DATA[1]", p.tool) + " ; the gripper",
        _decl("BASE_DATA[2]", p.base) + " ; the fixture",
        "$TOOL = TOOL_DATA[1]",
        "$BASE = BASE_DATA[2]",
    ]
    dat = [
        f"DEFDAT {p.name}",
        ";FOLD EXTERNAL DECLARATIONS;%{PE}%MKUKATPBASIS,%CEXT,%VCOMMON,%P",
        ";ENDFOLD (EXTERNAL DECLARATIONS)",
    ]
    for k in range(len(p.values)):
        if p.pose[k]:
            s, t = p.config[k] if p.config else (2, 0)
            dat.append(
                f"DECL E6POS XP{k + 1}={{{','.join(_pairs('XYZABC', p.values[k], 4))},"
                f"S {s},T {t},E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}}"
            )
            src.append(f"LIN XP{k + 1} C_DIS ; to point {k + 1}")
        else:
            names = [f"A{j + 1}" for j in range(len(p.axes[k]))]
            dat.append(
                f"DECL E6AXIS XP{k + 1}={{{','.join(_pairs(names, p.axes[k], 4))},"
                "E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}"
            )
            src.append(f"PTP XP{k + 1}")
    src += ["END", ""]
    dat += ["ENDDAT", ""]
    return {f"{p.name}.src": "\r\n".join(src), f"{p.name}.dat": "\r\n".join(dat)}


def _pairs(names: object, values: Array, places: int) -> list[str]:
    return [f"{n} {v:.{places}f}" for n, v in zip(names, values)]  # type: ignore[call-overload]


def _decl(key: str, values: Array) -> str:
    return f"{key}={{{','.join(_pairs('XYZABC', values, 3))}}}"


def _rapid(p: _Listing) -> dict[str, str]:
    def pose_text(v: Array) -> str:
        return f"[[{','.join(_numbers(v[:3], 2))}],[{','.join(_numbers(v[3:], 6))}]]"

    lines = [
        f"MODULE {p.name}",
        "    ! taught on the nominal model",
        f"    PERS tooldata tcp1:=[TRUE,{pose_text(p.tool)},[2,[0,0,100],[1,0,0,0],0,0,0]];",
        f'    TASK PERS wobjdata fixture:=[FALSE,TRUE,"",{pose_text(p.base)},'
        "[[0,0,0],[1,0,0,0]]];",
    ]
    body = []
    for k in range(len(p.values)):
        if p.pose[k]:
            cf = p.config[k] if p.config else (0, 0, 0, 0)
            lines.append(
                f"    CONST robtarget p{k + 1}:={pose_text(p.values[k])[:-1]},"
                f"[{','.join(map(str, cf))}],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];"
            )
            body.append(f"        MoveL p{k + 1}, v200, z1, tcp1\\WObj:=fixture;")
        else:
            lines.append(
                f"    CONST jointtarget j{k + 1}:=[[{','.join(_numbers(p.axes[k], 4))}],"
                "[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];"
            )
            body.append(f"        MoveAbsJ j{k + 1}, v500, fine, tcp1\\WObj:=fixture;")
    lines += ["    PROC main()", *body, "    ENDPROC", "ENDMODULE", ""]
    return {f"{p.name}.mod": "\r\n".join(lines)}


def _fanuc(p: _Listing) -> dict[str, str]:
    head = [
        f"/PROG  {p.name.upper()}",
        "/ATTR",
        "OWNER\t\t= MNEDITOR;",
        'COMMENT\t\t= "taught";',
        "DEFAULT_GROUP\t= 1,*,*,*,*;",
        "/MN",
        "   1:  UFRAME_NUM=1 ;",
        "   2:  UTOOL_NUM=1 ;",
    ]
    positions = ["/POS"]
    for k in range(len(p.values)):
        motion = "L" if p.pose[k] else "J"
        speed = "500mm/sec CNT50" if p.pose[k] else "50% FINE"
        head.append(f"{k + 3:4d}:{motion} P[{k + 1}] {speed}    ;")
        positions += [f"P[{k + 1}]{{", "   GP1:"]
        if p.pose[k]:
            f, u, t, *turns = p.config[k] if p.config else (0, 1, 1, 0, 0, 0)
            letters = f"{'F' if f else 'N'} {'U' if u else 'D'} {'T' if t else 'B'}"
            turn_text = ", ".join(map(str, turns))
            v = p.values[k]
            positions += [
                f"\tUF : 1, UT : 1,\t\tCONFIG : '{letters}, {turn_text}',",
                f"\tX = {v[0]:9.3f}  mm,\tY = {v[1]:9.3f}  mm,\tZ = {v[2]:9.3f}  mm,",
                f"\tW = {v[3]:9.3f} deg,\tP = {v[4]:9.3f} deg,\tR = {v[5]:9.3f} deg",
            ]
        else:
            a = p.axes[k]
            positions += [
                "\tUF : 1, UT : 1,\t",
                f"\tJ1= {a[0]:9.3f} deg,\tJ2= {a[1]:9.3f} deg,\tJ3= {a[2]:9.3f} deg,",
                f"\tJ4= {a[3]:9.3f} deg,\tJ5= {a[4]:9.3f} deg,\tJ6= {a[5]:9.3f} deg",
            ]
        positions.append("};")
    return {f"{p.name}.ls": "\n".join([*head, *positions, "/END", ""])}


def _urscript(p: _Listing) -> dict[str, str]:
    # URScript targets carry no configuration, and its poses are in the robot base
    lines = [
        f"def {p.name}():",
        "  # taught on the nominal model",
        f"  set_tcp(p[{','.join(_numbers(p.tool, 6))}])",
    ]
    for k in range(len(p.values)):
        if p.pose[k]:
            lines.append(f"  p{k + 1} = p[{', '.join(_numbers(p.values[k], 6))}]")
            lines.append(f"  movel(p{k + 1}, a=1.2, v=0.25)")
        else:
            lines.append(f"  movej([{', '.join(_numbers(p.axes[k], 6))}], a=1.4, v=1.05)")
    lines += ["end", ""]
    return {f"{p.name}.script": "\n".join(lines)}


#: decimals each writer uses: pose numbers (each), axis values
_PLACES = {
    "krl": (np.array([3, 3, 3, 4, 4, 4]), 4),
    "rapid": (np.array([2, 2, 2, 6, 6, 6, 6]), 4),
    "fanuc_tp": (np.array([3, 3, 3, 3, 3, 3]), 3),
    "urscript": (np.array([6, 6, 6, 6, 6, 6]), 6),
}
_WRITERS = {"krl": _krl, "rapid": _rapid, "fanuc_tp": _fanuc, "urscript": _urscript}
