"""Shared response-model machinery: every route declares a pydantic model for what it answers.

Conventions (docs/api.md): times are ``Timestamp`` (ISO 8601 UTC with ``Z``); a monotonic stamp is
named ``*_monotonic_s`` and says its origin; units are in the field name (``_m``, ``_s``, ``_rad``)
or its description; every list is a ``Page`` (``total, limit, offset, items``); errors are
``app.api.problems.Problem``. ``ERRORS`` documents the error answers a route may give.
"""

from __future__ import annotations

from datetime import UTC, datetime
from enum import StrEnum
from typing import Annotated, Any, Generic, Literal, TypeVar

from fastapi import Path as PathParam
from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field

from app.api.problems import problem_responses


def as_utc(value: datetime) -> datetime:
    """Naive datetimes (SQLite drops the zone) are UTC; aware ones are converted to UTC."""
    return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)


def _from_epoch(value: Any) -> Any:
    """Wall-clock epoch seconds (``time.time()``) are accepted and turned into a datetime."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return datetime.fromtimestamp(float(value), UTC)
    return value


Timestamp = Annotated[datetime, BeforeValidator(_from_epoch), AfterValidator(as_utc)]
"""A wall-clock instant, serialized ISO 8601 UTC with ``Z`` (``2026-11-26T06:45:41.123456Z``)."""


Pair = Annotated[list[float], Field(min_length=2, max_length=2)]
"""Two numbers (x, y or width, height): a list, as JSON has no tuple (and OpenAPI tools disagree on
how to write one)."""
Triple = Annotated[list[float], Field(min_length=3, max_length=3)]
"""Three numbers (x, y, theta or vx, vy, wz)."""


DbId = Annotated[int, PathParam(ge=1, le=2**63 - 1, description="a database id")]
"""A path id of a stored row (map, run): out of range is a 422, never an overflow in the database."""


class Out(BaseModel):
    """A response body with every field declared (unknown keys are an error of the route)."""

    model_config = ConfigDict(extra="forbid")


class OpenOut(BaseModel):
    """A response body whose listed fields are typed and which may carry more (diagnostic extras
    that change with the robot's stages); a client must ignore fields it does not know."""

    model_config = ConfigDict(extra="allow")


class Pose(Out):
    """A pose in the map frame (REP-103)."""

    x: float = Field(description="m")
    y: float = Field(description="m")
    theta: float = Field(description="rad, CCW from the map's x axis")


T = TypeVar("T")


class Page(Out, Generic[T]):
    """One page of a list, newest or best first; ``total`` counts every item of the list."""

    total: int = Field(ge=0)
    limit: int = Field(ge=1)
    offset: int = Field(ge=0)
    items: list[T]


ERRORS = problem_responses
"""``ERRORS(s404="no such map", s409="...")``: the documented problem answers of a route."""


# ------------------------------------------------------------------------------ robot-level shapes
class Vector3(Out):
    x: float
    y: float
    z: float


class Twist(Out):
    """geometry_msgs/Twist: linear in m/s, angular in rad/s (base_link frame)."""

    linear: Vector3
    angular: Vector3


class LoopStats(OpenOut):
    """The control loop's timing (ms) over its recent ticks."""

    ticks: int


class Health(Out):
    link: str = Field(description="the drive link: `ok`, `degraded`, `lost`...")
    link_reason: str
    lidar: bool = Field(description="the robot has a lidar")
    lidar_fault: str | None
    battery_v: float | None = Field(description="V")
    battery_pct: float | None = Field(description="% of the profile's empty..full range")
    scan_age_s: float | None = Field(description="s since the last laser scan")
    loop: LoopStats
    collisions: int
    fault: str | None
    fault_cleared: bool = Field(
        description="a fault is latched but its cause is gone: reset will be accepted"
    )


class Holder(Out):
    name: str
    since: Timestamp = Field(description="when this client took control")
    connected: bool = Field(description="it has a live teleop websocket")


class ControlState(Out):
    holder: Holder | None = Field(description="who holds the control lease; null: nobody")


# ------------------------------------------------------------------------------ navigation
class NavigationState(StrEnum):
    """The navigation state, in the vocabulary of missions: a request ends ``succeeded``, ``failed``
    or ``canceled`` (one spelling), the same words as ``Outcome.kind`` and ``MissionState``."""

    IDLE = "idle"
    PLANNING = "planning"
    FOLLOWING = "following"
    STUCK = "stuck"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELED = "canceled"


OutcomeKind = Literal["succeeded", "failed", "canceled"]

_PUBLIC_WORD = {"reached": "succeeded", "cancelled": "canceled"}
"""The navigator's internal words (nav.navigator, run events) -> the API's."""


def public_word(word: str | None) -> str | None:
    return None if word is None else _PUBLIC_WORD.get(word, word)


class NavOutcome(Out):
    """How the last navigation request ended."""

    kind: OutcomeKind
    reason: str = Field(description="the navigator's typed reason, or the cancel's `StopReason`")
    message: str
    actor: str | None = Field(description="who cancelled it (null unless canceled)")
    request_id: int | None
    goals_reached: int
    t_monotonic_s: float = Field(description="s since this server's session started (monotonic clock)")
    xy_goal_tolerance: float = Field(description="m")
    yaw_goal_tolerance: float = Field(description="rad")
    distance_to_goal: float | None = Field(description="m, straight line, when it ended")
    yaw_to_goal: float | None = Field(description="rad, goal minus robot, when it ended")


class NavigationOut(Out):
    state: NavigationState
    active: bool = Field(description="a request is being driven (or about to be)")
    request_id: int | None
    planner: str
    controller: str
    goal: Pose | None = Field(description="the goal being driven to")
    goal_index: int
    goals: list[Pose]
    distance_remaining_m: float | None = Field(description="along the planned path, m")
    eta_s: float | None
    xy_goal_tolerance: float = Field(description="m")
    yaw_goal_tolerance: float = Field(description="rad")
    distance_to_goal: float | None = Field(description="m, straight line")
    yaw_to_goal: float | None = Field(description="rad, goal minus robot")
    activity: str = Field(description="what it is doing, for people")
    outcome: NavOutcome | None = Field(description="how the last request ended")
    recoveries: int
    costmap_view: Literal["global", "local"]
    path: list[Pair] | None = Field(
        None, description="the planned path (map frame, m); REST only, not in telemetry"
    )


def public_navigation(state: dict[str, Any]) -> dict[str, Any]:
    """The navigation feature's state in the API's vocabulary and names (REST and telemetry)."""
    out = dict(state)
    out["state"] = public_word(out.get("state"))
    if "distance_remaining" in out:
        out["distance_remaining_m"] = out.pop("distance_remaining")
    o = out.get("outcome")
    if o is not None:
        o = dict(o, kind=public_word(o.get("kind")))
        if "t" in o:
            o["t_monotonic_s"] = o.pop("t")
        out["outcome"] = o
    return out
