"""Compensated robot programs driven through the true simulated robot: for each language,
a program of 50 targets (axis and Cartesian, with a tool and a base frame) taught on the
nominal model of a vendor arm whose truth has backlash and gravity compliance."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from program_world import drive, frame_options, program_world, taught

from robot_calib.compensation.program import compensate_program
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
    before = drive(language, program, taught_program.q, world, tool, base)
    after = drive(language, compensated, taught_program.q, world, tool, base)
    meant = taught_program.meant[:, :3, 3]
    miss_before = np.linalg.norm(before[:, :3, 3] - meant, axis=1)
    miss_after = np.linalg.norm(after[:, :3, 3] - meant, axis=1)
    held_out = world.held_out_rms_m
    assert 8e-6 < held_out < 30e-6  # the calibration is good to the tracker's noise
    assert _rms(miss_before) > 10 * held_out  # the nominal program misses by 10-40 x
    assert _rms(miss_after) < 1.5 * held_out
    assert miss_after.max() < 3 * held_out
    if language.configuration is not None:  # the controller keeps the taught configuration
        kept = [t.configuration for t in compensated.targets if t.kind == "pose"]
        assert kept == [t.configuration for t in program.targets if t.kind == "pose"]


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


def test_a_target_on_a_configuration_boundary_is_left_and_marked(tmp_path: Path) -> None:
    world = program_world("krl")
    language = language_for("x", "krl")
    robot = world.calibration.model.robot
    q = np.radians([[10.0, -80.0, 100.0, 0.00005, 40.0, 30.0]])  # A4 a hair above 0
    flange = robot.nominal_frames(q)[0, -1]
    values = language.base_to_pose(flange[None], np.zeros((1, 6)))[0]
    s, t = language.configuration(robot, q)[0]  # type: ignore[misc]
    numbers = ",".join(f"{k} {v:.6f}" for k, v in zip("XYZABC", values))
    (tmp_path / "edge.src").write_text(
        "DEF edge()\nPTP {A1 10,A2 -80,A3 100,A4 0,A5 40,A6 30}\nPTP P1\nEND\n"
    )
    (tmp_path / "edge.dat").write_text(
        f"DEFDAT edge\nDECL E6POS P1={{{numbers},S {s},T {t}}}\nENDDAT\n"
    )
    program = language.read(tmp_path / "edge.src")
    result = compensate_program(world.calibration, program, language)
    row = next(r for r in result.rows if r.target.name == "P1")
    if row.status == "configuration":  # compensating A4 by more than 0.00005 deg flips T
        assert row.values == program.targets[1].values
        assert "configuration" in row.reason
        assert result.texts["edge.dat"] == program.texts["edge.dat"]
    else:  # the compensation kept A4 above 0: then T is kept too
        assert row.status == "ok"


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
    assert row.status == "configuration"  # no nominal solution at all
    assert "no solution" in row.reason
    assert result.texts == program.texts
