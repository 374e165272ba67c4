"""A plan's poses -> the moves that reach them safely, every pose at once.

Safety rules (msgs_doc/capture.md):
- a pose outside the robot's joint limits is refused (named, never sent);
- no joint turns by more than `max_step_rad` in one move: a longer move is split into
  equal waypoints (the controller interpolates between them in joint space);
- with an approach side per joint (+1: arrive turning positive, -1: negative, 0: any),
  each pose is reached from `overshoot_rad` before it on that side, so that every
  measurement sees the same backlash side (the approach point must be inside the limits,
  else the pose is refused).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.errors import InputError
from robot_calib.kinematics.description import joint_violations
from robot_calib.kinematics.frames import Array


@dataclass(frozen=True)
class MoveRules:
    """max_step_rad : the largest joint step of one move [rad]; approach : (J,) side per
    joint (+1, -1, 0); overshoot_rad : how far before the pose the approach starts [rad]."""

    max_step_rad: float
    approach: Array
    overshoot_rad: float

    def __post_init__(self) -> None:
        if not self.max_step_rad > 0:
            raise InputError(f"max step per move must be > 0 rad, not {self.max_step_rad}")
        if not self.overshoot_rad >= 0:
            raise InputError(f"approach overshoot must be >= 0 rad, not {self.overshoot_rad}")
        if not np.all(np.isin(self.approach, (-1, 0, 1))):
            raise InputError(f"approach sides must be +1, -1 or 0, not {self.approach}")


@dataclass(frozen=True)
class Move:
    """pose : the plan's index of the pose; waypoints : (m, J) readings [rad] sent as one
    trajectory, the last the pose itself."""

    pose: int
    waypoints: Array


@dataclass(frozen=True)
class Refusal:
    """A pose not visited: its plan index and why (one line)."""

    pose: int
    reason: str


def parse_approach(text: str, n_joints: int) -> Array:
    """'+' / '-' / '0' for every joint, or one sign per joint ('+,+,0,-,+,+') -> (J,)."""
    signs = {"+": 1, "+1": 1, "1": 1, "-": -1, "-1": -1, "0": 0, "": 0, "none": 0}
    items = [t.strip() for t in text.split(",")]
    if len(items) == 1:
        items *= n_joints
    if len(items) != n_joints or any(t not in signs for t in items):
        raise InputError(
            f"approach {text!r}: give one of +, -, 0 for all joints or one per joint "
            f"({n_joints}, comma-separated)"
        )
    return np.array([signs[t] for t in items], dtype=float)


def limit_violations(q: Array, limits: Array, names: tuple[str, ...]) -> list[str | None]:
    """Per pose of q (n, J) [rad]: None inside `limits` (J, 2) [rad], else the first joint
    outside (or in degrees), as text: `kinematics.description.joint_violations`."""
    return joint_violations(q, limits, names)  # the one check (RobotDescription.check_joints)


def _split(start: Array, end: Array, max_step: float) -> Array:
    """Waypoints (m, J) from start (exclusive) to end (inclusive), each step <= max_step."""
    pieces = max(1, int(np.ceil(np.max(np.abs(end - start)) / max_step - 1e-12)))
    fractions = np.arange(1, pieces + 1) / pieces
    return start + fractions[:, None] * (end - start)


def plan_moves(
    q: Array, start: Array, limits: Array, names: tuple[str, ...], rules: MoveRules
) -> tuple[list[Move], list[Refusal]]:
    """The moves visiting the poses q (n, J) [rad] in order from readings `start` (J,),
    and the poses refused (module docstring). Each move starts where the last one ended."""
    moves: list[Move] = []
    refused: list[Refusal] = []
    outside = limit_violations(q, limits, names)
    approach_points = q - rules.approach * rules.overshoot_rad
    outside_approach = limit_violations(approach_points, limits, names)
    here = np.asarray(start, dtype=float)
    for k, pose in enumerate(q):
        if outside[k] is not None:
            refused.append(Refusal(k, f"pose {k}: {outside[k]}"))
            continue
        if outside_approach[k] is not None:
            refused.append(Refusal(k, f"pose {k}: its approach point has {outside_approach[k]}"))
            continue
        waypoints = _split(here, approach_points[k], rules.max_step_rad)
        if rules.overshoot_rad > 0 and np.any(rules.approach != 0):
            waypoints = np.vstack([waypoints, pose[None, :]])
        moves.append(Move(k, waypoints))
        here = pose
    return moves, refused


def describe(moves: list[Move], names: tuple[str, ...]) -> list[str]:
    """One line per move for a dry run: the pose, its waypoints' count and largest joint
    step [deg], and the pose [deg]."""
    lines = []
    here: Array | None = None
    for move in moves:
        path = move.waypoints if here is None else np.vstack([here[None, :], move.waypoints])
        step = np.degrees(np.max(np.abs(np.diff(path, axis=0)))) if len(path) > 1 else 0.0
        pose = ", ".join(f"{n}={v:.3f}" for n, v in zip(names, np.degrees(move.waypoints[-1])))
        lines.append(
            f"pose {move.pose}: {len(move.waypoints)} waypoint(s), largest step "
            f"{step:.2f} deg -> {pose} deg"
        )
        here = move.waypoints[-1]
    return lines


MIN_SEGMENT_S = 0.1  # no waypoint sooner than this after the one before [s]
PEAK_OVER_MEAN = 1.5  # a smooth segment's peak speed over its mean


def waypoint_times(
    start: Array, waypoints: Array, speed_rad_s: float, least_s: float = 0.0
) -> Array:
    """time_from_start (m,) [s] of `waypoints` (m, J) [rad] from readings `start` (J,):
    strictly increasing, each segment long enough that no joint's mean speed exceeds
    speed_rad_s / PEAK_OVER_MEAN (so its peak stays near speed_rad_s), at least
    MIN_SEGMENT_S, stretched to at least `least_s` in all. A joint_trajectory_controller
    takes the times as given and rejects times that do not increase; it has no speed limit
    of its own, so these times are the move's speed."""
    path = np.vstack([np.asarray(start, dtype=float)[None, :], waypoints])
    step = np.max(np.abs(np.diff(path, axis=0)), axis=1)  # (m,) [rad]
    segment = np.maximum(PEAK_OVER_MEAN * step / speed_rad_s, MIN_SEGMENT_S)
    times = np.cumsum(segment)
    if least_s > times[-1]:
        times *= least_s / times[-1]
    return times
