"""A robot program, compensated: every motion target replaced by the one the nominal
controller must be given so that the calibrated robot puts the program's tool where the
program meant it (msgs_doc/programs.md).

For each target, in the order the program first moves to it:

1. what the program means: a pose target is the tool's pose in its base frame, in the
   robot base frame G = base2robot x target; an axis target is where the nominal model
   puts the tool at those axis values, G = flange_nominal(q) x tool;
2. the nominal controller's solution q_nom: the axis values, or the nominal inverse
   kinematics of G on the configuration the target gives (the vendor's configuration
   data), else on the program's branch (rows followed as `nominal_ik` does);
3. the compensated readings q_cal at which the calibrated model (every effect, with the
   program's approach directions) puts the tool at G (`compensate_commands`, the tool
   the program's);
4. the new target: the axis values q_cal, or the pose the nominal model gives at q_cal,
   inv(base2robot) x flange_nominal(q_cal) x tool, which the controller turns back into
   q_cal on the same configuration. A target whose q_cal needs another configuration is
   left as it was and marked.

The calibration's measured target (the SMR) is not the program's tool: the tool frame is
the program's (or an option's) in the flange frame of the calibrated model. What a point
target cannot observe (the flange's roll about joint 6 and its offset along it, taken as
nominal) is carried into a tool away from the SMR as it is on the robot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robot_calib.compensation.solve import (
    BRANCHES,
    DIRECTION_ROUNDS,
    NOMINAL_ITERATIONS,
    branch_seed,
    compensate_commands,
    home_readings,
    nominal_counterpart,
    nominal_ik,
    within_limits,
)
from robot_calib.compensation.write import LARGE_CHANGE_DEG, row_status
from robot_calib.errors import InputError, param
from robot_calib.ik import solve_ik
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.model import Calibrated
from robot_calib.poses import Poses, approach_directions
from robot_calib.programs.configuration import matches, singular_margin
from robot_calib.programs.language import Language
from robot_calib.programs.source import EVERY, OUTSIDE, Frame, Program, Target, rewrite

#: statuses of targets written compensated; every other target is left as it was
WRITTEN = ("ok", "position_only", "near_singular")
#: `singular_margin` below this [m] at the nominal solution: the controller may take
#: another solution close by, the target is written but named
NEAR_SINGULAR_M = 0.01
TURNS = (-1, 0, 1)  # whole turns tried on axes 1, 4 and 6 to meet a configuration
#: readings this close to a boundary of the configuration data (a sign, a quadrant) meet
#: either side [deg]: the rounding of a taught target's numbers moves its solution by ~1e-3
BOUNDARY_DEG = 0.005


@dataclass(frozen=True)
class TargetRow:
    """One target's outcome.

    target : as read
    status : `ok`, `position_only` (near the wrist singularity: the tool point only),
        `near_singular` (written; within NEAR_SINGULAR_M of a singularity), or, left as it
        was: `large_change` (an axis would move more than LARGE_CHANGE_DEG),
        `not_reached`, `beyond_limits`, `configuration` (the calibrated solution needs
        another configuration than the target's, or the nominal one reaches none),
        `unused` (no motion goes to it), `left` (a note says why)
    values : the numbers written (the old ones where left)
    moved_mm : a pose target: how far its position moved [mm]; an axis target: how far
        the nominal model's tool moves between the old and new values [mm]
    turned_deg : a pose target: the angle between its old and new orientation [deg]; an
        axis target: the largest axis change [deg]
    error_m : the calibrated model's remaining tool error at q_cal [m] (nan where not
        solved)
    reason : the note, or why the status is not `ok`, in words
    """

    target: Target
    status: str
    values: tuple[float, ...]
    moved_mm: float
    turned_deg: float
    error_m: float
    reason: str


@dataclass(frozen=True)
class ProgramCompensation:
    """A compensated program: its files' new texts (same names as `program.texts`) and a
    row per target, in the program's order."""

    program: Program
    texts: dict[str, str]
    rows: tuple[TargetRow, ...]

    def count(self, *statuses: str) -> int:
        return sum(row.status in statuses for row in self.rows)


def frames_of(
    program: Program,
    language: Language,
    given_tools: dict[str, Frame],
    given_bases: dict[str, Frame],
) -> tuple[dict[str, Frame], dict[str, Frame]]:
    """The program's frames with the given ones over them (a frame keyed EVERY serves
    every target); InputError naming the first motion to a target whose frame neither
    declares, and a given frame no target is moved to with (a typing slip: its key)."""
    tools, bases = {**program.tools, **given_tools}, {**program.bases, **given_bases}
    moving = [t for t in program.targets if t.used and not t.note]
    for kind, known, given in ((0, tools, given_tools), (1, bases, given_bases)):
        what = ("tool", "base")[kind]
        used = {(t.tool, t.base)[kind] for t in moving}
        for key in given:
            if key != EVERY and key not in used:
                names = ", ".join(sorted(k for k in used if k)) or "none"
                raise InputError(
                    f"{param(what, language.option_key(kind, key) + '=...')}: no target of "
                    f"{', '.join(program.texts)} is moved to with {what} {key} (it uses: "
                    f"{names})"
                )
        for target in moving:
            frame = (target.tool, target.base)[kind]
            if frame is not None and frame not in known and EVERY not in known:
                if OUTSIDE in frame:
                    raise InputError(
                        f"{program_file(program)}:{target.used[0]}: {target.name} is moved to "
                        f"with {what} {frame}: declare it in the program, or set the frame "
                        "before the motion"
                    )
                raise InputError(
                    f"{program_file(program)}:{target.used[0]}: {target.name} is moved to with "
                    f"{what} {frame}, which {' and '.join(program.texts)} declare(s) no value "
                    f"of: give it ({param(what, language.option_key(kind, frame) + '=...')})"
                )
    return tools, bases


def program_file(program: Program) -> str:
    """The file the program's motions are in (the first read: a KRL program's .src)."""
    return next(iter(program.texts))


def compensate_program(
    calibration: Calibrated,
    program: Program,
    language: Language,
    tools: dict[str, Frame] | None = None,
    bases: dict[str, Frame] | None = None,
) -> ProgramCompensation:
    """`program` compensated for `calibration` (module docstring); `tools` and `bases`:
    frames by key, over the program's own (`frames_of`)."""
    all_tools, all_bases = frames_of(program, language, tools or {}, bases or {})
    model, params = calibration.model, calibration.parameters
    nominal, nominal_params = nominal_counterpart(model, params)
    robot = model.robot
    rows = [k for k, t in enumerate(program.targets) if t.used and not t.note and t.values]
    n = len(rows)
    tool = np.array([_pose(all_tools, t.tool) for t in _at(program, rows)]).reshape(n, 4, 4)
    base = np.array([_pose(all_bases, t.base) for t in _at(program, rows)]).reshape(n, 4, 4)
    joints = np.array([program.targets[k].kind == "joints" for k in rows], dtype=bool)
    q_nom = np.zeros((n, robot.n_joints))
    for j in np.flatnonzero(joints).tolist():
        q_nom[j] = np.asarray(program.targets[rows[j]].values) * language.joint_unit
    poses = np.flatnonzero(~joints)
    goal = np.zeros((n, 4, 4))
    if poses.size:
        values = np.array([program.targets[rows[j]].values for j in poses])
        goal[poses] = base[poses] @ language.pose_to_base(values)
    solved = np.ones(n, dtype=bool)
    reachable = np.ones(n, dtype=bool)
    if poses.size:
        q_nom, solved, reachable = _nominal_solutions(
            calibration, program, language, rows, joints, q_nom, goal, tool
        )
    if joints.any():  # what the program means at its axis values
        at = Poses.from_readings(q_nom[joints])
        goal[joints] = nominal.flange2base(nominal_params, at) @ tool[joints]
    q_cal, error, status = _compensated(calibration, q_nom, solved, tool)
    reason = [""] * n
    for row in np.flatnonzero(~solved).tolist():
        if reachable[row]:
            status[row], reason[row] = "configuration", _unreached(program.targets[rows[row]])
        else:
            status[row] = "not_reached"
            reason[row] = "out of the nominal arm's reach: no solution within the axis limits"
    _check_configuration(program, language, robot, rows, q_cal, status, reason)
    if n:
        margin = singular_margin(robot, np.nan_to_num(q_nom))
        for row in np.flatnonzero(margin < NEAR_SINGULAR_M).tolist():
            if status[row] == "ok":
                status[row] = "near_singular"
                reason[row] = (
                    f"{margin[row] * 1e3:.1f} mm from a singularity (the Jacobian's smallest "
                    "singular value): written, but the controller may take another solution "
                    "close by; check it"
                )
    new: dict[int, tuple[float, ...]] = {}
    out_rows = {}
    done = np.array([s in WRITTEN for s in status], dtype=bool)
    # the nominal model's tool at the compensated and the nominal readings, in one batch
    safe = np.where(done[:, None], q_cal, q_nom)
    after = nominal.flange2base(nominal_params, Poses.from_readings(np.nan_to_num(safe))) @ tool
    before = nominal.flange2base(nominal_params, Poses.from_readings(np.nan_to_num(q_nom)))
    before = before @ tool
    written = np.linalg.inv(base) @ after  # Cartesian targets as the program holds them
    cartesian = np.flatnonzero(done & ~joints)
    pose_values: dict[int, Array] = {}
    if cartesian.size:
        old_values = np.array([program.targets[rows[j]].values for j in cartesian])
        converted = language.base_to_pose(written[cartesian], old_values)
        pose_values = dict(zip(cartesian.tolist(), converted))
    for j, k in enumerate(rows):
        target = program.targets[k]
        old = np.asarray(target.values)
        reason[j] = reason[j] or ("" if status[j] == "ok" else _why(status[j]))
        if not done[j]:
            out_rows[k] = TargetRow(target, status[j], target.values, 0.0, 0.0, np.nan, reason[j])
            continue
        if joints[j]:
            values = q_cal[j] / language.joint_unit
            moved = np.linalg.norm(after[j, :3, 3] - before[j, :3, 3]) * 1e3
            turned = np.degrees(np.abs(q_cal[j] - q_nom[j]).max())
        else:
            values = pose_values[j]
            was = language.pose_to_base(old[None])[0]
            moved = np.linalg.norm(written[j, :3, 3] - was[:3, 3]) * 1e3
            cos = (np.trace(was[:3, :3].T @ written[j, :3, :3]) - 1.0) / 2.0
            turned = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
        new[k] = tuple(float(v) for v in values)
        out_rows[k] = TargetRow(
            target, status[j], new[k], float(moved), float(turned), float(error[j]), reason[j]
        )
    for k, target in enumerate(program.targets):
        if k not in out_rows:
            left = "unused" if not target.used else "left"
            why = target.note or "no motion goes to it"
            out_rows[k] = TargetRow(target, left, target.values, 0.0, 0.0, np.nan, why)
    places = {
        k: language.places(program.targets[k].kind, len(program.targets[k].values)) for k in new
    }
    texts = rewrite(program, new, places)
    return ProgramCompensation(program, texts, tuple(out_rows[k] for k in range(len(out_rows))))


def _at(program: Program, rows: list[int]) -> list[Target]:
    return [program.targets[k] for k in rows]


def _directions(q: Array, solved: NDArray[np.bool_]) -> Array:
    """(n, J) approach directions of the rows' readings (n, J) [rad] in program order, an
    unsolved row standing where the row before it stands."""
    steady = np.nan_to_num(q.copy())
    for row in range(1, len(q)):
        if not solved[row]:
            steady[row] = steady[row - 1]
    return approach_directions(steady) if len(q) else np.zeros_like(q)


def _compensated(
    calibration: Calibrated, q_nom: Array, solved: NDArray[np.bool_], tool: Array
) -> tuple[Array, Array, list[str]]:
    """Compensated readings (n, J) [rad] of the solved rows of the nominal readings q_nom
    (nan elsewhere), the calibrated model's remaining tool error (n,) [m] and each row's
    status (`row_status`; `not_reached` where not solved): one solve per tool frame (n,
    4, 4), with the approach directions of the nominal rows, then again (at most
    DIRECTION_ROUNDS times) with those of the compensated rows where they differ (a joint
    that barely moves between two targets may turn the other way once compensated)."""
    robot = calibration.model.robot
    n = len(q_nom)
    q_cal = np.full_like(q_nom, np.nan)
    error = np.full(n, np.nan)
    status = ["not_reached"] * n
    keys = [_key(t) for t in tool]
    direction = _directions(q_nom, solved)
    again = solved.copy()  # rows to solve (again): all, then those whose directions changed
    for _ in range(DIRECTION_ROUNDS + 1):
        commands = Poses(q_nom, direction, np.zeros(n))
        for key in sorted(set(keys)):  # one solve per tool
            group = np.flatnonzero(np.array([k == key for k in keys]) & again)
            if not group.size:
                continue
            found = compensate_commands(calibration, commands.subset(group), tool[group[0]])
            inside = within_limits(robot, found.q) & within_limits(robot, q_nom[group])
            flags = row_status(found, q_nom[group], inside)
            q_cal[group], error[group] = found.q, found.error_m
            for i, row in enumerate(group.tolist()):
                status[row] = flags[i]
        reached = solved & np.isfinite(q_cal).all(axis=1)
        after = _directions(np.where(reached[:, None], q_cal, q_nom), solved)
        again = solved & (after != direction).any(axis=1)
        if not again.any():
            break
        direction = after
    return q_cal, error, status


def _pose(frames: dict[str, Frame], key: str | None) -> Array:
    """The frame serving a target whose program names `key` (None: the flange or base)."""
    if EVERY in frames:
        return frames[EVERY].pose
    return frames[key].pose if key is not None else np.eye(4)


def _key(tool: Array) -> bytes:
    return np.round(tool, 12).tobytes()


def _why(status: str) -> str:
    return {
        "large_change": f"an axis would move more than {LARGE_CHANGE_DEG:g} deg: left as it "
        "was (near a singularity?)",
        "not_reached": "the calibrated robot does not reach it (out of reach or singular)",
        "beyond_limits": "reached only beyond the axis limits",
        "position_only": "near the wrist singularity: the tool point compensated, its "
        "orientation left as the exact pose would swing an axis by degrees",
    }.get(status, status)


def _unreached(target: Target) -> str:
    if target.configuration is None:
        return "the nominal model reaches no solution within the axis limits"
    return (
        f"the nominal model reaches no solution within the axis limits on its "
        f"configuration {target.configuration}"
    )


def _configurations(
    language: Language, robot: RobotDescription, q: Array
) -> list[list[tuple[int, ...]]]:
    """Per row of readings q (n, J) [rad], its configuration and those of q moved by
    +-BOUNDARY_DEG on every axis (a row at a boundary meets either side)."""
    assert language.configuration is not None
    step = np.radians(BOUNDARY_DEG)
    sides = [language.configuration(robot, q + shift) for shift in (0.0, step, -step)]
    return [list(row) for row in zip(*sides)]


def _check_configuration(
    program: Program,
    language: Language,
    robot: RobotDescription,
    rows: list[int],
    q_cal: Array,
    status: list[str],
    reason: list[str],
) -> None:
    """Mark `configuration` the written pose targets whose compensated readings have
    another configuration than the target gives."""
    if language.configuration is None:
        return
    check = [
        j
        for j, k in enumerate(rows)
        if status[j] in WRITTEN
        and program.targets[k].kind == "pose"
        and program.targets[k].configuration is not None
    ]
    if not check:
        return
    found = language.configuration(robot, q_cal[check])  # exactly: what the controller gets
    for j, config in zip(check, found):
        wanted = program.targets[rows[j]].configuration
        assert wanted is not None
        if not matches(config, wanted):
            status[j] = "configuration"
            reason[j] = (
                f"the calibrated solution needs configuration {config}, the target gives "
                f"{wanted} (at a configuration boundary: left as it was)"
            )


def _nominal_solutions(
    calibration: Calibrated,
    program: Program,
    language: Language,
    rows: list[int],
    joints: NDArray[np.bool_],
    q_nom: Array,
    goal: Array,
    tool: Array,
) -> tuple[Array, NDArray[np.bool_], NDArray[np.bool_]]:
    """The nominal controller's readings (n, J) [rad] for the pose rows (the axis rows as
    given), which rows have one, and which have any solution within the axis limits
    (on another configuration, where the first ones have none): rows followed from the
    axis targets before them (`nominal_ik` as for a program), then, where a target's
    configuration is not met, solved again from every branch seed with whole turns of
    axes 1, 4, 6 until one is."""
    model, params = calibration.model, calibration.parameters
    nominal, nominal_params = nominal_counterpart(model, params)
    robot = model.robot
    limits = robot.limits
    n = len(rows)
    flange_goal = goal @ np.linalg.inv(tool)
    seed = q_nom.copy()
    pose_rows = np.flatnonzero(~joints)
    eye = np.eye(4)
    seed[pose_rows] = home_readings(nominal, nominal_params, flange_goal[pose_rows], eye)
    # a pose row after an axis target starts at that target (the arm is there)
    last = np.maximum.accumulate(np.where(joints, np.arange(n), -1))
    after = np.flatnonzero(~joints & (last >= 0))
    seed[after] = q_nom[last[after]]
    flange_goal[joints] = nominal.flange2base(nominal_params, Poses.from_readings(q_nom[joints]))
    start = Poses(seed, np.ones_like(seed), np.zeros(n))
    found = nominal_ik(
        nominal,
        nominal_params,
        start,
        flange_goal,
        eye,
        np.ones(n, dtype=bool),
        program=True,
        pinned=joints,
    )
    q = np.where(joints[:, None], q_nom, found.q)
    ok = found.converged & (within_limits(robot, q) & np.isfinite(q).all(axis=1))
    ok |= joints
    wanted = [program.targets[k].configuration for k in rows]
    if language.configuration is None:
        return q, ok, ok.copy()
    # beyond the arm's longest reach (|a| + |d| of every link from the base): no seed helps
    reach = float(np.sum(np.abs(robot.a)) + np.sum(np.abs(robot.d)))
    far = np.linalg.norm(flange_goal[:, :3, 3], axis=1) > reach
    ok &= ~(far & ~joints)
    reachable = ok.copy()
    need = [j for j in pose_rows.tolist() if wanted[j] is not None and not far[j]]
    if not need:
        return q, ok, reachable
    met = np.ones(n, dtype=bool)
    met[need] = False
    _meet(language, robot, q, ok, met, wanted, need)
    for branch in BRANCHES:
        left = np.array([j for j in need if not met[j]], dtype=int)
        if not left.size:
            break
        start_q = branch_seed(seed[left], limits, *branch)
        again = solve_ik(
            nominal,
            nominal_params,
            Poses.from_readings(start_q),
            flange_goal[left],
            eye,
            max_iterations=NOMINAL_ITERATIONS,
        )
        trial = q.copy()
        trial[left] = again.q
        trial_ok = ok.copy()
        trial_ok[left] = again.converged
        reachable[left] |= again.converged & within_limits(robot, again.q)
        before = met.copy()
        _meet(language, robot, trial, trial_ok, met, wanted, [int(j) for j in left])
        newly = left[met[left] & ~before[left]]
        q[newly], ok[newly] = trial[newly], True
    bad = np.array([j for j in need if not met[j]], dtype=int)
    ok[bad] = False
    return q, ok, reachable


def _meet(
    language: Language,
    robot: RobotDescription,
    q: Array,
    ok: NDArray[np.bool_],
    met: NDArray[np.bool_],
    wanted: list[tuple[int, ...] | None],
    rows: list[int],
) -> None:
    """For `rows` solved (`ok`), the variant of q with whole turns on axes 1, 4, 6 (within
    the limits) whose configuration is the wanted one: q updated and `met` set there."""
    assert language.configuration is not None
    limits = robot.limits
    rows = [j for j in rows if ok[j] and not met[j]]
    if not rows:
        return
    shifts = np.array([(a, b, c) for a in TURNS for b in TURNS for c in TURNS]) * 2 * np.pi
    shifts = shifts[np.argsort(np.abs(shifts).sum(axis=1), kind="stable")]  # no turn first
    plain = _configurations(language, robot, q[rows])  # most rows meet it as solved
    for i, j in enumerate(list(rows)):
        wanted_j = wanted[j]
        if wanted_j is not None and any(matches(c, wanted_j) for c in plain[i]):
            met[j] = bool(np.all((q[j] >= limits[:, 0]) & (q[j] <= limits[:, 1])))
    rows = [j for j in rows if not met[j]]
    if not rows:
        return
    trial = np.repeat(q[rows][:, None, :], len(shifts), axis=1)  # (m, 27, J)
    trial[:, :, [0, 3, 5]] += shifts[None]
    flat = trial.reshape(-1, q.shape[1])
    inside = np.all((flat >= limits[:, 0]) & (flat <= limits[:, 1]), axis=1)
    found = _configurations(language, robot, flat)
    for i, j in enumerate(rows):
        wanted_j = wanted[j]
        assert wanted_j is not None
        for variant in range(len(shifts)):
            at = i * len(shifts) + variant
            if inside[at] and any(matches(c, wanted_j) for c in found[at]):
                q[j], met[j] = trial[i, variant], True
                break


__all__ = ["ProgramCompensation", "TargetRow", "compensate_program"]
