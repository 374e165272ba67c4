"""Nodes run alone speak ROS: an empty parameter value is one error line (not rcl's
traceback), errors name parameters rather than command-line flags under one prefix
convention ("NAME: error: ..."), and a recorder that recorded nothing leaves no file."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from rclpy.context import Context

from robot_calib.nodes.recorder import RecorderNode

BIN = Path(sys.executable).parent


def _run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(BIN / args[0]), *args[1:]],
        env=dict(os.environ),
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )


def _errors(stderr: str) -> list[str]:
    """Our own error lines (rcl logs its own '[ERROR] [rcl]' line on a bad argument)."""
    return [line for line in stderr.splitlines() if ": error: " in line]


@pytest.mark.parametrize("node", ["sim_robot", "sim_tracker"])
def test_an_empty_parameter_value_is_one_error_line(node: str) -> None:
    result = _run(node, "--ros-args", "-p", "world:=")
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    (line,) = _errors(result.stderr)
    assert line.startswith(f"{node}: error: the ROS argument '-p world:=' has no value")
    assert "-p \"world:=''\"" in line


@pytest.mark.parametrize(
    ("node", "args", "said"),
    [
        (
            "calibrator",
            ["-p", "model:=geometrc", "-p", "bags:=['x.mcap']"],
            "calibrator: error: parameter 'model' geometrc",
        ),
        ("compensator", ["-p", "params:=/nonexistent.json"], "compensator: error: "),
        (
            "calibrator",
            ["-p", "ecc_order:=0", "-p", "bags:=['x.mcap']"],
            "calibrator: error: parameter 'ecc_order' must be >= 1",
        ),  # named once
        (
            "calibrator",
            ["-p", "modle:=geometric+backlash:4"],
            "calibrator: error: parameter 'modle' is not one of calibrator's (did you mean "
            "'model'?)",
        ),  # a misspelt name is not ignored
        (
            "sim_robot",
            ["-p", "wait_for_subscribers:=-1"],
            "sim_robot: error: parameter 'wait_for_subscribers' must be >= 0",
        ),
    ],
)
@pytest.mark.slow
def test_node_errors_name_parameters_under_one_prefix(
    node: str, args: list[str], said: str
) -> None:
    result = _run(node, "--ros-args", *args)
    assert result.returncode == 2, result.stderr
    (line,) = _errors(result.stderr)
    assert line.startswith(said), line
    assert " --" not in line  # no command-line flag


def test_a_recorder_that_recorded_nothing_leaves_no_file(context: Context, tmp_path: Path) -> None:
    output = tmp_path / "empty.mcap"
    recorder = RecorderNode(output=str(output), context=context)
    recorder.destroy_node()
    assert not output.exists()  # a rerun with the same name is not blocked
    again = RecorderNode(output=str(output), context=context)
    again.destroy_node()


def test_core_keywords_are_named_as_this_nodes_parameters_or_said_otherwise() -> None:
    """A keyword of the core's message (`errors.param`) is the node's parameter when a node
    here declared it; else the command line's option where one exists, else in words: a
    node user is never told of a parameter the node does not have."""
    from robot_calib.nodes import _common

    if "model" not in _common._DECLARED:  # as a node of this process declares it
        _common._DECLARED.add("model")
    assert (
        _common.in_ros_terms("`model='geometrc'`: unknown")
        == "parameter 'model' geometrc: unknown"
    )
    assert "stream" not in _common._DECLARED
    assert (
        _common.in_ros_terms("moves: use `stream=True`")
        == "moves: use robot-calib calibrate --stream"
    )
    assert _common.in_ros_terms("`frobnicate=3` and `twiddle`") == "frobnicate=3 and twiddle"
