"""Progress checker: is the robot still getting somewhere? Nav2 ``SimpleProgressChecker`` (and
``PoseProgressChecker`` when ``required_movement_angle`` is set).

The robot must leave a circle of ``required_movement_radius`` around the pose where progress was
last confirmed within ``movement_time_allowance`` seconds; otherwise it is stuck (pushing against an
obstacle, oscillating in place) and the navigator hands over to recovery.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from nav.types import Pose2D, wrap_angle


@dataclass(frozen=True)
class ProgressCheckerOptions:
    """Options of :class:`ProgressChecker` (Nav2 names and defaults)."""

    required_movement_radius: float = 0.5
    """Distance the robot must move to count as progress, m. Nav2 0.5."""
    movement_time_allowance: float = 10.0
    """Time allowed to make that progress, s. Nav2 10.0."""
    required_movement_angle: float | None = None
    """If set, turning this much (rad) also counts as progress (Nav2 ``PoseProgressChecker``, 0.5)."""

    def __post_init__(self) -> None:
        if self.required_movement_radius <= 0 or self.movement_time_allowance <= 0:
            raise ValueError("required_movement_radius and movement_time_allowance must be positive")


class ProgressChecker:
    """``check(pose, now) -> bool``: False once no progress was made for too long."""

    def __init__(self, options: ProgressCheckerOptions | None = None) -> None:
        self.options = options or ProgressCheckerOptions()
        self._baseline: Pose2D | None = None
        self._baseline_time = 0.0

    def reset(self) -> None:
        self._baseline = None

    def check(self, pose: Pose2D, now: float) -> bool:
        o = self.options
        if self._baseline is None or self._moved(pose):
            self._baseline, self._baseline_time = pose, now
            return True
        return now - self._baseline_time <= o.movement_time_allowance

    def time_without_progress(self, now: float) -> float:
        return 0.0 if self._baseline is None else now - self._baseline_time

    def _moved(self, pose: Pose2D) -> bool:
        assert self._baseline is not None
        o = self.options
        if math.hypot(pose.x - self._baseline.x, pose.y - self._baseline.y) > o.required_movement_radius:
            return True
        if o.required_movement_angle is not None:
            return abs(float(wrap_angle(pose.theta - self._baseline.theta))) > o.required_movement_angle
        return False
