"""Navigation: goals and waypoints (Rviz2's "Nav2 Goal"), state and feedback, cancel."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from app.api.deps import RuntimeDep, StrictModel
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
    description="Takes the control lease if it is free. The mission then runs on its own: it is not "
    "cancelled when the client goes quiet, closes its sockets or its lease ends (only teleop has a "
    "deadman); it ends when reached or failed, by `POST /api/navigation/cancel`, a mode request or "
    "the e-stop. See the lease rules in the API description.",
    responses={
        409: {
            "description": "not localized, e-stop, fault, the mode does not allow navigating, or "
            "another client holds control"
        },
        422: {
            "description": "goal off the map, in an obstacle or its inscribed radius (+ nearest free "
            "pose), or an unknown or conflicting controller"
        },
    },
)
def post_goals(body: GoalIn | list[GoalIn], rt: RuntimeDep):
    from app.features.navigation import GoalRejected, NavigationRefused

    nav, err = _feature(rt)
    if err:
        return err
    goals = body if isinstance(body, list) else [body]
    if not goals:
        return JSONResponse({"detail": "goals: give at least one goal"}, status_code=422)
    named = {g.controller for g in goals if g.controller is not None}
    if len(named) > 1:
        return JSONResponse(
            {"detail": f"controller: one request drives with one controller, got {sorted(named)}"},
            status_code=422,
        )
    try:
        nav.set_goals([Pose2D(g.x, g.y, g.theta) for g in goals], named.pop() if named else None)
    except GoalRejected as exc:
        return JSONResponse(exc.as_dict(), status_code=422)
    except NavigationRefused as exc:
        return JSONResponse(exc.as_dict(), status_code=409)
    return navigation_state(nav)


@router.post("/api/navigation/cancel", summary="Cancel navigation (the robot stops, outcome 'cancelled')")
def cancel(rt: RuntimeDep):
    nav, err = _feature(rt)
    if err:
        return err
    was_running = nav.cancel()
    return {**navigation_state(nav), "cancelled": was_running}


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
