"""Feature: the safety filter (robot/safety.py) on every command, right before ``driver.command``.

Installed for every robot, simulated or real: the session applies ``session.safety`` after the speed
and acceleration limits, so nothing a planner, a behaviour or an operator asks can drive the base into
an obstacle its lidar or IR sensors see. Each safety stop (not each slow-down) becomes a ``safety`` run event.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from nav.types import Twist2D
from robot.base import SensorFrame
from robot.safety import SafetyFilter, SafetyOptions, SafetyStatus

if TYPE_CHECKING:
    from app.runtime import Runtime

ORDER = 90


class SafetyFeature:
    """The installed filter; reports changes of its verdict as session events."""

    def __init__(self, runtime: Runtime, options: SafetyOptions | None = None) -> None:
        self.session = runtime.session
        self.filter = SafetyFilter(runtime.profile, options)
        self._last_action: str | None = None

    def __call__(self, cmd: Twist2D, frame: SensorFrame) -> tuple[Twist2D, str | None]:
        out, reason = self.filter(cmd, frame)
        action = self.filter.status.action if reason else None
        if action == "stop" and self._last_action != "stop":  # slow-downs are too frequent to log
            self.session.add_event("safety", action=action, reason=reason)
        self._last_action = action
        return out, reason

    @property
    def status(self) -> SafetyStatus:
        """The filter's verdict on the last command (the navigation stage's safety_stop trigger)."""
        return self.filter.status

    def close(self) -> None:
        if self.session.safety is self:
            self.session.safety = None


def setup(runtime: Runtime) -> SafetyFeature:
    feature = SafetyFeature(runtime)
    runtime.session.safety = feature
    return feature
