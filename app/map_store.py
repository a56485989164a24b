"""Maps in the database: occupancy grids stored compressed with their geometry and a thumbnail."""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import numpy as np
from sqlalchemy.engine import Engine
from sqlalchemy.exc import IntegrityError
from sqlmodel import Session, col, select

from app.models import MapRecord, utcnow
from maps.render import thumbnail_png
from nav.types import GridGeometry, OccupancyGrid, Pose2D


@dataclass(frozen=True)
class MapInfo:
    id: int
    name: str
    resolution: float
    width: int
    height: int
    origin: tuple[float, float, float]
    source: str
    is_stock: bool
    robot_id: int | None
    run_id: int | None
    created_at: datetime
    updated_at: datetime
    parent_id: int | None = None
    version: int = 1

    def as_dict(self) -> dict:
        return {
            "id": self.id,
            "name": self.name,
            "resolution": self.resolution,
            "width": self.width,
            "height": self.height,
            "size_m": [round(self.width * self.resolution, 3), round(self.height * self.resolution, 3)],
            "origin": list(self.origin),
            "source": self.source,
            "is_stock": self.is_stock,
            "robot_id": self.robot_id,
            "run_id": self.run_id,
            "created_at": self.created_at.isoformat(),
            "updated_at": self.updated_at.isoformat(),
            "thumbnail_url": f"/api/maps/{self.id}/thumbnail.png",
            "parent_id": self.parent_id,
            "version": self.version,
        }


def _info(rec: MapRecord) -> MapInfo:
    assert rec.id is not None
    return MapInfo(
        rec.id,
        rec.name,
        rec.resolution,
        rec.width,
        rec.height,
        (rec.origin_x, rec.origin_y, rec.origin_yaw),
        rec.source,
        rec.is_stock,
        rec.robot_id,
        rec.run_id,
        rec.created_at,
        rec.updated_at,
        rec.parent_id,
        rec.version,
    )


def grid_of(rec: MapRecord) -> OccupancyGrid:
    data = np.frombuffer(zlib.decompress(rec.data), dtype=np.int8).reshape(rec.height, rec.width).copy()
    geom = GridGeometry(
        rec.resolution, rec.width, rec.height, Pose2D(rec.origin_x, rec.origin_y, rec.origin_yaw)
    )
    return OccupancyGrid(geom, data)


class MapStore:
    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    def add(
        self,
        name: str,
        grid: OccupancyGrid,
        *,
        source: str = "import",
        is_stock: bool = False,
        robot_id: int | None = None,
        run_id: int | None = None,
        parent_id: int | None = None,
        version: int = 1,
    ) -> MapInfo:
        """Store a map in one transaction (all or nothing)."""
        rec = map_record(
            name,
            grid,
            source=source,
            is_stock=is_stock,
            robot_id=robot_id,
            run_id=run_id,
            parent_id=parent_id,
            version=version,
        )
        with Session(self.engine, expire_on_commit=False) as s:
            s.add(rec)
            s.commit()
            s.refresh(rec)
        return _info(rec)

    def add_version(self, parent: MapInfo, grid: OccupancyGrid) -> MapInfo:
        """Save an edited map as a new version of ``parent``, named after the original with its
        version number (``office v2``; names stay unique); the parent stays as it is."""
        if grid.geometry != self.grid_geometry(parent.id):
            raise ValueError("a new version keeps the map's geometry")
        original = self.lineage(parent.id)[0]
        return self.add(
            self.free_name(f"{original.name} v{parent.version + 1}"),
            grid,
            source="edit",
            robot_id=parent.robot_id,
            run_id=parent.run_id,
            parent_id=parent.id,
            version=parent.version + 1,
        )

    def lineage(self, map_id: int) -> list[MapInfo]:
        """The versions ``map_id`` descends from, oldest (the original) first, ending with it."""
        chain: list[MapInfo] = []
        info = self.info(map_id)
        while info is not None and len(chain) < 10_000:
            chain.append(info)
            info = self.info(info.parent_id) if info.parent_id is not None else None
        return chain[::-1]

    def grid_geometry(self, map_id: int) -> GridGeometry | None:
        info = self.info(map_id)
        if info is None:
            return None
        return GridGeometry(info.resolution, info.width, info.height, Pose2D(*info.origin))

    def list(self) -> list[MapInfo]:
        with Session(self.engine) as s:
            recs = s.exec(select(MapRecord).order_by(MapRecord.is_stock, MapRecord.created_at.desc())).all()
            return [_info(r) for r in recs]

    def info(self, map_id: int) -> MapInfo | None:
        with Session(self.engine) as s:
            rec = s.get(MapRecord, map_id)
            return _info(rec) if rec else None

    def find(self, name: str, *, stock: bool | None = None) -> MapInfo | None:
        with Session(self.engine) as s:
            q = select(MapRecord).where(MapRecord.name == name)
            if stock is not None:
                q = q.where(MapRecord.is_stock == stock)
            rec = s.exec(q.order_by(MapRecord.id)).first()
            return _info(rec) if rec else None

    def free_name(self, name: str) -> str:
        """``name`` if no map has it, else the first free ``name (2)``, ``name (3)``...: importing the
        same files twice makes two maps that can be told apart (the answer says the name it got)."""
        with Session(self.engine) as s:
            taken = set(s.exec(select(MapRecord.name).where(col(MapRecord.name).startswith(name))).all())
        n = 1
        candidate = name
        while candidate in taken:
            n += 1
            candidate = f"{name} ({n})"
        return candidate

    def grid(self, map_id: int) -> OccupancyGrid | None:
        with Session(self.engine) as s:
            rec = s.get(MapRecord, map_id)
            return grid_of(rec) if rec else None

    def thumbnail(self, map_id: int) -> bytes | None:
        with Session(self.engine) as s:
            rec = s.get(MapRecord, map_id)
            return rec.thumbnail_png if rec else None

    def rename(self, map_id: int, name: str) -> MapInfo | None:
        with Session(self.engine, expire_on_commit=False) as s:
            rec = s.get(MapRecord, map_id)
            if rec is None:
                return None
            rec.name = name
            rec.updated_at = utcnow()
            s.add(rec)
            s.commit()
            s.refresh(rec)
            return _info(rec)

    def delete(self, map_id: int) -> bool:
        with Session(self.engine) as s:
            rec = s.get(MapRecord, map_id)
            if rec is None:
                return False
            s.delete(rec)
            s.commit()
            return True

    def register_stock(self, worlds: dict[str, Path], load) -> list[MapInfo]:
        """Register each stock world once (by name), loading it with ``load(path) -> OccupancyGrid``.

        Race-safe for a fleet starting at once on one PostgreSQL: the partial unique index
        ``uq_maps_stock_name`` lets exactly one insert per name commit; a process that loses the race
        gets an IntegrityError (its transaction rolled back, nothing half-written) and keeps the
        winner's row."""
        added = []
        for name, path in worlds.items():
            if self.find(name, stock=True) is not None:
                continue
            try:
                added.append(self.add(name, load(path), source="stock", is_stock=True))
            except IntegrityError:
                if self.find(name, stock=True) is None:  # a different constraint failed: not the race
                    raise
        return added


def map_record(
    name: str,
    grid: OccupancyGrid,
    *,
    source: str = "import",
    is_stock: bool = False,
    robot_id: int | None = None,
    run_id: int | None = None,
    parent_id: int | None = None,
    version: int = 1,
) -> MapRecord:
    """The database row of a map (grid compressed, thumbnail rendered), not yet stored."""
    g = grid.geometry
    if g.width <= 0 or g.height <= 0:
        raise ValueError(f"a map needs cells; this one is {g.width} x {g.height}")
    return MapRecord(
        name=name,
        resolution=g.resolution,
        origin_x=g.origin.x,
        origin_y=g.origin.y,
        origin_yaw=g.origin.theta,
        width=g.width,
        height=g.height,
        data=zlib.compress(np.ascontiguousarray(grid.data, dtype=np.int8).tobytes(), 6),
        thumbnail_png=thumbnail_png(grid),
        source=source,
        is_stock=is_stock,
        robot_id=robot_id,
        run_id=run_id,
        parent_id=parent_id,
        version=version,
    )
