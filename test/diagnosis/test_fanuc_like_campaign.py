"""The FANUC-like campaign (`robot_calib.sim.scenarios.fanuc_like`), from the
raw controller readings with no preprocessing: J3 coupled to J2, three SMRs 0.34 m out
(one on the joint-6 axis), sweeps of 6 poses with 144 deg steps over +-360 deg on joints 4
and 6. Known answers: the simulated truth and its noise."""

from __future__ import annotations

import numpy as np

from robot_calib.accuracy import accuracy
from robot_calib.identify.calibrate import calibrate
from robot_calib.model import absorb_base_offsets
from robot_calib.sim.scenarios import fanuc_like, noise_rms_mm, wrist_288_subset

SCENARIO = fanuc_like(seed=0)
WORLD = SCENARIO.world
ROBOT = WORLD.model.robot


def test_cpa_and_geometric_reach_the_noise_with_all_three_targets_in_one_calibration() -> None:
    recording, holdout = SCENARIO.calibration, SCENARIO.holdout
    assert recording.target_names == ("", "smr_b", "smr_axis")
    assert sorted({s.joint for s in recording.sweeps}) == [1, 2, 3, 4, 5, 6]
    # The coupled J2 sweep moves readings 2 and 3 together and is still a sweep of joint 2.
    j2 = recording.sweeps_of(2)[0]
    assert np.ptp(recording.poses.q[j2.index, 2]) > 0.5
    floor = noise_rms_mm(WORLD, recording)
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    for model, bound in (("cpa", 1.4), ("geometric", 1.1)):
        messages: list[str] = []
        cal = calibrate(recording, ROBOT, model, log=messages.append)
        assert cal.accuracy.absolute_rms_mm < bound * floor, (model, cal.accuracy, floor)
        for p in ("a2", "a3", "d4", "alpha3", "alpha5"):
            assert abs(cal.parameters[p] - truth[p]) < 6e-5, (model, p)  # 60 um / 60 urad
        # The SMR on the J6 axis is named, and CPA leaned on the other two.
        near = [m for m in messages if "too close" in m]
        assert len(near) == 1 and "/laser_tracker/smr_axis/point" in near[0]
        assert "leans on the joint's 2 other circle(s)" in near[0]
        held = accuracy(holdout.points, cal.model.target_points(cal.parameters, holdout.poses))
        # 36 poses identify ~30 parameters: held-out error is a few times the noise, not mm.
        assert held.absolute_rms_mm < 4.0 * noise_rms_mm(WORLD, holdout), (model, held)


def test_every_other_pose_of_the_wrist_sweeps_288_deg_steps_flips_no_axis() -> None:
    """Poses 1, 3, 5, 6 of the J4 and J6 sweeps (-360, -72, 216, 360 deg: steps of 288 deg,
    two of them the same place): the axes still come from the readings, no circle point
    is taken for a blunder, and the geometry stays within tens of um."""
    subset = wrist_288_subset(SCENARIO.calibration)
    messages: list[str] = []
    cal = calibrate(subset, ROBOT, "cpa", log=messages.append)
    assert not [m for m in messages if "blunders" in m]
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    for p in ("a3", "d4", "alpha4", "alpha5"):
        assert abs(cal.parameters[p] - truth[p]) < 1e-4, p
    assert cal.accuracy.absolute_rms_mm < 2.0 * noise_rms_mm(WORLD, subset)
