"""Every numeric input has a finite plausible range
(msgs_doc/units.md, walked row by row), copies of measurements are no data, stamps going
backwards are said, a tracker measuring one point is refused, duplicate CSV columns are
refused. Real CLI on a simulated KR5."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[list[float]]]:
    """60 random poses of a simulated KR5: the bag and its rows [q1..q6 rad, x, y, z m]."""
    from robot_calib.bag.read import read_recording
    from robot_calib.kinematics.loader import load_robot

    bag = tmp_path_factory.mktemp("sim") / "r60.mcap"
    run = cli("simulate", "--plan", "random", "--n-random", "60", "--seed", "3", "-o", str(bag))
    assert run.returncode == 0, run.stderr
    rec = read_recording([bag], load_robot("kr5_sixx_r650"))
    return bag, [[*q, *p] for q, p in zip(rec.poses.q.tolist(), rec.points.tolist())]


def _csv(path: Path, rows: list[list[float]], header: str = "q1,q2,q3,q4,q5,q6,x,y,z") -> Path:
    path.write_text(header + "\n" + "".join(",".join(f"{v:.9f}" for v in r) + "\n" for r in rows))
    return path


COLUMNS = ("--joints", "q1,q2,q3,q4,q5,q6", "--point", "x,y,z")


def _bag(
    path: Path,
    rows: list[list[float]],
    order: list[int] | None = None,
    stamp_of: list[int] | None = None,
) -> Path:
    """A contract bag of `rows`, stamped 1 s apart; `order`: the receive (file) order;
    `stamp_of`: row k's stamp number (default k)."""
    from robot_calib.bag.mcap_writer import BagWriter
    from robot_calib.bag.ros2_formats import typestore
    from robot_calib.bag.write import joint_state_cdr, point_cdr
    from robot_calib.kinematics.loader import load_robot
    from robot_calib.messages import JOINT_STATE_TYPE, JOINT_STATES_TOPIC, POINT_TOPIC, POINT_TYPE

    names = load_robot("kr5_sixx_r650").joint_names
    store = typestore(JOINT_STATE_TYPE, POINT_TYPE)
    t0 = 1_700_000_000_000_000_000
    with BagWriter(path) as writer:
        writer.add_topic(JOINT_STATES_TOPIC, JOINT_STATE_TYPE)
        writer.add_topic(POINT_TOPIC, POINT_TYPE)
        for n, k in enumerate(order or range(len(rows))):
            stamp = t0 + (k if stamp_of is None else stamp_of[k]) * 1_000_000_000
            received = t0 + n * 1_000_000_000
            writer.write(
                JOINT_STATES_TOPIC,
                joint_state_cdr(store, stamp, names, np.array(rows[k][:6]), np.zeros(0)),
                received,
            )
            writer.write(POINT_TOPIC, point_cdr(store, stamp, np.array(rows[k][6:])), received + 1)
    return path


def _one_line_error(run: object, *needles: str) -> None:
    assert run.returncode == 2, (run.stdout, run.stderr)  # type: ignore[attr-defined]
    err = run.stderr.strip()  # type: ignore[attr-defined]
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err


def test_a_csv_given_twice_or_copied_rows_are_refused(
    sim: tuple[Path, list[list[float]]], tmp_path: Path
) -> None:
    """Item 1: `import a.csv a.csv` wrote every row twice (exit 0); copies of rows are no
    measurements: exit 2 naming the file, line and how many, nothing written."""
    _, rows = sim
    a = _csv(tmp_path / "a.csv", rows)
    out = tmp_path / "aa.mcap"
    _one_line_error(
        cli("import", str(a), str(a), *COLUMNS, "-o", str(out)), "a.csv", "given twice"
    )
    x10 = _csv(tmp_path / "x10.csv", [r for r in rows for _ in range(10)])
    _one_line_error(
        cli("import", str(x10), *COLUMNS, "-o", str(out)),
        "x10.csv:3",
        "x10.csv:2",
        "540 of 600 rows",
    )
    assert not out.exists()
    # the tracker measuring again (a new point at the same readings) is a repeat, kept
    again = [r[:6] + [v + 2e-6 for v in r[6:]] for r in rows[:5]]
    run = cli("import", str(a), str(_csv(tmp_path / "b.csv", again)), *COLUMNS, "-o", str(out))
    assert run.returncode == 0, run.stderr


def test_copies_in_a_bag_count_once_with_a_warning(
    sim: tuple[Path, list[list[float]]], tmp_path: Path
) -> None:
    """Item 1: a bag of 60 measurements x10 fitted 600 points without a word."""
    _, rows = sim
    bag = _bag(tmp_path / "x10.mcap", [r for r in rows for _ in range(10)])
    run = cli("calibrate", str(bag), "-o", str(tmp_path / "p.json"))
    assert run.returncode == 0, run.stderr
    assert "540 of 600 measurements are copies" in run.stderr
    assert "(60 points)" in run.stdout + run.stderr


def test_stamps_going_backwards_are_said(
    sim: tuple[Path, list[list[float]]], tmp_path: Path
) -> None:
    """Item 2: joint-state stamps against the receive order (exit 0, no warning before)."""
    _, rows = sim
    order = list(range(len(rows)))
    order[10], order[11] = order[11], order[10]
    bag = _bag(tmp_path / "back.mcap", rows, order)
    run = cli("calibrate", str(bag), "-o", str(tmp_path / "p.json"))
    assert run.returncode == 0, run.stderr
    assert re.search(r"back\.mcap: /joint_states: 1 of 60 stamps go backwards", run.stderr)
    ok = cli("calibrate", str(_bag(tmp_path / "ok.mcap", rows)), "-o", str(tmp_path / "q.json"))
    assert ok.returncode == 0 and "backwards" not in ok.stderr


def test_approach_sides_follow_the_receive_order(tmp_path: Path) -> None:
    """Item 2: a backlash bag whose stamps go backwards (a clock jump: the stamps of poses
    40-79 come before those of 0-39) while the robot visited the poses in the order they
    were received: each pose's approach side follows the receive order, so the backlash
    fit equals the clean bag's (before: the sides flipped around the jump, 0.010 -> 0.206
    mm held out in the field)."""
    from robot_calib.bag.read import read_recording
    from robot_calib.kinematics.loader import load_robot

    clean = tmp_path / "clean.mcap"
    run = cli(
        "simulate",
        "--plan",
        "random",
        "--n-random",
        "120",
        "--seed",
        "5",
        "--effects",
        "backlash:4",
        "-o",
        str(clean),
    )
    assert run.returncode == 0, run.stderr
    robot = load_robot("kr5_sixx_r650")
    rec = read_recording([clean], robot)
    rows = [[*q, *p] for q, p in zip(rec.poses.q.tolist(), rec.points.tolist())]
    jump = [k + 80 if k < 40 else k - 40 for k in range(len(rows))]  # 40-79 first
    bag = _bag(tmp_path / "jump.mcap", rows, stamp_of=jump)
    jumped = read_recording([bag], robot)
    same = _bag(tmp_path / "same.mcap", rows)  # the clean rows, stamps in receive order
    reference = read_recording([same], robot)
    assert any("stamps go backwards" in w for w in jumped.warnings), jumped.warnings
    # the same poses (in stamp order there) with the same approach sides
    by_q = {tuple(np.round(q, 9)): d for q, d in zip(reference.poses.q, reference.poses.direction)}
    sides = np.array([by_q[tuple(np.round(q, 9))] for q in jumped.poses.q])
    np.testing.assert_array_equal(sides, jumped.poses.direction)
    fits = []
    for name, source in (("a", same), ("b", bag)):
        out = tmp_path / f"{name}.json"
        run = cli("calibrate", str(source), "--model", "geometric+backlash:4", "-o", str(out))
        assert run.returncode == 0, run.stderr
        found = re.search(r"absolute mean ([0-9.]+) / max", run.stdout)
        assert found, run.stdout
        fits.append(float(found.group(1)))
    # the same fit (the same measurements with the same sides); flipped sides: 0.03+ mm
    assert abs(fits[0] - fits[1]) <= 0.05 * fits[0] + 1e-4, fits


@pytest.mark.parametrize("column", [2, 7])
def test_a_corrupt_number_in_a_bag_is_refused(
    sim: tuple[Path, list[list[float]]], tmp_path: Path, column: int
) -> None:
    """Item 3: a joint reading (exit 0, 1.83 mm) or a tracker coordinate (an SVD that hung)
    of 1e300: one line naming the bag, topic and message, exit 2."""
    _, rows = sim
    bad = [list(r) for r in rows]
    bad[5][column] = 1e300
    bag = _bag(tmp_path / "bad.mcap", bad)
    topic = "/joint_states" if column < 6 else "/laser_tracker/point"
    run = cli("calibrate", str(bag), "-o", str(tmp_path / "p.json"), timeout=120)
    _one_line_error(run, "bad.mcap", f"{topic} message 6", "1e+300")
    assert not (tmp_path / "p.json").exists()


def test_one_point_measured_on_every_pose_is_refused(
    sim: tuple[Path, list[list[float]]], tmp_path: Path
) -> None:
    """Item 4: every tracker point identical on random poses: a collapsed robot (exit 0)."""
    _, rows = sim
    bag = _bag(
        tmp_path / "same.mcap",
        [r[:6] + [v + 1e-7 * k for v in rows[0][6:]] for k, r in enumerate(rows)],
    )
    run = cli("calibrate", str(bag), "-o", str(tmp_path / "p.json"))
    _one_line_error(run, "same.mcap", "tracker points stay within", "measured one point")
    assert not (tmp_path / "p.json").exists()


@pytest.mark.parametrize(
    ("header", "joints", "needle"),
    [
        ("q1,q2,q3,q4,q5,q6,x,y,z", "q1,q1,q3,q4,q5,q6", "'q1' is given twice"),
        ("q1,q2,q3,q4,q5,q6,x,x,z", "q1,q2,q3,q4,q5,q6", "2 columns named 'x'"),
    ],
)
def test_duplicate_columns_are_refused(
    sim: tuple[Path, list[list[float]]], tmp_path: Path, header: str, joints: str, needle: str
) -> None:
    """Item 5: `--joints q1,q1,...` and a header with two x columns were read silently."""
    _, rows = sim
    csv = _csv(tmp_path / "d.csv", rows, header)
    run = cli(
        "import", str(csv), "--joints", joints, "--point", "x,y,z", "-o", str(tmp_path / "d.mcap")
    )
    _one_line_error(run, "d.csv", needle)
    assert not (tmp_path / "d.mcap").exists()


def _table() -> list[tuple[str, str, str]]:
    """(verb, option, out-of-range value) of every row of msgs_doc/units.md's option table."""
    out = []
    for line in (ROOT / "msgs_doc" / "units.md").read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 5 and cells[1].startswith("`--"):
            for verb in cells[0].split(", "):
                out.append((verb, cells[1].strip("`"), cells[4]))
    return out


def test_the_units_table_covers_every_unit_bearing_option() -> None:
    """Every option whose help names a unit in brackets is in the table."""
    from robot_calib.cli import build_parser

    listed = {(verb, option) for verb, option, _ in _table()}
    assert len(listed) >= 14
    parser = build_parser()
    verbs = next(a for a in parser._actions if a.dest == "command" or a.choices)
    for verb, sub in verbs.choices.items():  # type: ignore[union-attr]
        for action in sub._actions:
            unit = re.search(r"\[(s|Hz|mm|m|kg)\]", action.help or "")
            flag = next((o for o in action.option_strings if o.startswith("--")), None)
            if unit and flag and action.type is not None:
                assert (verb, flag) in listed, (verb, flag, action.help)


@pytest.mark.parametrize(("verb", "option", "value"), _table())
def test_every_option_of_the_units_table_refuses_out_of_range(
    sim: tuple[Path, list[list[float]]], tmp_path: Path, verb: str, option: str, value: str
) -> None:
    """Item 6: each row's out-of-range value through the real CLI: exit 2, one line naming
    the option, nothing written."""
    bag, _ = sim
    out = tmp_path / "out"
    base = {
        "simulate": ["--stream", "-o", f"{out}.mcap"],
        "plan": ["--poses", "20", "--trials", "0", "-o", f"{out}.yaml"],
        "calibrate": [str(bag), "-o", f"{out}.json"],
        "diagnose": [str(bag), "-o", f"{out}.json"],
        "split": [
            str(bag),
            "--calibration-out",
            f"{out}.c.mcap",
            "--holdout-out",
            f"{out}.h.mcap",
        ],
        "score": [str(tmp_path / "missing.json"), str(bag)],
        "run": ["-o", str(out)],
    }[verb]
    run = cli(verb, *base, f"{option}={value}", timeout=120)
    _one_line_error(run, option)
    assert not list(tmp_path.iterdir())


def test_rounded_rereads_of_a_still_pose_import_and_a_pasted_block_does_not(
    sim: tuple[Path, list[list[float]]], tmp_path: Path
) -> None:
    """A tracker export rounding to 1 um reads a still pose 3 times; now and then two reads
    round to the same point (38 of 1134 rows of a real Meca500 export), which `import` once
    refused as copies. Scattered exact repeats are kept as re-reads (said in one note, and
    the bag keeps them: one pose in every fold); a block of rows pasted again, or a file
    of mostly copies, is still refused."""
    from robot_calib.bag.read import read_recording
    from robot_calib.kinematics.loader import load_robot
    from robot_calib.poses import reading_groups

    _, rows = sim
    rng = np.random.default_rng(0)
    reads = []
    for k, r in enumerate(rows):  # 3 reads a pose, 3 um noise, rounded to 1 um
        for read in range(3):
            noise = rng.normal(0.0, 3e-6, 3) if not (k % 10 == 0 and read == 2) else 0.0
            point = np.round((np.array(r[6:]) + (noise if read else 0.0)) * 1e6) / 1e6
            reads.append(r[:6] + point.tolist())
    reads = [r if i % 30 != 2 else reads[i - 2] for i, r in enumerate(reads)]  # exact re-reads
    out = tmp_path / "rereads.mcap"
    run = cli("import", str(_csv(tmp_path / "rereads.csv", reads)), *COLUMNS, "-o", str(out))
    assert run.returncode == 0, run.stderr
    assert "6 of 180 rows repeat an earlier row's joint readings and point exactly" in run.stdout
    recording = read_recording([out], load_robot("kr5_sixx_r650"))
    assert len(recording) == 180 and "copies" not in " ".join(recording.warnings)
    assert len(np.unique(reading_groups(recording.poses.q))) == 60  # 3 reads: one pose
    reversed_block = reads[:90] + reads[59:29:-1]  # a block pasted again, reversed
    _one_line_error(
        cli(
            "import",
            str(_csv(tmp_path / "rev.csv", reversed_block)),
            *COLUMNS,
            "-o",
            str(tmp_path / "r.mcap"),
        ),
        "a pasted block",
    )
    timed = [[*r, float(k)] for k, r in enumerate(reads[:90] + reads[30:60])]  # new times
    _one_line_error(
        cli(
            "import",
            str(_csv(tmp_path / "timed.csv", timed, "q1,q2,q3,q4,q5,q6,x,y,z,t")),
            *COLUMNS,
            "--time",
            "t",
            "-o",
            str(tmp_path / "t.mcap"),
        ),
        "a pasted block",
    )
    pasted = reads[:90] + reads[30:60]  # a block of 30 rows pasted again
    _one_line_error(
        cli(
            "import",
            str(_csv(tmp_path / "pasted.csv", pasted)),
            *COLUMNS,
            "-o",
            str(tmp_path / "p.mcap"),
        ),
        "pasted.csv:121 repeat rows",
        "33 of 120 rows",
        "a pasted block",
    )


def test_reference_reflectors_remove_the_trackers_drift(
    sim: tuple[Path, list[list[float]]], tmp_path: Path
) -> None:
    """Three reflectors fixed on the floor, read with every pose, while the tracker's frame
    drifts (50 um/h and 20 urad/h about its vertical, over an hour): `import --reference`
    removes the drift from the tool's points (back to the points the tracker read at the
    start, but for the noise of the drift's own estimate) and says how far it drifted and
    how much the references scatter about it (the 12.5 um per axis they were read with)."""
    import re

    from scipy.spatial.transform import Rotation

    from robot_calib.bag.read import read_recording
    from robot_calib.kinematics.loader import load_robot

    _, rows = sim
    rng = np.random.default_rng(4)
    n = len(rows)
    hours = np.arange(n) * 60.0 / 3600.0  # a pose a minute
    rotation = Rotation.from_rotvec(np.outer(hours * 20e-6, [0.0, 0.0, 1.0]))
    shift = np.outer(hours * 50e-6, [0.6, 0.8, 0.0])
    truth = np.array([r[6:] for r in rows])
    fixed = np.array([[2.0, 0.5, -0.8], [2.2, -0.6, -0.8], [1.8, 0.0, -0.2]])
    read = rotation.apply(truth) + shift
    refs = [
        rotation.apply(np.tile(p, (n, 1))) + shift + rng.normal(0, 12.5e-6, (n, 3)) for p in fixed
    ]
    table = [
        [*r[:6], *read[k], hours[k] * 3600.0, *(v for ref in refs for v in ref[k])]
        for k, r in enumerate(rows)
    ]
    names = ",".join(
        [
            *(f"q{j}" for j in range(1, 7)),
            "x",
            "y",
            "z",
            "t",
            *(f"{c}{i}" for i in range(3) for c in "uvw"),
        ]
    )
    csv = _csv(tmp_path / "refs.csv", table, names)
    out = tmp_path / "refs.mcap"
    references = (
        "--reference",
        "a:u0,v0,w0",
        "--reference",
        "b:u1,v1,w1",
        "--reference",
        "c:u2,v2,w2",
    )
    run = cli("import", str(csv), *COLUMNS, "--time", "t", *references, "-o", str(out))
    assert run.returncode == 0, run.stderr
    drifted = float(np.linalg.norm(read - truth, axis=1).max())
    assert drifted > 50e-6
    recording = read_recording([out], load_robot("kr5_sixx_r650"))
    # the drift gone but for its estimate's own noise (60 reads of references 12.5 um apiece)
    left = float(np.linalg.norm(recording.points - truth, axis=1).max())
    assert left < 25e-6 and left < 0.25 * drifted, (left, drifted)
    found = re.search(r"the robot's\): ([0-9.]+) mm per axis", run.stdout)
    assert found, run.stdout
    noise = float(found.group(1))
    assert noise == pytest.approx(0.0125, rel=0.2), run.stdout
    assert "rotation and translation" in run.stdout
    lines = csv.read_text().splitlines()  # reflector c out of sight at 10 poses: said
    for k in range(1, 11):
        cells = lines[k].split(",")
        lines[k] = ",".join(cells[:-3] + ["", "", ""])
    hidden = tmp_path / "hidden.csv"
    hidden.write_text("\n".join(lines) + "\n")
    run = cli(
        "import",
        str(hidden),
        *COLUMNS,
        "--time",
        "t",
        *references,
        "-o",
        str(tmp_path / "hidden.mcap"),
    )
    assert run.returncode == 0, run.stderr
    assert f"read together at {n - 10} of {n} poses" in run.stdout, run.stdout
    bad = cli("import", str(csv), *COLUMNS, "--reference", "a:u0,v0", "-o", str(out) + "x")
    assert bad.returncode == 2 and "--reference a:u0,v0: expected NAME:X,Y,Z" in bad.stderr


def test_stated_accuracy_per_point_weighs_the_fit(
    sim: tuple[Path, list[list[float]]], tmp_path: Path
) -> None:
    """A Leica export's uncertainty column: each point measured at its own accuracy, 1-60
    um per axis (a third of them at 40-60 um). Imported with `--sigma` the fit weighs each
    point by it and comes out closer to the points' true places than the same file read
    without it (where a 60 um point counts as much as a 1 um one)."""
    from robot_calib.bag.read import read_recording
    from robot_calib.identify.calibrate import calibrate
    from robot_calib.kinematics.loader import load_robot

    _, rows = sim
    robot = load_robot("kr5_sixx_r650")
    rng = np.random.default_rng(7)
    sigma = np.where(
        rng.random(len(rows)) < 1 / 3,
        rng.uniform(40e-6, 60e-6, len(rows)),
        rng.uniform(1e-6, 5e-6, len(rows)),
    )
    truth = np.array([r[6:] for r in rows])
    noisy = truth + rng.normal(0.0, 1.0, truth.shape) * sigma[:, None]
    table = [[*r[:6], *noisy[k], sigma[k] * 1e6] for k, r in enumerate(rows)]
    csv = _csv(tmp_path / "leica.csv", table, "q1,q2,q3,q4,q5,q6,x,y,z,u")
    errors = {}
    for name, extra in (("weighted", ("--sigma", "u", "--sigma-unit", "um")), ("plain", ())):
        out = tmp_path / f"{name}.mcap"
        run = cli("import", str(csv), *COLUMNS, *extra, "-o", str(out))
        assert run.returncode == 0, run.stderr
        recording = read_recording([out], robot)
        cal = calibrate(recording, robot, "geometric", log=None, screen_outliers=False)
        errors[name] = float(np.sqrt(np.mean((cal.predict(recording.poses) - truth) ** 2)))
    assert errors["weighted"] < 0.7 * errors["plain"], errors
