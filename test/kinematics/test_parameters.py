"""The named parameter vector: layout, pack/unpack and file round trips."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robot_calib.errors import ParameterError
from robot_calib.kinematics.loader import load_robot
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import geometric_parameters


def test_kr5_layout() -> None:
    params = geometric_parameters(load_robot("kr5_sixx_r650"))
    # 6 joints x (theta, d, a, alpha) + beta2 + 6 tracker pose + 3 target offset.
    assert len(params) == 24 + 1 + 6 + 3
    assert "beta2" in params and "beta3" not in params
    fixed = {p.name: p.fixed_reason for p in params.parameters if not p.free}
    assert set(fixed) == {"d2", "theta1", "d1", "theta6", "d6", "a6", "alpha6"}
    assert "Hayati" in fixed["d2"]
    assert len(params.free_names) == 27
    assert params.parameters[params.index("alpha1")].unit == "rad"
    assert params["a2"] == pytest.approx(0.270)
    assert params["theta3"] == pytest.approx(np.pi / 2)


def test_ur5_has_two_betas() -> None:
    params = geometric_parameters(load_robot("ur5"))
    assert {"beta2", "beta3"} <= set(params.names)
    assert len(params) == 24 + 2 + 6 + 3


def test_pack_unpack_round_trip() -> None:
    rng = np.random.default_rng(3)
    params = geometric_parameters(load_robot("kr5_sixx_r650"))
    x = rng.normal(size=len(params.free_names))
    moved = params.unpack(x)
    np.testing.assert_array_equal(moved.pack(), x)
    fixed = ~params.free
    np.testing.assert_array_equal(moved.values[fixed], params.values[fixed])
    np.testing.assert_array_equal(moved.unpack(params.pack()).values, params.values)
    with pytest.raises(ParameterError, match="expected 27 free values"):
        params.unpack(x[:-1])


def test_dict_round_trip_through_json() -> None:
    rng = np.random.default_rng(4)
    params = geometric_parameters(load_robot("ur10")).fixed(["a3"], "test reason")
    params = params.unpack(params.pack() + rng.normal(0, 1e-3, len(params.free_names)))
    back = ParameterVector.from_dict(json.loads(json.dumps(params.to_dict())))
    assert back.names == params.names
    np.testing.assert_array_equal(back.values, params.values)
    np.testing.assert_array_equal(back.nominal, params.nominal)
    np.testing.assert_array_equal(back.free, params.free)
    assert back.parameters[back.index("a3")].fixed_reason == "test reason"


def test_fix_and_free() -> None:
    params = geometric_parameters(load_robot("kr5_sixx_r650"))
    fixed = params.fixed(["a2"], "why")
    assert "a2" in params.free_names and "a2" not in fixed.free_names
    assert fixed.freed(["a2"]).free_names == params.free_names


def test_errors_name_the_parameter() -> None:
    params = geometric_parameters(load_robot("kr5_sixx_r650"))
    with pytest.raises(ParameterError, match="'beta9'"):
        params["beta9"]
    with pytest.raises(ParameterError, match="malformed"):
        ParameterVector.from_dict([{"name": "x"}])
