"""The 6-DoF tests' world: a KR5 with a probe at roll/pitch/yaw 20, 35, -30 deg and 50 urad
of orientation noise, measured at random poses."""

from __future__ import annotations

import numpy as np

from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.poses import Poses
from robot_calib.sim.measure import measure_every_target
from robot_calib.sim.plans import plan_times, random_plan
from robot_calib.sim.world import World, build_world

PROBE_RPY_DEG = [20.0, 35.0, -30.0]
ORIENTATION_SIGMA = 50e-6  # rad per axis
WORLD = build_world(
    {
        "seed": 3,
        "six_dof": {"first": PROBE_RPY_DEG},
        "noise": {"orientation_sigma_rad": ORIENTATION_SIGMA},
    }
)
ROBOT = WORLD.model.robot


def measured(world: World = WORLD, n: int = 150, seed: int = 1) -> tuple[Poses, np.ndarray]:
    plan = random_plan(ROBOT, n, np.random.default_rng(seed))
    return measure_every_target(
        world, plan.q, plan_times(plan, world.timing), np.random.default_rng(seed + 1)
    )


def as_recording(poses: Poses, points: np.ndarray, sigma: np.ndarray | None = None) -> Recording:
    return recording_from_arrays(
        poses.q, points, poses.time, robot=ROBOT, rotation=poses.rotation, sigma=sigma
    )
