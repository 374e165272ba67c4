"""Every params_best.json the diagnosis writes loads where it is used: `predict`, `score`
and `compensate` take it (exit 0) on blind worlds of each kind of model the ladder can
choose: geometric alone, a physical effect, and the hybrid with a learned correction (a
real ABB arm's file was refused by predict and score: its stored correction rms disagreed
with what the loader measured). `scripts/blind_harness.py` checks every class."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli

from robot_calib.bag.write import write_measurement_bag
from robot_calib.diagnosis.diagnosis import diagnose
from robot_calib.flows.diagnose import best_params_path, compare_before_after, write_diagnosis
from robot_calib.identify.calibration import load_calibration
from robot_calib.sim.blind import make_case
from robot_calib.sim.world import load_world

PROGRAM = "q1,q2,q3,q4,q5,q6\n0.0,-1.5708,1.5708,0.0,0.7854,0.0\n0.3,-1.2,1.4,0.5,0.6,-0.4\n"


@pytest.mark.parametrize("effect", ["none", "backlash", "gravity_backlash"])
@pytest.mark.slow
def test_the_best_model_loads_in_predict_score_and_compensate(effect: str, tmp_path: Path) -> None:
    case = make_case(effect, 1000)
    robot = load_world().model.robot
    diagnosis, ladder = diagnose(case.calibration, robot, case.holdout)
    out = tmp_path / "d.json"
    compared, warnings = compare_before_after(ladder)
    write_diagnosis(diagnosis, ladder, case.calibration, out, compared=compared, warnings=warnings)
    best = best_params_path(out)
    back = load_calibration(best)
    assert back.label == ladder.rungs[-1].model
    held = case.holdout
    expected = ladder.rungs[-1].calibration.predict(held.poses)
    assert np.max(np.abs(back.predict(held.poses) - expected)) < 1e-9
    write_measurement_bag(tmp_path / "held.mcap", held.poses.q, held.points, robot.joint_names)
    (tmp_path / "program.csv").write_text(PROGRAM)
    force = ["--force"] if diagnosis.implausible else []
    for args in (
        ["score", best.name, "held.mcap"],
        ["predict", best.name, "--joints", "program.csv", "-o", "p.csv", *force],
        ["compensate", best.name, "--joints", "program.csv", "-o", "c.csv", *force],
    ):
        proc = cli(*args, cwd=tmp_path)
        assert proc.returncode == 0, (args, proc.stderr)
    if effect == "gravity_backlash":  # general poses in the calibration: the hybrid wins
        assert back.correction is not None, back.label
