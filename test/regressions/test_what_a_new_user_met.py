"""What a new user met, each fixed where it is met: `score` flags an error far
above the calibration's own and orientations it cannot score, `predict` refuses degrees and
a --robot that is not the calibration's, `import` says why its rows are bad and which
--sep or --robot would help, `--help` shows the defaults, the docs list every column.

Known answers: a simulated UR10 with a 6-DoF probe (40 poses) and the sample KR5 bag."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli

from robot_calib.accuracy import Accuracy
from robot_calib.bag.csv_format import PRESETS, CsvFormat
from robot_calib.bag.csv_import import read_measurement_csv
from robot_calib.bag.read import read_recording
from robot_calib.bag.write import write_measurement_bag
from robot_calib.cli import build_parser
from robot_calib.csv_tables import read_joints_csv
from robot_calib.diagnosis.noise import estimate_noise, noise_basis
from robot_calib.errors import InputError
from robot_calib.identify.calibration import Calibration
from robot_calib.identify.score import IMPLAUSIBLE_HINT, score, score_warnings, write_points_table
from robot_calib.kinematics.loader import load_robot
from robot_calib.measurements import recording_from_arrays
from robot_calib.sim.measure import measure_every_target
from robot_calib.sim.plans import plan_times, random_plan
from robot_calib.sim.world import build_world

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "bags" / "paper_test3.mcap"  # KR5, joints joint_a1..joint_a6
KR5 = load_robot("kr5_sixx_r650")
UR10 = load_robot("ur10")
UR_NAMES = ",".join(UR10.joint_names)
KR5_NAMES = ",".join(KR5.joint_names)


@pytest.fixture(scope="module")
def work(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A UR10 bag with a 6-DoF probe (ur10.mcap) and its calibration (p10.json, a probe),
    and a KR5 calibration of the sample bag (p5.json, points only)."""
    folder = tmp_path_factory.mktemp("new_user")
    world = build_world(
        {
            "robot": "ur10",
            "geometry": "nominal",
            "seed": 1,
            "six_dof": {"first": [0, 90, 0]},
            "target_in_flange_m": [0, 0, 0.12],
        }
    )
    rng = np.random.default_rng(1)
    plan = random_plan(UR10, 40, rng)
    poses, points = measure_every_target(world, plan.q, plan_times(plan, world.timing), rng)
    write_measurement_bag(
        folder / "ur10.mcap",
        poses.q,
        points,
        UR10.joint_names,
        poses.time,
        six_dof={"": (poses.rotation, np.full((40, 2), np.nan))},
    )
    for args in (
        ["ur10.mcap", "--robot", "ur10", "-o", "p10.json"],
        [str(SAMPLE), "-o", "p5.json"],
    ):
        proc = cli("calibrate", *args, cwd=folder)
        assert proc.returncode == 0, proc.stderr
    return folder


def test_score_flags_another_robot_in_every_output(work: Path) -> None:
    """The user's case: a UR10 bag scored with KR5 parameters (its joints renamed) gave
    1082 mm and no word; now stderr, stdout and the per-point table each say it, and that
    the bag's orientations are not scored (the KR5 calibration has no probe)."""
    proc = cli(
        "score",
        "p5.json",
        "ur10.mcap",
        "--joint-names",
        UR_NAMES,
        "--points-csv",
        "points.csv",
        cwd=work,
    )
    assert proc.returncode == 0, proc.stderr
    implausible = [x for x in proc.stderr.splitlines() if IMPLAUSIBLE_HINT in x]
    assert len(implausible) == 1 and implausible[0].startswith("warning: ur10.mcap: absolute")
    not_scored = "6-DoF orientations at /laser_tracker/point, but the calibration has no probe"
    assert not_scored in proc.stderr
    for output in (proc.stdout, (work / "points.csv").read_text()):
        assert implausible[0] in output and not_scored in output
    with (work / "points.csv").open() as f:  # the warnings are comment lines before the header
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    assert len(rows) == 40 and float(rows[0]["error_m"]) > 0.01
    # The other way round: the probe calibration on a bag of points only.
    proc = cli("score", "p10.json", str(SAMPLE), "--joint-names", KR5_NAMES, cwd=work)
    assert proc.returncode == 0 and IMPLAUSIBLE_HINT in proc.stdout, proc.stderr
    assert "no 6-DoF orientations at /laser_tracker/point, where the calibration has a probe" in (
        proc.stderr
    )


def test_the_implausibility_threshold(work: Path) -> None:
    """Above 10 x the in-sample rms and above 1 mm: both are needed."""
    cal = Calibration.load(work / "p5.json")
    model, fitted = cal.model, cal.accuracy
    assert fitted is not None and fitted.absolute_rms_mm < 0.02
    recording = read_recording([SAMPLE], KR5)

    def warned(held_rms_mm: float, in_sample_rms_mm: float) -> bool:
        held, fit = (Accuracy(10, 0.0, 0.0, r, r, r) for r in (held_rms_mm, in_sample_rms_mm))
        return any(IMPLAUSIBLE_HINT in w for w in score_warnings(held, fit, (), model, recording))

    assert warned(1.2, 0.1) and warned(50.0, 4.0)
    assert not warned(0.9, 0.01)  # below 1 mm: a scatter, however many times the fit's
    assert not warned(30.0, 4.0)  # within 10 x: a poor calibration, honestly scored
    # A tracker moved by 5 mm since the calibration: flagged; where it stood: not (the
    # sample bag is the calibration's own: only that is said).
    shifted = recording_from_arrays(
        recording.poses.q, recording.points + [0.005, 0, 0], recording.poses.time, robot=KR5
    )
    assert any(IMPLAUSIBLE_HINT in w for w in score(cal, shifted, in_sample=fitted).warnings)
    (only,) = cal.score(recording).warnings
    assert "looks like a bag this calibration was fitted on" in only


def test_predict_refuses_degrees_and_another_robot(work: Path) -> None:
    q = np.round(np.degrees(read_recording([work / "ur10.mcap"], UR10).poses.q[:3]), 3)
    header = ",".join(f"q{j}" for j in range(1, 7))
    np.savetxt(work / "deg.csv", q, delimiter=",", fmt="%.3f", header=header, comments="")
    k, j = np.argwhere(np.abs(q) > 1.5 * 2 * np.pi)[0]  # UR10 joints turn +-360 deg
    proc = cli("predict", "p10.json", "--joints", "deg.csv", "-o", "out.csv", cwd=work)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert f"deg.csv:{k + 2}: column q{j + 1} (field {j + 1}) = {q[k, j]:g} is beyond" in (
        proc.stderr
    )
    assert "degrees?" in proc.stderr and not (work / "out.csv").exists()
    # The same readings in rad are read as they are.
    np.savetxt(
        work / "rad.csv", np.radians(q), delimiter=",", fmt="%.12f", header=header, comments=""
    )
    np.testing.assert_allclose(
        read_joints_csv(work / "rad.csv", 6, UR10.limits).q, np.radians(q), atol=1e-11
    )
    # --robot is checked against the calibration's robot, the default robot's name too.
    for verb in (
        ["predict", "p10.json", "--joints", "rad.csv", "-o", "out.csv"],
        ["score", "p10.json", "ur10.mcap"],
    ):
        proc = cli(*verb, "--robot", "kr5_sixx_r650", cwd=work)
        assert proc.returncode == 2, proc.stderr
        assert "p10.json: identified for robot ur10, not --robot kr5_sixx_r650" in proc.stderr
    assert not (work / "out.csv").exists()
    assert "header q1..qJ [rad]" in help_of("predict")


def help_of(verb: str) -> str:
    """The options part of `robot-calib VERB --help`, whitespace made single spaces."""
    choices = build_parser()._subparsers._group_actions[0].choices  # noqa: SLF001
    return " ".join(choices[verb].format_help().split()).split(" options: ", 1)[1]


def test_a_joint_state_of_another_built_in_robot_suggests_robot_first(work: Path) -> None:
    with pytest.raises(InputError) as info:
        read_recording([work / "ur10.mcap"], KR5)
    message = str(info.value)
    assert (
        "they are the joints of built-in robots ur10, ur10e, ur16e, ur3, ur3e, ur5, ur5e: "
        "give `robot='ur10'` (or another of them" in message
    )
    assert message.index("`robot=") < message.index("`joint_names=")
    # names of no built-in robot: only --joint-names
    renamed = tuple(f"axis{j}" for j in range(1, 7))
    write_measurement_bag(
        work / "axes.mcap",
        np.zeros((2, 6)) + [[0.1], [0.2]],
        np.array([[1.0, 0, 0], [1.1, 0, 0]]),
        renamed,
    )
    with pytest.raises(InputError, match="; map them with `joint_names=") as info:
        read_recording([work / "axes.mcap"], KR5)
    assert "robot" not in str(info.value).split("; map them")[1]


ROWS = [
    "t;q1;q2;q3;q4;q5;q6;x;y;z",
    "0.0;0.1;0.2;0.3;0.4;0.5;0.6;1250.5;20.0;-300.25",
    "1.0;0.1;;0.3;0.4;0.5;0.6;1251.5;;-300.25",
    "2.0;0.1;0.2;0.3;0.4;0.5;0.6;1252.5;20.0;x",
]
FMT = CsvFormat(
    joints=tuple(f"q{j}" for j in range(1, 7)),
    point=("x", "y", "z"),
    time="t",
    separator=";",
    length_unit="mm",
)


def test_import_says_which_column_makes_a_row_bad(tmp_path: Path) -> None:
    path = tmp_path / "e.csv"
    path.write_text("\n".join(ROWS) + "\n")
    table = read_measurement_csv(path, FMT)
    assert table.bad_rows == ((3, "columns q2, y are empty"), (4, "column z 'x' is not a number"))
    # Every row bad: the first one's line and reason, and how many.
    path.write_text("\n".join([ROWS[0], *ROWS[2:]]) + "\n")
    with pytest.raises(InputError) as info:
        read_measurement_csv(path, FMT)
    assert str(info.value) == (
        f"{path}:2: columns q2, y are empty (the first of 2 bad rows: no usable row)"
    )
    path.write_text(ROWS[0] + "\n02.03.2026 09:00:00;0.1;0.2;0.3;0.4;0.5;0.6;1.0;2.0;3.0\n")
    with pytest.raises(InputError) as info:
        read_measurement_csv(path, FMT)
    assert str(info.value) == (
        f"{path}:2: column t '02.03.2026 09:00:00' is not a number (the only row: no usable row)"
    )
    # one bad row of three: "1 bad row", not "1 bad rows"
    path.write_text("\n".join(ROWS[:3]) + "\n" + ROWS[1].replace("0.0;", "3.0;", 1) + "\n")
    proc = cli(
        "import",
        str(path),
        "--joints",
        "q1,q2,q3,q4,q5,q6",
        "--point",
        "x,y,z",
        "--time",
        "t",
        "--sep",
        ";",
        "--length-unit",
        "mm",
        "-o",
        str(tmp_path / "e.mcap"),
    )
    assert proc.returncode == 0, proc.stderr
    assert f"{path}: 2 rows imported, 1 bad row skipped" in proc.stdout
    assert f"warning: {path}:3: columns q2, y are empty: row skipped" in proc.stderr


@pytest.mark.parametrize(("sep", "hint"), [(";", "`separator=';'`"), ("\t", "`separator='\\t'`")])
def test_a_header_of_one_column_suggests_the_separator(
    tmp_path: Path, sep: str, hint: str
) -> None:
    path = tmp_path / "e.csv"
    path.write_text("\n".join(ROWS[:2]).replace(";", sep) + "\n")
    with pytest.raises(InputError) as info:
        read_measurement_csv(path, CsvFormat(joints=FMT.joints, point=FMT.point))
    assert str(info.value).startswith(f"{path}:1: the header is one column containing 9 ")
    assert str(info.value).endswith(f"(separator ','): give {hint}")
    # the hint works: tab spelt 'tab' on the command line
    args = ["--joints", "q1,q2,q3,q4,q5,q6", "--point", "x,y,z", "--length-unit", "mm"]
    proc = cli(
        "import",
        str(path),
        *args,
        "--sep",
        "tab" if sep == "\t" else sep,
        "-o",
        str(tmp_path / "e.mcap"),
    )
    assert proc.returncode == 0, proc.stderr


def test_a_separator_of_two_characters_is_a_usage_error(tmp_path: Path) -> None:
    proc = cli(
        "import",
        "e.csv",
        "--sep",
        ";;",
        "--joints",
        "a",
        "--point",
        "x,y,z",
        "-o",
        "e.mcap",
        cwd=tmp_path,
    )
    assert proc.returncode == 2 and "argument --sep: ';;': one character" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr


def test_import_help_shows_the_format_defaults() -> None:
    """The defaults import's help states are CsvFormat's (and the preset's where it has
    its own), so help and behaviour cannot drift apart."""
    text = help_of("import")
    default = CsvFormat(joints=(), point=("", "", ""))
    preset = PRESETS["ur5_jacobi2025"]
    for option, value, preset_value in (
        ("--angle-unit", default.angle_unit, preset.angle_unit),
        ("--length-unit", default.length_unit, preset.length_unit),
        ("--dif-sign", f"{default.dif_sign:+g}", f"{preset.dif_sign:+g}"),
    ):
        own = text[text.index(f"{option} {{") :][:200]  # its line: after the choices
        assert f"(default {value}; ur5_jacobi2025: {preset_value})" in own, own
    assert f"(default '{default.separator}')" in text
    assert "(default: the first row is the header)" in text and "numbers written 1.5)" in text
    assert "(default kr5_sixx_r650; with --preset, the preset's robot)" in text


def test_the_noise_floor_says_what_its_number_counts() -> None:
    noise = estimate_noise(read_recording([SAMPLE], KR5))
    assert noise.basis == f"{noise.source}, {noise.n} degrees of freedom" and noise.n > 100
    assert noise_basis("stated tracker accuracy (per point)", 300) == (
        "stated tracker accuracy (per point), rms of 300 values"
    )
    assert noise_basis("stated tracker accuracy (given by the user)", 0).endswith("user)")


def test_the_docs_list_every_column_of_the_score_table(work: Path) -> None:
    cal10 = Calibration.load(work / "p10.json")
    recording = read_recording([work / "ur10.mcap"], UR10)
    table = work / "table.csv"
    write_points_table(score(cal10, recording), recording, table)
    header = table.read_text().splitlines()[0].split(",")
    assert header[-4:] == ["rx_rad", "ry_rad", "rz_rad", "angle_rad"]
    doc = (ROOT / "msgs_doc" / "split_score.md").read_text()
    assert [c for c in header if f"`{c}`" not in doc] == []


def test_no_file_a_simulation_or_plan_reads_is_ever_overwritten(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A new user replaced a PLAN.yaml, a world file and a URDF with
    `-o SAME --force`: every file read is an input, never overwritten."""
    from robot_calib.cli import main

    data = Path(__file__).parents[1] / "data"
    (tmp_path / "ur.urdf").write_bytes((data / "ur10.urdf").read_bytes())
    plan = [
        "plan",
        "--model",
        "geometric",
        "--poses",
        "12",
        "--candidates",
        "200",
        "--trials",
        "1",
    ]
    assert main([*plan, "--robot", str(tmp_path / "ur.urdf"), "-o", str(tmp_path / "p.yaml")]) == 0
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    urdf, yaml_plan = str(tmp_path / "ur.urdf"), str(tmp_path / "p.yaml")
    for args in (
        ["simulate", "--robot", urdf, "--plan", yaml_plan, "-o", yaml_plan],
        ["simulate", "--robot", urdf, "--plan", "random", "-o", urdf],
        [*plan, "--robot", urdf, "-o", urdf],
    ):
        assert main([*args, "--force"]) == 2
        assert "is an input of this command; will not overwrite it" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"\x89MCAP0\r\n\xff\xfe\x00", "not a text CSV file (not UTF-8; a bag or a spreadsheet?"),
        (b"q1;q2;q3;q4;q5;q6\n0;0;0;0;0;0\n", "separated by ';'? use ','"),
    ],
)
def test_a_joints_file_that_is_no_csv_is_one_line(
    tmp_path: Path, content: bytes, message: str
) -> None:
    from robot_calib.csv_tables import read_csv_table

    path = tmp_path / "joints.csv"
    path.write_bytes(content)
    with pytest.raises(InputError, match=message.replace("?", r"\?").replace("(", r"\(")):
        read_csv_table(path, "joints", "q1..q6")


def test_an_interrupted_run_leaves_no_half_folder(tmp_path: Path) -> None:
    """The new user's Ctrl-C during `run` left a half-filled run folder: the run is built in
    a hidden folder and renamed when complete; interrupted, nothing of it stays (not even
    the output folder, when the run made it)."""
    from robot_calib.flows.run import run
    from robot_calib.nodes.simulate import simulate_bag

    calls = []

    def interrupt(plan: str, done: int, total: int) -> None:
        calls.append(plan)
        if plan == "random":  # the hold-out simulation: the calibration bag is written
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run(
            tmp_path / "o",
            plan="paper-test1",
            n_holdout=20,
            progress=interrupt,
            record=simulate_bag,
            say=lambda text: None,
        )
    assert "random" in calls and not (tmp_path / "o").exists()  # the folder it made: gone
    (tmp_path / "mine").mkdir()  # a folder the user made stays, empty
    with pytest.raises(KeyboardInterrupt):
        run(
            tmp_path / "mine",
            plan="paper-test1",
            n_holdout=20,
            progress=interrupt,
            record=simulate_bag,
            say=lambda text: None,
        )
    assert list((tmp_path / "mine").iterdir()) == []
