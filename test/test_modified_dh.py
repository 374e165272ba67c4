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

ROOT = Path(__file__).resolve().parents[1]


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
    path.write_text(yaml.safe_dump({"name": "mdh_arm", "convention": "modified_dh",
                                    "joints": joints, **extra}))  # fmt: skip
    return path


def test_a_random_modified_table_gives_its_own_forward_kinematics(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    rows = [{"alpha": 0.0, "a": 0.0, "theta": 0.3, "d": 0.4}]
    for _ in range(5):
        rows.append({"alpha": float(rng.choice([-1, 1]) * rng.uniform(0.3, 2.8)),
                     "a": float(rng.uniform(-0.5, 0.5)), "theta": float(rng.uniform(-3, 3)),
                     "d": float(rng.uniform(-0.5, 0.5))})  # fmt: skip
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
        row["com"] = [float(com[0] + a), float(c * com[1] - s * com[2]),
                      float(s * com[1] + c * com[2])]  # fmt: skip
        modified.append(row)
    doc["joints"], doc["convention"] = modified, "modified_dh"
    from robot_calib.kinematics.description import parse_robot

    again = parse_robot(doc, "kr5_modified.yaml")
    for field in ("theta", "d", "a", "alpha", "beta", "link_mass", "link_com"):
        np.testing.assert_allclose(getattr(again, field), getattr(kr5, field), atol=1e-12,
                                   err_msg=field)  # fmt: skip
    assert again.hayati.tolist() == kr5.hayati.tolist()


def test_a_modified_table_off_the_base_axis_is_refused(tmp_path: Path) -> None:
    rows = [{"alpha": 0.2, "a": 0.0, "theta": 0.0, "d": 0.4}, {"alpha": 1.0, "a": 0.1,
            "theta": 0.0, "d": 0.0}]  # fmt: skip
    with pytest.raises(RobotDescriptionError, match="alpha .* must be 0"):
        load_robot(str(_write(tmp_path / "off.yaml", rows)))
    with pytest.raises(RobotDescriptionError, match="convention must be one of"):
        load_robot(str(_write(tmp_path / "x.yaml", rows[1:] * 2, convention="craig")))


def test_a_modified_table_calibrates_and_exports_as_urdf(tmp_path: Path) -> None:
    """Simulated, calibrated (nominal) and exported as a URDF: the URDF's chain from its base
    to its flange is the table's, to 1e-9 m (the URDF's decimals)."""
    rows = [{"alpha": 0.0, "a": 0.0, "theta": 0.0, "d": 0.4},
            {"alpha": -np.pi / 2, "a": 0.15, "theta": -np.pi / 2, "d": 0.0},
            {"alpha": 0.0, "a": 0.55, "theta": 0.0, "d": 0.0},
            {"alpha": -np.pi / 2, "a": 0.12, "theta": 0.0, "d": 0.62},
            {"alpha": np.pi / 2, "a": 0.0, "theta": 0.0, "d": 0.0},
            {"alpha": -np.pi / 2, "a": 0.0, "theta": 0.0, "d": 0.1}]  # fmt: skip
    arm = _write(tmp_path / "arm.yaml", rows)
    for args in (("simulate", "--robot", str(arm), "--plan", "random", "--n-random", "40",
                  "-o", str(tmp_path / "m.mcap")),
                 ("calibrate", str(tmp_path / "m.mcap"), "--robot", str(arm), "--model",
                  "nominal", "-o", str(tmp_path / "n.json")),
                 ("export", str(tmp_path / "n.json"), "--format", "urdf",
                  "-o", str(tmp_path / "arm.urdf"))):  # fmt: skip
        run = cli(*args)
        assert run.returncode == 0, (args, run.stderr)
    from robot_calib.kinematics.urdf import load_urdf

    urdf = load_urdf(tmp_path / "arm.urdf", None, None)
    q = np.random.default_rng(1).uniform(-3.0, 3.0, (20, 6))
    exported = urdf.dh02base @ model_flange(urdf.description, q) @ urdf.tip2flange
    theirs = np.array([craig_flange(rows, qi) for qi in q])
    assert np.abs(exported[:, :3, 3] - theirs[:, :3, 3]).max() < 1e-9
