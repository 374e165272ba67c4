"""Command-line edge cases: bad input is one line and exit status 2 with nothing written;
a calibration of a robot from a YAML file is usable from anywhere."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = ROOT / "robot_calib" / "kinematics" / "robots"
RUN = [sys.executable, "-m", "robot_calib"]


def run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*RUN, *args], capture_output=True, text=True, check=False, cwd=cwd)


def one_line_error(proc: subprocess.CompletedProcess[str], text: str) -> None:
    assert proc.returncode == 2, proc.stderr
    assert text in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr


@pytest.mark.parametrize(
    ("args", "text"),
    [
        (["calibrate", "x.mcap", "--ecc-order", "-1", "--model", "geometric+eccentricity",
          "-o", "p.json"], "order must be an integer >= 1"),
        (["calibrate", "x.mcap", "--model", "geometric+eccentricity:1:order=0", "-o", "p.json"],
         "order must be an integer >= 1"),
        (["import", "x.csv", "--preset", "ur5_jacobi2025", "--angle-unit", "grad", "-o", "b"],
         "invalid choice: 'grad'"),
        (["simulate", "--plan", "nosuch", "-o", "t.mcap"], "--plan nosuch: unknown plan"),
    ],
)  # fmt: skip
def test_bad_arguments_are_one_line_and_write_nothing(
    tmp_path: Path, args: list[str], text: str
) -> None:
    one_line_error(run(*args, cwd=tmp_path), text)
    assert list(tmp_path.iterdir()) == []


def test_import_names_the_line_where_time_goes_back(tmp_path: Path) -> None:
    csv = tmp_path / "t.csv"
    csv.write_text(
        "t,a,b,c,d,e,f,x,y,z\n0,0,0,0,0,0,0,1,1,1\n2,0,0,0,0,0,0,1,1,1\n1,0,0,0,0,0,0,1,1,1\n"
    )
    proc = run("import", str(csv), "--joints", "a,b,c,d,e,f", "--point", "x,y,z", "--time", "t",
               "-o", str(tmp_path / "t.mcap"))  # fmt: skip
    one_line_error(proc, f"{csv}:4: time 1 s does not increase")
    assert not (tmp_path / "t.mcap").exists()


def test_a_robot_from_a_yaml_file_round_trips_through_params(tmp_path: Path) -> None:
    robot = tmp_path / "robots" / "my_kr5.yaml"
    robot.parent.mkdir()
    shutil.copy(ROBOTS / "kr5_sixx_r650.yaml", robot)  # its `source:` key is prose
    robot.write_text(robot.read_text().replace("name: kr5_sixx_r650", "name: my_kr5"))
    work = tmp_path / "work"
    work.mkdir()
    proc = run("simulate", "--robot", "robots/my_kr5.yaml", "--plan", "paper-test3",
               "-o", "b.mcap", cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    proc = run("calibrate", "b.mcap", "--robot", "robots/my_kr5.yaml", "-o", "p.json",
               cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert json.loads((tmp_path / "p.json").read_text())["robot"] == str(robot.resolve())
    (work / "j.csv").write_text("q1,q2,q3,q4,q5,q6\n0,-1.5,1.5,0,0.7,0\n")
    proc = run("predict", "../p.json", "--joints", "j.csv", "-o", "x.csv", cwd=work)
    assert proc.returncode == 0, proc.stderr
    assert (work / "x.csv").read_text().startswith("x,y,z\n")
    one_line_error(
        run(
            "predict", "../p.json", "--joints", "j.csv", "--robot", "ur5", "-o", "y.csv", cwd=work
        ),
        "identified for robot my_kr5, not --robot ur5",
    )
