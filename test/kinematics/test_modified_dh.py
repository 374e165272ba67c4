"""Modified-DH (Craig) tables as vendors and papers give them: `convention: modified_dh` in
a robot YAML file is converted once into the standard DH model (kinematics/modified_dh.py);
known answers: the forward kinematics of the table itself, the KR5 written both ways, a
centre of mass in either frame, and the URDF exported from it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_runner import cli

from robot_calib.errors import RobotDescriptionError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.dh import DHTable, chain
from robot_calib.kinematics.loader import load_robot

ROOT = Path(__file__).resolve().parents[2]


def _rx(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _rz(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _t(x: float, y: float, z: float) -> np.ndarray:
    out = np.eye(4)
    out[:3, 3] = [x, y, z]
    return out


def craig_flange(rows: list[dict[str, float]], q: np.ndarray) -> np.ndarray:
    """Frame n of a modified-DH table (rows in rad, m) at joint values q (J,), written out
    from the convention's definition: Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i + q_i) Tz(d_i)."""
    out = np.eye(4)
    for row, qi in zip(rows, q):
        out = out @ _rx(row["alpha"]) @ _t(row["a"], 0, 0) @ _rz(row["theta"] + qi)
        out = out @ _t(0, 0, row["d"])
    return out


def model_flange(robot: RobotDescription, q: np.ndarray) -> np.ndarray:
    """Our model's flange (DH frame J) in its base frame, (n, 4, 4), for joint values q."""
    return chain(DHTable(robot.theta + q, robot.d, robot.a, robot.alpha, robot.beta))[:, -1]


def _write(path: Path, rows: list[dict[str, float]], **extra: object) -> Path:
    joints = [{"name": f"j{i + 1}", **row, "limits": [-3.0, 3.0]} for i, row in enumerate(rows)]
    path.write_text(
        yaml.safe_dump({"name": "mdh_arm", "convention": "modified_dh", "joints": joints, **extra})
    )
    return path


def random_craig_rows(
    rng: np.random.Generator, theta1: float, d1: float
) -> list[dict[str, float]]:
    """A random 6-joint Craig table (rad, m): row 1 on the base axis (alpha_0 = a_0 = 0,
    theta1, d1), rows 2-6 drawn, each twist well away from 0 and pi."""
    rows = [{"alpha": 0.0, "a": 0.0, "theta": theta1, "d": d1}]
    for _ in range(5):
        rows.append(
            {
                "alpha": float(rng.choice([-1, 1]) * rng.uniform(0.3, 2.8)),
                "a": float(rng.uniform(-0.5, 0.5)),
                "theta": float(rng.uniform(-3, 3)),
                "d": float(rng.uniform(-0.5, 0.5)),
            }
        )
    return rows


def test_a_random_modified_table_gives_its_own_forward_kinematics(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    rows = random_craig_rows(rng, theta1=0.3, d1=0.4)
    robot = load_robot(str(_write(tmp_path / "arm.yaml", rows)))
    q = rng.uniform(-3.0, 3.0, (50, 6))
    ours = model_flange(robot, q)
    theirs = np.array([craig_flange(rows, qi) for qi in q])
    assert np.abs(ours - theirs).max() < 1e-12


def test_the_kr5_written_as_modified_dh_is_the_kr5() -> None:
    """The seed's KR5 table rewritten in Craig's convention (each row's alpha and a moved to
    the next row, row 1's zero), its centres of mass moved into the modified frames: the
    same robot, to 1e-12 (Hayati flags included)."""
    kr5 = load_robot("kr5_sixx_r650")
    doc = yaml.safe_load((ROOT / "robot_calib/kinematics/robots/kr5_sixx_r650.yaml").read_text())
    joints = doc["joints"]
    modified = []
    for i, entry in enumerate(joints):
        row = dict(entry)
        row["alpha"] = joints[i - 1]["alpha"] if i else 0
        row["a"] = joints[i - 1]["a"] if i else 0.0
        row.pop("hayati", None)
        row.pop("beta", None)
        for key in ("hayati", "beta"):  # with the row of the alpha and a they turn
            if i and key in joints[i - 1]:
                row[key] = joints[i - 1][key]
        alpha, a = np.radians(entry["alpha"]), entry["a"]  # standard frame i -> modified i
        com = np.array(entry.get("com", [0.0, 0.0, 0.0]))
        c, s = np.cos(alpha), np.sin(alpha)
        row["com"] = [
            float(com[0] + a),
            float(c * com[1] - s * com[2]),
            float(s * com[1] + c * com[2]),
        ]
        modified.append(row)
    doc["joints"], doc["convention"] = modified, "modified_dh"
    from robot_calib.kinematics.description import parse_robot

    again = parse_robot(doc, "kr5_modified.yaml")
    for field in ("theta", "d", "a", "alpha", "beta", "link_mass", "link_com"):
        np.testing.assert_allclose(
            getattr(again, field), getattr(kr5, field), atol=1e-12, err_msg=field
        )
    assert again.hayati.tolist() == kr5.hayati.tolist()


def test_a_modified_table_off_the_base_axis_is_refused(tmp_path: Path) -> None:
    rows = [
        {"alpha": 0.2, "a": 0.0, "theta": 0.0, "d": 0.4},
        {"alpha": 1.0, "a": 0.1, "theta": 0.0, "d": 0.0},
    ]
    with pytest.raises(RobotDescriptionError, match="alpha .* must be 0"):
        load_robot(str(_write(tmp_path / "off.yaml", rows)))
    with pytest.raises(RobotDescriptionError, match="convention must be one of"):
        load_robot(str(_write(tmp_path / "x.yaml", rows[1:] * 2, convention="craig")))


def test_a_modified_table_calibrates_and_exports_as_urdf(tmp_path: Path) -> None:
    """Simulated, calibrated (nominal) and exported as a URDF: the URDF's chain from its base
    to its flange is the table's, to 1e-9 m (the URDF's decimals)."""
    rows = [
        {"alpha": 0.0, "a": 0.0, "theta": 0.0, "d": 0.4},
        {"alpha": -np.pi / 2, "a": 0.15, "theta": -np.pi / 2, "d": 0.0},
        {"alpha": 0.0, "a": 0.55, "theta": 0.0, "d": 0.0},
        {"alpha": -np.pi / 2, "a": 0.12, "theta": 0.0, "d": 0.62},
        {"alpha": np.pi / 2, "a": 0.0, "theta": 0.0, "d": 0.0},
        {"alpha": -np.pi / 2, "a": 0.0, "theta": 0.0, "d": 0.1},
    ]
    arm = _write(tmp_path / "arm.yaml", rows)
    for args in (
        (
            "simulate",
            "--robot",
            str(arm),
            "--plan",
            "random",
            "--n-random",
            "40",
            "-o",
            str(tmp_path / "m.mcap"),
        ),
        (
            "calibrate",
            str(tmp_path / "m.mcap"),
            "--robot",
            str(arm),
            "--model",
            "nominal",
            "-o",
            str(tmp_path / "n.json"),
        ),
        ("export", str(tmp_path / "n.json"), "--format", "urdf", "-o", str(tmp_path / "arm.urdf")),
    ):
        run = cli(*args)
        assert run.returncode == 0, (args, run.stderr)
    from robot_calib.kinematics.urdf import load_urdf

    urdf = load_urdf(tmp_path / "arm.urdf", None, None)
    q = np.random.default_rng(1).uniform(-3.0, 3.0, (20, 6))
    exported = urdf.dh02base @ model_flange(urdf.description, q) @ urdf.tip2flange
    theirs = np.array([craig_flange(rows, qi) for qi in q])
    assert np.abs(exported[:, :3, 3] - theirs[:, :3, 3]).max() < 1e-9


def _csv(path: Path, header: str, rows: list[list[float]]) -> Path:
    lines = [",".join(f"{v:.17g}" for v in row) for row in rows]
    path.write_text("\n".join(["# an arm's table, as a vendor prints it", header, *lines]) + "\n")
    return path


def test_a_modified_table_as_csv_gives_its_own_forward_kinematics(tmp_path: Path) -> None:
    """A random Craig table written as a CSV with its units in the header (mm, deg): the
    flange of the loaded robot is the convention's own product, to 1e-12 m; a standard DH
    table of the KR5 as CSV is the built-in KR5."""
    rng = np.random.default_rng(8)
    rows = random_craig_rows(rng, theta1=0.2, d1=0.35)
    table = [
        [np.degrees(r["alpha"]), r["a"] * 1e3, np.degrees(r["theta"]), r["d"] * 1e3, -170.0, 170.0]
        for r in rows
    ]
    path = _csv(
        tmp_path / "craig.csv",
        "alpha_{i-1} [deg],a_{i-1} [mm],theta [deg],d [mm],min [deg],max [deg]",
        table,
    )
    robot = load_robot(str(path))
    assert robot.name == "craig" and robot.joint_names[0] == "joint_a1"
    q = rng.uniform(-2.9, 2.9, (50, 6))
    ours = model_flange(robot, q)
    theirs = np.array([craig_flange(rows, qi) for qi in q])
    assert np.abs(ours - theirs).max() < 1e-12
    np.testing.assert_allclose(np.degrees(robot.limits), [[-170.0, 170.0]] * 6)
    kr5 = load_robot("kr5_sixx_r650")
    doc = yaml.safe_load((ROOT / "robot_calib/kinematics/robots/kr5_sixx_r650.yaml").read_text())
    standard = [
        [j["name"], j["theta"], j["d"], j["a"], j["alpha"], *j["limits"]] for j in doc["joints"]
    ]
    dh = tmp_path / "kr5.csv"
    lines = [",".join(str(v) for v in row) for row in standard]
    dh.write_text("\n".join(["name,theta_deg,d_m,a_m,alpha_deg,min_deg,max_deg", *lines]) + "\n")
    again = load_robot(str(dh))
    for field in ("theta", "d", "a", "alpha", "beta", "limits"):
        np.testing.assert_allclose(
            getattr(again, field), getattr(kr5, field), atol=1e-12, err_msg=field
        )
    assert again.hayati.tolist() == kr5.hayati.tolist() and again.joint_names == kr5.joint_names


@pytest.mark.parametrize(
    ("header", "row", "said"),
    [
        (
            "alpha_prev,a_prev [mm],theta [deg],d [mm]",
            "0,0,0,400",
            "column 'alpha_prev' has no unit: write it as 'alpha_prev [deg or rad]'",
        ),
        (
            "alpha_prev [deg],a_prev [mm],theta [deg],d [mm],offset [deg]",
            "0,0,0,400,0",
            "column 'offset [deg]' is none of",
        ),
        (
            "alpha_prev [deg],a_prev [mm],a [mm],theta [deg],d [mm]",
            "0,0,0,0,400",
            "not both a and a_prev",
        ),
        ("alpha [deg],a [mm],theta [deg],d [mm]", "0,0,zero,400", "joint 1: theta: 'zero' is no"),
        ("alpha [deg],a [mm],theta [deg],d [inch]", "0,0,0,400", "column 'd [inch]' has unit"),
        (
            "alpha [deg],a [mm],theta [deg],d [mm],min [deg]",
            "0,0,0,400,-10",
            "limits need both min and max",
        ),
    ],
)
def test_a_bad_csv_table_is_one_line_naming_the_file(
    tmp_path: Path, header: str, row: str, said: str
) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(f"{header}\n{row}\n{row}\n")
    run = cli("plan", "--robot", str(path), "--poses", "5", "-o", str(tmp_path / "p.json"))
    assert run.returncode == 2 and said in run.stderr and str(path) in run.stderr, run.stderr
    assert len(run.stderr.strip().splitlines()) == 1 and not (tmp_path / "p.json").exists()


def test_a_csv_table_calibrates_and_its_result_carries_the_table(tmp_path: Path) -> None:
    """Simulated and calibrated with --robot arm.csv: PARAMS.json carries the table's text,
    so it loads (and predicts) with the CSV file gone."""
    arm = _csv(
        tmp_path / "arm.csv",
        "alpha_prev [deg],a_prev [m],theta [deg],d [m],mass [kg]",
        [
            [0, 0, 0, 0.4, 10],
            [-90, 0.15, -90, 0, 8],
            [0, 0.55, 0, 0, 5],
            [-90, 0.12, 0, 0.62, 3],
            [90, 0, 0, 0, 1],
            [-90, 0, 0, 0.1, 0.3],
        ],
    )
    for args in (
        (
            "simulate",
            "--robot",
            str(arm),
            "--plan",
            "random",
            "--n-random",
            "40",
            "-o",
            str(tmp_path / "m.mcap"),
        ),
        (
            "calibrate",
            str(tmp_path / "m.mcap"),
            "--robot",
            str(arm),
            "-o",
            str(tmp_path / "p.json"),
        ),
    ):
        run = cli(*args)
        assert run.returncode == 0, (args, run.stderr)
    text = arm.read_text()
    arm.unlink()
    from robot_calib.identify.calibration import Calibration

    model, params = (loaded := Calibration.load(str(tmp_path / "p.json"))).model, loaded.parameters
    assert model.robot.name == "arm" and model.robot.n_joints == 6
    assert "alpha_prev" in text and model.robot.source.startswith("DH table")
    assert params.names  # the calibrated parameters read back


def test_the_example_table_as_csv_is_the_example_yaml() -> None:
    """docs/examples/craig_arm.csv and craig_arm.yaml: one robot (the README's example)."""
    csv_arm = load_robot(str(ROOT / "docs/examples/craig_arm.csv"))
    yaml_arm = load_robot(str(ROOT / "docs/examples/craig_arm.yaml"))
    for field in ("theta", "d", "a", "alpha", "beta", "limits", "link_mass", "link_com"):
        np.testing.assert_allclose(
            getattr(csv_arm, field), getattr(yaml_arm, field), atol=1e-12, err_msg=field
        )
    assert csv_arm.joint_names == yaml_arm.joint_names
