"""UR5 nominal forward kinematics against the ur5_jacobi2025 laser-tracker dataset.

Convention of the dataset (its README): `x_t, y_t, z_t` [mm] are the commanded targets of the
robot's end effector in the robot base frame, and `joint_1..6` [deg] the commanded joint
angles, computed by the Robotics Toolbox for Python with UR's standard DH model. So our
nominal UR5 model must reproduce the targets from the angles, up to the tool point the
controller was told: one constant offset in the flange frame (fitted here by linear least
squares; it comes out at about 31 mm along the flange z axis). The listed angles are rounded,
which leaves about 0.01 mm rms.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robot_calib.kinematics.loader import load_robot
from robot_calib.model import KinematicModel, geometric_parameters
from robot_calib.poses import Poses

DATASET = Path(__file__).resolve().parents[2] / "datasets" / "ur5_jacobi2025"


def load(name: str) -> tuple[np.ndarray, np.ndarray]:
    """Joint angles (n, 6) [rad] and commanded targets (n, 3) [m] of one dataset file."""
    data = np.genfromtxt(DATASET / name, delimiter=",", names=True)
    q = np.radians(np.stack([data[f"joint_{j}"] for j in range(1, 7)], axis=1))
    target = np.stack([data["x_t"], data["y_t"], data["z_t"]], axis=1) / 1000.0
    return q, target


def test_nominal_fk_reproduces_commanded_targets() -> None:
    model = KinematicModel(load_robot("ur5"))
    params = geometric_parameters(model.robot)
    for name in ("3D_UR5_uncalibrated_grid_cleaned.csv", "3D_UR5_uncalibrated_random_cleaned.csv"):
        q, target = load(name)
        flange = model.flange2base(params, Poses.from_readings(q))
        # target = R_flange @ tool + o_flange: linear in the tool offset.
        rot, origin = flange[:, :3, :3], flange[:, :3, 3]
        tool, *_ = np.linalg.lstsq(rot.reshape(-1, 3), (target - origin).reshape(-1), rcond=None)
        assert abs(tool[2] - 0.031) < 0.001 and np.hypot(tool[0], tool[1]) < 0.001
        tool_params = params.with_values(dict(zip(("target_x", "target_y", "target_z"), tool)))
        error_mm = 1e3 * np.linalg.norm(
            model.target_points(tool_params, Poses.from_readings(q)) - target, axis=1
        )
        assert np.sqrt(np.mean(error_mm**2)) < 0.02
        assert error_mm.max() < 0.06


def test_nominal_is_far_from_measured() -> None:
    """Sanity of the convention: measured points differ from targets by millimetres."""
    data = np.genfromtxt(
        DATASET / "3D_UR5_uncalibrated_grid_cleaned.csv", delimiter=",", names=True
    )
    dif = np.stack([data["x_dif"], data["y_dif"], data["z_dif"]], axis=1)
    assert 1.0 < np.linalg.norm(dif, axis=1).mean() < 5.0
