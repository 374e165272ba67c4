"""The nominal controller running a program on the true simulated robot: where the tool
really goes for a program's targets (test/compensation and scripts/program_figures.py
score compensated programs with it).

A controller given a Cartesian target with configuration data moves to the inverse
kinematics' solution on that configuration; without configuration data, to the solution
nearest the arm's pose before the motion (the taught readings stand for it here). Axis
targets are moved to as written. The true robot (the world's model and truth: every
effect, with the approach directions of the sequence) puts the tool there.
"""

from __future__ import annotations

import itertools

import numpy as np

from robot_calib.compensation.solve import BRANCHES, branch_seed
from robot_calib.ik import solve_ik
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.model import KinematicModel
from robot_calib.poses import Poses, approach_directions
from robot_calib.programs.configuration import matches
from robot_calib.programs.language import Language
from robot_calib.programs.source import Program
from robot_calib.sim.world import World


def controller_solutions(
    language: Language, program: Program, robot: RobotDescription, goal: Array, start: Array
) -> Array:
    """(n, J) readings the nominal controller moves to for pose targets with flange goals
    (n, 4, 4): the solution the nominal inverse kinematics finds from the start readings,
    where it is within the limits and (a language with configuration data) on the target's
    configuration, axes 1, 4, 6 turned by whole turns where that gets it there; else the
    first such solution from seeds spread over the arm's branches (both facings of axis 1,
    elbow and wrist both ways). A configuration picks one solution of a 6-axis arm;
    without one, a controller takes the one nearest the arm (the start)."""
    nominal = KinematicModel(robot, ())
    params = nominal.parameters()
    targets = [t for t in program.targets if t.kind == "pose"]
    out = np.full_like(start, np.nan)
    seeds = [start] + [branch_seed(start, robot.limits, *branch) for branch in BRANCHES]
    best = np.full(len(start), np.inf)
    for k, seed in enumerate(seeds):  # the start first; the branches for rows left
        rows = np.arange(len(start)) if k == 0 else np.flatnonzero(~np.isfinite(best))
        if not rows.size:
            break
        ik = solve_ik(
            nominal,
            params,
            Poses.from_readings(seed[rows]),
            goal[rows],
            np.eye(4),
            tolerance_m=1e-12,
            max_iterations=100,
        )
        for i, row in enumerate(rows.tolist()):
            if not ik.converged[i]:
                continue
            found = _on_configuration(language, robot, targets[row].configuration, ik.q[i])
            if found is not None:
                distance = float(np.abs(found - start[row]).max())
                if distance < best[row]:
                    best[row], out[row] = distance, found
    for row, target in enumerate(targets):
        assert np.isfinite(out[row]).all(), (
            f"{target.name}: the controller finds no solution on its configuration"
        )
    return out


def _on_configuration(
    language: Language,
    robot: RobotDescription,
    wanted: tuple[int, ...] | None,
    q: Array,
) -> Array | None:
    """Readings q (J,) [rad], axes 1, 4, 6 turned by -1, 0 or +1 turn, within the limits and
    on the wanted configuration (any, without one): the fewest turns first; None if none."""
    limits = robot.limits
    shifts = sorted(itertools.product((-1, 0, 1), repeat=3), key=lambda t: sum(map(abs, t)))
    for shift in shifts:
        trial = q.copy()
        trial[[0, 3, 5]] += 2 * np.pi * np.array(shift)
        if not np.all((trial >= limits[:, 0]) & (trial <= limits[:, 1])):
            continue
        if wanted is None or language.configuration is None:
            return trial
        (config,) = language.configuration(robot, trial[None])
        if matches(config, wanted):
            return trial
    return None


def drive(
    language: Language,
    program: Program,
    taught_q: Array,
    world: World,
    tool2flange: Array,
    base2robot: Array,
) -> Array:
    """(n, 4, 4) where the true robot puts the tool at each target of `program` (program
    order) driven by the nominal controller: axis targets as written; pose targets at the
    controller's solution (`controller_solutions`: on the target's configuration, the one
    nearest the taught readings), with the approach directions of the sequence."""
    q = np.array(taught_q, dtype=float)
    kinds = np.array([t.kind for t in program.targets])
    poses = np.flatnonzero(kinds == "pose")
    joints = np.flatnonzero(kinds == "joints")
    if poses.size:
        values = np.array([program.targets[k].values for k in poses])
        goal = base2robot @ language.pose_to_base(values) @ np.linalg.inv(tool2flange)
        q[poses] = controller_solutions(language, program, world.model.robot, goal, q[poses])
    if joints.size:
        q[joints] = np.array([program.targets[k].values for k in joints]) * language.joint_unit
    at = Poses(q, approach_directions(q), np.zeros(len(q)))
    return world.model.flange2base(world.truth, at) @ tool2flange
