"""Maps in the store: list, metadata, thumbnails and full images, map_server export and import,
rename, delete, and activation for localization / navigation / the 3D view."""

from __future__ import annotations

import contextlib
import re
from pathlib import PurePosixPath
from typing import Annotated, Any

from fastapi import APIRouter, File, Form, HTTPException, Query, UploadFile
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response
from pydantic import Field

from app.api.deps import MapInfoDep, RuntimeDep, StrictModel
from app.api.problems import ProblemError
from app.api.schemas import ERRORS, DbId, Out, Page, Pair, Timestamp, Triple
from app.features.localization import Localization, map_fit
from app.features.mapping import Mapping
from app.features.recording import current_map_id
from app.map_store import MapInfo
from app.modes import Mode
from app.runtime import Runtime
from maps.mapio import DEFAULT_MAX_PIXELS, MapFormatError, encode_pgm, encode_yaml, read_map_bytes
from maps.png import encode_png
from maps.render import grid_to_grey
from nav.types import OccupancyGrid

router = APIRouter(tags=["maps"])

NOT_FOUND = ERRORS(s404="no such map")


class MapOut(Out):
    """A stored map (ROS map_server geometry: ``origin`` is the lower-left cell's pose in the map frame)."""

    id: int
    name: str
    resolution: float = Field(description="m per cell")
    width: int = Field(description="cells")
    height: int = Field(description="cells")
    size_m: Pair = Field(description="width, height in m")
    origin: Triple = Field(description="x (m), y (m), yaw (rad) of the lower-left cell")
    source: str = Field(description="`stock` (a simulator world), `slam` (built here) or `import`")
    is_stock: bool
    robot_id: int | None
    run_id: int | None = Field(description="the mapping run that built it, if any")
    created_at: Timestamp
    updated_at: Timestamp
    thumbnail_url: str
    active: bool = Field(description="true for the map the robot localizes and plans in now")
    parent_id: int | None = Field(description="the version this map was edited from (None: an original)")
    version: int = Field(description="1 for an original, +1 per edit (`POST /api/maps/{id}/versions`)")


class MapPage(Page[MapOut]):
    """Maps, user maps newest first, stock maps last."""

    active_map_id: int | None = Field(description="the active map (also flagged `active` in its item)")


class ActivatedOut(MapOut):
    active_map_id: int
    match_score: float | None = Field(
        None,
        description="0..1: how well the current lidar scan fits this map at the robot's true pose "
        "(simulation only; see docs/api.md, localization)",
    )


def active_map_id(rt: Runtime) -> int | None:
    """The map the robot localizes and plans in (the localization feature's, else the world's)."""
    loc = rt.find_feature(Localization)
    if loc is not None and loc.map_id is not None:
        return int(loc.map_id)
    return current_map_id(rt)


def map_out(info: MapInfo, active_id: int | None) -> MapOut:
    return MapOut(**info.as_dict(), active=info.id == active_id)


@router.get("/api/maps", response_model=MapPage, summary="Maps (paginated like /api/runs), stock maps last")
def list_maps(
    rt: RuntimeDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0)] = 0,
) -> MapPage:
    maps = rt.maps.list()
    active = active_map_id(rt)
    return MapPage(
        total=len(maps),
        limit=limit,
        offset=offset,
        items=[map_out(m, active) for m in maps[offset : offset + limit]],
        active_map_id=active,
    )


@router.get("/api/maps/{map_id}", response_model=MapOut, summary="One map's metadata", responses=NOT_FOUND)
def get_map(info: MapInfoDep, rt: RuntimeDep) -> MapOut:
    return map_out(info, active_map_id(rt))


@router.get(
    "/api/maps/{map_id}/thumbnail.png",
    response_class=Response,
    summary="A small PNG preview",
    responses={**NOT_FOUND, 200: {"content": {"image/png": {}}}},
)
def thumbnail(map_id: DbId, rt: RuntimeDep) -> Response:
    png = rt.maps.thumbnail(map_id)
    if png is None:
        raise HTTPException(404, f"no map with id {map_id}")
    return Response(png, media_type="image/png", headers={"Cache-Control": "max-age=60"})


# --------------------------------------------------------------------------- export (map_saver format)
# Downloads are exactly what Nav2's map_saver writes in trinary mode (maps.mapio): the YAML's
# ``image:`` is ``map.pgm``, the name the PGM is served under, so the two files saved side by side
# load unchanged in map_server.

PGM_NAME = "map.pgm"
YAML_NAME = "map.yaml"


def _grid(rt: Any, map_id: int) -> OccupancyGrid:
    grid = rt.maps.grid(map_id)
    if grid is None:
        raise HTTPException(404, f"no map with id {map_id}")
    return grid


def _attachment(filename: str) -> dict[str, str]:
    return {"Content-Disposition": f'attachment; filename="{filename}"', "Cache-Control": "no-cache"}


@router.get(
    "/api/maps/{map_id}/map.yaml",
    response_class=Response,
    summary="The map's YAML as map_saver writes it (image: map.pgm)",
    responses={**NOT_FOUND, 200: {"content": {"application/x-yaml": {}}}},
)
def export_yaml(map_id: DbId, rt: RuntimeDep) -> Response:
    body = encode_yaml(_grid(rt, map_id), PGM_NAME)
    return Response(body, media_type="application/x-yaml", headers=_attachment(YAML_NAME))


@router.get(
    "/api/maps/{map_id}/map.pgm",
    response_class=Response,
    summary="The map's P5 PGM as map_saver writes it (254 free, 0 occupied, 205 unknown)",
    responses={**NOT_FOUND, 200: {"content": {"image/x-portable-graymap": {}}}},
)
def export_pgm(map_id: DbId, rt: RuntimeDep) -> Response:
    body = encode_pgm(_grid(rt, map_id))
    return Response(body, media_type="image/x-portable-graymap", headers=_attachment(PGM_NAME))


@router.get(
    "/api/maps/{map_id}/image.png",
    response_class=Response,
    summary="The whole map as a PNG, one pixel per cell (map_saver's grey levels, top row = max y)",
    responses={**NOT_FOUND, 200: {"content": {"image/png": {}}}},
)
def full_image(map_id: DbId, rt: RuntimeDep) -> Response:
    png = encode_png(grid_to_grey(_grid(rt, map_id)))
    return Response(png, media_type="image/png", headers={"Cache-Control": "max-age=60"})


# --------------------------------------------------------------------------- import


def image_pixels(data: bytes) -> int | None:
    """Width x height from a PGM or PNG header without decoding (None if it cannot be read), so an
    oversize image is refused with 413 before any pixel is decoded."""
    if data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) >= 24:
        return int.from_bytes(data[16:20], "big") * int.from_bytes(data[20:24], "big")
    m = _PNM_HEADER.match(data[:4096])
    return int(m.group(1)) * int(m.group(2)) if m else None


_PNM_HEADER = re.compile(rb"^P[25](?:\s|#[^\n]*\n)+(\d+)(?:\s|#[^\n]*\n)+(\d+)")


def _upload_name(yaml: UploadFile, name: str | None) -> str:
    if name is not None and name.strip():
        return name.strip()[:100]
    stem = PurePosixPath((yaml.filename or "").replace("\\", "/")).stem.strip()
    return stem[:100] or "imported map"


@router.post(
    "/api/maps/import",
    summary="Upload a map_server map: YAML + image (PGM or PNG); returns the stored map",
    description="Map names are unique: importing under a name a map already has (the same files twice, "
    "say) stores the map as a new version named `name (2)`, `name (3)`...; the answer's `name` is the "
    "one it got. Renaming to a taken name is refused (409).",
    status_code=201,
    response_model=MapOut,
    responses=ERRORS(
        s413="the upload or the image is larger than the configured limit",
        s422="corrupt or truncated image, missing or wrong YAML field, unsupported mode",
    ),
)
async def import_map(
    rt: RuntimeDep,
    yaml: Annotated[UploadFile, File(description="the map YAML (image, resolution, origin, ...)")],
    image: Annotated[UploadFile, File(description="the PGM or PNG the YAML describes")],
    name: Annotated[str | None, Form(max_length=200, description="default: the YAML's file name")] = None,
):
    limit = rt.settings.max_upload_bytes
    yaml_bytes = await yaml.read(limit + 1)
    image_bytes = await image.read(limit + 1)
    if len(yaml_bytes) > limit or len(image_bytes) > limit:
        raise ProblemError(413, f"upload larger than {limit} bytes", kind="too-large")
    max_pixels = int(getattr(rt.settings, "max_map_pixels", DEFAULT_MAX_PIXELS))
    pixels = image_pixels(image_bytes)
    if pixels is not None and pixels > max_pixels:
        raise ProblemError(
            413, f"image has {pixels} pixels, more than the limit of {max_pixels}", kind="too-large"
        )
    try:
        grid = await run_in_threadpool(
            read_map_bytes, yaml_bytes, image_bytes, image.filename or "", max_pixels
        )
    except MapFormatError as exc:
        raise ProblemError(422, str(exc), kind="invalid-map") from None
    map_name = rt.maps.free_name(_upload_name(yaml, name))
    info = await run_in_threadpool(rt.maps.add, map_name, grid, source="import", robot_id=rt.robot_id)
    return map_out(info, active_map_id(rt))


def refuse_taken_name(rt: Any, name: str, *, own_id: int | None = None) -> None:
    """409 when another map already has ``name``: two maps with one name cannot be told apart."""
    taken = rt.maps.find(name)
    if taken is not None and taken.id != own_id:
        raise ProblemError(
            409,
            f"a map named {name!r} exists already (id {taken.id}): choose another name, or rename or "
            "delete that map",
            kind="map-name-taken",
            existing_id=taken.id,
        )


# --------------------------------------------------------------------------- rename, delete, activate


class RenameIn(StrictModel):
    """The new name (1..100 characters, not only spaces)."""

    name: str = Field(min_length=1, max_length=100, pattern=r"\S")


def _user_map(rt: Any, map_id: int, what: str):
    info = rt.maps.info(map_id)
    if info is None:
        raise HTTPException(404, f"no map with id {map_id}")
    if info.is_stock:
        # Stock maps are the simulator's worlds, registered again by name at every start: renaming
        # or deleting one would only make a duplicate appear. Import a copy to change it.
        raise ProblemError(
            409, f"map {map_id} is a stock map (a simulator world) and cannot be {what}", kind="stock-map"
        )
    return info


@router.patch(
    "/api/maps/{map_id}",
    summary="Rename a map (names are unique)",
    response_model=MapOut,
    responses={**NOT_FOUND, **ERRORS(s409="a stock map, or another map has this name (`existing_id`)")},
)
def rename_map(map_id: DbId, body: RenameIn, rt: RuntimeDep) -> MapOut:
    _user_map(rt, map_id, "renamed")
    refuse_taken_name(rt, body.name.strip(), own_id=map_id)
    info = rt.maps.rename(map_id, body.name.strip())
    if info is None:
        raise HTTPException(404, f"no map with id {map_id}")
    return map_out(info, active_map_id(rt))


@router.delete(
    "/api/maps/{map_id}",
    summary="Delete a map (not a stock map, not the active one)",
    status_code=204,
    responses={
        **NOT_FOUND,
        **ERRORS(s409="a stock map, or the active map (`active_map_id`): activate another map first"),
    },
)
def delete_map(map_id: DbId, rt: RuntimeDep) -> Response:
    _user_map(rt, map_id, "deleted")
    if active_map_id(rt) == map_id:
        raise ProblemError(
            409,
            f"map {map_id} is the active map (localization and navigation use it): activate another "
            "map first (POST /api/maps/{id}/activate), then delete this one",
            kind="active-map",
            active_map_id=map_id,
        )
    if not rt.maps.delete(map_id):
        raise HTTPException(404, f"no map with id {map_id}")
    return Response(status_code=204)


@router.post(
    "/api/maps/{map_id}/activate",
    summary="Make this the active map for localization, navigation and the 3D view",
    response_model=ActivatedOut,
    responses={**NOT_FOUND, **ERRORS(s409="not while MAPPING; in simulation, not a map of another world")},
)
def activate_map(map_id: DbId, rt: RuntimeDep) -> ActivatedOut:
    session = rt.session
    if session.modes.mode == Mode.MAPPING:
        raise ProblemError(
            409, "stop mapping before activating a map", kind="mode-refused", mode=session.modes.mode.value
        )
    info = rt.maps.info(map_id)
    if info is None:
        raise HTTPException(404, f"no map with id {map_id}")
    grid = _grid(rt, map_id)
    loc = rt.find_feature(Localization)
    score = _refuse_other_world(rt, loc, grid, map_id)
    if loc is not None:
        loc.set_map(grid, map_id)
        mapping = rt.find_feature(Mapping)
        if mapping is not None and mapping.saved_map_id == map_id:
            # The map this mapping session just built: same map frame, so the robot's pose holds.
            with contextlib.suppress(Exception):
                loc.set_initial_pose(session.pose)
    else:
        session.set_grid(grid)
    rt.active_map_id = map_id
    session.add_event("map", map_id=map_id, reason="map activated")
    return ActivatedOut(**map_out(info, map_id).model_dump(), active_map_id=map_id, match_score=score)


SIM_MATCH_RATIO = 0.8
"""In simulation a map is the world's when the lidar's scan fits it at least this fraction as well as
it fits the world's own map (the same measure, ``Amcl.quality``): a copy of the world's map scores 1,
a map of another world far less (docs/api.md has the measured figures)."""


def _refuse_other_world(
    rt: Runtime, loc: Localization | None, grid: OccupancyGrid, map_id: int
) -> float | None:
    """In simulation, 409 for a map the lidar does not see. The latest scan's fit to the map, at the
    robot's true pose (a map in the world's frame) or at its current estimate (a map in the current
    map frame, e.g. the one mapping just built), is compared with its fit to the world's own map at the
    true pose. Returns the map's score (None on a real robot, or without a scan)."""
    truth = getattr(rt.session.driver, "truth_pose", None)
    world = rt.maps.find(rt.world_name, stock=True) if rt.world_name else None
    world_grid = None if world is None else rt.maps.grid(world.id)
    if loc is None or truth is None or world_grid is None:
        return None
    score = map_fit(loc, grid, [truth, rt.session.pose])
    reference = map_fit(loc, world_grid, [truth])
    if score is None or not reference:
        return None
    if score < SIM_MATCH_RATIO * reference:
        raise ProblemError(
            409,
            f"map {map_id} does not match what the lidar sees in the simulated world {rt.world_name!r} "
            f"(scan fit {score:.2f}, the world's own map {reference:.2f}; at least {SIM_MATCH_RATIO:g} x "
            "that is needed): activate this world's map, or serve the world this map was made of",
            kind="map-mismatch",
            match_score=round(score, 4),
            world_match_score=round(reference, 4),
            world=rt.world_name,
        )
    return round(score, 4)
