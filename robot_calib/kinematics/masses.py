"""Mass models checked against the arm's size before gravity effects use them.

A robot description's masses and centres of mass (a URDF's `<inertial>`s, a YAML's `mass`
and `com`) drive the gravity torques of `compliance`, `gravity_compliance` and the load
features of the learned correction. Descriptions as they ship hold slips: a centre of mass
500 m from its link (a unit or sign typo in a URDF), a mass of 1e6 kg, a negative mass, a
link of mass 0 beside links with mass (an `<inertial>` left out). Such a model changes the
diagnosis silently (a compliance found or missed by the torques it predicts).
`checked_mass_model` finds them: a link whose centre of mass lies farther from its DH frame
than the arm reaches (`reach_m`), a negative or zero mass (when others are given), or a
whole arm heavier than MAX_DENSITY_KG_M3 times its reach cubed (a solid steel cube of that
size weighs about 7800 kg/m^3; real arms weigh 5-25 kg/m^3 of `reach_m` cubed). It warns
once, naming each link and value, and never uses that model. The gravity effects use
instead (`substitute_masses`):

1. the masses of a built-in description of the same arm (its forward kinematics equal to
   MATCH_M at random poses within both arms' limits), each link's centre of mass carried
   over through the two arms' frames at the zero pose (so a URDF converted to other DH
   frames gets the same physical centres);
2. else a default from the geometry: DEFAULT_DENSITY_KG_M3 times `reach_m` cubed in all,
   shared by the links in proportion to their length (with a floor), each centre mid-link.

The compliances fitted on a substitute are in rad/(N m) of the masses it assumes: their
pattern is the arm's, their scale only as right as those masses. The reports say which mass
model the gravity effects used and where it came from (`mass_model_line`). A description
without any mass is left as it is: no gravity effect of the arm's own weight (said so).
"""

from __future__ import annotations

import warnings as python_warnings
from dataclasses import replace

import numpy as np

from robot_calib.errors import param
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array

#: an arm's total mass [kg] above this times its reach [m] cubed is no arm
MAX_DENSITY_KG_M3 = 2000.0
#: the reach of an arm is at least this [m] when judging centres of mass (a tiny arm)
MIN_REACH_M = 0.1
#: a default arm's mass [kg] per `reach_m` [m] cubed (the built-in descriptions: IRB 120 12,
#: KR5 sixx 16, UR5 10, UR10 6; data sheets: KR16 15, IRB 6700 22)
DEFAULT_DENSITY_KG_M3 = 12.0
#: a link's share of the default mass counts at least this length [m]
MIN_LINK_M = 0.05
#: two arms are one when their flanges agree to this [m] (and MATCH_RAD) at every test pose
MATCH_M = 1e-3
MATCH_RAD = 1e-3
MATCH_POSES = 20


def reach_m(robot: RobotDescription) -> float:
    """The arm's reach [m]: the sum of its DH lengths |a| and offsets |d|."""
    return max(float(np.sum(np.abs(robot.a)) + np.sum(np.abs(robot.d))), MIN_REACH_M)


def mass_model_problems(robot: RobotDescription) -> list[str]:
    """What in `robot`'s mass model is beyond physics for its size (module docstring): one
    phrase per link or the whole arm, naming the value; [] when it is plausible."""
    reach = reach_m(robot)
    out = []
    given = bool(np.any(robot.link_mass > 0))
    for j, (mass, com) in enumerate(zip(robot.link_mass, robot.link_com)):
        name = robot.joint_names[j]
        if not np.isfinite(mass) or mass < 0 or (given and mass == 0):
            out.append(f"the link of {name}: mass {mass:g} kg")
        distance = float(np.linalg.norm(com))
        if mass > 0 and distance > reach:
            out.append(
                f"the link of {name}: centre of mass {distance:.4g} m from its frame "
                f"(the arm reaches {reach:.3g} m)"
            )
    total = float(np.sum(np.abs(robot.link_mass)))
    if total > MAX_DENSITY_KG_M3 * reach**3:
        out.append(
            f"the arm: {total:.4g} kg in all for a reach of {reach:.3g} m (at most "
            f"{MAX_DENSITY_KG_M3 * reach**3:.3g} kg)"
        )
    return out


def checked_mass_model(robot: RobotDescription, source: str) -> RobotDescription:
    """`robot` as it is when its mass model is plausible; else one warning naming `source`
    and each problem (`mass_model_problems`), and `robot` with the substitute mass model
    (`substitute_masses`) and a `mass_note` saying why and which."""
    problems = mass_model_problems(robot)
    if not problems:
        return robot
    substitute, which = substitute_masses(robot)
    note = f"{source}: mass model beyond physics ({'; '.join(problems)})"
    python_warnings.warn(
        f"{note}: not used; the gravity effects (compliance, gravity_compliance) use {which} "
        f"instead; fix the masses, or give {param('robot')} a description with sane ones",
        UserWarning,
        stacklevel=2,
    )
    return replace(substitute, mass_note=f"{which}, not the description's: {note}")


def substitute_masses(robot: RobotDescription) -> tuple[RobotDescription, str]:
    """`robot` with the mass model that replaces an implausible one (module docstring),
    and what it is, for people."""
    twin = builtin_twin(robot)
    if twin is not None:
        mass, com = _carried_over(twin, robot)
        return (
            replace(robot, link_mass=mass, link_com=com),
            f"the built-in {twin.name}'s masses (the same arm by its kinematics), "
            f"{float(np.sum(mass)):.1f} kg in all",
        )
    mass, com = default_masses(robot)
    return (
        replace(robot, link_mass=mass, link_com=com),
        f"a default from the geometry ({float(np.sum(mass)):.1f} kg in all: "
        f"{DEFAULT_DENSITY_KG_M3:g} kg per cubic metre of reach, each link's mass by its "
        "length, its centre mid-link; compliances in deg/(N m) only as right as these "
        "masses)",
    )


def builtin_twin(robot: RobotDescription) -> RobotDescription | None:
    """The built-in description of the same arm as `robot` (same joint count, flange
    frames within MATCH_M / MATCH_RAD at MATCH_POSES random poses inside both arms'
    limits) with a plausible mass model, else None."""
    from robot_calib.kinematics.description import ROBOTS_DIR, available_robots, load_robot_yaml

    low = robot.limits[:, 0]
    high = robot.limits[:, 1]
    for name in available_robots():
        other = load_robot_yaml(ROBOTS_DIR / f"{name}.yaml")
        if other.n_joints != robot.n_joints or mass_model_problems(other):
            continue
        if not np.any(other.link_mass > 0):
            continue
        lo, hi = np.maximum(low, other.limits[:, 0]), np.minimum(high, other.limits[:, 1])
        if np.any(lo > hi):
            continue
        q = np.random.default_rng(0).uniform(lo, hi, (MATCH_POSES, robot.n_joints))
        mine, theirs = robot.nominal_frames(q)[:, -1], other.nominal_frames(q)[:, -1]
        if (
            np.abs(mine[:, :3, 3] - theirs[:, :3, 3]).max() <= MATCH_M
            and np.abs(mine[:, :3, :3] - theirs[:, :3, :3]).max() <= MATCH_RAD
        ):
            return other
    return None


def _carried_over(twin: RobotDescription, robot: RobotDescription) -> tuple[Array, Array]:
    """`twin`'s link masses (J,) [kg] and centres of mass carried into `robot`'s DH
    frames (J, 3) [m] through both arms' frames at the zero pose."""
    zero = np.zeros((1, robot.n_joints))
    theirs, mine = twin.nominal_frames(zero)[0, 1:], robot.nominal_frames(zero)[0, 1:]
    in_base = np.einsum("jab,jb->ja", theirs[:, :3, :3], twin.link_com) + theirs[:, :3, 3]
    com = np.einsum("jba,jb->ja", mine[:, :3, :3], in_base - mine[:, :3, 3])
    return twin.link_mass.copy(), com


def default_masses(robot: RobotDescription) -> tuple[Array, Array]:
    """A default mass model from `robot`'s geometry (module docstring): masses (J,) [kg]
    and centres of mass (J, 3) [m, DH frame j], each link's centre midway between its
    frame's origin and the previous one at the zero pose."""
    frames = robot.nominal_frames(np.zeros((1, robot.n_joints)))[0]
    origins = frames[:, :3, 3]  # (J + 1, 3)
    length = np.maximum(np.linalg.norm(np.diff(origins, axis=0), axis=1), MIN_LINK_M)
    mass = DEFAULT_DENSITY_KG_M3 * reach_m(robot) ** 3 * length / length.sum()
    middle = 0.5 * (origins[:-1] + origins[1:])
    com = np.einsum("jba,jb->ja", frames[1:, :3, :3], middle - frames[1:, :3, 3])
    return mass, com


def mass_model_line(robot: RobotDescription) -> str:
    """Which masses the gravity effects used and where they came from, for the reports:
    the description's (its source, the total), a substitute (which, and why), none (why),
    and a payload when given."""
    payload = robot.payload_kg
    own = float(np.sum(robot.link_mass)) - payload
    if robot.mass_note:
        text = robot.mass_note
    elif own > 0:
        text = f"the description's ({robot.source or robot.name}), {own:.1f} kg in all"
    else:
        text = "none: the description gives no masses (no gravity effect of its own weight)"
    if payload > 0:
        com = ", ".join(f"{v:.3f}" for v in robot.payload_com_m)
        text += f"; a payload of {payload:.2f} kg at ({com}) m of the flange ({param('payload')})"
    return text
