"""Recovery policy: what the navigator does when navigation fails, as Nav2's default behaviour tree
``navigate_to_pose_w_replanning_and_recovery.xml`` does it.

That tree wraps navigation in a ``RecoveryNode`` with ``number_of_retries`` 6 whose recovery branch
is a ``RoundRobin`` over clear costmaps -> spin -> wait -> back up: each failure runs the *next*
recovery in the list (not the whole list), then navigation is retried; after the retry budget is
spent the goal is aborted. navdeck keeps that shape with an explicit ordered list
(clear local -> clear global -> spin -> wait -> back up by default), a per-trigger override (a robot
that is lost should spin until its scan matches the map again, source A, rather than clear
costmaps), and a structured event for every attempt and every result so each becomes a run event.

Pure state machine: the navigator calls :meth:`RecoveryPolicy.on_failure` with a trigger, ticks the
returned behaviour through :meth:`RecoveryPolicy.tick` and sends ``policy.command``; it calls
:meth:`RecoveryPolicy.on_goal_reached` or :meth:`reset` when a goal ends.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from enum import Enum
from typing import Any

from nav.behaviors import (
    Behavior,
    BehaviorConfigError,
    BehaviorContext,
    Status,
    WaitForWalker,
    behavior_options,
    make_behavior,
)
from nav.types import ZERO_TWIST, Twist2D


class Trigger(Enum):
    """Why recovery was entered."""

    PLANNER_FAILURE = "planner_failure"
    CONTROLLER_FAILURE = "controller_failure"
    NO_PROGRESS = "no_progress"
    LOCALIZATION_DIVERGENCE = "localization_divergence"
    SAFETY_STOP = "safety_stop"


class RecoveryConfigError(BehaviorConfigError):
    """The recovery configuration is invalid; the message names the field."""


@dataclass(frozen=True)
class RecoveryStep:
    """One entry of the recovery list: a behaviour name and its parameters."""

    behavior: str
    params: Mapping[str, Any] = field(default_factory=dict)


#: Nav2's default tree, in navdeck's order and with its BT parameter values.
DEFAULT_STEPS: tuple[RecoveryStep, ...] = (
    RecoveryStep("clear_local_costmap"),
    RecoveryStep("clear_global_costmap"),
    RecoveryStep("spin", {"spin_dist": 1.57}),
    RecoveryStep("wait", {"wait_duration": 5.0}),
    RecoveryStep("back_up", {"backup_dist": 0.30, "backup_speed": 0.15}),
)

#: Lost robots turn until the scan matches the map (source A), and if that fails start
#: localization over the whole map (a kidnapped robot); a robot the safety layer keeps stopping
#: gives the obstacle (often a person) time to move, then backs away from it.
DEFAULT_TRIGGER_STEPS: Mapping[str, tuple[RecoveryStep, ...]] = {
    Trigger.LOCALIZATION_DIVERGENCE.value: (
        RecoveryStep("spin_until_matched", {"min_turn": math.pi, "match_score_threshold": 0.75}),
        RecoveryStep("relocalize"),
        RecoveryStep("wait", {"wait_duration": 2.0}),
    ),
    Trigger.SAFETY_STOP.value: (
        RecoveryStep("wait", {"wait_duration": 3.0}),
        RecoveryStep("back_up", {"backup_dist": 0.30, "backup_speed": 0.15}),
    ),
}


def _as_step(raw: Any, where: str) -> RecoveryStep:
    if isinstance(raw, RecoveryStep):
        return raw
    if isinstance(raw, str):
        return RecoveryStep(raw)
    if isinstance(raw, Mapping):
        d = dict(raw)
        name = d.pop("behavior", None)
        if not isinstance(name, str):
            raise RecoveryConfigError(f"{where}.behavior: missing behaviour name")
        params = d.pop("params", None)
        if params is None:
            params, d = d, {}
        if d:
            raise RecoveryConfigError(f"{where}.{sorted(d)[0]}: unknown key")
        return RecoveryStep(name, dict(params))
    raise RecoveryConfigError(f"{where}: expected a behaviour name or a table, got {type(raw).__name__}")


@dataclass(frozen=True)
class RecoveryOptions:
    """Options of :class:`RecoveryPolicy`; validated on construction (start-up or API)."""

    steps: tuple[RecoveryStep, ...] = DEFAULT_STEPS
    """Ordered recovery list, run round-robin (one step per failure), Nav2's RoundRobin node."""
    number_of_retries: int = 6
    """Recoveries allowed per goal before it is aborted (Nav2 RecoveryNode ``number_of_retries``,
    6 in navigate_to_pose_w_replanning_and_recovery.xml)."""
    trigger_steps: Mapping[str, tuple[RecoveryStep, ...]] = field(
        default_factory=lambda: dict(DEFAULT_TRIGGER_STEPS)
    )
    """Per-trigger lists (by :class:`Trigger` value) used instead of ``steps`` for that trigger."""
    enabled_triggers: tuple[str, ...] = tuple(t.value for t in Trigger)
    """Triggers that start recovery; any other failure aborts the goal at once."""
    count_failed_starts: bool = False
    """Whether a behaviour that fails on start (a spin or back-up refused because it is blocked:
    it sent no command, the robot did not move) spends one of ``number_of_retries``. Nav2 counts
    every attempt (True); navdeck's default moves on to the next step at once and counts only the
    step that ran, so a walker in a door does not spend the budget on refused spins (apartment TEB
    61: six recoveries in 8 s, two of them refused). If every step of the list fails on start, the
    last one counts (the budget still ends)."""
    walker_wait: float = 10.0
    """When a tracked walker stands on the path ahead at a failure (``walker_wait_triggers``), stop
    and wait up to this many seconds for it to leave (``wait_for_walker``, Nav2's ``Wait`` ended by
    the walker) instead of running the next recovery; the wait does not spend the retry budget. A
    wait that ends with the walker still there lets the next failure run the recovery list as
    usual. 0: never wait for walkers."""
    walker_wait_total: float = 60.0
    """Seconds of walker waits allowed per goal (bounds the waits when walkers keep coming back)."""
    walker_wait_triggers: tuple[str, ...] = (
        Trigger.CONTROLLER_FAILURE.value,
        Trigger.NO_PROGRESS.value,
        Trigger.PLANNER_FAILURE.value,
        Trigger.SAFETY_STOP.value,
    )
    """Triggers for which a walker on the path means waiting (a lost robot does not wait)."""

    def __post_init__(self) -> None:
        if not isinstance(self.number_of_retries, int) or self.number_of_retries < 0:
            raise RecoveryConfigError(
                f"recovery.number_of_retries must be a non-negative integer, got {self.number_of_retries!r}"
            )
        object.__setattr__(self, "steps", self._validate_list(self.steps, "recovery.steps"))
        known_triggers = {t.value for t in Trigger}
        checked: dict[str, tuple[RecoveryStep, ...]] = {}
        for key, lst in dict(self.trigger_steps).items():
            k = key.value if isinstance(key, Trigger) else key
            if k not in known_triggers:
                raise RecoveryConfigError(
                    f"recovery.trigger_steps.{k}: unknown trigger; known: {', '.join(sorted(known_triggers))}"
                )
            checked[k] = self._validate_list(lst, f"recovery.trigger_steps.{k}")
        object.__setattr__(self, "trigger_steps", checked)
        enabled = tuple(t.value if isinstance(t, Trigger) else t for t in self.enabled_triggers)
        for i, t in enumerate(enabled):
            if t not in known_triggers:
                raise RecoveryConfigError(f"recovery.enabled_triggers[{i}]: unknown trigger {t!r}")
        object.__setattr__(self, "enabled_triggers", enabled)
        for name in ("walker_wait", "walker_wait_total"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise RecoveryConfigError(
                    f"recovery.{name} must be a non-negative number of seconds, got {v!r}"
                )
        waits = tuple(t.value if isinstance(t, Trigger) else t for t in self.walker_wait_triggers)
        for i, t in enumerate(waits):
            if t not in known_triggers:
                raise RecoveryConfigError(f"recovery.walker_wait_triggers[{i}]: unknown trigger {t!r}")
        object.__setattr__(self, "walker_wait_triggers", waits)

    @staticmethod
    def _validate_list(raw: Sequence[Any], where: str) -> tuple[RecoveryStep, ...]:
        if isinstance(raw, str | bytes) or not isinstance(raw, Sequence):
            raise RecoveryConfigError(f"{where}: expected a list of behaviours")
        if len(raw) == 0:
            raise RecoveryConfigError(f"{where}: the recovery list is empty")
        steps = tuple(_as_step(r, f"{where}[{i}]") for i, r in enumerate(raw))
        for i, s in enumerate(steps):
            try:
                behavior_options(s.behavior, s.params, f"{where}[{i}]")
            except RecoveryConfigError:
                raise
            except BehaviorConfigError as exc:
                raise RecoveryConfigError(str(exc)) from exc
        return steps

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any]) -> RecoveryOptions:
        """From parsed TOML/JSON: ``{"steps": ["spin", {"behavior": "wait", "wait_duration": 2}],
        "number_of_retries": 6, "trigger_steps": {...}, "enabled_triggers": [...]}``."""
        d = dict(data)
        known = {
            "steps",
            "number_of_retries",
            "trigger_steps",
            "enabled_triggers",
            "count_failed_starts",
            "walker_wait",
            "walker_wait_total",
            "walker_wait_triggers",
        }
        bad = sorted(set(d) - known)
        if bad:
            raise RecoveryConfigError(f"recovery.{bad[0]}: unknown field; known: {', '.join(sorted(known))}")
        kwargs: dict[str, Any] = {}
        if "steps" in d:
            kwargs["steps"] = d["steps"]
        if "number_of_retries" in d:
            kwargs["number_of_retries"] = d["number_of_retries"]
        if "trigger_steps" in d:
            if not isinstance(d["trigger_steps"], Mapping):
                raise RecoveryConfigError("recovery.trigger_steps: expected a table of lists")
            kwargs["trigger_steps"] = dict(d["trigger_steps"])
        if "enabled_triggers" in d:
            kwargs["enabled_triggers"] = tuple(d["enabled_triggers"])
        for name in ("count_failed_starts", "walker_wait", "walker_wait_total"):
            if name in d:
                kwargs[name] = d[name]
        if "walker_wait_triggers" in d:
            kwargs["walker_wait_triggers"] = tuple(d["walker_wait_triggers"])
        return cls(**kwargs)


@dataclass(frozen=True)
class RecoveryEvent:
    """One structured record: an attempt starting, its result, or the policy giving up."""

    kind: str  # "attempt" | "result" | "exhausted" | "rejected"
    t: float
    trigger: str
    behavior: str = ""
    attempt: int = 0  # 1-based attempt number within the current goal
    retries_left: int = 0
    status: str = ""  # for "result": succeeded | failed
    reason: str = ""
    detail: str = ""  # what the trigger said (the controller's or planner's message)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


class RecoveryPolicy:
    """Chooses and runs recovery behaviours. See the module docstring for the protocol."""

    def __init__(
        self, options: RecoveryOptions | None = None, on_event: Callable[[RecoveryEvent], None] | None = None
    ) -> None:
        self.options = options or RecoveryOptions()
        self.on_event = on_event
        self.events: list[RecoveryEvent] = []
        self.attempts = 0
        self.active: Behavior | None = None
        self.active_trigger: Trigger | None = None
        self._cursor: dict[str, int] = {}
        self._exhausted_reported = False  # the navigator asks every tick until it gives up
        self.last_status: Status = Status.SUCCEEDED
        self.walker_waited = 0.0  # s of walker waits in this goal
        self._walker_outlasted = False  # the last walker wait ended with the walker still there

    # ------------------------------------------------------------------ state
    @property
    def retries_left(self) -> int:
        return max(self.options.number_of_retries - self.attempts, 0)

    @property
    def exhausted(self) -> bool:
        return self.attempts >= self.options.number_of_retries

    @property
    def command(self) -> Twist2D:
        """Velocity to send this cycle: the active behaviour's, else zero."""
        return self.active.command if self.active is not None else ZERO_TWIST

    def reset(self) -> None:
        """New goal: full retry budget, round robins back to their first step."""
        self.attempts = 0
        self.active = None
        self.active_trigger = None
        self._cursor.clear()
        self._exhausted_reported = False
        self.walker_waited = 0.0
        self._walker_outlasted = False

    def on_goal_reached(self) -> None:
        """Navigation succeeded: like Nav2's RecoveryNode, the retry count starts over."""
        self.reset()

    def steps_for(self, trigger: Trigger) -> tuple[RecoveryStep, ...]:
        return self.options.trigger_steps.get(trigger.value, self.options.steps)

    def _emit(self, event: RecoveryEvent) -> None:
        self.events.append(event)
        if self.on_event is not None:
            self.on_event(event)

    # ------------------------------------------------------------------ protocol
    def on_failure(self, trigger: Trigger, ctx: BehaviorContext, detail: str = "") -> Behavior | None:
        """Navigation failed for ``trigger``: start the next recovery and return it, or return None
        when the goal must be aborted (budget spent, or trigger not enabled).

        A tracked walker on the path ahead first makes the robot wait for it (``walker_wait``, not
        counted). A behaviour that fails on start is reported; unless ``count_failed_starts``, it
        spends nothing and the next step of the list starts at once (see that option)."""
        if trigger.value not in self.options.enabled_triggers:
            self._emit(
                RecoveryEvent("rejected", ctx.now, trigger.value, reason="trigger not enabled", detail=detail)
            )
            return None
        if self._should_wait_for_walker(trigger, ctx):
            return self._start(
                make_behavior("wait_for_walker", {"max_wait": self._walker_wait_left}), trigger, ctx, detail
            )
        if self.exhausted:
            if not self._exhausted_reported:  # one event per spent budget, not one per tick
                self._exhausted_reported = True
                self._emit(
                    RecoveryEvent(
                        "exhausted",
                        ctx.now,
                        trigger.value,
                        attempt=self.attempts,
                        reason=f"number_of_retries ({self.options.number_of_retries}) spent",
                        detail=detail,
                    )
                )
            self.active = None
            return None
        self._walker_outlasted = False
        steps = self.steps_for(trigger)
        key = trigger.value if trigger.value in self.options.trigger_steps else "*"
        for tried in range(1, len(steps) + 1):
            i = self._cursor.get(key, 0)
            self._cursor[key] = (i + 1) % len(steps)
            self.attempts += 1
            behavior = self._start(make_behavior(steps[i].behavior, steps[i].params), trigger, ctx, detail)
            refused = self.active is None and self.last_status is Status.FAILED
            if not refused or self.options.count_failed_starts or tried == len(steps):
                return behavior
            self.attempts -= 1  # it sent no command: no recovery ran, try the next step now
        raise AssertionError("unreachable: the loop returns on its last step")

    @property
    def _walker_wait_left(self) -> float:
        return min(self.options.walker_wait, self.options.walker_wait_total - self.walker_waited)

    def _should_wait_for_walker(self, trigger: Trigger, ctx: BehaviorContext) -> bool:
        """A walker stands on the path, and neither this goal's walker waits nor the last wait (the
        walker stayed) say to recover instead."""
        return (
            trigger.value in self.options.walker_wait_triggers
            and self._walker_wait_left > 0.0
            and not self._walker_outlasted
            and ctx.walker_on_path is not None
            and ctx.walker_on_path()
        )

    def _start(self, behavior: Behavior, trigger: Trigger, ctx: BehaviorContext, detail: str) -> Behavior:
        self.active, self.active_trigger = behavior, trigger
        self._emit(
            RecoveryEvent(
                "attempt",
                ctx.now,
                trigger.value,
                behavior=behavior.name,
                attempt=self.attempts,
                retries_left=self.retries_left,
                detail=detail,
            )
        )
        status = behavior.start(ctx)
        if status is not Status.RUNNING:
            self._finish(ctx, status)
        return behavior

    def tick(self, ctx: BehaviorContext) -> Status:
        """Tick the active behaviour; on its end emit a result event and clear it."""
        if self.active is None:
            raise RuntimeError("RecoveryPolicy.tick without an active behaviour")
        status = self.active.tick(ctx)
        if status is not Status.RUNNING:
            self._finish(ctx, status)
        return status

    def _finish(self, ctx: BehaviorContext, status: Status) -> None:
        assert self.active is not None and self.active_trigger is not None
        self._emit(
            RecoveryEvent(
                "result",
                ctx.now,
                self.active_trigger.value,
                behavior=self.active.name,
                attempt=self.attempts,
                retries_left=self.retries_left,
                status=status.value,
                reason=self.active.reason,
            )
        )
        self.last_status = status
        if isinstance(self.active, WaitForWalker):
            started = self.active.started_at
            self.walker_waited += ctx.now - started if started is not None else 0.0
            self._walker_outlasted = status is Status.FAILED
        self.active = None

    def run_to_end(
        self,
        ctx: BehaviorContext,
        advance: Callable[[BehaviorContext, Twist2D], None],
        max_ticks: int = 10_000,
    ) -> Status:
        """Drive the active behaviour to its end, ``advance(ctx, command)`` moving the world and
        the clock between ticks (a simulator step or a test's integrator). RUNNING if ``max_ticks``
        ran out first."""
        for _ in range(max_ticks):
            if self.active is None:
                return self.last_status
            advance(ctx, self.command)
            self.tick(ctx)
        return self.last_status if self.active is None else Status.RUNNING


__all__ = [
    "DEFAULT_STEPS",
    "DEFAULT_TRIGGER_STEPS",
    "RecoveryConfigError",
    "RecoveryEvent",
    "RecoveryOptions",
    "RecoveryPolicy",
    "RecoveryStep",
    "Trigger",
]
