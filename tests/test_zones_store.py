"""Zones in the database on SQLite and PostgreSQL: stored per map, copied to a new version of a map,
deleted with their map (foreign key ON DELETE CASCADE, migration 0005)."""

from __future__ import annotations

import numpy as np

from app.db import make_engine, migrate
from app.map_store import MapStore
from app.zone_store import SpeedUnit, ZoneKind, ZoneSpec, ZoneStore
from nav.types import GridGeometry, OccupancyGrid, Pose2D


def test_zones_belong_to_their_map(db_url: str) -> None:
    engine = make_engine(db_url)
    try:
        migrate(engine)
        maps, zones = MapStore(engine), ZoneStore(engine)
        grid = OccupancyGrid(GridGeometry(0.05, 40, 30, Pose2D()), np.zeros((30, 40), np.int8))
        a, b = maps.add("a", grid), maps.add("b", grid)
        square = [[0.2, 0.2], [1.0, 0.2], [1.0, 1.0], [0.2, 1.0]]
        zones.add(a.id, ZoneSpec("k", ZoneKind.KEEPOUT, square))
        s = zones.add(a.id, ZoneSpec("s", ZoneKind.SPEED, square, 0.3, SpeedUnit.MPS))
        assert [z.name for z in zones.for_map(a.id)] == ["k", "s"] and zones.for_map(b.id) == []
        assert s.limit_mps(1.0) == 0.3 and zones.get(s.id).polygon[1] == (1.0, 0.2)
        assert zones.copy(a.id, b.id) == 2
        assert [z.name for z in zones.for_map(b.id)] == ["k", "s"]
        assert maps.delete(a.id)
        assert zones.for_map(a.id) == [] and len(zones.for_map(b.id)) == 2
    finally:
        engine.dispose()
