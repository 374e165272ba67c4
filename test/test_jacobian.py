"""The analytic Jacobian of the target points against central finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from robot_calib.kinematics.description import load_robot
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
