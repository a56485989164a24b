"""Migrations and the map store on a real SQLite file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from sqlalchemy import inspect

from app.db import downgrade, make_engine, migrate
from app.map_store import MapStore
from nav.types import GridGeometry, OccupancyGrid, Pose2D

TABLES = {"robots", "maps", "runs", "run_events"}


def test_migrations_upgrade_and_downgrade_on_empty_file(tmp_path: Path) -> None:
    engine = make_engine(f"sqlite:///{tmp_path / 'empty.db'}")
    migrate(engine)
    assert set(inspect(engine).get_table_names()) >= TABLES
    with engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
    downgrade(engine, "base")
    assert not TABLES & set(inspect(engine).get_table_names())
    migrate(engine)  # and up again
    assert set(inspect(engine).get_table_names()) >= TABLES


def test_map_store_round_trip(tmp_path: Path) -> None:
    engine = make_engine(f"sqlite:///{tmp_path / 'm.db'}")
    migrate(engine)
    store = MapStore(engine)
    rng = np.random.default_rng(1)
    data = rng.choice(np.array([-1, 0, 100], dtype=np.int8), size=(40, 60))
    grid = OccupancyGrid(GridGeometry(0.05, 60, 40, Pose2D(-1.5, 2.0, 0.1)), data)
    info = store.add("lab", grid, source="slam")
    assert info.name == "lab" and info.width == 60 and info.height == 40
    back = store.grid(info.id)
    assert back is not None
    np.testing.assert_array_equal(back.data, data)
    assert back.geometry == grid.geometry
    assert store.thumbnail(info.id).startswith(b"\x89PNG")
    assert store.rename(info.id, "lab 2").name == "lab 2"
    assert [m.name for m in store.list()] == ["lab 2"]
    assert store.delete(info.id) and store.info(info.id) is None
    assert not store.delete(info.id)
