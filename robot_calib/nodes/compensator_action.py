"""The compensator as a FollowJointTrajectory action in front of the controller's.

MoveIt and ros2_control's joint_trajectory_controller talk `control_msgs/action/
FollowJointTrajectory`. With the compensator's parameter `action_controller` set (e.g.
`/joint_trajectory_controller/follow_joint_trajectory`), this adapter serves
`~/follow_joint_trajectory`: each goal's trajectory is compensated exactly as a message on
the input topic (`CompensatorNode.compensated`: the same checks, the same ~/status line),
then sent on as a goal to the controller's action with the goal's tolerances unchanged;
the controller's feedback is relayed, its result returned, and a cancel is passed on. A
goal whose trajectory is dropped is aborted with INVALID_GOAL and the reason; a controller
that is not there aborts it with the action's name.

control_msgs is not installable from the PyPI wheels this repository is developed with:
this module is imported only when the parameter is set, and has not been run here (README,
"Nodes"). package.xml declares control_msgs.
"""

from __future__ import annotations

import copy
from typing import Any

from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup


class FollowJointTrajectoryAdapter:
    """`~/follow_joint_trajectory` on `node`, forwarding compensated goals to
    `controller_action` (module docstring). Raises ImportError without control_msgs."""

    def __init__(self, node: Any, controller_action: str) -> None:  # noqa: ANN401
        # `node`: the CompensatorNode (its `compensated`, `last_error`; typed loosely: the
        # node module imports this one)
        from control_msgs.action import FollowJointTrajectory

        self._node = node
        self._action = FollowJointTrajectory
        group = ReentrantCallbackGroup()  # a goal awaits the controller while others arrive
        self._client = ActionClient(
            node, FollowJointTrajectory, controller_action, callback_group=group
        )
        self._server = ActionServer(
            node,
            FollowJointTrajectory,
            "~/follow_joint_trajectory",
            execute_callback=self._execute,
            goal_callback=lambda _goal: GoalResponse.ACCEPT,
            cancel_callback=self._cancel,
            callback_group=group,
        )
        self.controller_action = controller_action
        self._forwarded: dict[bytes, Any] = {}  # our goal's id -> the controller's goal

    def _cancel(self, goal_handle: Any) -> CancelResponse:  # noqa: ANN401 - rclpy type
        """A cancel of our goal is passed on to the controller's goal (when sent)."""
        forwarded = self._forwarded.get(bytes(goal_handle.goal_id.uuid))
        if forwarded is not None:
            forwarded.cancel_goal_async()
        return CancelResponse.ACCEPT

    def _aborted(self, goal_handle: Any, code: int, text: str) -> Any:  # noqa: ANN401
        goal_handle.abort()
        return self._action.Result(error_code=code, error_string=text)

    async def _execute(self, goal_handle: Any) -> Any:  # noqa: ANN401 - rclpy action types
        """One goal: compensate, forward, relay feedback and the result; cancel passed on."""
        result_type = self._action.Result
        request = goal_handle.request
        where = f"{self._node.get_name()}/follow_joint_trajectory"
        corrected = self._node.compensated(request.trajectory, where)
        if corrected is None:
            return self._aborted(
                goal_handle, result_type.INVALID_GOAL, self._node.last_error or "dropped"
            )
        if not self._client.server_is_ready():  # never block the executor waiting for it
            return self._aborted(
                goal_handle,
                result_type.INVALID_GOAL,
                f"{self.controller_action}: no action server",
            )
        goal = copy.copy(request)
        goal.trajectory = corrected
        sent = await self._client.send_goal_async(
            goal, feedback_callback=lambda msg: goal_handle.publish_feedback(msg.feedback)
        )
        if not sent.accepted:
            return self._aborted(
                goal_handle, result_type.INVALID_GOAL, f"{self.controller_action}: goal rejected"
            )
        key = bytes(goal_handle.goal_id.uuid)
        self._forwarded[key] = sent
        if goal_handle.is_cancel_requested:  # cancelled before the controller accepted it
            sent.cancel_goal_async()
        try:
            outcome = await sent.get_result_async()
        finally:
            self._forwarded.pop(key, None)
        from action_msgs.msg import GoalStatus

        if outcome.status == GoalStatus.STATUS_SUCCEEDED:
            goal_handle.succeed()
        elif outcome.status == GoalStatus.STATUS_CANCELED and goal_handle.is_cancel_requested:
            goal_handle.canceled()
        else:
            goal_handle.abort()
        return outcome.result
