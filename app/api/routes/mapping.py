"""Mapping sessions: start / stop live SLAM and save the map it built (Cartographer + map_saver)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends
from pydantic import Field

from app.api.deps import RuntimeDep, StrictModel, feature_dependency
from app.api.problems import ProblemError
from app.api.routes.maps import MapOut, active_map_id, map_out
from app.api.routes.robot import refused
from app.api.schemas import ERRORS, Out, Pair
from app.features.mapping import Mapping, NoMapError
from app.features.recording import Recording
from app.modes import TransitionRefused
from app.runtime import Runtime

router = APIRouter(tags=["mapping"])


class MappingOut(Out):
    running: bool
    has_map: bool
    nodes: int = Field(description="pose-graph nodes")
    loop_closures: int
    map_size_m: Pair | None = Field(description="width, height in m")
    last_optimization_ms: float | None = Field(description="ms")
    front_end_ms: float | None = Field(description="ms per scan")
    scans_dropped: int
    scans_older_than_odometry: int = Field(
        description="scans stamped before the odometry history kept: paired with its oldest pose"
    )


MappingDep = Annotated[Mapping, Depends(feature_dependency(Mapping))]
UNAVAILABLE = ERRORS(s503="mapping is not running")


class SaveMapIn(StrictModel):
    """The name the map is stored under (any text, 1..100 characters, not only spaces)."""

    name: str = Field(min_length=1, max_length=100, pattern=r"\S")


@router.get(
    "/api/mapping",
    response_model=MappingOut,
    summary="Mapping state: running, nodes, loop closures, map size",
    responses=UNAVAILABLE,
)
def get_mapping(mapping: MappingDep) -> MappingOut:
    return MappingOut.model_validate(mapping.state())


@router.post(
    "/api/mapping/start",
    response_model=MappingOut,
    summary="Enter MAPPING with a fresh map (teleop stays allowed)",
    responses={**ERRORS(s409="the current mode does not allow MAPPING"), **UNAVAILABLE},
)
def start_mapping(mapping: MappingDep) -> MappingOut:
    try:
        mapping.start()
    except TransitionRefused as exc:
        raise refused(exc) from None
    return MappingOut.model_validate(mapping.state())


@router.post(
    "/api/mapping/stop",
    response_model=MappingOut,
    summary="Leave MAPPING (to IDLE); the map is kept for saving",
    responses={**ERRORS(s409="the mode machine refused"), **UNAVAILABLE},
)
def stop_mapping(mapping: MappingDep) -> MappingOut:
    try:
        mapping.stop()
    except TransitionRefused as exc:
        raise refused(exc) from None
    return MappingOut.model_validate(mapping.state())


@router.post(
    "/api/mapping/save",
    response_model=MapOut,
    summary="Store the map built by the current or last mapping session; returns the stored map",
    description="A name another map has gets a version suffix (`name (2)`); the answer's `name` says.",
    status_code=201,
    responses={
        **ERRORS(s409="no map has been built"),
        **UNAVAILABLE,
    },
)
def save_map(body: SaveMapIn, rt: RuntimeDep, mapping: MappingDep) -> MapOut:
    try:
        grid = mapping.current_map()
    except NoMapError as exc:
        raise ProblemError(409, str(exc), kind="no-map") from None
    info = rt.maps.add(
        rt.maps.free_name(body.name.strip()),
        grid,
        source="slam",
        robot_id=rt.robot_id,
        run_id=_run_id(rt, mapping),
    )
    mapping.saved(info.id)
    return map_out(info, active_map_id(rt))


def _run_id(rt: Runtime, mapping: Mapping) -> int | None:
    """The recorder's run of this mapping session, when one was recorded."""
    rec = rt.find_feature(Recording)
    run_id = None if rec is None else rec.recorder.current_run_id
    return run_id if run_id is not None else mapping.run_id
