"""ament_python package: `colcon build` installs the node executables in lib/robot_calib."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "robot_calib"
NODES = ["sim_robot", "sim_tracker", "recorder", "replay", "calibrator", "compensator", "capture"]

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    package_data={PACKAGE: ["kinematics/robots/*.yaml", "sim/worlds/*.yaml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/msgs_doc", glob("msgs_doc/*.md")),
        # `ros2 launch robot_calib X.launch.py` and the files it loads (msgs_doc/launch.md)
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/rviz", glob("rviz/*.rviz")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="robot_calib developers",
    maintainer_email="dev@robot-calib.invalid",
    description="Laser-tracker calibration of 6-axis robots and sim-to-real gap diagnosis",
    license="MIT",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "robot-calib = robot_calib.cli:run",
            *[f"{node} = robot_calib.nodes.{node}:main" for node in NODES],
        ],
    },
)
