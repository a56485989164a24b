from __future__ import annotations

from fastapi import APIRouter

from app.api.deps import RuntimeDep

router = APIRouter(tags=["health"])


@router.get("/api/health", summary="Liveness and the control loop's health")
def health(rt: RuntimeDep) -> dict:
    s = rt.session
    return {
        "status": "ok" if s.fault is None else "fault",
        "mode": s.modes.mode.value,
        "robot": rt.settings.robot,
        "robot_name": rt.settings.robot_name,
        "profile": rt.profile.name,
        "world": rt.world_name,
        "health": s.health(),
    }
