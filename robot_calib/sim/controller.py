"""A joint trajectory follower: what a joint_trajectory_controller does with a command.

A command is waypoints (m, J) [rad] with times from its start [s] (trajectory_msgs'
`time_from_start`). The simulated robot starts from where it is when the command arrives,
reaches each waypoint at its time, never faster than `max_speed_rad_s` per joint (a
waypoint without a usable time, or one too early for the speed limit, is reached as soon
as the speed limit allows), and holds the last waypoint. Between waypoints every joint
follows the same smooth step s(u) = 3u^2 - 2u^3 (zero velocity at each waypoint; peak
speed 1.5 x the mean), so the approach direction of each move is that of its last segment,
as on a real robot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.kinematics.frames import Array

PEAK_OVER_MEAN = 1.5  # the smooth step's peak speed / its mean speed


@dataclass(frozen=True)
class Motion:
    """start_s : when the motion starts [s] (the node's clock); times_s : (m + 1,) knot
    times since start_s, the first 0 [s]; q : (m + 1, J) knot readings [rad], the first
    where the robot was."""

    start_s: float
    times_s: Array
    q: Array

    @property
    def end_s(self) -> float:
        """When the last waypoint is reached [s]."""
        return self.start_s + float(self.times_s[-1])


def hold(q: Array, now_s: float) -> Motion:
    """Standing still at readings q (J,) [rad]."""
    return Motion(now_s, np.zeros(1), np.asarray(q, dtype=float)[None, :])


def follow(
    now_s: float, q_now: Array, waypoints: Array, times_s: Array, max_speed_rad_s: Array
) -> Motion:
    """The motion from q_now (J,) through `waypoints` (m, J) [rad] at `times_s` (m,) since
    now [s] (0 or decreasing = as soon as the speed limit allows), each segment no faster
    than `max_speed_rad_s` (J,) [rad/s] at its peak."""
    knots = np.vstack([np.asarray(q_now, dtype=float)[None, :], waypoints])
    step = np.abs(np.diff(knots, axis=0))  # (m, J)
    shortest = PEAK_OVER_MEAN * np.max(step / max_speed_rad_s, axis=1)  # (m,) [s]
    times = np.zeros(len(knots))
    for k, (asked, least) in enumerate(zip(times_s, shortest)):
        times[k + 1] = max(float(asked), times[k] + least)
    return Motion(now_s, times, knots)


def state_at(motion: Motion, t_s: float) -> tuple[Array, Array]:
    """Readings (J,) [rad] and velocities (J,) [rad/s] of `motion` at time t_s [s]."""
    q, velocity = states_at(motion, np.array([t_s], dtype=float))
    return q[0], velocity[0]


def states_at(motion: Motion, t_s: Array) -> tuple[Array, Array]:
    """Readings (n, J) [rad] and velocities (n, J) [rad/s] of `motion` at times t_s (n,)
    [s] (the node's clock): before the start the first knot, after the end the last, both
    at rest."""
    since = np.asarray(t_s, dtype=float) - motion.start_s
    times = motion.times_s
    k = np.clip(np.searchsorted(times, since, side="right") - 1, 0, max(len(times) - 2, 0))
    if len(times) == 1:
        n = len(since)
        return np.repeat(motion.q[:1], n, axis=0), np.zeros((n, motion.q.shape[1]))
    span = (times[k + 1] - times[k])[:, None]
    moving = span > 0
    u = np.where(moving, (since[:, None] - times[k][:, None]) / np.where(moving, span, 1.0), 1.0)
    u = np.clip(u, 0.0, 1.0)
    delta = motion.q[k + 1] - motion.q[k]
    q = motion.q[k] + delta * (3 * u**2 - 2 * u**3)
    velocity = np.where(moving, delta * (6 * u - 6 * u**2) / np.where(moving, span, 1.0), 0.0)
    return q, velocity
