"""The README's multi-process recipe loses nothing.

recorder, sim_tracker and sim_robot as three separate processes with their default
parameters, as the README starts them (`ros2 run robot_calib <node>`): sim_robot waits for
both readers of /joint_states (the recorder and sim_tracker), sim_tracker for the recorder
on its point topic. Before, sim_robot started on the first reader and a run at 50 Hz lost
the whole joint-1 sweep. The processes run this worktree's code (`python -m`, PYTHONPATH)
in the test process's ROS_DOMAIN_ID (conftest.py; children inherit it).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from robot_calib.bag import BagReader
from robot_calib.messages import JOINT_STATES_TOPIC, POINT_TOPIC, joint_positions
from robot_calib.sim.plans import paper_test_plan
from robot_calib.sim.world import load_world

ROOT = Path(__file__).resolve().parents[2]
PLAN = "paper-test1"  # 120 poses
SETTLE_S = 1.5  # after sim_robot exits (0.5 s after its last pose): the last points arrive


def node(name: str, cwd: Path, *ros_args: str, **popen: object) -> subprocess.Popen[str]:
    """Start robot_calib.nodes.NAME of this tree as its own process in `cwd` (not the
    tree: `python -m` puts the working directory first on sys.path)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    command = [sys.executable, "-m", f"robot_calib.nodes.{name}"]
    if ros_args:
        command += ["--ros-args", *ros_args]
    return subprocess.Popen(command, cwd=cwd, env=env, text=True, **popen)  # type: ignore[call-overload]


@pytest.mark.slow
def test_recipe_as_separate_processes_records_every_pose(tmp_path: Path) -> None:
    bag = tmp_path / "run.mcap"
    # The robot first and the recorder last: the worst start order for a robot that
    # started on its first reader. No wait_for_subscribers given: the defaults must do.
    robot = node(
        "sim_robot",
        tmp_path,
        "-p",
        f"plan:={PLAN}",
        "-p",
        "rate:=0.0",
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    tracker = node("sim_tracker", tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    recorder = node(
        "recorder",
        tmp_path,
        "-p",
        f"output:={bag}",
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    try:
        robot_out, _ = robot.communicate(timeout=30)
        assert robot.returncode == 0, robot_out[-2000:]
        time.sleep(SETTLE_S)
    finally:
        for process in (tracker, recorder):
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        tracker.wait(timeout=20)
        recorder_out, _ = recorder.communicate(timeout=20)
        if robot.poll() is None:
            robot.kill()
            robot.wait()
    assert recorder.returncode == 0 and tracker.returncode == 0, recorder_out
    assert "waiting for 2 subscriber(s) on /joint_states" in robot_out
    plan = paper_test_plan(1)
    n = len(plan)
    assert n == 120
    assert f"/joint_states={n}, {POINT_TOPIC}={n}" in recorder_out, recorder_out
    assert "LOST" not in recorder_out
    with BagReader(bag) as reader:
        assert reader.counts == {JOINT_STATES_TOPIC: n, POINT_TOPIC: n}
        names = load_world().model.robot.joint_names
        q = np.array(
            [joint_positions(m.decode(), names) for m in reader.messages([JOINT_STATES_TOPIC])]
        )
    np.testing.assert_array_equal(q, plan.q)  # every pose, in the plan's order
