"""Map editing (issue 19): an edit (brush strokes, line walls, filled polygons) saved as a new version
of a map; the versions a map descends from. The edited map is not activated: activate it (or restore
an older version) with ``POST /api/maps/{id}/activate`` when the operator says so. Zones and places
are carried over to the new version.
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from fastapi import APIRouter, Query, Response
from fastapi.concurrency import run_in_threadpool
from pydantic import Field

from app.api.deps import MapGridDep, MapInfoDep, RuntimeDep, StrictModel
from app.api.problems import ProblemError
from app.api.routes.maps import MapOut, active_map_id, map_out
from app.api.schemas import ERRORS, DbId, Page, Pair
from app.place_store import PlaceStore
from app.zone_store import ZoneStore
from nav.costmap.filter_layer import MAX_VERTICES, PolygonError, validate_polygon
from nav.map_edit import Fill, Operation, Stroke, apply_edits

router = APIRouter(tags=["maps"])

Value = Literal["free", "occupied", "unknown"]


class BrushOp(StrictModel):
    """A brush stroke: every cell within ``radius`` of the polyline through ``points``."""

    op: Literal["brush"]
    points: list[Pair] = Field(min_length=1, max_length=10_000, description="map frame, m")
    radius: float = Field(gt=0, le=10.0, description="m")
    value: Value


class LineOp(StrictModel):
    """A line wall from ``start`` to ``end``, ``width`` wide (a glass wall the lidar cannot see)."""

    op: Literal["line"]
    start: Pair
    end: Pair
    width: float = Field(0.05, gt=0, le=10.0, description="m")
    value: Value = "occupied"


class PolygonOp(StrictModel):
    """Fill a polygon (erase a region: ``unknown`` or ``free``)."""

    op: Literal["polygon"]
    polygon: list[Pair] = Field(max_length=MAX_VERTICES + 1)
    value: Value


EditOp = Annotated[BrushOp | LineOp | PolygonOp, Field(discriminator="op")]


class EditIn(StrictModel):
    operations: list[EditOp] = Field(min_length=1, max_length=1000, description="applied in order")


class EditOut(MapOut):
    """The new version (not active until activated), and what the edit changed."""

    changed_cells: int
    changed_bounds: list[int] | None = Field(
        description="rows r0..r1, columns c0..c1 (half-open) of the changed cells; None: nothing changed"
    )


class VersionPage(Page[MapOut]):
    """The versions a map descends from: the original first, the map itself last."""


def _operation(op: BrushOp | LineOp | PolygonOp) -> Operation:
    if isinstance(op, BrushOp):
        return Stroke(np.asarray(op.points, dtype=float), op.radius, op.value)
    if isinstance(op, LineOp):
        return Stroke(np.array([op.start, op.end], dtype=float), op.width / 2.0, op.value)
    try:
        return Fill(validate_polygon(op.polygon), op.value)
    except PolygonError as exc:
        raise ProblemError(422, str(exc), kind="invalid-polygon") from None


@router.post(
    "/api/maps/{map_id}/versions",
    status_code=201,
    response_model=EditOut,
    summary="Save an edit of a map as its new version (not activated)",
    responses=ERRORS(s404="no such map", s422="an invalid polygon"),
)
async def edit_map(
    map_id: DbId, body: EditIn, parent: MapInfoDep, grid: MapGridDep, rt: RuntimeDep, response: Response
) -> EditOut:
    ops = [_operation(op) for op in body.operations]
    edited, bounds, n = await run_in_threadpool(apply_edits, grid, ops)
    info = await run_in_threadpool(rt.maps.add_version, parent, edited)
    await run_in_threadpool(ZoneStore(rt.engine).copy, parent.id, info.id)
    await run_in_threadpool(PlaceStore(rt.engine).copy, parent.id, info.id)
    response.headers["Location"] = f"/api/maps/{info.id}"
    out = map_out(info, active_map_id(rt)).model_dump()
    return EditOut(**out, changed_cells=n, changed_bounds=None if bounds is None else list(bounds))


@router.get(
    "/api/maps/{map_id}/versions",
    response_model=VersionPage,
    summary="The versions this map descends from, the original first (each downloadable, activatable)",
    responses=ERRORS(s404="no such map"),
)
def list_versions(
    map_id: DbId,
    rt: RuntimeDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 100,
    offset: Annotated[int, Query(ge=0)] = 0,
) -> VersionPage:
    chain = rt.maps.lineage(map_id)
    if not chain:
        raise ProblemError(404, f"no map with id {map_id}", kind="not-found")
    active = active_map_id(rt)
    items = [map_out(i, active) for i in chain[offset : offset + limit]]
    return VersionPage(total=len(chain), limit=limit, offset=offset, items=items)
