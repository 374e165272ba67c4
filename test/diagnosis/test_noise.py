"""The noise floor from repeat poses anywhere in a recording: a UR10-style
series of random poses that revisits poses 7-8 rows later measures the simulated noise."""

from __future__ import annotations

import numpy as np
import pytest

from robot_calib.diagnosis.noise import estimate_noise, repeat_pairs
from robot_calib.measurements import recording_from_arrays
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import random_plan
from robot_calib.sim.world import load_world

WORLD = load_world()


def test_repeats_a_few_rows_apart_measure_the_noise() -> None:
    rng = np.random.default_rng(0)
    q = random_plan(WORLD.model.robot, 600, rng).q
    revisit = np.arange(10, 590, 10)
    q[revisit + 6] = q[revisit - 1]  # each tenth pose measured again 7 rows later,
    q[revisit + 7] = q[revisit]  # approached from the same pose (same directions)
    time = np.arange(len(q)) * 4.0  # 4 s per pose: 28 s apart
    points = physical_points(WORLD, Poses.from_readings(q, time=time), rng)
    recording = recording_from_arrays(q, points, time)
    pairs = repeat_pairs(recording)
    found = set(map(tuple, pairs.tolist()))
    assert {(int(i), int(i) + 7) for i in revisit} <= found  # every revisit is found
    assert all(np.array_equal(q[a], q[b]) for a, b in found)  # and only true repeats
    noise = estimate_noise(recording)
    assert noise.source.startswith("repeat poses")
    # The world's noise per axis: tracker 3.75 um and target 3 um, plus joint repeatability.
    assert 4e-6 < noise.sigma_m < 8e-6


def test_repeats_far_apart_in_time_are_not_used() -> None:
    """Revisits 10 minutes later may include drift: not taken as noise."""
    q = random_plan(WORLD.model.robot, 40, np.random.default_rng(1)).q
    q[20] = q[0]
    time = np.arange(len(q)) * 30.0
    recording = recording_from_arrays(q, np.zeros((len(q), 3)), time)
    assert repeat_pairs(recording).tolist() == []
    assert pytest.approx(600.0) == time[20] - time[0]
