"""Layering by imports: the core (measurement model, identification, diagnosis, flows)
never loads a file format or ROS, and each command line verb loads only what it uses
(checked in a fresh interpreter, or a child forked from one, through `sys.modules`; timings
live in benchmarks/bench_startup.py)."""

from __future__ import annotations

import json
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

HEAVY = ("mcap", "mcap_ros2", "rosbags", "rclpy", "scipy", "matplotlib")


def loaded_after(code: str) -> set[str]:
    """The heavy top-level packages in sys.modules after running `code` in a new process."""
    tops = "sorted({m.split('.')[0] for m in sys.modules})"
    probe = f"{code}\nimport json, sys\nprint(json.dumps({tops}))"
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True
    ).stdout
    return set(json.loads(out.strip().splitlines()[-1])) & set(HEAVY)


def core_modules() -> list[str]:
    """Every module of the core packages (measurement model, effects, identification,
    diagnosis, kinematics), the flows and the lazy bag package itself."""
    import robot_calib

    names = ["robot_calib.flows", "robot_calib.bag", "robot_calib.model"]
    for package in ("measurements", "effects", "identify", "diagnosis", "kinematics", "flows"):
        path = [str(Path(robot_calib.__file__).parent / package)]
        names += [f"robot_calib.{package}.{m.name}" for m in pkgutil.iter_modules(path)]
    return names


FORMATS_AND_ROS = {"mcap", "mcap_ros2", "rosbags", "rclpy"}
FORKED = """
import importlib, json, os, sys
# numpy and scipy (none of FORMATS_AND_ROS, checked below) loaded once here, where every
# module's import would load them again: each module is then imported alone in a child
# forked from this interpreter (its own sys.modules), without a new interpreter each
import numpy, scipy.linalg, scipy.optimize, scipy.spatial.transform
tops = lambda: sorted({m.split('.')[0] for m in sys.modules})
results = {'': tops()}
for name in sys.argv[1:]:
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(read)
        try:
            importlib.import_module(name)
            found = tops()
        except BaseException as exc:
            found = {'error': repr(exc)}
        os.write(write, json.dumps(found).encode())
        os._exit(0)
    os.close(write)
    with os.fdopen(read) as pipe:
        results[name] = json.loads(pipe.read())
    os.waitpid(pid, 0)
print(json.dumps(results))
"""


@pytest.fixture(scope="module")
def loaded_by_each_core_module() -> dict[str, list[str]]:
    """{core module: the top-level packages in sys.modules after importing it alone} (in a
    child forked from one new interpreter that loaded numpy and scipy only); '': the
    parent's own."""
    out = subprocess.run(
        [sys.executable, "-c", FORKED, *core_modules()], capture_output=True, text=True, check=True
    ).stdout
    results = json.loads(out.strip().splitlines()[-1])
    assert not set(results[""]) & FORMATS_AND_ROS, results[""]
    return results


@pytest.mark.parametrize("module", core_modules())
def test_the_core_imports_no_file_format_nor_ros(
    module: str, loaded_by_each_core_module: dict[str, list[str]]
) -> None:
    loaded = loaded_by_each_core_module[module]
    assert isinstance(loaded, list), loaded  # the import succeeded
    assert not set(loaded) & FORMATS_AND_ROS


def test_diagnose_does_not_import_the_simulator() -> None:
    diagnose = [m for m in core_modules() if m.startswith("robot_calib.diagnosis.")]
    probe = f"import {', '.join(diagnose)}, sys\n"
    probe += "print([m for m in sys.modules if m.startswith('robot_calib.sim')])"
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"


def test_help_and_reading_a_parameter_file_stay_light() -> None:
    """`--help` and `predict`'s path (the CLI, the light PARAMS.json reader, POINTS.csv)
    import no solver, file format, plotting or ROS."""
    assert not loaded_after("import robot_calib.cli as c; c.build_parser()")
    assert not loaded_after(
        "import robot_calib.identify.params_file, robot_calib.csv_tables, robot_calib.cli"
    )


def test_only_the_command_line_imports_the_command_line() -> None:
    """The command line sits on top: no module outside `robot_calib.cli` imports it (the
    flows, the core and the nodes work without it), but `python -m robot_calib`."""
    from test_import_cycles import PACKAGE, import_graph

    graph = import_graph(PACKAGE)
    assert "robot_calib.cli.registry" in graph["robot_calib.cli"]
    above = {"robot_calib.__main__"}  # `python -m robot_calib`
    importers = {
        module: sorted(t for t in targets if t.split(".")[:2] == ["robot_calib", "cli"])
        for module, targets in graph.items()
        if module.split(".")[:2] != ["robot_calib", "cli"] and module not in above
    }
    assert not {m: t for m, t in importers.items() if t}
