"""A campaign with 3 reads of every pose (a tracker export that re-measures each pose):
the reads of one pose share a fold, so the k-fold figure of the chosen model is that of
poses truly held out (the reads in different folds made a learned correction look 5 x
better than on new poses)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from robot_calib.accuracy import accuracy
from robot_calib.diagnose.diagnosis import diagnose
from robot_calib.measurements import Recording
from robot_calib.measurements.split import holdout_mask
from robot_calib.poses import reading_groups
from robot_calib.sim.blind import ur10_out_of_vocabulary

READS = 3
POSE_SIGMA_M = 20e-6  # what a pose's reads share, per axis: the robot's repeatability
READ_SIGMA_M = 2e-6  # what each read adds, per axis: the tracker re-measuring a still SMR


def reread(recording: Recording, reads: int, seed: int) -> Recording:
    """`recording` measured `reads` times at each pose: the same readings, an error shared
    by the reads of a pose (the robot stops a little elsewhere each time it comes) and a
    small one per read."""
    rng = np.random.default_rng(seed)
    shared = recording.points + rng.normal(0.0, POSE_SIGMA_M, recording.points.shape)
    copies = [replace(recording, points=shared
                      + rng.normal(0.0, READ_SIGMA_M, recording.points.shape))
              for _ in range(reads)]  # fmt: skip
    return Recording.concatenate(copies)


def test_the_k_fold_figure_of_re_read_poses_is_that_of_new_poses() -> None:
    scenario = ur10_out_of_vocabulary("link_bending", seed=0, n=1000)
    robot = scenario.world.model.robot
    recording = reread(scenario.calibration, READS, seed=1)
    diagnosis, ladder = diagnose(recording, robot)  # k-fold: no hold-out bag
    assert "fold" in diagnosis.scored_on
    chosen = ladder.rungs[-1]
    held = reread(scenario.holdout, 1, seed=3)  # new poses, measured as the others
    truth = accuracy(held.points, chosen.calibration.predict(held.poses)).absolute_rms_mm
    claimed = chosen.heldout.absolute_rms_mm
    assert 0.8 < claimed / truth < 1.25, (chosen.model, claimed, truth)


def test_split_holds_out_whole_poses() -> None:
    scenario = ur10_out_of_vocabulary("link_bending", seed=0, n=100)
    recording = reread(scenario.calibration, READS, seed=2)
    mask = holdout_mask(recording, 0.3)
    group = reading_groups(recording.poses.q)
    held_groups = set(group[mask].tolist())
    assert held_groups.isdisjoint(group[~mask].tolist())
    assert 0.2 < mask.mean() < 0.4
