"""`robot-calib compensate --program`: the example programs in, compensated programs and
their per-target tables out; bad inputs one line, exit 2, nothing written."""

from __future__ import annotations

import csv
import functools
import shutil
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli
from program_world import program_world

from robot_calib.programs.registry import language_for

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples" / "programs"
FANUC_FRAMES = ("--tool", "1=0,0,200,0,0,0", "--base", "1=800,-300,200,0,0,20")
CASES = {  # language: (main file, the arm of its world, options the program cannot hold)
    "krl": ("pick_place.src", None, ()),
    "rapid": ("pick_place.mod", None, ()),
    "fanuc_tp": ("pick_place.ls", None, FANUC_FRAMES),
    "urscript": ("pick_place.script", "ur5", ()),
}


@functools.cache
def _params(language: str, folder: str) -> Path:
    world = program_world(language, CASES[language][1])
    return world.calibration.save(Path(folder) / f"{language}.json", world.recording)


def _setup(language: str, tmp_path: Path) -> tuple[Path, Path]:
    for path in EXAMPLES.glob("pick_place.*"):
        shutil.copy(path, tmp_path)
    params = tmp_path / "PARAMS.json"
    shutil.copy(_params(language, str(tmp_path.parent)), params)
    return params, tmp_path / CASES[language][0]


@pytest.mark.parametrize("language", sorted(CASES))
def test_compensate_a_program(language: str, tmp_path: Path) -> None:
    params, program = _setup(language, tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    output = out / program.name
    options = CASES[language][2]
    proc = cli("compensate", str(params), "--program", str(program), "-o", str(output), *options)
    assert proc.returncode == 0, proc.stderr
    assert "targets of" in proc.stdout and "compensated" in proc.stdout
    lang = language_for(program)
    read = lang.read(program)
    written = lang.read(output)  # our reader reads what we wrote
    assert [t.name for t in written.targets] == [t.name for t in read.targets]
    with open(out / "pick_place.targets.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert [r["target"] for r in rows] == [t.name for t in read.targets]
    for row, old, new in zip(rows, read.targets, written.targets):
        assert row["status"] == "ok", row
        assert 0.05 < float(row["moved_mm"]) < 2.0  # tenths of a millimetre of correction
        assert old.values != new.values
        if old.kind == "pose":  # the table's change is the written target's, as read back
            was, now = lang.pose_to_base(np.array([old.values, new.values]))
            moved = np.linalg.norm(now[:3, 3] - was[:3, 3]) * 1e3
            cos = (np.trace(was[:3, :3].T @ now[:3, :3]) - 1.0) / 2.0
            turned = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
            assert float(row["moved_mm"]) == pytest.approx(moved, abs=2e-3)  # the decimals
            assert float(row["turned_deg"]) == pytest.approx(turned, abs=2e-4)
    if language == "krl":  # the .dat beside the .src, its line ends kept
        assert (out / "pick_place.dat").read_bytes().count(b"\r\n") == (
            program.with_suffix(".dat").read_bytes().count(b"\r\n")
        )
    # the program's other motions are named, not silently left
    named = {"krl": "XHOME", "rapid": "Offs(pPick", "fanuc_tp": "PR[1]", "urscript": "pose_trans"}
    assert named[language] in proc.stderr


def test_bad_program_inputs_are_one_line_and_write_nothing(tmp_path: Path) -> None:
    params, program = _setup("fanuc_tp", tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    output = str(out / "cal.ls")

    def refused(*args: str, needle: str) -> None:
        proc = cli("compensate", str(params), *args)
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and needle in lines[0], proc.stderr
        assert not list(out.iterdir())

    refused("--program", str(program), "-o", output, needle="UT 1, which pick_place.ls")
    refused("--program", str(program), "-o", output, "--tool", "1=0,0,200", needle="6 numbers")
    refused("--program", str(tmp_path / "none.ls"), "-o", output, needle="no such program")
    refused("--program", str(program), "-o", str(program), "--force", needle="pick_place.ls")
    (tmp_path / "prog.txt").write_text("hello\n")
    refused("--program", str(tmp_path / "prog.txt"), "-o", output, needle="--language")
    refused("--program", str(program), "-o", output, "--unit", "mm", needle="--unit goes with")
    tool = ("--tool", "0,0,0,0,0,0")
    refused("--joints", str(program), "-o", output, *tool, needle="--tool goes with --program")
    broken = tmp_path / "broken.ls"
    broken.write_text(program.read_text().replace("R =", "Q ="))
    refused("--program", str(broken), "-o", output, needle="broken.ls:32: 'Q =")


def test_an_existing_output_is_kept_without_force(tmp_path: Path) -> None:
    params, program = _setup("rapid", tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "cal.mod").write_text("mine\n")
    proc = cli("compensate", str(params), "--program", str(program), "-o", str(out / "cal.mod"))
    assert proc.returncode == 2 and "exists" in proc.stderr
    assert (out / "cal.mod").read_text() == "mine\n"
    assert not (out / "cal.targets.csv").exists()


def test_a_calibration_of_another_robot_or_a_misnamed_output_is_refused(tmp_path: Path) -> None:
    params, program = _setup("krl", tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    abb = _params("rapid", str(tmp_path.parent))
    mod = program.with_suffix(".mod")
    proc = cli("compensate", str(abb), "--program", str(program), "-o", str(out / program.name))
    assert proc.returncode == 2 and "irb2600_12_165 (ABB), not of the KUKA robot" in proc.stderr
    proc = cli("compensate", str(params), "--program", str(program), "-o", str(out / "pp2.src"))
    assert proc.returncode == 2 and "the module is pick_place" in proc.stderr
    proc = cli("compensate", str(params), "--program", str(program), "-o", str(out / "x.mod"))
    assert proc.returncode == 2 and "written as .src" in proc.stderr
    tool = ("--tool", "7=0,0,100,0,0,0")
    proc = cli(
        "compensate", str(params), "--program", str(program), "-o", str(out / program.name), *tool
    )
    assert proc.returncode == 2 and "no target of pick_place.src" in proc.stderr
    assert "TOOL_DATA[7]" in proc.stderr
    assert not list(out.iterdir()) and mod.exists()


def test_a_program_partly_compensated_exits_3_and_says_which(tmp_path: Path) -> None:
    params, program = _setup("rapid", tmp_path)
    text = program.read_text()
    far = "CONST robtarget pFar:=[[3500,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];"
    text = text.replace("    PROC main()", f"    {far}\r\n    PROC main()")
    text = text.replace(
        "        MoveC pVia", "        MoveJ pFar, v100, fine, gripper;\r\n        MoveC pVia"
    )
    program.write_text(text, newline="")
    out = tmp_path / "out"
    out.mkdir()
    proc = cli("compensate", str(params), "--program", str(program), "-o", str(out / program.name))
    assert proc.returncode == 3, proc.stderr
    assert "1 of its 6 targets could not be compensated" in proc.stderr
    assert "pFar (pick_place.mod:" in proc.stderr
    with open(out / "pick_place.targets.csv", newline="") as stream:
        rows = {r["target"]: r for r in csv.DictReader(stream)}
    assert rows["pFar"]["status"] == "not_reached" and rows["pFar"]["error_um"] == ""
    assert rows["pPick"]["status"] == "ok" and rows["pPick"]["tool"] == "gripper"
    assert rows["pPick"]["base"] == "fixture"
