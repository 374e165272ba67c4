"""Extra columns of a tracker export: a temperature column goes onto the side
topic /temperature (sensor_msgs/Temperature, deg C), one message per pose stamped as the
pose; the contract's two topics and their reading are unchanged."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from cli_runner import cli

from robot_calib.bag import BagReader
from robot_calib.bag.read import read_recording
from robot_calib.kinematics.loader import load_robot
from robot_calib.messages import stamp_to_ns


def test_a_temperature_column_is_imported_onto_its_topic(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    n = 30
    q = rng.uniform(-1.0, 1.0, (n, 6))
    points = rng.uniform(1.0, 2.0, (n, 3))
    celsius = 21.0 + np.linspace(0.0, 3.5, n)  # a warming robot
    rows = ["q1;q2;q3;q4;q5;q6;x;y;z;t;temp"]
    for k in range(n):
        cells = [*q[k], *points[k], 10.0 * k, celsius[k]]
        rows.append(";".join(f"{v:.9f}".replace(".", ",") for v in cells))
    (tmp_path / "in.csv").write_text("\n".join(rows) + "\n")
    proc = cli(
        "import",
        "in.csv",
        "--joints",
        "q1,q2,q3,q4,q5,q6",
        "--point",
        "x,y,z",
        "--time",
        "t",
        "--temperature",
        "temp",
        "--sep",
        ";",
        "--decimal-comma",
        "-o",
        "out.mcap",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    bag = tmp_path / "out.mcap"
    with BagReader(bag) as reader:
        assert reader.topics["/temperature"].type_name == "sensor_msgs/msg/Temperature"
        side = [m.decode() for m in reader.messages(["/temperature"])]
        poses = [m.decode() for m in reader.messages(["/laser_tracker/point"])]
    np.testing.assert_allclose([m.temperature for m in side], celsius, atol=1e-9)
    assert [stamp_to_ns(m.header.stamp) for m in side] == [
        stamp_to_ns(m.header.stamp) for m in poses
    ]
    recording = read_recording([bag], load_robot("kr5_sixx_r650"))
    np.testing.assert_allclose(recording.poses.q, q, atol=1e-9)
    np.testing.assert_allclose(recording.poses.time, 10.0 * np.arange(n), atol=1e-9)
    # `split` carries each pose's temperature into the bag its pose goes to
    proc = cli("split", "out.mcap", "--holdout", "0.3", "--seed", "1", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    by_stamp = {stamp_to_ns(m.header.stamp): m.temperature for m in side}
    total = 0
    for part in ("out.cal.mcap", "out.holdout.mcap"):
        with BagReader(tmp_path / part) as reader:
            kept = [m.decode() for m in reader.messages(["/temperature"])]
            n_poses = reader.topics["/laser_tracker/point"].message_count
        assert len(kept) == n_poses
        for m in kept:
            assert m.temperature == by_stamp[stamp_to_ns(m.header.stamp)]
        total += len(kept)
    assert total == n
