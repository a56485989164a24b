"""Places in the database: named poses on one map (version), goals by name (``{"place": "dock"}``)."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy.engine import Engine
from sqlalchemy.exc import IntegrityError
from sqlmodel import Session, select

from app.models import PlaceRecord
from nav.types import Pose2D


class PlaceExists(ValueError):
    """A place of that name is already on the map."""


@dataclass(frozen=True)
class Place:
    id: int
    map_id: int
    name: str
    pose: Pose2D


def _place(rec: PlaceRecord) -> Place:
    assert rec.id is not None
    return Place(rec.id, rec.map_id, rec.name, Pose2D(rec.x, rec.y, rec.theta))


class PlaceStore:
    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    def add(self, map_id: int, name: str, pose: Pose2D) -> Place:
        """Store a place; ``PlaceExists`` if the map already has one of that name (unique index)."""
        rec = PlaceRecord(map_id=map_id, name=name, x=pose.x, y=pose.y, theta=pose.theta)
        with Session(self.engine, expire_on_commit=False) as s:
            s.add(rec)
            try:
                s.commit()
            except IntegrityError:
                raise PlaceExists(f"map {map_id} already has a place named {name!r}") from None
            s.refresh(rec)
        return _place(rec)

    def for_map(self, map_id: int) -> list[Place]:
        with Session(self.engine) as s:
            q = select(PlaceRecord).where(PlaceRecord.map_id == map_id).order_by(PlaceRecord.name)
            return [_place(r) for r in s.exec(q).all()]

    def find(self, map_id: int, name: str) -> Place | None:
        with Session(self.engine) as s:
            q = select(PlaceRecord).where(PlaceRecord.map_id == map_id, PlaceRecord.name == name)
            rec = s.exec(q).first()
            return _place(rec) if rec else None

    def get(self, place_id: int) -> Place | None:
        with Session(self.engine) as s:
            rec = s.get(PlaceRecord, place_id)
            return _place(rec) if rec else None

    def delete(self, place_id: int) -> bool:
        with Session(self.engine) as s:
            rec = s.get(PlaceRecord, place_id)
            if rec is None:
                return False
            s.delete(rec)
            s.commit()
            return True

    def copy(self, from_map: int, to_map: int) -> int:
        """Copy every place of one map (version) to another (a new version of the same map)."""
        places = self.for_map(from_map)
        with Session(self.engine) as s:
            for p in places:
                s.add(PlaceRecord(map_id=to_map, name=p.name, x=p.pose.x, y=p.pose.y, theta=p.pose.theta))
            s.commit()
        return len(places)
