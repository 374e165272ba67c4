"""`diagnose` reads its bags in a forked child while it loads its modules, and identifies the
report's reference models (nominal, CPA) there while it climbs the ladder
(`flows.diagnose.ReadAside`). Known answers: the child's recording and reference models
equal those computed in this process; a reading's warning is printed once, before a
later input's error (the child's failure is computed again here, its warnings then
logged as they come); reference models of another recording (tracker blunders left
out) are never used."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from cli_runner import robot_calib

from robot_calib.bag.write import START_NS, STEP_NS, write_measurements
from robot_calib.measurements import Recording
from robot_calib.sim.scenarios import ur10_random


@pytest.fixture(scope="module")
def campaign() -> Recording:
    """300 random UR10 poses with gear harmonics (`ur10_random`'s campaign, smaller)."""
    return ur10_random(seed=4, n=300, holdout_share=0.0).calibration


NAMES = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)  # the UR10 description's


def _bag(path: Path, recording: Recording, swap: bool = False) -> Path:
    """A contract bag of `recording`; `swap`: two poses' stamps exchanged (the reader
    warns that stamps go backwards against the receive order)."""
    stamps = START_NS + np.arange(len(recording)) * STEP_NS
    if swap:
        stamps[[10, 11]] = stamps[[11, 10]]
    write_measurements(path, recording.poses.q, recording.points, NAMES, stamps)
    return path


CHILD_CHECK = """
import sys
import numpy as np
from robot_calib.errors import RobotCalibError
from robot_calib.flows.bags import read_inputs
from robot_calib.flows.diagnose import ReadAside
from robot_calib.identify.calibrate import reference_models
from robot_calib.kinematics.loader import load_robot

good, bad = sys.argv[1:3]
robot = load_robot("ur10")
here = read_inputs([good], (), robot)
with ReadAside([good], (), robot) as reading:
    assert reading._aside.forked  # a child reads (a fresh interpreter: no other thread)
    read = reading.read()
    assert reading._aside.received >= 1  # the child's reading, not one made here
    models = reading.references(read.recording)
    blunder_out = read.recording.subset(np.arange(len(read.recording)) > 0)
    other = reading.references(blunder_out)
np.testing.assert_array_equal(read.recording.poses.q, here.recording.poses.q)
np.testing.assert_array_equal(read.recording.points, here.recording.points)
assert read.holdout is None and read.lines == ()
assert models is not None and sorted(models) == ["nominal"], models  # no sweeps: no CPA
assert other is None  # another recording (a blunder left out): identified again there
expected = reference_models(here.recording, robot)["nominal"]
np.testing.assert_allclose(models["nominal"].parameters.values, expected.parameters.values,
                           rtol=0, atol=1e-12)
try:
    read_inputs([bad], (), robot)
except RobotCalibError as error:
    message = str(error)
with ReadAside([bad], (), robot) as reading:
    try:
        reading.read()
    except RobotCalibError as error:
        assert str(error) == message, (str(error), message)
    else:
        raise AssertionError("no error")
print("OK")
"""


def test_the_childs_reading_and_reference_models_are_those_computed_here(
    campaign: Recording, tmp_path: Path
) -> None:
    """In a fresh interpreter (one thread: the child is forked): the child's recording and
    reference models equal those computed here; a bad bag gives the same error."""
    good = _bag(tmp_path / "a.mcap", campaign)
    bad = tmp_path / "bad.mcap"
    bad.write_text("not a bag")
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    done = subprocess.run(
        [sys.executable, "-c", CHILD_CHECK, str(good), str(bad)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        env=env,
    )
    assert done.returncode == 0 and done.stdout.strip() == "OK", done.stderr[-3000:]
    assert not list(tmp_path.glob("robot_calib-aside-*"))  # the children's folders removed


def test_a_reading_warning_is_printed_once_before_a_hold_out_error(
    campaign: Recording, tmp_path: Path
) -> None:
    """The real program (its child reads; the hold-out fails there, and the reading is
    done again here): the calibration bag's warning, once, then the error; no output."""
    bag = _bag(tmp_path / "swapped.mcap", campaign, swap=True)
    bad = tmp_path / "bad.mcap"
    bad.write_text("not a bag")
    run = robot_calib(
        "diagnose",
        str(bag),
        "--holdout",
        str(bad),
        "--robot",
        "ur10",
        "-o",
        str(tmp_path / "d.json"),
    )
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    warned = [k for k, line in enumerate(lines) if "go backwards" in line]
    errors = [k for k, line in enumerate(lines) if "not an MCAP file" in line]
    assert len(warned) == 1 and len(errors) == 1 and warned[0] < errors[0], run.stderr
    assert not list(tmp_path.glob("d*"))
