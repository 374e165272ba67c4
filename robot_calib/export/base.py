"""The one interface of an export format, and what several formats share: the constant
part of each DH/Hayati row, roll-pitch-yaw of a rotation, the effects no geometry holds."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from robot_calib.errors import InputError, param
from robot_calib.kinematics.dh import link_transforms
from robot_calib.kinematics.frames import Array

if TYPE_CHECKING:
    from robot_calib.identify.calibration import Calibration

_GIMBAL_COS = 1e-9  # |cos(pitch)| below this: roll and yaw turn about one axis, roll := 0


class ExportError(InputError):
    """A calibration that the chosen format cannot represent (exit status 2)."""


@dataclass(frozen=True)
class Exporter:
    """An export format: `render(cal, source)` is the file's text for calibration `cal`
    read from `source` (the PARAMS.json path, named in the file's header)."""

    name: str
    suffix: str  # default file suffix, with the dot
    description: str  # one line, for --help
    render: Callable[[Calibration, str], str]


def constant_rows(cal: Calibration) -> Array:
    """The constant part of every DH/Hayati row, shape (J, 4, 4): link j's transform
    ``Rz(theta_j + offset_j) Tz(d_j) Tx(a_j) Rx(alpha_j) Ry(beta_j)`` at joint variables
    M q = 0 (offset_j: the robot's `reading_to_joint` offset [rad]), geometric values only
    (no effects). Frame j = frame j-1 Rz((M q)_j) row_j."""
    model, params = cal.model, cal.parameters
    zero = np.zeros((1, model.robot.n_joints))
    return link_transforms(model.dh_table(params, zero))[0]


def joint_signs(cal: Calibration, what: str) -> Array:
    """Each joint's reading-to-joint sign (J,) (+1/-1); ExportError naming `what` when the
    robot couples joints (a joint variable depending on another joint's reading), which no
    single-axis joint can hold."""
    robot = cal.model.robot
    matrix = robot.reading_matrix
    if matrix is None:
        return np.ones(robot.n_joints)
    coupled = matrix - np.diag(np.diag(matrix))
    if np.any(coupled != 0.0):
        pairs = ", ".join(f"{j + 1}<-{k + 1}" for j, k in zip(*np.nonzero(coupled)))
        raise ExportError(
            f"robot {robot.name} couples joints (reading_to_joint coupling {pairs}): {what} "
            "cannot hold a joint driven by another joint's reading; export "
            f"{param('format', 'dh')} or {param('format', 'json')} instead"
        )
    return np.diag(matrix).copy()


def rpy(rotation: Array) -> tuple[float, float, float]:
    """Roll, pitch, yaw [rad] of a rotation (3, 3) = Rz(yaw) Ry(pitch) Rx(roll) (URDF's
    fixed-axis XYZ); pitch from atan2 (accurate near +-pi/2), roll 0 at gimbal lock."""
    cos_pitch = float(np.hypot(rotation[0, 0], rotation[1, 0]))
    pitch = float(np.arctan2(-rotation[2, 0], cos_pitch))
    if cos_pitch < _GIMBAL_COS:
        return 0.0, pitch, float(np.arctan2(-rotation[0, 1], rotation[1, 1]))
    roll = float(np.arctan2(rotation[2, 1], rotation[2, 2]))
    yaw = float(np.arctan2(rotation[1, 0], rotation[0, 0]))
    return roll, pitch, yaw


def labelled_size(unit: str, value: float, mm_digits: int = 4, urad_digits: int = 1) -> str:
    """A value in SI `unit` for people: m as mm, rad as urad, other units as stored."""
    if unit == "m":
        return f"{value * 1e3:.{mm_digits}f} mm"
    if unit == "rad":
        return f"{value * 1e6:.{urad_digits}f} urad"
    return f"{value:.4g} {unit}"


# What an effect adds at the tool is measured at random poses over an hour of work between
# 15 and 35 deg C: enough to show backlash (both approach directions), drift and warm-up.
SIZE_POSES = 200
SIZE_HOURS = 1.0
SIZE_TEMPERATURE_C = (15.0, 35.0)


def effect_sizes(cal: Calibration) -> dict[str, tuple[float, float]]:
    """What each effect of the model moves the first target by [m], as (rms, max) over
    SIZE_POSES random poses (directions as visited, times over SIZE_HOURS, temperatures in
    SIZE_TEMPERATURE_C): the model's points with the effect against the same model with its
    parameters at 0 (no effect). By effect label."""
    from robot_calib.kinematics.description import random_readings
    from robot_calib.poses import Poses

    model, params = cal.model, cal.parameters
    rng = np.random.default_rng(0)
    q = random_readings(model.robot, SIZE_POSES, rng)
    time = np.sort(rng.uniform(0.0, SIZE_HOURS * 3600.0, SIZE_POSES))
    visited = Poses.from_readings(q, None, time)
    poses = replace(visited, temperature=rng.uniform(*SIZE_TEMPERATURE_C, SIZE_POSES))
    full = model.target_points(params, poses)
    out = {}
    for effect in model.effects:
        off = params.with_values(dict.fromkeys(effect.parameter_names(model.robot), 0.0))
        moved = np.linalg.norm(full - model.target_points(off, poses), axis=1)
        out[effect.label] = (float(np.sqrt(np.mean(moved**2))), float(moved.max()))
    return out


def correction_lines(cal: Calibration) -> list[str]:
    """The line every export format that cannot hold a learned correction (PARAMS.json
    `correction`, the hybrid model) writes into its header; none without one."""
    if cal.correction is None:
        return []
    return [
        "The learned correction of this calibration is not in this file: "
        f"{cal.correction.rms_m * 1e3:.4f} mm rms at the calibration poses (PARAMS.json "
        "`correction`; robot-calib predict, score and compensate apply it)"
    ]


def effect_lines(cal: Calibration) -> list[str]:
    """One line per effect of the calibration's model (none: an empty list): what it moves
    the tool by (`effect_sizes`, mm) and its largest parameter (mm / urad / as stored),
    then a line saying where the sizes were taken."""
    lines = []
    params, robot = cal.parameters, cal.model.robot
    sizes = effect_sizes(cal) if cal.model.effects else {}
    for effect in cal.model.effects:
        names = effect.parameter_names(robot)
        if not names:
            lines.append(f"{effect.label}: no parameters")
            continue
        rms, peak = sizes[effect.label]
        largest = max(names, key=lambda n: abs(params[n]))
        unit = params.parameters[params.index(largest)].unit
        lines.append(
            f"{effect.label}: moves the tool by {rms * 1e3:.4f} mm rms, {peak * 1e3:.4f} mm max "
            f"(largest parameter |{largest}| = {labelled_size(unit, abs(params[largest]))})"
        )
    if lines:
        lines.append(
            f"(tool sizes at {SIZE_POSES} random poses over {SIZE_HOURS:g} h at "
            f"{SIZE_TEMPERATURE_C[0]:g}-{SIZE_TEMPERATURE_C[1]:g} deg C)"
        )
    return lines


def number(value: float) -> str:
    """A float as text that reads back to the same double (repr), -0 as 0."""
    return repr(float(value) + 0.0)
