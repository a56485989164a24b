"""Navigation: goals and waypoints (Rviz2's "Nav2 Goal"), state and feedback, cancel."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from app.api.deps import ActorDep, RuntimeDep, StrictModel
from app.api.problems import ProblemError, problem_responses
from app.api.routes.missions import get_missions, start_mission
from app.features.missions import MissionEnded
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


def _feature(rt: Any):
    nav = rt.features.get("navigation")
    if nav is None:
        return None, JSONResponse({"detail": "navigation is not running"}, status_code=503)
    return nav, None


def navigation_state(nav: Any) -> dict:
    state = nav.state()
    path = nav.path()
    state["path"] = [] if path is None else path.poses[:, :2].round(3).tolist()
    return state


@router.get(
    "/api/navigation",
    summary="State, current goal and waypoints, path, feedback and the last outcome",
    responses={503: {"description": "navigation is not running"}},
)
def get_navigation(rt: RuntimeDep):
    nav, err = _feature(rt)
    return err or navigation_state(nav)


@router.post(
    "/api/navigation/goals",
    summary="Navigate to a goal, or through a list of goals (waypoints); replaces the current request",
    description="A thin wrapper over `POST /api/missions`: answers the new navigation state (`planning`, "
    "`active: true`) with the `mission_id` to wait on (`GET /api/missions/{id}?wait=30`). Takes the "
    "control lease if it is free. The mission then runs on its own: it is not cancelled when the client "
    "goes quiet, closes its sockets or its lease ends (only teleop has a deadman); it ends when reached "
    "or failed, by a cancel, a new mission, a mode request or the e-stop. See the lease rules in the API "
    "description.",
    responses=problem_responses(
        s409="not localized, e-stop, fault, the mode does not allow navigating, or another client holds "
        "control",
        s422="goal off the map, in an obstacle or its inscribed radius (`reason`, `index`, `nearest_free`), "
        "or an unknown or conflicting controller",
    ),
)
def post_goals(body: GoalIn | list[GoalIn], rt: RuntimeDep, actor: ActorDep):
    nav, err = _feature(rt)
    if err:
        return err
    goals = body if isinstance(body, list) else [body]
    named = {g.controller for g in goals if g.controller is not None}
    if len(named) > 1:
        raise ProblemError(
            422,
            f"controller: one request drives with one controller, got {sorted(named)}",
            kind="invalid-request",
        )
    missions = get_missions(rt)
    m = start_mission(
        missions, [Pose2D(g.x, g.y, g.theta) for g in goals], named.pop() if named else None, actor
    )
    # the new state (the loop picks the request up on its next tick), and the mission to wait on
    return {**navigation_state(nav), "mission_id": m.id, "mission_url": f"/api/missions/{m.id}"}


@router.post(
    "/api/navigation/cancel",
    summary="Cancel navigation (the robot stops, outcome 'cancelled'); answers the new state",
)
def cancel(rt: RuntimeDep, actor: ActorDep):
    nav, err = _feature(rt)
    if err:
        return err
    missions = get_missions(rt)
    m = missions.for_request(nav.current_request)
    if m is None:
        was_running = nav.cancel(actor=actor)
    else:
        try:
            missions.cancel(m.id, actor)
            was_running = True
        except MissionEnded:  # it ended between the look-up and the cancel
            was_running = False
    return {**navigation_state(nav), "cancelled": was_running, "mission_id": None if m is None else m.id}


@router.post(
    "/api/navigation/costmap_view",
    summary="Which costmap the 3D view overlays: the global one or the 3 x 3 m local window",
)
def set_costmap_view(body: CostmapViewIn, rt: RuntimeDep):
    nav, err = _feature(rt)
    if err:
        return err
    nav.costmap_view = body.view
    return navigation_state(nav)
