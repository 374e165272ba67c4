"""The analytic Jacobian of the target points against central finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from robot_calib.kinematics.loader import load_robot
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel, geometric_parameters
from robot_calib.poses import Poses


def finite_difference(model: KinematicModel, params: ParameterVector, poses: Poses) -> np.ndarray:
    step = 1e-6
    cols = []
    for name in params.names:
        plus = model.target_points(params.with_values({name: params[name] + step}), poses)
        minus = model.target_points(params.with_values({name: params[name] - step}), poses)
        cols.append((plus - minus) / (2 * step))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("robot", ["kr5_sixx_r650", "ur5", "ur10"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_jacobian_matches_finite_differences(robot: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    model = KinematicModel(load_robot(robot))
    nominal = geometric_parameters(
        model.robot,
        base2tracker=tuple(rng.uniform(-1, 1, 6) * [2, 2, 1, 0.5, 0.5, 3]),
        target_in_flange=tuple(rng.uniform(-0.05, 0.05, 3)),
    )
    # Random deviations everywhere, including fixed parameters and betas.
    params = nominal.with_values(
        {n: v + rng.normal(0, 0.01) for n, v in zip(nominal.names, nominal.values)}
    )
    lo, hi = model.robot.limits.T
    poses = Poses.from_readings(rng.uniform(lo, hi, (20, 6)))
    points, jac = model.jacobian(params, poses)
    assert jac.shape == (20, 3, len(params))
    np.testing.assert_allclose(points, model.target_points(params, poses))
    np.testing.assert_allclose(jac, finite_difference(model, params, poses), atol=1e-7)


def test_jacobian_with_every_effect_matches_finite_differences() -> None:
    """Effects enter through joint offsets, length strain and housing errors; the chain
    rule through all three must match finite differences (exact at non-zero values)."""
    from robot_calib.effects import make_effect

    rng = np.random.default_rng(7)
    model = KinematicModel(
        load_robot("kr5_sixx_r650"),
        (
            make_effect("eccentricity", [1, 3, 6], order=2),
            make_effect("backlash", [4]),
            make_effect("compliance", [2, 3]),
            make_effect("encoder_scale", [1, 5]),
            make_effect("thermal_drift"),
            make_effect("joint_ripple", [6]),
        ),
    )
    nominal = model.parameters((2.5, 0.1, 0.2, 0.1, 0.2, 0.3), (0.06, 0.0, 0.05))
    small = ("compliance", "thermal")  # their units make 1e-2 absurdly large
    params = nominal.with_values(
        {
            n: v + rng.normal(0, 1e-6 if n.startswith(small) else 1e-2)
            for n, v in zip(nominal.names, nominal.values)
        }
    )
    lo, hi = model.robot.limits.T
    poses = Poses.from_readings(rng.uniform(lo, hi, (9, 6)), time=rng.uniform(0, 1000, 9))
    assert len(set(poses.direction.ravel())) == 2  # both approach directions occur
    _, jac = model.jacobian(params, poses)
    fd = finite_difference(model, params, poses)
    scale = np.maximum(np.abs(jac).max(axis=(0, 1)), 1.0)
    np.testing.assert_allclose(jac / scale, fd / scale, atol=2e-7)


def test_gravity_torque_known_answer() -> None:
    """KR5 at q = 0: the arm is horizontal along base x, joint 2's axis is z1 = -y0 through
    x = 75 mm. A mass m at base x gives tau_2 = -g m (x - 0.075). Centres of mass in base x
    (from the frames worked out in test_kinematics and robots/kr5_sixx_r650.yaml):
    link 2: 0.345 - 0.135 = 0.210; link 3: 0.345 + 0.02 = 0.365 (z3 = x0);
    link 4: 0.640 - 0.150 = 0.490 (y4 = x0); link 5: 0.640; link 6: 0.720 - 0.010 = 0.710.
    Joint 1's axis is vertical: no gravity torque."""
    from robot_calib.effects.compliance import gravity_torques

    tau = gravity_torques(load_robot("kr5_sixx_r650"), np.zeros((1, 6)))[0]
    moments = 6 * 0.135 + 3.5 * 0.290 + 3 * 0.415 + 1.5 * 0.565 + 0.5 * 0.635
    assert tau[0] == pytest.approx(0.0, abs=1e-12)
    assert tau[1] == pytest.approx(-9.81 * moments, rel=1e-12)
