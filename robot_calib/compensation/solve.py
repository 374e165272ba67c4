"""Compensated joint commands: for nominal commands, and for targets (positions or poses).

The calibrated model, effects included (backlash with the commands' approach directions,
compliance, transmission error, thermal terms at the commands' times and temperatures),
says where the robot really goes. Compensation finds the readings q at which it puts the
tool (the calibration's first target: its point, and its probe frame's orientation where it
has one, else the flange's) at a goal pose in the robot base frame:

    flange2base_calibrated(q) * tool2flange  =  goal2base

Both kinds of goal go through one solver (`ik.solve_ik`: batched damped least squares):

- `compensate_commands`: a program taught or planned on the nominal model commands q_cmd
  (n, J) and expects the tool where the nominal model puts it: goal2base =
  T_nominal(q_cmd) * tool2flange, seeded at q_cmd (6 equations). Where that swings a joint
  by more than SINGULAR_CHANGE_DEG (near the wrist singularity a few urad of orientation
  cost joints 4 and 6 degrees), the row is solved for the tool position alone (3
  equations, the smallest joint change): `position_only`, its orientation error reported.
- `compensate_targets`: goal poses (or positions: 3 equations, the orientation left where
  the seed has it up to the smallest correction) given in the base or tracker frame; seeded
  at the nominal model's inverse kinematics, itself started from the given seed readings
  or the home pose.

A hybrid calibration (PARAMS.json `correction`: a learned residual r(q), predicted -
measured) puts the tool at model(q) - r(q). Both solve for that (`solve_corrected`): the
model is aimed at the goal + r(q) of the current solution, fixed-point rounds until
model(q) - r(q) is within the inverse kinematics' tolerance of the goal, at most
CORRECTION_ROUNDS (r changes by about its size per radian of the readings, a mm: a round
shrinks the gap by ~1e-3 to ~1e-2, measured: the simulated UR10's hybrid corrections of
compliance, a gravity-side backlash and a bending link settle within 1e-8 m in three
rounds). A row's reported error is that of model - correction against the goal (what
is achieved), and a row whose fixed point does not settle within the tolerance is not
converged. The correction is of the target point: orientations are the model's.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from robot_calib.compensation.targets import Targets
from robot_calib.ik import (
    CONVERGED_M,
    ORIENTATION_LEVER_M,
    TOLERANCE_M,
    IKSolution,
    first_tool2flange,
    pose_error,
    solve_ik,
    tool2base,
)
from robot_calib.kinematics.description import RobotDescription, home_variables
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import Calibrated, KinematicModel, PointCorrection
from robot_calib.poses import Poses, approach_directions

#: Compensated readings of nominal commands: `ik.IKSolution` (q, error_m, error_rad,
#: iterations, converged) of the calibrated model.
Compensation = IKSolution
SINGULAR_CHANGE_DEG = 2.0  # a calibration corrects by mrad: a larger swing is a singularity

NOMINAL_ITERATIONS = 100  # the nominal inverse kinematics may start far (the home pose)
CORRECTION_ROUNDS = 8  # fixed-point rounds of a learned correction at most (module docstring)
DIRECTION_ROUNDS = 3  # re-solves at most when compensating flips an approach direction


def solve_corrected(
    model: KinematicModel,
    params: ParameterVector,
    poses: Poses,
    goal2base: Array,
    tool2flange: Array,
    oriented: NDArray[np.bool_] | None = None,
    correction: PointCorrection | None = None,
) -> IKSolution:
    """`ik.solve_ik` for a model whose first target really sits at its point minus the
    learned `correction`'s predicted residual (tracker frame): the model aimed at
    goal + R r(q) (R: tracker to base) at the current solution, each round seeded at the
    last, on the rows whose model - correction is not yet within TOLERANCE_M of the goal
    (at most CORRECTION_ROUNDS rounds); `iterations` counts every round's steps; the errors
    are those of model - correction against the goal at the readings returned, and a row is
    converged when its last solve was and that error (position + lever x orientation) is
    below max(TOLERANCE_M, CONVERGED_M), as `solve_ik`'s. Without a correction:
    `solve_ik`."""
    found = solve_ik(model, params, poses, goal2base, tool2flange, oriented)
    if correction is None:
        return found
    rotation = model.base2tracker(params)[:3, :3]
    weight = np.ones((len(poses), 6))
    if oriented is not None:
        weight[~np.asarray(oriented, dtype=bool), 3:] = 0.0
    q, steps, solved = found.q.copy(), found.iterations.copy(), found.converged.copy()
    error = np.zeros((len(poses), 6))
    rows = np.arange(len(poses))  # those not yet within the tolerance
    for round_ in range(CORRECTION_ROUNDS + 1):
        seed = poses.subset(rows)
        reached = np.isfinite(q[rows]).all(axis=1, keepdims=True)  # others: at their seed
        at = replace(seed, q=np.where(reached, q[rows], seed.q), target=None)
        # `model.corrected` of tool frames: the predicted residual R^T r, row-wise, in the
        # base frame, taken off the model's tool positions
        shift = correction.predict(at) @ rotation
        achieved = tool2base(model, params, at, tool2flange)
        achieved[:, :3, 3] -= shift
        error[rows] = weight[rows] * pose_error(achieved, goal2base[rows])
        left = np.linalg.norm(error[rows], axis=1) >= TOLERANCE_M
        rows, at, shift = rows[left], at.subset(np.flatnonzero(left)), shift[left]
        if not rows.size or round_ == CORRECTION_ROUNDS:
            break
        shifted = goal2base[rows].copy()
        shifted[:, :3, 3] += shift
        part = solve_ik(
            model,
            params,
            at,
            shifted,
            tool2flange,
            None if oriented is None else np.asarray(oriented)[rows],
        )
        q[rows], solved[rows] = part.q, part.converged
        steps[rows] += part.iterations
    size = np.linalg.norm(error, axis=1)
    return IKSolution(
        q,
        np.linalg.norm(error[:, :3], axis=1),
        np.linalg.norm(error[:, 3:], axis=1) / ORIENTATION_LEVER_M,
        steps,
        solved & (size < max(TOLERANCE_M, CONVERGED_M)),
    )


def compensate_commands(
    calibration: Calibrated, commands: Poses, tool2flange: Array | None = None
) -> Compensation:
    """The compensated readings of `commands` (readings (n, J) [rad], approach directions
    and times of the nominal program; see the module docstring) for `calibration` (its
    model, parameters and learned correction, the hybrid model's). The tool, in both
    models, is `tool2flange` (4, 4) [m] (a program's TCP in the flange frame), else the
    calibrated first target; the nominal model is `nominal_counterpart`; both in the
    robot base frame."""
    calibrated, params = calibration.model, calibration.parameters
    correction = calibration.correction
    nominal, nominal_params = nominal_counterpart(calibrated, params)
    tool = first_tool2flange(calibrated, params) if tool2flange is None else tool2flange
    goal = tool2base(nominal, nominal_params, replace(commands, rotation=None), tool)
    full = solve_corrected(calibrated, params, commands, goal, tool, correction=correction)
    swing = np.abs(full.q - commands.q).max(axis=1)
    rows = np.flatnonzero(swing > np.radians(SINGULAR_CHANGE_DEG))
    if not rows.size:
        return full
    # near a singularity the exact pose swings joints 4 and 6 by degrees for a few urad of
    # orientation: solve the tool position alone there (the smallest joint change)
    part = commands.subset(rows)
    point = solve_corrected(
        calibrated, params, part, goal[rows], tool, np.zeros(rows.size, bool), correction
    )
    better = np.abs(point.q - part.q).max(axis=1) < swing[rows]
    rows, q = rows[better], point.q[better]
    at = tool2base(calibrated, params, replace(commands.subset(rows), q=q), tool)
    left = np.linalg.norm(pose_error(at, goal[rows])[:, 3:], axis=1) / ORIENTATION_LEVER_M
    fields = ("q", "error_m", "error_rad", "iterations", "converged")
    merged = {name: getattr(full, name).copy() for name in fields}
    merged["q"][rows], merged["error_rad"][rows] = q, left
    for name in ("error_m", "iterations", "converged"):
        merged[name][rows] = getattr(point, name)[better]
    position_only = np.zeros(len(commands), dtype=bool)
    position_only[rows] = True
    return IKSolution(**merged, position_only=position_only)


@dataclass(frozen=True)
class TargetCompensation:
    """Commands for targets.

    nominal : the nominal model's inverse kinematics (the seeds of the compensation):
        readings (n, J) [rad] and its errors
    compensated : the calibrated model's: readings (n, J) [rad], errors, iterations
    direction : shape (n, J), the approach directions (+1/-1) the compensation assumed:
        the given ones, or those of the compensated commands in row order
    within_limits : shape (n,) bool, the compensated readings inside the robot's limits
    """

    nominal: IKSolution
    compensated: IKSolution
    direction: Array
    within_limits: NDArray[np.bool_]

    @property
    def reached(self) -> NDArray[np.bool_]:
        """(n,) targets the calibrated model reaches within the joint limits."""
        return self.compensated.converged & self.within_limits


def home_readings(
    model: KinematicModel, params: ParameterVector, goal2base: Array, tool2flange: Array
) -> Array:
    """(n, J) readings [rad] of the home pose (`home_variables`) with joint 1 turned
    to face each goal (n, 4, 4) (base frame): the default seed of the nominal inverse
    kinematics. Joint 1's axis is the base z axis."""
    variables = home_variables(model.robot.n_joints)
    home = model.robot.readings(variables[None, :])
    tool = tool2base(model, params, Poses.from_readings(home), tool2flange)[0, :3, 3]
    turn = np.arctan2(goal2base[:, 1, 3], goal2base[:, 0, 3]) - np.arctan2(tool[1], tool[0])
    out = np.tile(variables, (len(goal2base), 1))
    out[:, 0] += np.angle(np.exp(1j * turn))  # wrapped to (-pi, pi]
    return model.robot.readings(out)


def wrap_into_limits(q: Array, limits: Array) -> Array:
    """(n, J) readings [rad] shifted by whole turns into the joint limits (J, 2) [rad] where a
    shift gets them there (the same pose: the joint variables change by whole turns for
    identity and integer couplings); others unchanged."""
    low = q - 2 * np.pi * np.floor((q - limits[:, 0]) / (2 * np.pi))  # lowest turn >= min
    return np.where((low <= limits[:, 1]) & ((q < limits[:, 0]) | (q > limits[:, 1])), low, q)


def _inside(q: Array, limits: Array) -> NDArray[np.bool_]:
    """(n,) readings q (n, J) [rad] within the joint limits (J, 2) [rad], exactly."""
    return np.all((q >= limits[:, 0]) & (q <= limits[:, 1]), axis=1)


def _merged(
    found: IKSolution,
    rows: IntArray,
    again: IKSolution,
    better: NDArray[np.bool_],
    spent: IntArray,
) -> IKSolution:
    """`found` with its rows `rows` solved again (`again`, one row each): readings, errors
    and convergence taken where `better` (len(rows),), and `spent` (len(rows),) steps of
    the new attempt added to those rows' iterations."""
    out = {
        name: getattr(found, name).copy() for name in ("q", "error_m", "error_rad", "converged")
    }
    for name, values in out.items():
        values[rows[better]] = getattr(again, name)[better]
    iterations = found.iterations.copy()
    iterations[rows] += spent
    return replace(found, iterations=iterations, **out)


def nominal_ik(
    nominal: KinematicModel,
    nominal_params: ParameterVector,
    start: Poses,
    goal2base: Array,
    tool: Array,
    oriented: NDArray[np.bool_],
    program: bool,
    pinned: NDArray[np.bool_] | None = None,
) -> IKSolution:
    """The nominal inverse kinematics from `start`'s readings, shifted into the joint limits
    by whole turns; targets it does not reach (or only beyond the limits) are tried once more
    from the solution of the nearest target (tool point) it reached within them, then from
    seeds on the arm's other branches (`_other_branches`); with `program` (rows of a
    program, no seeds given) the rows are kept on one branch (`_follow_the_rows`), rows
    `pinned` (n,) (a program's axis targets: their seeds are their solutions) never
    moved."""
    limits = nominal.robot.limits

    def solve(poses: Poses, goal: Array, which: NDArray[np.bool_]) -> IKSolution:
        found = solve_ik(
            nominal, nominal_params, poses, goal, tool, which, max_iterations=NOMINAL_ITERATIONS
        )
        return replace(found, q=wrap_into_limits(found.q, limits))

    first = solve(start, goal2base, oriented)
    good = first.converged & _inside(first.q, limits)
    if not good.all():  # another branch: from seeds spread over the arm's joint ranges
        first = _other_branches(first, start, goal2base, oriented, solve, limits)
        good = first.converged & _inside(first.q, limits)
    if not good.all() and good.any():
        retry, done = np.flatnonzero(~good), np.flatnonzero(good)
        from scipy.spatial import cKDTree  # nearest neighbours of thousands in milliseconds

        points = goal2base[:, :3, 3]
        distance, nearest = cKDTree(points[done]).query(points[retry])
        retry = retry[np.isfinite(distance)]  # no neighbour (a point at infinity): as it was
        if retry.size:
            seeds = first.q[done[nearest[np.isfinite(distance)]]]
            again = solve(replace(start.subset(retry), q=seeds), goal2base[retry], oriented[retry])
            first = _merged(
                first,
                retry,
                again,
                again.converged,
                np.where(again.converged, again.iterations, 0),
            )
    if not program:
        return first
    return _follow_the_rows(first, start, goal2base, oriented, solve, limits, pinned)


#: a change of any joint by more than this between consecutive rows of a program [rad]
#: is a switch of branch when another solution within the limits moves less
BRANCH_JUMP_RAD = 0.5


def _follow_the_rows(
    found: IKSolution,
    start: Poses,
    goal2base: Array,
    oriented: NDArray[np.bool_],
    solve: Callable[[Poses, Array, NDArray[np.bool_]], IKSolution],
    limits: Array,
    pinned: NDArray[np.bool_] | None = None,
) -> IKSolution:
    """`found` (the nominal IK of the rows of a program, solved each on its own) with every
    row (but those `pinned`) that jumps more than BRANCH_JUMP_RAD from the row before solved
    again from that row's solution (`solve`), kept where it converges within the limits
    and moves less: a program of close targets stays on one branch (elbow up or down,
    reaching forwards or over backwards) instead of switching between them from one target
    to the next.

    The row-by-row rule (each row decided from the row before as it finally stands, from its
    own solution in `found`) in batched rounds: every candidate row starts over from `found`,
    those that jump are solved at once from the row before as it stands, and the rows after
    those that changed are the next round's candidates, until none changes. A row decided
    from a row before that later changes is decided again, so the result is the row-by-row
    one (was one solve per row: 917 s for 10000 scattered targets; now 9.9 s)."""
    names = ("error_m", "error_rad", "iterations", "converged")
    q = found.q.copy()
    fields = {name: getattr(found, name).copy() for name in names}
    ok = found.converged & _inside(found.q, limits)
    free = np.ones(len(q), dtype=bool) if pinned is None else ~np.asarray(pinned, dtype=bool)
    candidates = np.flatnonzero(free[1:]) + 1
    while candidates.size:
        before = q[candidates].copy()
        q[candidates] = found.q[candidates]  # start over: the row before may have changed
        for name in names:
            fields[name][candidates] = getattr(found, name)[candidates]
        jump = np.abs(q[candidates] - q[candidates - 1]).max(axis=1)
        jumps = ok[candidates] & ok[candidates - 1] & (jump > BRANCH_JUMP_RAD)
        rows = candidates[jumps]
        if rows.size:
            again = solve(
                replace(start.subset(rows), q=q[rows - 1]), goal2base[rows], oriented[rows]
            )
            better = (
                again.converged
                & _inside(again.q, limits)
                & (np.abs(again.q - q[rows - 1]).max(axis=1) < jump[jumps])
            )
            kept = rows[better]
            q[kept] = again.q[better]
            for name in ("error_m", "error_rad", "converged"):
                fields[name][kept] = getattr(again, name)[better]
            fields["iterations"][kept] += again.iterations[better]
        # decided again: the rows after a row that now differs from what they were decided
        # against (its value before this round, or the start-over value this round's
        # decisions used); the first candidate moves down each round: at most n rounds
        now = q[candidates]
        moved = candidates[
            np.any(now != before, axis=1) | np.any(now != found.q[candidates], axis=1)
        ]
        candidates = moved[moved + 1 < len(q)] + 1
        candidates = candidates[free[candidates]]
    return replace(found, q=q, **fields)


#: where in each joint's range the branch seeds put joints 2, 3 and 5 (joint 1 facing the
#: target, then facing away: reaching over backwards; 4 and 6 at zero): elbow up and down,
#: wrist flipped or not
BRANCH_SHARES = (
    (0.3, 0.3, 0.25),
    (0.3, 0.7, 0.25),
    (0.7, 0.3, 0.25),
    (0.7, 0.7, 0.25),
    (0.3, 0.3, 0.75),
    (0.3, 0.7, 0.75),
    (0.7, 0.3, 0.75),
    (0.7, 0.7, 0.75),
)


#: the branch seeds' (turn of joint 1 [rad], shares of joints 2, 3 and 5): facing the
#: target, then away from it, each with every BRANCH_SHARES
BRANCHES = tuple((turn, shares) for turn in (0.0, np.pi) for shares in BRANCH_SHARES)


def branch_seed(
    facing: Array, limits: Array, turn: float, shares: tuple[float, float, float]
) -> Array:
    """Seed readings (n, J) [rad] on one branch: joint 1 as in `facing` (n, J) turned by
    `turn`, joints 2, 3 and 5 at `shares` of their ranges (J, 2), joints 4 and 6 at 0."""
    seed = np.array(facing, dtype=float)
    seed[:, 0] = np.angle(np.exp(1j * (seed[:, 0] + turn)))  # facing it, or away
    seed[:, 3:] = 0.0
    for joint, share in zip((1, 2, 4), shares):
        seed[:, joint] = limits[joint, 0] + share * (limits[joint, 1] - limits[joint, 0])
    return seed


def _other_branches(
    found: IKSolution,
    start: Poses,
    goal2base: Array,
    oriented: NDArray[np.bool_],
    solve: Callable[[Poses, Array, NDArray[np.bool_]], IKSolution],
    limits: Array,
) -> IKSolution:
    """`found` with the targets it did not reach within the joint limits (a position target
    of a 6-joint arm has many solutions; from the home pose the solver may end on the
    branch behind the robot, beyond joint 1's limits) solved again from BRANCH_SHARES seeds,
    joint 1 facing the target and then away from it, until one converges within the
    limits."""
    if found.q.shape[1] < 5:
        return found
    for branch in BRANCHES:
        left = np.flatnonzero(~(found.converged & _inside(found.q, limits)))
        if not left.size:
            break
        seed = branch_seed(start.q[left], limits, *branch)
        again = solve(replace(start.subset(left), q=seed), goal2base[left], oriented[left])
        found = _merged(
            found, left, again, again.converged & _inside(again.q, limits), again.iterations
        )
    return found


def compensate_targets(
    calibration: Calibrated, targets: Targets, goal2base: Array
) -> TargetCompensation:
    """Commands at which the calibrated model reaches the goals.

    calibration : its model, parameters and learned correction (the hybrid model: the
        model aimed at goal + the predicted residual, `solve_corrected`)
    targets : the rows of a TARGETS.csv (seeds, directions, times, temperatures)
    goal2base : shape (n, 4, 4), the goal tool frames in the robot base frame [m]
        (`targets.goals_in_base`); only the position where `targets.rotation` is None

    The nominal model's inverse kinematics from the seeds (or the home pose) gives the start;
    the calibrated model's from there the commands. Without given directions, those of the
    commands found in row order are used, re-solving (at most DIRECTION_ROUNDS times) where
    compensating flips one.
    """
    calibrated, params = calibration.model, calibration.parameters
    correction = calibration.correction
    nominal, nominal_params = nominal_counterpart(calibrated, params)
    n = len(targets)
    oriented = np.full(n, targets.rotation is not None)
    tool = first_tool2flange(calibrated, params)
    seed = (
        targets.seed
        if targets.seed is not None
        else home_readings(nominal, nominal_params, goal2base, tool)
    )
    ones = np.ones_like(seed)
    start = Poses(seed, ones, targets.time, temperature=targets.temperature)
    # without seeds: rows of a program, kept on one branch
    first = nominal_ik(
        nominal, nominal_params, start, goal2base, tool, oriented, program=targets.seed is None
    )
    direction = approach_directions(first.q) if targets.direction is None else targets.direction
    poses = replace(start, q=first.q, direction=direction)
    result = solve_corrected(calibrated, params, poses, goal2base, tool, oriented, correction)
    steps = result.iterations.copy()  # every round's steps count: the target's iterations
    for _ in range(DIRECTION_ROUNDS if targets.direction is None else 0):
        found = approach_directions(result.q)
        if np.array_equal(found, direction):
            break
        direction = found
        poses = replace(poses, q=result.q, direction=direction)
        result = solve_corrected(calibrated, params, poses, goal2base, tool, oriented, correction)
        steps += result.iterations
    result = replace(result, iterations=steps)
    within = within_limits(calibrated.robot, result.q)
    return TargetCompensation(first, result, direction, within)


def within_limits(robot: RobotDescription, q: Array) -> NDArray[np.bool_]:
    """(n,) readings q (n, J) [rad] that pass the one check of limits and units
    (`RobotDescription.check_joints`: finite, within the limits, not degrees); nan rows
    (not reached) count as within, their status says not_reached."""
    q = np.asarray(q, dtype=float).reshape(-1, robot.n_joints)
    unreached = np.asarray(~np.isfinite(q).all(axis=1), dtype=np.bool_)
    within = unreached.copy()
    within[~unreached] = [text is None for text in robot.joint_violations(q[~unreached])]
    return within


def nominal_counterpart(
    model: KinematicModel, params: ParameterVector
) -> tuple[KinematicModel, ParameterVector]:
    """The nominal model of a calibration (the robot's nominal geometry, no effects) with
    the calibration's tracker pose and target offsets: what a program taught on the nominal
    model expects, in the same frames."""
    nominal = KinematicModel(model.robot, (), model.targets, model.oriented)
    fresh = nominal.parameters()
    frames = {p.name: params[p.name] for p in fresh.parameters if p.group == "frames"}
    return nominal, fresh.with_values(frames)
