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
msgs_doc/launch.md; what it starts: robot_calib/nodes/launch_support.py.
"""

from robot_calib.nodes.launch_support import CAPTURE, launch_description


def generate_launch_description():  # -> launch.LaunchDescription
    return launch_description(CAPTURE)
