"""The simulated graph: sim_robot + sim_tracker + recorder, one command.

    ros2 launch robot_calib sim_graph.launch.py plan:=paper-test3 rate:=20.0 output:=run.mcap

sim_robot visits the plan and publishes /joint_states, sim_tracker measures the simulated
target (same world), the recorder writes both topics into `output` (must not exist).
Nothing is lost in any start order: sim_robot starts once its `wait_for_subscribers`
readers of /joint_states are matched (the recorder and sim_tracker: 2; 3 with a live
calibrator), sim_tracker takes /joint_states once the recorder reads its points. When the
plan is done (sim_robot exits), the launch shuts down 1 s later: the recorder closes the bag.
A world with further targets or 6-DoF probes: list their topics in the recorder's `topics`
(params_file). msgs_doc/launch.md.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler, TimerAction
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

PACKAGE = "robot_calib"
LAST_POINTS_S = 1.0  # after sim_robot exits, before the shutdown closes the bag


def generate_launch_description() -> LaunchDescription:
    params_file = LaunchConfiguration("params_file")
    robot = Node(
        package=PACKAGE,
        executable="sim_robot",
        output="screen",
        parameters=[
            params_file,
            {
                "mode": "plan",
                "plan": ParameterValue(LaunchConfiguration("plan"), value_type=str),
                "rate": LaunchConfiguration("rate"),
                "world": ParameterValue(LaunchConfiguration("world"), value_type=str),
                "wait_for_subscribers": LaunchConfiguration("wait_for_subscribers"),
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
                "plan", default_value="paper-test3", description="built-in plan or PLAN.yaml"
            ),
            DeclareLaunchArgument(
                "rate",
                default_value="1.0",
                description="time factor vs the plan's timing (<= 0: one pose per 5 ms)",
            ),
            DeclareLaunchArgument(
                "world", default_value="", description="world YAML ('' = built-in default)"
            ),
            DeclareLaunchArgument(
                "output", default_value="run.mcap", description="bag to write (must not exist)"
            ),
            DeclareLaunchArgument(
                "wait_for_subscribers",
                default_value="2",
                description="/joint_states readers sim_robot waits for (recorder + "
                "sim_tracker; 3 with a live calibrator)",
            ),
            Node(
                package=PACKAGE,
                executable="recorder",
                output="screen",
                parameters=[
                    params_file,
                    {"output": ParameterValue(LaunchConfiguration("output"), value_type=str)},
                ],
            ),
            Node(
                package=PACKAGE,
                executable="sim_tracker",
                output="screen",
                parameters=[
                    params_file,
                    {
                        "world": ParameterValue(LaunchConfiguration("world"), value_type=str),
                        "wait_for_subscribers": 1,
                    },
                ],
            ),
            robot,
            RegisterEventHandler(
                OnProcessExit(
                    target_action=robot,
                    on_exit=[
                        TimerAction(
                            period=LAST_POINTS_S,
                            actions=[EmitEvent(event=Shutdown(reason="plan done"))],
                        )
                    ],
                )
            ),
        ]
    )
