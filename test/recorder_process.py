"""A recorder node run as a process, and the messages published to it (the recorder's and
the repair's tests kill it for real)."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState

from robot_calib.bag import BagReader
from robot_calib.errors import BagError

JS, PS = "/joint_states", "/laser_tracker/point"
REPO = Path(__file__).resolve().parents[1]
TIMEOUT_S = 20.0


def joint_state(i: int) -> JointState:
    msg = JointState(name=[f"joint_a{j}" for j in range(1, 7)])
    msg.position = [1e-3 * i + 0.1 * j for j in range(6)]  # velocity, effort empty
    msg.header.stamp.sec = 1000 + i
    return msg


def point(i: int) -> PointStamped:
    msg = PointStamped()
    msg.header.frame_id = "laser_tracker"
    msg.header.stamp.sec = 1000 + i
    msg.point.x, msg.point.y, msg.point.z = 0.5 + 1e-3 * i, -0.25, 1.0
    return msg


def wait_until(condition: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + TIMEOUT_S
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


def start_recorder(output: Path, *params: str) -> subprocess.Popen[str]:
    command = [sys.executable, "-m", "robot_calib.nodes.recorder", "--ros-args"]
    for param in (f"output:={output}", *params):
        command += ["-p", param]
    return subprocess.Popen(
        command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def publish_to_process(node: Node, proc: subprocess.Popen[str], n: int) -> None:
    """Publish n JointStates (and n PointStamped) once the recorder process subscribed.

    No wait_for_all_acked: Fast DDS acknowledges on its heartbeat (every 3 s)."""
    js_pub = node.create_publisher(JointState, JS, 1000)
    ps_pub = node.create_publisher(PointStamped, PS, 1000)
    wait_until(
        lambda: (
            proc.poll() is not None
            or (js_pub.get_subscription_count() > 0 and ps_pub.get_subscription_count() > 0)
        ),
        "the recorder to subscribe",
    )
    assert proc.poll() is None, proc.communicate()[1]
    # Our writers see the recorder's readers; give its readers a moment to see our writers,
    # else the first samples come only with the next DDS heartbeat (3 s later).
    time.sleep(0.2)
    for i in range(n):
        js_pub.publish(joint_state(i))
        ps_pub.publish(point(i))
        if i % 50 == 49:
            time.sleep(0.002)


def readable(path: Path) -> int:
    """Messages readable now from a bag that is still being written."""
    try:
        with BagReader(path, allow_truncated=True) as reader:
            return reader.message_count
    except BagError:  # not even the header yet
        return 0


def stop(proc: subprocess.Popen[str], signum: int) -> tuple[str, str]:
    proc.send_signal(signum)
    try:
        return proc.communicate(timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise
