"""Several targets (SMRs) on one flange, measured at the same poses
(msgs_doc/targets.md): each has its own offset, all share the tracker pose; bags carry them
on /laser_tracker/NAME/point beside the contract's /laser_tracker/point, `import` takes
their columns, CPA uses every target's circles and leans on the others where one target
sits on a joint's axis. Known answers: a simulated KR5 with three targets.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli

from robot_calib.bag.mcap_reader import BagReader
from robot_calib.bag.read import read_recording
from robot_calib.bag.write import write_measurement_bag
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.calibration import Calibration
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.model import absorb_base_offsets, target_parameters
from robot_calib.sim.measure import measure_every_target
from robot_calib.sim.plans import paper_test_plan, plan_times, random_plan
from robot_calib.sim.world import World, build_world

TARGETS = {"smr2": [0.0, 0.08, 0.04], "smr3": [-0.05, -0.05, 0.06]}
WORLD = build_world({"targets": TARGETS, "seed": 3})
ROBOT = WORLD.model.robot


def simulated(world: World, seed: int = 1, plan_name: str = "test2") -> Recording:
    """Every target of `world` at each pose of the seed's Test 2 (or `random`)."""
    plan = (
        paper_test_plan(2)
        if plan_name == "test2"
        else random_plan(ROBOT, 60, np.random.default_rng(seed))
    )
    poses, points = measure_every_target(
        world, plan.q, plan_times(plan, world.timing), np.random.default_rng(seed)
    )
    return recording_from_arrays(
        poses.q,
        points,
        poses.time,
        robot=ROBOT,
        target=poses.target,
        target_names=world.model.targets,
    )


def test_every_target_offset_and_the_shared_tracker_pose_come_out_exactly() -> None:
    recording = simulated(WORLD)
    assert recording.target_names == ("", "smr2", "smr3")
    # Sweeps are found per target: 6 joints x 3 targets, each within one target.
    assert len(recording.sweeps) == 18
    for s in recording.sweeps:
        assert len(set(recording.poses.target_index[s.index].tolist())) == 1
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    for model in ("cpa", "geometric"):
        cal = calibrate(recording, ROBOT, model)
        assert cal.accuracy.absolute_rms_mm < 0.012, model  # the simulated noise: ~9 um rms
        for name in ("", *TARGETS):
            for p in target_parameters(name):
                assert abs(cal.parameters[p] - truth[p]) < 5e-6, (model, p)
        for p in ("a2", "a3", "d4", "base2tracker_x", "base2tracker_yaw"):
            assert abs(cal.parameters[p] - truth[p]) < 1e-5, (model, p)
    assert not cal.warnings


def test_extra_targets_identify_what_one_target_cannot() -> None:
    """With eccentricity in the model, one target leaves each joint's axial runout
    (dz_c1/dz_s1) unidentifiable; three targets identify it: reported, not silent."""
    world = build_world({"targets": TARGETS, "effects": [{"name": "eccentricity", "order": 1}]})
    three = calibrate(simulated(world), ROBOT, "geometric+eccentricity")
    assert any(n.startswith("ecc") and "_dz_" in n for n in three.by_extra_targets)
    one = simulated(world).only_target("")
    single = calibrate(one, ROBOT, "geometric+eccentricity")
    assert single.by_extra_targets == ()
    assert single.parameters.free.sum() < three.parameters.free.sum() - 3 * 2  # offsets aside


@pytest.mark.slow
def test_a_target_on_the_last_axis_gives_way_to_the_others() -> None:
    """SMR smr2 on the joint-6 axis: its circle cannot fix the axis direction; CPA says so
    and leans on the other two targets, so the geometry stays exact."""
    world = build_world({"targets": {"smr2": [0.0, 0.0, 0.05], **{"smr3": TARGETS["smr3"]}}})
    recording = simulated(world)
    messages: list[str] = []
    cal = calibrate(recording, ROBOT, "cpa", log=messages.append)
    near = [m for m in messages if "too close" in m]
    assert near and all("/laser_tracker/smr2/point" in m for m in near)
    assert any("leans on the joint's 2 other circle(s)" in m for m in near)
    truth = absorb_base_offsets(ROBOT, world.truth)
    for p in ("alpha5", "a5", "d5", "target_smr2_x", "target_smr2_y", "target_smr2_z"):
        assert abs(cal.parameters[p] - truth[p]) < 2e-5, p
    # The on-axis target alone: the same warning, told to move the target.
    alone = recording.only_target("smr2")
    messages.clear()
    calibrate(alone, ROBOT, "cpa", log=messages.append)
    assert any("put a target farther off this axis" in m for m in messages)


def test_bag_round_trip_keeps_the_contract_topic_and_adds_one_per_target(tmp_path: Path) -> None:
    plan = paper_test_plan(3)
    rng = np.random.default_rng(2)
    poses, points = measure_every_target(WORLD, plan.q, plan_times(plan, WORLD.timing), rng)
    per_target = points.reshape(len(plan.q), 3, 3)
    extra = {name: per_target[:, k + 1] for k, name in enumerate(TARGETS)}
    extra["smr3"][5] = np.nan  # smr3 not measured at pose 6 (line of sight)
    bag = tmp_path / "three.mcap"
    counts = write_measurement_bag(
        bag,
        plan.q,
        per_target[:, 0],
        ROBOT.joint_names,
        plan_times(plan, WORLD.timing),
        extra_points=extra,
    )
    n = len(plan.q)
    assert counts == {
        "/joint_states": n,
        "/laser_tracker/point": n,
        "/laser_tracker/smr2/point": n,
        "/laser_tracker/smr3/point": n - 1,
    }
    with BagReader(bag) as reader:  # a single-target reader sees the contract's topic as ever
        assert reader.topics["/laser_tracker/point"].message_count == n
    recording = read_recording([bag], ROBOT)
    assert recording.target_names == ("", "smr2", "smr3") and len(recording) == 3 * n - 1
    first, by_target = recording.points_by_target()
    assert len(first) == n and np.isnan(by_target[2, 5]).all()
    np.testing.assert_allclose(by_target[1], extra["smr2"], atol=1e-12)
    # Repeat measurements of one pose compare the same target only; poses fold together.
    params = tmp_path / "p.json"
    proc = cli("calibrate", str(bag), "-o", str(params))
    assert proc.returncode == 0, proc.stderr
    assert "targets: 3 (/laser_tracker/point" in proc.stderr + proc.stdout
    doc = json.loads(params.read_text())
    assert [t["topic"] for t in doc["targets"]] == [
        "/laser_tracker/point",
        "/laser_tracker/smr2/point",
        "/laser_tracker/smr3/point",
    ]
    assert [t["measurements"] for t in doc["targets"]] == [n, n, n - 1]
    model, fitted = (loaded := Calibration.load(params)).model, loaded.parameters
    assert model.targets == ("", "smr2", "smr3")
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    assert abs(fitted["target_smr3_z"] - truth["target_smr3_z"]) < 1e-5
    # split keeps each pose's targets together; score uses every target.
    cal, hold = tmp_path / "cal.mcap", tmp_path / "hold.mcap"
    proc = cli(
        "split",
        str(bag),
        "--holdout",
        "0.3",
        "--calibration-out",
        str(cal),
        "--holdout-out",
        str(hold),
    )
    assert proc.returncode == 0, proc.stderr
    parts = [read_recording([p], ROBOT) for p in (cal, hold)]
    assert sum(len(p) for p in parts) == len(recording)
    assert all(p.target_names == ("", "smr2", "smr3") for p in parts)
    table = tmp_path / "points.csv"
    proc = cli("score", str(params), str(hold), "--points-csv", str(table))
    assert proc.returncode == 0, proc.stderr
    with table.open() as handle:
        rows = list(csv.DictReader(handle))
    assert {r["target"] for r in rows} == {
        "/laser_tracker/point",
        "/laser_tracker/smr2/point",
        "/laser_tracker/smr3/point",
    }
    assert max(float(r["error_m"]) for r in rows) < 5e-5


def test_import_takes_one_column_triple_per_target(tmp_path: Path) -> None:
    plan = random_plan(ROBOT, 40, np.random.default_rng(5))
    poses, points = measure_every_target(WORLD, plan.q, np.arange(40.0), np.random.default_rng(5))
    xyz = points.reshape(40, 3, 3) * 1e3  # mm
    path = tmp_path / "export.csv"
    lines = ["q1;q2;q3;q4;q5;q6;x;y;z;x2;y2;z2;x3;y3;z3"]
    for k in range(40):
        cells = [f"{v:.6f}" for v in np.degrees(plan.q[k])] + [f"{v:.5f}" for v in xyz[k].ravel()]
        if k == 7:
            cells[12:15] = ["", "", ""]  # the third SMR not seen at this pose
        lines.append(";".join(c.replace(".", ",") for c in cells))
    path.write_text("\n".join(lines) + "\n")
    bag = tmp_path / "imported.mcap"
    proc = cli(
        "import",
        str(path),
        "--sep",
        ";",
        "--decimal-comma",
        "--angle-unit",
        "deg",
        "--length-unit",
        "mm",
        "--joints",
        "q1,q2,q3,q4,q5,q6",
        "--point",
        "x,y,z",
        "--target",
        "smr2:x2,y2,z2",
        "--target",
        "smr3:x3,y3,z3",
        "-o",
        str(bag),
    )
    assert proc.returncode == 0, proc.stderr
    recording = read_recording([bag], ROBOT)
    assert recording.target_names == ("", "smr2", "smr3") and len(recording) == 119
    _, by_target = recording.points_by_target()
    np.testing.assert_allclose(by_target[1], xyz[:, 1] * 1e-3, atol=1e-8)
    # Half a target's cells empty, or a bad --target, is one clear line and exit 2.
    text = path.read_text().splitlines()
    cells = text[3].split(";")
    cells[13] = ""
    text[3] = ";".join(cells)
    broken = tmp_path / "broken.csv"
    broken.write_text("\n".join(text) + "\n")
    for args, message in [
        (
            (str(broken), "--target", "smr2:x2,y2,z2", "--target", "smr3:x3,y3,z3"),
            "some of its x, y, z cells empty",
        ),
        ((str(path), "--target", "2bad:x2,y2,z2"), "expected NAME:X,Y,Z"),
        ((str(path), "--target", "smr2:x2,y2"), "expected NAME:X,Y,Z"),
        ((str(path), "--target", "smr2:x2,y2,nope"), "no column 'nope'"),
    ]:
        proc = cli(
            "import",
            *args,
            "--sep",
            ";",
            "--decimal-comma",
            "--angle-unit",
            "deg",
            "--length-unit",
            "mm",
            "--joints",
            "q1,q2,q3,q4,q5,q6",
            "--point",
            "x,y,z",
            "-o",
            str(tmp_path / "x.mcap"),
        )
        assert proc.returncode == 2 and message in proc.stderr, proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr
        assert not (tmp_path / "x.mcap").exists()


@pytest.mark.parametrize("bad", ["7smr", "a-b"])
def test_world_target_names_are_topic_tokens(bad: str) -> None:
    with pytest.raises(Exception, match="ROS topic token"):
        build_world({"targets": {bad: [0.0, 0.0, 0.1]}})


def test_predict_takes_the_target_of_a_several_target_calibration(tmp_path: Path) -> None:
    recording = simulated(WORLD)
    cal = calibrate(recording, ROBOT, "geometric")
    params = tmp_path / "p.json"
    params.write_text(json.dumps(cal.to_dict(recording)))
    joints = tmp_path / "joints.csv"
    q = recording.poses.q[recording.poses.target_index == 0][:5]  # one row per pose
    joints.write_text(
        "q1,q2,q3,q4,q5,q6\n" + "\n".join(",".join(f"{v!r}" for v in r.tolist()) for r in q)
    )
    for name in ("", "smr3"):
        out = tmp_path / f"points{name}.csv"
        args = ("--target", name) if name else ()
        proc = cli("predict", str(params), "--joints", str(joints), "-o", str(out), *args)
        assert proc.returncode == 0, proc.stderr
        predicted = np.loadtxt(out, delimiter=",", skiprows=1)
        k = WORLD.model.targets.index(name)
        measured = recording.points[recording.poses.target_index == k][: len(q)]
        assert np.abs(predicted - measured).max() < 5e-5  # the noise, not another target
    proc = cli(
        "predict",
        str(params),
        "--joints",
        str(joints),
        "-o",
        str(tmp_path / "x.csv"),
        "--target",
        "smr9",
    )
    assert proc.returncode == 2 and "no target 'smr9'" in proc.stderr


def test_a_target_missing_from_the_last_joints_sweep_still_calibrates() -> None:
    """smr3 out of sight during the whole joint-6 sweep: its offset comes through the
    geometry of the others (with a warning), and the geometric fit is exact again."""
    recording = simulated(WORLD)
    j6 = np.concatenate([s.index for s in recording.sweeps_of(6)])
    hidden = np.zeros(len(recording), dtype=bool)
    hidden[j6] = recording.poses.target_index[j6] == 2
    part = recording.subset(~hidden)
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    messages: list[str] = []
    cpa = calibrate(part, ROBOT, "cpa", log=messages.append)
    assert any("smr3/point has no sweep of joint 6" in m for m in messages)
    assert abs(cpa.parameters["target_smr3_z"] - truth["target_smr3_z"]) < 1e-4
    geo = calibrate(part, ROBOT, "geometric")
    for p in target_parameters("smr3"):
        assert abs(geo.parameters[p] - truth[p]) < 5e-6, p


def test_a_pose_whose_targets_move_together_is_the_robot_not_the_tracker() -> None:
    """3 SMRs on the tool: at 3 poses all three sit 3 mm off the same way (the tool, so the
    robot, was elsewhere), at one the tool turned about its first SMR (that one not off), at
    2 others one SMR alone is off (a tracker blunder). Both are
    left out of the fit, but only the lone ones are called tracker blunders; every line
    names its target."""
    from dataclasses import replace

    from robot_calib.identify.outliers import ROBOT as ROBOT_ERROR
    from robot_calib.identify.outliers import outlier_counts
    from robot_calib.messages import target_topic

    recording = simulated(WORLD)
    pose = recording.pose_index()
    points = recording.points.copy()
    robot_poses, lone = (40, 200, 400), (100, 300)
    for p in robot_poses:
        points[pose == p] += [0.002, 0.002, -0.001]  # every target: a rigid shift
    blunders = [int(np.flatnonzero(pose == p)[1]) for p in lone]
    points[blunders] += [0.0, 0.003, 0.0]
    turned = np.flatnonzero(pose == 500)  # the tool turned about its first SMR (unflagged)
    pivot = points[turned[0]].copy()
    c, s = np.cos(0.03), np.sin(0.03)
    points[turned] = (points[turned] - pivot) @ np.array(
        [[c, s, 0], [-s, c, 0], [0, 0, 1]]
    ) + pivot
    robot_poses = (*robot_poses, 500)
    cal = calibrate(replace(recording, points=points), ROBOT, "geometric", log=None)
    kinds = {(int(pose[o.index]), o.target): o.kind for o in cal.outliers}
    assert {p for (p, _), k in kinds.items() if k == ROBOT_ERROR} == set(robot_poses), kinds
    assert {p for (p, _), k in kinds.items() if k == "tracker"} == set(lone), kinds
    assert len(kinds) == 3 * (len(robot_poses) - 1) + 2 + len(lone)
    assert {o.target for o in cal.outliers} <= {target_topic(t) for t in recording.target_names}
    assert "2 tracker blunder(s), 11 measurement(s) of poses where the robot was off" in (
        outlier_counts(cal.outliers)
    )
    robot_line = next(o.line() for o in cal.outliers if o.kind == ROBOT_ERROR)
    assert "(target " in robot_line and "moved as one rigid tool" in robot_line
    assert "a place where the model misses" in robot_line
