"""The report's header a quality system files it under, in DIAGNOSIS.json (read back) and
first in the HTML and Markdown reports; the report printed to PDF by Chromium."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli

from robot_calib.diagnosis.diagnosis import Diagnosis
from robot_calib.diagnosis.header import HeaderFields, report_header
from robot_calib.flows.diagnose import (
    diagnose_recordings,
    html_report_path,
    pdf_report_path,
    report_path,
    write_diagnosis,
)
from robot_calib.flows.simulate import simulation_world
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import Plan, paper_test_plan, plan_times, random_plan

WORLD = simulation_world(effects=["backlash:4"], seed=3)
ROBOT = WORLD.model.robot
FIELDS = HeaderFields("KR5-0042", "A. Tester", "Leica AT960 #7", "robot-calib diagnose x.mcap")


def recorded(plan: Plan, seed: int, temperature: np.ndarray | None = None) -> Recording:
    time = plan_times(plan, WORLD.timing)
    points = physical_points(
        WORLD, Poses.from_readings(plan.q, time=time), np.random.default_rng(seed)
    )
    return recording_from_arrays(plan.q, points, time, robot=ROBOT, temperature=temperature)


def _written(tmp_path: Path, pdf: bool = False) -> tuple[Path, Diagnosis]:
    plan = paper_test_plan(1)
    warm = np.linspace(20.5, 27.25, len(plan.q))  # the campaign warmed the robot by 6.75 K
    calibration = recorded(plan, 1, warm)
    held = recorded(random_plan(ROBOT, 40, np.random.default_rng(5)), 2, np.full(40, 24.0))
    diagnosis, ladder = diagnose_recordings(calibration, ROBOT, held)
    header = report_header(ROBOT.name, [calibration, held], FIELDS, 5e-6)
    diagnosis = Diagnosis.from_dict({**diagnosis.to_dict(), "header": header.to_dict()})
    output = tmp_path / "DIAGNOSIS.json"
    write_diagnosis(diagnosis, ladder, calibration, output, pdf=pdf)
    return output, diagnosis


def test_the_header_is_in_every_report_and_read_back(tmp_path: Path) -> None:
    output, diagnosis = _written(tmp_path)
    back = Diagnosis.from_dict(json.loads(output.read_text()))
    assert back.header == diagnosis.header
    header = back.header
    assert header is not None
    assert header.temperature_c == pytest.approx((20.5, 27.25))
    assert header.stated_accuracy_mm == pytest.approx(0.005)
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d[+-]\d\d:\d\d", header.written)
    assert header.software.startswith("robot_calib ")
    page = html_report_path(output).read_text()
    markdown = report_path(output).read_text()
    for label, _ in header.rows():
        assert label in page and label in markdown
    for value in ("KR5-0042", "A. Tester", "Leica AT960 #7", "20.5 to 27.2 deg C", "0.005 mm"):
        assert value in page and value in markdown
    # first: before the verdict
    assert page.index("KR5-0042") < page.index("Best model")
    assert markdown.index("KR5-0042") < markdown.index("**Verdict**")


def test_a_header_left_empty_says_so() -> None:
    plan = paper_test_plan(2)
    header = report_header(ROBOT.name, [recorded(plan, 1)], HeaderFields(), None)
    rows = dict(header.rows())
    assert rows["Robot"] == f"{ROBOT.name}, serial not given"
    assert rows["Campaign temperature"] == "not recorded"
    assert "not given" in rows["Operator"] and "not given" in rows["Instrument"]


@pytest.mark.slow
def test_the_report_prints_to_pdf(tmp_path: Path) -> None:
    if not any(shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome")):
        pytest.skip("chromium not found: .ci/run installs it with apt-get install chromium")
    output, _ = _written(tmp_path, pdf=True)
    pdf = pdf_report_path(output).read_bytes()
    assert pdf.startswith(b"%PDF-")
    pages = len(re.findall(rb"/Type\s*/Page[^s]", pdf))
    assert pages >= 3  # the report's sections over several A4 pages
    assert len(pdf) > 50_000  # the figures are in it


def test_no_chromium_is_said_before_any_work(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    proc = cli("run", "-o", str(tmp_path), "--pdf")
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "--pdf" in lines[0] and "apt-get install chromium" in lines[0]
    assert not list(tmp_path.glob("run-*"))
