"""Zones in the database: keepout and speed-limit polygons, each belonging to one map (version)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from enum import StrEnum

import numpy as np
from sqlalchemy.engine import Engine
from sqlmodel import Session, select

from app.models import ZoneRecord, utcnow


class ZoneKind(StrEnum):
    """Nav2 costmap filter types: ``keepout`` (KeepoutFilter), ``speed`` (SpeedFilter)."""

    KEEPOUT = "keepout"
    SPEED = "speed"


class SpeedUnit(StrEnum):
    """Nav2 SpeedFilter's two mask types: percent of the maximum speed, or an absolute m/s limit."""

    PERCENT = "percent"
    MPS = "m/s"


@dataclass(frozen=True)
class Zone:
    id: int
    map_id: int
    name: str
    kind: ZoneKind
    polygon: tuple[tuple[float, float], ...]
    speed_limit: float | None
    speed_limit_unit: SpeedUnit
    created_at: datetime
    updated_at: datetime

    def vertices(self) -> np.ndarray:
        return np.asarray(self.polygon, dtype=float)

    def limit_mps(self, max_speed: float) -> float | None:
        """The zone's linear speed limit in m/s for a robot whose top speed is ``max_speed``; None for
        no limit (keepout zones, or a speed limit of 0, which Nav2 treats as "no limit")."""
        if self.kind != ZoneKind.SPEED or not self.speed_limit:
            return None
        if self.speed_limit_unit == SpeedUnit.PERCENT:
            return max_speed * self.speed_limit / 100.0
        return self.speed_limit


def _zone(rec: ZoneRecord) -> Zone:
    assert rec.id is not None
    return Zone(
        rec.id,
        rec.map_id,
        rec.name,
        ZoneKind(rec.kind),
        tuple((float(x), float(y)) for x, y in rec.polygon),
        rec.speed_limit,
        SpeedUnit(rec.speed_limit_unit),
        rec.created_at,
        rec.updated_at,
    )


@dataclass(frozen=True)
class ZoneSpec:
    """What a zone is made of (validated by the caller: app/api/routes/zones.py)."""

    name: str
    kind: ZoneKind
    polygon: list[list[float]]
    speed_limit: float | None = None
    speed_limit_unit: SpeedUnit = SpeedUnit.PERCENT


class ZoneStore:
    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    def add(self, map_id: int, spec: ZoneSpec) -> Zone:
        rec = ZoneRecord(map_id=map_id, **_columns(spec))
        with Session(self.engine, expire_on_commit=False) as s:
            s.add(rec)
            s.commit()
            s.refresh(rec)
        return _zone(rec)

    def for_map(self, map_id: int) -> list[Zone]:
        with Session(self.engine) as s:
            recs = s.exec(select(ZoneRecord).where(ZoneRecord.map_id == map_id).order_by(ZoneRecord.id)).all()
            return [_zone(r) for r in recs]

    def get(self, zone_id: int) -> Zone | None:
        with Session(self.engine) as s:
            rec = s.get(ZoneRecord, zone_id)
            return _zone(rec) if rec else None

    def replace(self, zone_id: int, spec: ZoneSpec) -> Zone | None:
        with Session(self.engine, expire_on_commit=False) as s:
            rec = s.get(ZoneRecord, zone_id)
            if rec is None:
                return None
            for key, value in _columns(spec).items():
                setattr(rec, key, value)
            rec.updated_at = utcnow()
            s.add(rec)
            s.commit()
            s.refresh(rec)
            return _zone(rec)

    def delete(self, zone_id: int) -> Zone | None:
        with Session(self.engine, expire_on_commit=False) as s:
            rec = s.get(ZoneRecord, zone_id)
            if rec is None:
                return None
            zone = _zone(rec)
            s.delete(rec)
            s.commit()
            return zone

    def copy(self, from_map: int, to_map: int) -> int:
        """Copy every zone of one map (version) to another (a new version of the same map)."""
        zones = self.for_map(from_map)
        with Session(self.engine) as s:
            for z in zones:
                s.add(
                    ZoneRecord(
                        map_id=to_map,
                        name=z.name,
                        kind=z.kind.value,
                        polygon=[list(p) for p in z.polygon],
                        speed_limit=z.speed_limit,
                        speed_limit_unit=z.speed_limit_unit.value,
                    )
                )
            s.commit()
        return len(zones)


def _columns(spec: ZoneSpec) -> dict:
    speed = spec.kind == ZoneKind.SPEED
    return {
        "name": spec.name,
        "kind": spec.kind.value,
        "polygon": [[float(x), float(y)] for x, y in spec.polygon],
        "speed_limit": spec.speed_limit if speed else None,
        "speed_limit_unit": spec.speed_limit_unit.value,
    }
