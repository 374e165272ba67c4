"""A calibrated URDF: the calibrated DH/Hayati geometry as a chain of URDF joints.

Chain: ``base_link`` -> joint 1 -> ``link_1`` -> joint 2 -> ... -> joint J -> ``link_J``
-> fixed ``flange`` (DH frame J) -> fixed ``tcp`` (the first target; ``tcp_NAME`` for the
others, with the probe's orientation for 6-DoF targets), and a fixed ``laser_tracker``
frame under ``base_link`` (the identified tracker pose). ``base_link`` is DH frame 0.

With the DH link ``frame_j = frame_{j-1} Rz(theta_j + (M q)_j) Tz(d_j) Tx(a_j) Rx(alpha_j)
Ry(beta_j)`` and ``(M q)_j = sign_j q_j + offset_j``: joint 1's origin is the identity,
joint j+1's origin (and the flange's) is row j's constant part (theta_j + offset_j with
the rest, `base.constant_rows`), and every joint turns about z, ``0 0 -1`` where the
reading's sign is -1, so that a URDF joint position is the controller's reading. A
coupling between joints (FANUC J2/J3) has no URDF form: refused. Joint names are the
robot's JointState names, limits its reading limits; effort and velocity limits are
placeholders (a URDF requires them; the calibration knows neither). Effects (backlash,
compliance, ...) are listed in the header with their size: no URDF holds them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING
from xml.sax.saxutils import quoteattr

import numpy as np

from robot_calib.export.base import (
    Exporter,
    constant_rows,
    correction_lines,
    effect_lines,
    joint_signs,
    number,
    rpy,
)
from robot_calib.kinematics.frames import Array, homogeneous
from robot_calib.model import target_parameters
from robot_calib.poses import PRIMARY_TARGET

if TYPE_CHECKING:
    from robot_calib.identify.calibration import Calibration

EFFORT_LIMIT = 1000.0  # [N m] placeholder: URDF requires one
VELOCITY_LIMIT = 3.14  # [rad/s] placeholder: URDF requires one
BASE_LINK, FLANGE, TRACKER = "base_link", "flange", "laser_tracker"


def target_link(name: str) -> str:
    """The URDF link of target `name`: ``tcp`` for the first (unnamed) one, else tcp_NAME."""
    return "tcp" if name == PRIMARY_TARGET else f"tcp_{name}"


def comment_text(text: str) -> str:
    """`text` safe inside an XML comment."""
    return text.replace("--", "- -")  # '--' may not appear inside an XML comment


def _origin(transform: Array) -> str:
    xyz = " ".join(number(v) for v in transform[:3, 3])
    angles = " ".join(number(v) for v in rpy(transform[:3, :3]))
    return f'<origin xyz="{xyz}" rpy="{angles}"/>'


def _fixed(name: str, parent: str, child: str, transform: Array) -> list[str]:
    return [
        f'  <joint name={quoteattr(name)} type="fixed">',
        f"    <parent link={quoteattr(parent)}/>",
        f"    <child link={quoteattr(child)}/>",
        f"    {_origin(transform)}",
        "  </joint>",
    ]


def render(cal: Calibration, source: str) -> str:
    """The URDF text of calibration `cal` (from PARAMS.json `source`); ExportError for a
    robot with coupled joints."""
    model, params = cal.model, cal.parameters
    robot = model.robot
    signs = joint_signs(cal, "a URDF")
    rows = constant_rows(cal)
    n = robot.n_joints
    effects = effect_lines(cal)
    header = [
        f"Calibrated URDF of robot {robot.name}, written by robot-calib export",
        f"from {source} (model {cal.name}).",
        "Geometry only: joint origins from the calibrated DH/Hayati table; joint positions",
        "are the controller's readings [rad]. Effort and velocity limits are placeholders.",
    ]
    if effects:
        header.append("Effects identified that no URDF can hold (compensate them separately):")
        header += [f"  {line}" for line in effects]
    elif cal.correction is None:
        header.append("The model has no effects beyond the geometry: the URDF holds it whole.")
    header += correction_lines(cal)
    lines = [
        '<?xml version="1.0"?>',
        "<!--",
        *(f"  {comment_text(h)}" for h in header),
        "-->",
        f"<robot name={quoteattr(robot.name)}>",
    ]
    links = [BASE_LINK] + [f"link_{j}" for j in range(1, n + 1)]
    links += [FLANGE, TRACKER] + [target_link(t) for t in model.targets]
    lines += [f"  <link name={quoteattr(link)}/>" for link in links]
    for j in range(1, n + 1):
        origin = np.eye(4) if j == 1 else rows[j - 2]
        lower, upper = robot.limits[j - 1]
        lines += [
            f'  <joint name={quoteattr(robot.joint_names[j - 1])} type="revolute">',
            f"    <parent link={quoteattr(links[j - 1])}/>",
            f"    <child link={quoteattr(links[j])}/>",
            f"    {_origin(origin)}",
            f'    <axis xyz="0 0 {number(signs[j - 1])}"/>',
            f'    <limit lower="{number(lower)}" upper="{number(upper)}" '
            f'effort="{number(EFFORT_LIMIT)}" velocity="{number(VELOCITY_LIMIT)}"/>',
            "  </joint>",
        ]
    lines += _fixed(f"{links[n]}-{FLANGE}", links[n], FLANGE, rows[n - 1])
    base2tracker = model.base2tracker(params)
    rotation = base2tracker[:3, :3].T
    tracker2base = homogeneous(rotation, -rotation @ base2tracker[:3, 3])
    lines += _fixed(f"{BASE_LINK}-{TRACKER}", BASE_LINK, TRACKER, tracker2base)
    rotations = model.tool_rotations(params)
    for k, name in enumerate(model.targets):
        offset = np.array([params[p] for p in target_parameters(name)])
        link = target_link(name)
        lines += _fixed(f"{FLANGE}-{link}", FLANGE, link, homogeneous(rotations[k], offset))
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


EXPORTER = Exporter("urdf", ".urdf", "a calibrated URDF (geometry; effects listed)", render)
