"""ISO 9283 pose accuracy (AP) and repeatability (RP) before and after calibration, from
repeat poses. Known answers: a simulated KR5 (the seed's Table 3 geometry)
calibrated on Test 2 and scored on the ISO cube's five poses over ten cycles."""

from __future__ import annotations

import numpy as np
import pytest

from robot_calib.diagnosis.diagnosis import diagnose
from robot_calib.diagnosis.iso9283 import iso9283, repeat_groups
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.sim.measure import measure_every_target
from robot_calib.sim.plans import Plan, iso9283_plan, paper_test_plan, plan_times
from robot_calib.sim.world import World, build_world

WORLD = build_world({"seed": 4})
ROBOT = WORLD.model.robot


def recorded(world: World, plan: Plan, seed: int) -> Recording:
    poses, points = measure_every_target(
        world, plan.q, plan_times(plan, world.timing), np.random.default_rng(seed)
    )
    return recording_from_arrays(poses.q, points, poses.time, robot=ROBOT)


def test_ap_falls_with_calibration_and_rp_is_the_repeatability() -> None:
    cal = recorded(WORLD, paper_test_plan(2), 1)
    cube = iso9283_plan(WORLD.model, WORLD.truth, cycles=10)
    held = recorded(WORLD, cube, 2)
    # P5's first visit comes from the other side of a joint (the cycle start): not a repeat
    assert [len(g) for g in repeat_groups(held)] == [10, 10, 10, 10, 9]
    diagnosis, _ = diagnose(cal, ROBOT, held)
    before, after = diagnosis.iso9283
    assert before.model == "nominal" and before.scored_on == "hold-out bags"
    assert len(before.poses) == len(after.poses) == 5
    assert before.ap_max_mm > 0.3  # the uncalibrated geometry: tenths of a millimetre
    assert after.ap_max_mm < 0.02  # calibrated: the barycentre's noise only
    assert before.rp_max_mm == pytest.approx(after.rp_max_mm)  # RP is the robot's own
    # RP of pure noise: mean + 3 sigma of |x - mean|, ~ (1.6 + 3 x 0.7) sigma_3d / sqrt(3)
    assert 0.01 < after.rp_max_mm < 0.05


def test_figures_by_hand_and_no_figures_without_repeats() -> None:
    """Three measurements of one pose: AP and RP as ISO 9283 writes them."""
    q = np.zeros((4, 6))
    q[3] = 0.1  # a fourth pose, visited once: no figures of its own
    points = np.array([[1.0, 0, 0], [1.002, 0, 0], [1.001, 0.001, 0], [2.0, 0, 0]])
    recording = recording_from_arrays(q, points)
    predicted = np.tile([1.0, 0.0, 0.0], (4, 1))
    figures = iso9283(recording, predicted, "m", "x")
    assert figures is not None and len(figures.poses) == 1
    centre = points[:3].mean(axis=0)
    assert figures.ap_max_mm == pytest.approx(np.linalg.norm(centre - [1, 0, 0]) * 1e3)
    distance = np.linalg.norm(points[:3] - centre, axis=1)
    rp = distance.mean() + 3 * distance.std(ddof=1)
    assert figures.rp_max_mm == pytest.approx(rp * 1e3)
    assert (
        iso9283(
            recording.subset(np.array([True, False, False, True])), predicted[[0, 3]], "m", "x"
        )
        is None
    )


def test_orientation_ap_falls_with_calibration_and_rp_is_three_sigma() -> None:
    """A 6-DoF probe with 50 urad of orientation noise per axis: RP_a/b/c is 3 x that noise
    (the robot repeats exactly in simulation), AP_a/b/c falls from the nominal geometry's
    tenths of a milliradian to the barycentre's noise; positions-only data give none."""
    sigma = 50e-6
    probe = {"first": [20.0, 35.0, -30.0]}
    world = build_world({"seed": 4, "six_dof": probe, "noise": {"orientation_sigma_rad": sigma}})

    def oriented(plan: Plan, seed: int) -> Recording:
        poses, points = measure_every_target(
            world, plan.q, plan_times(plan, world.timing), np.random.default_rng(seed)
        )
        return recording_from_arrays(
            poses.q, points, poses.time, robot=ROBOT, rotation=poses.rotation
        )

    cal = oriented(paper_test_plan(2), 1)
    held = oriented(iso9283_plan(world.model, world.truth, cycles=30), 2)
    diagnosis, _ = diagnose(cal, ROBOT, held)
    before, after = diagnosis.iso9283
    assert before.ap_orientation_max_deg is not None and after.rp_orientation_max_deg is not None
    rp = np.array([p.rp_abc_deg for p in after.poses])
    assert np.radians(rp).mean() == pytest.approx(3 * sigma, rel=0.25)
    assert after.ap_orientation_max_deg < np.degrees(3 * sigma / np.sqrt(29)) * 2
    assert before.ap_orientation_max_deg > 5 * after.ap_orientation_max_deg
    # what the reports print: the per-pose a/b/c columns and the line
    assert "orientation AP max" in after.line()
    # distance accuracy between P2 and P4 over the 30 cycles (ISO 9283 7.3): RD is the
    # noise of a difference of two measurements (3 sqrt(2) sigma per component), AD falls
    assert before.distance is not None and after.distance is not None
    assert after.distance.n == 30
    assert after.distance.rd_mm == pytest.approx(before.distance.rd_mm)  # the robot's own
    assert abs(after.distance.ad_mm) < 0.005 < abs(before.distance.ad_mm)
    assert after.distance.rd_abc_deg is not None and after.distance.ad_abc_deg is not None
    rd = np.radians(np.mean(after.distance.rd_abc_deg))
    assert rd == pytest.approx(3 * np.sqrt(2) * sigma, rel=0.3)
    assert "distance AD" in after.line()
    cube = iso9283_plan(WORLD.model, WORLD.truth, cycles=5)
    plain, _ = diagnose(recorded(WORLD, paper_test_plan(2), 1), ROBOT, recorded(WORLD, cube, 3))
    assert all(f.ap_orientation_max_deg is None for f in plain.iso9283)
    assert all(p.ap_abc_deg is None for f in plain.iso9283 for p in f.poses)
