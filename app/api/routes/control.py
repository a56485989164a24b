"""The control lease over REST: ``GET /api/control``, ``POST /api/control/acquire``, ``.../release``.

Many people may watch; exactly one client holds control and everyone sees who. The dashboard holds it
through its teleop websocket; scripts may hold it over REST (freed after ``Settings.lease_idle_s``).
The rules, as the API description states them, are ``app.security.LEASE_RULES``.
"""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Body, Depends, Query, Request
from pydantic import Field

from app.api.deps import RuntimeDep, StrictModel
from app.api.problems import ProblemError
from app.api.schemas import ERRORS, ControlState, Out
from app.auth import Role
from app.security import LEASE_RULES, principal_of
from app.viewer.scene import KIND_LABELS, Viewer

router = APIRouter(tags=["control"])

ClickKind = Literal["goal", "goal_unknown", "initial_pose"]
"""What a click in the 3D view sets (the view's own pose kinds, ``KIND_LABELS``)."""
assert set(ClickKind.__args__) == set(KIND_LABELS)  # type: ignore[attr-defined]


class AcquireRequest(StrictModel):
    take_over: bool = Field(False, description="take control from the current holder")


class You(Out):
    name: str
    role: Role
    can_drive: bool
    holder: bool = Field(description="you hold control")


class ControlOut(ControlState):
    you: You | None = Field(description="the caller, null when not signed in")


def _state(request: Request) -> ControlOut:
    guard = request.app.state.guard
    p = principal_of(request.scope)
    you = (
        None if p is None else You(name=p.display, role=p.role, can_drive=p.can_drive, holder=guard.holds(p))
    )
    return ControlOut.model_validate({**guard.as_dict(), "you": you})


@router.get(
    "/api/control",
    response_model=ControlOut,
    summary="Who holds control, and whether it is you",
    description=LEASE_RULES,
)
def get_control(request: Request) -> ControlOut:
    return _state(request)


@router.post(
    "/api/control/acquire",
    response_model=ControlOut,
    summary="Take control (``take_over`` takes it from the current holder); the body is optional",
    description=LEASE_RULES,
    responses=ERRORS(s403="a viewer may not drive", s409="someone else holds control (`control`)"),
)
def acquire(request: Request, body: Annotated[AcquireRequest | None, Body()] = None) -> ControlOut:
    guard = request.app.state.guard
    p = principal_of(request.scope)
    if p is None or not p.can_drive:
        raise ProblemError(403, "only operators may take control", kind="forbidden")
    if not guard.acquire(p, take_over=body is not None and body.take_over):
        h = guard.lease.holder
        raise ProblemError(
            409,
            f"{h.name if h else 'another client'} holds control; ask them, or take over",
            kind="control-held",
            control=guard.as_dict(),
        )
    guard.touch(p.client_id)
    return _state(request)


@router.post(
    "/api/control/release",
    response_model=ControlOut,
    summary="Give control back (teleop stops; a running mission keeps going)",
    description=LEASE_RULES,
    responses=ERRORS(s409="you do not hold control (`control`)"),
)
def release(request: Request) -> ControlOut:
    guard = request.app.state.guard
    p = principal_of(request.scope)
    if p is None or not guard.release(p):
        raise ProblemError(409, "you do not hold control", kind="not-holder", control=guard.as_dict())
    return _state(request)


class ClickModeRequest(StrictModel):
    kind: ClickKind
    tab: str = Field(
        min_length=1,
        max_length=64,
        pattern=r"^[A-Za-z0-9_-]+$",
        description="the browser tab whose 3D view this is for (the dashboard sends its view's tab token)",
    )


def get_viewer(runtime: RuntimeDep) -> Viewer | None:
    """The running 3D view, or None (``--no-viewer``)."""
    viewer = runtime.viewer
    return viewer if isinstance(viewer, Viewer) else None


ViewerDep = Annotated[Viewer | None, Depends(get_viewer)]


class ClickModeOut(Out):
    kind: ClickKind
    tab: str


NO_VIEW = ERRORS(s503="the 3D view is not running")


def _viewer(viewer: Viewer | None) -> Viewer:
    if viewer is None:
        raise ProblemError(503, "the 3D view is not running", kind="viewer-unavailable")
    return viewer


@router.get(
    "/api/viewer/click_mode",
    response_model=ClickModeOut,
    summary="What a click in one browser tab's 3D view sets: goal, goal_unknown (a goal that may lie in "
    "unknown space) or initial_pose",
    responses=NO_VIEW,
)
def get_click_mode(
    viewer: ViewerDep, tab: str = Query("", max_length=64, pattern=r"^[A-Za-z0-9_-]*$")
) -> ClickModeOut:
    return ClickModeOut(kind=_viewer(viewer).click_kind(tab), tab=tab)


@router.post(
    "/api/viewer/click_mode",
    summary="Choose what a click in one browser tab's 3D view sets (like Rviz2's pose tools); other tabs "
    "keep theirs. An initial pose is one-shot: once set, that tab's clicks set goals again",
    response_model=ClickModeOut,
    responses=NO_VIEW,
)
def set_click_mode(body: ClickModeRequest, viewer: ViewerDep) -> ClickModeOut:
    _viewer(viewer).set_click_kind(body.tab, body.kind)
    return ClickModeOut(kind=body.kind, tab=body.tab)
