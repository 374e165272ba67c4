"""Readings to joint variables (robot YAML `reading_to_joint`): the model, sweeps and CPA
work in joint variables, so a robot whose controller couples J3 to J2 (FANUC style) and
flips joint 4 calibrates from its raw readings; the same bag fitted without the mapping
does not predict new poses.

The coupled robot is the KR5 with `coupling: {3: {2: 1.0}}` (joint variable 3 = reading 3
+ reading 2) and `sign: -1` on joint 4, written into tmp_path; the simulator runs the
seed's Test 2 plan in its readings (Table 2's single-joint sweeps of the joint variables:
the joint-2 sweep moves readings 2 and 3 together).
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli

from robot_calib.accuracy import accuracy
from robot_calib.errors import RobotDescriptionError
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.calibration import Calibration
from robot_calib.kinematics.description import ROBOTS_DIR
from robot_calib.kinematics.loader import load_robot
from robot_calib.measurements import find_sweeps
from robot_calib.model import KinematicModel, absorb_base_offsets
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import random_plan
from robot_calib.sim.world import load_world

MAPPING = "reading_to_joint:\n  sign: [1, 1, 1, -1, 1, 1]\n  coupling: {3: {2: 1.0}}\n"
# True geometry: nominal plus deviations of the size of the seed's Table 3 [m, rad].
DEVIATIONS = (
    "{a1: -1.6e-4, a2: 3.4e-4, a3: 2.8e-4, d4: 2.8e-4, theta2: -5.0e-4, theta3: -9.0e-4, "
    "theta4: 3.7e-3, alpha3: -5.2e-4, alpha4: 5.1e-4, beta2: 9.4e-4}"
)


def coupled_yaml(folder: Path, mapping: str = MAPPING) -> Path:
    """The KR5 description with `mapping` (joint 3's reading limits widened: reading 3 =
    joint variable 3 - reading 2)."""
    text = (ROBOTS_DIR / "kr5_sixx_r650.yaml").read_text()
    text = text.replace("name: kr5_sixx_r650", "name: kr5_coupled")
    text = text.replace("joints:\n", mapping + "joints:\n", 1)
    text = text.replace("limits: [-114, 145]", "limits: [-200, 320]")
    path = folder / "kr5_coupled.yaml"
    path.write_text(text)
    return path


def run(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return cli(*args, cwd=cwd)


def test_the_mapping_is_diag_sign_plus_coupling(tmp_path: Path) -> None:
    robot = load_robot(coupled_yaml(tmp_path))
    expected = np.eye(6)
    expected[3, 3], expected[2, 1] = -1.0, 1.0
    np.testing.assert_array_equal(robot.reading_matrix, expected)
    assert robot.reading_offset is None and robot.has_mapping
    q = np.random.default_rng(0).uniform(-3, 3, (10, 6))
    np.testing.assert_allclose(robot.readings(robot.joint_variables(q)), q, atol=1e-15)
    # The same mapping as a matrix (zero diagonal), with an offset in degrees.
    rows = [[0.0] * 6 for _ in range(6)]
    rows[2][1] = 1.0
    matrix = f"reading_to_joint:\n  sign: [1, 1, 1, -1, 1, 1]\n  offset: [0, 0, 0, 90, 0, 0]\n  coupling: {rows}\n"  # noqa: E501
    full = load_robot(coupled_yaml(tmp_path, matrix))
    np.testing.assert_array_equal(full.reading_matrix, expected)
    shift = full.joint_variables(q) - robot.joint_variables(q)
    np.testing.assert_allclose(shift, np.tile(np.radians([0, 0, 0, 90, 0, 0]), (10, 1)))
    # The built-ins declare none: joint variables are the readings themselves.
    kr5 = load_robot("kr5_sixx_r650")
    assert not kr5.has_mapping and kr5.joint_variables(q) is q


@pytest.mark.parametrize(
    ("section", "message"),
    [
        ("  sign: [1, 1, 1, 2, 1, 1]\n", "sign must be +1 or -1 per joint"),
        ("  sign: [1, 1]\n", "sign must be a list of 6 numbers"),
        ("  coupling: {3: {3: 1.0}}\n", "reading 3 must be another joint in 1..6"),
        ("  coupling: {7: {2: 1.0}}\n", "coupling must map joints 1..6"),
        ("  coupling: {2: {3: 1.0}, 3: {2: 1.0}}\n", "is singular"),
        ("  cuopling: {3: {2: 1.0}}\n", "unknown key 'cuopling' (did you mean 'coupling'?)"),
    ],
)
def test_bad_mappings_are_refused(tmp_path: Path, section: str, message: str) -> None:
    path = coupled_yaml(tmp_path, "reading_to_joint:\n" + section)
    with pytest.raises(RobotDescriptionError) as err:
        load_robot(path)
    assert message in str(err.value) and str(path) in str(err.value)


def test_forward_kinematics_with_a_mapping_is_the_plain_model_at_the_joint_variables(
    tmp_path: Path,
) -> None:
    """FK known answer: the model with the mapping at readings q equals the model without it
    at joint variables M q + offset (points, flange poses, gravity-driven effects alike)."""
    mapping = MAPPING.replace("sign:", "offset: [0, 10, 0, 0, -5, 0]\n  sign:")
    robot = load_robot(coupled_yaml(tmp_path, mapping))
    plain_robot = load_robot("kr5_sixx_r650")
    q = np.random.default_rng(1).uniform(-2.5, 2.5, (50, 6))
    m = np.eye(6)
    m[3, 3], m[2, 1] = -1.0, 1.0
    variables = q @ m.T + np.radians([0, 10, 0, 0, -5, 0])
    np.testing.assert_allclose(robot.joint_variables(q), variables, atol=1e-15)
    world = load_world()
    params = world.truth
    mapped, unmapped = KinematicModel(robot), KinematicModel(plain_robot)
    np.testing.assert_allclose(
        mapped.target_points(params, Poses.from_readings(q)),
        unmapped.target_points(params, Poses.from_readings(variables)),
        atol=1e-12,
    )
    # The parameter Jacobian is taken at the joint variables too.
    np.testing.assert_allclose(
        mapped.jacobian(params, Poses.from_readings(q))[1],
        unmapped.jacobian(params, Poses.from_readings(variables))[1],
        atol=1e-12,
    )


def test_coupled_robot_calibrates_from_raw_readings(tmp_path: Path) -> None:
    """Simulate Test 2 on the coupled robot (in its readings), calibrate with its YAML: CPA
    finds the 6 sweeps and the geometric fit reaches the noise floor, within 3 sigma of the
    truth; the same bag calibrated as the plain KR5 finds 5 sweeps and misses new poses by
    millimetres."""
    robot_file = coupled_yaml(tmp_path)
    (tmp_path / "w.yaml").write_text(
        f"robot: {robot_file}\ngeometry: nominal\ndeviations: {DEVIATIONS}\n"
    )
    sim = run(
        "simulate",
        "--world",
        "w.yaml",
        "--plan",
        "paper-test2",
        "--seed",
        "3",
        "-o",
        "b.mcap",
        cwd=tmp_path,
    )
    assert sim.returncode == 0, sim.stderr
    cal = run("calibrate", "b.mcap", "--robot", str(robot_file), "-o", "p.json", cwd=tmp_path)
    assert cal.returncode == 0, cal.stderr
    assert "6 sweeps [J1:120, J2:60, J3:100, J4:120, J5:60, J6:120]" in cal.stdout, cal.stdout
    assert "warning" not in cal.stdout + cal.stderr, cal.stdout + cal.stderr

    # Recompute in memory: the readings really couple 2 and 3 in the joint-2 sweep.
    from robot_calib.bag.read import read_recording

    robot = load_robot(robot_file)
    rec = read_recording([tmp_path / "b.mcap"], robot)
    j2 = rec.sweeps_of(2)[0].index
    assert np.ptp(rec.poses.q[j2, 1]) > 2.0 and np.ptp(rec.poses.q[j2, 2]) > 2.0
    assert 2 not in {s.joint for s in find_sweeps(rec.poses.q)}  # not on the readings
    mapped = calibrate(rec, robot, "geometric")
    assert mapped.cpa is not None and len(mapped.cpa.sweeps) == 6
    assert mapped.accuracy.absolute_rms_mm < 0.015
    world = load_world(tmp_path / "b.world.yaml")
    truth = absorb_base_offsets(robot, world.truth)
    free = mapped.parameters.free
    z = (mapped.parameters.values - truth.values)[free] / mapped.std[free]
    assert np.all(np.abs(z) < 3.0), dict(zip(mapped.parameters.free_names, np.round(z, 2)))
    model, params = (loaded := Calibration.load(tmp_path / "p.json")).model, loaded.parameters
    assert model.robot.has_mapping

    # Hold-out: random general poses (readings within the limits).
    rng = np.random.default_rng(7)
    poses = Poses.from_readings(random_plan(robot, 200, rng).q)
    points = physical_points(world, poses, rng)
    floor = accuracy(points, world.model.target_points(world.truth, poses))
    held = accuracy(points, model.target_points(params, poses))
    assert held.absolute_rms_mm < 1.3 * floor.absolute_rms_mm

    plain_robot = load_robot("kr5_sixx_r650")
    as_plain = read_recording([tmp_path / "b.mcap"], plain_robot)
    assert [s.joint for s in as_plain.sweeps] == [1, 3, 4, 5, 6]  # joint 2's is no sweep
    plain = calibrate(as_plain, plain_robot, "geometric")
    assert plain.cpa is None  # CPA needs a sweep of every joint
    missed = accuracy(points, plain.predict(poses))
    assert missed.absolute_rms_mm > 100 * floor.absolute_rms_mm
