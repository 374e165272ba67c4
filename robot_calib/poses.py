"""Measurement poses: joint readings with the approach direction and time of each pose.

The direction rule is the contract's (msgs_doc/specification.md section 1, "Measurements"): the
direction from which joint j approached a pose is the sign of its change since the
previous pose; unchanged (within `joint_change_tolerance`) keeps the previous direction;
at the first pose every direction is +1.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robot_calib.errors import InputError
from robot_calib.kinematics.frames import Array, IntArray

JOINT_CHANGE_TOLERANCE = 1e-4  # rad, contract default
PRIMARY_TARGET = ""  # name of the contract's single target (/laser_tracker/point)
TARGET_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")  # a further target's name: a topic token
#: a reading in rad beyond this factor x its joint's largest |limit| (and beyond 2 pi) is
#: no reading of that joint: it looks like degrees
REACH_FACTOR = 1.5


def beyond_reach(q: Array, limits: Array | None = None) -> tuple[NDArray[np.bool_], Array]:
    """Which readings look like degrees: beyond any reading in rad of their joint.

    q : shape (n, J), joint readings read as rad
    limits : shape (J, 2), the robot's joint limits [rad] (None, or another J: 2 pi only)

    Returns
    -------
    beyond : shape (n, J) bool, |q| beyond the reach of its joint
    reach : shape (J,) [rad], 2 pi, or REACH_FACTOR x the joint's largest |limit| where
        that is larger (a Yaskawa GP25's T axis turns +-455 deg)
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    reach = np.full(q.shape[1], 2 * np.pi)
    if limits is not None and len(limits) == q.shape[1]:
        reach = np.maximum(reach, REACH_FACTOR * np.abs(limits).max(axis=1))
    return np.abs(q) > reach, reach


def next_direction(
    previous_direction: Array,
    previous_q: Array,
    q: Array,
    tolerance: float = JOINT_CHANGE_TOLERANCE,
) -> Array:
    """Directions (..., J) at readings q given those of the previous pose: the sign of the
    change, or the previous direction where the joint held still (within `tolerance`)."""
    step = q - previous_q
    return np.where(np.abs(step) > tolerance, np.sign(step), previous_direction)


def approach_directions(
    q: Array,
    tolerance: float = JOINT_CHANGE_TOLERANCE,
    start: tuple[Array, Array] | None = None,
) -> Array:
    """Approach direction of every joint at every pose.

    q : shape (n_poses, n_joints), readings in visiting order [rad].
    start : the robot's readings (J,) [rad] and directions (J,) before the first pose, when
        known (a trajectory sent to a robot that stands somewhere): the first pose's
        directions then follow from them; None: +1 at the first pose (the contract's rule).
    Returns shape (n_poses, n_joints), values +1.0 / -1.0.
    """
    q = np.asarray(q, dtype=float)
    direction = np.ones(q.shape)
    if start is not None and len(q):
        direction[0] = next_direction(np.asarray(start[1], float), start[0], q[0], tolerance)
    for k in range(1, q.shape[0]):
        direction[k] = next_direction(direction[k - 1], q[k - 1], q[k], tolerance)
    return direction


@dataclass
class DirectionTracker:
    """Each joint's approach direction from a stream of joint states: the sign of its last
    motion of more than `tolerance_rad` since the reading where the direction last changed
    or was confirmed (an anchor per joint, so that a slow move whose samples each change by
    less than the tolerance still counts; encoder jitter below it does not), or the sign of
    a reported velocity where the message has one. Starts at +1 (the contract's first
    direction).

    direction : (J,) +1/-1; anchor : (J,) [rad], None before the first reading."""

    tolerance_rad: float = JOINT_CHANGE_TOLERANCE
    direction: Array | None = None
    anchor: Array | None = None

    def add(self, q: Array, signs: Array | None = None) -> None:
        """One joint reading q (J,) [rad], with its velocities' signs (J,) (0: unknown)."""
        q = np.asarray(q, dtype=float)
        if self.anchor is None or self.direction is None:
            self.anchor, self.direction = q.copy(), np.ones_like(q)
        change = q - self.anchor
        moved = np.abs(change) > self.tolerance_rad
        self.direction[moved] = np.sign(change[moved])
        self.anchor[moved] = q[moved]
        if signs is not None:
            told = np.asarray(signs) != 0
            self.direction[told] = np.sign(np.asarray(signs)[told])
            self.anchor[told] = q[told]


@dataclass(frozen=True)
class Poses:
    """A batch of measurement poses.

    q : shape (n, J), joint readings [rad]
    direction : shape (n, J), approach direction +1/-1 of every joint
    time : shape (n,), seconds since the first measurement of the recording [s]
    target : shape (n,), which target (SMR) on the flange each measurement is of: an index
      into the model's and recording's target names (None: all the first target, the
      contract's single `/laser_tracker/point`; msgs_doc/targets.md)
    rotation : shape (n, 3, 3), what a 6-DoF probe measured besides its point: the probe
      frame's orientation in the tracker frame (columns: its x, y, z axes), NaN where only
      the point was measured (None: no orientation at all; msgs_doc/six_dof.md)
    sigma : shape (n, 2), the standard deviations the tracker stated for each measurement:
      position [m] (per coordinate) and orientation [rad] (per axis), NaN where none was
      stated (None: none at all); they weight the residuals (`identify.weights`)
    temperature : shape (n,), the robot's temperature at each measurement [deg C] from the
      recording's side topic (msgs_doc/temperature.md; None: none recorded), for effects
      driven by it (`thermal_temperature`)
    """

    q: Array
    direction: Array
    time: Array
    target: IntArray | None = None
    rotation: Array | None = None
    sigma: Array | None = None
    temperature: Array | None = None

    @property
    def target_index(self) -> IntArray:
        """(n,) target of each measurement (zeros when `target` is None)."""
        if self.target is None:
            return np.zeros(len(self), dtype=np.int64)
        return self.target

    @property
    def oriented(self) -> NDArray[np.bool_]:
        """(n,) which measurements carry a measured orientation (6-DoF probe)."""
        if self.rotation is None:
            return np.zeros(len(self), dtype=bool)
        return np.all(np.isfinite(self.rotation), axis=(1, 2))

    def __len__(self) -> int:
        return int(self.q.shape[0])

    @classmethod
    def from_readings(
        cls, q: Array, direction: Array | None = None, time: Array | None = None
    ) -> Poses:
        """Poses from readings; missing directions follow the row order, missing time is 0."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if q.ndim != 2 or not np.all(np.isfinite(q)):
            raise InputError(f"joint readings must be a finite (n, J) array, got shape {q.shape}")
        n = q.shape[0]
        d = approach_directions(q) if direction is None else np.asarray(direction, dtype=float)
        t = np.zeros(n) if time is None else np.asarray(time, dtype=float)
        if d.shape != q.shape or not np.all(np.abs(d) == 1.0):
            raise InputError(f"directions must be +1/-1 of shape {q.shape}, got {d.shape}")
        if t.shape != (n,) or not np.all(np.isfinite(t)):
            raise InputError(f"time must be finite of shape ({n},), got {t.shape}")
        return cls(q, d, t)

    @classmethod
    def concatenate(cls, parts: list[Poses], with_target: bool = True) -> Poses:
        """The poses of `parts` one after the other; optional per-measurement fields are
        kept when any part has them (NaN where a part has none), `target` only with
        `with_target`."""

        def joined(field: str, shape: tuple[int, ...]) -> Array | None:
            values = [getattr(p, field) for p in parts]
            if all(v is None for v in values):
                return None
            return np.concatenate(
                [
                    np.full((len(p), *shape), np.nan) if v is None else v
                    for p, v in zip(parts, values)
                ]
            )

        return cls(
            np.concatenate([p.q for p in parts]),
            np.concatenate([p.direction for p in parts]),
            np.concatenate([p.time for p in parts]),
            np.concatenate([p.target_index for p in parts]) if with_target else None,
            joined("rotation", (3, 3)),
            joined("sigma", (2,)),
            joined("temperature", ()),
        )

    def subset(self, index: slice | IntArray | NDArray[np.bool_]) -> Poses:
        """The poses selected by an index or boolean mask (directions kept as recorded)."""
        target = None if self.target is None else self.target[index]
        rotation = None if self.rotation is None else self.rotation[index]
        sigma = None if self.sigma is None else self.sigma[index]
        temperature = None if self.temperature is None else self.temperature[index]
        return Poses(
            self.q[index],
            self.direction[index],
            self.time[index],
            target,
            rotation,
            sigma,
            temperature,
        )


#: joint readings closer than this in every joint are one pose [rad] (a re-read of the
#: tracker without moving the robot; a repeat of a commanded pose): far below any planned
#: step, far above an export's rounding
SAME_READINGS_RAD = 1e-6


def reading_groups(q: Array) -> IntArray:
    """(n,) 0-based group of each row of readings q (n, J) [rad]: rows at the same readings
    (within SAME_READINGS_RAD) share a group, numbered in order of first appearance. The
    measurements of one pose (several targets, re-reads, repeats) belong together in any
    split of the data into fitted and held-out parts."""
    if len(q) == 0:
        return np.zeros(0, dtype=np.int64)
    key = np.round(np.asarray(q, dtype=float) / SAME_READINGS_RAD).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(np.argsort(first, kind="stable"), kind="stable")
    return order[inverse.reshape(-1)].astype(np.int64)
