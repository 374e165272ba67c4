"""Compensated robot programs driven through the true simulated robot: for each language,
a program of 50 targets (axis and Cartesian, with a tool and a base frame) taught on the
nominal model of a vendor arm whose truth has backlash and gravity compliance."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from program_world import drive, frame_options, program_world, taught

from robot_calib.compensation.program import compensate_program
from robot_calib.compensation.solve import nominal_counterpart
from robot_calib.ik import solve_ik
from robot_calib.poses import Poses
from robot_calib.programs.registry import language_for

LANGUAGES = ("krl", "rapid", "fanuc_tp", "urscript")


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(a**2)))


@pytest.mark.parametrize("name", LANGUAGES)
def test_compensated_program_reaches_what_the_program_meant(name: str, tmp_path: Path) -> None:
    world = program_world(name)
    language = language_for("x", name)
    taught_program, path = taught(name, tmp_path)
    program = language.read(path)
    assert [t.kind for t in program.targets].count("pose") == 25
    tools, bases = frame_options(name, taught_program)
    result = compensate_program(world.calibration, program, language, tools, bases)
    assert all(row.status == "ok" for row in result.rows), [r.reason for r in result.rows]
    out = tmp_path / "out"
    out.mkdir()
    for file, text in result.texts.items():
        (out / file).write_bytes(text.encode())
    compensated = language.read(out / path.name)  # our own reader reads what we wrote
    tool, base = taught_program.tool2flange, taught_program.base2robot
    before = drive(language, program, taught_program.q, world.world, tool, base)
    after = drive(language, compensated, taught_program.q, world.world, tool, base)
    meant = taught_program.meant[:, :3, 3]
    miss_before = np.linalg.norm(before[:, :3, 3] - meant, axis=1)
    miss_after = np.linalg.norm(after[:, :3, 3] - meant, axis=1)
    held_out = world.held_out_rms_m
    assert 8e-6 < held_out < 30e-6  # the calibration is good to the tracker's noise
    assert _rms(miss_before) > 10 * held_out  # the nominal program misses by 10-40 x
    assert _rms(miss_after) < 1.5 * held_out
    assert miss_after.max() < 3 * held_out  # `drive`: on each target's configuration


@pytest.mark.parametrize("name", LANGUAGES)
def test_compensation_changes_nothing_but_target_numbers(name: str, tmp_path: Path) -> None:
    world = program_world(name)
    language = language_for("x", name)
    taught_program, path = taught(name, tmp_path, n=12)
    program = language.read(path)
    tools, bases = frame_options(name, taught_program)
    result = compensate_program(world.calibration, program, language, tools, bases)
    for file, text in program.texts.items():
        new = result.texts[file]
        spans = sorted(
            (s.start, s.end) for t in program.targets for s in t.spans if s.file == file
        )
        assert (new != text) == bool(spans)  # a KRL .src holds no numbers: unchanged
        kept, at = [], 0
        for start, end in spans:
            kept.append(text[at:start])
            at = end
        kept.append(text[at:])
        # every piece between target numbers appears, in order, in the new text
        position = 0
        for piece in kept:
            found = new.find(piece, position)
            assert found >= position, piece
            position = found + len(piece)
        assert text.count("\r\n") == new.count("\r\n")


def _edge_program(folder: Path, a4_deg: float) -> Path:
    """A KRL program: an axis target, then P1 (with S and T) at axes whose A4 is
    `a4_deg`, on the KR 16's nominal model."""
    language = language_for("x", "krl")
    robot = program_world("krl").calibration.model.robot
    q = np.radians([[10.0, -80.0, 100.0, a4_deg, 40.0, 30.0]])
    values = language.base_to_pose(robot.nominal_frames(q)[:, -1], np.zeros((1, 6)))[0]
    s, t = language.configuration(robot, q)[0]  # type: ignore[misc]
    numbers = ",".join(f"{k} {v:.6f}" for k, v in zip("XYZABC", values))
    folder.mkdir(exist_ok=True)
    (folder / "edge.src").write_text(
        "DEF edge()\nPTP {A1 10,A2 -80,A3 100,A4 0,A5 40,A6 30}\nPTP XP1\nEND\n"
    )
    (folder / "edge.dat").write_text(
        f"DEFDAT edge\nDECL E6POS XP1={{{numbers},S {s},T {t}}}\nENDDAT\n"
    )
    return folder / "edge.src"


def test_a_target_whose_compensation_flips_a_turn_bit_is_left_and_marked(tmp_path: Path) -> None:
    """KUKA's T bit 3 says A4 < 0. A target taught at A4 just below 0 that compensation
    moves above 0 cannot keep its T: left as it was, marked, never rewritten with a T the
    controller would turn A4 a whole turn for."""
    world = program_world("krl")
    language = language_for("x", "krl")
    probe = language.read(_edge_program(tmp_path / "probe", 0.5))
    moved = compensate_program(world.calibration, probe, language)
    new = np.array(moved.rows[1].values)  # how compensating moves A4 there
    goal = language.pose_to_base(new[None])
    q0 = np.radians([[10.0, -80.0, 100.0, 0.5, 40.0, 30.0]])
    model, params = nominal_counterpart(world.calibration.model, world.calibration.parameters)
    q_cal = solve_ik(model, params, Poses.from_readings(q0), goal, np.eye(4), tolerance_m=1e-12).q
    delta = float(np.degrees(q_cal[0, 3] - q0[0, 3]))
    assert abs(delta) > 1e-3  # compensating moves A4 measurably
    edge = language.read(_edge_program(tmp_path / "edge", -delta / 2))  # crosses 0
    result = compensate_program(world.calibration, edge, language)
    row = result.rows[1]
    assert row.status == "configuration", row
    assert row.values == edge.targets[1].values and "configuration" in row.reason
    assert result.texts["edge.dat"] == edge.texts["edge.dat"]
    away = language.read(_edge_program(tmp_path / "away", delta / 2))  # stays on its side
    assert compensate_program(world.calibration, away, language).rows[1].status == "ok"


def test_a_target_out_of_reach_is_left_and_marked(tmp_path: Path) -> None:
    world = program_world("rapid")
    language = language_for("x", "rapid")
    (tmp_path / "far.mod").write_text(
        "MODULE far\n"
        "  CONST robtarget p1:=[[3500,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
        "  PROC main()\n    MoveJ p1, v100, fine, tool0;\n  ENDPROC\nENDMODULE\n"
    )
    program = language.read(tmp_path / "far.mod")
    result = compensate_program(world.calibration, program, language)
    (row,) = result.rows
    assert row.status == "not_reached"  # no nominal solution at all
    assert "out of the nominal arm's reach" in row.reason
    assert result.texts == program.texts


def test_a_program_whose_every_target_is_left_writes_it_unchanged(tmp_path: Path) -> None:
    world = program_world("urscript")
    language = language_for("x", "urscript")
    (tmp_path / "s.script").write_text(
        "def s():\n  a = p[0.4, 0.1, 0.3, 0, 3.14, 0]\n  a[2] = 0.6\n  movel(a)\nend\n"
    )
    program = language.read(tmp_path / "s.script")
    result = compensate_program(world.calibration, program, language)
    assert [r.status for r in result.rows] == ["left"]
    assert result.texts == program.texts
