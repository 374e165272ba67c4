"""A measurement campaign on a real robot: capture (+ a recorder of the raw streams).

    ros2 launch robot_calib capture.launch.py plan:=plan.yaml output:=campaign.mcap \
        controller:=joint_trajectory_controller robot:=ur10 dry_run:=true   # look first
    ros2 launch robot_calib capture.launch.py plan:=plan.yaml output:=campaign.mcap \
        robot:=ur10 record_raw:=true

capture drives the robot through `plan` via /<controller>/joint_trajectory, waits for
/joint_states to settle, takes the tracker's point (or calls `trigger_service`) and writes
one pair per pose into `output` (msgs_doc/capture.md). With record_raw:=true a recorder also
writes the raw /joint_states and /laser_tracker/point streams into `raw_output`. The
controller and the tracker driver are yours (for a simulated controller: sim_robot
-p mode:=controller). When capture ends, the launch shuts down: the bags are closed.
msgs_doc/launch.md.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.conditions import IfCondition
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

PACKAGE = "robot_calib"


def generate_launch_description() -> LaunchDescription:
    # string parameters go through ParameterValue(value_type=str): launch_ros reads a bare
    # launch argument as YAML ('' -> null, refused; approach '0' -> an integer)
    params_file = LaunchConfiguration("params_file")
    capture = Node(
        package=PACKAGE,
        executable="capture",
        output="screen",
        parameters=[
            params_file,
            {
                "plan": ParameterValue(LaunchConfiguration("plan"), value_type=str),
                "output": ParameterValue(LaunchConfiguration("output"), value_type=str),
                "controller": ParameterValue(LaunchConfiguration("controller"), value_type=str),
                "robot": ParameterValue(LaunchConfiguration("robot"), value_type=str),
                "trigger_service": ParameterValue(
                    LaunchConfiguration("trigger_service"), value_type=str
                ),
                "approach": ParameterValue(LaunchConfiguration("approach"), value_type=str),
                "dry_run": LaunchConfiguration("dry_run"),
            },
        ],
    )
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
                "plan", description="PLAN.yaml of robot-calib plan (or a built-in plan)"
            ),
            DeclareLaunchArgument(
                "output", description="campaign bag .mcap (resumed if it exists)"
            ),
            DeclareLaunchArgument(
                "controller",
                default_value="joint_trajectory_controller",
                description="commands go to /<controller>/joint_trajectory",
            ),
            DeclareLaunchArgument(
                "robot",
                default_value="",
                description="built-in robot, YAML or URDF ('' = the PLAN.yaml's robot)",
            ),
            DeclareLaunchArgument(
                "trigger_service",
                default_value="",
                description="std_srvs/Trigger of the tracker driver ('' = next point)",
            ),
            DeclareLaunchArgument(
                "approach", default_value="0", description="approach side: +, -, 0 or per joint"
            ),
            DeclareLaunchArgument(
                "dry_run", default_value="false", description="log the moves, move nothing"
            ),
            DeclareLaunchArgument(
                "record_raw",
                default_value="false",
                description="also record the raw /joint_states and /laser_tracker/point",
            ),
            DeclareLaunchArgument(
                "raw_output", default_value="raw.mcap", description="bag of the raw streams"
            ),
            capture,
            Node(
                package=PACKAGE,
                executable="recorder",
                output="screen",
                condition=IfCondition(LaunchConfiguration("record_raw")),
                parameters=[
                    params_file,
                    {"output": ParameterValue(LaunchConfiguration("raw_output"), value_type=str)},
                ],
            ),
            RegisterEventHandler(
                OnProcessExit(
                    target_action=capture,
                    on_exit=[EmitEvent(event=Shutdown(reason="capture ended"))],
                )
            ),
        ]
    )
