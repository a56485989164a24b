"""Feature: missions as resources (issue 22) over the navigation stage.

A mission is one navigation request (goals / waypoints, a controller): it gets an id, a state
(``MissionState``), per-goal outcomes and, when cancelled, the reason and actor (``StopCause``). Every
navigation request is a mission, whichever way it came (``POST /api/missions``, the goal endpoints,
a click in the 3D view). Missions live in memory (the newest ``KEEP``) and every state change is a
``mission`` event of the run; every leg that ends (reached, failed, cancelled) is a ``mission_leg``
event. A mission runs on with no client connected (``LEASE_RULES``).

A patrol (``create(..., patrol=True)``) runs its legs in a loop until cancelled: it starts with two
laps queued and, when the robot starts the last queued lap, appends another one to the running
request (the navigation's extension, as a click in the 3D view adds a goal), so the robot never
stops between laps and every leg keeps its own outcome.

Waiting without polling: ``wait_change`` is an asyncio wait on the mission's version; the navigation
stage's listener (loop thread) bumps it and wakes the waiters with ``call_soon_threadsafe``.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import uuid
from collections import OrderedDict
from dataclasses import dataclass, field
from datetime import UTC, datetime
from enum import StrEnum
from typing import TYPE_CHECKING, Any

from app.features.navigation import GoalRejected, Navigation, NavigationRefused, StopReason
from nav.types import Pose2D

if TYPE_CHECKING:
    from app.runtime import Runtime

ORDER = 45  # after navigation (40): it listens to it
KEEP = 1000  # missions remembered; the oldest ended ones are dropped first
log = logging.getLogger("navdeck.missions")


class MissionState(StrEnum):
    ACCEPTED = "accepted"  # validated and queued; the control loop picks it up on its next tick
    ACTIVE = "active"  # driving (planning, following, recovering)
    CANCELING = "canceling"  # a cancel was asked; the robot stops on the next tick
    SUCCEEDED = "succeeded"  # every goal reached
    FAILED = "failed"  # a goal failed (see the goal's reason)
    CANCELED = "canceled"  # see ``cancel`` for the reason and actor


TERMINAL = frozenset({MissionState.SUCCEEDED, MissionState.FAILED, MissionState.CANCELED})


class GoalState(StrEnum):
    PENDING = "pending"
    ACTIVE = "active"
    REACHED = "reached"
    FAILED = "failed"
    CANCELED = "canceled"


def utc_now() -> datetime:
    return datetime.now(UTC)


@dataclass
class Mission:
    id: str
    request_id: int
    goals: list[Pose2D]
    controller: str | None
    actor: str
    state: MissionState = MissionState.ACCEPTED
    goal_states: list[GoalState] = field(default_factory=list)
    goal_reasons: list[str] = field(default_factory=list)
    cancel: dict[str, str] | None = None  # reason, actor, message
    failure: dict[str, str] | None = None  # reason, message of a failed goal
    created_at: datetime = field(default_factory=utc_now)
    started_at: datetime | None = None
    ended_at: datetime | None = None
    updated_at: datetime = field(default_factory=utc_now)
    version: int = 0
    waiters: list[tuple[asyncio.AbstractEventLoop, asyncio.Event]] = field(default_factory=list)
    patrol: list[Pose2D] | None = None  # the lap of a patrol (repeated until cancelled)
    patrol_queued: int = 0  # goal count once the last lap asked for is queued

    def __post_init__(self) -> None:
        self.goal_states = [GoalState.PENDING] * len(self.goals)
        self.goal_reasons = [""] * len(self.goals)

    @property
    def reached(self) -> int:
        return sum(s == GoalState.REACHED for s in self.goal_states)


class MissionNotFound(KeyError):
    pass


class MissionEnded(RuntimeError):
    """A cancel of a mission that already ended (409)."""


class Missions:
    """The mission registry. Thread-safe: routes call it from the event loop or worker threads, the
    navigation listener from the control loop."""

    def __init__(self, navigation: Navigation) -> None:
        self.nav = navigation
        self.session = navigation.session
        self._lock = threading.RLock()
        self._missions: OrderedDict[str, Mission] = OrderedDict()
        self._by_request: dict[int, Mission] = {}
        navigation.add_listener(self._on_navigation)

    # ---------------------------------------------------------------- requests
    def create(
        self,
        goals: list[Pose2D],
        controller: str | None = None,
        actor: str = "operator",
        allow_unknown: bool | None = None,
        patrol: bool = False,
    ) -> Mission:
        """Start a mission (raises the navigation's GoalRejected / NavigationRefused). It supersedes
        the running one, whose cancel then says ``superseded`` with this ``actor``. ``allow_unknown``
        accepts goals in unknown space (None: the navigation option ``allow_unknown_goals``).
        ``patrol``: run ``goals`` as a lap, again and again until the mission is cancelled."""
        if patrol and len(goals) < 2:
            raise ValueError("a patrol needs at least two stops")
        queued = list(goals) * 2 if patrol else list(goals)
        with self._lock:  # held across set_goals: the loop's "started" cannot overtake the registration
            rid = self.nav.set_goals(queued, controller, actor=actor, allow_unknown=allow_unknown)
            m = self._register(rid, queued, controller, actor, patrol=list(goals) if patrol else None)
            return m

    def _register(
        self,
        rid: int,
        goals: list[Pose2D],
        controller: str | None,
        actor: str,
        patrol: list[Pose2D] | None = None,
    ) -> Mission:
        m = Mission(uuid.uuid4().hex[:16], rid, list(goals), controller, actor, patrol=patrol)
        m.patrol_queued = len(goals)
        self._missions[m.id] = m
        self._by_request[rid] = m
        self._trim()
        self._changed(m)
        return m

    def cancel(self, mission_id: str, actor: str) -> Mission:
        """Cancel a mission; its state is CANCELING until the loop stops the robot (next tick)."""
        with self._lock:
            m = self.get(mission_id)
            if m.state in TERMINAL:
                raise MissionEnded(f"mission {mission_id} already ended: {m.state.value}")
            if m.state != MissionState.CANCELING and self.nav.current_request == m.request_id:
                self.nav.cancel(actor=actor, reason=StopReason.OPERATOR_CANCEL)
                m.state = MissionState.CANCELING
                self._changed(m)
            return m

    def get(self, mission_id: str) -> Mission:
        with self._lock:
            m = self._missions.get(mission_id)
        if m is None:
            raise MissionNotFound(mission_id)
        return m

    def for_request(self, request_id: int | None) -> Mission | None:
        with self._lock:
            return None if request_id is None else self._by_request.get(request_id)

    def page(self, limit: int, offset: int) -> tuple[int, list[Mission]]:
        """Newest first."""
        with self._lock:
            items = list(reversed(self._missions.values()))
        return len(items), items[offset : offset + limit]

    def distance_remaining(self, m: Mission) -> float | None:
        """Metres left along the path (the navigator's feedback) while ``m`` is the running request."""
        if (
            m.state not in (MissionState.ACTIVE, MissionState.CANCELING)
            or self.nav.request_id != m.request_id
        ):
            return None
        return self.nav.state().get("distance_remaining")

    # ---------------------------------------------------------------- waiting
    async def wait_change(self, m: Mission, version: int, timeout: float) -> None:
        """Return once ``m.version`` differs from ``version``, ``m`` has ended, or after ``timeout`` s.
        Never blocks the event loop."""
        if timeout <= 0:
            return
        loop = asyncio.get_running_loop()
        event = asyncio.Event()
        with self._lock:
            if m.version != version or m.state in TERMINAL:
                return
            m.waiters.append((loop, event))
        try:
            await asyncio.wait_for(event.wait(), timeout)
        except TimeoutError:
            pass
        finally:
            with self._lock:
                if (loop, event) in m.waiters:
                    m.waiters.remove((loop, event))

    # ---------------------------------------------------------------- navigation listener (loop thread)
    def _on_navigation(self, kind: str, rid: int, data: dict[str, Any]) -> None:
        with self._lock:
            m = self._by_request.get(rid)
            if m is None:  # a request that did not come through here (a click in the 3D view)
                m = self._register(rid, list(data.get("goals") or []), None, "viewer")
            if kind == "started":
                m.state = MissionState.ACTIVE if m.state != MissionState.CANCELING else m.state
                m.started_at = utc_now()
                self._mark(m, 0)
            elif kind == "extended":
                added = list(data["goals"])[len(m.goals) :]
                m.goals.extend(added)
                m.goal_states.extend([GoalState.PENDING] * len(added))
                m.goal_reasons.extend([""] * len(added))
                self._mark(m, m.reached)
            elif kind == "progress":
                self._mark(m, int(data["goal_index"]))
            elif kind == "ended":
                self._end(m, data["outcome"], data.get("cause"))
            else:
                return
            self._changed(m)
            self._next_lap(m)

    def _next_lap(self, m: Mission) -> None:
        """A patrol on its last queued lap gets one more (once: ``patrol_queued`` is the goal count
        that lap will bring, so the progress ticks before the extension lands ask nothing)."""
        lap = m.patrol
        if not lap or m.state != MissionState.ACTIVE or m.patrol_queued > len(m.goals):
            return
        if m.reached < len(m.goals) - len(lap) or self.nav.current_request != m.request_id:
            return
        m.patrol_queued = len(m.goals) + len(lap)
        try:
            for goal in lap:
                self.nav.add_goal(goal)
        except (GoalRejected, NavigationRefused) as exc:  # a stop became unreachable (a new keepout)
            log.warning("patrol %s: next lap refused: %s", m.id, exc)
            self.session.add_event("mission", id=m.id, state=m.state.value, patrol_stopped=str(exc))

    def _mark(self, m: Mission, reached: int) -> None:
        for i in range(len(m.goals)):
            if i < reached:
                self._leg(m, i, GoalState.REACHED)
            elif i == reached and m.state in (MissionState.ACTIVE, MissionState.CANCELING):
                m.goal_states[i] = GoalState.ACTIVE

    def _leg(self, m: Mission, i: int, state: GoalState, reason: str = "") -> None:
        """Set leg ``i``'s outcome; the first time it ends, a ``mission_leg`` event of the run."""
        if m.goal_states[i] in (GoalState.REACHED, GoalState.FAILED, GoalState.CANCELED):
            return
        m.goal_states[i], m.goal_reasons[i] = state, reason
        g = m.goals[i]
        lap = {"lap": i // len(m.patrol) + 1} if m.patrol else {}
        self.session.add_event(
            "mission_leg", id=m.id, index=i, **lap, state=state.value, reason=reason, pose=[g.x, g.y, g.theta]
        )

    def _end(self, m: Mission, outcome: dict[str, Any], cause: dict[str, str] | None) -> None:
        kind = outcome["kind"]
        reached = int(outcome.get("goals_reached", 0))
        m.ended_at = utc_now()
        if kind == "reached":
            m.state = MissionState.SUCCEEDED
            reached = len(m.goals)
        self._mark(m, reached)
        reason = str(outcome.get("reason") or "")
        message = str(outcome.get("message") or "")
        for i in range(reached, len(m.goals)):
            if i == reached and kind == "failed":
                self._leg(m, i, GoalState.FAILED, f"{reason}: {message}".strip(": "))
            elif i == reached:
                self._leg(m, i, GoalState.CANCELED, (cause or {}).get("reason", reason))
            else:
                self._leg(m, i, GoalState.CANCELED, "not_attempted")
        if kind == "failed":
            m.state = MissionState.FAILED
            m.failure = {"reason": reason, "message": message}
        elif kind == "cancelled":
            m.state = MissionState.CANCELED
            m.cancel = (
                dict(cause) if cause else {"reason": "operator_cancel", "actor": "operator", "message": ""}
            )

    def _changed(self, m: Mission) -> None:
        """Bump the version, record the change in the run's events, wake the long-polls."""
        m.version += 1
        m.updated_at = utc_now()
        self.session.add_event(
            "mission",
            id=m.id,
            state=m.state.value,
            goals_reached=m.reached,
            goal_count=len(m.goals),
            **({"cancel": m.cancel} if m.cancel else {}),
        )
        waiters, m.waiters = m.waiters, []
        for loop, event in waiters:
            if not loop.is_closed():
                loop.call_soon_threadsafe(event.set)

    def _trim(self) -> None:
        while len(self._missions) > KEEP:
            victim = next((k for k, v in self._missions.items() if v.state in TERMINAL), None)
            if victim is None:
                return
            old = self._missions.pop(victim)
            self._by_request.pop(old.request_id, None)

    def close(self) -> None:
        pass


def setup(runtime: Runtime) -> Missions | None:
    nav = runtime.find_feature(Navigation)
    if nav is None:
        log.warning("missions need the navigation feature")
        return None
    return Missions(nav)
