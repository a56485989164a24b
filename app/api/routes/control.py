"""The control lease over REST: ``GET /api/control``, ``POST /api/control/acquire``, ``.../release``.

Many people may watch; exactly one client holds control and everyone sees who. The dashboard holds it
through its teleop websocket; scripts may hold it over REST (freed after ``Settings.lease_idle_s``).
The rules, as the API description states them, are ``app.security.LEASE_RULES``.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request
from fastapi.responses import JSONResponse
from pydantic import Field

from app.api.deps import RuntimeDep, StrictModel
from app.security import LEASE_RULES, principal_of
from app.viewer.scene import KIND_LABELS, Viewer

router = APIRouter(tags=["control"])


class AcquireRequest(StrictModel):
    take_over: bool = False


def _state(request: Request) -> dict:
    guard = request.app.state.guard
    p = principal_of(request.scope)
    return {
        **guard.as_dict(),
        "you": None
        if p is None
        else {"name": p.display, "role": p.role.value, "can_drive": p.can_drive, "holder": guard.holds(p)},
    }


@router.get("/api/control", summary="Who holds control, and whether it is you", description=LEASE_RULES)
def get_control(request: Request) -> dict:
    return _state(request)


@router.post(
    "/api/control/acquire",
    summary="Take control (``take_over`` takes it from the current holder)",
    description=LEASE_RULES,
    responses={409: {"description": "someone else holds control"}, 403: {"description": "viewer"}},
)
def acquire(body: AcquireRequest, request: Request):
    guard = request.app.state.guard
    p = principal_of(request.scope)
    if p is None or not p.can_drive:
        return JSONResponse({"detail": "only operators may take control"}, status_code=403)
    if not guard.acquire(p, take_over=body.take_over):
        h = guard.lease.holder
        return JSONResponse(
            {
                "detail": f"{h.name if h else 'another client'} holds control; ask them, or take over",
                "control": guard.as_dict(),
            },
            status_code=409,
        )
    guard.touch(p.client_id)
    return _state(request)


@router.post(
    "/api/control/release",
    summary="Give control back (teleop stops; a running mission keeps going)",
    description=LEASE_RULES,
)
def release(request: Request):
    guard = request.app.state.guard
    p = principal_of(request.scope)
    if p is None or not guard.release(p):
        return JSONResponse(
            {"detail": "you do not hold control", "control": guard.as_dict()}, status_code=409
        )
    return _state(request)


class ClickModeRequest(StrictModel):
    kind: str
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


@router.get(
    "/api/viewer/click_mode",
    summary="What a click in one browser tab's 3D view sets: goal or initial_pose",
    responses={503: {"description": "no 3D view"}},
)
def get_click_mode(viewer: ViewerDep, tab: str = Query("", max_length=64, pattern=r"^[A-Za-z0-9_-]*$")):
    if viewer is None:
        return JSONResponse({"detail": "the 3D view is not running"}, status_code=503)
    return {"kind": viewer.click_kind(tab), "tab": tab}


@router.post(
    "/api/viewer/click_mode",
    summary="Choose what a click in one browser tab's 3D view sets (like Rviz2's pose tools); other tabs "
    "keep theirs. An initial pose is one-shot: once set, that tab's clicks set goals again",
    responses={422: {"description": "unknown kind or tab"}, 503: {"description": "no 3D view"}},
)
def set_click_mode(body: ClickModeRequest, viewer: ViewerDep):
    if body.kind not in KIND_LABELS:  # the view's own pose kinds ("goal", "initial_pose")
        return JSONResponse({"detail": f"kind must be one of: {', '.join(KIND_LABELS)}"}, status_code=422)
    if viewer is None:
        return JSONResponse({"detail": "the 3D view is not running"}, status_code=503)
    viewer.set_click_kind(body.tab, body.kind)
    return {"kind": body.kind, "tab": body.tab}
