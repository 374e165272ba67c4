"""The calibrator, from bags or live, with RViz showing its result.

    ros2 launch robot_calib calibrator.launch.py bags:="['run.mcap']" diagnose:=true rviz:=true
    ros2 launch robot_calib calibrator.launch.py solve_after_idle_s:=5.0 rviz:=true   # live

Bag mode (`bags` a YAML list of .mcap paths) solves at start; live mode (`bags` empty)
collects /joint_states and /laser_tracker/point and solves on
`ros2 service call /calibrator/solve std_srvs/srv/Trigger`, a message on the topic
/calibrator/solve, or `solve_after_idle_s` after the last point. Results are latched
(msgs_doc/calibrator.md); rviz:=true starts RViz with rviz/robot_calib.rviz (markers of
the identified axes, circles, measured points and residuals, fixed frame laser_tracker).
msgs_doc/launch.md.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import (
    EqualsSubstitution,
    LaunchConfiguration,
    NotEqualsSubstitution,
    PathJoinSubstitution,
)
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

PACKAGE = "robot_calib"


def generate_launch_description() -> LaunchDescription:
    params_file = LaunchConfiguration("params_file")
    bags = LaunchConfiguration("bags")
    # string parameters go through ParameterValue(value_type=str): launch_ros reads a bare
    # launch argument as YAML ('' -> null, which it refuses)
    common = {
        "model": ParameterValue(LaunchConfiguration("model"), value_type=str),
        "robot": ParameterValue(LaunchConfiguration("robot"), value_type=str),
        "output": ParameterValue(LaunchConfiguration("output"), value_type=str),
        "diagnose": LaunchConfiguration("diagnose"),
    }
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "params_file",
                default_value=PathJoinSubstitution(
                    [FindPackageShare(PACKAGE), "config", "robot_calib.yaml"]
                ),
                description="parameters YAML of the nodes (the arguments below win)",
            ),
            DeclareLaunchArgument(
                "bags",
                default_value="",
                description="YAML list of calibration bags, e.g. \"['run.mcap']\"; '' = live mode",
            ),
            DeclareLaunchArgument(
                "model", default_value="geometric", description="model of the ladder to fit"
            ),
            DeclareLaunchArgument(
                "robot", default_value="kr5_sixx_r650", description="built-in robot, YAML, URDF"
            ),
            DeclareLaunchArgument(
                "output", default_value="", description="also write PARAMS.json here"
            ),
            DeclareLaunchArgument(
                "diagnose", default_value="false", description="also run the diagnosis"
            ),
            DeclareLaunchArgument(
                "solve_after_idle_s",
                default_value="0.0",
                description="live: solve this long after the last point [s]; 0 = on request",
            ),
            DeclareLaunchArgument(
                "rviz", default_value="false", description="start RViz with robot_calib.rviz"
            ),
            Node(  # bag mode
                package=PACKAGE,
                executable="calibrator",
                output="screen",
                condition=IfCondition(NotEqualsSubstitution(bags, "")),
                parameters=[params_file, {**common, "bags": bags}],
            ),
            Node(  # live mode (an empty list is no launch_ros parameter value: not passed)
                package=PACKAGE,
                executable="calibrator",
                output="screen",
                condition=IfCondition(EqualsSubstitution(bags, "")),
                parameters=[
                    params_file,
                    {
                        **common,
                        "solve_after_idle_s": LaunchConfiguration("solve_after_idle_s"),
                    },
                ],
            ),
            Node(
                package="rviz2",
                executable="rviz2",
                output="screen",
                condition=IfCondition(LaunchConfiguration("rviz")),
                arguments=[
                    "-d",
                    PathJoinSubstitution([FindPackageShare(PACKAGE), "rviz", "robot_calib.rviz"]),
                ],
            ),
        ]
    )
