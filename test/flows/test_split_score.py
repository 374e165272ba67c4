"""`robot-calib split` and `score`: verbs that replace users' scripts. A split
keeps every measurement exactly once, with the approach directions it was measured with;
a score is the calibration's error on a bag it was not fitted on."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli

from robot_calib.accuracy import accuracy
from robot_calib.bag.read import read_recording
from robot_calib.identify.calibration import Calibration
from robot_calib.kinematics.loader import load_robot

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "bags" / "paper_test3.mcap"
ROBOT = load_robot("kr5_sixx_r650")


@pytest.mark.parametrize("by", ["random", "order", "time"])
def test_split_keeps_every_measurement_once_with_its_direction(tmp_path: Path, by: str) -> None:
    cal, hold = tmp_path / "cal.mcap", tmp_path / "hold.mcap"
    proc = cli(
        "split",
        str(SAMPLE),
        "--holdout",
        "0.3",
        "--by",
        by,
        "--seed",
        "4",
        "--calibration-out",
        str(cal),
        "--holdout-out",
        str(hold),
    )
    assert proc.returncode == 0, proc.stderr
    whole = read_recording([SAMPLE], ROBOT)
    parts = [read_recording([path], ROBOT) for path in (cal, hold)]
    # about 30 %, in whole poses: the sample repeats some poses, whose every measurement
    # goes with the one chosen (a repeat on the other side would be a fitted copy)
    assert len(parts[0]) + len(parts[1]) == len(whole) and 87 <= len(parts[1]) <= 95
    groups = [{tuple(np.round(q, 6)) for q in part.poses.q} for part in parts]
    assert not groups[0] & groups[1]
    rows = {tuple(np.round(p, 12)): i for i, p in enumerate(whole.points)}
    firsts = []  # per part: the first measurement of each of its poses, in the whole bag
    for part in parts:
        index = [rows[tuple(np.round(p, 12))] for p in part.points]
        np.testing.assert_array_equal(part.poses.q, whole.poses.q[index])
        np.testing.assert_array_equal(part.poses.direction, whole.poses.direction[index])
        first: dict[tuple[float, ...], int] = {}
        for i in sorted(index):
            first.setdefault(tuple(np.round(whole.poses.q[i], 6)), i)
        firsts.append(sorted(first.values()))
    if by != "random":  # the poses first measured last in order (= in time here)
        assert firsts[0][-1] < firsts[1][0]
    assert len({tuple(np.round(p, 12)) for part in parts for p in part.points}) == len(whole)
    # The original stamps: the halves share none, so they can be used together.
    stamps = [set(part.stamp_ns.tolist()) for part in parts]
    assert not stamps[0] & stamps[1] and stamps[0] | stamps[1] == set(whole.stamp_ns.tolist())
    proc = cli("calibrate", str(cal), str(hold), "-o", str(tmp_path / "both.json"))
    assert proc.returncode == 0, proc.stderr


def test_score_is_the_error_on_a_bag_not_fitted(tmp_path: Path) -> None:
    cal, hold, params = tmp_path / "cal.mcap", tmp_path / "hold.mcap", tmp_path / "p.json"
    assert (
        cli(
            "split", str(SAMPLE), "--calibration-out", str(cal), "--holdout-out", str(hold)
        ).returncode
        == 0
    )
    assert cli("calibrate", str(cal), "-o", str(params)).returncode == 0
    table = tmp_path / "points.csv"
    proc = cli("score", str(params), str(hold), "--points-csv", str(table))
    assert proc.returncode == 0, proc.stderr
    model, values = (loaded := Calibration.load(params)).model, loaded.parameters
    held = read_recording([hold], ROBOT)
    acc = accuracy(held.points, model.target_points(values, held.poses))
    assert f"absolute error mean {acc.absolute_mean_mm:.4f}" in proc.stdout
    assert f"seed criterion (pairwise distances) mean {acc.pairwise_mean_mm:.4f}" in proc.stdout
    assert acc.absolute_rms_mm < 0.02  # the sample world has no effect: the noise
    rows = list(csv.DictReader(table.open()))
    assert len(rows) == len(held) and rows[0]["bag"] == str(hold)
    errors = np.array([float(r["error_m"]) for r in rows])
    assert errors.mean() * 1e3 == pytest.approx(acc.absolute_mean_mm, rel=1e-9)
    assert "warning" not in proc.stderr
    # Scoring the calibration bag itself says the score is in-sample.
    assert "would be in-sample" in cli("score", str(params), str(cal)).stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["split", str(SAMPLE), "--holdout", "1.5"], "a fraction between 0 and 1"),
        (
            ["split", str(SAMPLE), "--calibration-out", "x.mcap", "--holdout-out", "x.mcap"],
            "name one file",
        ),
        (["score", "nosuch.json", str(SAMPLE)], "no such parameter file"),
        (
            ["split", str(SAMPLE), "--calibration-out", "a/x.mcap", "--holdout-out", "y.mcap"],
            "no such folder",
        ),
    ],
)
def test_bad_split_and_score_inputs(tmp_path: Path, args: list[str], message: str) -> None:
    proc = cli(*args, cwd=tmp_path)
    assert proc.returncode == 2 and message in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and list(tmp_path.iterdir()) == []


def test_no_seed_criterion_without_a_pair_of_points() -> None:
    """The seed criterion compares distances between pairs of points: one point has none,
    and its 0.0000 / 0.0000 measured nothing; every report says n/a instead."""
    from robot_calib.accuracy import accuracy

    one = accuracy(np.zeros((1, 3)), np.full((1, 3), 1e-4))
    assert "seed criterion n/a" in one.line() and "0.0000 / " not in one.line()
    assert one.pairwise_text().strip().startswith("n/a")
    two = accuracy(np.array([[0.0, 0, 0], [1.0, 0, 0]]), np.array([[0.0, 0, 0], [1.001, 0, 0]]))
    assert "seed criterion mean 1.0000 / max 1.0000 mm" in two.line(), two.line()
