"""Recorder at tracker-stream rates: does the recorder node keep every message?

This process publishes geometry_msgs/PointStamped on /laser_tracker/point at --point-rate
(default 1000 Hz) and sensor_msgs/JointState on /joint_states at --joint-rate (200 Hz) for
--seconds (10 s), paced by the wall clock; the recorder node runs as its own process
(`python -m robot_calib.nodes.recorder`, as `ros2 run` starts it) and is stopped with SIGINT
one second after the last message. The bag's message counts are compared with the messages
sent. Prints: sent, recorded, lost per topic, the achieved publish rate, the recorder's CPU
over the publishing window [% of one core] and its peak RSS.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_recorder_stream.py [--seconds 10]

A private ROS_DOMAIN_ID is claimed as the tests do (a lock file per domain, from 232 down).
Publishers are RELIABLE, KEEP_LAST --pub-depth (1000): a tracker driver's queue.
Not a test: it asserts nothing; its exit status is 0 even with losses (they are printed).
"""

from __future__ import annotations

import argparse
import fcntl
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import IO

import robot_calib  # noqa: F401 - first: its one-BLAS-thread default precedes numpy

LOCKS = Path(tempfile.gettempdir()) / "robot_calib_ros_domains"


def free_domain() -> tuple[int, IO[str]]:
    """A ROS_DOMAIN_ID no test or benchmark holds, and its held lock file."""
    LOCKS.mkdir(exist_ok=True)
    for domain in range(232, 214, -1):
        lock = open(LOCKS / f"{domain}.lock", "w")  # noqa: SIM115 - held until exit
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return domain, lock
        except OSError:
            lock.close()
    raise SystemExit("no free ROS_DOMAIN_ID among 215-232")


def cpu_seconds(pid: int) -> float:
    """User + system CPU time [s] of process `pid` so far (/proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def peak_rss_mb(pid: int) -> float:
    """Peak resident set size [MB] of process `pid` (VmHWM)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="publishing time (default 10)")
    parser.add_argument("--point-rate", type=float, default=1000.0, help="Hz (default 1000)")
    parser.add_argument("--joint-rate", type=float, default=200.0, help="Hz (default 200)")
    parser.add_argument("--pub-depth", type=int, default=1000, help="publisher depth (1000)")
    parser.add_argument(
        "--recorder-args", default="", help="extra recorder ROS args, e.g. '-p qos_depth:=100'"
    )
    args = parser.parse_args()
    domain, _lock = free_domain()
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    import rclpy
    from geometry_msgs.msg import PointStamped
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    from robot_calib.bag.mcap_reader import BagReader
    from robot_calib.messages import JOINT_STATES_TOPIC, POINT_TOPIC

    folder = Path(tempfile.mkdtemp(prefix="bench_recorder_stream_"))
    bag = folder / "stream.mcap"
    recorder = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "robot_calib.nodes.recorder",
            "--ros-args",
            "-p",
            f"output:={bag}",
            *args.recorder_args.split(),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    rclpy.init()
    node = rclpy.create_node("bench_stream_publisher")
    qos = QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=args.pub_depth,
        reliability=ReliabilityPolicy.RELIABLE,
    )
    points = node.create_publisher(PointStamped, POINT_TOPIC, qos)
    joints = node.create_publisher(JointState, JOINT_STATES_TOPIC, qos)
    deadline = time.monotonic() + 30.0
    while points.get_subscription_count() < 1 or joints.get_subscription_count() < 1:
        rclpy.spin_once(node, timeout_sec=0.05)
        if time.monotonic() > deadline or recorder.poll() is not None:
            raise SystemExit("the recorder did not subscribe within 30 s")
    time.sleep(0.5)  # the reliable writer's matching settles
    names = [f"joint_{k}" for k in range(1, 7)]
    n_points = int(args.seconds * args.point_rate)
    every = max(1, round(args.point_rate / args.joint_rate))
    sent = {POINT_TOPIC: 0, JOINT_STATES_TOPIC: 0}
    late = 0
    cpu0, start = cpu_seconds(recorder.pid), time.monotonic()
    for k in range(n_points):
        due = start + k / args.point_rate
        while (now := time.monotonic()) < due:
            time.sleep(min(due - now, 2e-4))
        late += now - due > 1.0 / args.point_rate
        stamp = node.get_clock().now().to_msg()
        pt = PointStamped()
        pt.header.stamp, pt.header.frame_id = stamp, "laser_tracker"
        pt.point.x, pt.point.y, pt.point.z = 1.0 + 1e-6 * k, 0.5, 0.3
        points.publish(pt)
        sent[POINT_TOPIC] += 1
        if k % every == 0:
            js = JointState()
            js.header.stamp, js.name = stamp, names
            js.position = [0.001 * k] * 6
            js.velocity = [1.0] * 6
            joints.publish(js)
            sent[JOINT_STATES_TOPIC] += 1
    wall = time.monotonic() - start
    cpu = cpu_seconds(recorder.pid) - cpu0
    time.sleep(1.0)
    rss = peak_rss_mb(recorder.pid)
    recorder.send_signal(signal.SIGINT)
    output, _ = recorder.communicate(timeout=30)
    node.destroy_node()
    rclpy.shutdown()
    with BagReader(bag) as reader:
        recorded = {t: reader.topics[t].message_count if t in reader.topics else 0 for t in sent}
    print(f"domain {domain}, load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")
    print(f"published for {wall:.2f} s ({late} point(s) more than one period late)")
    print(f"{'topic':<22} {'sent':>7} {'recorded':>9} {'lost':>5} {'rate [Hz]':>10}")
    for topic, n in sent.items():
        print(
            f"{topic:<22} {n:>7} {recorded[topic]:>9} {n - recorded[topic]:>5} {n / wall:>10.1f}"
        )
    print(
        f"recorder CPU {100 * cpu / wall:.1f} % of one core while publishing; peak RSS "
        f"{rss:.0f} MB; bag {bag.stat().st_size / 1e6:.1f} MB"
    )
    print(f"recorder said: {output.strip().splitlines()[-1] if output.strip() else '(nothing)'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
