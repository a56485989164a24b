"""Keepout and speed zones of a map: list, create, read, replace, delete, and export / import as
Nav2 costmap filter masks (issue 19).

Polygons are in the map frame (metres). A polygon with fewer than 3 vertices, crossing or touching
edges, no area or a vertex off the map is refused with 422 (``invalid-polygon``, the reason in
``detail``). A change to the active map's zones takes effect at the next control tick.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, File, Form, Query, Response, UploadFile
from fastapi.concurrency import run_in_threadpool
from pydantic import Field, model_validator

from app.api.deps import MapInfoDep, RuntimeDep, StrictModel, feature_dependency
from app.api.problems import ProblemError
from app.api.schemas import ERRORS, DbId, Out, Page, Pair, Timestamp
from app.features.zones import Zones
from app.zone_masks import (
    DEFAULT_INFO,
    FilterInfo,
    FilterType,
    MaskError,
    export_zip,
    filter_type,
    parse_filter_info,
    read_mask,
    zones_from_mask,
)
from app.zone_store import SpeedUnit, Zone, ZoneKind, ZoneSpec
from nav.costmap.filter_layer import MAX_VERTICES, PolygonError, validate_polygon

router = APIRouter(tags=["zones"])


class ZoneIn(StrictModel):
    """A zone: ``keepout`` (never entered, never planned through) or ``speed`` (a speed limit inside,
    Nav2 SpeedFilter: ``speed_limit`` in percent of the robot's top speed, or m/s)."""

    name: str = Field(min_length=1, max_length=100, pattern=r"\S")
    kind: ZoneKind
    polygon: list[Pair] = Field(
        max_length=MAX_VERTICES + 1, description="[[x, y], ...] in the map frame (m), 3 or more vertices"
    )
    speed_limit: float | None = Field(
        None, gt=0, description="speed zones: the limit, in `speed_limit_unit` (required for `speed`)"
    )
    speed_limit_unit: SpeedUnit = SpeedUnit.PERCENT

    @model_validator(mode="after")
    def _speed_fields(self) -> ZoneIn:
        if self.kind == ZoneKind.SPEED:
            if self.speed_limit is None:
                raise ValueError("a speed zone needs speed_limit")
            if self.speed_limit_unit == SpeedUnit.PERCENT and self.speed_limit > 100:
                raise ValueError("speed_limit in percent is at most 100")
        elif self.speed_limit is not None:
            raise ValueError("only speed zones have a speed_limit")
        return self


class ZoneOut(Out):
    id: int
    map_id: int
    name: str
    kind: ZoneKind
    polygon: list[Pair] = Field(description="[[x, y], ...] in the map frame (m)")
    speed_limit: float | None = Field(description="speed zones: in `speed_limit_unit`")
    speed_limit_unit: SpeedUnit
    created_at: Timestamp
    updated_at: Timestamp


class ZonePage(Page[ZoneOut]):
    """A map's zones, oldest first."""

    map_id: int


ZonesDep = Annotated[Zones, Depends(feature_dependency(Zones))]

NO_MAP = ERRORS(s404="no such map")
NO_ZONE = ERRORS(s404="no such zone")
INVALID = ERRORS(s422="invalid polygon (fewer than 3 vertices, self-intersecting, off the map)")


def zone_out(z: Zone) -> ZoneOut:
    return ZoneOut(
        id=z.id,
        map_id=z.map_id,
        name=z.name,
        kind=z.kind,
        polygon=[list(p) for p in z.polygon],
        speed_limit=z.speed_limit,
        speed_limit_unit=z.speed_limit_unit,
        created_at=z.created_at,
        updated_at=z.updated_at,
    )


def _spec(rt: RuntimeDep, map_id: int, body: ZoneIn) -> ZoneSpec:
    """The zone as stored, after checking its polygon against the map's extent."""
    grid = rt.maps.grid(map_id)
    if grid is None:
        raise ProblemError(404, f"no map with id {map_id}", kind="not-found")
    try:
        poly = validate_polygon(body.polygon, grid.geometry)
    except PolygonError as exc:
        raise ProblemError(422, str(exc), kind="invalid-polygon") from None
    return ZoneSpec(body.name.strip(), body.kind, poly.tolist(), body.speed_limit, body.speed_limit_unit)


def _zone(zones: Zones, zone_id: int) -> Zone:
    z = zones.store.get(zone_id)
    if z is None:
        raise ProblemError(404, f"no zone with id {zone_id}", kind="not-found")
    return z


@router.get(
    "/api/maps/{map_id}/zones", response_model=ZonePage, summary="The zones of a map", responses=NO_MAP
)
def list_zones(
    map_id: DbId,
    _map: MapInfoDep,
    zones: ZonesDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 100,
    offset: Annotated[int, Query(ge=0)] = 0,
) -> ZonePage:
    found = zones.store.for_map(map_id)
    items = [zone_out(z) for z in found[offset : offset + limit]]
    return ZonePage(total=len(found), limit=limit, offset=offset, items=items, map_id=map_id)


@router.post(
    "/api/maps/{map_id}/zones",
    status_code=201,
    response_model=ZoneOut,
    summary="Draw a keepout or speed zone on a map",
    responses={**NO_MAP, **INVALID},
)
def create_zone(map_id: DbId, body: ZoneIn, rt: RuntimeDep, zones: ZonesDep, response: Response) -> ZoneOut:
    z = zones.store.add(map_id, _spec(rt, map_id, body))
    zones.reload(map_id)
    response.headers["Location"] = f"/api/zones/{z.id}"
    return zone_out(z)


@router.get("/api/zones/{zone_id}", response_model=ZoneOut, summary="One zone", responses=NO_ZONE)
def get_zone(zone_id: DbId, zones: ZonesDep) -> ZoneOut:
    return zone_out(_zone(zones, zone_id))


@router.put(
    "/api/zones/{zone_id}",
    response_model=ZoneOut,
    summary="Replace a zone (name, kind, polygon, limit)",
    responses={**NO_ZONE, **INVALID},
)
def replace_zone(zone_id: DbId, body: ZoneIn, rt: RuntimeDep, zones: ZonesDep) -> ZoneOut:
    old = _zone(zones, zone_id)
    z = zones.store.replace(zone_id, _spec(rt, old.map_id, body))
    if z is None:
        raise ProblemError(404, f"no zone with id {zone_id}", kind="not-found")
    zones.reload(z.map_id)
    return zone_out(z)


@router.delete("/api/zones/{zone_id}", status_code=204, summary="Delete a zone", responses=NO_ZONE)
def delete_zone(zone_id: DbId, zones: ZonesDep) -> Response:
    z = zones.store.delete(zone_id)
    if z is None:
        raise ProblemError(404, f"no zone with id {zone_id}", kind="not-found")
    zones.reload(z.map_id)
    return Response(status_code=204)


# --------------------------------------------------------------------------- Nav2 filter masks

BAD_MASK = ERRORS(
    s404="no such map", s422="the zones or the mask cannot be converted (the reason in `detail`)"
)


def _geometry(rt: RuntimeDep, map_id: int):
    geometry = rt.maps.grid_geometry(map_id)
    if geometry is None:
        raise ProblemError(404, f"no map with id {map_id}", kind="not-found")
    return geometry


@router.get(
    "/api/maps/{map_id}/zones/export",
    response_class=Response,
    summary="The map's keepout or speed zones as a Nav2 filter mask (zip: PGM, YAML, filter info YAML)",
    description="`kind=keepout`: CostmapFilterInfo type 0, keepout cells occupied (100). `kind=speed`: "
    "type 1 (`unit=percent`) or 2 (`unit=m/s`), mask value v = (limit - base) / multiplier, 1..100 "
    "(rounded to the nearest), 0 = no limit; only the speed zones of that unit are written (default: the "
    "unit the map's speed zones share). `mode`: `scale` (the Nav2 tutorials') or `raw`.",
    responses={**BAD_MASK, 200: {"content": {"application/zip": {}}}},
)
def export_masks(
    map_id: DbId,
    rt: RuntimeDep,
    zones: ZonesDep,
    kind: ZoneKind,
    unit: SpeedUnit | None = None,
    mode: Annotated[str, Query(pattern="^(scale|raw)$")] = "scale",
    base: Annotated[float | None, Query(allow_inf_nan=False)] = None,
    multiplier: Annotated[float | None, Query(allow_inf_nan=False)] = None,
) -> Response:
    geometry = _geometry(rt, map_id)
    found = zones.store.for_map(map_id)
    if kind == ZoneKind.SPEED and unit is None:
        units = {z.speed_limit_unit for z in found if z.kind == ZoneKind.SPEED}
        if len(units) > 1:
            raise ProblemError(
                422,
                "the map has speed zones in percent and in m/s: export each with ?unit=",
                kind="invalid-mask",
            )
        unit = units.pop() if units else SpeedUnit.PERCENT
    default = DEFAULT_INFO[filter_type(kind, unit or SpeedUnit.PERCENT)]
    info = FilterInfo(
        default.type,
        default.base if base is None else base,
        default.multiplier if multiplier is None else multiplier,
    )
    try:
        body = export_zip(found, geometry, info, mode)
    except MaskError as exc:
        raise ProblemError(422, str(exc), kind="invalid-mask") from None
    name = f"map{map_id}_{kind.value}_mask.zip"
    headers = {"Content-Disposition": f'attachment; filename="{name}"', "Cache-Control": "no-cache"}
    return Response(body, media_type="application/zip", headers=headers)


class MaskImportOut(StrictModel):
    map_id: int
    filter_type: int = Field(description="CostmapFilterInfo type: 0 keepout, 1 speed %, 2 speed m/s")
    replaced: int = Field(description="zones of that kind (and unit) deleted first (`replace=true`)")
    items: list[ZoneOut] = Field(description="the zones created, one per connected region of equal value")


@router.post(
    "/api/maps/{map_id}/zones/import",
    status_code=201,
    response_model=MaskImportOut,
    summary="Import a Nav2 filter mask (map_server YAML + PGM/PNG, and its filter info YAML) as zones",
    description="The mask must cover the map's cells (same size, resolution and origin). Without "
    "`filter_info`, `kind` says what the mask is (keepout, or a speed mask with the tutorial's "
    "base/multiplier). Each connected region of equal mask value becomes a polygon along the cell "
    "boundaries; a region with a hole is split into rectangles. Nothing is stored if anything is wrong.",
    responses={**BAD_MASK, 413: {"description": "the upload is larger than the configured limit"}},
)
async def import_masks(
    map_id: DbId,
    rt: RuntimeDep,
    zones: ZonesDep,
    yaml: Annotated[UploadFile, File(description="the mask's map_server YAML")],
    image: Annotated[UploadFile, File(description="the PGM or PNG the YAML describes")],
    filter_info: Annotated[
        UploadFile | None, File(description="costmap_filter_info_server parameters")
    ] = None,
    kind: Annotated[
        ZoneKind | None, Form(description="without filter_info: keepout or speed (percent)")
    ] = None,
    replace: Annotated[
        bool, Form(description="delete the map's zones of this kind (and unit) first")
    ] = False,
    name: Annotated[str, Form(min_length=1, max_length=80, description="zone name prefix")] = "imported",
) -> MaskImportOut:
    geometry = _geometry(rt, map_id)
    limit = rt.settings.max_upload_bytes
    parts = [await f.read(limit + 1) for f in (yaml, image, *([filter_info] if filter_info else []))]
    if any(len(p) > limit for p in parts):
        raise ProblemError(413, f"upload larger than {limit} bytes", kind="too-large")
    try:
        if filter_info is not None:
            info = parse_filter_info(parts[2].decode("utf-8", errors="replace"))
        elif kind is not None:
            info = DEFAULT_INFO[filter_type(kind)]
        else:
            raise MaskError("send the filter info YAML (filter_info) or say the mask's kind (kind)")
        values = await run_in_threadpool(read_mask, parts[0], parts[1], image.filename or "", geometry)
        specs = await run_in_threadpool(zones_from_mask, values, geometry, info, name.strip() or "imported")
    except MaskError as exc:
        raise ProblemError(422, str(exc), kind="invalid-mask") from None
    zkind = ZoneKind.KEEPOUT if info.type == FilterType.KEEPOUT else ZoneKind.SPEED
    unit = SpeedUnit.MPS if info.type == FilterType.SPEED_ABSOLUTE else SpeedUnit.PERCENT
    replaced = 0
    if replace:
        for z in zones.store.for_map(map_id):
            if z.kind == zkind and (zkind == ZoneKind.KEEPOUT or z.speed_limit_unit == unit):
                zones.store.delete(z.id)
                replaced += 1
    created = [zones.store.add(map_id, spec) for spec in specs]
    zones.reload(map_id)
    return MaskImportOut(
        map_id=map_id, filter_type=int(info.type), replaced=replaced, items=[zone_out(z) for z in created]
    )
