"""A bag replayed into the live calibrator and solved at once, 20 times in a row: every
point pairs with its joint state (the solve first takes what was delivered but not yet
handed to a callback), where one run in four lost the end of the bag before."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor

from robot_calib.messages import JOINT_STATES_TOPIC, POINT_TOPIC
from robot_calib.nodes.calibrator import CalibratorNode
from robot_calib.nodes.replay import ReplayNode

SAMPLE = Path(__file__).resolve().parents[2] / "bags" / "paper_test3.mcap"
ROUNDS = 20


@pytest.mark.slow
def test_replay_then_solve_never_loses_the_end_of_the_bag(context: Context) -> None:
    for round_ in range(ROUNDS):
        calibrator = CalibratorNode(context=context, node_name=f"calibrator_{round_}")
        replay = ReplayNode(
            bag=SAMPLE,
            rate=0.0,
            wait_for_subscribers=1,
            context=context,
            node_name=f"replay_{round_}",
        )
        executor = SingleThreadedExecutor(context=context)
        for node in (calibrator, replay):
            executor.add_node(node)
        try:
            deadline = time.monotonic() + 20.0
            while not replay.done:  # as fast as it publishes: the consumer lags behind
                assert time.monotonic() < deadline, "replay timed out"
                executor.spin_once(timeout_sec=0.01)
            assert replay.wait_for_acks(5.0)  # delivered, not necessarily handed over
            cal = calibrator.solve()  # at once, as a service call right after replay ends
        finally:
            executor.shutdown()
            for node in (calibrator, replay):
                node.destroy_node()
        assert cal is not None, calibrator.error
        assert calibrator.received == {JOINT_STATES_TOPIC: 290, POINT_TOPIC: 290}, round_
        assert calibrator.recording is not None and calibrator.recording.n_unpaired == 0
        assert cal.accuracy.n_points == 290
