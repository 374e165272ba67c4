"""Effects outside the vocabulary (a gravity-side backlash, a link twisting out of
the arm plane) on simulated UR10 random-pose campaigns whose truth is known: no physical
rung reaches the noise floor, and the diagnosis names the joint and says the structure is
outside the vocabulary."""

from __future__ import annotations

import numpy as np
import pytest

from robot_calib.diagnosis.diagnosis import diagnose
from robot_calib.sim.blind import ur10_out_of_vocabulary
from robot_calib.sim.scenarios import noise_rms_mm

STATED_SIGMA_M = float(np.hypot(3.75e-6, 3.0e-6))  # the scenario's tracker + target noise
ANSWERS = {"gravity_backlash": {2}, "link_bending": {3, 4}}  # diagnosed_joints of each


@pytest.mark.parametrize("kind", sorted(ANSWERS))
def test_physical_diagnosis_names_the_joint_and_the_vocabulary_gap(kind: str) -> None:
    scenario = ur10_out_of_vocabulary(kind, seed=1, n=800)
    robot = scenario.world.model.robot
    diagnosis, ladder = diagnose(
        scenario.calibration, robot, scenario.holdout, tracker_sigma_m=STATED_SIGMA_M
    )
    floor = noise_rms_mm(scenario.world, scenario.holdout)
    physical = [r for r in diagnosis.ladder if not r.learned]
    assert min(r.holdout_abs_rms_mm for r in physical) > 5 * floor  # no rung explains it
    assert "outside the vocabulary" in diagnosis.unexplained.note
    # the joint: where the geometric model's residual lies, and what the rungs took on
    strongest = diagnosis.where.strongest_signature
    assert strongest is not None and strongest.joint in ANSWERS[kind], strongest
    assert diagnosis.dominant_effect is not None
    assert set(diagnosis.dominant_effect.joints) & ANSWERS[kind], diagnosis.verdict
