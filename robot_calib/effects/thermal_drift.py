"""thermal_drift: link lengths that grow with time since the start of the recording.

Warm-up expands the structure: every a_j and d_j is scaled by (1 + rate * t), with t the
time since the first measurement of the recording (CONTRACT.md). Over a recording of tens
of minutes the warm-up exponential is close to this linear start. It belongs to no joint.
Parameter `thermal_drift_rate` [1/s].
"""

from __future__ import annotations

from robot_calib.effects.base import Contribution, Effect
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses


class ThermalDrift(Effect):
    name = "thermal_drift"

    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        return [Parameter("thermal_drift_rate", "1/s", 0.0, group=self.name)]

    def contribution(
        self, robot: RobotDescription, params: ParameterVector, poses: Poses
    ) -> Contribution:
        jac = poses.time[:, None].astype(float)
        return Contribution(
            length_strain=jac[:, 0] * params["thermal_drift_rate"], length_strain_jac=jac
        )
