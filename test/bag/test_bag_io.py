"""MCAP bag writer/reader: real files in tmp_path, read back by our reader, by mcap/mcap_ros2
and by rosbags; the rosbag2 formats (schema text, QoS YAML, metadata record); bad files.

Messages are serialised with rclpy.serialization (no ROS graph needed). JointStates carry
velocity and effort: for a JointState with empty float64 arrays, Jazzy's serialize_message
returns 8 stray bytes after the CDR data (what a subscriber receives has none); rclpy and
mcap_ros2 read such bytes, rosbags rejects them ("CDR message size mismatch").
"""

from __future__ import annotations

import shutil
import sys
import time
from pathlib import Path

import pytest
import yaml
from geometry_msgs.msg import PointStamped
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.highlevel import AnyReader
from rosbags.rosbag2.storage_mcap import McapReader as RosbagsMcapReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from sensor_msgs.msg import JointState

from robot_calib.bag import BagReader, BagWriter, QosProfile, message_definition
from robot_calib.bag.ros2_formats import (
    DURATION_INFINITE,
    dump_yaml,
    qos_profiles_from_yaml,
    qos_profiles_to_yaml,
    type_description_hash,
)
from robot_calib.errors import BagError

JS, PS = "/joint_states", "/laser_tracker/point"
JS_TYPE, PS_TYPE = "sensor_msgs/msg/JointState", "geometry_msgs/msg/PointStamped"
SHARE = Path(sys.prefix) / "share"  # where the ROS 2 wheels install the .msg files
T0 = 1_700_000_000_000_000_000  # ns
# What a Fast DDS publisher offers, as rclpy's get_publishers_info_by_topic reports it.
OFFER = QosProfile(
    history="unknown",
    depth=0,
    reliability="reliable",
    durability="volatile",
    deadline=DURATION_INFINITE,
    lifespan=DURATION_INFINITE,
    liveliness="automatic",
    liveliness_lease_duration=DURATION_INFINITE,
)


def joint_state(i: int) -> JointState:
    msg = JointState(name=[f"joint_a{j}" for j in range(1, 7)])
    msg.position = [0.001 * i + 0.1 * j for j in range(6)]
    msg.velocity = [0.0] * 6
    msg.effort = [float(i)] * 6
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1000 + i, 5000
    return msg


def point(i: int) -> PointStamped:
    msg = PointStamped()
    msg.header.frame_id = "laser_tracker"
    msg.header.stamp.sec = 1000 + i
    msg.point.x, msg.point.y, msg.point.z = 0.5 + 1e-3 * i, -0.25, 1.0 + 1e-6 * i
    return msg


def write_bag(path: Path, n: int = 200, chunk_size: int = 8192) -> list[tuple[str, bytes, int]]:
    """n JointStates and n PointStamped, interleaved, log times 1 ms apart; what was written."""
    written = []
    with BagWriter(path, chunk_size=chunk_size, ros_distro="jazzy") as writer:
        writer.add_topic(JS, JS_TYPE, offered_qos=[OFFER])
        writer.add_topic(PS, PS_TYPE, offered_qos=[OFFER])
        for i in range(n):
            for topic, msg in ((JS, joint_state(i)), (PS, point(i))):
                data = serialize_message(msg)
                log_time = T0 + 1_000_000 * len(written)
                writer.write(topic, data, log_time)
                written.append((topic, data, log_time))
        assert writer.counts == {JS: n, PS: n}
    return written


@pytest.fixture
def bag(tmp_path: Path) -> tuple[Path, list[tuple[str, bytes, int]]]:
    path = tmp_path / "run.mcap"
    return path, write_bag(path)


def test_round_trip_with_our_reader(bag: tuple[Path, list]) -> None:
    path, written = bag
    with BagReader(path) as reader:
        assert reader.complete and reader.has_summary
        assert reader.counts == {JS: 200, PS: 200}
        assert reader.topics[JS].type_name == JS_TYPE
        assert reader.topics[PS].type_name == PS_TYPE
        assert reader.topics[JS].offered_qos == (OFFER,)
        messages = list(reader.messages())
        assert [(m.topic, m.data, m.log_time_ns) for m in messages] == written
        assert all(m.publish_time_ns == m.log_time_ns for m in messages)
        assert [m.topic for m in reader.messages([PS])] == [PS] * 200
        decoded = messages[2 * 17].decode()  # JointState no. 17
        assert list(decoded.position) == pytest.approx(joint_state(17).position)
        assert decoded.header.stamp.sec == 1017
        point_17 = messages[2 * 17 + 1].decode()
        assert (point_17.header.frame_id, point_17.point.x) == ("laser_tracker", 0.517)
        assert deserialize_message(messages[0].data, JointState) == joint_state(0)


def test_file_is_what_rosbag2_writes(bag: tuple[Path, list]) -> None:
    """Profile ros2, ros2msg schemas with the full definitions, cdr channels with QoS and
    type hash metadata, chunked and indexed, a rosbag2 metadata record."""
    path, written = bag
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == len(written)
        assert len(summary.chunk_indexes) > 3  # chunked
        assert all(c.compression == "" for c in summary.chunk_indexes)  # rosbag2 default
        assert all(c.message_index_length > 0 for c in summary.chunk_indexes)  # indexed
        schemas = {s.name: s for s in summary.schemas.values()}
        assert set(schemas) == {JS_TYPE, PS_TYPE}
        for name, schema in schemas.items():
            assert schema.encoding == "ros2msg"
            assert schema.data.decode() == message_definition(name)[1]
        for channel in summary.channels.values():
            assert channel.message_encoding == "cdr"
            assert set(channel.metadata) == {"offered_qos_profiles", "topic_type_hash"}
            assert yaml.safe_load(channel.metadata["offered_qos_profiles"])[0]["history"] == (
                "unknown"
            )
            schema_name = summary.schemas[channel.schema_id].name
            assert channel.metadata["topic_type_hash"] == type_description_hash(schema_name)
            assert channel.metadata["topic_type_hash"].startswith("RIHS01_")
        decoded = [
            (c.topic, m) for _, c, _, m in reader.iter_decoded_messages(log_time_order=False)
        ]
        assert len(decoded) == len(written)
        assert list(decoded[2 * 5][1].effort) == [5.0] * 6
        assert decoded[2 * 5 + 1][1].point.z == pytest.approx(1.000005)
        records = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
    # rosbag2 writes its metadata when it opens the bag and again when it closes it.
    assert [
        yaml.safe_load(r.metadata["serialized_metadata"])["message_count"] for r in records
    ] == [
        0,
        len(written),
    ]


def test_rosbag2_metadata_record(bag: tuple[Path, list]) -> None:
    path, written = bag
    text = BagReader(path).rosbag2_metadata()
    assert text is not None and not text.endswith("\n")  # YAML::Dump adds none
    metadata = yaml.safe_load(text)
    assert metadata["version"] == 9
    assert metadata["storage_identifier"] == "mcap"
    assert metadata["relative_file_paths"] == ["run.mcap"]
    assert metadata["message_count"] == len(written)
    assert metadata["starting_time"] == {"nanoseconds_since_epoch": T0}
    assert metadata["duration"] == {"nanoseconds": written[-1][2] - T0}
    assert metadata["ros_distro"] == "jazzy"
    assert metadata["custom_data"] is None and metadata["compression_format"] == ""
    topics = {t["topic_metadata"]["name"]: t for t in metadata["topics_with_message_count"]}
    assert topics[JS]["message_count"] == 200
    assert topics[JS]["topic_metadata"]["serialization_format"] == "cdr"
    assert topics[JS]["topic_metadata"]["offered_qos_profiles"] == [OFFER.to_dict()]
    assert "  - topic_metadata:\n      name: /joint_states\n" in text  # yaml-cpp indentation


def test_rosbags_reads_the_file(bag: tuple[Path, list], tmp_path: Path) -> None:
    """rosbags' MCAP storage reader takes the bare file; its AnyReader takes a rosbag2 bag
    directory, whose metadata.yaml we make from the rosbag2 record inside the file (what
    `ros2 bag reindex` recovers). AnyReader also checks the type hashes we recorded."""
    path, written = bag
    storage = RosbagsMcapReader(path)
    storage.open()
    try:
        connections = {c.topic: c for c in storage.connections}
        assert connections[JS].msgtype == JS_TYPE
        assert connections[JS].msgcount == 200
        assert str(connections[JS].ext.offered_qos_profiles[0].reliability.name) == "RELIABLE"
        raw = [(c.topic, bytes(data)) for c, _, data in storage.messages(storage.connections)]
        typestore = get_typestore(Stores.EMPTY)
        for connection in storage.connections:
            typestore.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
    finally:
        storage.close()
    assert raw == [(topic, data) for topic, data, _ in written]
    assert typestore.hash_rihs01(JS_TYPE) == type_description_hash(JS_TYPE)
    assert typestore.hash_rihs01(PS_TYPE) == type_description_hash(PS_TYPE)

    bag_dir = tmp_path / "rosbag2_dir"
    bag_dir.mkdir()
    shutil.copy(path, bag_dir / path.name)
    metadata = yaml.safe_load(BagReader(path).rosbag2_metadata() or "")
    (bag_dir / "metadata.yaml").write_text(
        yaml.safe_dump({"rosbag2_bagfile_information": metadata})
    )
    with AnyReader([bag_dir]) as reader:
        assert {c.topic: c.digest for c in reader.connections} == {
            JS: type_description_hash(JS_TYPE),
            PS: type_description_hash(PS_TYPE),
        }
        decoded = [
            (c.topic, reader.deserialize(data, c.msgtype)) for c, _, data in reader.messages()
        ]
    assert len(decoded) == len(written)
    positions = [m.position.tolist() for topic, m in decoded if topic == JS]
    assert positions[42] == pytest.approx(joint_state(42).position)
    assert [m.point.x for topic, m in decoded if topic == PS][7] == pytest.approx(0.507)


def test_message_definition_is_rosbag2s_concatenation() -> None:
    """The .msg text, then each dependency (sorted, depth first, once) after a line of 80
    '=' and 'MSG: pkg/Type'; rosbag2's LocalMessageDefinitionSource::get_full_text."""

    def msg(package: str, name: str) -> str:
        return (SHARE / package / "msg" / f"{name}.msg").read_text()

    rule = "=" * 80 + "\n"
    joint_state_text = (
        msg("sensor_msgs", "JointState")
        + "\n"
        + rule
        + "MSG: std_msgs/Header\n"
        + msg("std_msgs", "Header")
        + "\n"
        + rule
        + "MSG: builtin_interfaces/Time\n"
        + msg("builtin_interfaces", "Time")
    )
    assert message_definition(JS_TYPE) == ("ros2msg", joint_state_text)
    point_text = (
        msg("geometry_msgs", "PointStamped")
        + "\n"
        + rule
        + "MSG: geometry_msgs/Point\n"
        + msg("geometry_msgs", "Point")
        + "\n"
        + rule
        + "MSG: std_msgs/Header\n"
        + msg("std_msgs", "Header")
        + "\n"
        + rule
        + "MSG: builtin_interfaces/Time\n"
        + msg("builtin_interfaces", "Time")
    )
    assert message_definition(PS_TYPE) == ("ros2msg", point_text)


def test_qos_yaml_is_rosbag2s() -> None:
    """serialize_rclcpp_qos_vector, metadata version 9: YAML::Dump of the sequence."""
    expected = (
        "- history: unknown\n"
        "  depth: 0\n"
        "  reliability: reliable\n"
        "  durability: volatile\n"
        "  deadline:\n"
        "    sec: 9223372036\n"
        "    nsec: 854775807\n"
        "  lifespan:\n"
        "    sec: 9223372036\n"
        "    nsec: 854775807\n"
        "  liveliness: automatic\n"
        "  liveliness_lease_duration:\n"
        "    sec: 9223372036\n"
        "    nsec: 854775807\n"
        "  avoid_ros_namespace_conventions: false"
    )
    assert qos_profiles_to_yaml([OFFER]) == expected
    assert qos_profiles_from_yaml(expected) == (OFFER,)
    assert qos_profiles_to_yaml([]) == "[]"
    assert qos_profiles_from_yaml("[]") == ()
    # Metadata version <= 8 stored the rmw enum values.
    old = expected.replace("unknown", "3").replace("reliable", "1").replace("volatile", "2")
    assert qos_profiles_from_yaml(old.replace("automatic", "1")) == (OFFER,)
    with pytest.raises(ValueError, match="unknown QoS policy"):
        qos_profiles_from_yaml(expected.replace("reliable", "sometimes"))


def test_yaml_dump_quotes_what_needs_it() -> None:
    text = dump_yaml({"a": "", "b": "yes", "c": "/x/y", "d": None, "e": "1.5", "f": []})
    assert text == 'a: ""\nb: "yes"\nc: /x/y\nd: ~\ne: "1.5"\nf:\n  []'
    assert yaml.safe_load(text) == {
        "a": "",
        "b": "yes",
        "c": "/x/y",
        "d": None,
        "e": "1.5",
        "f": [],
    }


def test_never_overwrites(bag: tuple[Path, list]) -> None:
    path, _ = bag
    before = path.read_bytes()
    with pytest.raises(BagError, match="already exists") as error:
        BagWriter(path)
    assert str(path) in str(error.value)
    assert path.read_bytes() == before


def test_writer_rejects_unknown_topics_and_types(tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    with BagWriter(path) as writer:
        with pytest.raises(BagError, match="/nowhere"):
            writer.write("/nowhere", b"\x00\x01\x00\x00", T0)
        writer.add_topic(JS, JS_TYPE)
        writer.add_topic(JS, JS_TYPE)  # same again: fine
        with pytest.raises(BagError, match="already recorded as sensor_msgs/msg/JointState"):
            writer.add_topic(JS, PS_TYPE)
        with pytest.raises(BagError, match="no message definition for no_such_msgs/msg/Thing"):
            writer.add_topic("/thing", "no_such_msgs/msg/Thing")
    with pytest.raises(BagError, match="closed"):
        writer.write(JS, serialize_message(joint_state(0)), T0)
    assert BagReader(path).counts == {JS: 0}


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "not an MCAP file"),
        (b"ros2 bag? no, a text file\n", "not an MCAP file"),
        (b"\x89MCAP0\r\n\x01\x10", "truncated MCAP file"),
    ],
)
def test_bad_files_raise_one_line_bag_errors(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "bad.mcap"
    path.write_bytes(content)
    with pytest.raises(BagError, match=message) as error:
        BagReader(path, allow_truncated=True)
    assert str(path) in str(error.value) and "\n" not in str(error.value)


def test_missing_file_and_foreign_profile(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="cannot open") as error:
        BagReader(tmp_path / "missing.mcap")
    assert "missing.mcap" in str(error.value)
    from mcap.writer import Writer

    path = tmp_path / "foxglove.mcap"
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start(profile="", library="test")
        writer.finish()
    with pytest.raises(BagError, match="profile '' is not 'ros2'"):
        BagReader(path)


def test_truncated_bag_reads_up_to_the_last_complete_chunk(
    bag: tuple[Path, list], tmp_path: Path
) -> None:
    """A killed writer leaves no summary or footer: strict opening refuses the file, with
    allow_truncated every message of every chunk that ends before the cut is read back."""
    path, written = bag
    data = path.read_bytes()
    with open(path, "rb") as stream:
        chunks = make_reader(stream).get_summary().chunk_indexes  # type: ignore[union-attr]
    assert len(chunks) > 3
    # messages per chunk, from its message index records (16 bytes per message)
    per_chunk = []
    for chunk in chunks:
        end = chunk.chunk_start_offset + chunk.chunk_length
        index_bytes = chunk.message_index_length - 15 * len(chunk.message_index_offsets)
        per_chunk.append((end, index_bytes // 16))
    assert sum(n for _, n in per_chunk) == len(written)
    cut_path = tmp_path / "killed.mcap"
    for cut in (per_chunk[2][0] + 100, per_chunk[-1][0] - 1, per_chunk[-1][0]):
        cut_path.write_bytes(data[:cut])
        with pytest.raises(BagError, match="truncated") as error:
            BagReader(cut_path)
        assert str(cut_path) in str(error.value)
        with BagReader(cut_path, allow_truncated=True) as reader:
            assert not reader.complete
            got = [(m.topic, m.data, m.log_time_ns) for m in reader.messages()]
            assert reader.message_count == len(got)
            assert reader.rosbag2_metadata() is not None  # the one written at open
        closed = sum(n for end, n in per_chunk if end <= cut)
        assert closed > 0
        assert got == written[:closed]  # every closed chunk, nothing of the cut one


def test_open_bag_is_readable_after_each_chunk_and_after_max_age(tmp_path: Path) -> None:
    """While the writer is still open, a reader sees every closed chunk; a chunk older than
    max_chunk_age_s is closed by flush_stale (the recorder's timer calls it)."""
    path = tmp_path / "live.mcap"
    writer = BagWriter(path, chunk_size=1 << 20, max_chunk_age_s=0.05)
    try:
        writer.add_topic(PS, PS_TYPE)
        for i in range(3):
            writer.write(PS, serialize_message(point(i)), T0 + i)
        assert not writer.flush_stale()  # younger than 50 ms
        assert BagReader(path, allow_truncated=True).message_count == 0
        time.sleep(0.06)
        assert writer.flush_stale()
        with BagReader(path, allow_truncated=True) as reader:
            assert [m.decode().point.x for m in reader.messages()] == [0.5, 0.501, 0.502]
    finally:
        writer.close()
    assert BagReader(path).counts == {PS: 3}


def test_writer_reproduces_the_committed_sample_byte_for_byte(tmp_path: Path) -> None:
    """The messages of `bags/paper_test3.mcap`, written again as `robot-calib simulate`
    wrote them (recorder defaults: 128 KiB chunks, uncompressed; topics added at their
    first message with one Fast DDS offer each; installed type hashes; ROS_DISTRO unset),
    give the committed file exactly: schemas, channel metadata, rosbag2 metadata records,
    chunking, indexes and summary are all unchanged. No field is masked. max_chunk_age_s is
    large so that no chunk is closed by age (the simulation took under a second)."""
    sample = Path(__file__).resolve().parents[2] / "bags" / "paper_test3.mcap"
    with BagReader(sample) as reader:
        types = {topic: info.type_name for topic, info in reader.topics.items()}
        messages = list(reader.messages())
    path = tmp_path / sample.name  # the file name is part of the rosbag2 metadata
    with BagWriter(path, max_chunk_age_s=3600.0, ros_distro="") as writer:
        for m in messages:
            if not writer.has_topic(m.topic):
                writer.add_topic(m.topic, types[m.topic], offered_qos=[OFFER])
            writer.write(m.topic, m.data, m.log_time_ns, m.publish_time_ns, m.sequence)
    assert path.read_bytes() == sample.read_bytes()
