"""Robot state, mode changes, e-stop and reset."""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated

from fastapi import APIRouter, Depends, Request
from pydantic import Field

from app.api.deps import RuntimeDep, StrictModel
from app.api.problems import ProblemError
from app.api.schemas import ERRORS, ControlState, Health, Out, Pair, Pose, Twist
from app.modes import USER_REQUESTABLE, Mode, TransitionRefused
from app.security import LeaseGuard
from app.telemetry import pose_dict, twist_dict

router = APIRouter(tags=["robot"])


class RequestableMode(StrEnum):
    """The modes an operator may ask for by name (``app.modes.USER_REQUESTABLE``); the others
    (`recovering`, `estop`, `fault`) are entered by the robot or by their own calls (e-stop, reset)."""

    IDLE = "idle"
    TELEOP = "teleop"
    MAPPING = "mapping"
    LOCALIZING = "localizing"
    NAVIGATING = "navigating"


assert {m.value for m in RequestableMode} == {m.value for m in USER_REQUESTABLE}


class ModeRequest(StrictModel):
    """Unknown or not requestable names are refused with 422 (the schema lists the choices)."""

    mode: RequestableMode


class Limits(Out):
    """Velocity (m/s, rad/s) and acceleration (m/s², rad/s²) limits, Nav2 parameter names."""

    max_vel_x: float
    min_vel_x: float
    max_vel_y: float
    max_vel_theta: float
    min_speed_xy: float
    min_speed_theta: float
    acc_lim_x: float
    acc_lim_y: float
    acc_lim_theta: float
    decel_lim_x: float
    decel_lim_y: float
    decel_lim_theta: float


class Profile(Out):
    """The robot profile: the one shape of ``profile`` everywhere (telemetry carries ``profile_name``)."""

    name: str
    kinematics: str = Field(description="`diff` or `omni`")
    footprint: list[Pair] = Field(description="polygon in base_link, m")
    limits: Limits


class RobotOut(Out):
    name: str
    mode: Mode
    mode_reason: str
    allowed_modes: list[Mode] = Field(description="modes a request may enter from here")
    pose: Pose = Field(description="map frame")
    odom_pose: Pose = Field(description="odom frame")
    velocity: Twist = Field(description="measured")
    command: Twist = Field(description="last command sent to the base")
    clamped: list[str] = Field(description="limits that clamped the last command")
    estop: bool
    fault: str | None
    profile: Profile
    health: Health
    control: ControlState


def get_guard(request: Request) -> LeaseGuard:
    return request.app.state.guard


GuardDep = Annotated[LeaseGuard, Depends(get_guard)]


def robot_state(rt, guard: LeaseGuard) -> RobotOut:
    s = rt.session
    return RobotOut.model_validate(
        {
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
            "control": guard.as_dict(),
        }
    )


def refused(exc: TransitionRefused) -> ProblemError:
    """409 for a refused mode change, with ``mode``, ``requested`` and ``allowed``."""
    body = exc.as_dict()
    return ProblemError(409, body.pop("detail"), kind="mode-refused", **body)


REFUSED = ERRORS(s409="transition refused (`mode`, `requested`, `allowed`), or another client holds control")


@router.get("/api/robot", response_model=RobotOut, summary="Mode, pose, velocity, profile and health")
def get_robot(rt: RuntimeDep, guard: GuardDep) -> RobotOut:
    return robot_state(rt, guard)


@router.post(
    "/api/robot/mode",
    response_model=RobotOut,
    summary="Request a mode (409 with the allowed modes when refused; 422 for an unknown mode)",
    description="A mode request is not driving: it never takes the control lease, and is refused "
    "(409) only while another client holds it. Answers the new robot state.",
    responses=REFUSED,
)
def set_mode(body: ModeRequest, rt: RuntimeDep, guard: GuardDep) -> RobotOut:
    try:
        rt.session.request_mode(body.mode.value)
    except TransitionRefused as exc:
        raise refused(exc) from None
    return robot_state(rt, guard)


@router.post(
    "/api/robot/estop",
    response_model=RobotOut,
    summary="Latch the emergency stop (always allowed); answers the new state (`mode: estop`)",
)
def estop(rt: RuntimeDep, guard: GuardDep) -> RobotOut:
    rt.session.estop("api")
    return robot_state(rt, guard)


@router.post(
    "/api/robot/reset",
    response_model=RobotOut,
    summary="Release the e-stop or clear a fault; answers the new state",
    responses=ERRORS(s409="nothing to reset, or the fault is still present"),
)
def reset(rt: RuntimeDep, guard: GuardDep) -> RobotOut:
    try:
        rt.session.reset()
    except TransitionRefused as exc:
        raise refused(exc) from None
    return robot_state(rt, guard)
