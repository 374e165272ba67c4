"""The blind harness's flow: one blind case (`sim.blind`: a world drawn at random from an
effect class) made, diagnosed as `robot-calib diagnose` diagnoses (`diagnose_recordings`,
on the runner the caller installed), judged against its truth, and its best model written as
params_best.json and read back (scripts/blind_harness.py runs many)."""

from __future__ import annotations

from typing import Any

from robot_calib.diagnosis.diagnosis import Diagnosis
from robot_calib.diagnosis.ladder import Ladder
from robot_calib.flows.diagnose import (
    check_loads,
    diagnose_recordings,
    marked_implausible,
    selected_document,
)
from robot_calib.sim.blind import judge, make_case, right_model_rms_mm
from robot_calib.sim.world import load_world


def run_case(effect: str, seed: int) -> dict[str, Any]:
    """Make, diagnose and judge one blind case (with its right model's held-out error), and
    whether its best model's PARAMS.json loads (`best_loads`, `best_model_loads`)."""
    case = make_case(effect, seed)
    diagnosis, ladder = diagnose_recordings(
        case.calibration, load_world().model.robot, case.holdout
    )
    return {
        **judge(case, diagnosis, right_model_rms_mm(case)),
        "best_loads": best_model_loads(ladder, diagnosis),
    }


def best_model_loads(ladder: Ladder, diagnosis: Diagnosis) -> str:
    """'' when the ladder's chosen model, written as `diagnose` writes params_best.json,
    loads back and predicts as it did (`flows.diagnose.check_loads`), else why not."""
    import tempfile
    from pathlib import Path

    from robot_calib.errors import WrittenFileError
    from robot_calib.identify.params_file import write_json_atomic

    recording = ladder.recording
    assert recording is not None
    chosen = ladder.rungs[-1].calibration
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "params_best.json"
        document = selected_document(
            marked_implausible(chosen, diagnosis),
            recording,
            "blind harness",
            diagnosis.scored_on,
            {},
        )
        write_json_atomic(document, path)
        try:
            check_loads(path, path, chosen, recording)
        except WrittenFileError as exc:
            return str(exc)
    return ""
