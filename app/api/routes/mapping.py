"""Mapping sessions: start / stop live SLAM and save the map it built (Cartographer + map_saver)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from fastapi.responses import JSONResponse
from pydantic import Field

from app.api.deps import RuntimeDep, StrictModel
from app.modes import TransitionRefused

router = APIRouter(tags=["mapping"])


class SaveMapIn(StrictModel):
    """The name the map is stored under (any text, 1..100 characters, not only spaces)."""

    name: str = Field(min_length=1, max_length=100, pattern=r"\S")


def _feature(rt: Any):
    mapping = rt.features.get("mapping")
    if mapping is None:
        return None, JSONResponse({"detail": "mapping is not running"}, status_code=503)
    return mapping, None


@router.get("/api/mapping", summary="Mapping state: running, nodes, loop closures, map size")
def get_mapping(rt: RuntimeDep):
    mapping, err = _feature(rt)
    return err or mapping.state()


@router.post(
    "/api/mapping/start",
    summary="Enter MAPPING with a fresh map (teleop stays allowed)",
    responses={409: {"description": "the current mode does not allow MAPPING"}},
)
def start_mapping(rt: RuntimeDep):
    mapping, err = _feature(rt)
    if err:
        return err
    try:
        mapping.start()
    except TransitionRefused as exc:
        return JSONResponse(exc.as_dict(), status_code=409)
    return mapping.state()


@router.post(
    "/api/mapping/stop",
    summary="Leave MAPPING (to IDLE); the map is kept for saving",
    responses={409: {"description": "the mode machine refused"}},
)
def stop_mapping(rt: RuntimeDep):
    mapping, err = _feature(rt)
    if err:
        return err
    try:
        mapping.stop()
    except TransitionRefused as exc:
        return JSONResponse(exc.as_dict(), status_code=409)
    return mapping.state()


@router.post(
    "/api/mapping/save",
    summary="Store the map built by the current or last mapping session; returns its id",
    status_code=201,
    responses={409: {"description": "no map has been built"}},
)
def save_map(body: SaveMapIn, rt: RuntimeDep):
    from app.features.mapping import NoMapError

    mapping, err = _feature(rt)
    if err:
        return err
    try:
        grid = mapping.current_map()
    except NoMapError as exc:
        return JSONResponse({"detail": str(exc)}, status_code=409)
    info = rt.maps.add(
        body.name.strip(), grid, source="slam", robot_id=rt.robot_id, run_id=_run_id(rt, mapping)
    )
    mapping.saved(info.id)
    return JSONResponse({"id": info.id, **info.as_dict()}, status_code=201)


def _run_id(rt: Any, mapping: Any) -> int | None:
    """The recorder's run of this mapping session, when one was recorded."""
    rec = rt.features.get("recording")
    recorder = getattr(rec, "recorder", None)
    run_id = getattr(recorder, "current_run_id", None)
    return run_id if run_id is not None else mapping.run_id
