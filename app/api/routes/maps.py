"""Maps in the store."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException
from fastapi.responses import Response

from app.api.deps import RuntimeDep

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
