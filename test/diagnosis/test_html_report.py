"""The HTML report: one self-contained file an engineer reads in two minutes,
from a small simulated diagnosis whose truth is known (joint-4 backlash, one tracker
blunder, the ISO 9283 cube repeated in the hold-out), checked as a document and rendered
in a real headless browser (Debian's Chromium) to a screenshot that must not be blank."""

from __future__ import annotations

import base64
import dataclasses
import html
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from robot_calib.diagnosis.diagnosis import Diagnosis
from robot_calib.diagnosis.ladder import Ladder
from robot_calib.diagnosis.names import with_breaks
from robot_calib.flows.diagnose import (
    compare_before_after,
    diagnose_recordings,
    html_report_path,
    write_diagnosis,
)
from robot_calib.flows.simulate import simulation_world
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import Plan, iso9283_plan, paper_test_plan, plan_times, random_plan

WORLD = simulation_world(effects=["backlash:4"], seed=3)
ROBOT = WORLD.model.robot
BLUNDER = 40  # the calibration point knocked 4.6 mm off
SECTIONS = ("accuracy", "ladder", "where", "vectors", "iso9283", "parameters", "warnings")


def recorded(plan: Plan, seed: int, blunder: int | None = None) -> Recording:
    time = plan_times(plan, WORLD.timing)
    points = physical_points(
        WORLD, Poses.from_readings(plan.q, time=time), np.random.default_rng(seed)
    )
    if blunder is not None:
        points[blunder] += [0.004, -0.002, 0.001]
    return recording_from_arrays(plan.q, points, time, robot=ROBOT)


@pytest.fixture(scope="module")
def diagnosed() -> tuple[Diagnosis, Ladder, Recording]:
    calibration = recorded(paper_test_plan(2), 1, BLUNDER)
    rnd = random_plan(ROBOT, 60, np.random.default_rng(5))
    cube = iso9283_plan(WORLD.model, WORLD.truth, cycles=3)
    held = recorded(
        Plan("holdout", np.vstack([rnd.q, cube.q]), np.concatenate([rnd.sweep, cube.sweep]), 0.1),
        2,
    )
    diagnosis, ladder = diagnose_recordings(calibration, ROBOT, held)
    return diagnosis, ladder, calibration


@pytest.fixture(scope="module")
def report(
    tmp_path_factory: pytest.TempPathFactory, diagnosed: tuple[Diagnosis, Ladder, Recording]
) -> Path:
    diagnosis, ladder, calibration = diagnosed
    compared, warnings = compare_before_after(ladder)
    out = tmp_path_factory.mktemp("html") / "diagnosis.json"
    extra = ["warning: <script>alert(1)</script> & co", *warnings]
    write_diagnosis(diagnosis, ladder, calibration, out, compared=compared, warnings=extra)
    return html_report_path(out)


def test_diagnose_says_when_a_richer_model_generalises_worse(
    diagnosed: tuple[Diagnosis, Ladder, Recording], report: Path
) -> None:
    """Scored on hold-out bags, each model that does worse than the simpler one before it
    (nominal, cpa, geometric, the best rung) gets a warning, which the report lists."""
    compared, warnings = compare_before_after(diagnosed[1])
    scores = [(m.model, m.accuracy.absolute_rms_mm) for m in compared]
    assert [m for m, _ in scores][:3] == ["nominal", "cpa", "geometric"]
    worse = [rich for (_, a), (rich, b) in zip(scores, scores[1:]) if b > a]
    assert [w.split(" generalises worse")[0].removeprefix("warning: ") for w in warnings] == worse
    page = report.read_text()
    assert all(html.escape(w, quote=True) in page for w in warnings)
    no_holdout = dataclasses.replace(diagnosed[1], holdout=None)
    assert compare_before_after(no_holdout)[1] == []  # not comparable: silent


class Links(HTMLParser):
    """Every src / href of a document, and the ids of its sections."""

    def __init__(self) -> None:
        super().__init__()
        self.urls: list[tuple[str, str, str]] = []
        self.ids: list[str] = []
        self.tags: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        for key, value in attrs:
            if key in ("src", "href") and value is not None:
                self.urls.append((tag, key, value))
            if key == "id" and value is not None:
                self.ids.append(value)


def test_the_report_is_self_contained_and_says_what_happened(report: Path) -> None:
    text = report.read_text()
    links = Links()
    links.feed(text)
    images = [url for tag, _, url in links.urls if tag == "img"]
    assert len(images) >= 6  # histogram, ladder, arcs, maps, time, 3D vectors
    for url in images:
        head, _, data = url.partition(",")
        assert head == "data:image/png;base64"
        assert base64.b64decode(data)[:8] == b"\x89PNG\r\n\x1a\n"
    assert all(url.startswith(("data:", "#")) for _, _, url in links.urls), links.urls
    assert "http://" not in text and "https://" not in text
    assert not {"script", "link", "iframe"} & set(links.tags)  # nothing to run or fetch
    assert "&lt;script&gt;alert(1)&lt;/script&gt; &amp; co" in text  # warnings escaped
    assert set(SECTIONS) <= set(links.ids)
    # the verdict names the truth: joint-4 backlash, the best model and what to run next
    verdict = text[text.index('class="verdict') : text.index("</section>")]
    assert "backlash on joints [4]" in verdict
    assert "geometric+backlash:4 (diagnosis.params_best.json)" in verdict
    assert "robot-calib export diagnosis.params_best.json --format urdf" in verdict
    # before / after: nominal, CPA, geometric and the best rung, all on the hold-out bag
    table = text[text.index('id="accuracy"') : text.index('id="ladder"')]
    for model in ("nominal", "cpa", "geometric", "geometric+backlash:4"):  # breaks at '+' only
        assert f'<td class="text"><span class="model">{with_breaks(model)}</span></td>' in table
    assert table.count("hold-out bags</td>") == 4
    # the blunder is named, ISO 9283 before/after, the parameter table with 1-sigma and why
    problems = text[text.index('id="warnings"') :]
    assert f'<td class="text">arrays</td><td>{BLUNDER}</td>' in problems
    assert "AP nominal [mm]" in text and "AP geometric+backlash:4 [mm]" in text
    assert '<td class="text">backlash4</td><td class="text">deg</td>' in text
    assert "redundant with base2tracker" in text
    # one unit per quantity: angles in deg only (the Markdown report's urad never shows)
    assert "urad" not in text and "[deg]" in text and "[mm]" in text


def test_the_markdown_report_says_what_the_html_says(report: Path) -> None:
    """The warnings, the nominal 'before' row, the parameter table and ISO 9283 are in the
    Markdown report as in the HTML one, with the same figures."""
    html = report.read_text()
    markdown = report.with_suffix(".md").read_text()
    assert "<script>alert(1)</script> & co" in markdown  # the caller's warning, as given
    assert "generalises worse" in html and "generalises worse" in markdown
    accuracy = markdown[markdown.index("## Accuracy before and after calibration") :]
    for model in ("nominal", "cpa", "geometric", "geometric+<wbr>backlash:4"):
        assert f"| {model} |" in accuracy
    nominal = next(line for line in accuracy.splitlines() if line.startswith("| nominal |"))
    assert "before calibration" in nominal and "hold-out bags" in nominal
    rms = nominal.split("|")[4].split("/")[1].strip()  # the same figure as the HTML's
    assert rms in html
    parameters = markdown[markdown.index("## Parameters of the best model") :]
    backlash = next(line for line in parameters.splitlines() if line.startswith("| backlash4 |"))
    assert "| deg |" in backlash and backlash.split("|")[3].strip() in html
    assert "ISO 9283" in markdown and "AP nominal" in markdown


def _browser() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    pytest.skip("chromium not found: .ci/run installs it with apt-get install chromium")


@pytest.mark.slow
def test_the_report_renders_in_a_headless_browser(report: Path, tmp_path: Path) -> None:
    """Debian's Chromium draws the page: a screenshot with ink and colours, not blank."""
    import matplotlib.image

    shot = tmp_path / "report.png"
    browser = _browser()
    proc = subprocess.run(
        [
            browser,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={tmp_path / 'profile'}",
            "--window-size=1280,2000",
            f"--screenshot={shot}",
            report.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0 and shot.exists(), proc.stderr[-2000:]
    pixels = matplotlib.image.imread(shot)[:, :, :3]
    assert pixels.shape[:2] == (2000, 1280)
    ink = np.any(pixels < 0.9, axis=2).mean()
    colours = len(np.unique((pixels * 255).astype(np.uint8).reshape(-1, 3), axis=0))
    assert ink > 0.05, ink  # text, tables and figures, not a white page
    assert colours > 50, colours  # the verdict's tint, the plots' lines: not a blank page
