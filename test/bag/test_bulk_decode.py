"""Bags read in bulk (`BagReader.channel_messages` + `bulk_decode`) give what message-by-
message decoding gives, bit for bit: every committed bag, bags of every writer (the CSV
import, the stream writer, the ROS graph's recorder) with every contract topic, and bags
whose messages do not share a layout (the fallback), with the same errors for bad input."""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from robot_calib.bag import BagReader, BagWriter
from robot_calib.bag import read as bag_read
from robot_calib.bag.bulk_decode import decode_columns
from robot_calib.bag.ros2_formats import typestore
from robot_calib.bag.write import (
    write_measurement_bag,
    write_stream_bag,
)
from robot_calib.errors import BagError
from robot_calib.kinematics.loader import load_robot
from robot_calib.messages import (
    JOINT_STATE_TYPE,
    JOINT_STATES_TOPIC,
    POINT_TOPIC,
    POINT_TYPE,
    TEMPERATURE_TOPIC,
    TEMPERATURE_TYPE,
)
from robot_calib.sim.world import build_world, load_world, save_world

REPO = Path(__file__).resolve().parents[2]
UR10 = load_robot("ur10")
N = 40


def robot_of(bag: Path) -> Any:
    """The robot of a simulated bag (its world file beside it)."""
    return load_world(bag.with_name(bag.name.replace(".mcap", ".world.yaml"))).model.robot


def committed_bags() -> list[Path]:
    files = subprocess.run(
        ["git", "ls-files", "*.mcap"], cwd=REPO, capture_output=True, text=True, check=True
    ).stdout.split()
    return [REPO / f for f in files]


def same(a: Any, b: Any) -> bool:
    """Exact equality: arrays of the same dtype, shape and values (NaN equal to NaN),
    containers element by element, scalars of the same type."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (
            isinstance(a, np.ndarray)
            and isinstance(b, np.ndarray)
            and a.dtype == b.dtype
            and a.shape == b.shape
            and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
        )
    if isinstance(a, dict):
        return isinstance(b, dict) and list(a) == list(b) and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and (a == b or (a != a and b != b))


def used_bulk(path: Path, robot: Any) -> bool:
    """Whether `_bag_messages` reads the bag in bulk (no fallback)."""
    try:
        reader = BagReader(path)
    except BagError:
        return False
    with reader:
        points, poses, names = bag_read._target_topics(reader, path, [])
        side = [TEMPERATURE_TOPIC] if TEMPERATURE_TOPIC in reader.topics else []
        return bag_read._read_bulk(reader, robot, points, poses, side, len(names)) is not None


def assert_same_reading(path: Path, robot: Any, bulk: bool) -> None:
    """Both ways give the same result (or the same BagError); `bulk`: the fast way is taken."""
    results = []
    for fast in (True, False):
        try:
            results.append(bag_read._bag_messages(path, robot, bulk=fast))
        except BagError as exc:
            results.append(str(exc))
    assert same(results[0], results[1]), path
    assert used_bulk(path, robot) == bulk


@pytest.mark.parametrize("path", committed_bags(), ids=lambda p: p.name)
def test_every_committed_bag_reads_the_same_in_bulk(path: Path) -> None:
    assert_same_reading(path, robot_of(path), bulk=True)


@pytest.fixture(scope="module")
def poses() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(7)
    q = rng.uniform(-2, 2, (N, 6))
    points = rng.uniform(-1, 1, (N, 3))
    rotation = np.array([np.eye(3)] * N)
    angle = rng.uniform(-1, 1, N)
    rotation[:, 0, 0] = rotation[:, 1, 1] = np.cos(angle)
    rotation[:, 0, 1], rotation[:, 1, 0] = -np.sin(angle), np.sin(angle)
    return {"q": q, "points": points, "rotation": rotation, "time": np.arange(N) * 0.5}


@pytest.mark.parametrize("compression", ["none", "zstd", "lz4"])
def test_contract_bags_of_every_kind_read_the_same_in_bulk(
    tmp_path: Path, poses: dict[str, np.ndarray], compression: str, monkeypatch: Any
) -> None:
    """JointState with and without velocities, further targets (one with gaps), 6-DoF
    PoseStamped and PoseWithCovarianceStamped, Temperature; chunks compressed or not."""
    import robot_calib.bag.write as bag_write

    real = bag_write.BagWriter
    monkeypatch.setattr(  # small chunks: messages of a topic spread over many of them
        bag_write, "BagWriter", lambda p: real(p, chunk_size=2000, compression=compression)
    )
    q, points, rotation = poses["q"], poses["points"], poses["rotation"]
    extra = points + 0.1
    extra[::3] = np.nan
    sigma = np.full((N, 2), np.nan)
    stated = np.tile([2e-5, 1e-4], (N, 1))
    names = UR10.joint_names
    cases: dict[str, dict[str, Any]] = {
        "plain": {},
        "directions": {"direction": np.sign(q - 0.1)},
        "temperature": {"temperature": 20 + np.arange(N) * 0.1},
        "targets": {"extra_points": {"smr2": extra, "smr3": points - 0.1}},
        "pose": {"six_dof": {"": (rotation, sigma)}},
        "pose_targets": {"extra_points": {"smr2": points}, "six_dof": {"smr2": (rotation, sigma)}},
        "pose_covariance": {"six_dof": {"": (rotation, stated)}},
    }
    for name, kwargs in cases.items():
        bag = tmp_path / f"{name}.mcap"
        write_measurement_bag(bag, q, points, names, poses["time"], **kwargs)
        assert_same_reading(bag, UR10, bulk=True)
    stream = tmp_path / "stream.mcap"
    js_ns = np.arange(N, dtype=np.int64) * 5_000_000
    write_stream_bag(stream, js_ns, q, q * 0.1, js_ns[::2] + 1000, points[::2], names)
    assert_same_reading(stream, UR10, bulk=True)


def hand_written_bag(
    path: Path,
    joint_states: list[bytes],
    points: list[bytes],
    temperatures: list[bytes] = (),  # type: ignore[assignment]
) -> Path:
    with BagWriter(path, chunk_size=1500) as writer:
        writer.add_topic(JOINT_STATES_TOPIC, JOINT_STATE_TYPE)
        writer.add_topic(POINT_TOPIC, POINT_TYPE)
        if temperatures:
            writer.add_topic(TEMPERATURE_TOPIC, TEMPERATURE_TYPE)
        t = 1_700_000_000_000_000_000
        for k, (js, pt) in enumerate(zip(joint_states, points)):
            writer.write(JOINT_STATES_TOPIC, js, t + k * 1000)
            writer.write(POINT_TOPIC, pt, t + k * 1000 + 1)
            if k < len(temperatures):
                writer.write(TEMPERATURE_TOPIC, temperatures[k], t + k * 1000 + 2)
    return path


def test_layouts_not_shared_or_not_walked_fall_back_to_the_same_result(
    tmp_path: Path, poses: dict[str, np.ndarray]
) -> None:
    store = typestore(JOINT_STATE_TYPE, POINT_TYPE, TEMPERATURE_TYPE)
    types = store.types
    q, pts = poses["q"], poses["points"]
    names = UR10.joint_names
    t0 = 1_700_000_000_000_000_000
    stamps = [t0 + k * 10_000_000 for k in range(N)]

    def js(
        k: int, order: tuple[str, ...] = names, velocity: bool = False, le: bool = True
    ) -> bytes:
        at = [names.index(n) for n in order]
        stamp = types["builtin_interfaces/msg/Time"](*divmod(stamps[k], 1_000_000_000))
        msg = types[JOINT_STATE_TYPE](
            header=types["std_msgs/msg/Header"](stamp=stamp, frame_id="base"),
            name=list(order),
            position=q[k][at],
            velocity=np.ones(6) if velocity else np.empty(0),
            effort=np.zeros(6),
        )
        return bytes(store.serialize_cdr(msg, JOINT_STATE_TYPE, little_endian=le))

    def pt(k: int, le: bool = True, value: np.ndarray | None = None) -> bytes:
        stamp = types["builtin_interfaces/msg/Time"](*divmod(stamps[k], 1_000_000_000))
        msg = types[POINT_TYPE](
            header=types["std_msgs/msg/Header"](stamp=stamp, frame_id="laser_tracker"),
            point=types["geometry_msgs/msg/Point"](*(pts[k] if value is None else value)),
        )
        return bytes(store.serialize_cdr(msg, POINT_TYPE, little_endian=le))

    def temp(k: int) -> bytes:
        stamp = types["builtin_interfaces/msg/Time"](*divmod(stamps[k], 1_000_000_000))
        msg = types[TEMPERATURE_TYPE](
            header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=""),
            temperature=20.0 + k,
            variance=0.5,
        )
        return bytes(store.serialize_cdr(msg, TEMPERATURE_TYPE))

    shuffled = tuple(reversed(names))
    big = hand_written_bag(
        tmp_path / "big_endian.mcap",
        [js(k, le=False) for k in range(N)],
        [pt(k, le=False) for k in range(N)],
        [temp(k) for k in range(N)],
    )
    assert_same_reading(big, UR10, bulk=True)  # big-endian CDR: the same views, '>' dtypes
    reordered = hand_written_bag(
        tmp_path / "reordered.mcap",
        [js(k, shuffled, True) for k in range(N)],
        [pt(k) for k in range(N)],
    )
    assert_same_reading(reordered, UR10, bulk=True)
    mixed = hand_written_bag(
        tmp_path / "mixed.mcap",
        [js(k, names if k % 2 else shuffled) for k in range(N)],
        [pt(k) for k in range(N)],
    )
    assert_same_reading(mixed, UR10, bulk=False)  # same size, other names: fallback
    sometimes = hand_written_bag(
        tmp_path / "velocity_sometimes.mcap",
        [js(k, velocity=k > 3) for k in range(N)],
        [pt(k) for k in range(N)],
    )
    assert_same_reading(sometimes, UR10, bulk=False)  # sizes differ: fallback
    # errors: the message-by-message reading's, whatever the bulk reading saw first
    bad = np.array([np.nan, 0, 0])
    nan = hand_written_bag(
        tmp_path / "nan.mcap",
        [js(k) for k in range(N)],
        [pt(k, value=bad if k == 9 else None) for k in range(N)],
    )
    assert_same_reading(nan, UR10, bulk=False)
    with pytest.raises(BagError, match="message 10 is not finite"):
        bag_read._bag_messages(nan, UR10)
    assert_same_reading(nan, load_robot("ur5"), bulk=False)  # other joint names: the error


def test_corrupt_chunks_give_the_message_by_message_error(tmp_path: Path) -> None:
    """A flipped byte inside a chunk (CRC), and a file cut inside its summary: the bulk
    reader gives up and the error is the one mcap's stream reader raises."""
    bags = committed_bags()
    source = bags[0].read_bytes()
    robot = robot_of(bags[0])
    for name, data in {
        "flipped": source[:2000] + bytes([source[2000] ^ 0xFF]) + source[2001:],
        "cut": source[: len(source) // 2] + source[-8:],
    }.items():
        bad = tmp_path / f"{name}.mcap"
        bad.write_bytes(data)
        assert_same_reading(bad, robot, bulk=False)


def test_columns_are_the_decoded_fields(tmp_path: Path, poses: dict[str, np.ndarray]) -> None:
    """Every numeric field of every message equals mcap_ros2's decoding of it."""
    bag = tmp_path / "all.mcap"
    write_measurement_bag(
        bag,
        poses["q"],
        poses["points"],
        UR10.joint_names,
        poses["time"],
        direction=np.sign(poses["q"]),
        temperature=np.arange(N) + 20.0,
    )
    with BagReader(bag) as reader:
        table = reader.channel_messages(reader.topics)
        assert table is not None
        for channel in table.values():
            columns = decode_columns(channel)
            assert columns is not None and len(columns) == len(channel) == N
            for i in range(N):
                msg = channel.decode(channel.data(i))
                for name, values in columns.fields.items():
                    value = msg
                    for part in name.split("."):
                        value = getattr(value, part)
                    assert np.array_equal(values[i], np.asarray(value, dtype=values.dtype))


@pytest.fixture(scope="module")
def graph_bags(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Bags of the ROS graph's recorder (sim_robot -> sim_tracker -> recorder, as
    `robot-calib simulate` runs it): /clock besides the contract's topics; a 6-DoF probe
    with stated (PoseWithCovarianceStamped) and unstated (PoseStamped) accuracy, a
    further target, the side topic's temperature."""
    from robot_calib.nodes.simulate import simulate_bag

    folder = tmp_path_factory.mktemp("graph_bags")
    worlds = {
        "covariance": {
            "seed": 3,
            "six_dof": {"first": [10, 20, 30]},
            "targets": {"smr2": [-0.04, 0.05, 0.03]},
            "noise": {"orientation_sigma_rad": 1e-4},
        },
        "poses": {
            "seed": 4,
            "six_dof": {"first": [10, 20, 30], "smr2": [0, 0, 90]},
            "targets": {"smr2": [-0.04, 0.05, 0.03]},
        },
        "temperature": {"seed": 5, "temperature": {}},
    }
    bags = []
    for name, spec in worlds.items():
        world = folder / f"{name}.world.yaml"
        save_world(build_world(spec), world)
        bag = folder / f"{name}.mcap"
        simulate_bag(bag, "random", world, n_random=12)
        bags.append(bag)
    return bags


def test_bags_of_the_ros_graph_read_the_same_in_bulk(graph_bags: list[Path]) -> None:
    for bag in graph_bags:
        assert_same_reading(bag, robot_of(bag), bulk=True)
