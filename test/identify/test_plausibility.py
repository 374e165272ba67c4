"""A fit that converges can still be wrong: plausibility warnings against known
answers. Clean data of the right robot warn nothing; a wrong robot, swapped joints,
readings in degrees, a stuck joint and a residual far above the noise each warn, naming
what is wrong. Nonsense (readings in degrees, parameters beyond physics, a
residual > 1000 x the noise, worse than the simpler model) is more than a warning: the
calibration is `implausible`, PARAMS.json `plausible: false`, `calibrate` exits 3 and
`predict`, `compensate`, `export` refuse the file without --force."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from robot_calib.effects import make_effect
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.calibration import summary
from robot_calib.kinematics.loader import load_robot
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
    """The warnings of a calibration (one per line), and after them its implausible
    reasons, each as 'implausible: REASON'."""
    recording = recording_from_arrays(q, points)
    cal = calibrate(recording, load_robot(robot_name))
    text = "\n".join(cal.warnings)
    assert all(w in summary(cal, recording) for w in cal.warnings)  # stdout shows them
    doc = cal.to_dict(recording)
    assert all(w in doc["warnings"] for w in cal.warnings)  # PARAMS.json
    assert doc["plausible"] == cal.plausible and doc["implausible"] == list(cal.implausible)
    return "\n".join([text, *(f"implausible: {r}" for r in cal.implausible)]).strip()


def test_clean_data_of_the_right_robot_warn_nothing() -> None:
    assert warnings_of(Q) == ""
    rng = np.random.default_rng(1)
    q = random_plan(ROBOT, 300, rng).q
    assert warnings_of(q, points=physical_points(WORLD, Poses.from_readings(q), rng)) == ""


@pytest.mark.parametrize(
    ("case", "expected"),
    [
        ("ur10", "parameters far from nominal (ur10): a1 +7"),
        ("ur10", "implausible: geometric parameters beyond physics (ur10; more than 500 mm"),
        ("swapped 2/3", "a3 -2"),
        ("swapped 2/3", "joint 2 (joint_a2): 536 of 580 readings outside its limits"),
        ("degrees", "readings reach 177.0 rad"),
        ("degrees", "implausible: readings of joint(s) 1 (167.0 rad), 2 (162.0 rad)"),
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


@pytest.mark.parametrize("case", ["swapped 2/3", "20 mrad backlash on joint 2"])
def test_unusual_is_a_warning_not_nonsense(case: str) -> None:
    """A parameter 270 mm from nominal, a residual far above the noise: warned, still
    plausible (the thresholds of nonsense are 500 mm / 30 deg, 1000 x the noise; a joint
    stuck at one reading while it moved leaves 24 mm per axis, 2400 x: nonsense)."""
    q, points = Q.copy(), POINTS
    if case == "swapped 2/3":
        q[:, [1, 2]] = q[:, [2, 1]]
    else:
        world = with_effect(WORLD, make_effect("backlash", [2]), {"backlash2": 0.02})
        points = physical_points(world, Poses.from_readings(q), np.random.default_rng(3))
    text = warnings_of(q, points=points)
    assert "warning: " in text and "implausible" not in text, text


def test_worse_than_the_simpler_model_is_implausible() -> None:
    """A richer model that ends in-sample above the geometric fit it extends (on the same
    measurements) diverged; calibrate records the geometric fit's rms to compare with."""
    from robot_calib.identify.plausibility import WORSE_TOLERANCE, implausible_reasons

    recording = recording_from_arrays(Q, POINTS)
    cal = calibrate(recording, ROBOT, "geometric+backlash:4")
    assert cal.simpler is not None and cal.simpler[0] == "geometric" and cal.plausible
    rms = float(np.sqrt(np.mean(cal.residuals**2)))
    assert rms <= cal.simpler[1] * (1 + WORSE_TOLERANCE)
    assert implausible_reasons(cal, recording, True, ("geometric", rms)) == []
    (reason,) = implausible_reasons(cal, recording, True, ("geometric", 0.9 * rms))
    assert reason.startswith(f"in-sample {rms * 1e3:.4f} mm per axis, worse than the geometric")
    assert calibrate(recording, ROBOT, "geometric").simpler is None  # nothing simpler fitted


def test_calibrate_of_readings_in_degrees_exits_3_and_the_file_is_refused(tmp_path: Path) -> None:
    """The CLI: calibrate writes PARAMS.json marked plausible false and exits 3 with one
    'fitted, implausible' line; predict and export refuse that file (exit 2, naming it and
    the reason) unless --force, which warns instead."""
    from cli_runner import cli

    from robot_calib.bag.write import write_measurement_bag

    q = np.degrees(paper_test_plan(3).q)
    points = physical_points(WORLD, Poses.from_readings(np.radians(q)), np.random.default_rng(5))
    write_measurement_bag(tmp_path / "deg.mcap", q, points, ROBOT.joint_names)
    proc = cli("calibrate", "deg.mcap", "-o", "p.json", cwd=tmp_path)
    assert proc.returncode == 3, proc.stderr
    said = [line for line in proc.stderr.splitlines() if line.startswith("robot-calib")]
    assert len(said) == 1 and said[0].startswith(
        "robot-calib calibrate: fitted, implausible: readings of joint(s) 1 ("
    ), proc.stderr
    assert said[0].endswith("(p.json: plausible false)")
    doc = json.loads((tmp_path / "p.json").read_text())
    assert doc["plausible"] is False and "look like degrees" in doc["implausible"][0]
    (tmp_path / "j.csv").write_text("q1,q2,q3,q4,q5,q6\n0.1,-1.2,1.1,0.2,0.3,0.4\n")
    for verb in (
        ["predict", "p.json", "--joints", "j.csv"],
        ["export", "p.json", "--format", "dh"],
    ):
        proc = cli(*verb, "-o", "out", cwd=tmp_path)
        assert proc.returncode == 2 and not (tmp_path / "out").exists(), proc.stderr
        assert "p.json: fitted, implausible (readings of joint(s) 1 (" in proc.stderr
        assert "--force to use it anyway" in proc.stderr
    proc = cli("predict", "p.json", "--joints", "j.csv", "--force", "-o", "out.csv", cwd=tmp_path)
    assert proc.returncode == 0 and (tmp_path / "out.csv").exists(), proc.stderr
    assert "warning: p.json: fitted, implausible (" in proc.stderr


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


def test_diagnose_of_readings_in_degrees_exits_3_without_a_traceback(tmp_path: Path) -> None:
    """The diagnosis of a UR10 bag whose readings are in degrees (the geometric fit then
    has almost nothing free: the frequency scan once crashed reshaping an empty Jacobian)
    writes DIAGNOSIS.json with the reasons and exits 3 with one line."""
    from cli_runner import cli

    from robot_calib.bag.write import write_measurement_bag
    from robot_calib.sim.scenarios import ur10_random

    scenario = ur10_random(seed=4, n=150, holdout_share=0.0)
    rec = scenario.calibration
    robot = scenario.world.model.robot
    write_measurement_bag(
        tmp_path / "deg.mcap", np.degrees(rec.poses.q), rec.points, robot.joint_names
    )
    proc = cli("diagnose", "deg.mcap", "--robot", "ur10", "-o", "d.json", cwd=tmp_path)
    assert proc.returncode == 3, proc.stderr
    assert "Traceback" not in proc.stderr
    said = [line for line in proc.stderr.splitlines() if line.startswith("robot-calib")]
    assert len(said) == 1 and "look like degrees" in said[0], proc.stderr
    doc = json.loads((tmp_path / "d.json").read_text())
    assert doc["implausible"] and "look like degrees" in doc["implausible"][0]


def test_diagnose_with_hold_out_readings_in_degrees_exits_3(tmp_path: Path) -> None:
    """Calibration bag in rad, hold-out bag in degrees: every held-out figure is nonsense;
    it once ended with exit 0 and a null verdict. Now DIAGNOSIS.json names the reason and
    the verb exits 3."""
    from cli_runner import cli

    from robot_calib.bag.write import START_NS, STEP_NS, write_measurements
    from robot_calib.sim.scenarios import ur10_random

    scenario = ur10_random(seed=5, n=200, holdout_share=0.3)
    robot, cal, held = scenario.world.model.robot, scenario.calibration, scenario.holdout
    stamps = START_NS + np.arange(len(cal) + len(held)) * STEP_NS
    write_measurements(
        tmp_path / "cal.mcap", cal.poses.q, cal.points, robot.joint_names, stamps[: len(cal)]
    )
    write_measurements(
        tmp_path / "deg.mcap",
        np.degrees(held.poses.q),
        held.points,
        robot.joint_names,
        stamps[len(cal) :],
    )
    proc = cli(
        "diagnose",
        "cal.mcap",
        "--holdout",
        "deg.mcap",
        "--robot",
        "ur10",
        "-o",
        "d.json",
        cwd=tmp_path,
    )
    assert proc.returncode == 3, proc.stderr
    doc = json.loads((tmp_path / "d.json").read_text())
    assert any("hold-out readings" in r and "degrees" in r for r in doc["implausible"])
    assert "IMPLAUSIBLE" in (tmp_path / "d.html").read_text()
