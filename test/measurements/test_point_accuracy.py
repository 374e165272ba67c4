"""Each point's own stated accuracy, simulated with a known answer: the simulated tracker
states an accuracy per point, drawn from 5-60 um (a Leica export's uncertainty column), and
each point's noise has that 1-sigma. The stated figures reach the bag, are the points' real
scatter, and weighting the fit by them brings it closer to the truth."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from robot_calib.bag.read import read_recording
from robot_calib.flows.simulate import simulate as simulate_world
from robot_calib.identify.calibrate import calibrate
from robot_calib.nodes.simulate import simulate_bag
from robot_calib.sim.world import World, build_world

EXACT = {"tracker_sigma_m": 1e-6, "target_sigma_m": 0.0, "joint_sigma_rad": 0.0}


def _world(point_sigma: list[float], seed: int) -> World:
    """The KR5 with each point's accuracy drawn from `point_sigma` [m]; (0, 0): measured
    to 1 um (a check of the truth)."""
    noise = {"point_sigma_range_m": point_sigma, **({} if point_sigma[1] else EXACT)}
    return build_world(
        {"robot": "kr5_sixx_r650", "seed": seed, "noise": noise}, "stated accuracy per point"
    )


def test_stated_accuracies_are_the_points_noise_and_weigh_the_fit(tmp_path: Path) -> None:
    world = _world([5e-6, 60e-6], 3)
    bag = tmp_path / "leica.mcap"
    sim = simulate_world(bag, "random", world, n_random=300, record=simulate_bag)
    assert sim.counts["/laser_tracker/pose"] == 300  # the accuracies ride on the pose topic
    recording = read_recording([bag], world.model.robot)
    sigma = recording.poses.sigma
    assert sigma is not None and np.isfinite(sigma[:, 0]).all()
    assert 5e-6 <= sigma[:, 0].min() < 8e-6 and 45e-6 < sigma[:, 0].max() <= 60e-6
    robot = world.model.robot
    weighted = calibrate(recording, robot, "geometric", log=None, screen_outliers=False)
    plain_rec = replace(recording, poses=replace(recording.poses, sigma=None))
    plain = calibrate(plain_rec, robot, "geometric", log=None, screen_outliers=False)
    # the stated figures are the scatter: residuals in units of their sigma have rms ~1
    # (the robot's 5 urad repeatability adds a little at the most accurate points)
    scaled = (weighted.predict(recording.poses) - recording.points) / sigma[:, :1]
    assert float(np.sqrt(np.mean(scaled**2))) == pytest.approx(1.0, abs=0.25)
    # scored on 150 other poses measured to 1 um: the weighted fit is closer to the truth
    exact = tmp_path / "exact.mcap"
    simulate_world(
        exact, "random", _world([0.0, 0.0], 3), seed=9, n_random=150, record=simulate_bag
    )
    check = read_recording([exact], robot)
    error = {
        name: float(np.sqrt(np.mean((cal.predict(check.poses) - check.points) ** 2)))
        for name, cal in (("weighted", weighted), ("plain", plain))
    }
    assert error["weighted"] < 0.8 * error["plain"], error


def test_a_point_accuracy_range_below_the_noise_is_refused() -> None:
    from robot_calib.errors import InputError

    with pytest.raises(InputError, match="point_sigma_range_m .* <= low <= high"):
        _world([1e-6, 60e-6], 1)  # below the default tracker and target noise (4.8 um)
    with pytest.raises(InputError, match="expected two finite numbers"):
        build_world({"noise": {"point_sigma_range_m": [-1.0, 2.0]}}, "bad.yaml")
