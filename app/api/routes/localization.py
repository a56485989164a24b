"""Localization on the active map: state, initial pose (Rviz2's "2D Pose Estimate"), global localization."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from app.api.deps import RuntimeDep, StrictModel
from app.modes import TransitionRefused
from nav.types import Pose2D

router = APIRouter(tags=["localization"])


class PoseIn(StrictModel):
    """A pose in the map frame: metres and radians (CCW from +x). NaN/inf are refused (422)."""

    x: float
    y: float
    theta: float = 0.0


def _feature(rt: Any):
    loc = rt.features.get("localization")
    if loc is None:
        return None, JSONResponse({"detail": "localization is not running"}, status_code=503)
    return loc, None


@router.get(
    "/api/localization",
    summary="Pose, covariance, particle count, quality score and the localized flag",
    responses={503: {"description": "localization is not running"}},
)
def get_localization(rt: RuntimeDep):
    loc, err = _feature(rt)
    return err or loc.state()


@router.post(
    "/api/localization/initial_pose",
    summary="Tell the robot where it is (AMCL restarts around this pose)",
    responses={422: {"description": "off the map, inside a wall, or not finite"}},
)
def set_initial_pose(body: PoseIn, rt: RuntimeDep):
    from app.features.localization import LocalizationRequestError

    loc, err = _feature(rt)
    if err:
        return err
    try:
        loc.set_initial_pose(Pose2D(body.x, body.y, body.theta))
    except LocalizationRequestError as exc:
        return JSONResponse({"detail": str(exc)}, status_code=422)
    return loc.state()


@router.post(
    "/api/localization/global",
    summary="Find the robot anywhere on the map: particles everywhere, rotate in place until converged",
    responses={409: {"description": "the current mode does not allow LOCALIZING"}},
)
def start_global(rt: RuntimeDep):
    from app.features.localization import NoActiveMapError

    loc, err = _feature(rt)
    if err:
        return err
    try:
        loc.start_global()
    except TransitionRefused as exc:
        return JSONResponse(exc.as_dict(), status_code=409)
    except NoActiveMapError as exc:
        return JSONResponse({"detail": str(exc)}, status_code=409)
    return loc.state()
