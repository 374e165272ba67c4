"""The simulated graph: sim_robot + sim_tracker + recorder, one command.

    ros2 launch robot_calib sim_graph.launch.py plan:=paper-test3 rate:=20.0 output:=run.mcap

sim_robot visits the plan and publishes /joint_states, sim_tracker measures the simulated
target (same world), the recorder writes both topics into `output` (must not exist).
Nothing is lost in any start order: sim_robot starts once its `wait_for_subscribers`
readers of /joint_states are matched (the recorder and sim_tracker: 2; 3 with a live
calibrator), sim_tracker takes /joint_states once the recorder reads its points. When the
plan is done (sim_robot exits), the launch shuts down 1 s later: the recorder closes the bag.
A world with further targets or 6-DoF probes: list their topics in the recorder's `topics`
(params_file). msgs_doc/launch.md; what it starts: robot_calib/nodes/launch_support.py.
"""

from robot_calib.nodes.launch_support import SIM_GRAPH, launch_description


def generate_launch_description():  # -> launch.LaunchDescription
    return launch_description(SIM_GRAPH)
