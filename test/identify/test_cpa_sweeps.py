"""Circle sweeps as real robots record them: the axis direction comes from the
readings, never from the order of the points, so steps above 180 deg work (six poses at
144 deg over +-360 deg on joints 4 and 6, and four of them, with 288 deg steps, which the
point order turned backwards before); a target too close to an axis is warned about."""

from __future__ import annotations

import numpy as np
import pytest

from robot_calib.identify.calibrate import calibrate
from robot_calib.measurements import find_sweeps, recording_from_arrays
from robot_calib.model import absorb_base_offsets
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import paper_test_plan
from robot_calib.sim.world import build_world, load_world

WORLD = load_world()
ROBOT = WORLD.model.robot


def big_step_plan(keep: list[int] | None) -> np.ndarray:
    """The seed's Test 2 sweeps, with joints 4 and 6 swept in 144 deg steps over +-360 deg
    (6 poses; `keep`: only those of them)."""
    plan = paper_test_plan(2)
    blocks = []
    for sweep in find_sweeps(plan.q):
        block = plan.q[sweep.index]
        if sweep.joint in (4, 6):
            angles = np.radians(np.arange(-360, 361, 144))[keep if keep else slice(None)]
            block = np.tile(block[0], (len(angles), 1))
            block[:, sweep.joint - 1] = angles
        blocks.append(block)
    return np.vstack(blocks)


@pytest.mark.parametrize("keep", [None, [0, 2, 4, 5]], ids=["144 deg steps", "288 deg steps"])
def test_steps_above_180_deg_give_the_right_axes(keep: list[int] | None) -> None:
    q = big_step_plan(keep)
    points = physical_points(WORLD, Poses.from_readings(q), np.random.default_rng(0))
    recording = recording_from_arrays(q, points)
    n_big = len(keep) if keep else 6
    assert [(s.joint, s.n_poses) for s in recording.sweeps][3::2] == [(4, n_big), (6, n_big)]
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    for model in ("cpa", "geometric"):
        cal = calibrate(recording, ROBOT, model)
        assert cal.accuracy.absolute_rms_mm < 0.015, model  # the noise, not a flipped axis
        for name in ("alpha3", "alpha4", "alpha5", "d4", "a3"):
            assert cal.parameters[name] == pytest.approx(truth[name], abs=5e-4), (model, name)


def test_a_target_near_an_axis_is_warned_about() -> None:
    """A target 0.5 mm off the joint-6 axis: its circle cannot fix that axis's direction."""
    world = build_world({"target_in_flange_m": [0.0005, 0.0, 0.1]}, "target on the J6 axis")
    q = paper_test_plan(2).q
    points = physical_points(world, Poses.from_readings(q), np.random.default_rng(1))
    cal = calibrate(recording_from_arrays(q, points), ROBOT, "cpa")
    assert any("sweep of joint 6" in w and "too close" in w for w in cal.cpa.warnings)
    assert not any(
        "too close" in w
        for w in calibrate(
            recording_from_arrays(
                q, physical_points(WORLD, Poses.from_readings(q), np.random.default_rng(1))
            ),
            ROBOT,
            "cpa",
        ).cpa.warnings
    )
