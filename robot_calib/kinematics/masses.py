"""Mass models checked against the arm's size before gravity effects use them.

A robot description's masses and centres of mass (a URDF's `<inertial>`s, a YAML's `mass`
and `com`) drive the gravity torques of `compliance`, `gravity_compliance` and the load
features of the learned correction. Descriptions as they ship hold slips: a centre of mass
500 m from its link (a unit or sign typo in a URDF), a mass of 1e6 kg, a negative mass.
Such a model changes the diagnosis silently (a compliance found or missed by the torques
it predicts). `checked_mass_model` finds them: a link whose centre of mass lies farther
from its DH frame than the arm reaches (`reach_m`), a negative mass, or a whole arm heavier
than MAX_DENSITY_KG_M3 times its reach cubed (a solid steel cube of that size weighs about
7800 kg/m^3; real arms weigh 10-200 kg/m^3 of reach cubed). It warns once, naming each link
and value, and leaves the mass model out (all masses 0: the robot's weight then drives no
gravity effect; a payload given with --payload still does), never uses it; the reports say
which mass model the gravity effects used (`mass_model_line`).
"""

from __future__ import annotations

import warnings as python_warnings
from dataclasses import replace

import numpy as np

from robot_calib.kinematics.description import RobotDescription

#: an arm's total mass [kg] above this times its reach [m] cubed is no arm
MAX_DENSITY_KG_M3 = 2000.0
#: the reach of an arm is at least this [m] when judging centres of mass (a tiny arm)
MIN_REACH_M = 0.1


def reach_m(robot: RobotDescription) -> float:
    """The arm's reach [m]: the sum of its DH lengths |a| and offsets |d|."""
    return max(float(np.sum(np.abs(robot.a)) + np.sum(np.abs(robot.d))), MIN_REACH_M)


def mass_model_problems(robot: RobotDescription) -> list[str]:
    """What in `robot`'s mass model is beyond physics for its size (module docstring): one
    phrase per link or the whole arm, naming the value; [] when it is plausible."""
    reach = reach_m(robot)
    out = []
    for j, (mass, com) in enumerate(zip(robot.link_mass, robot.link_com)):
        name = robot.joint_names[j]
        if not np.isfinite(mass) or mass < 0:
            out.append(f"the link of {name}: mass {mass:g} kg")
        distance = float(np.linalg.norm(com))
        if mass > 0 and distance > reach:
            out.append(f"the link of {name}: centre of mass {distance:.4g} m from its frame "
                       f"(the arm reaches {reach:.3g} m)")  # fmt: skip
    total = float(np.sum(np.abs(robot.link_mass)))
    if total > MAX_DENSITY_KG_M3 * reach**3:
        out.append(f"the arm: {total:.4g} kg in all for a reach of {reach:.3g} m (at most "
                   f"{MAX_DENSITY_KG_M3 * reach**3:.3g} kg)")  # fmt: skip
    return out


def checked_mass_model(robot: RobotDescription, source: str) -> RobotDescription:
    """`robot` as it is when its mass model is plausible; else one warning naming `source`
    and each problem (`mass_model_problems`), and `robot` without a mass model (all link
    masses and centres 0: no gravity torque, so no gravity effect is fitted on it)."""
    problems = mass_model_problems(robot)
    if not problems:
        return robot
    note = f"{source}: mass model beyond physics ({'; '.join(problems)})"
    python_warnings.warn(
        f"{note}: not used, so the robot's own weight drives no gravity effect (compliance, "
        "gravity_compliance; a --payload still does); fix the masses, or give --robot a "
        "description with sane ones",
        UserWarning, stacklevel=2,
    )  # fmt: skip
    zero = np.zeros_like(robot.link_mass)
    return replace(robot, link_mass=zero, link_com=np.zeros_like(robot.link_com),
                   mass_note=note)  # fmt: skip


def mass_model_line(robot: RobotDescription) -> str:
    """Which masses the gravity effects used and where they came from, for the reports:
    the description's (its source, the total), none (why), and a payload when given."""
    payload = robot.payload_kg
    own = float(np.sum(robot.link_mass)) - payload
    if robot.mass_note:
        text = f"none of the description's, {robot.mass_note}"
    elif own > 0:
        text = f"the description's ({robot.source or robot.name}), {own:.1f} kg in all"
    else:
        text = "none: the description gives no masses (no gravity effect of its own weight)"
    if payload > 0:
        com = ", ".join(f"{v:.3f}" for v in robot.payload_com_m)
        text += f"; a payload of {payload:.2f} kg at ({com}) m of the flange (--payload)"
    return text
