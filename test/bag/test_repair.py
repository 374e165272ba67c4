"""`robot-calib repair`: bags whose writer was killed for real (a BagWriter process and the
recorder node, both SIGKILLed with chunks closed and one open) are repaired through the
command line and read back by the mcap library, by rosbags and by our `read_recording`
(and calibrated); an intact bag is reproduced; bad paths are one-line errors that write
nothing; a cut record or a zero-filled tail (power loss) is counted as bytes lost."""

from __future__ import annotations

import re
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from cli_runner import cli as main_cli
from mcap.reader import make_reader
from rclpy.context import Context
from rclpy.node import Node
from recorder_process import (
    JS,
    PS,
    publish_to_process,
    readable,
    start_recorder,
    stop,
    wait_until,
)
from rosbags.highlevel import AnyReader

from robot_calib.bag import BagReader, BagWriter
from robot_calib.bag.read import read_recording
from robot_calib.bag.repair import repair_bag
from robot_calib.errors import BagError
from robot_calib.kinematics.loader import load_robot

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "bags" / "paper_test3.mcap"  # 290 poses, one chunk
ROBOT = load_robot("kr5_sixx_r650")

# Copies the sample's first N messages with 4 KiB chunks, says how many, then waits to be
# killed with the last chunk still open (in memory).
WRITE_THEN_WAIT = """
import sys, time
from robot_calib.bag import BagReader, BagWriter
source, output, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
with BagReader(source) as reader:
    writer = BagWriter(output, chunk_size=4096, max_chunk_age_s=3600, ros_distro="jazzy")
    for info in reader.topics.values():
        writer.add_topic(info.topic, info.type_name, offered_qos=info.offered_qos,
                         type_hash=info.type_hash,
                         definition=(info.schema_encoding, info.definition))
    for k, m in enumerate(reader.messages()):
        if k == n:
            break
        writer.write(m.topic, m.data, m.log_time_ns, m.publish_time_ns, m.sequence)
print(n, flush=True)
time.sleep(600)
"""


@pytest.fixture
def source(context: Context) -> Iterator[Node]:
    node = Node("source", context=context)
    yield node
    node.destroy_node()


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return main_cli(*args, cwd=REPO, timeout=120)


def killed_writer_bag(path: Path, n: int) -> int:
    """A bag of the sample's first `n` messages whose writer process was SIGKILLed; the
    messages readable from it just before the kill."""
    proc = subprocess.Popen(
        [sys.executable, "-c", WRITE_THEN_WAIT, str(SAMPLE), str(path), str(n)],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == str(n), (
            proc.communicate()[1]
        )
        before_kill = readable(path)
    finally:
        stop(proc, signal.SIGKILL)
    assert proc.returncode == -signal.SIGKILL
    return before_kill


def mcap_counts(path: Path) -> dict[str, int]:
    """Messages per topic from the file's summary (statistics), as the mcap library reads it."""
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.statistics is not None and summary.chunk_indexes
    topics = {cid: channel.topic for cid, channel in summary.channels.items()}
    return {topics[cid]: n for cid, n in summary.statistics.channel_message_counts.items()}


def rosbags_counts(path: Path, tmp_path: Path) -> dict[str, int]:
    """Messages per topic decoded by rosbags' AnyReader from a rosbag2 directory holding the
    file and the metadata.yaml of its own rosbag2 record (`ros2 bag reindex` would make it)."""
    bag_dir = tmp_path / f"{path.stem}_rosbag2"
    bag_dir.mkdir()
    shutil.copy(path, bag_dir / path.name)
    metadata = yaml.safe_load(BagReader(path).rosbag2_metadata() or "")
    assert metadata["relative_file_paths"] == [path.name]  # the final name, not a temporary
    (bag_dir / "metadata.yaml").write_text(
        yaml.safe_dump({"rosbag2_bagfile_information": metadata})
    )
    counts: dict[str, int] = {}
    with AnyReader([bag_dir]) as reader:
        for connection, _, data in reader.messages():
            reader.deserialize(data, connection.msgtype)
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
        assert reader.message_count == sum(counts.values())
    return counts


def messages(path: Path, allow_truncated: bool = False) -> list[tuple[str, bytes, int, int, int]]:
    with BagReader(path, allow_truncated=allow_truncated) as reader:
        return [
            (m.topic, m.data, m.log_time_ns, m.publish_time_ns, m.sequence)
            for m in reader.messages()
        ]


def test_repair_of_a_killed_writer_process(tmp_path: Path) -> None:
    """SIGKILL with chunks closed and one open: repair keeps every closed chunk's message,
    the output is an indexed bag that mcap, rosbags and calibrate read."""
    crashed, fixed = tmp_path / "crashed.mcap", tmp_path / "fixed.mcap"
    written = 560  # of 580: the kill comes near the end, with 4 KiB chunks closed
    before_kill = killed_writer_bag(crashed, written)
    calibrate = cli("calibrate", str(crashed), "-o", str(tmp_path / "p.json"))
    assert calibrate.returncode == 2
    assert f"run `robot-calib repair {crashed} -o FIXED.mcap`" in calibrate.stderr
    assert len(calibrate.stderr.strip().splitlines()) == 1

    proc = cli("repair", str(crashed), "-o", str(fixed))
    assert proc.returncode == 0, proc.stderr
    sent = messages(SAMPLE)[:written]
    got = messages(fixed)
    assert before_kill == len(got) and written - 40 < len(got) < written  # open chunk lost
    assert got == sent[: len(got)]  # topics, bytes, log/publish times, sequence numbers
    counts = {JS: sum(m[0] == JS for m in got), PS: sum(m[0] == PS for m in got)}
    assert proc.stdout.strip() == (
        f"{fixed}: recovered {len(got)} messages ({JS}={counts[JS]}, {PS}={counts[PS]}) "
        "of a truncated recording"
    )
    assert mcap_counts(fixed) == counts
    assert rosbags_counts(fixed, tmp_path) == counts
    with BagReader(SAMPLE) as original, BagReader(fixed) as repaired:
        assert repaired.complete and repaired.has_summary
        for topic, info in original.topics.items():
            assert repaired.topics[topic] == info.__class__(
                **{**info.__dict__, "message_count": counts[topic]}
            )  # type, definition, QoS, type hash, encodings
        assert yaml.safe_load(repaired.rosbag2_metadata() or "")["ros_distro"] == "jazzy"
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_file()) == [
        "crashed.mcap",
        "fixed.mcap",
    ]  # no temporary file left, no PARAMS.json from the refused calibrate
    recording = read_recording([fixed], ROBOT)
    assert len(recording) == min(counts.values())
    params = tmp_path / "params.json"
    calibrate = cli("calibrate", str(fixed), "-o", str(params))
    assert calibrate.returncode == 0, calibrate.stderr
    assert params.is_file()


def test_repair_of_a_killed_recorder(source: Node, tmp_path: Path) -> None:
    """The recorder node killed as in test_recorder: every message it had written out
    comes back, in order, in a bag that the mcap library and rosbags read."""
    crashed, fixed = tmp_path / "recorder.mcap", tmp_path / "recorder_fixed.mcap"
    proc = start_recorder(crashed, "chunk_size:=16384", "max_chunk_age:=100.0")
    n = 1000
    try:
        publish_to_process(source, proc, n)
        wait_until(lambda: readable(crashed) >= 2 * n - 100, "the recorder to close chunks")
    finally:
        stop(proc, signal.SIGKILL)
    before = messages(crashed, allow_truncated=True)
    repair = cli("repair", str(crashed), "-o", str(fixed))
    assert repair.returncode == 0, repair.stderr
    assert messages(fixed) == before and 2 * n - 100 <= len(before) < 2 * n
    counts = {JS: sum(m[0] == JS for m in before), PS: sum(m[0] == PS for m in before)}
    # per topic in channel order: whichever topic the recorder heard first comes first
    said = re.search(r"recovered (\d+) messages \(([^)]*)\)", repair.stdout)
    assert said is not None, repair.stdout
    assert int(said.group(1)) == len(before)
    assert sorted(said.group(2).split(", ")) == sorted(f"{t}={n}" for t, n in counts.items())
    assert mcap_counts(fixed) == counts
    assert rosbags_counts(fixed, tmp_path) == counts


def test_repair_of_an_intact_bag_reproduces_it(tmp_path: Path) -> None:
    fixed = tmp_path / "copy.mcap"
    report = repair_bag(SAMPLE, fixed)
    assert report.source_complete and report.bytes_lost == 0 and report.messages_lost == 0
    assert report.recovered == {JS: 290, PS: 290} and report.total == 580
    assert report.summary() == (
        f"{fixed}: recovered 580 messages ({JS}=290, {PS}=290); the recording was complete"
    )
    assert messages(fixed) == messages(SAMPLE)
    with BagReader(SAMPLE) as original, BagReader(fixed) as repaired:
        assert repaired.topics == original.topics
        original_meta = yaml.safe_load(original.rosbag2_metadata() or "")
        repaired_meta = yaml.safe_load(repaired.rosbag2_metadata() or "")
    assert repaired_meta["relative_file_paths"] == ["copy.mcap"]
    for key in ("ros_distro", "message_count", "starting_time", "duration"):
        assert repaired_meta[key] == original_meta[key]


def small_chunks_copy(path: Path) -> None:
    """The sample written again in 4 KiB chunks (it has one chunk of 128 KiB)."""
    with BagReader(SAMPLE) as reader, BagWriter(path, chunk_size=4096) as writer:
        for info in reader.topics.values():
            writer.add_topic(
                info.topic,
                info.type_name,
                offered_qos=info.offered_qos,
                type_hash=info.type_hash,
                definition=(info.schema_encoding, info.definition),
            )
        for m in reader.messages():
            writer.write(m.topic, m.data, m.log_time_ns, m.publish_time_ns, m.sequence)


@pytest.mark.parametrize("tail", ["cut record", "zero-filled"])
def test_repair_counts_the_bytes_after_the_last_complete_record(tmp_path: Path, tail: str) -> None:
    """A crash in the middle of a write leaves a cut record; a power loss may leave a tail
    of zeros. Both are dropped and counted; every message of the closed chunks is kept."""
    small = tmp_path / "small.mcap"
    small_chunks_copy(small)
    with open(small, "rb") as stream:
        chunks = make_reader(stream).get_summary().chunk_indexes  # type: ignore[union-attr]
    assert len(chunks) > 10
    chunk_end = chunks[5].chunk_start_offset + chunks[5].chunk_length
    data = small.read_bytes()
    crashed = tmp_path / "crashed.mcap"
    if tail == "cut record":  # cut inside the message index records after chunk 5
        crashed.write_bytes(data[: chunk_end + 100])
    else:
        crashed.write_bytes(data[:chunk_end] + bytes(3000))
    report = repair_bag(crashed, tmp_path / "fixed.mcap")
    assert not report.source_complete and report.messages_lost is None
    assert report.bytes_lost == (100 if tail == "cut record" else 3000)
    assert f"({report.bytes_lost} bytes of a record cut by the crash dropped)" in report.summary()
    got = messages(tmp_path / "fixed.mcap")
    # messages per chunk from its message index records (15 bytes + 16 per message)
    closed = sum(
        (c.message_index_length - 15 * len(c.message_index_offsets)) // 16 for c in chunks[:6]
    )
    assert got == messages(small)[:closed] and report.total == closed


@pytest.mark.parametrize(
    "case", ["output is input", "output exists", "no folder", "not an MCAP file", "no input"]
)
def test_repair_refuses_bad_paths_and_writes_nothing(tmp_path: Path, case: str) -> None:
    bag = tmp_path / "bag.mcap"
    shutil.copy(SAMPLE, bag)
    output = tmp_path / "fixed.mcap"
    if case == "output is input":
        output = bag
        message = f"{bag}: is the bag to repair; will not overwrite it"
    elif case == "output exists":
        output.write_bytes(b"precious")
        message = f"{output}: exists; will not overwrite it"
    elif case == "no folder":
        output = tmp_path / "missing" / "fixed.mcap"
        message = f"{output.parent}: no such folder for the repaired bag"
    elif case == "not an MCAP file":
        bag = tmp_path / "notes.mcap"
        bag.write_text("x,y,z\n")
        message = f"{bag}: not an MCAP file (no MCAP magic at the start)"
    else:
        bag = tmp_path / "nowhere.mcap"
        message = f"{bag}: cannot open"
    before = {p: p.read_bytes() for p in tmp_path.iterdir()}
    proc = cli("repair", str(bag), "-o", str(output))
    assert proc.returncode == 2
    assert proc.stderr.startswith(f"robot-calib repair: error: {message}"), proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and proc.stdout == ""
    assert {p: p.read_bytes() for p in tmp_path.iterdir()} == before  # nothing written


def test_repair_refuses_a_bag_without_a_complete_message(tmp_path: Path) -> None:
    """Killed before its first chunk closed: nothing to recover, nothing written."""
    crashed = tmp_path / "early.mcap"
    crashed.write_bytes(SAMPLE.read_bytes()[:60000])  # inside the sample's only chunk
    with pytest.raises(BagError, match="no complete message to recover") as error:
        repair_bag(crashed, tmp_path / "fixed.mcap")
    assert str(crashed) in str(error.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["early.mcap"]
