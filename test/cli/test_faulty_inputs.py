"""Faulty inputs, files and interruptions through the real command line.

Every case is one line of CASES: an input maker (writes files into the case's folder),
the command (run there by the command line's main() in the test process, cli_runner.cli,
or as `python -m robot_calib ...` in a process of its own where it has a file-size limit or
a signal; {sample} is the sample bag, {params} a PARAMS.json calibrated once per session),
the expected exit status, a message
fragment (for failures: in the one line on stderr that starts with 'robot-calib'; for
successes: anywhere in the output), files that must not exist afterwards and files that
must not change. The table's lines are long on purpose (one case, one line: noqa E501).
No case may leave a staging folder or temporary file behind.

Extra columns: `fsize` runs the command with that many bytes as its file-size limit
(RLIMIT_FSIZE, SIGXFSZ ignored: writes fail as on a full disk); `interrupt` sends that
signal once the simulation reports progress; `present` lists files that must exist.

The cases run in one module fixture (the processes two at a time, their simulations one at
a time; the in-process cases one after another meanwhile); each case is then its own test.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import signal
import subprocess
import sys
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_runner import cli

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "bags" / "paper_test3.mcap"
KR5 = ROOT / "robot_calib" / "kinematics" / "robots" / "kr5_sixx_r650.yaml"
JOINTS = "q1,q2,q3,q4,q5,q6"
IMPORT = f"import in.csv --joints {JOINTS} --point x,y,z"
WRAPPED = (  # robot_calib with a file-size limit of argv[1] bytes (0: none), as on a full
    # disk, and Ctrl-C handled even when the test runs where SIGINT is ignored (a background job)
    "import resource, runpy, signal, sys; n = int(sys.argv.pop(1)); "
    "n and resource.setrlimit(resource.RLIMIT_FSIZE, (n, n)); "
    "signal.signal(signal.SIGXFSZ, signal.SIG_IGN); "
    "signal.signal(signal.SIGINT, signal.default_int_handler); "
    "runpy.run_module('robot_calib', run_name='__main__', alter_sys=True)"
)


# --- shared inputs -------------------------------------------------------------------------


@cache
def sample_measurements() -> tuple[np.ndarray, np.ndarray]:
    """Readings (n, 6) [rad] and points (n, 3) [m] of the sample bag."""
    from robot_calib.bag.read import read_recording
    from robot_calib.kinematics.loader import load_robot

    rec = read_recording([SAMPLE], load_robot("kr5_sixx_r650"))
    return rec.poses.q, rec.points


@cache
def calibrated_params(folder: Path) -> Path:
    """One PARAMS.json of the sample bag per session."""
    from robot_calib.flows.calibrate import calibrate_bags
    from robot_calib.identify.params_file import write_json_atomic
    from robot_calib.kinematics.loader import load_robot

    robot = load_robot("kr5_sixx_r650")
    cal, rec = calibrate_bags([SAMPLE], robot)
    path = folder / "params.json"
    write_json_atomic(cal.to_dict(rec), path)
    return path


def write_bag(
    path: Path, js: list[tuple[int, np.ndarray]], points: list[tuple[int, np.ndarray]]
) -> None:
    """A contract bag of joint states (stamp [ns], q [rad]) and points (stamp, p [m])."""
    from geometry_msgs.msg import PointStamped
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from robot_calib.bag import BagWriter

    def stamp(msg, ns: int) -> None:  # noqa: ANN001 - any stamped message
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(ns), 1_000_000_000)

    names = [f"joint_a{j}" for j in range(1, 7)]
    with BagWriter(path, ros_distro="jazzy") as writer:
        writer.add_topic("/joint_states", "sensor_msgs/msg/JointState")
        writer.add_topic("/laser_tracker/point", "geometry_msgs/msg/PointStamped")
        for ns, q in js:
            msg = JointState(name=names, position=[float(v) for v in q])
            stamp(msg, ns)
            writer.write("/joint_states", serialize_message(msg), ns)
        for ns, p in points:
            pt = PointStamped()
            pt.header.frame_id = "laser_tracker"
            pt.point.x, pt.point.y, pt.point.z = (float(v) for v in p)
            stamp(pt, ns)
            writer.write("/laser_tracker/point", serialize_message(pt), ns + 1000)


T0, STEP = 1_700_000_000_000_000_000, 1_000_000_000


def bag_with(duplicate: str) -> Callable[[Path], None]:
    """The sample's measurements as in.mcap plus one duplicate at pose 10: a joint state
    with other readings ('js-different'), the same one ('js-same'), or a point ('point')."""

    def make(folder: Path) -> None:
        q, points = sample_measurements()
        js = [(T0 + i * STEP, qi) for i, qi in enumerate(q)]
        pts = [(T0 + i * STEP, p) for i, p in enumerate(points)]
        if duplicate == "js-different":
            js.insert(11, (js[10][0], js[10][1] + [0, 0.01, 0, 0, 0, 0]))
        elif duplicate == "js-same":
            js.insert(11, js[10])
        else:
            pts.insert(11, (pts[10][0], pts[10][1] + 1e-6))
        write_bag(folder / "in.mcap", js, pts)

    return make


def many_poses(folder: Path) -> None:
    """big.mcap: 1300 random poses (more than `--objective seed` may take)."""
    from robot_calib.bag.write import write_measurement_bag

    rng = np.random.default_rng(0)
    q = rng.uniform(-1.0, 1.0, (1300, 6)) + [0, -1.5, 1.5, 0, 0, 0]
    points = rng.uniform(-0.5, 0.5, (1300, 3)) + [2.0, 1.0, 0.0]
    write_measurement_bag(
        folder / "big.mcap", q, points, tuple(f"joint_a{j}" for j in range(1, 7))
    )


def csv(
    rows: int = 20,
    sep: str = ",",
    angle: float = 1.0,
    length: float = 1.0,
    cell: tuple[int, int, str] | None = None,
    header: bool = True,
) -> Callable[[Path], None]:
    """in.csv: q1..q6,x,y,z of the sample's first `rows` poses, angles x `angle`, points x
    `length`, numbers written with `sep` and (sep ';') a decimal comma; `cell` (row, column,
    text) replaces one cell."""

    def make(folder: Path) -> None:
        q, points = sample_measurements()
        table = np.hstack([q[:rows] * angle, points[:rows] * length])
        lines = [[repr(float(v)) for v in row] for row in table]
        if sep == ";":
            lines = [[v.replace(".", ",") for v in row] for row in lines]
        if cell is not None:
            lines[cell[0]][cell[1]] = cell[2]
        text = [sep.join([*JOINTS.split(","), "x", "y", "z"])] if header else []
        (folder / "in.csv").write_text("\n".join(text + [sep.join(r) for r in lines]) + "\n")

    return make


def mixed_units(folder: Path) -> None:
    """in.csv in rad and m, but row 3 in degrees and row 5 in mm."""
    csv()(folder)
    q, points = sample_measurements()
    lines = (folder / "in.csv").read_text().splitlines()
    lines[3] = ",".join(repr(float(v)) for v in [*np.degrees(q[2]), *points[2]])
    lines[5] = ",".join(repr(float(v)) for v in [*q[4], *(points[4] * 1e3)])
    (folder / "in.csv").write_text("\n".join(lines) + "\n")


def sample_bag(change: str) -> Callable[[Path], None]:
    """in.mcap: the sample's measurements with a change: 'blunders' (points 40, 150, 250
    moved 5 mm), 'blunder-1m' (point 150 moved 1 m), 'swapped' (joint 2 and 3 readings
    swapped), 'repeats' (3 poses measured 10 times each), 'copy' (the sample, unchanged:
    a copy under another name)."""

    def make(folder: Path) -> None:
        if change == "copy":
            (folder / "in.mcap").write_bytes(SAMPLE.read_bytes())
            return
        q, points = sample_measurements()
        q, points = q.copy(), points.copy()
        if change == "blunders":
            points[[40, 150, 250]] += [0.0, 0.0, 5e-3]
        elif change == "blunder-1m":
            points[150] += [1.0, 0.0, 0.0]
        elif change == "swapped":
            q[:, [1, 2]] = q[:, [2, 1]]
        elif change == "repeats":
            q, points = (
                np.repeat(q[[0, 100, 200]], 10, axis=0),
                np.repeat(points[[0, 100, 200]], 10, axis=0),
            )
        js = [(T0 + i * STEP, qi) for i, qi in enumerate(q)]
        write_bag(folder / "in.mcap", js, [(T0 + i * STEP, p) for i, p in enumerate(points)])

    return make


def text(name: str, content: str) -> Callable[[Path], None]:
    def make(folder: Path) -> None:
        (folder / name).write_text(content)

    return make


def both(*makers: Callable[[Path], None]) -> Callable[[Path], None]:
    def make(folder: Path) -> None:
        for maker in makers:
            maker(folder)

    return make


def robot_yaml(change: str) -> Callable[[Path], None]:
    """r.yaml: the KR5 with its joint 2 named like joint 1 ('duplicate') or without its
    last joint ('five')."""

    def make(folder: Path) -> None:
        data = yaml.safe_load(KR5.read_text())
        if change == "duplicate":
            data["joints"][1]["name"] = data["joints"][0]["name"]
        else:
            data["joints"] = data["joints"][:5]
            data["name"] = "kr5_five"
        (folder / "r.yaml").write_text(yaml.safe_dump(data))

    return make


def params_with(key: str, value: object) -> Callable[[Path], None]:
    """p.json: the session's PARAMS.json with parameter a2's `key` set to `value`."""

    def make(folder: Path) -> None:
        doc = json.loads(calibrated_params(folder.parent / "shared").read_text())
        record = next(r for r in doc["parameters"] if r["name"] == "a2")
        record[key] = value
        (folder / "p.json").write_text(json.dumps(doc))

    return make


def readonly_folder(folder: Path) -> None:
    (folder / "ro").mkdir()
    (folder / "ro").chmod(0o555)


J6 = "q1,q2,q3,q4,q5,q6\n0,-1.5,1.5,0,0.7,0\n"
WORLD = "w.yaml"
SIM = f"simulate --plan paper-test1 --world {WORLD} -o s.mcap"
NEVER = ("s.mcap", "s.world.yaml")


@dataclass(frozen=True)
class Case:
    name: str
    make: Callable[[Path], None] | None
    command: str
    status: int
    message: str
    absent: tuple[str, ...] = ()
    unchanged: tuple[str, ...] = ()
    present: tuple[str, ...] = ()
    fsize: int | None = None
    interrupt: int | None = None


# fmt: off
CASES = [
    # --- pairing -----------------------------------------------------------------------------
    Case("joint states: same stamp, other readings", bag_with("js-different"), "calibrate in.mcap -o p.json", 2, "states 11 and 12 have the same stamp 1700000010000000000 ns but different", ("p.json",), ("in.mcap",)),  # noqa: E501
    Case("joint states: identical duplicate", bag_with("js-same"), "calibrate in.mcap -o p.json", 0, "290 measurements", present=("p.json",)),  # noqa: E501
    Case("points: shared stamp", bag_with("point"), "calibrate in.mcap -o p.json", 0, "warning: in.mcap: 1 tracker points share their stamp"),  # noqa: E501
    Case("--pair-tolerance nan", None, "calibrate {sample} --pair-tolerance nan -o p.json", 2, "--pair-tolerance: nan s: need a finite number >= 0", ("p.json",)),  # noqa: E501
    Case("--pair-tolerance negative", None, "diagnose {sample} --pair-tolerance -0.1 -o d.json", 2, "-0.1 s: need a finite number >= 0", ("d.json",)),  # noqa: E501
    # --- CSV import ----------------------------------------------------------------------------
    Case("csv: '1,5' cell shifts a row", csv(cell=(4, 6, "1,5")), IMPORT + " -o out.mcap", 0, "in.csv:6: 10 fields, the header has 9: row skipped", present=("out.mcap",)),  # noqa: E501
    Case("csv: --decimal-comma on dot decimals", csv(), IMPORT + " --decimal-comma -o out.mcap", 2, "in.csv:2: --decimal-comma, but the numbers have a decimal point", ("out.mcap",)),  # noqa: E501
    Case("csv: decimal comma without the option", csv(sep=";"), IMPORT + " --sep ; -o out.mcap", 2, "has a decimal comma; add --decimal-comma", ("out.mcap",)),  # noqa: E501
    Case("csv: degrees read as rad", csv(angle=180 / np.pi), IMPORT + " -o out.mcap", 2, "the angles look like degrees; give --angle-unit deg", ("out.mcap",)),  # noqa: E501
    Case("csv: millimetres read as m", csv(length=1e3), IMPORT + " -o out.mcap", 2, "x/y/z are 2.24e+03 m from the tracker read as m: they look like millimetres", ("out.mcap",)),  # noqa: E501
    Case("csv: metres read as mm", csv(), IMPORT + " --length-unit mm -o out.mcap", 2, "they look like metres; give --length-unit m", ("out.mcap",)),  # noqa: E501
    Case("csv: radians read as deg", csv(), IMPORT + " --angle-unit deg -o out.mcap", 0, "they look like radians"),  # noqa: E501
    Case("csv: rows in mixed units", mixed_units, IMPORT + " -o out.mcap", 0, "in.csv:4: joint column", present=("out.mcap",)),  # noqa: E501
    Case("csv: row in mm among m", mixed_units, IMPORT + " -o out.mcap", 0, "in.csv:6: point x/y/z 2.65e+03 m from the tracker looks like millimetres"),  # noqa: E501
    Case("csv: empty file", text("in.csv", ""), IMPORT + " -o out.mcap", 2, "in.csv: the file is empty", ("out.mcap",)),  # noqa: E501
    Case("csv: header only", text("in.csv", "q1,q2,q3,q4,q5,q6,x,y,z\n"), IMPORT + " -o out.mcap", 2, "no rows after the header", ("out.mcap",)),  # noqa: E501
    # --- predict -----------------------------------------------------------------------------
    Case("predict: extra q7 column", text("j.csv", "q1,q2,q3,q4,q5,q6,q7\n0,-1.5,1.5,0,0.7,0,0\n"), "predict {params} --joints j.csv -o out.csv", 2, "columns ['q7'] beyond the robot's 6 joints", ("out.csv",)),  # noqa: E501
    Case("predict: q3 twice", text("j.csv", "q1,q2,q3,q3,q4,q5,q6\n0,-1.5,1.5,1.5,0,0.7,0\n"), "predict {params} --joints j.csv -o out.csv", 2, "columns ['q3'] given more than once", ("out.csv",)),  # noqa: E501
    Case("predict: NaN in PARAMS.json", both(params_with("value", float("nan")), text("j.csv", J6)), "predict p.json --joints j.csv -o out.csv", 2, "p.json: parameter a2 value nan is not finite", ("out.csv",)),  # noqa: E501
    Case("predict: mm in PARAMS.json", both(params_with("unit", "mm"), text("j.csv", J6)), "predict p.json --joints j.csv -o out.csv", 2, "p.json: parameter a2 has unit 'mm', expected 'm'", ("out.csv",)),  # noqa: E501
    # --- files: inputs, the overwrite policy, folders, full disk --------------------------------
    Case("import -o its CSV, even --force", csv(), IMPORT + " --force -o in.csv", 2, "in.csv: is an input of this command", unchanged=("in.csv",)),  # noqa: E501
    Case("import over an existing bag", both(csv(), text("out.mcap", "old")), IMPORT + " -o out.mcap", 2, "out.mcap: exists; will not overwrite it (use --force)", unchanged=("out.mcap",)),  # noqa: E501
    Case("import --force replaces it", both(csv(), text("out.mcap", "old")), IMPORT + " --force -o out.mcap", 0, "out.mcap: /joint_states=20"),  # noqa: E501
    Case("import -o a folder", both(csv(), lambda f: (f / "out").mkdir()), IMPORT + " -o out", 2, "out: is a folder"),  # noqa: E501
    Case("calibrate over an existing file", text("p.json", "old"), "calibrate {sample} -o p.json", 2, "p.json: exists; will not overwrite it (use --force)", unchanged=("p.json",)),  # noqa: E501
    Case("calibrate --force replaces it", text("p.json", "old"), "calibrate {sample} --force -o p.json", 0, "p.json: geometric"),  # noqa: E501
    Case("calibrate into a read-only folder", readonly_folder, "calibrate {sample} -o ro/p.json", 2, "ro: folder not writable", ("ro/p.json",)),  # noqa: E501
    Case("predict over an existing file", text("j.csv", J6), "predict {params} --joints j.csv -o j.csv", 2, "j.csv: is an input of this command", unchanged=("j.csv",)),  # noqa: E501
    Case("predict over another file", both(text("j.csv", J6), text("out.csv", "old")), "predict {params} --joints j.csv -o out.csv", 2, "out.csv: exists; will not overwrite", unchanged=("out.csv",)),  # noqa: E501
    Case("diagnose -o d.md", None, "diagnose {sample} -o d.md", 2, "-o d.md: names DIAGNOSIS.json", ("d.md", "d.json")),  # noqa: E501
    Case("diagnose over an existing report", text("d.md", "old"), "diagnose {sample} -o d.json", 2, "d.md: exists; will not overwrite it (use --force)", ("d.json",), ("d.md",)),  # noqa: E501
    Case("diagnose: JSON and report apart", None, "diagnose {sample} -o d.json", 0, "d.json, d.md in", present=("d.json", "d.md", "d_ladder.png")),  # noqa: E501
    Case("simulate over an existing bag", text("s.mcap", "old"), "simulate -o s.mcap", 2, "s.mcap: exists; will not overwrite it (use --force)", ("s.world.yaml",), ("s.mcap",)),  # noqa: E501
    Case("simulate --force replaces bag and world", both(text("s.mcap", "old"), text("s.world.yaml", "old")), "simulate --plan paper-test1 --force -o s.mcap", 0, "truth in s.world.yaml", present=("s.mcap", "s.world.yaml")),  # noqa: E501
    Case("full disk: import", csv(rows=290), IMPORT + " -o out.mcap", 2, "File too large", ("out.mcap",), fsize=16_384),  # noqa: E501
    Case("full disk: calibrate", None, "calibrate {sample} -o p.json", 2, "p.json: cannot write: File too large", ("p.json",), fsize=4_096),  # noqa: E501
    Case("full disk: simulate", None, "simulate --plan paper-test1 -o s.mcap", 2, "File too large", ("s.mcap", "s.world.yaml"), fsize=16_384),  # noqa: E501
    Case("Ctrl-C in simulate", None, "simulate --plan random --n-random 20000 -o s.mcap", 130, "robot-calib simulate: interrupted", ("s.mcap", "s.world.yaml"), interrupt=signal.SIGINT),  # noqa: E501
    Case("SIGTERM in simulate", None, "simulate --plan random --n-random 20000 -o s.mcap", 130, "robot-calib simulate: interrupted", ("s.mcap", "s.world.yaml"), interrupt=signal.SIGTERM),  # noqa: E501
    # --- outliers, plausibility, too little data ----------------------------------------------
    Case("calibrate: 3 blunders of 5 mm", sample_bag("blunders"), "calibrate in.mcap -o p.json", 0, "in.mcap point 150, stamp 1700000150.000 s: 5.0", present=("p.json",)),  # noqa: E501
    Case("calibrate: a blunder of 1 m", sample_bag("blunder-1m"), "calibrate in.mcap -o p.json", 0, "in.mcap point 150, stamp 1700000150.000 s: 1000.0", present=("p.json",)),  # noqa: E501
    Case("diagnose: blunders are no robot effect", sample_bag("blunders"), "diagnose in.mcap -o d.json", 0, "dominant effect: null", present=("d.json", "d.md")),  # noqa: E501
    Case("calibrate as the wrong robot", sample_bag("copy"), "calibrate in.mcap --robot ur10 --joint-names " + ",".join(f"joint_a{j}" for j in range(1, 7)) + " -o p.json", 3, "robot-calib calibrate: fitted, implausible: geometric parameters beyond physics (ur10; more than 500 mm or 30 deg from nominal): a2 +", present=("p.json",)),  # noqa: E501
    Case("bag joint names not the robot's", sample_bag("copy"), "calibrate in.mcap --robot ur10 -o p.json", 2, "in.mcap: /joint_states: JointState names ['joint_a1', 'joint_a2', 'joint_a3', 'joint_a4', 'joint_a5', 'joint_a6'] are not the robot's joints ['shoulder_pan_joint', 'shoulder_lift_joint', 'elbow_joint', 'wrist_1_joint', 'wrist_2_joint', 'wrist_3_joint']; they are the joints of built-in robots kr16_2, kr210_r2700_extra, kr5_sixx_r650, kr6_r900_sixx: give --robot kr16_2 (or another of them), or map them with --joint-names NAME1,...,NAME6", ("p.json",)),  # noqa: E501
    Case("--joint-names: too few", sample_bag("copy"), "calibrate in.mcap --joint-names a,b,c -o p.json", 2, "joint names a,b,c: 3 names for robot kr5_sixx_r650 with 6 joints", ("p.json",)),  # noqa: E501
    Case("--joint-names: repeated", sample_bag("copy"), "diagnose in.mcap --joint-names a,b,c,d,e,a -o d.json", 2, "joint names a,b,c,d,e,a: names must be distinct; ['a'] repeated", ("d.json",)),  # noqa: E501
    Case("calibrate: joints 2 and 3 swapped", sample_bag("swapped"), "calibrate in.mcap -o p.json", 0, "readings outside its limits", present=("p.json",)),  # noqa: E501
    Case("calibrate: 3 poses measured 10 times", sample_bag("repeats"), "calibrate in.mcap -o p.json", 2, "3 distinct poses (9 residuals) cannot determine 27 free parameters: at least 10 distinct poses are needed", ("p.json",)),  # noqa: E501
    Case("a copy of a bag as hold-out", sample_bag("copy"), "diagnose {sample} --holdout in.mcap -o d.json", 2, "the same measurements twice (a copy?)", ("d.json",)),  # noqa: E501
    # --- other cases -------------------------------------------------------------------------
    Case("one bag twice", None, "calibrate {sample} {sample} -o p.json", 2, "paper_test3.mcap: the same bag given twice", ("p.json",)),  # noqa: E501
    Case("calibration bag as hold-out", None, "diagnose {sample} --holdout {sample} -o d.json", 2, "the same bag given as calibration and as hold-out bag", ("d.json",)),  # noqa: E501
    Case("--objective seed beyond memory", many_poses, "calibrate big.mcap --objective seed -o p.json", 2, "seed on 1300 points needs 2.1 GiB for its pairwise rows (limit 2 GiB: at most 1257", ("p.json",)),  # noqa: E501
    Case("robot YAML: duplicate joint names", robot_yaml("duplicate"), "calibrate {sample} --robot r.yaml -o p.json", 2, "joint names must be distinct; ['joint_a1']", ("p.json",)),  # noqa: E501
    Case("5-joint robot on a 6-joint bag", robot_yaml("five"), "calibrate {sample} --robot r.yaml -o p.json", 2, "has joints ['joint_a6'] that robot kr5_five (5 joints", ("p.json",)),  # noqa: E501
    Case("world robot differs from --robot", text(WORLD, "robot: ur5\ngeometry: nominal\n"), SIM + " --robot kr5_sixx_r650", 2, "w.yaml: world robot ur5 differs from --robot kr5_sixx_r650", NEVER),  # noqa: E501
    Case("world: negative noise", text(WORLD, "noise: {tracker_sigma_m: -1.0e-6}\n"), SIM, 2, "w.yaml: noise.tracker_sigma_m: expected a finite number >= 0, got -1e-06", NEVER),  # noqa: E501
    Case("world: noise not a number", text(WORLD, "noise: {target_sigma_m: abc}\n"), SIM, 2, "noise.target_sigma_m: expected a number, got 'abc'", NEVER),  # noqa: E501
    Case("world: seed abc", text(WORLD, "seed: abc\n"), SIM, 2, "w.yaml: seed: expected an integer >= 0, got 'abc'", NEVER),  # noqa: E501
    Case("world: 5 joint speeds", text(WORLD, "timing: {max_joint_speed_deg_s: [1, 2, 3, 4, 5]}\n"), SIM, 2, "timing.max_joint_speed_deg_s: expected one speed per joint (6)", NEVER),  # noqa: E501
    Case("world: a zero joint speed", text(WORLD, "timing: {max_joint_speed_deg_s: [375, 0, 375, 410, 410, 660]}\n"), SIM, 2, "every speed must be finite and > 0", NEVER),  # noqa: E501
    Case("world: dropout 1", text(WORLD, "tracker: {dropout_probability: 1.0}\n"), SIM, 2, "tracker.dropout_probability 1.0: must be in [0, 1)", NEVER),  # noqa: E501
    Case("world: dropout -0.5", text(WORLD, "tracker: {dropout_probability: -0.5}\n"), SIM, 2, "tracker.dropout_probability: expected a finite number >= 0", NEVER),  # noqa: E501
    Case("simulation records no point", text(WORLD, "tracker: {dropout_probability: 0.999999}\n"), f"simulate --world {WORLD} --plan random --n-random 2 -o s.mcap", 2, "s.mcap: the simulation recorded no tracker point", ("s.mcap", "s.world.yaml")),  # noqa: E501
]
# fmt: on


@dataclass
class Outcome:
    status: int
    stdout: str
    stderr: str
    changed: list[str]
    skipped: str = ""


def _needs_a_process(case: Case) -> bool:
    """A file-size limit or a signal: the case runs as a process of its own; the others run
    the command's main() in the test process (cli_runner.cli), one at a time."""
    return case.fsize is not None or case.interrupt is not None


def _run(case: Case, folder: Path, shared: Path) -> Outcome:
    folder.mkdir()
    if case.make is not None:
        case.make(folder)
    if case.name == "calibrate into a read-only folder" and os.access(folder / "ro", os.W_OK):
        return Outcome(0, "", "", [], "running as root: a read-only folder stays writable")
    kept = {name: (folder / name).read_bytes() for name in case.unchanged}
    args = shlex.split(
        case.command.format(sample=SAMPLE, params=calibrated_params(shared)), posix=True
    )
    if case.fsize is not None or case.interrupt is not None:
        command = [sys.executable, "-c", WRAPPED, str(case.fsize or 0), *args]
    else:
        command = [sys.executable, "-m", "robot_calib", *args]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    if not _needs_a_process(case):  # the command's main() here: no Python start-up
        proc = cli(*args, cwd=folder)
        out, err, status = proc.stdout, proc.stderr, proc.returncode
    elif case.interrupt is None:
        proc = subprocess.run(
            command, cwd=folder, capture_output=True, text=True, check=False, env=env, timeout=120
        )
        out, err, status = proc.stdout, proc.stderr, proc.returncode
    else:
        with subprocess.Popen(
            command, cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
        ) as live:
            assert live.stderr is not None
            seen = []
            for line in live.stderr:  # wait until the simulation runs
                seen.append(line)
                if re.search(r"random: \d+/20000 poses", line):
                    break
            live.send_signal(case.interrupt)
            out, rest = live.communicate(timeout=60)
            err, status = "".join(seen) + rest, live.returncode
    changed = [
        n for n, b in kept.items() if not (folder / n).exists() or (folder / n).read_bytes() != b
    ]
    return Outcome(status, out, err, changed)


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Outcome, Path]]:
    """Every case run once: the cases that need a process of their own (limits, signals) in
    a pool, their simulations one after another, the rest meanwhile in this thread, one
    after another (main() is not thread-safe: it redirects this process's output)."""
    base = tmp_path_factory.mktemp("reliability")
    shared = base / "shared"
    shared.mkdir()
    calibrated_params(shared)
    sample_measurements()
    folders = {case.name: base / f"case{k}" for k, case in enumerate(CASES)}
    processes = [c for c in CASES if _needs_a_process(c)]
    ros = [c for c in processes if c.command.startswith("simulate")]
    others = [c for c in processes if c not in ros]

    def serial() -> dict[str, Outcome]:
        return {c.name: _run(c, folders[c.name], shared) for c in ros}

    with ThreadPoolExecutor(2) as pool:
        sims = pool.submit(serial)
        rest = {c.name: pool.submit(_run, c, folders[c.name], shared) for c in others}
        here = {c.name: _run(c, folders[c.name], shared) for c in CASES if c not in processes}
        results = here | {name: f.result() for name, f in rest.items()} | sims.result()
    return {name: (outcome, folders[name]) for name, outcome in results.items()}


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_case(case: Case, outcomes: dict[str, tuple[Outcome, Path]]) -> None:
    outcome, folder = outcomes[case.name]
    if outcome.skipped:
        pytest.skip(outcome.skipped)
    said = [line for line in outcome.stderr.splitlines() if line.startswith("robot-calib")]
    assert outcome.status == case.status, outcome.stderr
    assert "Traceback" not in outcome.stderr and "Exception ignored" not in outcome.stderr
    if case.status == 0:
        assert case.message in outcome.stdout + outcome.stderr, outcome.stdout + outcome.stderr
    else:
        assert len(said) == 1 and case.message in said[0], outcome.stderr
    assert not [n for n in case.absent if (folder / n).exists()], sorted(os.listdir(folder))
    assert not outcome.changed
    assert all((folder / n).exists() for n in case.present), sorted(os.listdir(folder))
    leftovers = [p.name for p in folder.rglob(".*")]
    assert not leftovers, leftovers  # no staging folder, no temporary file


def test_the_overwrite_policy_is_in_every_help() -> None:
    from robot_calib.cli import OVERWRITE_POLICY, build_parser

    parser = build_parser()
    verbs = parser._subparsers._group_actions[0].choices  # noqa: SLF001 - argparse internals
    for verb in ("simulate", "calibrate", "diagnose", "predict", "import"):
        text = " ".join(verbs[verb].format_help().split())
        assert "--force" in text and " ".join(OVERWRITE_POLICY.split()) in text, verb


def test_every_option_of_every_verb_states_its_default_or_that_it_is_required() -> None:
    import argparse

    from robot_calib.cli import build_parser

    parser = build_parser()
    verbs = parser._subparsers._group_actions[0].choices  # noqa: SLF001 - argparse internals
    silent = []
    for verb, sub in verbs.items():
        text = sub.format_help()
        for action in sub._actions:  # noqa: SLF001 - argparse internals
            if not action.option_strings or isinstance(
                action,
                argparse._HelpAction | argparse._StoreTrueAction,  # noqa: SLF001
            ):
                continue
            shown = " ".join((sub._get_formatter()._expand_help(action) or "").split())  # noqa: SLF001
            assert shown.split(" (")[0] in " ".join(text.split()), (verb, action.dest)
            said = (
                "default" in shown
                or "required" in shown
                or (action.default is not None and f"({action.default}" in shown)
            )
            if not said:
                silent.append(f"{verb} {action.option_strings[-1]}")
    assert not silent, silent
