"""A calibration from Python with `import robot_calib` alone (README "From Python").

Run: .venv/bin/python docs/examples/python_api.py [FOLDER]  (writes into FOLDER, default a
temporary folder): a KR5 with joint-4 backlash is simulated, calibrated with and without
the backlash, scored, diagnosed, saved, loaded again, and a few joint commands compensated.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

import robot_calib as rc


def main(folder: Path) -> None:
    robot = rc.load_robot("kr5_sixx_r650")
    rc.simulate(folder / "run.mcap", plan="paper-test2", effects=["backlash:4"], seed=1)
    rc.simulate(
        folder / "holdout.mcap", plan="random", n_random=60, effects=["backlash:4"], seed=2
    )
    recording = rc.read_recording(folder / "run.mcap", robot=robot)
    holdout = rc.read_recording(folder / "holdout.mcap", robot=robot)
    for model in ("geometric", "geometric+backlash:4"):
        cal = rc.calibrate(recording, robot, model=model)
        held = cal.score(holdout).accuracy
        print(f"{model}: held-out rms {held.absolute_rms_mm:.4f} mm")
    path = cal.save(folder / "params.json", recording)
    again = rc.Calibration.load(path)
    print(f"loaded {again.name} from {path.name}: plausible {again.plausible}")
    diagnosis = rc.diagnose(recording, robot, holdout=holdout)
    diagnosis.save(folder / "diagnosis.json")
    print(f"dominant effect: {diagnosis.verdict}")
    page = diagnosis.report(folder / "DIAGNOSIS.json")  # + Markdown, HTML, best model
    print(f"report: {page.name}")
    commands = rc.compensate(again, holdout.poses.q[:5])
    moved = np.degrees(np.abs(commands.q - holdout.poses.q[:5]).max())
    print(
        f"5 commands compensated, at most {moved:.4f} deg moved, all reached: "
        f"{bool(commands.converged.all())}"
    )


if __name__ == "__main__":
    if len(sys.argv) > 1:
        main(Path(sys.argv[1]))
    else:
        with tempfile.TemporaryDirectory() as scratch:
            main(Path(scratch))
