"""The program's standard output and error as a shell can leave them: closed (`>&-`,
`2>&-`), full (`/dev/full`) or read by a program that quits early (`2>&1 | head -1`). The
command's work and exit status stay its own, and never a traceback (each ran the real
program, `python -m robot_calib`, in a shell)."""

from __future__ import annotations

import json
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "bags" / "paper_test3.mcap"


def shell(line: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """`line` in bash with `RC` standing for the program; its exit status is the program's
    (pipefail off: PIPESTATUS[0] is printed last on stdout as `status=N`)."""
    program = f"{shlex.quote(sys.executable)} -m robot_calib"
    script = line.replace("RC", program) + '; echo "status=${PIPESTATUS[0]}"'
    return subprocess.run(
        ["bash", "-c", script], cwd=cwd, capture_output=True, text=True, timeout=120
    )


def status(result: subprocess.CompletedProcess[str]) -> int:
    return int(result.stdout.strip().splitlines()[-1].removeprefix("status="))


def test_closed_stdout_writes_the_result_and_exits_0(tmp_path: Path) -> None:
    """`>&-` was an AttributeError traceback and exit 120 (no sys.stdout at all)."""
    result = shell(f"RC calibrate {SAMPLE} -o a.json >&- 2>err.txt", tmp_path)
    assert status(result) == 0, (tmp_path / "err.txt").read_text()
    assert "Traceback" not in (tmp_path / "err.txt").read_text()
    assert json.loads((tmp_path / "a.json").read_text())["plausible"] is True


def test_closed_stderr_is_not_printed_into_stdout(tmp_path: Path) -> None:
    """`2>&-`: the progress lines (stderr's) were printed into standard output among the
    results (print to a missing sys.stderr prints to sys.stdout), and descriptor 2 was free
    for the first file the program opened; now /dev/null holds it and takes them."""
    result = shell(f"RC calibrate {SAMPLE} -o a.json >out.txt 2>&-", tmp_path)
    assert status(result) == 0
    assert json.loads((tmp_path / "a.json").read_text())["plausible"] is True
    out = (tmp_path / "out.txt").read_text()
    assert "identifiability:" in out and "Levenberg-Marquardt" not in out, out


def test_full_stderr_keeps_the_verbs_exit_status(tmp_path: Path) -> None:
    """`2>/dev/full`: a bad input was exit 1 (a traceback nobody could read, of the failed
    error line); it is the verb's 2, and a good run's 0 with its file written."""
    bad = shell("RC calibrate missing.mcap -o b.json 2>/dev/full", tmp_path)
    assert status(bad) == 2
    assert not (tmp_path / "b.json").exists()
    good = shell(f"RC calibrate {SAMPLE} -o c.json 2>/dev/full >/dev/null", tmp_path)
    assert status(good) == 0
    assert json.loads((tmp_path / "c.json").read_text())["plausible"] is True


@pytest.mark.parametrize("verb", ["calibrate", pytest.param("run", marks=pytest.mark.slow)])
def test_a_reader_gone_is_sigpipes_status_and_the_files_are_written(
    verb: str, tmp_path: Path
) -> None:
    """`2>&1 | head -1` and `| true`: the shell's status for a broken pipe (141), no
    traceback in what was read, and the files written as usual (was: calibrate and run
    stopped where they printed and wrote nothing)."""
    for i, pipe in enumerate(("2>&1 | head -1", "| true")):
        out = tmp_path / f"d{i}"
        args = f"calibrate {SAMPLE} -o {out}.json" if verb == "calibrate" else f"run -o {out}"
        result = shell(f"RC {args} {pipe}", tmp_path)
        assert status(result) == 141, result.stderr
        assert "Traceback" not in result.stdout + result.stderr
        if verb == "calibrate":
            assert json.loads(Path(f"{out}.json").read_text())["plausible"] is True
        else:
            assert list(out.glob("run-*/diagnosis.json")), list(out.rglob("*"))


def test_full_stdout_is_one_line_and_2_and_the_files_are_written(tmp_path: Path) -> None:
    result = shell(f"RC calibrate {SAMPLE} -o e.json >/dev/full", tmp_path)
    assert status(result) == 2
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith("robot-calib calibrate: cannot write to standard output"), last
    assert "Traceback" not in result.stderr
    assert json.loads((tmp_path / "e.json").read_text())["plausible"] is True


def loading_numpy(pid: int) -> bool:
    """Whether process `pid` has mapped numpy's core library: robot_calib's start-up
    handlers are in place (robot_calib/__init__.py runs before numpy is imported)."""
    try:
        return "_multiarray_umath" in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


def test_ctrl_c_while_starting_with_a_full_stderr_is_130(tmp_path: Path) -> None:
    """SIGINT while the modules load (numpy mapped, 0-70 ms later), stderr on /dev/full:
    the start-up handler's one line failed inside the handler (OSError) and the import in
    progress got it: exit 1, or the Ctrl-C swallowed; now 130. (A signal during Python's
    own start-up, before robot_calib's first line, is out of its reach: not sent then.)"""
    for i in range(8):
        with open("/dev/full", "w") as full:
            run = subprocess.Popen(
                [sys.executable, "-m", "robot_calib", "calibrate", str(SAMPLE), "-o", f"{i}.json"],
                cwd=tmp_path,
                stdout=subprocess.DEVNULL,
                stderr=full,
                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
            )
            deadline = time.monotonic() + 60
            while not loading_numpy(run.pid) and run.poll() is None:
                assert time.monotonic() < deadline
                time.sleep(0.002)
            time.sleep(0.01 * i)
            run.send_signal(signal.SIGINT)
            assert run.wait(timeout=120) == 130, (i, run.returncode)
        assert not (tmp_path / f"{i}.json").exists()
