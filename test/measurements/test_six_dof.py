"""6-DoF measurements (msgs_doc/six_dof.md): a tracker's 6-DoF probe measures the
probe frame's orientation besides its point; bags carry it on /laser_tracker/(NAME/)pose
(PoseStamped, or PoseWithCovarianceStamped with the stated accuracies); the fit weights
every residual by the stated accuracies and identifies the whole tool frame (offset and
orientation in the flange frame). Known answers: a simulated KR5 with a probe.
"""

from __future__ import annotations

import csv
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli
from rosbags.highlevel import AnyReader
from scipy.spatial.transform import Rotation
from six_dof_world import (
    ORIENTATION_SIGMA,
    PROBE_RPY_DEG,
    ROBOT,
    WORLD,
    as_recording,
    measured,
)

from robot_calib.bag.mcap_writer import BagWriter
from robot_calib.bag.read import read_recording
from robot_calib.bag.ros2_formats import typestore
from robot_calib.bag.write import write_measurement_bag
from robot_calib.errors import BagError
from robot_calib.identify.calibrate import calibrate
from robot_calib.measurements import recording_from_arrays
from robot_calib.messages import JOINT_STATE_TYPE, POINT_TYPE, POSE_TYPE
from robot_calib.model import absorb_base_offsets, target_parameters, tool_rotation_parameters
from robot_calib.poses import Poses
from robot_calib.sim.world import build_world


def test_the_whole_tool_frame_is_identified_through_a_bag(tmp_path: Path) -> None:
    poses, points = measured()
    sigma = np.tile([10e-6, ORIENTATION_SIGMA], (len(poses), 1))
    bag = tmp_path / "six_dof.mcap"
    write_measurement_bag(
        bag, poses.q, points, ROBOT.joint_names, poses.time, six_dof={"": (poses.rotation, sigma)}
    )
    recording = read_recording([bag], ROBOT)
    assert recording.oriented_targets == ("",)
    assert recording.poses.rotation is not None
    np.testing.assert_allclose(recording.poses.rotation, poses.rotation, atol=1e-12)
    np.testing.assert_allclose(recording.poses.sigma, sigma)
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    cal = calibrate(recording, ROBOT, "geometric")
    names = target_parameters("") + tool_rotation_parameters("")
    for name in names:
        k = cal.parameters.index(name)
        assert cal.parameters.free[k], name
        error = abs(cal.parameters[name] - truth[name])
        assert error < 4 * cal.std[k] + 1e-9, (name, error, cal.std[k])
    # the probe's frame to a few urad, its offset to a micrometre
    rotation = [cal.parameters[n] - truth[n] for n in tool_rotation_parameters("")]
    assert max(abs(v) for v in rotation) < 2e-5
    assert cal.orientation_residuals is not None
    rms = np.sqrt(np.mean(cal.orientation_residuals**2))
    assert 0.8 * ORIENTATION_SIGMA < rms < 1.2 * ORIENTATION_SIGMA  # the simulated noise
    assert cal.accuracy.absolute_rms_mm < 0.012  # points: ~9 um rms of noise
    assert not cal.warnings
    # the nominal rung (tracker pose and tool frame only) starts from the closed form
    nominal = calibrate(recording, ROBOT, "nominal")
    assert abs(nominal.parameters["target_ry"] - truth["target_ry"]) < 0.01


def test_residuals_are_weighted_by_the_stated_accuracies() -> None:
    """Half the points 20x noisier, and said so: the weighted fit explains the accurate
    half to its noise; the same data without stated accuracies cannot."""
    poses, points = measured(n=200, seed=5)
    rng = np.random.default_rng(9)
    noisy = np.arange(len(points)) % 2 == 1
    points = points.copy()
    points[noisy] += rng.normal(0.0, 200e-6, (int(noisy.sum()), 3))
    sigma = np.column_stack([np.where(noisy, 200e-6, 10e-6), np.full(len(points), np.nan)])
    exact = WORLD.model.target_points(WORLD.truth, poses)
    errors = {}
    for stated in (sigma, None):
        recording = as_recording(replace(poses, rotation=None), points, stated)
        cal = calibrate(recording, ROBOT, "geometric", screen_outliers=False)
        predicted = cal.predict(recording.poses)
        errors[stated is None] = np.sqrt(np.mean((predicted - exact)[~noisy] ** 2)) * 1e3
    assert errors[False] < 0.5 * errors[True], errors  # weighted: model error halves at least


def test_orientation_makes_the_tool_frame_identifiable_where_points_cannot() -> None:
    """With points alone the probe's orientation is not a parameter at all; with 6-DoF
    measurements it is free and determined, and the geometry is no worse."""
    poses, points = measured()
    six = calibrate(as_recording(poses, points), ROBOT, "geometric")
    three = calibrate(as_recording(replace(poses, rotation=None), points), ROBOT, "geometric")
    assert "target_rx" not in three.parameters
    assert six.parameters.free.sum() == three.parameters.free.sum() + 3
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    for name in ("a2", "a3", "d4", "alpha3"):
        k6, k3 = six.parameters.index(name), three.parameters.index(name)
        assert abs(six.parameters[name] - truth[name]) < 4 * six.std[k6] + 1e-9
        assert six.std[k6] <= 1.05 * three.std[k3], name


def write_poses(tmp_path: Path, poses: Poses, points: np.ndarray, name: str = "a") -> Path:
    bag = tmp_path / f"{name}.mcap"
    write_measurement_bag(
        bag,
        poses.q,
        points,
        ROBOT.joint_names,
        poses.time,
        six_dof={"": (poses.rotation, np.full((len(poses), 2), np.nan))},
    )
    return bag


def test_a_pose_topic_is_readable_by_rosbags_and_read_back(tmp_path: Path) -> None:
    poses, points = measured(n=20)
    bag = write_poses(tmp_path, poses, points)
    with AnyReader([bag]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        assert topics["/laser_tracker/pose"] == "geometry_msgs/msg/PoseStamped"
        connection = next(c for c in reader.connections if c.topic == "/laser_tracker/pose")
        first = next(reader.messages(connections=[connection]))
        msg = reader.deserialize(first[2], connection.msgtype)
        assert msg.pose.position.x == pytest.approx(points[0, 0], abs=1e-12)
        assert msg.header.frame_id == "laser_tracker"
    recording = read_recording([bag], ROBOT)
    assert recording.poses.oriented.all() and recording.poses.sigma is None


def write_raw(
    path: Path, q: np.ndarray, points: np.ndarray | None, poses: np.ndarray, quats: np.ndarray
) -> Path:
    """A bag written message by message: joint states, points (None: no point topic) and
    PoseStamped of positions `poses` (n, 3) and quaternions `quats` (n, 4) x, y, z, w."""
    store = typestore(JOINT_STATE_TYPE, POINT_TYPE, POSE_TYPE)
    t = store.types
    with BagWriter(path) as writer:
        writer.add_topic("/joint_states", JOINT_STATE_TYPE)
        writer.add_topic("/laser_tracker/pose", POSE_TYPE)
        if points is not None:
            writer.add_topic("/laser_tracker/point", POINT_TYPE)
        for k in range(len(q)):
            ns = 1_700_000_000_000_000_000 + k * 1_000_000_000
            stamp = t["builtin_interfaces/msg/Time"](ns // 10**9, ns % 10**9)
            header = t["std_msgs/msg/Header"](stamp=stamp, frame_id="laser_tracker")
            js = t[JOINT_STATE_TYPE](
                header=header,
                name=list(ROBOT.joint_names),
                position=q[k],
                velocity=np.empty(0),
                effort=np.empty(0),
            )
            writer.write("/joint_states", store.serialize_cdr(js, JOINT_STATE_TYPE), ns)
            if points is not None:
                pt = t[POINT_TYPE](header=header, point=t["geometry_msgs/msg/Point"](*points[k]))
                writer.write("/laser_tracker/point", store.serialize_cdr(pt, POINT_TYPE), ns + 1)
            pose = t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](*poses[k]),
                orientation=t["geometry_msgs/msg/Quaternion"](*quats[k]),
            )
            msg = t[POSE_TYPE](header=header, pose=pose)
            writer.write("/laser_tracker/pose", store.serialize_cdr(msg, POSE_TYPE), ns + 1)
        writer.close()
    return path


def test_a_bag_of_poses_alone_reads_and_bad_poses_are_one_line_errors(tmp_path: Path) -> None:
    poses, points = measured(n=20)
    quats = Rotation.from_matrix(poses.rotation).as_quat()
    alone = read_recording(
        [write_raw(tmp_path / "alone.mcap", poses.q, None, points, quats)], ROBOT
    )
    np.testing.assert_allclose(alone.points, points, atol=1e-12)
    assert alone.poses.oriented.all()
    moved = points.copy()
    moved[4] += 1e-3
    bag = write_raw(tmp_path / "moved.mcap", poses.q, points, moved, quats)
    with pytest.raises(BagError, match=r"moved.mcap: /laser_tracker/pose at stamp .* but"):
        read_recording([bag], ROBOT)
    scaled = quats.copy()
    scaled[7] *= 2.0
    bag = write_raw(tmp_path / "scaled.mcap", poses.q, points, points, scaled)
    with pytest.raises(BagError, match=r"scaled.mcap: /laser_tracker/pose message 8: .* norm 2"):
        read_recording([bag], ROBOT)


def test_split_calibrate_and_score_keep_the_orientations(tmp_path: Path) -> None:
    """The verbs on a 6-DoF bag: `split` keeps every pose's orientation and stated
    accuracy, `calibrate` prints the orientation residual, `score` the held-out one, and
    its per-point table has the rotation columns."""
    poses, points = measured(n=120, seed=11)
    sigma = np.tile([5e-6, ORIENTATION_SIGMA], (len(poses), 1))
    bag = tmp_path / "probe.mcap"
    write_measurement_bag(
        bag, poses.q, points, ROBOT.joint_names, poses.time, six_dof={"": (poses.rotation, sigma)}
    )
    assert cli("split", str(bag), "--holdout", "0.3", "--seed", "2").returncode == 0
    parts = [read_recording([tmp_path / f"probe.{p}.mcap"], ROBOT) for p in ("cal", "holdout")]
    assert sum(len(p) for p in parts) == len(poses)
    for part in parts:
        assert part.poses.oriented.all() and part.poses.sigma is not None
        np.testing.assert_allclose(part.poses.sigma, sigma[: len(part)])
    params = tmp_path / "p.json"
    proc = cli("calibrate", str(tmp_path / "probe.cal.mcap"), "-o", str(params))
    assert proc.returncode == 0, proc.stderr
    assert "residuals (in-sample): orientation error angle mean" in proc.stdout
    doc = json.loads(params.read_text())
    assert doc["targets"][0]["six_dof"] is True
    assert doc["orientation_residuals"]["n_measurements"] == len(parts[0])
    table = tmp_path / "points.csv"
    proc = cli(
        "score", str(params), str(tmp_path / "probe.holdout.mcap"), "--points-csv", str(table)
    )
    assert proc.returncode == 0, proc.stderr
    line = next(x for x in proc.stdout.splitlines() if "orientation error angle" in x)
    rms_urad = float(line.split("per axis rms ")[1].split(" ")[0])
    assert 0.8 * ORIENTATION_SIGMA * 1e6 < rms_urad < 1.3 * ORIENTATION_SIGMA * 1e6
    with table.open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(parts[1]) and float(rows[0]["angle_rad"]) > 0
    # predict gives the probe frame as a quaternion beside the point
    joints = tmp_path / "joints.csv"
    q_cal = parts[1].poses.q
    np.savetxt(
        joints, q_cal, delimiter=",", comments="", header=",".join(f"q{j + 1}" for j in range(6))
    )
    out = tmp_path / "points_out.csv"
    proc = cli("predict", str(params), "--joints", str(joints), "-o", str(out))
    assert proc.returncode == 0 and "qx,qy,qz,qw" in proc.stdout, proc.stderr
    predicted = np.loadtxt(out, delimiter=",", skiprows=1)
    truth = WORLD.model.probe_orientations(WORLD.truth, Poses.from_readings(q_cal))
    turn = Rotation.from_quat(predicted[:, 3:]) * Rotation.from_matrix(truth).inv()
    assert np.abs(turn.magnitude()).max() < 1e-4  # the calibrated frame within 100 urad


def test_a_probe_with_a_further_target_keeps_its_frame_to_itself() -> None:
    """What the further targets add is judged on the rows the fit sees: the probe's
    orientation rows identify its frame, so the frame is not credited to the SMR."""
    world = build_world(
        {"seed": 3, "six_dof": {"first": PROBE_RPY_DEG}, "targets": {"smr2": [0.0, 0.08, 0.04]}}
    )
    poses, points = measured(world, n=80)
    recording = recording_from_arrays(
        poses.q,
        points,
        poses.time,
        robot=ROBOT,
        target=poses.target,
        target_names=world.model.targets,
        rotation=poses.rotation,
    )
    cal = calibrate(recording, ROBOT, "geometric")
    assert cal.model.oriented == ("",)
    assert not set(tool_rotation_parameters("")) & set(cal.by_extra_targets)
    truth = absorb_base_offsets(ROBOT, world.truth)
    for name in tool_rotation_parameters("") + target_parameters("smr2"):
        k = cal.parameters.index(name)
        assert abs(cal.parameters[name] - truth[name]) < 4 * cal.std[k] + 1e-9, name


def test_diagnose_takes_6dof_measurements() -> None:
    """The ladder's screening model keeps the probe (its frame's parameters): diagnose runs
    on 6-DoF data and, on a world without effects, finds none."""
    from robot_calib.diagnosis.diagnosis import diagnose

    poses, points = measured(n=120, seed=21)
    held_poses, held_points = measured(n=60, seed=22)
    diagnosis, ladder = diagnose(
        as_recording(poses, points),
        ROBOT,
        as_recording(held_poses, held_points),
        tracker_sigma_m=4.8e-6,
    )
    assert ladder.rungs[0].calibration.model.oriented == ("",)
    assert diagnosis.dominant_effect is None


def test_orientation_columns_mixed_up_are_flagged_and_the_points_calibrate_alone() -> None:
    """Quaternions read in the wrong order (w taken for x) are still unit quaternions, but
    no probe frame explains them: the calibration says so, names the likely cause and
    calibrates from the points alone (positions at the noise, no probe parameters)."""
    poses, points = measured()
    quat = Rotation.from_matrix(poses.rotation).as_quat()  # x, y, z, w
    wrong = Rotation.from_quat(np.roll(quat, 1, axis=1)).as_matrix()  # w, x, y, z as x..w
    stated = np.tile([5e-6, ORIENTATION_SIGMA], (len(poses), 1))
    cal = calibrate(
        as_recording(replace(poses, rotation=wrong), points, stated), ROBOT, "geometric"
    )
    warning = next(w for w in cal.warnings if "orientations disagree" in w)
    assert "quaternion order" in warning and "points alone" in warning
    assert cal.model.oriented == () and "target_rx" not in cal.parameters
    assert cal.accuracy.absolute_rms_mm < 0.012


def test_orientation_blunders_are_left_out_their_points_kept() -> None:
    """Three orientations 5 deg off (a probe knocked, a line of sight to a wrong LED): they
    are flagged and left out, their points still fitted, and the probe frame comes out as
    without them."""
    poses, points = measured()
    rotation = poses.rotation.copy()
    for k, axis in ((10, [1.0, 0, 0]), (60, [0, 1.0, 0]), (120, [0, 0, 1.0])):
        rotation[k] = (
            Rotation.from_rotvec(np.radians(5.0) * np.array(axis)).as_matrix() @ rotation[k]
        )
    stated = np.tile([5e-6, ORIENTATION_SIGMA], (len(poses), 1))
    cal = calibrate(
        as_recording(replace(poses, rotation=rotation), points, stated), ROBOT, "geometric"
    )
    warning = next(w for w in cal.warnings if "6-DoF orientation(s)" in w)
    assert warning.startswith("warning: outliers: 3 6-DoF orientation(s)")
    assert cal.orientation_residuals is not None
    assert np.isnan(cal.orientation_residuals[[10, 60, 120]]).all()
    assert len(cal.residuals) == len(points)  # every point kept
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    frame = [cal.parameters[n] - truth[n] for n in tool_rotation_parameters("")]
    assert max(abs(v) for v in frame) < 2e-5


def test_stated_accuracies_far_from_the_residuals_are_flagged() -> None:
    """An orientation accuracy stated 10 x too good (5 urad for 50 urad of noise): the fit
    weights by it, and says that the residual is 10 x the stated figure."""
    poses, points = measured()
    stated = np.tile([5e-6, ORIENTATION_SIGMA / 10], (len(poses), 1))
    cal = calibrate(as_recording(poses, points, stated), ROBOT, "geometric")
    warning = next(w for w in cal.warnings if "orientation residual" in w)
    assert "x the stated accuracy (5 urad)" in warning
    assert not any("position residual" in w for w in cal.warnings)


def test_a_probe_pitched_90_deg_has_no_gimbal_lock() -> None:
    """The probe frame is a rotation vector: at pitch 89.99 deg from the flange (where
    roll and yaw would turn about one axis) every component stays free and the frame comes
    out to the noise."""
    world = build_world({"seed": 4, "six_dof": {"first": [10.0, 89.99, -40.0]}})
    poses, points = measured(world)
    cal = calibrate(as_recording(poses, points), ROBOT, "geometric")
    truth = absorb_base_offsets(ROBOT, world.truth)
    for name in tool_rotation_parameters(""):
        k = cal.parameters.index(name)
        assert cal.parameters.free[k] and cal.std[k] < 2e-5, name
    tool = cal.model.tool_rotations(cal.parameters)[0]
    true_tool = world.model.tool_rotations(truth)[0]
    assert Rotation.from_matrix(tool @ true_tool.T).magnitude() < 2e-5
