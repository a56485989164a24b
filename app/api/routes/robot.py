"""Robot state, mode changes, e-stop and reset."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from app.api.deps import RuntimeDep, StrictModel
from app.modes import TransitionRefused
from app.telemetry import pose_dict, twist_dict

router = APIRouter(tags=["robot"])


class ModeRequest(StrictModel):
    mode: str


def robot_state(rt) -> dict:
    s = rt.session
    return {
        "name": rt.settings.robot_name,
        "mode": s.modes.mode.value,
        "mode_reason": s.modes.reason,
        "allowed_modes": s.modes.allowed(),
        "pose": pose_dict(s.pose),
        "odom_pose": pose_dict(s.odom_pose),
        "velocity": twist_dict(s.velocity),
        "command": twist_dict(s.last_command),
        "clamped": list(s.last_clamped),
        "estop": s.estop_latched,
        "fault": s.fault,
        "profile": {
            "name": rt.profile.name,
            "kinematics": rt.profile.kinematics,
            "footprint": rt.profile.footprint_polygon().round(4).tolist(),
            "limits": rt.profile.limits.__dict__,
        },
        "health": s.health(),
        "control": rt.lease.as_dict(),
    }


def refused(exc: TransitionRefused) -> JSONResponse:
    return JSONResponse(status_code=409, content=exc.as_dict())


@router.get("/api/robot", summary="Mode, pose, velocity, profile and health")
def get_robot(rt: RuntimeDep) -> dict:
    return robot_state(rt)


@router.post(
    "/api/robot/mode",
    summary="Request a mode (409 with the allowed modes when refused)",
    description="A mode request is not driving: it never takes the control lease, and is refused "
    "(409) only while another client holds it.",
    responses={409: {"description": "transition refused, or another client holds control"}},
)
def set_mode(body: ModeRequest, rt: RuntimeDep):
    try:
        rt.session.request_mode(body.mode)
    except TransitionRefused as exc:
        return refused(exc)
    return robot_state(rt)


@router.post("/api/robot/estop", summary="Latch the emergency stop (always allowed)")
def estop(rt: RuntimeDep) -> dict:
    rt.session.estop("api")
    return robot_state(rt)


@router.post(
    "/api/robot/reset",
    summary="Release the e-stop or clear a fault",
    responses={409: {"description": "nothing to reset, or the fault is still present"}},
)
def reset(rt: RuntimeDep):
    try:
        rt.session.reset()
    except TransitionRefused as exc:
        return refused(exc)
    return robot_state(rt)
