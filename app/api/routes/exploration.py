"""Exploration (issue 18): start frontier exploration with one click, stop it, read its state.

Starting explores from where the robot stands, mapping as it goes (MAPPING mode: a mapping session
starts unless one runs); when no reachable frontier is left (or the time budget is used) mapping
stops and the map is offered for saving (``POST /api/mapping/save``). See docs/exploration.md.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends
from pydantic import BaseModel, Field

from app.api.deps import ActorDep, StrictModel, feature_dependency
from app.api.problems import ProblemError, problem_responses
from app.features.exploration import Exploration, ExplorationRefused, ExplorationState

router = APIRouter(tags=["exploration"])


ExplorationDep = Annotated[Exploration, Depends(feature_dependency(Exploration))]


class ExplorationStartIn(StrictModel):
    time_budget_s: float | None = Field(
        None, gt=0, le=86400, description="stop after this many seconds (default: when no frontier is left)"
    )


class PointOut(BaseModel):
    x: float = Field(description="m, map frame")
    y: float = Field(description="m, map frame")


class ExplorationOut(BaseModel):
    state: ExplorationState
    active: bool
    reason: str = Field(description="why it ended (empty while exploring)")
    elapsed_s: float | None = Field(description="seconds since it started (to its end once ended)")
    time_budget_s: float | None
    time_left_s: float | None = Field(description="seconds of the budget left (None without a budget)")
    explored_area_m2: float | None = Field(description="known-free area of the map, m^2")
    frontiers: int | None = Field(description="frontiers in the latest map (None before the first)")
    reachable_frontiers: int | None
    frontier_cells: int | None
    goal: PointOut | None = Field(description="the frontier goal being driven to")
    goals_sent: int
    goals_reached: int
    goals_failed: int
    blacklisted: int = Field(description="failed goals whose frontiers are no longer chosen")
    save_offered: bool = Field(description="it ended with a map not saved yet: POST /api/mapping/save")
    saved_map_id: int | None


@router.get("/api/exploration", summary="Exploration state, explored area, frontiers, time left")
def get_state(ex: ExplorationDep) -> ExplorationOut:
    return ExplorationOut(**ex.status())


@router.post(
    "/api/exploration/start",
    summary="Explore from here: map while driving to frontiers until none is reachable",
    responses=problem_responses(
        s409="already exploring, or the mode (e-stop, fault, navigating...) does not allow mapping",
        s503="exploration is not available on this server",
    ),
)
def start(ex: ExplorationDep, body: ExplorationStartIn | None = None) -> ExplorationOut:
    try:
        ex.start(None if body is None else body.time_budget_s)
    except ExplorationRefused as exc:
        raise ProblemError(
            409, str(exc), kind="exploration-refused", mode=exc.mode, allowed=exc.allowed
        ) from None
    return ExplorationOut(**ex.status())


@router.post(
    "/api/exploration/stop",
    summary="Stop exploring (the robot stops; mapping keeps running)",
    responses=problem_responses(s409="not exploring", s503="exploration is not available on this server"),
)
def stop(ex: ExplorationDep, actor: ActorDep) -> ExplorationOut:
    if not ex.stop(actor):
        raise ProblemError(409, "not exploring", kind="not-exploring", state=ex.status()["state"])
    return ExplorationOut(**ex.status())
