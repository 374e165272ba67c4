"""Reads of one pose, simulated with a known answer: the simulated tracker reads every pose
3 times while the robot stands still (one physical pose, the tracker's noise drawn again),
as the Meca500's FARO export does. The reads are one pose to every fold and split, their
scatter is the tracker's own noise, and the k-fold figure matches a true hold-out."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robot_calib.bag.read import read_recording
from robot_calib.diagnosis.noise import REREADS, estimate_noise
from robot_calib.flows.diagnose import diagnose_recordings
from robot_calib.flows.simulate import simulate as simulate_world
from robot_calib.nodes.simulate import simulate_bag
from robot_calib.poses import reading_groups
from robot_calib.sim.world import World, build_world


def _world(seed: int) -> World:
    return build_world(
        {
            "robot": "kr5_sixx_r650",
            "seed": seed,
            "tracker": {"reads_per_pose": 3},
            "effects": [{"name": "backlash", "joints": [4]}],
        },
        "three reads per pose",
    )


def test_three_reads_per_pose_are_one_pose_and_the_trackers_noise(tmp_path: Path) -> None:
    world = _world(3)
    bag = tmp_path / "reads.mcap"
    sim = simulate_world(bag, "random", world, n_random=120, record=simulate_bag)
    assert sim.counts["/laser_tracker/point"] == 3 * sim.counts["/joint_states"] == 360
    recording = read_recording([bag], world.model.robot)
    assert not recording.warnings  # no stream, no copies: re-reads
    assert len(np.unique(reading_groups(recording.poses.q))) == 120
    noise = estimate_noise(recording)
    assert noise.source == REREADS  # the tracker alone: the robot did not move between reads
    # the tracker's own noise: the SMR's centring error stays with it while it stands still
    assert noise.sigma_m == pytest.approx(world.noise.tracker_sigma_m, rel=0.15)
    # k-fold over poses (reads together) against a true hold-out of 120 new poses
    holdout_bag = tmp_path / "holdout.mcap"
    simulate_world(holdout_bag, "random", _world(4), seed=44, n_random=120, record=simulate_bag)
    holdout = read_recording([holdout_bag], world.model.robot)
    kfold, _ = diagnose_recordings(recording, world.model.robot)
    held, _ = diagnose_recordings(recording, world.model.robot, holdout)
    assert kfold.reads_line().startswith("360 measurements at 120 poses (3.0 per pose")
    first = {r.model: r for r in kfold.ladder}
    second = {r.model: r for r in held.ladder}
    for model in set(first) & set(second):
        a, b = first[model].holdout_abs_rms_mm, second[model].holdout_abs_rms_mm
        assert a == pytest.approx(b, rel=0.2), (model, a, b)


def test_reads_per_pose_are_checked(tmp_path: Path) -> None:
    from robot_calib.errors import InputError

    with pytest.raises(InputError, match="reads_per_pose: a whole number 1-20"):
        build_world({"tracker": {"reads_per_pose": 0}}, "bad.yaml")
    with pytest.raises(InputError, match="with six_dof probes: not simulated"):
        build_world({"tracker": {"reads_per_pose": 2}, "six_dof": {"first": [0, 0, 0]}}, "p")
