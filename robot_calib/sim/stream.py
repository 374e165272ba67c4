"""A simulated stream (continuous tracking, msgs_doc/stream.md): the world's true robot moves
smoothly through waypoints (the controller's motion, `sim/controller.py`) while the
controller publishes its joint states at `joint_rate_hz` and the tracker its points at
`point_rate_hz`, the two clocks offset by a known latency: the controller stamps the
readings of real time tau with tau + latency_s, the tracker its measurement of tau with tau.
Points carry the world's noise (repeatability per point, tracker and target noise) and its
dropouts; each point's approach directions are the signs of the joint velocities.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.errors import InputError
from robot_calib.kinematics.frames import Array
from robot_calib.measurements.stream import JointStream, velocity_directions
from robot_calib.poses import Poses
from robot_calib.sim.controller import Motion, follow, states_at
from robot_calib.sim.measure import physical_points
from robot_calib.sim.world import World


@dataclass(frozen=True)
class StreamOptions:
    """joint_rate_hz, point_rate_hz : message rates [Hz]; latency_s : how much later the
    controller's stamps are than the tracker's for one instant [s]; speed_fraction : of
    each joint's max speed (world timing) at the peak of each move [1]; start_ns : the
    tracker stamp of the motion's start [ns]."""

    joint_rate_hz: float = 200.0
    point_rate_hz: float = 1000.0
    latency_s: float = 0.002
    speed_fraction: float = 0.3
    start_ns: int = 1_700_000_000_000_000_000


@dataclass(frozen=True)
class SimulatedStream:
    """stream : the messages (JointStream); velocity : (m, J) the joint states' velocity
    field [rad/s]; motion : the true motion (controller time 0 = the tracker's start_ns)."""

    stream: JointStream
    velocity: Array
    motion: Motion


def simulate_stream(
    world: World, waypoints: Array, options: StreamOptions, rng: np.random.Generator
) -> SimulatedStream:
    """The stream of a smooth move through `waypoints` (m, J) readings [rad], the first
    where the robot starts, each reached at rest (the controller's smooth step)."""
    waypoints = np.asarray(waypoints, dtype=float)
    if waypoints.ndim != 2 or len(waypoints) < 2:
        raise InputError(f"a stream needs >= 2 waypoints (m, J), got shape {waypoints.shape}")
    if not (options.joint_rate_hz > 0 and options.point_rate_hz > 0):
        raise InputError("stream rates must be > 0 Hz")
    speed = world.timing.speeds(waypoints.shape[1])
    motion = follow(
        0.0,
        waypoints[0],
        waypoints[1:],
        np.zeros(len(waypoints) - 1),
        speed * options.speed_fraction,
    )
    # real time tau [s] since the start; the joint states sample a grid shifted off the points'
    tau_js = np.arange(0.0, motion.end_s, 1.0 / options.joint_rate_hz) + 0.37e-3
    tau_pt = np.arange(0.0, motion.end_s, 1.0 / options.point_rate_hz)
    q_js, v_js = states_at(motion, tau_js)
    q_pt, v_pt = states_at(motion, tau_pt)
    poses = Poses(q_pt, velocity_directions(v_pt), tau_pt)
    points = physical_points(world, poses, rng)
    kept = rng.random(len(tau_pt)) >= world.tracker.dropout_probability
    start = options.start_ns
    js_ns = start + np.round((tau_js + options.latency_s) * 1e9).astype(np.int64)
    point_ns = start + np.round(tau_pt[kept] * 1e9).astype(np.int64)
    stream = JointStream.from_messages(
        js_ns, q_js, np.sign(v_js), point_ns, points[kept], source="simulated stream"
    )
    return SimulatedStream(stream, v_js, motion)
