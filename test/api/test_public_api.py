"""The public Python API: `import robot_calib` alone is enough to load a robot, simulate,
calibrate, score, diagnose, save and load a calibration and compensate (the example script
docs/examples/python_api.py, run here, with known answers: the backlash model's held-out
error at the noise, the verdict backlash on joint 4); importing it stays light."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import robot_calib as rc

ROOT = Path(__file__).resolve().parents[2]


def test_every_public_name_resolves() -> None:
    for name in rc.__all__:
        assert getattr(rc, name) is not None, name


def test_importing_robot_calib_loads_no_numpy() -> None:
    code = "import sys, robot_calib; print('numpy' in sys.modules, 'scipy' in sys.modules)"
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
        env=dict(os.environ),
    )
    assert out.stdout.split() == ["False", "False"], out.stdout


def test_the_example_script_calibrates_from_python(tmp_path: Path) -> None:
    run = subprocess.run(
        [sys.executable, str(ROOT / "docs/examples/python_api.py"), str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        env=dict(os.environ),
    )
    assert run.returncode == 0, run.stderr[-2000:]
    lines = dict(line.split(": ", 1) for line in run.stdout.splitlines() if ": " in line)
    geometric = float(lines["geometric"].split()[2])
    backlash = float(lines["geometric+backlash:4"].split()[2])
    assert backlash < 0.015 < 0.1 < geometric  # the backlash model at the noise floor
    assert lines["dominant effect"] == "backlash on joints [4]"
    assert "plausible True" in run.stdout and "all reached: True" in run.stdout
    for written in ("run.mcap", "holdout.mcap", "params.json", "diagnosis.json"):
        assert (tmp_path / written).is_file(), written
    # Diagnosis.report: the set `robot-calib diagnose -o DIAGNOSIS.json` writes
    assert "report: DIAGNOSIS.html" in run.stdout
    page = (tmp_path / "DIAGNOSIS.html").read_text()
    assert "backlash" in page and "<html" in page.lower()
    assert (tmp_path / "DIAGNOSIS.md").is_file() and (tmp_path / "DIAGNOSIS.json").is_file()
    best = rc.Calibration.load(tmp_path / "DIAGNOSIS.params_best.json")
    assert best.name == "geometric+backlash:4"
    again = rc.Calibration.load(tmp_path / "params.json")  # written by the script, read here
    assert again.name == "geometric+backlash:4"
    import json

    diagnosis = rc.Diagnosis.from_dict(json.loads((tmp_path / "diagnosis.json").read_text()))
    assert diagnosis.verdict == "backlash on joints [4]"


def test_a_model_name_is_a_value_that_round_trips() -> None:
    spec = rc.ModelSpec.parse("geometric+backlash:4+joint_harmonics:1,2:orders=17,23")
    assert spec.base == "geometric" and spec.effect_names == ("backlash", "joint_harmonics")
    assert str(spec) == "geometric+backlash:4+joint_harmonics:1,2:orders=17,23"
    assert str(rc.ModelSpec.parse("cpa")) == "cpa" and rc.ModelSpec.parse("cpa").terms == ()
    assert spec.added_to(rc.ModelSpec.parse("geometric+backlash:4")) == (
        "joint_harmonics:1,2:orders=17,23"
    )


def test_no_exported_name_is_also_a_submodule() -> None:
    """A submodule named like an API function would replace it once imported (importing
    `robot_calib.x` binds `robot_calib.x` to the module): `rc.diagnose` must stay the
    function after the diagnosis package has loaded."""
    import importlib

    import robot_calib as rc

    package = Path(rc.__file__).parent
    for name in rc.__all__:
        assert not (package / name).is_dir() and not (package / f"{name}.py").exists(), name
    importlib.import_module("robot_calib.diagnosis.ladder")
    importlib.import_module("robot_calib.compensation.solve")
    assert callable(rc.diagnose) and rc.diagnose.__module__ == "robot_calib.api"
    assert callable(rc.compensate) and rc.compensate.__module__ == "robot_calib.api"


def test_importing_the_library_tunes_nothing_and_the_programs_do() -> None:
    """`import robot_calib` (a notebook, the API's simulation importing the nodes' package)
    leaves the environment's BLAS threads and the signal handlers alone; the program
    `robot-calib` and the nodes' programs set one BLAS thread before numpy loads, unless
    the user chose."""
    probe = (
        "import os, signal, sys\n"
        "for v in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):\n"
        "    os.environ.pop(v, None)\n"
        "handlers = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)\n"
        "if len(sys.argv) > 1: sys.argv[0] = sys.argv[1]\n"
        "import robot_calib, robot_calib.nodes\n"
        "same = handlers == (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM))\n"
        "print(os.environ.get('OPENBLAS_NUM_THREADS'), same)\n"
    )

    def run(*argv: str) -> str:
        out = subprocess.run(
            [sys.executable, "-c", probe, *argv], capture_output=True, text=True, check=True
        )
        return out.stdout.strip()

    assert run() == "None True"  # the library: untouched
    assert run("/opt/ros/lib/robot_calib/calibrator") == "1 True"  # a node: one thread
    assert run("/usr/bin/robot-calib") == "1 False"  # the program: its handlers as well


def test_bad_arguments_are_input_errors_naming_the_keyword() -> None:
    """A notebook user's wrong argument is one InputError naming the keyword they typed, not
    a numpy error from deep inside."""
    import numpy as np

    robot = rc.load_robot("kr5_sixx_r650")
    sample = Path(rc.__file__).parents[1] / "bags" / "paper_test3.mcap"
    with pytest.raises(rc.InputError, match=r"^`pair_tolerance=-1(\.0)?`"):
        rc.read_recording(sample, robot=robot, pair_tolerance=-1)
    recording = rc.read_recording(sample, robot=robot)
    with pytest.raises(rc.InputError, match=r"^`ecc_order=0`"):
        rc.calibrate(recording, robot, ecc_order=0)
    with pytest.raises(rc.InputError, match=r"^`model='geometric\+backlash:4\+backlash:4'`"):
        rc.calibrate(recording, robot, model="geometric+backlash:4+backlash:4")
    cal = rc.calibrate(recording, robot)
    with pytest.raises(rc.InputError, match=r"^`q`: joint commands of shape \(n, 6\)"):
        rc.compensate(cal, np.zeros((3, 5)))
    with pytest.raises(rc.InputError, match=r"^`tracker_sigma_m=-0.001`"):
        rc.diagnose(recording, robot, tracker_sigma_m=-1e-3)


def test_a_robot_by_name_and_bags_as_a_list_are_taken_and_wrong_types_said() -> None:
    """What a notebook user types first: the robot's name instead of its description, a
    list of bags; a wrong type is one InputError naming the keyword, never a traceback."""
    sample = Path(rc.__file__).parents[1] / "bags" / "paper_test3.mcap"
    recording = rc.read_recording([sample], robot="kr5_sixx_r650")
    assert len(recording) == 290  # the sample: the seed's Test 3 sweeps
    cal = rc.calibrate(recording, "kr5_sixx_r650")
    assert cal.plausible and cal.recordings == (str(sample),)
    # its own bag: no held-out warning that it does not generalise there
    assert not any("held-out residual" in w for w in cal.score(recording).warnings)
    for call, keyword in [
        (lambda: rc.calibrate(recording, 5), "robot"),
        (lambda: rc.calibrate(recording, "kr5_sixx_r650", model=None), "model"),
        (lambda: rc.calibrate("run.mcap", "kr5_sixx_r650"), "recording"),
        (lambda: rc.diagnose(recording, "kr5_sixx_r650", holdout="x.mcap"), "holdout"),
        (
            lambda: rc.diagnose(recording, "kr5_sixx_r650", tracker_sigma_m="5e-6"),
            "tracker_sigma_m",
        ),
        (lambda: rc.compensate(cal, [[0, 0, 0, 0, 0, "a"]]), "q"),
    ]:
        with pytest.raises(rc.InputError, match=rf"^`{keyword}[`=]"):
            call()


def test_a_robot_program_compensated_from_python(tmp_path: Path) -> None:
    """`rc.compensate_program`: the example FANUC program with its UT/UF given as the
    language's poses; every target compensated, the texts written back and read again."""
    from program_world import program_world

    examples = Path(__file__).resolve().parents[2] / "docs" / "examples" / "programs"
    calibration = program_world("fanuc_tp").calibration
    done = rc.compensate_program(
        calibration,
        examples / "pick_place.ls",
        tools={"1": [0, 0, 200, 0, 0, 0]},
        bases={"1": [800, -300, 200, 0, 0, 20]},
    )
    assert [r.status for r in done.rows] == ["ok"] * 5
    (tmp_path / "pick_place.ls").write_text(done.texts["pick_place.ls"], newline="")
    from robot_calib.programs.registry import language_for

    read = language_for(tmp_path / "pick_place.ls").read(tmp_path / "pick_place.ls")
    for target, row in zip(read.targets, done.rows):  # as written: 3 decimals, 4 for angles
        assert np.allclose(target.values, row.values, atol=5e-4)
    with pytest.raises(rc.InputError, match="`tools`: 1: 6 numbers"):
        rc.compensate_program(calibration, examples / "pick_place.ls", tools={"1": [0, 0]})
