"""Robot descriptions as data: built-ins, the user YAML format and its errors."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_runner import cli

from robot_calib.errors import RobotDescriptionError
from robot_calib.kinematics.description import JOINT_KEYS, ROBOT_KEYS, ROBOTS_DIR, available_robots
from robot_calib.kinematics.loader import load_robot

REPO = Path(__file__).resolve().parents[2]


def test_builtins() -> None:
    assert {"kr5_sixx_r650", "ur5", "ur10"} <= set(available_robots())
    kr5 = load_robot("kr5_sixx_r650")
    assert kr5.joint_names == tuple(f"joint_a{j}" for j in range(1, 7))
    np.testing.assert_allclose(np.degrees(kr5.limits[1]), [-162, -5])
    assert np.all(kr5.link_mass > 0)
    assert load_robot("ur5").a[1] == pytest.approx(-0.425)


def test_help_lists_every_built_in(capsys: pytest.CaptureFixture[str]) -> None:
    from robot_calib.cli import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args(["calibrate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert all(name in text for name in available_robots())
    assert {"kr6_r900_sixx", "irb120_3_58", "r2000ic_165f", "m20ia", "gp25"} <= set(
        available_robots()
    )


def test_user_yaml_in_degrees(tmp_path: Path) -> None:
    path = tmp_path / "two_link.yaml"
    path.write_text(
        "name: two_link\nangle_unit: deg\njoints:\n"
        "  - {theta: 0, d: 0.1, a: 0.5, alpha: 0}\n"
        "  - {theta: 90, d: 0, a: 0.4, alpha: 0, limits: [-90, 90]}\n"
    )
    robot = load_robot(path)
    assert robot.name == "two_link" and robot.n_joints == 2
    assert robot.theta[1] == pytest.approx(np.pi / 2)
    assert robot.hayati.tolist() == [True, False]  # alpha1 = 0: axes 1 and 2 parallel
    np.testing.assert_allclose(robot.limits[1], [-np.pi / 2, np.pi / 2])


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("joints: [1", "not valid YAML"),
        ("- 1\n- 2\n", "expected a mapping"),
        (
            "joints:\n  - {theta: 0, d: 0, a: 1}\n  - {theta: 0, d: 0, a: 1, alpha: 0}\n",
            "joint 1: missing 'alpha'",
        ),
        (
            "joints:\n  - {theta: x, d: 0, a: 1, alpha: 0}\n"
            "  - {theta: 0, d: 0, a: 1, alpha: 0}\n",
            "joint 1 theta: expected a number",
        ),
        ("angle_unit: grad\njoints: []\n", "angle_unit"),
    ],
)
def test_malformed_yaml(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(RobotDescriptionError, match=message) as info:
        load_robot(path)
    assert "bad.yaml" in str(info.value)


def test_unknown_robot() -> None:
    with pytest.raises(RobotDescriptionError, match="unknown robot 'kr6'"):
        load_robot("kr6")


@pytest.mark.parametrize("robot", ["kr6_nonexistent", "{tmp}/broken.yaml"])
def test_cli_bad_robot_exits_2_with_one_line(tmp_path: Path, robot: str) -> None:
    (tmp_path / "broken.yaml").write_text("joints: [1")
    result = cli("run", "-o", str(tmp_path / "out"), "--robot", robot.format(tmp=tmp_path))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "error" in lines[0]
    assert robot.format(tmp=tmp_path).split("/")[-1] in lines[0]
    assert not (tmp_path / "out").exists()


TWO_JOINTS = "  - {theta: 0, d: 0.1, a: 0.5, alpha: 0}\n  - {theta: 0, d: 0, a: 0.4, alpha: 0%s}\n"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "name: two_link\nefects: [compliance]\njoints:\n" + TWO_JOINTS % "",
            r"robot\.yaml: unknown key 'efects' \(known: name, source, angle_unit, "
            r"convention, reading_to_joint, joints\)$",
        ),
        (
            "nmae: two_link\njoints:\n" + TWO_JOINTS % "",
            "unknown key 'nmae' (did you mean 'name'?)",
        ),
        ("joint:\n" + TWO_JOINTS % "", "unknown key 'joint' (did you mean 'joints'?)"),
    ],
)
def test_unknown_top_level_key(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "robot.yaml"
    path.write_text(text)
    with pytest.raises(RobotDescriptionError) as info:
        load_robot(path)
    error = str(info.value)
    assert "\n" not in error and error.startswith(str(path))
    if message.endswith("$"):
        assert re.search(message, error), error
    else:
        assert error.endswith(message), error


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (", mas: 3", "joint 2: unknown key 'mas' (did you mean 'mass'?)"),
        (", alpah: 0", "joint 2: unknown key 'alpah' (did you mean 'alpha'?)"),
        (", limit: [-1, 1]", "joint 2: unknown key 'limit' (did you mean 'limits'?)"),
        (", stiffness: 1.0e5", "joint 2: unknown key 'stiffness' (known: name, theta, d, a,"),
    ],
)
def test_unknown_joint_key(tmp_path: Path, extra: str, message: str) -> None:
    path = tmp_path / "robot.yaml"
    path.write_text("name: two_link\njoints:\n" + TWO_JOINTS % extra)
    with pytest.raises(RobotDescriptionError) as info:
        load_robot(path)
    error = str(info.value)
    assert "\n" not in error and error.startswith(f"{path}: ")
    assert message in error, error


def test_every_key_of_the_builtins_is_known() -> None:
    for name in available_robots():
        data = yaml.safe_load((ROBOTS_DIR / f"{name}.yaml").read_text())
        assert set(data) <= set(ROBOT_KEYS), name
        for joint in data["joints"]:
            assert set(joint) <= set(JOINT_KEYS), name
        load_robot(name)


def test_cli_unknown_robot_key_exits_2_with_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "BAD.yaml"
    bad.write_text("name: two_link\njoints:\n" + TWO_JOINTS % ", mas: 3")
    out = tmp_path / "x.json"
    result = cli(
        "calibrate",
        str(REPO / "bags/paper_test3.mcap"),
        "--robot",
        str(bad),
        "-o",
        str(out),
        cwd=tmp_path,
    )
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "BAD.yaml" in lines[0] and "joint 2: unknown key 'mas'" in lines[0]
    assert "did you mean 'mass'?" in lines[0]
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [bad]


@pytest.mark.parametrize("name", available_robots())
def test_every_built_in_robot_names_its_source_and_calibrates_to_the_noise(name: str) -> None:
    """Each built-in description says where its numbers come from, and a simulated robot of
    it (nominal geometry, default noise) calibrates to the noise with no warning."""
    import numpy as np

    from robot_calib.identify.calibrate import calibrate
    from robot_calib.measurements import recording_from_arrays
    from robot_calib.poses import Poses
    from robot_calib.sim.measure import physical_points
    from robot_calib.sim.plans import random_plan
    from robot_calib.sim.world import build_world

    robot = load_robot(name)
    assert robot.source and robot.source != name
    world = build_world({"robot": name, "geometry": "nominal"}, name)
    rng = np.random.default_rng(0)
    q = random_plan(robot, 150, rng).q
    points = physical_points(world, Poses.from_readings(q), rng)
    cal = calibrate(recording_from_arrays(q, points), robot)
    assert cal.accuracy.absolute_rms_mm < 0.02 and cal.warnings == ()
