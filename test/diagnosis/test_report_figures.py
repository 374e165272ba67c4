"""The diagnosis reports as a field user reads them: the ladder on a
log axis when its rungs span decades, with the noise floor labelled on its line; the
histogram's legend beside the data, never over it; a colour bar on the 3D residual vectors;
model names broken only between terms (or after a comma); and the per-joint rows of the
geometric model saying what the best model removed."""

from __future__ import annotations

import html
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from matplotlib.transforms import Bbox

from robot_calib.diagnosis.figures import (
    COLOUR_BAR_LABEL,
    error_histogram_figure,
    ladder_figure,
    ladder_yscale,
    pyplot,
    quiver_figure,
)
from robot_calib.diagnosis.names import name_pieces, with_breaks, wrap_name
from robot_calib.diagnosis.signatures import (
    REMOVED,
    RemovedSignature,
    removed_note,
    removed_signatures,
)
from robot_calib.effects import make_effect
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
from robot_calib.sim.plans import Plan, paper_test_plan, plan_times, random_plan

LONG = "geometric+backlash:4+joint_harmonics:2:orders=12,20+eccentricity:1:order=2"


def fake_ladder(heldout_mm: list[float], bound_mm: float | None) -> SimpleNamespace:
    """What `ladder_figure` reads of a Ladder: each rung's name and held-out rms [mm], the
    learnable bound [mm] and what it is scored on; the tracker frame = the base frame."""
    names = LONG.split("+")
    rungs = [
        SimpleNamespace(
            model="+".join(names[: k + 1]),
            heldout=SimpleNamespace(absolute_rms_mm=value),
            calibration=SimpleNamespace(
                model=SimpleNamespace(base2tracker=lambda _: np.eye(4)), parameters=None
            ),
        )
        for k, value in enumerate(heldout_mm)
    ]
    learnable = (
        None if bound_mm is None else SimpleNamespace(holdout_abs_rms_mm=bound_mm, bounds=True)
    )
    return SimpleNamespace(rungs=rungs, learnable=learnable, scored_on="hold-out bags")


def test_the_ladder_axis_is_logarithmic_when_the_rungs_span_decades() -> None:
    assert ladder_yscale([50.0, 3.1, 0.4, 0.02]) == "log"
    assert ladder_yscale([0.2332, 0.0095, 0.0091]) == "log"  # the main job's ladder
    assert ladder_yscale([0.30, 0.12, 0.05]) == "linear"  # within a decade
    assert ladder_yscale([0.1, 0.0]) == "linear"  # a zero is no decade
    wide = ladder_figure(fake_ladder([50.0, 3.1, 0.4, 0.02], 0.021), 0.018)  # type: ignore[arg-type]
    ax = wide.axes[0]
    assert ax.get_yscale() == "log"
    low, high = ax.get_ylim()
    assert 0 < low < 0.018 and high > 50.0  # every bar and line inside the axes
    labels = [t.get_text() for t in ax.texts]
    assert any(text.startswith("noise floor") and "0.0180 mm" in text for text in labels)
    assert any("learnable bound" in text for text in labels)
    narrow = ladder_figure(fake_ladder([0.30, 0.12], None), 0.05)  # type: ignore[arg-type]
    assert narrow.axes[0].get_yscale() == "linear"
    # model names on the ticks break only between terms
    ticks = [t.get_text() for t in ax.get_xticklabels()]
    assert ticks[-1] == wrap_name(LONG, 20) and "\n" in ticks[-1]
    for fig in (wide, narrow):
        pyplot().close(fig)


def test_the_histogram_legend_lies_beside_the_data() -> None:
    rng = np.random.default_rng(0)
    errors = [
        (name, np.abs(rng.normal(v, v / 3, 200)))
        for name, v in (("nominal", 1.0), ("geometric", 0.2), (LONG, 0.01))
    ]
    fig = error_histogram_figure(errors, "hold-out bags")
    fig.canvas.draw()
    ax = fig.axes[0]
    legend = ax.get_legend()
    assert legend is not None
    box, data = legend.get_window_extent(), ax.get_window_extent()
    assert Bbox.intersection(box, data) is None, (box, data)  # nothing of the axes covered
    inside = fig.get_window_extent()
    assert box.x1 <= inside.x1 + 1 and box.y0 >= inside.y0 - 1  # and not cut off
    assert any(wrap_name(LONG) in t.get_text() for t in legend.get_texts())
    pyplot().close(fig)


def test_the_residual_vectors_have_a_colour_bar_in_mm() -> None:
    ladder = fake_ladder([0.2, 0.01], None)
    rng = np.random.default_rng(1)
    points = rng.uniform(-0.5, 0.5, (50, 3))
    residuals = [("geometric", rng.normal(0, 2e-4, (50, 3))), (LONG, rng.normal(0, 1e-5, (50, 3)))]
    fig = quiver_figure(ladder, points, residuals, "hold-out bags")  # type: ignore[arg-type]
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert len(bars) == 2  # one per panel: each panel's colours run 0 .. its largest
    assert all(bar.get_ylabel() == COLOUR_BAR_LABEL == "|residual| [mm]" for bar in bars)
    largest = np.linalg.norm(residuals[0][1], axis=1).max() * 1e3
    assert bars[0].get_ylim() == pytest.approx((0.0, largest))
    pyplot().close(fig)


@pytest.mark.parametrize(
    "name",
    [
        LONG,
        "geometric",
        "geometric+joint_harmonics:2:orders=11,27",
        "geometric+thermal_drift+learned",
        "a+",
    ],
)
@pytest.mark.parametrize("width", [1, 12, 24, 200])
def test_model_names_break_only_between_terms_or_after_commas(name: str, width: int) -> None:
    wrapped = wrap_name(name, width)
    assert wrapped.replace("\n", "") == name  # nothing lost, nothing added
    lines = wrapped.split("\n")
    assert all(line[-1] in "+," for line in lines[:-1])  # every break after '+' or ','
    terms = name.split("+")
    # a term is cut only when it is too long for a line, and then only after a comma
    for line in lines:
        assert len(line) <= width or len(name_pieces(line)) == 1
    for term in terms:
        if len(term) <= width:
            assert any(term in line for line in lines), (term, lines)
    assert "".join(name_pieces(name)) == name
    assert with_breaks(name).replace("<wbr>", "") == name
    assert with_breaks(name).count("<wbr>") == sum(c in "+," for c in name.rstrip("+,"))


def test_wrap_examples() -> None:
    # whole terms while they fit; the term longer than 24 cut after its comma only
    assert wrap_name(LONG, 24).split("\n") == [
        "geometric+backlash:4+",
        "joint_harmonics:2:orders=12,",
        "20+",
        "eccentricity:1:order=2",
    ]
    assert wrap_name(LONG, 40).split("\n") == [
        "geometric+backlash:4+",
        "joint_harmonics:2:orders=12,20+",
        "eccentricity:1:order=2",
    ]
    assert with_breaks("geometric+backlash:4+joint_harmonics:2:orders=12,20") == (
        "geometric+<wbr>backlash:4+<wbr>joint_harmonics:2:orders=12,<wbr>20"
    )


def test_what_the_best_model_removes_per_joint() -> None:
    effects = [
        make_effect("backlash", [4]),
        make_effect("joint_harmonics", [2], orders=(2, 20)),
        make_effect("encoder_scale", [1, 3]),
        make_effect("thermal_drift"),
    ]
    removed = removed_signatures(effects)
    assert removed == [
        RemovedSignature(4, "direction", "backlash:4"),
        RemovedSignature(2, "harmonics", "joint_harmonics:2:orders=2,20", [2, 20]),
        RemovedSignature(1, "scale", "encoder_scale:1,3"),
        RemovedSignature(3, "scale", "encoder_scale:1,3"),
    ]
    assert removed_note(removed, 4) == f"{REMOVED}: direction (backlash:4)"
    assert removed_note(removed, 2) == f"{REMOVED}: harmonics 2 (joint_harmonics:2:orders=2,20)"
    assert removed_note(removed, 2, (20,), ("harmonics",)).startswith(f"{REMOVED}: harmonics 20")
    assert removed_note(removed, 2, (5,)) == ""  # an order it does not model
    assert removed_note(removed, 5) == ""
    assert removed_note(removed, 4, families=("scale",)) == ""


def test_a_scanned_order_the_physical_model_leaves_no_trace_of_is_said_an_image() -> None:
    """A geometric frequency-scan order (joint 6's order 5 while joint 4 has backlash) that
    the physical model's own scan no longer finds is said to be an image of what that model
    models; one it still finds gets no note; one the best model has is 'removed'."""
    from robot_calib.diagnosis.frequency import JointSpectrum
    from robot_calib.diagnosis.signatures import (
        TimeTrend,
        WhereItLies,
        Workspace,
        scan_order_note,
    )

    def where(*spectra: JointSpectrum) -> WhereItLies:
        return WhereItLies([], [], None, TimeTrend([], 0.0), Workspace([]), 0.0, list(spectra))

    def spectrum(joint: int, orders: list[int]) -> JointSpectrum:
        return JointSpectrum(
            joint,
            True,
            100.0,
            [0.0] * 64,
            orders,
            [1.0] * len(orders),
            [9.0] * len(orders),
            ["?"] * len(orders),
        )

    removed = removed_signatures(
        [make_effect("backlash", [4]), make_effect("joint_harmonics", [2], orders=(11,))]
    )
    after = where(spectrum(1, [17]))
    model = "geometric+backlash:4+joint_harmonics:2:orders=11"
    image = scan_order_note(removed, 6, 5, after, model)
    assert image == f"not in the residuals of {model}: an image of what it models"
    assert scan_order_note(removed, 1, 17, after, model) == ""  # still there: a real one
    assert scan_order_note(removed, 2, 11, after, model).startswith(REMOVED)
    assert scan_order_note(removed, 6, 5, None, model) == ""  # no scan after: nothing said


WORLD = simulation_world(effects=["backlash:4"], seed=3)
ROBOT = WORLD.model.robot


def recorded(plan: Plan, seed: int) -> Recording:
    time = plan_times(plan, WORLD.timing)
    points = physical_points(
        WORLD, Poses.from_readings(plan.q, time=time), np.random.default_rng(seed)
    )
    return recording_from_arrays(plan.q, points, time, robot=ROBOT)


@pytest.mark.slow
def test_joint_4_backlash_is_said_removed_by_the_best_model(tmp_path: Path) -> None:
    """A simulated joint-4 backlash: the geometric model's per-joint rows of joint 4 say the
    best model (geometric+backlash:4) removed it, in the HTML, the Markdown and the JSON;
    the model names in the HTML tables break only between their terms."""
    calibration = recorded(paper_test_plan(2), 1)
    held = recorded(random_plan(ROBOT, 60, np.random.default_rng(5)), 2)
    diagnosis, ladder = diagnose_recordings(calibration, ROBOT, held)
    assert diagnosis.ladder[-1].model == "geometric+backlash:4"
    compared, warnings = compare_before_after(ladder)
    out = tmp_path / "d.json"
    # the learned correction's own warnings: counted on the console, listed in the reports
    from dataclasses import replace

    assert diagnosis.learnable is not None
    edge = "signal variance at the upper edge of its range (an example)"
    diagnosis = replace(diagnosis, learnable=replace(diagnosis.learnable, warnings=[edge]))
    assert "1 warning(s) in the reports" in diagnosis.learnable.line()
    write_diagnosis(diagnosis, ladder, calibration, out, compared=compared, warnings=warnings)
    assert f"learnable bound (learned correction): {edge}" in out.with_suffix(".md").read_text()
    assert f"learnable bound (learned correction): {edge}" in html_report_path(out).read_text()
    note = f"{REMOVED}: direction (backlash:4)"
    doc = json.loads(out.read_text())
    assert {"joint": 4, "family": "direction", "effect": "backlash:4", "orders": []} in doc[
        "removed_by_best_model"
    ]
    assert type(diagnosis).from_dict(doc).removed_by_best_model == diagnosis.removed_by_best_model
    markdown = out.with_suffix(".md").read_text()
    rows = [line for line in markdown.splitlines() if line.startswith("| 4 |")]
    assert len(rows) == 2 and all(row.endswith(f"| {note} |") for row in rows), rows
    assert not [
        line
        for line in markdown.splitlines()
        if line.startswith(("| 1 |", "| 2 |")) and REMOVED in line
    ]
    assert "| geometric+<wbr>backlash:4 |" in markdown
    page = html_report_path(out).read_text()
    where = page[page.index('id="where"') : page.index('id="vectors"')]
    row = where[where.index('<tr><td class="text">4</td>') :]
    row = row[: row.index("</tr>")]
    assert html.escape(note, quote=True) in row
    assert where.count(REMOVED) >= 2  # both per-joint tables (and the strongest structure)
    assert '<td class="text"><span class="model">geometric+<wbr>backlash:4</span></td>' in page
    assert ".model{overflow-wrap:normal;word-break:keep-all" in page
    assert "anywhere" not in page  # no text cell breaks inside a word


ASIDE_CHECK = """
import os, signal
import numpy as np
from robot_calib.diagnosis.figures import FigureCache, pyplot
from robot_calib.flows.figures import FiguresAside

parent = os.getpid()

def line(k):
    fig, ax = pyplot().subplots(figsize=(3, 2))
    ax.plot(np.arange(10), np.arange(10) ** (1 + k / 10), label=f"k = {k}")
    ax.legend()
    return fig

def fails_in_a_child():
    if os.getpid() != parent:
        raise RuntimeError("only in the child")
    return line(9)

def killed_in_a_child():  # the child dies mid-way (SIGKILL)
    if os.getpid() != parent:
        os.kill(os.getpid(), signal.SIGKILL)
    return line(7)

here = FigureCache()
expected = {f"f{k}": here.png(f"f{k}", lambda k=k: line(k)) for k in range(3)}
aside = FiguresAside()
aside.draw_aside([*((f"f{k}", lambda k=k: line(k)) for k in range(3)), ("bad", fails_in_a_child)])
got = {f"f{k}": aside.png(f"f{k}", lambda: None) for k in range(3)}  # never drawn here
assert got == expected and all(got.values())
assert aside.png("bad", fails_in_a_child) == here.png("bad", fails_in_a_child)
aside.close()
dying = FiguresAside()
dying.draw_aside([("f0", lambda: line(0)), ("dies", killed_in_a_child), ("f1", lambda: line(1))])
assert dying.png("f0", lambda: None) == expected["f0"]  # sent before it died
assert dying.png("dies", killed_in_a_child) == here.png("dies", killed_in_a_child)
assert dying.png("f1", lambda: line(1)) == expected["f1"]  # drawn here instead
dying.close()
from functools import partial
started = FiguresAside.started()  # the helper and its twin (pickled draws)
started.draw_aside([("f0", partial(line, 0)), ("f1", partial(line, 1))],
                   [("f2", partial(line, 2))])
assert started._asides and started._asides[0].forked
assert {k: started.png(k, lambda: None) for k in expected} == expected
assert started._asides[0].received == 3
started.close()
print("OK")
"""


def test_figures_drawn_aside_are_the_figures_drawn_here() -> None:
    """FiguresAside.draw_aside, in a fresh interpreter (it forks only a process without other
    threads): a forked child draws some figures while the process goes on, or the helper
    of `FigureCache.started` and its twin; their PNG bytes equal those drawn here; a
    figure the child failed on, or did not send because it was killed mid-way, is drawn
    here when asked."""
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-c", ASIDE_CHECK],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0 and done.stdout.strip() == "OK", done.stderr[-2000:]
