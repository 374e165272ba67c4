"""Command-line edge cases: bad input is one line and exit status 2 with nothing written;
a calibration of a robot from a YAML file is usable from anywhere."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from cli_runner import cli

ROOT = Path(__file__).resolve().parents[2]
ROBOTS = ROOT / "robot_calib" / "kinematics" / "robots"
RUN = [sys.executable, "-m", "robot_calib"]


def run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """The command's main() in this process (cli_runner.cli): the same exit status and
    output as `python -m robot_calib ARGS`, without a Python start-up per command."""
    return cli(*args, cwd=cwd)


def run_process(*args: str) -> subprocess.CompletedProcess[str]:
    """`python -m robot_calib ARGS` as a process of its own."""
    return subprocess.run([*RUN, *args], capture_output=True, text=True, check=False)


def one_line_error(proc: subprocess.CompletedProcess[str], text: str) -> None:
    assert proc.returncode == 2, proc.stderr
    assert text in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr


@pytest.mark.parametrize(
    ("args", "text"),
    [
        (
            [
                "calibrate",
                "x.mcap",
                "--ecc-order",
                "-1",
                "--model",
                "geometric+eccentricity",
                "-o",
                "p.json",
            ],
            "argument --ecc-order: -1 < 1",
        ),
        (
            ["calibrate", "x.mcap", "--model", "geometric+eccentricity:1:order=0", "-o", "p.json"],
            "order must be an integer >= 1",
        ),
        (
            ["import", "x.csv", "--preset", "ur5_jacobi2025", "--angle-unit", "grad", "-o", "b"],
            "invalid choice: 'grad'",
        ),
        (["simulate", "--plan", "nosuch", "-o", "t.mcap"], "--plan nosuch: unknown plan"),
        (
            ["simulate", "--effects", "eccentricity:1:ordr=2", "-o", "t.mcap"],
            "unknown option 'ordr' (did you mean 'order'?)",
        ),
        (["simulate", "--effects", "backlash:9", "-o", "t.mcap"], "joints [9] outside 1..6"),
        (["simulate", "--effects", "backlash:4,4", "-o", "t.mcap"], "must be distinct"),
        (["simulate", "--effects", "thermal_drift:3", "-o", "t.mcap"], "belongs to no joint"),
        (["simulate", "--effects", "compliance:2=nan", "-o", "t.mcap"], "must be finite"),
        (["simulate", "--plan", "random", "--n-random", "-5", "-o", "t.mcap"], "-5 < 1"),
        (["simulate", "--seed", "-1", "-o", "t.mcap"], "-1 < 0"),
        (
            ["calibrate", "x.mcap", "--model", "geometric+backlash:99", "-o", "p.json"],
            "joints [99] outside 1..6",
        ),
        (["run", "-o", "out", "--effects", "foo:1"], "unknown effect 'foo'"),
        (["run", "-o", "out", "--plan", "nosuch"], "--plan nosuch: unknown plan"),
        (["run", "-o", "out", "--holdout", "0"], "0 < 1"),
        # a --holdout without a bag once meant k-fold without a word
        (["diagnose", "x.mcap", "--holdout", "-o", "d.json"], "--holdout: expected at least one"),
    ],
)
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
    proc = run(
        "import",
        str(csv),
        "--joints",
        "a,b,c,d,e,f",
        "--point",
        "x,y,z",
        "--time",
        "t",
        "-o",
        str(tmp_path / "t.mcap"),
    )
    one_line_error(proc, f"{csv}:4: time 1 s does not increase")
    assert not (tmp_path / "t.mcap").exists()


def test_a_robot_from_a_yaml_file_round_trips_through_params(tmp_path: Path) -> None:
    robot = tmp_path / "robots" / "my_kr5.yaml"
    robot.parent.mkdir()
    shutil.copy(ROBOTS / "kr5_sixx_r650.yaml", robot)  # its `source:` key is prose
    robot.write_text(robot.read_text().replace("name: kr5_sixx_r650", "name: my_kr5"))
    work = tmp_path / "work"
    work.mkdir()
    proc = run(
        "simulate",
        "--robot",
        "robots/my_kr5.yaml",
        "--plan",
        "paper-test3",
        "-o",
        "b.mcap",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    proc = run(
        "calibrate", "b.mcap", "--robot", "robots/my_kr5.yaml", "-o", "p.json", cwd=tmp_path
    )
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


def test_no_command_overwrites_its_input(tmp_path: Path) -> None:
    """`-o` naming an input (the bag, PARAMS.json, JOINTS.csv, a world file) is refused."""
    bag = tmp_path / "in.mcap"
    shutil.copy(ROOT / "bags" / "paper_test3.mcap", bag)
    before = bag.read_bytes()
    one_line_error(run("calibrate", str(bag), "-o", str(bag)), "is an input of this command")
    one_line_error(run("diagnose", str(bag), "-o", str(bag)), "is an input of this command")
    one_line_error(run("calibrate", str(bag), "-o", str(tmp_path)), "is a folder")
    assert bag.read_bytes() == before
    params, joints = tmp_path / "p.json", tmp_path / "j.csv"
    assert run("calibrate", str(bag), "-o", str(params)).returncode == 0
    joints.write_text("q1,q2,q3,q4,q5,q6\n0,0.1,0.2,0.3,0.4,0.5\n")
    for target in (params, joints):
        kept = target.read_bytes()
        proc = run("predict", str(params), "--joints", str(joints), "-o", str(target))
        one_line_error(proc, "is an input of this command")
        assert target.read_bytes() == kept
    world = tmp_path / "my.world.yaml"
    world.write_text((ROOT / "robot_calib" / "sim" / "worlds" / "default.yaml").read_text())
    kept = world.read_bytes()
    proc = run("simulate", "--world", str(world), "-o", str(tmp_path / "my.mcap"))
    one_line_error(proc, "my.world.yaml: is an input of this command")
    assert world.read_bytes() == kept and not (tmp_path / "my.mcap").exists()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("base2tracker: {xyz_m: [2.2, 1.0]}", "base2tracker.xyz_m: expected three finite"),
        ("target_in_flange_m: 0.05", "target_in_flange_m: expected three numbers"),
        ("efects: []", "unknown key 'efects' (did you mean 'effects'?)"),
        ("effects: [{name: backlash, joints: [4], ordr: 2}]", "unknown key 'ordr'"),
    ],
)
def test_bad_world_files_are_one_line_errors(tmp_path: Path, text: str, message: str) -> None:
    world = tmp_path / "w.yaml"
    world.write_text(text + "\n")
    one_line_error(run("simulate", "--world", str(world), "-o", str(tmp_path / "x.mcap")), message)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w.yaml"]


def test_a_robot_file_edited_after_calibration_is_noticed(tmp_path: Path) -> None:
    """PARAMS.json keeps the description's fingerprint: predicting with an edited robot
    file is refused instead of silently wrong."""
    robot = tmp_path / "my_kr5.yaml"
    shutil.copy(ROBOTS / "kr5_sixx_r650.yaml", robot)
    params, joints = tmp_path / "p.json", tmp_path / "j.csv"
    sample = ROOT / "bags" / "paper_test3.mcap"
    assert run("calibrate", str(sample), "--robot", str(robot), "-o", str(params)).returncode == 0
    joints.write_text("q1,q2,q3,q4,q5,q6\n0,-1.5,1.5,0,0.7,0\n")
    assert (
        run(
            "predict", str(params), "--joints", str(joints), "-o", str(tmp_path / "a.csv")
        ).returncode
        == 0
    )
    text = robot.read_text()
    robot.write_text(
        text.replace(
            "name: kr5_sixx_r650",
            "name: kr5_sixx_r650\nreading_to_joint: {sign: [1, 1, 1, -1, 1, 1]}",
            1,
        )
    )  # noqa: E501
    # PARAMS.json carries its description: the edited file is not read, the
    # prediction is the calibrated robot's (its own text is guarded by the fingerprint)
    proc = run("predict", str(params), "--joints", str(joints), "-o", str(tmp_path / "c.csv"))
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "c.csv").read_text() == (tmp_path / "a.csv").read_text()
    old = json.loads(params.read_text())  # a file from before: the path, checked
    del old["robot_description"]
    params.write_text(json.dumps(old))
    proc = run("predict", str(params), "--joints", str(joints), "-o", str(tmp_path / "b.csv"))
    one_line_error(proc, "is not the one it was calibrated with")
    assert not (tmp_path / "b.csv").exists()


def test_version_and_the_summary_of_frames() -> None:
    """`--version`; the tracker pose and target offsets have no nominal: the
    parameter table shows '-' for their nominal and deviation, never their value again."""
    proc = run_process("--version")  # the program itself: its exit status and output
    assert proc.returncode == 0 and proc.stdout.strip().startswith("robot-calib 0.")
    bag = ROOT / "bags" / "paper_test3.mcap"
    from robot_calib.flows.calibrate import calibrate_bags
    from robot_calib.identify.calibration import summary
    from robot_calib.kinematics.loader import load_robot

    cal, recording = calibrate_bags([bag], load_robot("kr5_sixx_r650"), "geometric")
    lines = summary(cal, recording).splitlines()
    frame = next(line for line in lines if line.startswith("base2tracker_x [mm]"))
    assert frame.split()[3:5] == ["-", "-"]
    joint = next(line for line in lines if line.startswith("a2 [mm]"))
    assert len(joint.split()) == 6 and joint.split()[3] != "-"


def test_a_python_warning_is_one_line_naming_the_verb(capsys: pytest.CaptureFixture[str]) -> None:
    """A warning raised while a verb runs (numpy's, scipy's, a capped learned correction's
    RuntimeWarning) reaches the user as 'warning: ...' on one line, as the verb's own
    warnings, never with a file path and source line; `main` leaves Python's own warning
    display as it was."""
    import warnings

    from robot_calib import cli as cli_package

    before = warnings.showwarning
    cli_package._warning_line(
        "predict",
        RuntimeWarning("learned correction: 3 of 9 poses\npredicted beyond 10 mm"),
        RuntimeWarning,
        "/x/correction_structured.py",
        220,
    )
    err = capsys.readouterr().err
    assert err == "warning: learned correction: 3 of 9 poses predicted beyond 10 mm\n"
    assert cli_package.main(["score", "no_such_file.json", "no_such.mcap"]) == 2
    assert warnings.showwarning is before


def test_a_bag_where_the_parameter_file_belongs_is_named(tmp_path: Path) -> None:
    """`score BAG PARAMS.json` (the arguments swapped) once said 'not valid JSON ('utf-8'
    codec can't decode byte 0x89 ...)'; it says which comes first."""
    (tmp_path / "hold.mcap").write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)))
    (tmp_path / "p.json").write_text("{}")
    one_line_error(
        run("score", "hold.mcap", "p.json", cwd=tmp_path), "hold.mcap: a bag, not a parameter file"
    )


def test_run_help_states_its_own_file_policy() -> None:
    """`run` has no --force (each run writes a new folder): its --help says so, and does
    not offer the other verbs' --force."""
    run = cli("run", "--help")
    text = " ".join(run.stdout.split())
    assert run.returncode == 0 and "writes a new folder" in text and "--force" not in text


def test_import_refuses_a_joint_count_before_reading_anything(tmp_path: Path) -> None:
    """Three joint columns for a six-joint robot: one line naming --joints, before any file
    is read (no 'rows imported' line first), and no bag."""
    csv = tmp_path / "m.csv"
    csv.write_text("q1,q2,q3,x,y,z\n0.1,0.2,0.3,1.0,0.0,0.5\n")
    run = cli(
        "import",
        str(csv),
        "--joints",
        "q1,q2,q3",
        "--point",
        "x,y,z",
        "-o",
        "m.mcap",
        cwd=tmp_path,
    )
    assert run.returncode == 2 and "imported" not in run.stdout
    assert "--joints q1,q2,q3: 3 columns for robot kr5_sixx_r650 with 6 joints" in run.stderr
    assert not (tmp_path / "m.mcap").exists()


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (
            ["calibrate", "{bag}", "--max-gap", "0.1", "-o", "p.json"],
            "--max-gap applies with --stream only",
        ),
        (
            ["calibrate", "{bag}", "--stream-max-points", "5", "-o", "p.json"],
            "--stream-max-points applies",
        ),
        (
            [
                "import",
                "{csv}",
                "--joints",
                "q1,q2,q3,q4,q5,q6",
                "--point",
                "x,y,z",
                "--sigma-unit",
                "um",
                "-o",
                "p.json",
            ],
            "--sigma-unit goes with --sigma",
        ),
        (
            ["plan", "--poses", "30", "--model", "geometric+frobnicate", "-o", "plan.yaml"],
            "--model geometric+frobnicate: unknown effect",
        ),
    ],
)
def test_an_option_that_would_be_ignored_or_a_bad_model_is_refused_first(
    args: list[str], said: str, tmp_path: Path
) -> None:
    """An option of a mode not asked for (a stream's on poses at rest, a unit of no column)
    is refused, not ignored; a plan's bad model is refused before any work is printed."""
    csv = tmp_path / "m.csv"
    csv.write_text("q1,q2,q3,q4,q5,q6,x,y,z\n" + "0.1,-1.5,1.5,0,0.5,0,1.0,0.0,0.5\n" * 3)
    bag = Path(__file__).resolve().parents[2] / "bags" / "paper_test3.mcap"
    run = cli(*[a.format(bag=bag, csv=csv) for a in args], cwd=tmp_path)
    assert run.returncode == 2 and said in run.stderr, run.stderr
    assert run.stdout == "" and len(run.stderr.strip().splitlines()) == 1
