"""Goal checker: has the robot reached its goal pose? Nav2 ``nav2_controller::SimpleGoalChecker``
(and ``StoppedGoalChecker`` when ``check_stopped``).

Stateful like Nav2's: once the position is inside ``xy_goal_tolerance`` it stays satisfied while the
robot turns in place, so the small drift of a skid-steer base rotating does not undo it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from nav.types import Pose2D, Twist2D, wrap_angle


@dataclass(frozen=True)
class GoalCheckerOptions:
    """Options of :class:`GoalChecker` (Nav2 names and defaults)."""

    xy_goal_tolerance: float = 0.25
    """Distance to the goal position that counts as reached, m. Nav2 0.25."""
    yaw_goal_tolerance: float = 0.25
    """Heading error that counts as reached, rad. Nav2 0.25."""
    stateful: bool = True
    """Once the position is reached, only the heading is checked until ``reset``. Nav2 True."""
    check_stopped: bool = False
    """Also require the robot to be (nearly) stopped (Nav2 ``StoppedGoalChecker``)."""
    trans_stopped_velocity: float = 0.25
    """Speed under which the robot counts as stopped, m/s. Nav2 0.25."""
    rot_stopped_velocity: float = 0.25
    """Angular speed under which the robot counts as stopped, rad/s. Nav2 0.25."""

    def __post_init__(self) -> None:
        if self.xy_goal_tolerance <= 0 or self.yaw_goal_tolerance <= 0:
            raise ValueError("goal tolerances must be positive")


class GoalChecker:
    """``is_goal_reached(pose, goal, velocity)``; ``reset()`` when a new goal starts."""

    def __init__(self, options: GoalCheckerOptions | None = None) -> None:
        self.options = options or GoalCheckerOptions()
        self._xy_latched = False

    def reset(self) -> None:
        self._xy_latched = False

    @property
    def position_latched(self) -> bool:
        """The goal's position was reached (stateful checker): only its heading is left."""
        return self.options.stateful and self._xy_latched

    def xy_reached(self, pose: Pose2D, goal: Pose2D) -> bool:
        o = self.options
        if o.stateful and self._xy_latched:
            return True
        inside = math.hypot(pose.x - goal.x, pose.y - goal.y) <= o.xy_goal_tolerance
        if inside and o.stateful:
            self._xy_latched = True
        return inside

    def is_goal_reached(self, pose: Pose2D, goal: Pose2D, velocity: Twist2D | None = None) -> bool:
        o = self.options
        if not self.xy_reached(pose, goal):
            return False
        if abs(float(wrap_angle(goal.theta - pose.theta))) > o.yaw_goal_tolerance:
            return False
        if o.check_stopped and velocity is not None:
            return (
                math.hypot(velocity.vx, velocity.vy) <= o.trans_stopped_velocity
                and abs(velocity.wz) <= o.rot_stopped_velocity
            )
        return True

    def tolerances(self) -> tuple[float, float]:
        """(xy, yaw) tolerances, as Nav2's ``getTolerances``."""
        return self.options.xy_goal_tolerance, self.options.yaw_goal_tolerance
