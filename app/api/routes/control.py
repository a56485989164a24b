"""The control lease over REST: ``GET /api/control``, ``POST /api/control/acquire``, ``.../release``.

Many people may watch; exactly one client holds control and everyone sees who. The dashboard holds it
through its teleop websocket; scripts may hold it over REST (freed after ``Settings.lease_idle_s``).
The rules, as the API description states them, are ``app.security.LEASE_RULES``.
"""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse

from app.api.deps import StrictModel
from app.security import LEASE_RULES, principal_of

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


# The 3D view's "Click sets" dropdown: its labels and the pose-input kinds they stand for.
CLICK_KINDS = {"goal": "goal", "initial_pose": "initial pose"}


@router.get("/api/viewer/click_mode", summary="What a click in the 3D view sets: goal or initial_pose")
def get_click_mode(request: Request):
    viewer = request.app.state.runtime.viewer
    if viewer is None or not hasattr(viewer, "click_mode"):
        return JSONResponse({"detail": "the 3D view is not running"}, status_code=503)
    label = str(viewer.click_mode.value)
    return {"kind": next((k for k, v in CLICK_KINDS.items() if v == label), "goal")}


@router.post(
    "/api/viewer/click_mode",
    summary="Choose what a click in the 3D view sets (like Rviz2's pose tools); shared by all viewers",
    responses={422: {"description": "unknown kind"}, 503: {"description": "no 3D view"}},
)
def set_click_mode(body: ClickModeRequest, request: Request):
    viewer = request.app.state.runtime.viewer
    if body.kind not in CLICK_KINDS:
        return JSONResponse({"detail": f"kind must be one of: {', '.join(CLICK_KINDS)}"}, status_code=422)
    if viewer is None or not hasattr(viewer, "click_mode"):
        return JSONResponse({"detail": "the 3D view is not running"}, status_code=503)
    viewer.click_mode.value = CLICK_KINDS[body.kind]
    return {"kind": body.kind}
