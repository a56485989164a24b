"""Shared route dependencies and request models."""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, TypeVar

from fastapi import Depends, Request, WebSocket
from pydantic import BaseModel, ConfigDict

from app.api.problems import ProblemError
from app.api.schemas import DbId
from app.map_store import MapInfo
from app.runtime import Runtime
from app.security import principal_of
from nav.types import OccupancyGrid


class StrictModel(BaseModel):
    """Request bodies: unknown fields are errors and NaN/inf never get in (422)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


def get_runtime(request: Request) -> Runtime:
    return request.app.state.runtime


def get_runtime_ws(websocket: WebSocket) -> Runtime:
    return websocket.app.state.runtime


RuntimeDep = Annotated[Runtime, Depends(get_runtime)]

FeatureT = TypeVar("FeatureT")


def feature_dependency(kind: type[FeatureT]) -> Callable[[Runtime], FeatureT]:
    """A route dependency giving the running feature of this type. A server without it answers 503
    (``FeatureUnavailable``, turned into a problem by ``app.api.problems``), in this one place."""

    def running_feature(rt: RuntimeDep) -> FeatureT:
        return rt.feature(kind)

    return running_feature


def get_actor(request: Request) -> str:
    """Who is asking, as others may see it (a mission's cancel actor): the user, else ``operator``."""
    p = principal_of(request.scope)
    return p.display if p is not None else "operator"


ActorDep = Annotated[str, Depends(get_actor)]


def get_map_info(map_id: DbId, rt: RuntimeDep) -> MapInfo:
    """The stored map the path names, or 404 (one place for every ``/api/maps/{map_id}/...`` route)."""
    info = rt.maps.info(map_id)
    if info is None:
        raise ProblemError(404, f"no map with id {map_id}", kind="not-found")
    return info


MapInfoDep = Annotated[MapInfo, Depends(get_map_info)]


def get_map_grid(map_id: DbId, rt: RuntimeDep) -> OccupancyGrid:
    """The occupancy grid of the map the path names, or 404."""
    grid = rt.maps.grid(map_id)
    if grid is None:
        raise ProblemError(404, f"no map with id {map_id}", kind="not-found")
    return grid


MapGridDep = Annotated[OccupancyGrid, Depends(get_map_grid)]
