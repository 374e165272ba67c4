"""The calibrator, from bags or live, with RViz showing its result.

    ros2 launch robot_calib calibrator.launch.py bags:="['run.mcap']" diagnose:=true rviz:=true
    ros2 launch robot_calib calibrator.launch.py solve_after_idle_s:=5.0 rviz:=true   # live

Bag mode (`bags` a YAML list of .mcap paths) solves at start; live mode (`bags` empty)
collects /joint_states and /laser_tracker/point and solves on
`ros2 service call /calibrator/solve std_srvs/srv/Trigger`, a message on the topic
/calibrator/solve, or `solve_after_idle_s` after the last point. Results are latched
(msgs_doc/calibrator.md); rviz:=true starts RViz with rviz/robot_calib.rviz (markers of
the identified axes, circles, measured points and residuals, fixed frame laser_tracker).
msgs_doc/launch.md; what it starts: robot_calib/nodes/launch_support.py.
"""

from robot_calib.nodes.launch_support import CALIBRATOR, launch_description


def generate_launch_description():  # -> launch.LaunchDescription
    return launch_description(CALIBRATOR)
