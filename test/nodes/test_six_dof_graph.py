"""6-DoF probes and further targets through the ROS graph (msgs_doc/six_dof.md,
msgs_doc/sim_tracker.md, msgs_doc/calibrator.md): sim_tracker publishes each probe's frame
as a PoseWithCovarianceStamped beside its point, the recorder keeps it (and a further
target's points), and the bag identifies the probe's frame in the flange; the live
calibrator, fed the same messages by real publishers, finds the same parameters.

Real rclpy and Fast DDS on this process's private ROS_DOMAIN_ID (conftest.py). Known
answers: a simulated KR5 with a probe at roll/pitch/yaw 20/35/-30 deg, 50 urad noise.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from scipy.spatial.transform import Rotation

from robot_calib.bag import BagReader
from robot_calib.bag.read import read_recording
from robot_calib.errors import InputError
from robot_calib.identify.calibrate import calibrate
from robot_calib.measurements import Recording
from robot_calib.messages import JOINT_STATES_TOPIC, POINT_TOPIC, POSE_COV_TYPE, POSE_TOPIC
from robot_calib.model import absorb_base_offsets, tool_rotation_parameters
from robot_calib.nodes.calibrator import CalibratorNode
from robot_calib.nodes.replay import ReplayNode
from robot_calib.nodes.simulate import simulate_bag
from robot_calib.sim.measure import stated_accuracy, tracker_noise
from robot_calib.sim.world import NoiseModel, World, build_world, save_world

PROBE_RPY_DEG = [20.0, 35.0, -30.0]
ORIENTATION_SIGMA = 50e-6  # rad per axis: the world's default, stated here to be explicit
SMR2_TOPIC = "/laser_tracker/smr2/point"
N_POSES = 80  # random poses: enough for the geometry, the tracker pose and both tool frames
WORLD = build_world(
    {
        "seed": 3,
        "six_dof": {"first": PROBE_RPY_DEG},
        "targets": {"smr2": [-0.04, 0.05, 0.03]},
        "noise": {"orientation_sigma_rad": ORIENTATION_SIGMA},
    }
)
ROBOT = WORLD.model.robot
TIMEOUT_S = 20.0


@pytest.fixture(scope="module")
def six_dof_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The world simulated through sim_robot -> sim_tracker -> recorder (in-process, as
    `robot-calib simulate` runs it) over a random plan."""
    folder = tmp_path_factory.mktemp("six_dof_graph")
    world_file = folder / "probe.world.yaml"
    save_world(WORLD, world_file)
    bag = folder / "probe.mcap"
    counts = simulate_bag(bag, "random", world_file, n_random=N_POSES)
    # every topic got every pose: joint states, both targets' points, the probe's poses
    assert counts == {
        JOINT_STATES_TOPIC: N_POSES,
        POINT_TOPIC: N_POSES,
        SMR2_TOPIC: N_POSES,
        POSE_TOPIC: N_POSES,
    }
    return bag


def angle_errors(recording: Recording, world: World) -> np.ndarray:
    """Rotation vectors (n, 3) [rad] of measured * true^T of the oriented measurements, the
    truth at the readings (the robot's repeatability, 5 urad, is inside the noise)."""
    oriented = recording.poses.oriented
    assert recording.poses.rotation is not None
    true = world.model.probe_orientations(world.truth, recording.poses)[oriented]
    measured = recording.poses.rotation[oriented]
    return Rotation.from_matrix(measured @ np.swapaxes(true, 1, 2)).as_rotvec()


def test_simulated_bag_carries_every_probe_orientation_and_identifies_the_tool_frame(
    six_dof_bag: Path,
) -> None:
    with BagReader(six_dof_bag) as reader:
        assert reader.topics[POSE_TOPIC].type_name == POSE_COV_TYPE
    recording = read_recording([six_dof_bag], ROBOT)
    assert recording.target_names == ("", "smr2")
    assert recording.oriented_targets == ("",)
    first = recording.poses.target_index == 0
    assert len(recording) == 2 * N_POSES and recording.n_unpaired == 0
    # an orientation for every point of the probe, none for the plain SMR
    np.testing.assert_array_equal(recording.poses.oriented, first)
    # the stated accuracies are the world's noise: sqrt(3.75^2 + 3^2) um, 50 urad
    assert recording.poses.sigma is not None
    np.testing.assert_allclose(recording.poses.sigma[first, 0], np.hypot(3.75e-6, 3e-6))
    np.testing.assert_allclose(recording.poses.sigma[first, 1], ORIENTATION_SIGMA)
    assert np.isnan(recording.poses.sigma[~first]).all()

    errors = angle_errors(recording, WORLD)
    assert len(errors) == N_POSES
    assert np.linalg.norm(errors, axis=1).max() < 5 * ORIENTATION_SIGMA
    rms = np.sqrt(np.mean(errors**2))  # per axis
    assert 0.75 * ORIENTATION_SIGMA < rms < 1.25 * ORIENTATION_SIGMA

    cal = calibrate(recording, ROBOT, "geometric")
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    for name in tool_rotation_parameters(""):
        k = cal.parameters.index(name)
        assert cal.parameters.free[k], name
        error = abs(cal.parameters[name] - truth[name])
        assert error < 5e-5 and error < 5 * cal.std[k], (name, error, cal.std[k])
    assert "target_smr2_rx" not in cal.parameters  # a plain SMR has no frame
    assert cal.orientation_residuals is not None
    assert np.sqrt(np.nanmean(cal.orientation_residuals**2)) < 1.25 * ORIENTATION_SIGMA
    assert cal.accuracy.absolute_rms_mm < 0.012  # the points' noise, ~9 um rms
    assert not cal.warnings


def spin_until(executor: SingleThreadedExecutor, condition: Callable[[], bool]) -> None:
    deadline = time.monotonic() + TIMEOUT_S
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        executor.spin_once(timeout_sec=0.01)


def test_live_calibrator_with_a_further_target_and_poses_equals_the_bag(
    context: Context, six_dof_bag: Path
) -> None:
    """The bag's messages (raw CDR, as recorded) published again by a real replay node to a
    live calibrator taking smr2's points and the first target's poses: its recording is the
    bag's, its parameters are those the bag gives."""
    calibrator = CalibratorNode(
        context=context,
        parameter_overrides=[
            Parameter("targets", value=["smr2"]),
            Parameter("six_dof_targets", value=["first"]),
        ],
    )
    replay = ReplayNode(
        six_dof_bag, rate=0.0, autoplay=False, wait_for_subscribers=1, context=context
    )
    executor = SingleThreadedExecutor(context=context)
    for node in (calibrator, replay):
        executor.add_node(node)
    try:
        spin_until(executor, replay.ready)  # every topic matched: the pose topic discovered
        while replay.step() is not None:
            executor.spin_once(timeout_sec=0)
        expected = {
            JOINT_STATES_TOPIC: N_POSES,
            POINT_TOPIC: N_POSES,
            SMR2_TOPIC: N_POSES,
            POSE_TOPIC: N_POSES,
        }
        spin_until(executor, lambda: calibrator.received == expected)
        live = calibrator.solve()
    finally:
        executor.shutdown()
        for node in (replay, calibrator):
            node.destroy_node()
    assert live is not None, calibrator.error
    recording = calibrator.recording
    assert recording is not None
    assert recording.sources == (
        f"live {JOINT_STATES_TOPIC} + {POINT_TOPIC} + {SMR2_TOPIC} + {POSE_TOPIC}",
    )
    bag = read_recording([six_dof_bag], ROBOT)
    assert recording.target_names == bag.target_names
    for field in ("q", "direction", "time", "target", "rotation", "sigma"):
        np.testing.assert_array_equal(getattr(recording.poses, field), getattr(bag.poses, field))
    np.testing.assert_array_equal(recording.points, bag.points)

    offline = calibrate(bag, ROBOT, "geometric")
    assert live.parameters.names == offline.parameters.names
    assert "target_rx" in live.parameters and "target_smr2_x" in live.parameters
    np.testing.assert_allclose(live.parameters.values, offline.parameters.values, atol=1e-12)


@pytest.mark.parametrize(
    ("name", "values", "message"),
    [
        ("targets", ["2nd"], "parameter 'targets'"),
        ("targets", ["first"], "'first' in six_dof_targets only"),
        ("six_dof_targets", ["first", "first"], "distinct target names"),
    ],
)
def test_bad_live_target_names_are_refused(
    context: Context, name: str, values: list[str], message: str
) -> None:
    with pytest.raises(InputError, match=message):
        CalibratorNode(context=context, parameter_overrides=[Parameter(name, value=values)])


def test_stated_accuracy_is_the_simulated_tracker_noise() -> None:
    """The standard deviations sim_tracker states are those of the noise it adds: known
    answers, and the rms per coordinate of many draws of `tracker_noise`."""
    at = np.array([[2.0, 0.0, 0.0], [0.0, 3.0, 4.0]])  # 2 m and 5 m from the tracker
    iso = stated_accuracy(NoiseModel(), at)
    np.testing.assert_allclose(iso, [[4.8023e-6, 50e-6]] * 2, rtol=1e-4)
    aniso = NoiseModel(anisotropic=True, orientation_sigma_rad=0.0)
    stated = stated_accuracy(aniso, at)
    # sqrt(3^2 + (2.5^2 + 2 (2 urad * range)^2) / 3) um: range 2 m -> 4.6637 um, 5 m -> 8.8176
    np.testing.assert_allclose(stated[:, 0], [4.6637e-6, 8.8176e-6], rtol=1e-4)
    assert (stated[:, 1] == 0.0).all()  # no orientation noise: not stated (the 0 flag, exact)
    rng = np.random.default_rng(0)
    for k, p in enumerate(at):
        draws = tracker_noise(aniso, np.repeat(p[None], 20000, axis=0), rng)
        assert np.sqrt(np.mean(draws**2)) == pytest.approx(stated[k, 0], rel=0.02)
