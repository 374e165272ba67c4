"""The compensation tests' world: a KR5 with 2 mrad of joint-4 backlash, calibrated once per
process with geometric+backlash:4 on the seed's Test 2 sweeps."""

from __future__ import annotations

import functools

import numpy as np

from robot_calib.effects import parse_effect
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.calibration import Calibration
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.sim.measure import measure_every_target
from robot_calib.sim.plans import paper_test_plan, plan_times
from robot_calib.sim.world import build_world, with_effect

WORLD = with_effect(build_world({"seed": 4}), parse_effect("backlash:4", 6), {"backlash4": 2e-3})
ROBOT = WORLD.model.robot


@functools.cache
def calibrated() -> tuple[Calibration, Recording]:
    plan = paper_test_plan(2)
    poses, points = measure_every_target(
        WORLD, plan.q, plan_times(plan, WORLD.timing), np.random.default_rng(1)
    )
    recording = recording_from_arrays(poses.q, points, poses.time, robot=ROBOT)
    return calibrate(recording, ROBOT, "geometric+backlash:4"), recording


NOISE_FLOOR_M = 9e-6  # the simulated tracker's noise, rms distance (~9 um)
