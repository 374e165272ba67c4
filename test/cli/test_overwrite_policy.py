"""Safe in the field: the overwrite policy of every verb holds for
`repair` (--force), `plan` writes YAML only under a YAML name and refuses a floor height
given in mm, and `run -o` in a folder it cannot create or write is one line, exit 2 (was a
NotADirectoryError / PermissionError traceback). Real CLI, as a user runs it."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from cli_runner import cli

BAG = Path(__file__).resolve().parents[2] / "bags" / "paper_test3.mcap"


def one_line_error(proc: object, *needles: str) -> None:
    assert proc.returncode == 2, (proc.stdout, proc.stderr)  # type: ignore[attr-defined]
    err = proc.stderr.strip()  # type: ignore[attr-defined]
    assert "\n" not in err and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err


def test_repair_replaces_an_output_only_with_force(tmp_path: Path) -> None:
    source = tmp_path / "in.mcap"
    shutil.copyfile(BAG, source)
    output = tmp_path / "fixed.mcap"
    output.write_text("old")
    refused = cli("repair", str(source), "-o", str(output))
    one_line_error(refused, "exists; will not overwrite it (use --force)")
    assert output.read_text() == "old"
    forced = cli("repair", str(source), "-o", str(output), "--force")
    assert forced.returncode == 0, forced.stderr
    assert output.read_bytes() != b"old" and output.stat().st_size > 1000
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    same = cli("repair", str(source), "-o", str(source), "--force")  # the input: never
    one_line_error(same, "is the bag to repair")
    assert source.read_bytes() == BAG.read_bytes()


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["-o", "x.mcap"], "x.mcap: a plan is written as YAML: give a .yaml or .yml name"),
        (["--floor-z", "-500", "-o", "p.yaml"], "--floor-z -500: a height in m"),
        (["--floor-z", "nan", "-o", "p.yaml"], "--floor-z nan"),
    ],
)
def test_plan_refuses_a_wrong_format_or_a_floor_in_mm(
    tmp_path: Path, args: list[str], needle: str
) -> None:
    proc = cli("plan", "--poses", "12", "--candidates", "200", *args, cwd=tmp_path)
    one_line_error(proc, needle)
    assert list(tmp_path.iterdir()) == []


def test_plan_takes_a_plausible_floor(tmp_path: Path) -> None:
    proc = cli(
        "plan",
        "--poses",
        "12",
        "--candidates",
        "200",
        "--floor-z",
        "-0.5",
        "-o",
        "p.yml",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    assert "poses:" in (tmp_path / "p.yml").read_text()


def test_run_into_a_path_through_a_file_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "afile").write_text("x")
    proc = cli("run", "-o", "afile/out", cwd=tmp_path)
    one_line_error(proc, "afile/out: afile exists and is not a folder")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only folder")
def test_run_into_a_read_only_folder_is_one_line(tmp_path: Path) -> None:
    folder = tmp_path / "ro"
    folder.mkdir(mode=0o555)
    try:
        proc = cli("run", "-o", "ro", cwd=tmp_path)
        one_line_error(proc, "ro: folder not writable")
        nested = cli("run", "-o", "ro/out", cwd=tmp_path)
        one_line_error(nested, "ro/out: cannot create the output folder (Permission denied)")
    finally:
        folder.chmod(0o755)
