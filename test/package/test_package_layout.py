"""The ament_python layout: `colcon build` installs what `ros2 run` looks up.

`ros2 run robot_calib X` finds the package through the ament index
(share/ament_index/resource_index/packages/robot_calib) and runs lib/robot_calib/X.
"""

from __future__ import annotations

import ast
import configparser
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
ROS_DEPENDENCIES = {
    "rclpy",
    "sensor_msgs",
    "geometry_msgs",
    "std_msgs",
    "diagnostic_msgs",
    "visualization_msgs",
    "python3-numpy",
    "python3-scipy",
    "python3-yaml",
}
ROS_SUFFIXES = ("_msgs", "_srvs", "_interfaces")
# 'sensor_msgs/msg/JointState': a type name that code turns into an import at run time.
TYPE_NAME = re.compile(r"^([a-z][a-z0-9_]*)/(msg|srv|action)/[A-Z]\w*$")
# A file a package.xml comment names (requirements.txt, test/package/test_package_layout.py, ...).
FILE_NAME = re.compile(r"[\w./-]+\.(?:txt|py|md|yaml|cfg|toml|xml)\b")


def is_ros_package(name: str) -> bool:
    return name == "rclpy" or name.endswith(ROS_SUFFIXES)


def ros_packages_used(root: Path) -> dict[str, str]:
    """ROS packages the code under `root` imports (or names as 'pkg/msg/Type'), each with
    the first file that does."""
    found: dict[str, str] = {}
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                match = TYPE_NAME.match(node.value)
                names = [match.group(1)] if match else []
            for name in names:
                top = name.split(".")[0]
                if is_ros_package(top):
                    found.setdefault(top, str(path.relative_to(REPO)))
    return found


def package_xml_depends() -> set[str | None]:
    root = ET.parse(REPO / "package.xml").getroot()
    return {e.text for e in root if e.tag in ("depend", "exec_depend")}


def console_scripts(site_packages: Path) -> set[str]:
    """Console-script names recorded in the egg-info that colcon installed."""
    parser = configparser.ConfigParser()
    parser.read(next(site_packages.glob("robot_calib-*.egg-info")) / "entry_points.txt")
    return set(parser["console_scripts"])


def test_package_xml_declares_ros_dependencies() -> None:
    root = ET.parse(REPO / "package.xml").getroot()
    assert root.get("format") == "3"
    assert root.findtext("name") == "robot_calib"
    depends = {e.text for e in root if e.tag in ("depend", "exec_depend")}
    assert depends >= ROS_DEPENDENCIES
    assert root.find("export/build_type").text == "ament_python"


def test_package_xml_declares_every_ros_package_the_code_imports() -> None:
    used = ros_packages_used(REPO / "robot_calib")
    # The scan itself: the client library and the interface packages the nodes import.
    assert {"rclpy", "rcl_interfaces", "rosgraph_msgs", "sensor_msgs"} <= set(used)
    missing = {name: where for name, where in used.items() if name not in package_xml_depends()}
    assert not missing, f"package.xml lacks <exec_depend> for {missing}"


def test_package_xml_comments_name_only_existing_files() -> None:
    text = (REPO / "package.xml").read_text()
    comments = " ".join(re.findall(r"<!--(.*?)-->", text, flags=re.DOTALL))
    assert "requirements-ros.txt" not in comments
    named = FILE_NAME.findall(comments)
    assert "requirements.txt" in named  # where the pip-only dependencies are pinned
    for name in named:
        assert (REPO / name).is_file(), f"package.xml names {name}, which does not exist"


def test_colcon_build_installs_executables_and_ament_index(tmp_path: Path) -> None:
    colcon = Path(sys.executable).with_name("colcon")
    result = subprocess.run(
        [
            str(colcon),
            "--log-base",
            str(tmp_path / "log"),
            "build",
            "--base-paths",
            str(REPO),
            "--packages-select",
            "robot_calib",
            "--build-base",
            str(tmp_path / "build"),
            "--install-base",
            str(tmp_path / "install"),
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    prefix = tmp_path / "install" / "robot_calib"
    assert (prefix / "share/ament_index/resource_index/packages/robot_calib").is_file()
    assert (prefix / "share/robot_calib/package.xml").is_file()
    site_packages = next((prefix / "lib").glob("python3*/site-packages"))
    scripts = console_scripts(site_packages)
    assert "robot-calib" in scripts
    for script in scripts:
        exe = prefix / "lib" / "robot_calib" / script
        assert exe.is_file() and os.access(exe, os.X_OK), f"missing executable {exe}"
    assert (site_packages / "robot_calib/kinematics/robots/kr5_sixx_r650.yaml").is_file()
    # what `ros2 launch robot_calib ...` finds: launch files, parameters, RViz
    share = prefix / "share" / "robot_calib"
    for folder, pattern in (("launch", "*.launch.py"), ("config", "*.yaml"), ("rviz", "*.rviz")):
        files = sorted(p.name for p in (REPO / folder).glob(pattern))
        assert files, folder
        installed = sorted(p.name for p in (share / folder).iterdir())
        assert installed == files, folder
        for name in files:
            assert (share / folder / name).read_bytes() == (REPO / folder / name).read_bytes()


def test_the_node_programs_are_setups_console_scripts() -> None:
    """`robot_calib.NODE_PROGRAMS` (the programs tuned at start-up) are the nodes setup.py
    installs, no more, no fewer."""
    import ast

    import robot_calib

    tree = ast.parse((REPO / "setup.py").read_text())
    nodes = next(
        ast.literal_eval(n.value)
        for n in ast.walk(tree)
        if isinstance(n, ast.Assign) and getattr(n.targets[0], "id", "") == "NODES"
    )
    assert sorted(nodes) == sorted(robot_calib.NODE_PROGRAMS)
