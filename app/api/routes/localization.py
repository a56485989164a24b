"""Localization on the active map: state, initial pose (Rviz2's "2D Pose Estimate"), global localization."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends
from fastapi.concurrency import run_in_threadpool
from pydantic import Field

from app.api.deps import StrictModel, feature_dependency
from app.api.problems import ProblemError
from app.api.routes.robot import refused
from app.api.schemas import ERRORS, Out, Pose
from app.features.localization import (
    APPLY_TIMEOUT_S,
    Localization,
    LocalizationRequestError,
    NoActiveMapError,
    nearest_free_pose,
)
from app.modes import TransitionRefused
from nav.types import Pose2D

router = APIRouter(tags=["localization"])


class PoseIn(StrictModel):
    """A pose in the map frame: metres and radians (CCW from +x). NaN/inf are refused (422)."""

    x: float = Field(description="m")
    y: float = Field(description="m")
    theta: float = Field(0.0, description="rad")


class LocalizationOut(Out):
    source: Literal["amcl", "truth"]
    localized: bool = Field(
        description="the scan fits the active map at the estimate: true at a filter update with "
        "`fit >= criterion.localized_fit_on` (and spread within `localized_max_spread`), false after "
        "`unlocalized_updates` updates below `localized_fit_off`; docs/localization.md (criterion)"
    )
    converged: bool = Field(
        description="at the last filter update the particle spread (larger x / y std) was within "
        "`matched_std_xy` and the scan matched the map at the estimate with `quality >= min_quality`"
    )
    global_running: bool
    pose: Pose = Field(description="the estimate, map frame")
    covariance: list[list[float]] = Field(description="3x3 of x (m), y (m), theta (rad)")
    spread_m: float = Field(description="the estimate's larger x / y standard deviation, m")
    particles: int
    quality: float = Field(description="0..1, how well the last scan fits the map at the estimate")
    fit: float = Field(
        description="0..1, the fraction of the last scan's returns ending within `fit_tolerance` (m) "
        "of a mapped obstacle at the estimate: what `localized` is decided on"
    )
    match_score: float = Field(
        description="`quality` while the cloud is tight (spread within `matched_std_xy`), else 0"
    )
    map_mismatch: bool = Field(
        description="the cloud is tight but the scan does not fit the map (`quality < mismatch_quality`): "
        "the active map is probably not where the robot is"
    )
    updates: int = Field(description="filter updates since start")
    map_id: int | None
    map_version: int
    criterion: dict[str, float] = Field(
        description="the thresholds: `matched_std_xy` (m), `min_quality`, `mismatch_quality` (0..1), "
        "`fit_tolerance` (m), `localized_fit_on`, `localized_fit_off` (0..1), `unlocalized_updates`, "
        "`localized_max_spread` (m)"
    )


LocalizationDep = Annotated[Localization, Depends(feature_dependency(Localization))]
UNAVAILABLE = ERRORS(s503="localization is not running")


@router.get(
    "/api/localization",
    response_model=LocalizationOut,
    summary="Pose, covariance, particle count, quality score and the localized flag",
    responses=UNAVAILABLE,
)
def get_localization(loc: LocalizationDep) -> LocalizationOut:
    return LocalizationOut.model_validate(loc.state())


def _pose_problem(loc: Any, exc: LocalizationRequestError, pose: Pose2D) -> ProblemError:
    nf = nearest_free_pose(loc, pose)
    return ProblemError(
        422,
        str(exc),
        kind="pose-rejected",
        nearest_free=None if nf is None else {"x": nf.x, "y": nf.y, "theta": nf.theta},
    )


@router.post(
    "/api/localization/initial_pose",
    response_model=LocalizationOut,
    summary="Tell the robot where it is (AMCL restarts around this pose); answers after the filter's "
    "first update there",
    description="The answer is the state after the control loop applied the pose and the filter "
    f"weighed the next scan there (at most {APPLY_TIMEOUT_S:g} s): the new pose, the particles, the "
    "scan's fit (`quality`) and whether that counts as localized.",
    responses={
        **ERRORS(s422="off the map, inside a wall, or not finite (`nearest_free` when there is one)"),
        **UNAVAILABLE,
    },
)
async def set_initial_pose(body: PoseIn, loc: LocalizationDep) -> LocalizationOut:
    pose = Pose2D(body.x, body.y, body.theta)
    try:
        loc.set_initial_pose(pose)
    except LocalizationRequestError as exc:
        raise _pose_problem(loc, exc, pose) from None
    await run_in_threadpool(loc.wait_applied, APPLY_TIMEOUT_S)
    return LocalizationOut.model_validate(loc.state())


@router.post(
    "/api/localization/global",
    response_model=LocalizationOut,
    summary="Find the robot anywhere on the map: particles everywhere, rotate in place until converged",
    responses={
        **ERRORS(s409="the current mode does not allow LOCALIZING, or there is no map"),
        **UNAVAILABLE,
    },
)
def start_global(loc: LocalizationDep) -> LocalizationOut:
    try:
        loc.start_global()
    except TransitionRefused as exc:
        raise refused(exc) from None
    except NoActiveMapError as exc:
        raise ProblemError(409, str(exc), kind="no-active-map") from None
    return LocalizationOut.model_validate(loc.state())
