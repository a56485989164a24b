"""Maps in the store: list, metadata, thumbnails and full images, map_server export and import,
rename, delete, and activation for localization / navigation / the 3D view."""

from __future__ import annotations

import contextlib
import re
from pathlib import PurePosixPath
from typing import Annotated, Any

from fastapi import APIRouter, File, Form, HTTPException, UploadFile
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse, Response
from pydantic import Field

from app.api.deps import RuntimeDep, StrictModel
from nav.types import OccupancyGrid

router = APIRouter(tags=["maps"])


@router.get("/api/maps", summary="All maps, stock maps last")
def list_maps(rt: RuntimeDep) -> list[dict]:
    return [m.as_dict() for m in rt.maps.list()]


@router.get(
    "/api/maps/{map_id}", summary="One map's metadata", responses={404: {"description": "no such map"}}
)
def get_map(map_id: int, rt: RuntimeDep) -> dict:
    info = rt.maps.info(map_id)
    if info is None:
        raise HTTPException(404, f"no map with id {map_id}")
    return info.as_dict()


@router.get(
    "/api/maps/{map_id}/thumbnail.png",
    summary="A small PNG preview",
    responses={404: {"description": "no such map"}, 200: {"content": {"image/png": {}}}},
)
def thumbnail(map_id: int, rt: RuntimeDep) -> Response:
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
    summary="The map's YAML as map_saver writes it (image: map.pgm)",
    responses={404: {"description": "no such map"}, 200: {"content": {"application/x-yaml": {}}}},
)
def export_yaml(map_id: int, rt: RuntimeDep) -> Response:
    from maps.mapio import encode_yaml

    body = encode_yaml(_grid(rt, map_id), PGM_NAME)
    return Response(body, media_type="application/x-yaml", headers=_attachment(YAML_NAME))


@router.get(
    "/api/maps/{map_id}/map.pgm",
    summary="The map's P5 PGM as map_saver writes it (254 free, 0 occupied, 205 unknown)",
    responses={404: {"description": "no such map"}, 200: {"content": {"image/x-portable-graymap": {}}}},
)
def export_pgm(map_id: int, rt: RuntimeDep) -> Response:
    from maps.mapio import encode_pgm

    body = encode_pgm(_grid(rt, map_id))
    return Response(body, media_type="image/x-portable-graymap", headers=_attachment(PGM_NAME))


@router.get(
    "/api/maps/{map_id}/image.png",
    summary="The whole map as a PNG, one pixel per cell (map_saver's grey levels, top row = max y)",
    responses={404: {"description": "no such map"}, 200: {"content": {"image/png": {}}}},
)
def full_image(map_id: int, rt: RuntimeDep) -> Response:
    from maps.png import encode_png
    from maps.render import grid_to_grey

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
    status_code=201,
    responses={
        413: {"description": "the upload or the image is larger than the configured limit"},
        422: {"description": "corrupt or truncated image, missing or wrong YAML field, unsupported mode"},
    },
)
async def import_map(
    rt: RuntimeDep,
    yaml: Annotated[UploadFile, File(description="the map YAML (image, resolution, origin, ...)")],
    image: Annotated[UploadFile, File(description="the PGM or PNG the YAML describes")],
    name: Annotated[str | None, Form(max_length=200, description="default: the YAML's file name")] = None,
):
    from maps.mapio import DEFAULT_MAX_PIXELS, MapFormatError, read_map_bytes

    limit = rt.settings.max_upload_bytes
    yaml_bytes = await yaml.read(limit + 1)
    image_bytes = await image.read(limit + 1)
    if len(yaml_bytes) > limit or len(image_bytes) > limit:
        return JSONResponse({"detail": f"upload larger than {limit} bytes"}, status_code=413)
    max_pixels = int(getattr(rt.settings, "max_map_pixels", DEFAULT_MAX_PIXELS))
    pixels = image_pixels(image_bytes)
    if pixels is not None and pixels > max_pixels:
        return JSONResponse(
            {"detail": f"image has {pixels} pixels, more than the limit of {max_pixels}"}, status_code=413
        )
    try:
        grid = await run_in_threadpool(
            read_map_bytes, yaml_bytes, image_bytes, image.filename or "", max_pixels
        )
    except MapFormatError as exc:
        return JSONResponse({"detail": str(exc)}, status_code=422)
    info = await run_in_threadpool(
        rt.maps.add, _upload_name(yaml, name), grid, source="import", robot_id=rt.robot_id
    )
    return JSONResponse(info.as_dict(), status_code=201)


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
        raise HTTPException(409, f"map {map_id} is a stock map (a simulator world) and cannot be {what}")
    return info


@router.patch(
    "/api/maps/{map_id}",
    summary="Rename a map",
    responses={404: {"description": "no such map"}, 409: {"description": "stock maps cannot be renamed"}},
)
def rename_map(map_id: int, body: RenameIn, rt: RuntimeDep) -> dict:
    _user_map(rt, map_id, "renamed")
    info = rt.maps.rename(map_id, body.name.strip())
    if info is None:
        raise HTTPException(404, f"no map with id {map_id}")
    return info.as_dict()


@router.delete(
    "/api/maps/{map_id}",
    summary="Delete a map (stock maps cannot be deleted)",
    status_code=204,
    responses={404: {"description": "no such map"}, 409: {"description": "stock maps cannot be deleted"}},
)
def delete_map(map_id: int, rt: RuntimeDep) -> Response:
    _user_map(rt, map_id, "deleted")
    if not rt.maps.delete(map_id):
        raise HTTPException(404, f"no map with id {map_id}")
    return Response(status_code=204)


@router.post(
    "/api/maps/{map_id}/activate",
    summary="Make this the active map for localization, navigation and the 3D view",
    responses={404: {"description": "no such map"}, 409: {"description": "not while MAPPING"}},
)
def activate_map(map_id: int, rt: RuntimeDep):
    from app.modes import Mode

    session = rt.session
    if session.modes.mode == Mode.MAPPING:
        return JSONResponse(
            {"detail": "stop mapping before activating a map", "mode": session.modes.mode.value},
            status_code=409,
        )
    info = rt.maps.info(map_id)
    if info is None:
        raise HTTPException(404, f"no map with id {map_id}")
    grid = _grid(rt, map_id)
    loc = rt.features.get("localization")
    if loc is not None and hasattr(loc, "set_map"):
        loc.set_map(grid, map_id)
        mapping = rt.features.get("mapping")
        if getattr(mapping, "saved_map_id", None) == map_id and hasattr(loc, "set_initial_pose"):
            # The map this mapping session just built: same map frame, so the robot's pose holds.
            with contextlib.suppress(Exception):
                loc.set_initial_pose(session.pose)
    else:
        session.set_grid(grid)
    rt.active_map_id = map_id
    session.add_event("map", map_id=map_id, reason="map activated")
    return {"active_map_id": map_id, **info.as_dict()}
