"""Known answers for the DH/Hayati chain, worked out by hand from the seed's Table 1."""

from __future__ import annotations

import numpy as np
import pytest

from robot_calib.kinematics.dh import DHTable, chain, link_transforms
from robot_calib.kinematics.loader import load_robot
from robot_calib.model import KinematicModel, geometric_parameters
from robot_calib.poses import Poses

DEG = np.pi / 180.0


@pytest.fixture(scope="module")
def kr5() -> KinematicModel:
    return KinematicModel(load_robot("kr5_sixx_r650"))


def flange(model: KinematicModel, q_deg: list[float]) -> np.ndarray:
    params = geometric_parameters(model.robot)
    return model.flange2base(params, Poses.from_readings(np.array([q_deg]) * DEG))[0]


def test_kr5_zero_reading(kr5: KinematicModel) -> None:
    """q = 0. Table 1 rows: (d, theta, a, alpha) = (335, 0, 75, 90), (0, 0, 270, 0),
    (0, 90, 90, 90), (295, 0, 0, 90), (0, 180, 0, 90), (80, 0, 0, 0) [mm, deg].

    Frame 1: origin (75, 0, 335); Rx(90) gives x1 = x0, y1 = z0, z1 = -y0.
    Link 2 (theta 0, a 270): origin 2 = (345, 0, 335), axes as frame 1.
    Link 3 (theta 90, a 90): Rz(90) turns x onto y1 = z0, so origin 3 = (345, 0, 425);
      after Rx(90): x3 = z0, y3 = -y0, z3 = x0 (the forearm points along x0).
    Link 4 (d 295 along z3): origin 4 = (640, 0, 425); x4 = z0, y4 = x0, z4 = y0.
    Link 5 (theta 180): x5 = -z0, y5 = y0, z5 = x0; origin unchanged.
    Link 6 (d 80 along z5): flange at (720, 0, 425) with x6 = -z0, y6 = y0, z6 = x0.
    """
    f = flange(kr5, [0, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(f[:3, 3], [0.720, 0.0, 0.425], atol=1e-12)
    np.testing.assert_allclose(f[:3, :3], [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-12)


def test_kr5_joint2_minus_90(kr5: KinematicModel) -> None:
    """q2 = -90 deg: joint 2 turns -90 deg about z1 = -y0, i.e. +90 deg about y0, which maps
    x0 -> -z0 and z0 -> x0. At q = 0 the flange sits at (645, 0, 90) mm from the shoulder
    (75, 0, 335); rotated: (90, 0, -645); so the flange is at (165, 0, -310) mm.
    The flange z axis (x0 at q = 0) becomes -z0.
    """
    f = flange(kr5, [0, -90, 0, 0, 0, 0])
    np.testing.assert_allclose(f[:3, 3], [0.165, 0.0, -0.310], atol=1e-12)
    np.testing.assert_allclose(f[:3, 2], [0, 0, -1], atol=1e-12)


def test_kr5_joints_1_and_5(kr5: KinematicModel) -> None:
    """q1 = 90, q5 = 90 deg. At q = 0 the wrist centre (origin 4) is (640, 0, 425) and joint
    5's axis is z4 = y0; +90 deg about y0 maps the 80 mm flange offset x0 -> -z0: flange at
    (640, 0, 345). Joint 1 then turns everything +90 deg about z0: (x, y) -> (-y, x), so the
    flange is at (0, 640, 345) mm and its z axis is -z0.
    """
    f = flange(kr5, [90, 0, 0, 0, 90, 0])
    np.testing.assert_allclose(f[:3, 3], [0.0, 0.640, 0.345], atol=1e-12)
    np.testing.assert_allclose(f[:3, 2], [0, 0, -1], atol=1e-12)


def test_target_in_tracker_frame(kr5: KinematicModel) -> None:
    """Target 50 mm along the flange z axis; base placed in the tracker at (2.5, 0.1, -0.3) m
    and turned yaw = 90 deg, which maps base (x, y, z) -> tracker (-y, x, z) + offset.
    At q = 0 the target is at (720 + 50, 0, 425) mm in the base, so at
    (2.5 - 0, 0.1 + 0.770, -0.3 + 0.425) m in the tracker.
    """
    params = geometric_parameters(
        kr5.robot,
        base2tracker=(2.5, 0.1, -0.3, 0.0, 0.0, np.pi / 2),
        target_in_flange=(0, 0, 0.05),
    )
    p = kr5.target_points(params, Poses.from_readings(np.zeros((1, 6))))[0]
    np.testing.assert_allclose(p, [2.5, 0.87, 0.125], atol=1e-12)


def plain_dh(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """Textbook DH matrix (Spong), written out independently of the package."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0, sa, ca, d],
            [0, 0, 0, 1],
        ]
    )


def test_beta_zero_is_plain_dh() -> None:
    rng = np.random.default_rng(1)
    theta, d, a, alpha = rng.uniform(-3, 3, (4, 5, 6))
    links = link_transforms(DHTable(theta, d, a, alpha, np.zeros((5, 6))))
    for i in range(5):
        for j in range(6):
            np.testing.assert_allclose(
                links[i, j], plain_dh(theta[i, j], d[i, j], a[i, j], alpha[i, j]), atol=1e-12
            )


def test_beta_is_a_final_rotation_about_y() -> None:
    """Hayati-Mirmirani: the link matrix with beta is the DH matrix times Ry(beta)."""
    beta = 0.01
    ry = np.array(
        [
            [np.cos(beta), 0, np.sin(beta), 0],
            [0, 1, 0, 0],
            [-np.sin(beta), 0, np.cos(beta), 0],
            [0, 0, 0, 1],
        ]
    )
    link = link_transforms(DHTable(np.array([[0.3]]), 0.0, 0.27, 0.0, beta))[0, 0]
    np.testing.assert_allclose(link, plain_dh(0.3, 0.0, 0.27, 0.0) @ ry, atol=1e-12)


def test_chain_is_product_of_links() -> None:
    rng = np.random.default_rng(2)
    dh = DHTable(*rng.uniform(-1, 1, (5, 3, 6)))
    frames = chain(dh)
    links = link_transforms(dh)
    expected = np.eye(4)
    for j in range(6):
        expected = expected @ links[:, j]
        np.testing.assert_allclose(frames[:, j + 1], expected, atol=1e-12)


def test_hayati_joints_of_builtins() -> None:
    assert load_robot("kr5_sixx_r650").hayati.tolist() == [False, True] + [False] * 4
    for name in ("ur5", "ur10"):
        assert load_robot(name).hayati.tolist() == [False, True, True, False, False, False]
