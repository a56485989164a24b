"""Progress checker: is the robot still getting somewhere? Nav2 ``SimpleProgressChecker`` (and
``PoseProgressChecker`` when ``required_movement_angle`` is set).

The robot must leave a circle of ``required_movement_radius`` around the pose where progress was
last confirmed within ``movement_time_allowance`` seconds; otherwise it is stuck (pushing against an
obstacle, oscillating in place) and the navigator hands over to recovery.

Stall window (navdeck, issue 18): a robot whose controller commands standing still while it stands
still, for ``stall_time_allowance`` seconds of following, is stalled: the controller found nothing it
will do (no trajectory it likes towards a gap it will not enter), so waiting the full
``movement_time_allowance`` (and its retries) only delays the recovery. Pushing against something
(commands non-zero, no motion) stays the job of the movement check and of the safety layer's own
time-out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from nav.types import Pose2D, Twist2D, wrap_angle


@dataclass(frozen=True)
class ProgressCheckerOptions:
    """Options of :class:`ProgressChecker` (Nav2 names and defaults)."""

    required_movement_radius: float = 0.5
    """Distance the robot must move to count as progress, m. Nav2 0.5."""
    movement_time_allowance: float = 10.0
    """Time allowed to make that progress, s. Nav2 10.0."""
    required_movement_angle: float | None = None
    """If set, turning this much (rad) also counts as progress (Nav2 ``PoseProgressChecker``, 0.5)."""
    stall_time_allowance: float = 3.0
    """Seconds commanded and measured standing still while following before the robot counts as
    stalled (navdeck); <= 0 disables the check."""
    stall_velocity: float = 0.01
    """Speed (m/s, rad/s) below which a command or a measured velocity counts as standing still."""

    def __post_init__(self) -> None:
        if self.required_movement_radius <= 0 or self.movement_time_allowance <= 0:
            raise ValueError("required_movement_radius and movement_time_allowance must be positive")
        if self.stall_velocity < 0:
            raise ValueError("stall_velocity must be non-negative")


class ProgressChecker:
    """``check(pose, now) -> bool``: False once no progress was made for too long."""

    def __init__(self, options: ProgressCheckerOptions | None = None) -> None:
        self.options = options or ProgressCheckerOptions()
        self._baseline: Pose2D | None = None
        self._baseline_time = 0.0
        self._still_since: float | None = None

    def reset(self) -> None:
        self._baseline = None
        self._still_since = None

    def reset_stall(self) -> None:
        """Restart the stall window only (the robot is not following: planning, stuck)."""
        self._still_since = None

    def stalled(self, command: Twist2D, velocity: Twist2D, now: float) -> bool:
        """Feed one following cycle (the last command sent, the velocity measured now); True once
        both stood still for more than ``stall_time_allowance`` s. ``reset`` restarts the window
        (the navigator resets when it is not following)."""
        o = self.options
        if o.stall_time_allowance <= 0:
            return False
        eps = o.stall_velocity
        values = (command.vx, command.vy, command.wz, velocity.vx, velocity.vy, velocity.wz)
        still = all(abs(v) <= eps for v in values)
        if not still:
            self._still_since = None
            return False
        if self._still_since is None:
            self._still_since = now
        return now - self._still_since > o.stall_time_allowance

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
