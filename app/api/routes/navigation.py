"""Navigation: goals and waypoints (Rviz2's "Nav2 Goal"), state and feedback, cancel."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends
from pydantic import Field

from app.api.deps import ActorDep, RuntimeDep, StrictModel, feature_dependency
from app.api.problems import ProblemError, problem_responses
from app.api.routes.missions import MissionsDep, start_mission
from app.api.routes.places import resolve_place
from app.api.schemas import NavigationOut, public_navigation
from app.features.missions import MissionEnded
from app.features.navigation import Navigation
from nav.types import Pose2D

router = APIRouter(tags=["navigation"])


class CostmapViewIn(StrictModel):
    view: Literal["global", "local"]


class GoalIn(StrictModel):
    """A goal pose in the map frame: metres and radians. NaN/inf are refused (422). ``controller``
    picks the local controller for this request ("dwa" | "teb"; default: the profile's); in a list
    of waypoints every goal that names one must name the same."""

    x: float
    y: float
    theta: float = 0.0
    controller: Literal["dwa", "teb"] | None = None
    allow_unknown: bool | None = None
    """Accept a goal in unknown space (None: the navigation option ``allow_unknown_goals``); in a
    list, any goal that sets it sets it for the whole request."""


class PlaceGoalIn(StrictModel):
    """A goal by name: a place of the active map (``GET /api/maps/{id}/places``)."""

    place: str = Field(min_length=1, max_length=100)
    controller: Literal["dwa", "teb"] | None = None


NavigationDep = Annotated[Navigation, Depends(feature_dependency(Navigation))]
UNAVAILABLE = problem_responses(s503="navigation is not running")


class GoalsOut(NavigationOut):
    mission_id: str = Field(description="the mission this request became: wait on it")
    mission_url: str


class CancelOut(NavigationOut):
    canceled: bool = Field(description="a request was running and is now stopping")
    mission_id: str | None


def navigation_state(nav: Any) -> dict[str, Any]:
    state = public_navigation(nav.state())
    path = nav.path()
    state["path"] = [] if path is None else path.poses[:, :2].round(3).tolist()
    return state


@router.get(
    "/api/navigation",
    response_model=NavigationOut,
    summary="State, current goal and waypoints, path, feedback and the last outcome",
    responses=UNAVAILABLE,
)
def get_navigation(nav: NavigationDep) -> NavigationOut:
    return NavigationOut.model_validate(navigation_state(nav))


@router.post(
    "/api/navigation/goals",
    summary="Navigate to a goal, or through a list of goals (waypoints); replaces the current request",
    description="A thin wrapper over `POST /api/missions`: answers the new navigation state (`planning`, "
    "`active: true`) with the `mission_id` to wait on (`GET /api/missions/{id}?wait=30`). Takes the "
    "control lease if it is free. The mission then runs on its own: it is not cancelled when the client "
    "goes quiet, closes its sockets or its lease ends (only teleop has a deadman); it ends when reached "
    "or failed, by a cancel, a new mission, a mode request or the e-stop. See the lease rules in the API "
    "description.",
    response_model=GoalsOut,
    responses={
        **problem_responses(
            s409="not localized, e-stop, fault, the mode does not allow navigating, or another client "
            "holds control",
            s422="goal off the map, in an obstacle or its inscribed radius (`reason`, `index`, "
            "`nearest_free`; a goal in unknown space names `allow_unknown`), an unknown place name "
            "(`places`: the known ones), or an unknown or "
            "conflicting controller",
        ),
        **UNAVAILABLE,
    },
)
def post_goals(
    body: GoalIn | PlaceGoalIn | list[GoalIn],
    rt: RuntimeDep,
    nav: NavigationDep,
    missions: MissionsDep,
    actor: ActorDep,
) -> GoalsOut:
    if isinstance(body, PlaceGoalIn):
        pose = resolve_place(rt, body.place)
        body = GoalIn(x=pose.x, y=pose.y, theta=pose.theta, controller=body.controller)
    goals = body if isinstance(body, list) else [body]
    named = {g.controller for g in goals if g.controller is not None}
    if len(named) > 1:
        raise ProblemError(
            422,
            f"controller: one request drives with one controller, got {sorted(named)}",
            kind="invalid-request",
        )
    flags = {g.allow_unknown for g in goals if g.allow_unknown is not None}
    allow_unknown = None if not flags else any(flags)
    m = start_mission(
        missions,
        [Pose2D(g.x, g.y, g.theta) for g in goals],
        named.pop() if named else None,
        actor,
        allow_unknown,
    )
    # the new state (the loop picks the request up on its next tick), and the mission to wait on
    return GoalsOut.model_validate(
        {**navigation_state(nav), "mission_id": m.id, "mission_url": f"/api/missions/{m.id}"}
    )


@router.post(
    "/api/navigation/cancel",
    response_model=CancelOut,
    summary="Cancel navigation (the robot stops, state `canceled`); answers the new state",
    responses=UNAVAILABLE,
)
def cancel(nav: NavigationDep, missions: MissionsDep, actor: ActorDep) -> CancelOut:
    m = missions.for_request(nav.current_request)
    if m is None:
        was_running = nav.cancel(actor=actor)
    else:
        try:
            missions.cancel(m.id, actor)
            was_running = True
        except MissionEnded:  # it ended between the look-up and the cancel
            was_running = False
    return CancelOut.model_validate(
        {**navigation_state(nav), "canceled": was_running, "mission_id": None if m is None else m.id}
    )


@router.post(
    "/api/navigation/costmap_view",
    response_model=NavigationOut,
    summary="Which costmap the 3D view overlays: the global one or the 3 x 3 m local window",
    responses=UNAVAILABLE,
)
def set_costmap_view(body: CostmapViewIn, nav: NavigationDep) -> NavigationOut:
    nav.costmap_view = body.view
    return NavigationOut.model_validate(navigation_state(nav))
