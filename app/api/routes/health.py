from __future__ import annotations

from typing import Literal

from fastapi import APIRouter
from pydantic import Field

from app.api.deps import RuntimeDep
from app.api.schemas import Health, Out
from app.modes import Mode

router = APIRouter(tags=["health"])


class HealthOut(Out):
    status: Literal["ok", "fault"]
    mode: Mode
    robot: str = Field(description="the robot URI it was served with (`sim://...`, `serial://...`)")
    robot_name: str
    profile_name: str = Field(description="the robot profile's name (`GET /api/robot` has the profile)")
    world: str | None = Field(description="the simulated world, null on a real robot")
    health: Health


@router.get("/api/health", response_model=HealthOut, summary="Liveness and the control loop's health")
def health(rt: RuntimeDep) -> HealthOut:
    s = rt.session
    return HealthOut.model_validate(
        {
            "status": "ok" if s.fault is None else "fault",
            "mode": s.modes.mode.value,
            "robot": rt.settings.robot,
            "robot_name": rt.settings.robot_name,
            "profile_name": rt.profile.name,
            "world": rt.world_name,
            "health": s.health(),
        }
    )
