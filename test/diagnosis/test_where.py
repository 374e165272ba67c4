"""Where the residual lies, on real robots' data: per-joint figures only where
a target's lever makes them observable, a sweep table that says why it is empty, and the
residual maps of the report."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robot_calib.diagnosis.diagnosis import diagnose
from robot_calib.diagnosis.report import write_report
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import Plan, paper_test_plan, plan_times, random_plan
from robot_calib.sim.world import World, build_world

ROBOT = build_world({}).model.robot


def recorded(world: World, plan: Plan, seed: int) -> Recording:
    time = plan_times(plan, world.timing)
    points = physical_points(
        world, Poses.from_readings(plan.q, time=time), np.random.default_rng(seed)
    )
    return recording_from_arrays(plan.q, points, time, robot=ROBOT)


def test_a_target_on_the_last_axis_makes_that_joint_not_observable(tmp_path: Path) -> None:
    """The target 0.2 mm from joint 6's axis: its angle error cannot be seen (noise / 0.2 mm
    would read as tens of mrad): 'not observable', never a number; the other joints keep
    theirs."""
    world = build_world({"target_in_flange_m": [0.0002, 0.0, 0.08], "seed": 2})
    cal = recorded(world, paper_test_plan(2), 1)
    held = recorded(world, random_plan(ROBOT, 60, np.random.default_rng(3)), 4)
    diagnosis, ladder = diagnose(cal, ROBOT, held)
    arcs = {j.joint: j for j in diagnosis.where.joints}
    assert not arcs[6].observable and arcs[6].harmonics_urad is None
    assert arcs[6].lever_mm is not None and arcs[6].lever_mm < 1.0
    assert all(arcs[j].observable and arcs[j].harmonics_urad for j in range(1, 6))
    terms = {t.joint: t for t in diagnosis.where.joints_from_all_poses}
    assert not terms[6].observable and terms[6].harmonics_urad is None
    strongest = diagnosis.where.strongest_signature
    assert strongest is None or strongest.joint != 6
    report = tmp_path / "d.md"
    write_report(diagnosis, ladder, cal, report)
    text = report.read_text()
    assert "| 6 | - | not observable (target 0." in text
    assert (tmp_path / "d_map.png").stat().st_size > 10_000  # the residual maps


def test_without_sweeps_the_table_says_why(tmp_path: Path) -> None:
    world = build_world({"seed": 5})
    cal = recorded(world, random_plan(ROBOT, 120, np.random.default_rng(6)), 7)
    diagnosis, ladder = diagnose(cal, ROBOT, tracker_sigma_m=4.8e-6)
    assert diagnosis.where.joints == []
    report = tmp_path / "d.md"
    write_report(diagnosis, ladder, cal, report)
    text = report.read_text()
    assert "No circle sweeps in the recording" in text
    assert "| joint | rms [urad]" not in text
