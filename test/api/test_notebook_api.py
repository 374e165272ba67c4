"""The public API in a Jupyter kernel (nbclient driving an ipykernel, as a notebook runs):
simulate, calibrate, save, load, diagnose and compensate with `import robot_calib` alone,
while the kernel's own threads run (a kernel must not hang: with other threads running
nothing forks, and a library call installs no forked runner anyway)."""

from __future__ import annotations

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

CELLS = [
    "import robot_calib as rc\nfrom pathlib import Path\nfolder = Path({folder!r})",
    "robot = rc.load_robot('kr5_sixx_r650')\n"
    "rc.simulate(folder / 'run.mcap', plan='paper-test2', effects=['backlash:4'], seed=1)\n"
    "recording = rc.read_recording(folder / 'run.mcap', robot=robot)",
    "cal = rc.calibrate(recording, robot, model='geometric+backlash:4')\n"
    "again = rc.Calibration.load(cal.save(folder / 'params.json', recording))\n"
    "print('rms', cal.score(recording).accuracy.absolute_rms_mm)",
    "diagnosis = rc.diagnose(recording, robot)\nprint('verdict', diagnosis.verdict)",
    "commands = rc.compensate(again, recording.poses.q[:3])\n"
    "print('reached', bool(commands.converged.all()))",
]


@pytest.mark.slow
def test_the_api_runs_in_a_jupyter_kernel(tmp_path: Path) -> None:
    notebook = nbformat.v4.new_notebook()
    notebook.cells = [nbformat.v4.new_code_cell(c.format(folder=str(tmp_path))) for c in CELLS]
    NotebookClient(
        notebook,
        timeout=180,
        kernel_name="python3",
        resources={"metadata": {"path": str(tmp_path)}},
    ).execute()
    outputs = [out for cell in notebook.cells for out in cell.get("outputs", [])]
    printed = "".join(out.get("text", "") for out in outputs if out.get("name") == "stdout")
    lines = dict(line.split(" ", 1) for line in printed.splitlines() if " " in line)
    assert float(lines["rms"]) < 0.015  # the backlash model at the noise
    assert lines["verdict"] == "backlash on joints [4]"
    assert lines["reached"] == "True"
    assert (tmp_path / "params.json").is_file()
