"""Feature: the safety filter (robot/safety.py) on every command, right before ``driver.command``.

Installed for every robot, simulated or real: the session applies ``session.safety`` after the speed
and acceleration limits, so nothing a planner, a behaviour or an operator asks can drive the base into
an obstacle its lidar or IR sensors see. Each safety stop (not each slow-down) becomes a ``safety`` run event.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from nav.types import Twist2D
from robot.base import SensorFrame
from robot.safety import SafetyFilter, SafetyOptions, SafetyStatus

if TYPE_CHECKING:
    from app.runtime import Runtime
    from app.session import Session

CONTACT_HOLD = 0.5
"""s; the robot counts as in contact this long after the last contact report (a frame reports one
only while something is being pushed), so the dashboard does not flicker."""

ORDER = 90


class SafetyFeature:
    """The installed filter; reports changes of its verdict as session events."""

    def __init__(self, runtime: Runtime, options: SafetyOptions | None = None) -> None:
        self.session = runtime.session
        self.filter = SafetyFilter(runtime.profile, options, lidar=runtime.session.has_lidar)
        self._last_action: str | None = None
        self._contact_at = -math.inf  # when the base last reported a contact
        self._contact_with: str | None = None

    def __call__(self, cmd: Twist2D, frame: SensorFrame) -> tuple[Twist2D, str | None]:
        out, reason = self.filter(cmd, frame)
        action = self.filter.status.action if reason else None
        if action == "stop" and self._last_action != "stop":  # slow-downs are too frequent to log
            self.session.add_event("safety", action=action, reason=reason)
        self._last_action = action
        return out, reason

    # ------------------------------------------------------------------ stage: the contact report
    def tick(self, session: Session, frame: SensorFrame, now: float) -> None:
        if frame.collision:
            self._contact_at = now
            self._contact_with = getattr(session.driver, "collision_with", None)

    def snapshot_fields(self, session: Session) -> dict[str, Any]:
        return {"extras": {"contact": self.contact(session.clock.now())}}

    def contact(self, now: float) -> dict[str, Any]:
        """Telemetry ``contact``: whether the base is touching something (it reported a contact in
        the last ``CONTACT_HOLD`` s), with what (``obstacle``, ``person:<id>`` or null when the
        base does not say), the nearest reading's distance to the footprint, and which elementary
        motions the readings leave room for (``free``: forward / back / turn left / turn right)."""
        in_contact = now - self._contact_at <= CONTACT_HOLD
        nearest = self.filter.nearest_reading(now)
        return {
            "in_contact": in_contact,
            "with": self._contact_with if in_contact else None,
            "nearest_m": round(nearest, 3) if math.isfinite(nearest) else None,
            "free": self.filter.free_motions(now) if in_contact else None,
        }

    @property
    def status(self) -> SafetyStatus:
        """The filter's verdict on the last command (the navigation stage's safety_stop trigger)."""
        return self.filter.status

    def close(self) -> None:
        if self.session.safety is self:
            self.session.safety = None
        if self in self.session.stages:
            self.session.stages.remove(self)


def setup(runtime: Runtime) -> SafetyFeature:
    feature = SafetyFeature(runtime)
    runtime.session.safety = feature
    runtime.session.add_stage(feature)
    return feature
