"""A fit that converges can still be wrong: plausibility warnings against known answers
(issue 12). Clean data of the right robot warn nothing; a wrong robot, swapped joints,
readings in degrees, a stuck joint and a residual far above the noise each warn, naming
what is wrong."""

from __future__ import annotations

import numpy as np
import pytest

from robot_calib.effects import make_effect
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.params_file import summary
from robot_calib.kinematics.description import load_robot
from robot_calib.measurements import recording_from_arrays
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import paper_test_plan, random_plan
from robot_calib.sim.world import load_world, with_effect

WORLD = load_world()
ROBOT = WORLD.model.robot
Q = paper_test_plan(2).q
POINTS = physical_points(WORLD, Poses.from_readings(Q), np.random.default_rng(0))


def warnings_of(q: np.ndarray, robot_name: str = "kr5_sixx_r650", points=POINTS) -> str:  # noqa: ANN001
    recording = recording_from_arrays(q, points)
    cal = calibrate(recording, load_robot(robot_name))
    text = "\n".join(cal.warnings)
    assert all(w in summary(cal, recording) for w in cal.warnings)  # stdout shows them
    assert all(w in cal.to_dict(recording)["warnings"] for w in cal.warnings)  # PARAMS.json
    return text


def test_clean_data_of_the_right_robot_warn_nothing() -> None:
    assert warnings_of(Q) == ""
    rng = np.random.default_rng(1)
    q = random_plan(ROBOT, 300, rng).q
    assert warnings_of(q, points=physical_points(WORLD, Poses.from_readings(q), rng)) == ""


@pytest.mark.parametrize(
    ("case", "expected"),
    [
        ("ur10", "parameters far from nominal (ur10): a1 +7"),
        ("swapped 2/3", "a3 -2"),
        ("swapped 2/3", "joint 2 (joint_a2): 536 of 580 readings outside its limits"),
        ("degrees", "readings reach 177.0 rad"),
        ("stuck 4", "joint 4 (joint_a4) never moves while others do"),
        ("20 mrad backlash on joint 2", "x the noise"),
    ],
)
def test_implausible_results_warn(case: str, expected: str) -> None:
    q, robot, points = Q.copy(), "kr5_sixx_r650", POINTS
    if case == "ur10":
        robot = "ur10"
    elif case == "swapped 2/3":
        q[:, [1, 2]] = q[:, [2, 1]]
    elif case == "degrees":
        q = np.degrees(q)
    elif case == "stuck 4":
        q[:, 3] = 0.3
    elif case == "20 mrad backlash on joint 2":
        world = with_effect(WORLD, make_effect("backlash", [2]), {"backlash2": 0.02})
        points = physical_points(world, Poses.from_readings(q), np.random.default_rng(3))
    assert expected in warnings_of(q, robot, points)


def test_readings_within_a_joints_own_limits_beyond_2pi_are_not_degrees() -> None:
    """The GP25's T axis turns +-455 deg: readings within its limits are rad, not degrees;
    beyond both them and 2 pi they still look like degrees."""
    from robot_calib.identify.plausibility import recording_warnings

    robot = load_robot("gp25")
    q = np.tile(np.linspace(0.1, 0.3, 3)[:, None], (1, 6))
    q[:, 5] = np.radians([-450.0, 0.0, 450.0])
    recording = recording_from_arrays(q, np.zeros((3, 3)))
    assert recording_warnings(recording, robot) == []
    q[2, 5] = 30.0
    warnings = recording_warnings(recording_from_arrays(q, np.zeros((3, 3))), robot)
    assert any("joint 6 (joint_6_t) readings reach 30.0 rad" in w for w in warnings), warnings
