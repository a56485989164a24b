"""Missions as resources (issue 22): create, read (with a long-poll), list, cancel.

A mission is one navigation request: goals or waypoints (map-frame poses) and an optional controller.
It keeps running with no client connected; see ``LEASE_RULES`` and docs/api.md.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Literal

from fastapi import APIRouter, Depends, Query, Response
from pydantic import BaseModel, Field

from app.api.deps import ActorDep, StrictModel, feature_dependency
from app.api.problems import ProblemError, problem_responses
from app.features.missions import (
    GoalState,
    Mission,
    MissionEnded,
    MissionNotFound,
    Missions,
    MissionState,
)
from app.features.navigation import GoalRejected, NavigationRefused, StopReason
from nav.types import Pose2D

router = APIRouter(tags=["missions"])

WAIT_MAX_S = 60.0


class PoseIn(StrictModel):
    """A pose in the map frame (REP-103: metres, radians CCW). NaN/inf are refused (422)."""

    x: float = Field(description="m")
    y: float = Field(description="m")
    theta: float = Field(0.0, description="rad, CCW from the map's x axis")


class MissionIn(StrictModel):
    """``goals``: navigate through these poses in order (one pose: a single goal); ``waypoints`` is
    the same list under its other name, appended after ``goals`` when both are given."""

    goals: list[PoseIn] = Field(default_factory=list)
    waypoints: list[PoseIn] = Field(default_factory=list)
    controller: Literal["dwa", "teb"] | None = Field(
        None, description="local controller for this mission; default: the robot profile's"
    )
    allow_unknown: bool | None = Field(
        None, description="accept goals in unknown space; default: the navigation option allow_unknown_goals"
    )


class PoseOut(BaseModel):
    x: float = Field(description="m")
    y: float = Field(description="m")
    theta: float = Field(description="rad")


class GoalOut(BaseModel):
    pose: PoseOut
    state: GoalState
    reason: str = Field(
        "", description="why it failed or was cancelled (e.g. `operator_cancel`, `NoValidPath`)"
    )


class Progress(BaseModel):
    goal_index: int = Field(
        description="index of the goal being driven to (== goal_count once all are reached)"
    )
    goal_count: int
    goals_reached: int
    distance_remaining_m: float | None = Field(
        None, description="metres left along the planned path to the current goal, while active"
    )


class CancelInfo(BaseModel):
    reason: StopReason
    actor: str = Field(description="who: the user name for an API call, `robot` for a fault")
    message: str = ""


class FailureInfo(BaseModel):
    reason: str = Field(description="the navigator's typed reason, e.g. `NoValidPath`, `NoProgress`")
    message: str = ""


class MissionOut(BaseModel):
    id: str
    state: MissionState
    controller: str | None
    created_by: str
    goals: list[GoalOut]
    progress: Progress
    cancel: CancelInfo | None = Field(None, description="set when the mission was cancelled")
    failure: FailureInfo | None = Field(None, description="set when the mission failed")
    created_at: datetime = Field(description="ISO 8601 UTC")
    started_at: datetime | None = Field(None, description="ISO 8601 UTC: when the control loop took it")
    ended_at: datetime | None = None
    updated_at: datetime
    version: int = Field(description="increases on every change (state or progress)")


class MissionPage(BaseModel):
    total: int
    limit: int
    offset: int
    items: list[MissionOut]


MissionsDep = Annotated[Missions, Depends(feature_dependency(Missions))]

NOT_FOUND = problem_responses(s404="no such mission")
UNAVAILABLE = problem_responses(s503="navigation is not running")


def mission_out(missions: Missions, m: Mission) -> MissionOut:
    index = min(m.reached, len(m.goals))
    return MissionOut(
        id=m.id,
        state=m.state,
        controller=m.controller,
        created_by=m.actor,
        goals=[
            GoalOut(pose=PoseOut(x=g.x, y=g.y, theta=g.theta), state=s, reason=r)
            for g, s, r in zip(m.goals, m.goal_states, m.goal_reasons, strict=True)
        ],
        progress=Progress(
            goal_index=index,
            goal_count=len(m.goals),
            goals_reached=m.reached,
            distance_remaining_m=missions.distance_remaining(m),
        ),
        cancel=CancelInfo(**m.cancel) if m.cancel else None,
        failure=FailureInfo(**m.failure) if m.failure else None,
        created_at=m.created_at,
        started_at=m.started_at,
        ended_at=m.ended_at,
        updated_at=m.updated_at,
        version=m.version,
    )


def goal_problem(exc: GoalRejected | NavigationRefused) -> ProblemError:
    """422 for a goal the costmap refuses (with ``reason``, ``index``, ``nearest_free``), 409 when
    navigation cannot run now (with ``mode`` and ``allowed``)."""
    body = exc.as_dict()
    detail = body.pop("detail")
    if isinstance(exc, GoalRejected):
        return ProblemError(422, detail, kind="goal-rejected", **body)
    return ProblemError(409, detail, kind="navigation-refused", **body)


def start_mission(
    missions: Missions,
    goals: list[Pose2D],
    controller: str | None,
    actor: str,
    allow_unknown: bool | None = None,
    patrol: bool = False,
) -> Mission:
    """Create a mission (``patrol``: its goals in a loop until cancelled); raises ProblemError
    (409 / 422) when it cannot start."""
    if not goals:
        raise ProblemError(422, "goals: give at least one goal", kind="invalid-request")
    try:
        return missions.create(goals, controller, actor, allow_unknown, patrol=patrol)
    except (GoalRejected, NavigationRefused) as exc:
        raise goal_problem(exc) from None
    except ValueError as exc:  # an unknown controller name
        raise ProblemError(422, str(exc), kind="invalid-request") from None


def find(missions: Missions, mission_id: str) -> Mission:
    try:
        return missions.get(mission_id)
    except MissionNotFound:
        raise ProblemError(404, f"no mission with id {mission_id}", kind="not-found") from None


@router.post(
    "/api/missions",
    status_code=201,
    response_model=MissionOut,
    summary="Start a mission: goals / waypoints in order; replaces (supersedes) the running one",
    description="Answers 201 with the new mission (state `accepted`) and its URL in `Location`. The "
    "mission runs on its own: it is not cancelled when the client goes quiet or disconnects (only teleop "
    "has a deadman, see the lease rules). Wait for its end with `GET /api/missions/{id}?wait=30`.",
    responses={
        **problem_responses(
            s409="not localized, e-stop, fault, the mode does not allow navigating, or another client "
            "holds control",
            s422="a goal off the map, in an obstacle or its inscribed radius (`reason`, `index`, "
            "`nearest_free`), or no goal",
        ),
        **UNAVAILABLE,
    },
)
def create_mission(body: MissionIn, missions: MissionsDep, actor: ActorDep, response: Response) -> MissionOut:
    goals = [Pose2D(g.x, g.y, g.theta) for g in [*body.goals, *body.waypoints]]
    m = start_mission(missions, goals, body.controller, actor, body.allow_unknown)
    response.headers["Location"] = f"/api/missions/{m.id}"
    return mission_out(missions, m)


@router.get(
    "/api/missions",
    response_model=MissionPage,
    summary="Missions, newest first (kept in memory: the latest 1000), paginated like /api/runs",
    responses=UNAVAILABLE,
)
def list_missions(
    missions: MissionsDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0)] = 0,
) -> MissionPage:
    total, items = missions.page(limit, offset)
    return MissionPage(
        total=total, limit=limit, offset=offset, items=[mission_out(missions, m) for m in items]
    )


@router.get(
    "/api/missions/{mission_id}",
    response_model=MissionOut,
    summary="One mission: state, progress, per-goal outcomes, cancel reason and actor",
    description="Long-poll: with `wait` (s, at most 60) the answer comes as soon as the mission changes "
    "(state or goal progress) or when `wait` runs out, whichever is first; an ended mission answers at "
    "once. Pass the `version` you already have to wait for the next change after it.",
    responses={**NOT_FOUND, **UNAVAILABLE},
)
async def get_mission(
    mission_id: str,
    missions: MissionsDep,
    wait: Annotated[float, Query(ge=0, le=WAIT_MAX_S, allow_inf_nan=False, description="s")] = 0.0,
    version: Annotated[int | None, Query(ge=0, description="wait for a version after this one")] = None,
) -> MissionOut:
    m = find(missions, mission_id)
    await missions.wait_change(m, m.version if version is None else version, wait)
    return mission_out(missions, m)


@router.post(
    "/api/missions/{mission_id}/cancel",
    response_model=MissionOut,
    summary="Cancel a mission: the robot stops; the answer's state is `canceling`, then `canceled`",
    responses={
        **NOT_FOUND,
        **problem_responses(s409="the mission already ended (`state` says how)"),
        **UNAVAILABLE,
    },
)
def cancel_mission(mission_id: str, missions: MissionsDep, actor: ActorDep) -> MissionOut:
    m = find(missions, mission_id)
    try:
        missions.cancel(mission_id, actor)
    except MissionEnded as exc:
        raise ProblemError(409, str(exc), kind="mission-ended", state=m.state.value) from None
    return mission_out(missions, m)
