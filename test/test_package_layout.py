"""The ament_python layout: `colcon build` installs what `ros2 run` looks up.

`ros2 run robot_calib X` finds the package through the ament index
(share/ament_index/resource_index/packages/robot_calib) and runs lib/robot_calib/X.
"""

from __future__ import annotations

import configparser
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
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
