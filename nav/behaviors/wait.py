"""Wait: stand still for a while (Nav2 ``nav2_behaviors::Wait``), e.g. for a person to step aside
or a dynamic obstacle to clear from the costmap."""

from __future__ import annotations

from dataclasses import dataclass

from nav.behaviors.base import BehaviorContext, Status, TimedBehavior, check_non_negative


@dataclass(frozen=True)
class WaitOptions:
    """Nav2 Wait goal fields."""

    wait_duration: float = 5.0
    """How long to wait, s (the BT's ``wait_duration``; Nav2 BT 5.0)."""

    def __post_init__(self) -> None:
        check_non_negative("wait", wait_duration=self.wait_duration)


class Wait(TimedBehavior):
    """Send zero velocity until ``wait_duration`` has passed, then succeed."""

    name = "wait"

    def __init__(self, options: WaitOptions | None = None) -> None:
        self.options = options or WaitOptions()
        super().__init__(self.options.wait_duration)

    def start(self, ctx: BehaviorContext) -> Status:
        self._begin(ctx)
        return self.tick(ctx)

    def tick(self, ctx: BehaviorContext) -> Status:
        self._require_started()
        assert self.started_at is not None
        if ctx.now - self.started_at >= self.options.wait_duration:
            return self._succeed()
        return Status.RUNNING


__all__ = ["Wait", "WaitOptions"]
