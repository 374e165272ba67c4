"""Safe in the field (issue 24, items 2, 4, 7, 8, 9 and CPA's 1-sigma): a stated tracker
accuracy the evidence contradicts is said so (never a green verdict resting on a unit
slip), self-contained PARAMS.json, CSV imports, multi-target bags. Real CLI on simulated
robots whose answers are known."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cli_runner import robot_calib


@pytest.fixture(scope="module")
def backlash_bags(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Random poses (no repeats, no sweeps) of a KR5 with joint-4 backlash: calibration
    and hold-out bags."""
    work = tmp_path_factory.mktemp("backlash")
    for name, n, seed in (("cal.mcap", "150", "1"), ("held.mcap", "100", "2")):
        run = robot_calib("simulate", "--plan", "random", "--n-random", n, "--effects",
                          "backlash:4", "--seed", seed, "-o", str(work / name))  # fmt: skip
        assert run.returncode == 0, run.stderr
    return work / "cal.mcap", work / "held.mcap"


def test_a_stated_accuracy_in_the_wrong_unit_hides_no_effect(
    backlash_bags: tuple[Path, Path], tmp_path: Path
) -> None:
    """--tracker-accuracy 5 (mm typed for um) on a bag with neither repeats nor sweeps: 5 mm
    is far above the geometric fit's residual (about 0.06 mm per axis): a warning naming
    both figures, the stated accuracy not used (floor unknown), backlash on joint 4 named,
    never 'null (geometric reaches the noise level)'."""
    cal, held = backlash_bags
    out = tmp_path / "d.json"
    run = robot_calib("diagnose", str(cal), "--holdout", str(held), "--tracker-accuracy", "5",
                      "-o", str(out))  # fmt: skip
    assert run.returncode == 0, run.stderr
    warning = next(line for line in run.stdout.splitlines() if "stated tracker accuracy" in line)
    assert warning.startswith("warning: ") and "5 mm per axis" in warning
    assert "in-sample residual (0.0" in warning and "not used" in warning
    assert "dominant effect: backlash on joints [4]" in run.stdout
    assert "null" not in run.stdout.split("dominant effect:")[1].splitlines()[0]
    doc = json.loads(out.read_text())
    assert doc["noise"]["floor_known"] is False and doc["noise"]["warning"] == warning
    assert warning in doc["warnings"]
    assert "refuted" in doc["unexplained"]["note"]
    assert "5 mm per axis" in out.with_suffix(".md").read_text()


def test_a_stated_accuracy_a_few_times_the_residual_is_used_and_said(
    backlash_bags: tuple[Path, Path], tmp_path: Path
) -> None:
    """0.2 mm stated, about 3.5 x the residual: used (the floor rests on it), with a warning
    naming both figures; the verdict says the floor rests on the stated accuracy alone."""
    cal, held = backlash_bags
    out = tmp_path / "d.json"
    run = robot_calib("diagnose", str(cal), "--holdout", str(held), "--tracker-accuracy",
                      "0.2", "-o", str(out))  # fmt: skip
    assert run.returncode == 0, run.stderr
    doc = json.loads(out.read_text())
    assert doc["noise"]["floor_known"] is True
    assert doc["noise"]["source"] == "stated tracker accuracy (--tracker-accuracy)"
    assert doc["noise"]["sigma_mm"] == pytest.approx(0.2, rel=1e-9)
    warning = doc["noise"]["warning"]
    assert "0.2 mm per axis is" in warning and "rest on the stated accuracy alone" in warning
    assert warning in run.stdout
    if doc["dominant_effect"] is None:  # at that floor geometric is "at the noise level"
        assert "rests on the stated tracker accuracy (--tracker-accuracy) alone" in run.stdout


def test_the_calibrate_warning_inside_diagnose_uses_the_stated_accuracy(
    backlash_bags: tuple[Path, Path], tmp_path: Path
) -> None:
    """--tracker-accuracy 0.002: the geometric fit's residual (about 0.06 mm per axis) is
    above 20 x that; the warning compares it with the stated 0.0020 mm, not an assumed
    0.0100 mm."""
    cal, held = backlash_bags
    run = robot_calib("diagnose", str(cal), "--holdout", str(held), "--tracker-accuracy",
                      "0.002", "-o", str(tmp_path / "d.json"))  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert "(0.0020 mm, stated tracker accuracy (--tracker-accuracy))" in run.stderr
    assert "assumed tracker noise" not in run.stderr


def test_on_a_bag_with_sweeps_a_stated_accuracy_is_never_ignored_without_a_word(
    tmp_path: Path,
) -> None:
    """paper-test2 (sweeps and repeat poses) with --tracker-accuracy 5: the measured noise
    (about 0.005 mm per axis) is the floor, and a warning names both figures."""
    bag = tmp_path / "sw.mcap"
    run = robot_calib("simulate", "--plan", "paper-test2", "--effects", "backlash:4", "-o",
                      str(bag))  # fmt: skip
    assert run.returncode == 0, run.stderr
    out = tmp_path / "d.json"
    run = robot_calib("diagnose", str(bag), "--tracker-accuracy", "5", "-o", str(out))
    assert run.returncode == 0, run.stderr
    doc = json.loads(out.read_text())
    assert doc["noise"]["sigma_mm"] == pytest.approx(0.0048, rel=0.3)  # the simulated noise
    warning = doc["noise"]["warning"]
    assert warning.startswith("warning: ") and "5 mm per axis is not used" in warning
    assert "x that" in warning and warning in run.stdout
    assert doc["dominant_effect"] == {"effect": "backlash", "joints": [4]}
    # a consistent stated accuracy is a note, still a word
    run = robot_calib("diagnose", str(bag), "--tracker-accuracy", "0.005", "-o",
                      str(tmp_path / "ok.json"))  # fmt: skip
    note = json.loads((tmp_path / "ok.json").read_text())["noise"]["warning"]
    assert note.startswith("note: ") and "not used" in note


def test_three_targets_per_pose_are_no_stream(tmp_path: Path) -> None:
    """A static bag of 36 poses x 3 targets (108 points, 36 joint states): no stream
    warning (it counted every target's points against the joint states)."""
    world = tmp_path / "w3.yaml"
    world.write_text("targets:\n  smr2: [0.0, 0.08, 0.04]\n  smr3: [-0.05, -0.05, 0.06]\n")
    bag = tmp_path / "t3.mcap"
    run = robot_calib("simulate", "--world", str(world), "--plan", "random", "--n-random",
                      "36", "-o", str(bag))  # fmt: skip
    assert run.returncode == 0, run.stderr
    run = robot_calib("calibrate", str(bag), "-o", str(tmp_path / "p.json"))
    assert run.returncode == 0, run.stderr
    assert "targets: 3 (/laser_tracker/point 36" in run.stderr + run.stdout
    assert "stream" not in run.stderr + run.stdout
