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


@dataclass(frozen=True)
class WaitForWalkerOptions:
    """How long to wait for a walker to leave the path."""

    max_wait: float = 10.0
    """Seconds after which the wait fails with the walker still on the path (the next failure then
    runs the recovery list), s."""

    clear_time: float = 1.0
    """Seconds the path must stay clear before the wait succeeds: a walker that turns or pauses
    drops out of tracking (below ``PERSON_MIN_SPEED``) for a scan or two, s."""

    def __post_init__(self) -> None:
        check_non_negative("wait_for_walker", max_wait=self.max_wait, clear_time=self.clear_time)


class WaitForWalker(TimedBehavior):
    """Nav2's ``Wait``, ended by the walker rather than the clock: send zero velocity while
    ``ctx.walker_on_path()`` says a tracked walker stands on the path ahead; succeed once it has
    been gone for ``clear_time`` s, fail after ``max_wait`` s (or at once without a walker
    predicate in the context)."""

    name = "wait_for_walker"

    def __init__(self, options: WaitForWalkerOptions | None = None) -> None:
        self.options = options or WaitForWalkerOptions()
        super().__init__(self.options.max_wait)
        self._seen_at = 0.0  # when a walker was last on the path

    def start(self, ctx: BehaviorContext) -> Status:
        self._begin(ctx)
        self._seen_at = ctx.now
        if ctx.walker_on_path is None:
            return self._fail("wait_for_walker: no walker tracking in the context")
        return self.tick(ctx)

    def tick(self, ctx: BehaviorContext) -> Status:
        self._require_started()
        assert ctx.walker_on_path is not None
        if ctx.walker_on_path():
            self._seen_at = ctx.now
        elif ctx.now - self._seen_at >= self.options.clear_time:
            return self._succeed()
        if self._timed_out(ctx):
            return self._fail(
                f"wait_for_walker: a walker still on the path after {self.options.max_wait:g} s"
            )
        return Status.RUNNING


__all__ = ["Wait", "WaitForWalker", "WaitForWalkerOptions", "WaitOptions"]
